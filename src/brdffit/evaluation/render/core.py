"""Rendering entry points: :func:`render`, :func:`render_ex`, :func:`noise_floor`.

A render builds the Dr.Jit evaluator of the BRDF (:func:`.translate.to_evaluator`), wraps it
in the Mitsuba plugin (:class:`.plugin.BRDFBSDF`), loads the named scene
(:func:`.scenes.scene_dict`) and runs Mitsuba's ``direct`` (sphere scenes) or ``path``
(knot) integrator, both with MIS between the BSDF's sampling and emitter sampling. Output
is linear RGB ``(H, W, 3)`` float32 in the units of the lights (environment radiance ×
BRDF); the film's alpha gives the coverage and the foreground mask (pixels fully covered by the object, as Bagher 2016 §5 counts for PSNR).

Comparisons with common random numbers: :class:`MultiRenderer` renders the
reference and any number of models *in one pass* with a Python ``mi.SamplingIntegrator``
(:func:`crn_integrator`): every path is traced once, its directions drawn from one
model-independent :class:`.proposal.Proposal` (fitted to the reference) combined by MIS
(power heuristic) with Mitsuba's emitter sampling, and every model's BRDF is evaluated along
it, each model keeping its own path throughput; the images come out as AOVs of the film.
The sample draws per vertex mirror Mitsuba's ``direct`` integrator (one emitter sample
``next_2d``, then the proposal's ``next_2d`` and ``next_1d``, in the order the compiled
``direct`` integrator draws them), there is no Russian roulette
(it would depend on a model's throughput), so the directions, densities, MIS weights and the
number of random numbers consumed are identical for every model *by construction*. The same
holds one model at a time with :class:`Renderer` ``(proposal=...)`` (the plugin's option):
:func:`crn_integrator` on a sphere scene reproduces Mitsuba's ``direct`` integrator with the
plugin and the same proposal (tested). Scenes are loaded once per (scene, map, resolution)
and reused for every material (:func:`load_scene`): the CRN integrator does not use the
shape's BSDF, it evaluates the models itself.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..metrics import rendered_psnr as psnr  # Bagher 2016 §5 (one implementation)
from ._mitsuba import load
from .plugin import make_bsdf
from .proposal import proposal_for
from .scenes import SCENES, roughness_texture, scene_dict, scene_spec, window_sensor
from .translate import to_evaluator

__all__ = ["RenderResult", "Renderer", "render", "render_ex", "noise_floor", "psnr",
           "foreground_mask", "MultiRenderer", "MultiRenderResult", "render_models",
           "crn_integrator", "load_scene"]


@dataclasses.dataclass
class RenderResult:
    """A rendering: ``image`` (H, W, 3) linear float32, ``alpha`` (H, W) coverage,
    ``mask`` (H, W) bool foreground, ``seconds`` (render only, excluding set-up, wall
    clock), ``cpu_seconds`` (CPU time of the process during the render, all threads: a
    load-independent cost on a shared machine),
    ``setup_seconds`` (tabulation, translation, scene load) and ``info`` (scene, spp, seed,
    evaluator path/kind)."""

    image: np.ndarray
    alpha: np.ndarray
    mask: np.ndarray
    seconds: float
    setup_seconds: float
    info: dict
    cpu_seconds: float = float("nan")


def foreground_mask(alpha, threshold: float = 0.999) -> np.ndarray:
    """Pixels fully covered by the object (coverage ≥ ``threshold``)."""
    return np.asarray(alpha) >= threshold


def describe_evaluator(ev) -> str:
    """Short description of a Dr.Jit evaluator (kind and, for microfacet ones, components)."""
    d = getattr(ev, "describe", None)
    return d() if callable(d) else getattr(ev, "kind", type(ev).__name__)


class Renderer:
    """A prepared scene for one BRDF: build once, render with several seeds/spp.

    Parameters as :func:`render`; ``mode`` is passed to :func:`.translate.to_evaluator`
    (``"auto"``, ``"table"``, ``"closed"``); ``evaluator`` bypasses translation;
    ``proposal`` (a :class:`.proposal.Proposal`, or a BRDF to fit one to) replaces the
    model's own sampling (common random numbers: see :mod:`.plugin`).
    """

    def __init__(self, brdf=None, scene: str = "sphere-env", envmap=None, spp: int = 256,
                 resolution: int = 256, mode: str = "auto", evaluator=None,
                 alpha_texture=None, proposal=None):
        self.mi, self.dr = load()
        t0 = time.perf_counter()
        if evaluator is None:
            if brdf is None:
                raise ValueError("Renderer needs a brdf or an evaluator")
            evaluator = to_evaluator(brdf, mode=mode)
        self.evaluator = evaluator
        if scene == "sphere-svrough" and alpha_texture is None:
            alpha_texture = roughness_texture()
        if alpha_texture is not None and not getattr(evaluator, "supports_roughness", False):
            import warnings

            warnings.warn(f"the {getattr(evaluator, 'kind', 'table')} evaluator has no "
                          "microfacet roughness: the roughness texture is ignored (only "
                          "microfacet models, closed-form or tabulated, support Eq. 9 scaling)",
                          RuntimeWarning, stacklevel=2)
        if proposal is not None and not hasattr(proposal, "sample"):
            proposal = proposal_for(proposal)
        self.proposal = proposal
        self.bsdf = make_bsdf(evaluator, alpha_texture=alpha_texture, proposal=proposal)
        self.scene_name, self.spp, self.resolution = scene, int(spp), int(resolution)
        self.envmap = envmap
        if envmap is None and scene not in SCENES:  # a suite name carries its map
            self.envmap = scene_spec(scene).envmap
        self.scene = self.mi.load_dict(scene_dict(self.bsdf, scene, envmap, spp, resolution))
        self.setup_seconds = time.perf_counter() - t0

    def render(self, seed: int = 0, spp: int | None = None) -> RenderResult:
        spp = self.spp if spp is None else int(spp)
        t0, c0 = time.perf_counter(), time.process_time()
        img = self.mi.render(self.scene, seed=int(seed), spp=spp)
        arr = np.array(img, dtype=np.float32)  # forces evaluation
        seconds = time.perf_counter() - t0
        cpu = time.process_time() - c0
        rgb = np.ascontiguousarray(arr[..., :3])
        alpha = np.ascontiguousarray(arr[..., 3]) if arr.shape[-1] > 3 else np.ones(arr.shape[:2], np.float32)
        info = {"scene": self.scene_name, "spp": spp, "seed": int(seed),
                "resolution": self.resolution,
                "envmap": None if self.envmap is None or isinstance(self.envmap, np.ndarray)
                else str(self.envmap),
                "evaluator": describe_evaluator(self.evaluator),
                "path": getattr(self.evaluator, "path", None),
                "proposal": None if self.proposal is None else self.proposal.describe()}
        return RenderResult(rgb, alpha, foreground_mask(alpha), seconds, self.setup_seconds, info,
                            cpu)


def render_ex(brdf, scene: str = "sphere-env", envmap=None, spp: int = 256,
              resolution: int = 256, seed: int = 0, mode: str = "auto",
              alpha_texture=None, proposal=None) -> RenderResult:
    """Render ``brdf`` and return a :class:`RenderResult` (image, alpha, mask, timings);
    ``proposal``: see :class:`Renderer`."""
    return Renderer(brdf, scene, envmap, spp, resolution, mode,
                    alpha_texture=alpha_texture, proposal=proposal).render(seed)


def render(brdf, scene: str = "sphere-env", envmap=None, spp: int = 256, resolution: int = 256,
           seed: int = 0, mode: str = "auto", return_mask: bool = False):
    """Render any BRDF of the library with Mitsuba 3; linear ``(H, W, 3)`` float32.

    ``scene``: one of :data:`.scenes.SCENES`; ``envmap``: ``None`` (procedural), a name of
    ``../shared/data/envmaps`` or an EXR path; ``mode``: evaluator choice (``"auto"``,
    ``"table"``, ``"closed"``). With ``return_mask=True`` returns ``(image, mask)`` where
    ``mask`` marks fully covered foreground pixels.
    """
    res = render_ex(brdf, scene, envmap, spp, resolution, seed, mode)
    return (res.image, res.mask) if return_mask else res.image


def noise_floor(brdf, scene: str = "sphere-env", envmap=None, spp: int = 256,
                resolution: int = 256, seeds=(0, 1), mode: str = "auto") -> dict:
    """Monte Carlo noise floor: PSNR (Bagher 2016 §5) between two renders of the same BRDF
    with different seeds. Superseded in comparisons by the standard error of the CRN
    estimator (:func:`brdffit.evaluation.metrics.crn_psnr`); kept as a diagnostic. Returns ``{"psnr": ..., "seeds": ..., "spp": ..., ...}``."""
    r = Renderer(brdf, scene, envmap, spp, resolution, mode)
    a, b = r.render(seeds[0]), r.render(seeds[1])
    return {"psnr": psnr(a.image, b.image, a.mask), "seeds": list(seeds), "spp": int(spp),
            "resolution": int(resolution), "scene": scene,
            "render_seconds": [a.seconds, b.seconds], "path": a.info["path"]}


# ------------------------------------------------------------------------------------------
# common random numbers: several models in one pass
# ------------------------------------------------------------------------------------------
_SCENES: "dict[tuple, object]" = {}
_SCENE_CACHE_SIZE = 8


def load_scene(scene: str = "sphere-env", envmap=None, resolution: int = 256):
    """The Mitsuba scene of ``scene`` (any name of :func:`.scenes.scene_spec`) with a
    placeholder diffuse BSDF, cached per (scene, map, resolution) so that every material of a
    comparison reuses it (environment-map sampling tables, the knot mesh and its BVH are built
    once). For :func:`crn_integrator`, which evaluates the models itself."""
    mi, _ = load()
    spec = scene_spec(scene, envmap)
    key = (spec.base, spec.envmap if not isinstance(spec.envmap, np.ndarray) else id(spec.envmap),
           int(resolution))
    hit = _SCENES.get(key)
    if hit is not None:
        return hit
    sc = mi.load_dict(scene_dict(mi.load_dict({"type": "diffuse"}), spec.base, spec.envmap, 4,
                                 resolution))
    if not isinstance(spec.envmap, np.ndarray):
        _SCENES[key] = sc
        while len(_SCENES) > _SCENE_CACHE_SIZE:
            _SCENES.pop(next(iter(_SCENES)))
    return sc


_INTEGRATOR_CLS = None


def crn_integrator(evaluators, proposal, max_depth: int = 2, alpha_texture=None):
    """A ``mi.SamplingIntegrator`` rendering every evaluator of ``evaluators`` along the same
    paths (see the module docstring); the film gets ``3·len(evaluators)`` AOV channels
    ``m<i>.R/G/B`` (the main RGB output is model 0).

    Per scattering vertex (``max_depth − 1`` of them: 1 for a convex object lit directly, 3
    for the knot, as Mitsuba's ``path`` with ``max_depth``): an emitter sample (MIS weight
    ``p_e² / (p_e² + p_prop²)``, 1 for delta lights) and a proposal sample (weight
    ``p_prop² / (p_prop² + p_e²)`` when the ray escapes to the environment), the model's
    ``f · cos θ`` applied per model; the path continues along the proposal's direction with
    each model's throughput multiplied by its ``f cos θ / p_prop``. Two-sided like the plugin
    (directions mirrored when the viewer is below the shading frame). ``alpha_texture`` gives
    the spatially varying roughness of ``sphere-svrough`` to the models that support it.
    """
    global _INTEGRATOR_CLS
    mi, dr = load()
    if _INTEGRATOR_CLS is None:
        _INTEGRATOR_CLS = _make_integrator_class(mi, dr)
    return _INTEGRATOR_CLS(list(evaluators), proposal, int(max_depth), alpha_texture)


def _flip(v, f):
    """``v`` with z negated where ``f`` (two-sided shading)."""
    mi, dr = load()
    return mi.Vector3f(v.x, v.y, dr.select(f, -v.z, v.z))


def _power(a, b):
    """The power-heuristic MIS weight ``a² / (a² + b²)`` of densities a, b (0 when both are 0)."""
    _, dr = load()
    a2, b2 = dr.square(a), dr.square(b)
    return dr.detach(dr.select(a2 + b2 > 0, a2 / (a2 + b2), 0.0))


def _crn_aov_names(self):
    """The film's AOV channels: ``m<i>.R/G/B`` per evaluator."""
    return [f"m{i}.{c}" for i in range(len(self.evs)) for c in "RGB"]


def _crn_to_string(self):
    return f"CRNIntegrator[{len(self.evs)} models, max_depth={self.max_depth}]"


def _crn_sample(self, scene, sampler, ray, medium=None, active=True):
    """``SamplingIntegrator.sample`` of :func:`crn_integrator`: the paths of every model
    along the same vertices (module docstring); returns model 0's radiance, the validity
    mask and every model's RGB as AOVs."""
    mi, dr = load()
    n = len(self.evs)
    out = [mi.Color3f(0.0) for _ in range(n)]
    thr = [mi.Color3f(1.0) for _ in range(n)]
    si = scene.ray_intersect(ray, active)
    valid = mi.Bool(active) & si.is_valid()
    act = mi.Bool(valid)
    for depth in range(1, self.max_depth):
        last = depth == self.max_depth - 1
        f_ = si.wi.z < 0
        view = _flip(si.wi, f_)
        s = 1.0
        if self.alpha_tex is not None:
            s = dr.maximum(self.alpha_tex.eval(si.uv)[0], 1e-3)
        frame = (view, f_, s)
        self.emitter_sampling(scene, sampler, si, act, frame, out, thr)
        si_b, ok_b = self.proposal_sampling(scene, sampler, si, act, frame, out, thr, last)
        if not last:
            si = si_b
            act = ok_b & si_b.is_valid()
    aovs = []
    for o in out:
        aovs += [o.x, o.y, o.z]
    return out[0], valid, aovs


def _crn_emitter_sampling(self, scene, sampler, si, act, frame, out, thr):
    """Add each model's emitter-sampled light at ``si`` (model-independent samples, MIS
    with the proposal) to ``out``; ``frame`` = (view, flip, roughness scale)."""
    _, dr = load()
    view, f_, s = frame
    ds, em_w = scene.sample_emitter_direction(si, sampler.next_2d(act), True, act)
    act_e = act & (ds.pdf != 0)
    light = _flip(si.to_local(ds.d), f_)
    ok_e = act_e & (light.z > 0) & (view.z > 0)
    p_b = self.proposal.pdf(view, light, 1.0, ok_e)
    mis_e = dr.select(ds.delta, 1.0, _power(ds.pdf, p_b))
    c_e = em_w * (mis_e * light.z)
    for i, ev in enumerate(self.evs):
        f = ev.eval(light, view, s if self.rough[i] else 1.0, ok_e)
        out[i] += dr.select(ok_e, thr[i] * f * c_e, 0.0)


def _crn_proposal_sampling(self, scene, sampler, si, act, frame, out, thr, last):
    """Sample the proposal at ``si``, add each model's emitter hit (MIS with emitter
    sampling) to ``out`` and, unless ``last``, weight ``thr`` by the bounce; returns the
    next interaction and its mask."""
    mi, dr = load()
    view, f_, s = frame
    # Mitsuba's direct integrator passes next_1d(), next_2d() as arguments of
    # bsdf->sample; the compiler evaluates them right to left, so the 2D sample is
    # drawn first. Same order here: same random numbers as Mitsuba + the plugin.
    u2 = sampler.next_2d(act)
    u1 = sampler.next_1d(act)
    lb, pb = self.proposal.sample(view, u1, u2, 1.0, act)
    ok_b = act & (lb.z > 0) & (view.z > 0) & (pb > 0)
    si_b = scene.ray_intersect(si.spawn_ray(si.to_world(_flip(lb, f_))), ok_b)
    ds_b = mi.DirectionSample3f(scene, si_b, si)
    em_b = ds_b.emitter
    hit_e = ok_b & (em_b != None)  # noqa: E711 – Dr.Jit pointer comparison
    p_em = scene.pdf_emitter_direction(si, ds_b, hit_e)
    le = em_b.eval(si_b, hit_e)
    c_b = dr.select(hit_e, le * _power(pb, p_em), 0.0)
    inv_p = dr.select(ok_b, 1.0 / pb, 0.0) * lb.z
    for i, ev in enumerate(self.evs):
        w = dr.select(ok_b, ev.eval(lb, view, s if self.rough[i] else 1.0, ok_b)
                      * inv_p, 0.0)
        out[i] += thr[i] * w * c_b
        if not last:
            thr[i] = thr[i] * w
    return si_b, ok_b


def _make_integrator_class(mi, dr):
    """The ``mi.SamplingIntegrator`` subclass of :func:`crn_integrator` (made at first use:
    Mitsuba is loaded lazily); its methods are the ``_crn_*`` functions. Attributes:
    ``evs`` (evaluators), ``proposal``, ``max_depth``, ``alpha_tex`` (``mi.Texture2f`` or
    None) and ``rough`` (per evaluator: whether it takes the roughness scale)."""

    class CRNIntegrator(mi.SamplingIntegrator):
        aov_names = _crn_aov_names
        to_string = _crn_to_string
        sample = _crn_sample
        emitter_sampling = _crn_emitter_sampling
        proposal_sampling = _crn_proposal_sampling

        def __init__(self, evaluators, proposal, max_depth, alpha_texture):
            mi.SamplingIntegrator.__init__(self, mi.Properties())
            if max_depth < 2:
                raise ValueError(f"max_depth must be ≥ 2, got {max_depth}")
            self.evs = evaluators
            self.proposal = proposal
            self.max_depth = max_depth
            self.alpha_tex = None
            if alpha_texture is not None:
                a = np.asarray(alpha_texture, np.float32)
                self.alpha_tex = mi.Texture2f(mi.TensorXf(a[..., None] if a.ndim == 2 else a),
                                              filter_mode=dr.FilterMode.Linear,
                                              wrap_mode=dr.WrapMode.Repeat)
            self.rough = [bool(getattr(e, "supports_roughness", False)) for e in evaluators]

    return CRNIntegrator


@dataclasses.dataclass
class MultiRenderResult:
    """One pass of :class:`MultiRenderer`: ``images`` label → (H, W, 3) linear float32 (all
    rendered from the same paths), ``alpha``/``mask`` as :class:`RenderResult`, ``seconds``
    (wall) and ``cpu_seconds`` of the render, ``info`` (scene, spp, seed, proposal)."""

    images: dict
    alpha: np.ndarray
    mask: np.ndarray
    seconds: float
    cpu_seconds: float
    info: dict


class MultiRenderer:
    """Render a reference and several models with common random numbers.

    ``models``: mapping label → BRDF (translated with :func:`.translate.to_evaluator`, ``mode``)
    unless ``evaluators`` (label → ready Dr.Jit evaluator) has it already. ``proposal``: a :class:`.proposal.Proposal`;
    by default one fitted to ``reference`` (a BRDF) or else to the first model. ``scene``: any
    name of :func:`.scenes.scene_spec` (``sphere-studio``, ``knot-courtyard``, ``sphere-env``
    with ``envmap``, ...). Translation, proposal and the scene are prepared once;
    :meth:`render` then renders every model in one pass for a seed.
    """

    def __init__(self, models, scene: str = "sphere-env", envmap=None, resolution: int = 256,
                 proposal=None, reference=None, mode: str = "auto", evaluators=None):
        self.mi, self.dr = load()
        t0 = time.perf_counter()
        self.labels = list(models)
        if not self.labels:
            raise ValueError("MultiRenderer needs at least one model")
        evs = dict(evaluators or {})
        for k in self.labels:
            if k not in evs:
                evs[k] = to_evaluator(models[k], mode=mode)
        self.evaluators = evs
        if proposal is None:
            src = reference if reference is not None else models[self.labels[0]]
            proposal = proposal_for(src)
        self.proposal = proposal
        self.spec = scene_spec(scene, envmap)
        self.resolution = int(resolution)
        self.scene = load_scene(scene, envmap, resolution)
        alpha_tex = roughness_texture() if self.spec.base == "sphere-svrough" else None
        self.integrator = crn_integrator([evs[k] for k in self.labels], proposal,
                                         self.spec.max_depth, alpha_tex)
        self._sensors: dict = {}
        self.setup_seconds = time.perf_counter() - t0

    def render(self, seed: int = 0, spp: int = 16, crop=None) -> MultiRenderResult:
        """Render every model in one pass; ``crop=(x0, y0, width, height)`` renders only that
        window of the image (same pixels, e.g. to converge the reference's peak)."""
        t0, c0 = time.perf_counter(), time.process_time()
        kw = {}
        if crop is not None:
            crop = tuple(int(v) for v in crop)
            x0, y0, w, h = crop
            if not (0 <= x0 and 0 <= y0 and w >= 1 and h >= 1
                    and x0 + w <= self.resolution and y0 + h <= self.resolution):
                raise ValueError(f"crop: expected a window inside the {self.resolution}² "
                                 f"film, found (x0, y0, width, height) = {crop}")
            if (w, h) not in self._sensors:
                self._sensors[w, h] = window_sensor(self.resolution, w, h)
            self._sensors[w, h].move(x0, y0)
            kw["sensor"] = self._sensors[w, h]
        img = self.mi.render(self.scene, integrator=self.integrator, seed=int(seed), spp=int(spp),
                             **kw)
        arr = np.array(img, dtype=np.float32)
        seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
        n = len(self.labels)
        if arr.shape[-1] != 4 + 3 * n:
            raise RuntimeError(f"expected {4 + 3 * n} film channels (RGBA + AOVs), found {arr.shape[-1]}")
        alpha = np.ascontiguousarray(arr[..., 3])
        images = {k: np.ascontiguousarray(arr[..., 4 + 3 * i: 7 + 3 * i])
                  for i, k in enumerate(self.labels)}
        info = {"scene": self.spec.name, "base": self.spec.base,
                "envmap": self.spec.envmap if isinstance(self.spec.envmap, (str, type(None))) else "array",
                "spp": int(spp), "seed": int(seed), "resolution": self.resolution,
                "crop": crop, "max_depth": self.spec.max_depth, "proposal": self.proposal.describe(),
                "evaluators": {k: describe_evaluator(self.evaluators[k]) for k in self.labels}}
        return MultiRenderResult(images, alpha, foreground_mask(alpha), seconds, cpu, info)


def render_models(models, scene: str = "sphere-env", envmap=None, spp: int = 16,
                  resolution: int = 256, seed: int = 0, proposal=None, reference=None,
                  mode: str = "auto") -> MultiRenderResult:
    """Render several BRDFs with common random numbers in one pass (:class:`MultiRenderer`)."""
    return MultiRenderer(models, scene, envmap, resolution, proposal, reference, mode).render(seed, spp)
