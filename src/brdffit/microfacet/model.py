"""Microfacet BRDFs (Dupuy et al. 2015 Eq. 1), lobe sums, and the component registry.

:class:`MicrofacetBRDF`
    ``f_r = ρd/π + ks · F(θd) D(h) G(i, o) / (4 cos θi cos θo)`` — Dupuy 2015 **Eq. 1** with the
    height-correlated Smith G of **Eq. 2** (``correlated=False`` gives the uncorrelated
    ``G1(i) G1(o)``), an optional Lambertian RGB albedo ρd and an optional RGB specular
    scale ``ks`` (Bagher 2012's ρs; 1 by default). Constructed from an isotropic distribution
    it is an :class:`~brdffit.brdf.IsotropicBRDF` (``eval_hd`` available).

:class:`SumBRDF`
    A sum of BRDFs (e.g. two GGX lobes), sampled as a mixture.

Sampling (``MicrofacetBRDF.sample``)
    Visible normals (Heitz & d'Eon 2014) when the distribution implements
    ``sample_visible``, else normals from slope sampling (Walter 2007 / Dupuy App. A), then
    mirror reflection; mixed with cosine-weighted sampling when there is a diffuse term, the
    lobe probability being ``a_s / (a_s + a_d)`` with the albedo estimates
    ``a_s = mean_rgb(ks · F(cos θi))`` and ``a_d = mean_rgb(ρd)``. Reflected directions
    below the horizon are returned with pdf 0 (invalid sample); ``pdf`` is 0 for ``wo``
    below the horizon, so ``∫ pdf dω`` equals the probability of a valid sample.

Serialisation and the component registry
    ``MicrofacetBRDF`` is a :class:`~brdffit.serialization.SerializableModel` of kind
    ``"microfacet"`` (``SumBRDF``: ``"microfacet_sum"``). Its distribution and Fresnel are
    stored through two small registries mapping a string ``kind`` to a class::

        register_distribution("sgd", SGD)          # in the module defining SGD
        register_fresnel("my_fresnel", MyFresnel)

    A registered component class is saved as ``{"kind": kind, "params": ...}`` plus named
    arrays. By default ``params = obj.params()`` and the object is rebuilt with
    ``cls(**params)``; a class with tables implements ``to_state() -> (params, arrays)`` and
    ``classmethod from_state(params, arrays)`` instead (see :class:`TabulatedFresnel`).
    Built in: distributions ``beckmann``, ``ggx``, ``scaled``; Fresnels ``schlick``,
    ``generalized_schlick``, ``dielectric``, ``conductor``, ``tabulated``. A class with its
    own ``kind`` class attribute is registered automatically the first time it is saved.
    When a file names an unregistered kind, ``brdffit.microfacet.<kind>`` and the modules in
    ``_COMPONENT_MODULES`` (``sgd``, ``tabulated``) are imported so they can register
    themselves (this is how ``sgd`` and the tabulated distributions load lazily).

State schemas (:mod:`brdffit.schema`)
    Every registered component class declares ``state_schema`` (its ``params`` and arrays,
    with physical ranges); a file's ``distribution``/``fresnel`` entry is checked against the
    schema of the class its ``kind`` names before the component is built. A class with its
    own ``to_state`` and no schema gets only the generic checks (finite numeric arrays).
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

import numpy as np

from ..brdf import (BRDF, IsotropicBRDF, _as_dirs, cosine_hemisphere_pdf, cosine_hemisphere_sample,
                    eval_hd_through_directions, sample_arguments)
from ..geometry import slope_to_normal
from ..schema import (ALBEDO_MAX, ALPHA_MAX, ALPHA_MIN, SPECULAR_MAX, RGB, Bool, Component,
                      ListOf, Number, Opt, Schema, StateError, Text)
from ..serialization import SerializableModel, resolve_kind
from .base import Fresnel, ScaledDistribution, SlopeDistribution
from .beckmann import Beckmann
from .fresnel import (ConductorFresnel, DielectricFresnel, GeneralizedSchlickFresnel,
                      SchlickFresnel, TabulatedFresnel)
from .ggx import GGX

__all__ = ["MicrofacetBRDF", "SumBRDF", "register_distribution", "register_fresnel",
           "distribution_to_state", "distribution_from_state", "fresnel_to_state",
           "fresnel_from_state", "half_vectors"]

# ----------------------------------------------------------------------------------------
# component registry
# ----------------------------------------------------------------------------------------
_DISTRIBUTIONS: dict[str, type] = {}
_FRESNELS: dict[str, type] = {}
#: sibling modules imported when a fit file names a kind that is not registered yet
_COMPONENT_MODULES = ("sgd", "tabulated")


def register_distribution(kind: str, cls: type) -> type:
    """Register a :class:`SlopeDistribution` subclass under ``kind`` (for fit files)."""
    if not (isinstance(cls, type) and issubclass(cls, SlopeDistribution)):
        raise TypeError(f"register_distribution: {cls!r} is not a SlopeDistribution subclass")
    _DISTRIBUTIONS[str(kind)] = cls
    return cls


def register_fresnel(kind: str, cls: type) -> type:
    """Register a :class:`Fresnel` subclass under ``kind`` (for fit files)."""
    if not (isinstance(cls, type) and issubclass(cls, Fresnel)):
        raise TypeError(f"register_fresnel: {cls!r} is not a Fresnel subclass")
    _FRESNELS[str(kind)] = cls
    return cls


for _k, _c in (("beckmann", Beckmann), ("ggx", GGX), ("scaled", ScaledDistribution)):
    register_distribution(_k, _c)
for _c in (SchlickFresnel, GeneralizedSchlickFresnel, DielectricFresnel, ConductorFresnel,
           TabulatedFresnel):
    register_fresnel(_c.kind, _c)


def _base_of(what: str) -> type:
    return SlopeDistribution if what == "distribution" else Fresnel


def _kind_of(obj, registry: dict[str, type], what: str) -> str:
    """The registered kind of ``obj``'s class; a class with its own ``kind`` attribute is
    registered on first use."""
    for kind, cls in registry.items():
        if type(obj) is cls:
            return kind
    kind = type(obj).__dict__.get("kind")
    if isinstance(kind, str) and kind:
        if kind in registry and registry[kind] is not type(obj):
            # the module of the registered class may define the same name after a reload
            if registry[kind].__qualname__ != type(obj).__qualname__:
                raise TypeError(f"{what} kind {kind!r} is already registered for "
                                f"{registry[kind].__name__}, not {type(obj).__name__}")
        registry[kind] = type(obj)
        return kind
    raise TypeError(f"{what} class {type(obj).__name__} is not registered; call "
                    f"register_{what}(kind, {type(obj).__name__}) first")


def _lookup(kind: str, registry: dict[str, type], what: str) -> type:
    """Class registered under ``kind``; unknown kinds are looked for in the module
    ``brdffit.microfacet.<kind>`` (a class there whose ``kind`` attribute equals ``kind``)."""
    if kind not in registry and isinstance(kind, str) and kind.isidentifier():
        try:
            mod = import_module(f".{kind}", __package__)
        except ImportError as exc:
            if kind == "sgd":
                raise ValueError(f"distribution kind 'sgd' needs brdffit.microfacet.sgd, which "
                                 f"could not be imported ({exc})") from exc
            mod = None
        if mod is not None:
            for obj in vars(mod).values():
                if (isinstance(obj, type) and issubclass(obj, _base_of(what))
                        and obj.__dict__.get("kind") == kind):
                    registry.setdefault(kind, obj)
    if kind not in registry:
        for name in _COMPONENT_MODULES:      # modules that register kinds on import
            try:
                import_module(f".{name}", __package__)
            except ImportError:
                pass
    if kind not in registry:
        raise ValueError(f"unknown {what} kind {kind!r}; registered: {sorted(registry)}")
    return registry[kind]


def _component_to_state(obj, registry, what) -> tuple[dict, dict[str, np.ndarray]]:
    kind = _kind_of(obj, registry, what)
    if hasattr(obj, "to_state"):
        params, arrays = obj.to_state()
    else:
        params, arrays = obj.params(), {}
    return {"kind": kind, "params": params}, dict(arrays)


def _component_from_state(meta: dict, arrays: dict[str, np.ndarray], registry, what):
    if not isinstance(meta, dict) or "kind" not in meta:
        raise ValueError(f"{what} entry must be a dict with a 'kind', found {meta!r}")
    cls = _lookup(meta["kind"], registry, what)
    params = meta.get("params") or {}
    if hasattr(cls, "from_state"):
        return cls.from_state(params, arrays)
    return cls(**params)


def distribution_to_state(dist) -> tuple[dict, dict[str, np.ndarray]]:
    """``({"kind", "params"}, arrays)`` of a registered distribution."""
    return _component_to_state(dist, _DISTRIBUTIONS, "distribution")


def distribution_from_state(meta: dict, arrays: dict[str, np.ndarray] | None = None):
    """Rebuild a distribution saved by :func:`distribution_to_state`."""
    return _component_from_state(meta, arrays or {}, _DISTRIBUTIONS, "distribution")


def fresnel_to_state(fresnel) -> tuple[dict, dict[str, np.ndarray]]:
    """``({"kind", "params"}, arrays)`` of a registered Fresnel."""
    return _component_to_state(fresnel, _FRESNELS, "fresnel")


def fresnel_from_state(meta: dict, arrays: dict[str, np.ndarray] | None = None):
    """Rebuild a Fresnel saved by :func:`fresnel_to_state`."""
    return _component_from_state(meta, arrays or {}, _FRESNELS, "fresnel")


def _scaled_to_state(self):
    meta, arrays = distribution_to_state(self.base)
    return ({"ax": self.ax, "ay": self.ay, "base": meta},
            {f"base.{k}": v for k, v in arrays.items()})


def _scaled_from_state(cls, params, arrays):
    sub = {k[5:]: v for k, v in arrays.items() if k.startswith("base.")}
    return cls(distribution_from_state(params["base"], sub), params["ax"], params["ay"])


def _lookup_distribution(kind: str) -> type:
    return _lookup(kind, _DISTRIBUTIONS, "distribution")


def _lookup_fresnel(kind: str) -> type:
    return _lookup(kind, _FRESNELS, "fresnel")


ScaledDistribution.to_state = _scaled_to_state
ScaledDistribution.from_state = classmethod(_scaled_from_state)
#: roughness scales of Eq. 9 (> 0, <= ALPHA_MAX) and the base distribution (any kind)
ScaledDistribution.state_schema = Schema(
    {"ax": Number(ge=ALPHA_MIN, le=ALPHA_MAX), "ay": Number(ge=ALPHA_MIN, le=ALPHA_MAX),
     "base": Component(_lookup_distribution, prefix="base.", what="distribution")},
    required=("ax", "ay", "base"))


def _supports_vndf(dist) -> bool:
    """True when ``dist`` implements visible-normal sampling (also through scaling)."""
    if isinstance(dist, ScaledDistribution):
        return _supports_vndf(dist.base)
    return type(dist).sample_visible is not SlopeDistribution.sample_visible


def _prefixed(arrays: dict[str, np.ndarray], prefix: str) -> dict[str, np.ndarray]:
    return {f"{prefix}{k}": v for k, v in arrays.items()}


def _unprefixed(arrays: dict[str, np.ndarray], prefix: str) -> dict[str, np.ndarray]:
    n = len(prefix)
    return {k[n:]: v for k, v in arrays.items() if k.startswith(prefix)}


def _rgb_or_none(name, value):
    if value is None:
        return None
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        arr = np.full(3, float(arr))
    if arr.shape != (3,) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ValueError(f"{name} must be a non-negative scalar or RGB triple, got {value!r}")
    return arr


# ----------------------------------------------------------------------------------------
# MicrofacetBRDF
# ----------------------------------------------------------------------------------------
def _rgb_list(v) -> list[float]:
    return [float(x) for x in np.broadcast_to(np.asarray(v, dtype=np.float64), (3,))]


def channel_figures(lobes) -> dict[str, Any]:
    """The figures of a per-channel model whose channel c is channel c of ``lobes[c]``: one
    isotropic α per channel (``alpha_rgb``), ``f0`` and ``rho_d`` from each lobe's channel."""
    rows = [lobe.figures() for lobe in lobes]
    out: dict[str, Any] = {"f0": [r["f0"][c] for c, r in enumerate(rows)],
                           "rho_d": [r["rho_d"][c] for c, r in enumerate(rows)]}
    if all(r.get("alpha") for r in rows):
        out["alpha_rgb"] = [float(r["alpha"][0]) for r in rows]
        kinds = {r.get("alpha_kind") for r in rows}
        out["alpha_kind"] = kinds.pop() if len(kinds) == 1 else "mixed"
    return out


def half_vectors(wi, wo) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(h, cos θd = wi·h, both above the horizon)`` of unit direction pairs ``(..., 3)``:
    the normalised half vector of Dupuy 2015 Eq. 1 (``(0, 0, 0)`` where ``wi = −wo``)."""
    ok = (wi[..., 2] > 0) & (wo[..., 2] > 0)
    h = wi + wo
    hn = np.sqrt(np.einsum("...k,...k->...", h, h))
    h /= np.where(hn > 0, hn, 1.0)[..., None]
    return h, np.einsum("...k,...k->...", wi, h), ok


class MicrofacetBRDF(BRDF, SerializableModel):
    """Microfacet BRDF of Dupuy 2015 Eq. 1 with an optional Lambertian term.

    Parameters
    ----------
    distribution:
        A :class:`SlopeDistribution` (GGX, Beckmann, SGD, tabulated...).
    fresnel:
        A :class:`Fresnel`, or ``None`` for ``F = 1`` (white).
    diffuse:
        Lambertian RGB albedo ρd (scalar or triple), term ``ρd/π``; ``None`` for none.
    specular:
        RGB scale ``ks`` of the microfacet term (default 1).
    correlated:
        Height-correlated Smith G (Dupuy Eq. 2, default) or uncorrelated ``G1 G1``.
    name, source:
        Metadata.
    """

    fit_kind = "microfacet"
    #: ``distribution`` and ``fresnel`` follow the schema of their kind (arrays under
    #: ``distribution.`` / ``fresnel.``); ρd in [0, ALBEDO_MAX], ks in [0, SPECULAR_MAX]
    state_schema = Schema(
        {"distribution": Component(_lookup_distribution, prefix="distribution.",
                                   what="distribution"),
         "fresnel": Opt(Component(_lookup_fresnel, prefix="fresnel.", what="fresnel")),
         "diffuse": Opt(RGB(ge=0, le=ALBEDO_MAX)), "specular": Opt(RGB(ge=0, le=SPECULAR_MAX)),
         "correlated": Bool(), "name": Opt(Text()), "source": Opt(Text())},
        required=("distribution",))

    def __new__(cls, distribution=None, *args, **kwargs):
        if cls is MicrofacetBRDF and getattr(distribution, "isotropic", False):
            cls = IsotropicMicrofacetBRDF
        return super().__new__(cls)

    def __init__(self, distribution: SlopeDistribution, fresnel: Fresnel | None = None,
                 diffuse=None, *, specular=None, correlated: bool = True,
                 name: str | None = None, source: str | None = None):
        if not isinstance(distribution, SlopeDistribution):
            raise TypeError(f"distribution must be a SlopeDistribution, got "
                            f"{type(distribution).__name__}")
        if fresnel is not None and not isinstance(fresnel, Fresnel):
            raise TypeError(f"fresnel must be a Fresnel or None, got {type(fresnel).__name__}")
        self.distribution = distribution
        self.fresnel = fresnel
        self.diffuse = _rgb_or_none("diffuse", diffuse)
        self.specular = _rgb_or_none("specular", specular)
        self.correlated = bool(correlated)
        self.isotropic = bool(distribution.isotropic)
        self.name = name or f"{type(distribution).__name__.lower()}-microfacet"
        self.source = source
        self._has_vndf = _supports_vndf(distribution)

    # -- evaluation --------------------------------------------------------------------------
    def _fresnel(self, cos_d, channel: int | None = None) -> np.ndarray:
        """``F(cos θd)`` times the specular scale: RGB, or only ``channel``."""
        rgb = channel is None
        if self.fresnel is None:
            F = np.ones(np.shape(cos_d) + ((3,) if rgb else ()))
        else:
            F = self.fresnel.eval(cos_d) if rgb else self.fresnel.eval_channel(channel, cos_d)
        if self.specular is not None:
            F = F * (self.specular if rgb else self.specular[channel])
        return F

    def eval(self, wi, wo) -> np.ndarray:
        """``f_r(wi, wo)`` (Dupuy 2015 Eq. 1 + ρd/π), RGB, 0 below the horizon."""
        wi, wo = _as_dirs(wi, wo)
        h, cos_d, ok = half_vectors(wi, wo)
        # a new array, not *=: user Fresnels may return read-only arrays
        f = self._fresnel(cos_d) * self._specular(wi, wo, h, cos_d, ok)[..., None]
        if self.diffuse is not None:
            f += np.where(ok, 1.0, 0.0)[..., None] * (self.diffuse / np.pi)
        return f

    def eval_channel(self, c: int, wi, wo, h, cos_d, ok) -> np.ndarray:
        """Channel ``c`` of :meth:`eval` (the same numbers) at unit directions ``wi``, ``wo``
        with their :func:`half_vectors` ``h, cos_d, ok``: for models made of one lobe per
        channel, which share the half vectors."""
        f = self._fresnel(cos_d, c) * self._specular(wi, wo, h, cos_d, ok)
        if self.diffuse is not None:
            f += np.where(ok, 1.0, 0.0) * (self.diffuse[c] / np.pi)
        return f

    def _specular(self, wi, wo, h, cos_d, ok) -> np.ndarray:
        """``D(h) G / (4 cos θi cos θo)`` (Dupuy 2015 Eq. 1 without F), 0 where a direction
        is below the horizon or ``cos θd ≤ 0``."""
        ci, co = wi[..., 2], wo[..., 2]
        dist = self.distribution
        D = dist.D(h)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            if self.correlated:
                lam_i, lam_o = dist.Lambda(wi), dist.Lambda(wo)
                G = 1.0 / (1.0 + lam_i + lam_o)                       # Dupuy Eq. 2
            else:
                G = dist.G1(wi) * dist.G1(wo)
            spec = D * G / (4.0 * np.where(ok, ci * co, 1.0))
        return np.where(ok & (cos_d > 0), spec, 0.0)

    #: value at Rusinkiewicz coordinates (φh = 0 for anisotropic distributions)
    eval_hd = eval_hd_through_directions

    # -- sampling ----------------------------------------------------------------------------
    def lobe_weights(self, wi) -> tuple[np.ndarray, np.ndarray]:
        """Albedo estimates ``(a_spec, a_diff)`` at ``wi`` used to pick a lobe (and by SumBRDF)."""
        ci = np.clip(np.asarray(wi, dtype=np.float64)[..., 2], 0.0, 1.0)
        a_s = np.mean(self._fresnel(ci), axis=-1)
        a_d = np.full(ci.shape, float(np.mean(self.diffuse)) if self.diffuse is not None else 0.0)
        return np.maximum(a_s, 0.0), a_d

    def _p_spec(self, wi) -> np.ndarray:
        a_s, a_d = self.lobe_weights(wi)
        tot = a_s + a_d
        return np.where(tot > 0, a_s / np.where(tot > 0, tot, 1.0), 1.0)

    def _pdf_spec(self, wi, wo) -> np.ndarray:
        h = wi + wo
        hn = np.sqrt(np.sum(h * h, axis=-1))
        h = h / np.where(hn > 0, hn, 1.0)[..., None]
        ih = np.sum(wi * h, axis=-1)
        ok = (wi[..., 2] > 0) & (wo[..., 2] > 0) & (hn > 0) & (ih > 0) & (h[..., 2] > 0)
        D = self.distribution.D(h)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            if self._has_vndf:   # <i,h> D(h) / σ_v(i) / (4 <i,h>), σ_v = cos θi / G1(i)
                sv = self.distribution.sigma_visible(wi)
                p = D / (4.0 * np.where(ok & (sv > 0), sv, 1.0))
            else:                # D(h) cos θh / (4 <o,h>)
                p = D * h[..., 2] / (4.0 * np.where(ok, ih, 1.0))
        return np.where(ok, p, 0.0)

    def pdf(self, wi, wo) -> np.ndarray:
        """Solid-angle density of :meth:`sample` (0 for ``wo`` below the horizon)."""
        wi, wo = _as_dirs(wi, wo)
        p = self._pdf_spec(wi, wo)
        if self.diffuse is not None:
            ps = self._p_spec(wi)
            p = ps * p + (1.0 - ps) * cosine_hemisphere_pdf(wo)
        return np.where((wi[..., 2] > 0) & (wo[..., 2] > 0), p, 0.0)

    def _sample_spec(self, wi, u) -> np.ndarray:
        if self._has_vndf:
            m = self.distribution.sample_visible(wi, u)
        else:
            m = slope_to_normal(self.distribution.sample(u))
        im = np.sum(wi * m, axis=-1, keepdims=True)
        return 2.0 * im * m - wi

    def sample(self, wi, u) -> tuple[np.ndarray, np.ndarray]:
        """Draw ``wo`` for ``wi`` from ``u`` ``(..., 2)``; returns ``(wo, pdf)``."""
        wi, u = sample_arguments(wi, u)
        wi_up = np.where((wi[..., 2] > 0)[..., None], wi, [0.0, 0.0, 1.0])
        if self.diffuse is None:
            wo = self._sample_spec(wi_up, u)
        else:
            ps = self._p_spec(wi_up)
            choose = u[..., 0] < ps
            u0 = np.where(choose, u[..., 0] / np.where(ps > 0, ps, 1.0),
                          (u[..., 0] - ps) / np.where(ps < 1, 1.0 - ps, 1.0))
            u2 = np.stack([np.clip(u0, 0.0, 1.0 - 1e-16), u[..., 1]], -1)
            wo = np.where(choose[..., None], self._sample_spec(wi_up, u2),
                          cosine_hemisphere_sample(u2))
        n = np.linalg.norm(wo, axis=-1, keepdims=True)
        wo = wo / np.where(n > 0, n, 1.0)
        return wo, self.pdf(wi, wo)

    # -- metadata / serialisation ------------------------------------------------------------
    def figures(self) -> dict[str, Any]:
        """α of the distribution (:meth:`SlopeDistribution.figures`), ``f0`` = ks·F(θd = 0)
        and ``rho_d`` per channel (0 without a diffuse term)."""
        out: dict[str, Any] = dict(self.distribution.figures())
        f0 = (np.ones(3) if self.fresnel is None
              else np.asarray(self.fresnel.eval(np.array(1.0)), dtype=np.float64))
        ks = 1.0 if self.specular is None else np.asarray(self.specular, dtype=np.float64)
        out["f0"] = _rgb_list(f0 * ks)
        out["rho_d"] = _rgb_list(0.0 if self.diffuse is None else self.diffuse)
        return out

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        d.update(distribution=repr(self.distribution), fresnel=repr(self.fresnel),
                 diffuse=None if self.diffuse is None else self.diffuse.tolist(),
                 correlated=self.correlated)
        return d

    def to_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        dmeta, darr = distribution_to_state(self.distribution)
        arrays = _prefixed(darr, "distribution.")
        if self.fresnel is not None:
            fmeta, farr = fresnel_to_state(self.fresnel)
            arrays.update(_prefixed(farr, "fresnel."))
        else:
            fmeta = None
        params = {"distribution": dmeta, "fresnel": fmeta,
                  "diffuse": None if self.diffuse is None else self.diffuse.tolist(),
                  "specular": None if self.specular is None else self.specular.tolist(),
                  "correlated": self.correlated, "name": self.name, "source": self.source}
        return params, arrays

    @classmethod
    def from_state(cls, params: dict[str, Any], arrays: dict[str, np.ndarray]):
        dist = distribution_from_state(params["distribution"],
                                       _unprefixed(arrays, "distribution."))
        fmeta = params.get("fresnel")
        fres = None if fmeta is None else fresnel_from_state(fmeta, _unprefixed(arrays, "fresnel."))
        return MicrofacetBRDF(dist, fres, params.get("diffuse"), specular=params.get("specular"),
                              correlated=params.get("correlated", True), name=params.get("name"),
                              source=params.get("source"))

    def __repr__(self) -> str:
        extra = "" if self.diffuse is None else f", diffuse={np.round(self.diffuse, 4).tolist()}"
        return f"MicrofacetBRDF({self.distribution!r}, {self.fresnel!r}{extra})"


class IsotropicMicrofacetBRDF(MicrofacetBRDF, IsotropicBRDF):
    """A :class:`MicrofacetBRDF` with an isotropic distribution (also an IsotropicBRDF).

    Created automatically by ``MicrofacetBRDF(...)``; not meant to be instantiated directly.
    """

    eval = MicrofacetBRDF.eval
    eval_hd = MicrofacetBRDF.eval_hd


# ----------------------------------------------------------------------------------------
# Sum of lobes
# ----------------------------------------------------------------------------------------
def _brdf_weight(b, wi) -> np.ndarray:
    if hasattr(b, "lobe_weights"):
        a_s, a_d = b.lobe_weights(wi)
        return a_s + a_d
    return np.ones(np.shape(wi)[:-1])


#: most lobes a saved sum may hold in all (nested sums counted through)
MAX_SUM_LOBES = 64


def _check_lobe_count(params, arrays, path, field) -> None:
    """A saved sum holds at most :data:`MAX_SUM_LOBES` lobes, nested sums included (each
    level allows 16; without a total, a 4 MB header could nest thousands)."""
    n, stack = 0, [params]
    while stack:
        for comp in stack.pop().get("components", ()):
            if comp.get("model") == "microfacet_sum" and isinstance(comp.get("params"), dict):
                stack.append(comp["params"])
            else:
                n += 1
    if n > MAX_SUM_LOBES:
        raise StateError(f"{path}.components", f"expected at most {MAX_SUM_LOBES} lobes in all, "
                                               f"found {n}")


class SumBRDF(BRDF, SerializableModel):
    """``f_r = Σ_k f_k`` of BRDFs (e.g. two microfacet lobes), sampled as a mixture.

    Component ``k`` is chosen with probability ∝ its albedo estimate at ``wi``
    (:meth:`MicrofacetBRDF.lobe_weights`, 1 for other BRDFs); the pdf is the mixture pdf.
    Serialisable (kind ``"microfacet_sum"``) when every component is a SerializableModel.
    """

    fit_kind = "microfacet_sum"
    #: 1 to 16 lobes, each ``{"model": KIND, "params": ...}`` with the schema of that kind
    #: and its arrays under ``c0.``, ``c1.``...
    state_schema = Schema(
        {"components": ListOf(Component(resolve_kind, kind_key="model", what="model"),
                              min_len=1, max_len=16, item_prefix="c{index}."),
         "name": Opt(Text()), "source": Opt(Text())},
        required=("components",), checks=(_check_lobe_count,))

    def __new__(cls, components=None, *args, **kwargs):
        if cls is SumBRDF and components is not None and all(
                getattr(c, "isotropic", False) for c in components):
            cls = IsotropicSumBRDF
        return super().__new__(cls)

    def __init__(self, components, *, name: str | None = None, source: str | None = None):
        components = list(components)
        if not components or not all(isinstance(c, BRDF) for c in components):
            raise TypeError("SumBRDF needs a non-empty list of BRDF objects")
        self.components = components
        self.isotropic = all(c.isotropic for c in components)
        self.name = name or "+".join(c.name for c in components)
        self.source = source

    def eval(self, wi, wo) -> np.ndarray:
        wi, wo = _as_dirs(wi, wo)
        return sum(c.eval(wi, wo) for c in self.components)

    #: value at Rusinkiewicz coordinates (φh = 0 for anisotropic distributions)
    eval_hd = eval_hd_through_directions

    def lobe_weights(self, wi) -> tuple[np.ndarray, np.ndarray]:
        tot = [c.lobe_weights(wi) if hasattr(c, "lobe_weights") else
               (np.ones(np.shape(wi)[:-1]), np.zeros(np.shape(wi)[:-1]))
               for c in self.components]
        return sum(t[0] for t in tot), sum(t[1] for t in tot)

    def _probs(self, wi) -> np.ndarray:
        w = np.stack([_brdf_weight(c, wi) for c in self.components], -1)
        tot = w.sum(-1, keepdims=True)
        n = len(self.components)
        return np.where(tot > 0, w / np.where(tot > 0, tot, 1.0), 1.0 / n)

    def pdf(self, wi, wo) -> np.ndarray:
        wi, wo = _as_dirs(wi, wo)
        p = self._probs(wi)
        return sum(p[..., k] * c.pdf(wi, wo) for k, c in enumerate(self.components))

    def sample(self, wi, u) -> tuple[np.ndarray, np.ndarray]:
        wi, u = sample_arguments(wi, u)
        p = self._probs(wi)
        cdf = np.cumsum(p, -1)
        k = np.minimum(np.sum(u[..., :1] >= cdf, -1), len(self.components) - 1)
        lo = np.take_along_axis(np.concatenate([np.zeros(wi.shape[:-1] + (1,)), cdf], -1),
                                k[..., None], -1)[..., 0]
        pk = np.take_along_axis(p, k[..., None], -1)[..., 0]
        u0 = np.clip((u[..., 0] - lo) / np.where(pk > 0, pk, 1.0), 0.0, 1.0 - 1e-16)
        u2 = np.stack([u0, u[..., 1]], -1)
        wo = np.zeros(wi.shape)
        for j, c in enumerate(self.components):      # loop over lobes, not samples
            sel = k == j
            if np.any(sel):
                wo[sel] = c.sample(wi[sel], u2[sel])[0]
        return wo, self.pdf(wi, wo)

    def to_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        comps, arrays = [], {}
        for k, c in enumerate(self.components):
            if not isinstance(c, SerializableModel) or not c.fit_kind:
                raise TypeError(f"SumBRDF component {type(c).__name__} is not serialisable")
            params, arr = c.to_state()
            comps.append({"model": c.fit_kind, "params": params})
            arrays.update(_prefixed(arr, f"c{k}."))
        return {"components": comps, "name": self.name, "source": self.source}, arrays

    @classmethod
    def from_state(cls, params: dict[str, Any], arrays: dict[str, np.ndarray]):
        comps = []
        for k, meta in enumerate(params["components"]):
            try:
                cls_k = resolve_kind(meta["model"])
            except KeyError:
                raise ValueError(f"unknown component model {meta['model']!r}") from None
            comps.append(cls_k.from_state(meta["params"], _unprefixed(arrays, f"c{k}.")))
        return SumBRDF(comps, name=params.get("name"), source=params.get("source"))

    def __repr__(self) -> str:
        return f"SumBRDF({self.components!r})"


class IsotropicSumBRDF(SumBRDF, IsotropicBRDF):
    """A :class:`SumBRDF` of isotropic components (created automatically)."""

    eval = SumBRDF.eval
    eval_hd = SumBRDF.eval_hd
