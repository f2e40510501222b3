"""The Mitsuba 3 BSDF plugin that renders any BRDF of the library (written with Dr.Jit ops).

:class:`BRDFBSDF` subclasses ``mi.BSDF`` and delegates to a Dr.Jit *evaluator*
(:mod:`.drjit_eval`, chosen by :func:`.translate.to_evaluator`), so all the work runs in
Mitsuba's compiled LLVM kernels; Python is only called while tracing.

Conventions. Mitsuba's ``si.wi`` points to the viewer and the BSDF's ``wo`` to the light; the
library's ``eval(wi, wo)`` has ``wi`` towards the light and ``wo`` towards the viewer, so the
plugin calls ``evaluator.eval(light, viewer)``; sampling draws the light direction given the
viewer (``evaluator.sample(viewer, ...)``) and ``pdf`` is that density (reciprocal BRDFs make
the distinction moot, but it keeps non-reciprocal tables right). The plugin is two-sided
(both directions mirrored when the viewer is below the surface, like Mitsuba's ``twosided``).

Spatially varying roughness (Dupuy 2015 Eq. 9, Fig. 1/4): with ``alpha_texture`` (a 2D array
of positive scales), the roughness multiplier at the hit point's ``uv`` is read with bilinear
filtering (``mi.Texture2f``) and passed to the evaluator's distribution.

Common random numbers: with ``proposal`` (an object with the evaluators'
``sample``/``pdf`` interface, e.g. :class:`.proposal.Proposal` fitted to a comparison's
reference), ``sample`` and ``pdf`` come from the proposal and only ``eval`` from the model.
Two BSDFs sharing a proposal then draw the same light directions with the same densities and
MIS weights from the same random numbers (``sample`` always consumes one 1D and one 2D
sample, whatever the model), so images of different models rendered with one seed differ
only through the BRDF values.
"""

from __future__ import annotations

import itertools

import numpy as np

from ._mitsuba import load as _load

mi, dr = _load()

__all__ = ["BRDFBSDF", "make_bsdf", "register_evaluator", "unregister_evaluator", "PLUGIN_NAME"]

PLUGIN_NAME = "brdffit"
_EVALUATORS: dict[str, object] = {}
_ids = itertools.count()


class BRDFBSDF(mi.BSDF):
    """Mitsuba BSDF wrapping a Dr.Jit evaluator (see module docstring)."""

    def __init__(self, props, evaluator=None, alpha_texture=None, proposal=None):
        mi.BSDF.__init__(self, props)
        if evaluator is None:
            key = props.get("evaluator_id", None) if hasattr(props, "get") else None
            if key is None or key not in _EVALUATORS:
                raise ValueError(f"{PLUGIN_NAME} BSDF needs an evaluator (evaluator_id {key!r} unknown)")
            evaluator = _EVALUATORS[key]
        self.evaluator = evaluator
        self.proposal = proposal
        self.sampler = evaluator if proposal is None else proposal
        self.alpha_tex = None
        if alpha_texture is not None:
            a = np.asarray(alpha_texture, dtype=np.float32)
            if a.ndim == 2:
                a = a[..., None]
            if a.ndim != 3 or a.shape[-1] != 1 or not np.all(a > 0):
                raise ValueError(f"alpha_texture must be a positive (H, W) array, got {a.shape}")
            self.alpha_tex = mi.Texture2f(mi.TensorXf(a), filter_mode=dr.FilterMode.Linear,
                                          wrap_mode=dr.WrapMode.Repeat)
        flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide
        if getattr(evaluator, "has_diffuse", True):
            flags = flags | mi.BSDFFlags.DiffuseReflection
        if self.alpha_tex is not None:
            flags = flags | mi.BSDFFlags.SpatiallyVarying
        self.m_flags = flags
        self.m_components = [flags]

    # -- helpers ---------------------------------------------------------------------------
    def _scale(self, si):
        if self.alpha_tex is None:
            return 1.0
        return dr.maximum(self.alpha_tex.eval(si.uv)[0], 1e-3)

    @staticmethod
    def _flip(v, flip):
        return mi.Vector3f(v.x, v.y, dr.select(flip, -v.z, v.z))

    # -- mi.BSDF interface -----------------------------------------------------------------
    def sample(self, ctx, si, sample1, sample2, active=True):
        flip = si.wi.z < 0
        view = self._flip(si.wi, flip)
        s = self._scale(si)
        light, pdf = self.sampler.sample(view, sample1, sample2, s, active)
        ok = active & (light.z > 0) & (pdf > 0)
        f = self.evaluator.eval(light, view, s, ok)
        weight = f * (light.z / dr.select(ok, pdf, 1.0))
        bs = mi.BSDFSample3f()
        bs.wo = self._flip(light, flip)
        bs.pdf = dr.select(ok, pdf, 0.0)
        bs.eta = 1.0
        bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
        bs.sampled_component = mi.UInt32(0)
        return bs, dr.select(ok, weight, 0.0)

    def eval(self, ctx, si, wo, active=True):
        flip = si.wi.z < 0
        view = self._flip(si.wi, flip)
        light = self._flip(wo, flip)
        ok = active & (light.z > 0) & (view.z > 0)
        f = self.evaluator.eval(light, view, self._scale(si), ok)
        return dr.select(ok, f * light.z, 0.0)

    def pdf(self, ctx, si, wo, active=True):
        flip = si.wi.z < 0
        view = self._flip(si.wi, flip)
        light = self._flip(wo, flip)
        ok = active & (light.z > 0) & (view.z > 0)
        return dr.select(ok, self.sampler.pdf(view, light, self._scale(si), ok), 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

    def traverse(self, callback):
        pass

    def to_string(self):
        kind = getattr(self.evaluator, "kind", type(self.evaluator).__name__)
        return f"BRDFBSDF[{kind}" + (", proposal]" if self.proposal is not None else "]")


def _factory(props):
    return BRDFBSDF(props)


mi.register_bsdf(PLUGIN_NAME, _factory)


def make_bsdf(evaluator, alpha_texture=None, proposal=None) -> BRDFBSDF:
    """A ready BSDF object to put in a Mitsuba scene dict (``{"type": "sphere", "bsdf": it}``).

    ``alpha_texture``: optional positive ``(H, W)`` roughness-scale texture; ``proposal``:
    sample/pdf from this object instead of the evaluator (common random numbers).
    """
    return BRDFBSDF(mi.Properties(), evaluator, alpha_texture, proposal)


def register_evaluator(evaluator) -> str:
    """Register an evaluator for use as ``{"type": "brdffit", "evaluator_id": key}`` in scene
    dicts; returns the key (kept until :func:`unregister_evaluator`)."""
    key = f"e{next(_ids)}"
    _EVALUATORS[key] = evaluator
    return key


def unregister_evaluator(key: str) -> None:
    _EVALUATORS.pop(key, None)
