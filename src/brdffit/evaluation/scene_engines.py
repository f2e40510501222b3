"""The engines that render a comparison's scenes: the reference and every model, batch by
batch, with the same seeds (:mod:`.compare`).

An engine has ``labels`` (the models it renders), ``setup_seconds``,
``render_scene(spec, seeds, spp, resolution) -> (stacks, alpha, failures)`` (``stacks``: the
reference's batches under ``None`` and each model's under its label, ``(batches, H, W, 3)``;
``alpha`` the mean coverage; ``failures`` label → error of the models that did not render)
and ``peak(spec, ref_stack, mask, resolution, seed) -> dict`` (the PSNR numerator); the
Mitsuba engines also ``proposal_dict``, and :class:`IsolatedCRNEngine` ``close()``.

* :class:`CRNEngine`: Mitsuba 3 with common random numbers, one
  :class:`.render.core.MultiRenderer` pass per scene and batch; its peak is converged by
  re-rendering windows of the brightest pixels;
* :class:`IsolatedCRNEngine`: the same in a child process (:mod:`brdffit._isolation`), so
  that a renderer that dies from a signal fails one scene;
* :class:`CallbackEngine`: a user renderer called per model, scene and batch.
"""

from __future__ import annotations

import gc
import os
import sys
import threading
import time
import traceback
from typing import Mapping

import numpy as np

from .._isolation import ChildCrashed, IsolatedProcess, NotSendable
from ..progress import report
from .render.core import MultiRenderer, describe_evaluator
from .render.proposal import proposal_for
from .render.translate import clear_evaluator_cache, to_evaluator

__all__ = ["CRNEngine", "IsolatedCRNEngine", "CallbackEngine", "make_engine",
           "peak_from_batches", "cpu_seconds", "unpack_render"]


def unpack_render(out):
    """Renderer output → (image (H, W, 3) float64, mask (H, W) bool)."""
    img = mask = None
    if isinstance(out, tuple):
        img, mask = out[0], (out[1] if len(out) > 1 else None)
    elif isinstance(out, Mapping):
        img, mask = out.get("image"), out.get("mask")
    else:
        img, mask = getattr(out, "image", out), getattr(out, "mask", None)
    img = np.asarray(img, dtype=np.float64)
    if img.ndim == 3 and img.shape[-1] == 4:
        if mask is None:
            mask = img[..., 3] > 0.5
        img = img[..., :3]
    if mask is None:
        mask = np.ones(img.shape[:2], bool)
    return img, np.asarray(mask).astype(bool).reshape(img.shape[:2])


def _peak_candidates(ref_stack, mask):
    """Per-pixel peak statistics of the reference batches: the mean image's max RGB component
    ``v``, its standard error ``se`` (spread of that channel over the batches) and the
    candidate pixels that could hold the converged maximum (``v + 2 se ≥ max(v − 2 se)``)."""
    K = ref_stack.shape[0]
    mean = ref_stack.mean(0)
    c = np.argmax(mean, -1)
    v = np.take_along_axis(mean, c[..., None], -1)[..., 0]
    if K > 1:
        ch = np.take_along_axis(ref_stack, np.broadcast_to(c[None, ..., None], ref_stack.shape[:3] + (1,)), -1)[..., 0]
        se = ch.std(0, ddof=1) / np.sqrt(K)
    else:
        se = np.zeros_like(v)
    vm = np.where(mask, v, -np.inf)
    lo = np.max(np.where(mask, v - 2 * se, -np.inf))
    cand = mask & (vm + 2 * se >= lo)
    return v, se, cand


def peak_from_batches(ref_stack, mask) -> dict:
    """The PSNR numerator from the batches alone: max RGB of the mean reference foreground,
    with the standard error of that pixel and the PSNR shift it can cause (``20/ln 10 ·
    se/peak`` dB, common to every model of the scene)."""
    v, se, _ = _peak_candidates(ref_stack, mask)
    j = np.unravel_index(np.argmax(np.where(mask, v, -np.inf)), v.shape)
    peak = float(v[j])
    out = {"peak": peak, "peak_source": f"mean of the {ref_stack.shape[0]} batches"}
    if ref_stack.shape[0] > 1 and peak > 0:
        out |= {"peak_rel_se": float(se[j] / peak),
                "peak_psnr_se": float(20.0 / np.log(10.0) * se[j] / peak)}
    return out


class CRNEngine:
    """Mitsuba renders with common random numbers: one :class:`.render.core.MultiRenderer`
    pass per scene and batch renders the reference and every model (evaluators and the
    proposal built once per comparison)."""

    REF = "\0reference"

    def __init__(self, reference, models: Mapping, records, say, mat_name):
        t0 = time.perf_counter()
        say(f"{mat_name}: preparing the renderer (evaluators, proposal)")
        self.evaluators = {self.REF: to_evaluator(reference)}
        self.models = {self.REF: reference}
        by = {r["name"]: r for r in records}
        for label, model in models.items():
            try:
                self.evaluators[label] = to_evaluator(model)
                self.models[label] = model
                by[label]["evaluator"] = _describe(self.evaluators[label])
            except Exception as exc:  # noqa: BLE001
                by[label].update(status="failed",
                                 error=f"render failed: {type(exc).__name__}: {exc}")
                by[label]["traceback"] = traceback.format_exc(limit=4)
        self.labels = [k for k in self.models if k != self.REF]
        self.records = [by[k] for k in models]
        self.proposal = proposal_for(reference)
        self.proposal_dict = self.proposal.as_dict()
        self.setup_seconds = time.perf_counter() - t0

    #: Converging the reference's peak: samples, number of windows, window side.
    PEAK_SAMPLES = 1 << 20
    PEAK_WINDOWS = 3
    PEAK_WINDOW = 3

    def peak(self, spec, ref_stack, mask, resolution, seed) -> dict:
        """Converge the PSNR numerator (Bagher 2016 §5: the max RGB component of the
        *ground-truth* foreground).

        The max over the noisy mean of the batches is biased upwards: the brightest pixels of
        a highlight carry the most noise (10-25 % relative at 64 spp on a glossy sphere under
        the studio lights) and the max picks the luckiest; the peak scales every model's PSNR
        of the scene alike. So the batches only *select* the pixels: the ``PEAK_WINDOWS``
        brightest of the mean reference, at least ``PEAK_WINDOW`` pixels apart, and the
        ``PEAK_WINDOW × PEAK_WINDOW`` windows around them are re-rendered with the reference
        alone and independent seeds, ``PEAK_SAMPLES`` samples in all (4 batches, so their
        standard error is known; ~40k spp per pixel). The peak is the max of those converged
        windows over the foreground: with independent samples the selection's luck does not
        carry over, the max over a few converged pixels has a negligible bias, and missing
        the true maximum pixel costs little precisely when many pixels are close to it (a
        broad highlight). Reported: ``peak``, ``peak_rel_se`` / ``peak_psnr_se`` (residual
        uncertainty; added to every model's ``psnr_se`` of the scene), ``peak_batches_only``
        (the naive max, for comparison) and the windows."""
        v, _, _ = _peak_candidates(ref_stack, mask)
        H, Wd = v.shape
        W = self.PEAK_WINDOW
        vm = np.where(mask, v, -np.inf)
        batches_max = float(vm.max())
        windows = []
        for _ in range(self.PEAK_WINDOWS):
            if not np.isfinite(vm.max()):
                break
            jy, jx = np.unravel_index(np.argmax(vm), vm.shape)
            y0 = int(np.clip(jy - W // 2, 0, max(H - W, 0)))
            x0 = int(np.clip(jx - W // 2, 0, max(Wd - W, 0)))
            windows.append((x0, y0, min(W, Wd), min(W, H)))
            vm[max(0, y0 - W // 2):y0 + W + W // 2, max(0, x0 - W // 2):x0 + W + W // 2] = -np.inf
        nb = 4
        area = sum(w * h for _, _, w, h in windows)
        spp = int(np.clip(self.PEAK_SAMPLES // (area * nb), 64, 1 << 16))
        mr = MultiRenderer({self.REF: self.models[self.REF]}, scene=spec.name, envmap=spec.envmap,
                           resolution=resolution, proposal=self.proposal,
                           evaluators={self.REF: self.evaluators[self.REF]})
        best = None
        for k, (x0, y0, w, h) in enumerate(windows):
            st = np.stack([mr.render(seed + 4 * k + b, spp, crop=(x0, y0, w, h)).images[self.REF]
                           for b in range(nb)])
            wv, wse, _ = _peak_candidates(st, np.ones((h, w), bool))
            wv = np.where(mask[y0:y0 + h, x0:x0 + w], wv, -np.inf)
            j = np.unravel_index(np.argmax(wv), wv.shape)
            if best is None or wv[j] > best[0]:
                best = (float(wv[j]), float(wse[j]))
        if best is None or not best[0] > 0:
            return peak_from_batches(ref_stack, mask)
        peak, pse = best
        return {"peak": peak, "peak_rel_se": pse / peak,
                "peak_psnr_se": float(20.0 / np.log(10.0) * pse / peak),
                "peak_source": f"{len(windows)} window(s) of the brightest pixels re-rendered "
                               f"with {nb * spp} spp",
                "peak_windows": [list(w) for w in windows], "peak_spp": nb * spp,
                "peak_batches_only": batches_max}

    def _render(self, labels, spec, seeds, spp, resolution):
        keys = [self.REF] + list(labels)
        mr = MultiRenderer({k: self.models[k] for k in keys}, scene=spec.name,
                           envmap=spec.envmap, resolution=resolution, proposal=self.proposal,
                           evaluators={k: self.evaluators[k] for k in keys})
        stacks = {k: [] for k in keys}
        alpha = []
        for i, s in enumerate(seeds):
            report(stage=f"render {spec.name}, {len(keys)} images", iteration=i + 1,
                   max_iterations=len(seeds))
            res = mr.render(s, spp)
            for k in keys:
                stacks[k].append(res.images[k])
            alpha.append(res.alpha)
        return {k: np.stack(v) for k, v in stacks.items()}, np.mean(alpha, 0)

    def render_scene(self, spec, seeds, spp, resolution):
        failures: dict[str, str] = {}
        try:
            stacks, alpha = self._render(self.labels, spec, seeds, spp, resolution)
        except Exception:  # noqa: BLE001 – isolate the model that breaks the pass
            stacks, alpha = self._render([], spec, seeds, spp, resolution)
            for label in self.labels:
                try:
                    one, _ = self._render([label], spec, seeds, spp, resolution)
                    stacks[label] = one[label]
                except Exception as exc:  # noqa: BLE001
                    failures[label] = f"render failed: {type(exc).__name__}: {exc}"
        stacks[None] = stacks.pop(self.REF)
        return stacks, alpha, failures


# -- the renders in a child process ------------------------------------------------------------
_CHILD_ENGINE: "CRNEngine | None" = None


def _child_engine_init(reference, models: Mapping, mat_name: str) -> None:
    """In the renderer's child process: build the :class:`CRNEngine` that the following
    :func:`_child_engine_call` use."""
    global _CHILD_ENGINE
    _CHILD_ENGINE = None
    records = [{"name": label, "status": "ok"} for label in models]
    _CHILD_ENGINE = CRNEngine(reference, models, records, lambda msg: report(stage=msg),
                               mat_name)


def _child_engine_info() -> dict:
    """What the parent's :class:`IsolatedCRNEngine` mirrors of the child's engine."""
    e = _CHILD_ENGINE
    return {"labels": list(e.labels), "records": e.records, "proposal_dict": e.proposal_dict,
            "setup_seconds": e.setup_seconds}


def _child_engine_call(method: str, *args):
    return getattr(_CHILD_ENGINE, method)(*args)


def _child_engine_release() -> None:
    """In the renderer's child process: free the engine and its evaluators (the translation
    cache, reference cycles), keep the process. Left alive, they make the next material's
    renders cost 1.2-1.3× and its peaks 3-4× the CPU (docs/design/batch.md)."""
    global _CHILD_ENGINE
    _CHILD_ENGINE = None
    clear_evaluator_cache()
    gc.collect()


#: comparisons one renderer child serves before a new child replaces it (it keeps Dr.Jit's
#: compiled kernels and the loaded scenes between them; the bound caps whatever else it
#: accumulates)
RENDERER_CHILD_USES = 32
_RENDERER_CHILD = threading.local()


def _renderer_child() -> IsolatedProcess:
    """This thread's renderer child (one per thread: concurrent comparisons never share
    one), replaced after :data:`RENDERER_CHILD_USES` comparisons and when the environment
    or ``sys.path`` it was started with changed (they configure the renderer)."""
    setting = (sorted(os.environ.items()), list(sys.path))
    child, uses, started_with = getattr(_RENDERER_CHILD, "slot", (None, 0, None))
    if child is None or uses >= RENDERER_CHILD_USES or started_with != setting:
        if child is not None:
            child.close()
        child, uses = IsolatedProcess("the renderer", track_stages=False), 0
    _RENDERER_CHILD.slot = (child, uses + 1, setting)
    return child


class IsolatedCRNEngine:
    """:class:`CRNEngine` in a child process (:class:`brdffit._isolation.IsolatedProcess`):
    a renderer that dies from a signal fails the scene it was rendering, with one line
    (``the renderer crashed (SIGSEGV) while rendering knot-courtyard for gold-ggx``), and the
    next scene starts a new child. The child is the thread's (:func:`_renderer_child`), kept
    for its next comparison with its compiled kernels. Same interface as :class:`CRNEngine`;
    ``child_cpu_seconds``: the child's CPU time for this engine."""

    def __init__(self, reference, models: Mapping, records, say, mat_name):
        self.mat_name, self.say = mat_name, say
        say(f"{mat_name}: preparing the renderer (evaluators, proposal)")
        self.child = _renderer_child()
        self._cpu0 = self.child.cpu_seconds
        self.child.stage = f"preparing the renderer for {mat_name}"
        self.child.reinit([(_child_engine_init, (reference, dict(models), mat_name), {})])
        info = self.child.call(_child_engine_info)
        by = {r["name"]: r for r in records}
        for rec in info["records"]:
            by[rec["name"]].update(rec)
        self.labels, self.proposal_dict = info["labels"], info["proposal_dict"]
        self.setup_seconds = info["setup_seconds"]

    @property
    def child_cpu_seconds(self) -> float:
        return self.child.cpu_seconds - self._cpu0

    def _call(self, stage: str, method: str, *args):
        self.child.stage = stage
        try:
            return self.child.call(_child_engine_call, method, *args)
        except ChildCrashed as exc:
            self.say(f"{self.mat_name}: {exc}")
            raise

    def render_scene(self, spec, seeds, spp, resolution):
        return self._call(f"rendering {spec.name} for {self.mat_name}", "render_scene", spec,
                          seeds, spp, resolution)

    def peak(self, spec, ref_stack, mask, resolution, seed) -> dict:
        return self._call(f"converging the peak of {spec.name} for {self.mat_name}", "peak",
                          spec, ref_stack, mask, resolution, seed)

    def close(self) -> None:
        """Drop the engine in the child; the child stays for the thread's next comparison."""
        self.child.init = []
        if self.child.running:
            try:
                self.child.call(_child_engine_release)
            except ChildCrashed:  # the next comparison starts a new child
                pass


def cpu_seconds(engine) -> float:
    """CPU time of this process and of the engine's renderer child (if any)."""
    return time.process_time() + getattr(engine, "child_cpu_seconds", 0.0)


def make_engine(reference, models: Mapping, records, say, mat_name, isolate: bool):
    """The Mitsuba engine, in a child process when ``isolate`` and the BRDFs can be sent
    there (pickled); otherwise in this process, with the reason. Returns ``(engine, note)``."""
    if isolate:
        try:
            return IsolatedCRNEngine(reference, models, records, say, mat_name), None
        except NotSendable as exc:  # e.g. a class defined in __main__
            note = f"renders ran in this process, not isolated: {exc}"
            say = (lambda msg: None)  # "preparing the renderer" was said already
    else:
        note = None
    return CRNEngine(reference, models, records, say, mat_name), note


class CallbackEngine:
    """A user renderer called per model, scene and batch with the batch's seed."""

    def __init__(self, renderer, reference, models: Mapping, ropts):
        self.renderer, self.reference, self.models, self.ropts = renderer, reference, models, ropts
        self.labels = list(models)
        self.setup_seconds = 0.0

    def peak(self, spec, ref_stack, mask, resolution, seed) -> dict:
        return peak_from_batches(ref_stack, mask)

    def render_scene(self, spec, seeds, spp, resolution):
        opts = dict(self.ropts)
        if spec.envmap is not None and isinstance(spec.envmap, str):
            opts["envmap"] = spec.envmap
        failures: dict[str, str] = {}
        ref, alpha = [], []
        for s in seeds:
            img, mask = unpack_render(self.renderer(self.reference, scene=spec.name, spp=spp,
                                                     resolution=resolution, seed=s, **opts))
            ref.append(img)
            alpha.append(mask.astype(np.float64))
        stacks = {None: np.stack(ref)}
        for label, model in self.models.items():
            try:
                stacks[label] = np.stack([
                    unpack_render(self.renderer(model, scene=spec.name, spp=spp,
                                                 resolution=resolution, seed=s, **opts))[0]
                    for s in seeds])
            except Exception as exc:  # noqa: BLE001
                failures[label] = f"render failed: {type(exc).__name__}: {exc}"
        return stacks, np.min(alpha, 0), failures


def _describe(ev) -> str:
    return describe_evaluator(ev)
