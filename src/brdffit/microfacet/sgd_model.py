"""The model of Bagher, Soler & Holzschuch 2012: one single-lobe Cook-Torrance BRDF per channel.

Eq. 1, per colour channel c, each channel with its own distribution (§5.1)::

    f_c(i, o) = ρd_c/π + ρs_c/π · F_c(i·h) D_c(θh) G1_c(θi) G1_c(θo) / (cos θi cos θo)

with the generalised Schlick Fresnel (Eq. 11) and the separable Smith shadowing of §3.2.
:class:`PerChannelMicrofacetBRDF` holds the three lobes; each lobe is a
:class:`~brdffit.microfacet.model.MicrofacetBRDF` (uncorrelated G, ``specular = 4ρs/π`` so that
its ``ks F D G/(4 cos cos)`` equals the term above). Its distributions are SGD (with G1 from
the Eq. 6 table or the Eq. 9 approximation), Beckmann or GGX; :mod:`brdffit.fit.sgd` fits it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..brdf import (IsotropicBRDF, _as_dirs, cosine_hemisphere_pdf, cosine_hemisphere_sample,
                    sample_arguments)
from ..geometry import slope_to_normal
from ..schema import (ALBEDO_MAX, F1_MAX, SPECULAR_MAX, Choice, Component, ListOf, Nested, Number,
                      Opt, Schema, Text)
from ..serialization import SerializableModel
from .fresnel import GeneralizedSchlickFresnel
from .ggx import GGX
from .model import (MicrofacetBRDF, _lookup_distribution, channel_figures, half_vectors,
                    distribution_from_state, distribution_to_state)
from .sgd import EQ9_C_MAX, SGD, SGDApproxG1

__all__ = ["PerChannelMicrofacetBRDF"]

_CHANNELS = ("r", "g", "b")


class PerChannelMicrofacetBRDF(IsotropicBRDF, SerializableModel):
    """Three single-lobe Cook-Torrance BRDFs, channel c evaluated with lobe c (Bagher §5.1).

    Parameters
    ----------
    channels:
        Three dicts with ``distribution`` (a :class:`SlopeDistribution`), ``rho_d``,
        ``rho_s``, ``F0``, ``F1`` (Eq. 1 and Eq. 11 parameters of that channel).
    g1_approx:
        Optional three dicts ``{"lambda", "c", "k", ...}`` (Eq. 9) of SGD channels.
    g1:
        ``"table"`` (default: G1 from the Eq. 6 table) or ``"approx"`` (Eq. 9).
    """

    fit_kind = "per_channel_microfacet"
    #: fit-file state (:mod:`brdffit.schema`): three channels (distribution arrays under
    #: ``c0.``...), ρd in [0, ALBEDO_MAX], ρs in [0, SPECULAR_MAX], F0 in [0, 1] and
    #: |F1| <= F1_MAX (Eq. 11 with F(π/2) = 1 gives F1 ≪ 0 when ρs → 0); Eq. 9 parameters
    #: λ in (0, 1e6], c in (0, EQ9_C_MAX] (mirror-like MERL fits reach ~5e18), k in (0, 1e3]
    state_schema = Schema(
        {"channels": ListOf(Nested(Schema(
            {"distribution": Component(_lookup_distribution, what="distribution"),
             "rho_d": Number(ge=0, le=ALBEDO_MAX), "rho_s": Number(ge=0, le=SPECULAR_MAX),
             "F0": Number(ge=0, le=1), "F1": Number(ge=-F1_MAX, le=F1_MAX)},
            required=("distribution", "rho_d", "rho_s", "F0", "F1"))),
            min_len=3, max_len=3, item_prefix="c{index}."),
         "g1_approx": Opt(ListOf(Opt(Nested(Schema(
             {"lambda": Number(gt=0, le=1e6), "c": Number(gt=0, le=EQ9_C_MAX),
              "k": Number(gt=0, le=1e3)}, required=("lambda", "c", "k")))),
             min_len=3, max_len=3)),
         "g1": Choice("table", "approx"), "name": Opt(Text()), "source": Opt(Text())},
        required=("channels",))

    def __init__(self, channels, *, g1_approx=None, g1: str = "table", name: str | None = None,
                 source: str | None = None):
        channels = list(channels)
        if len(channels) != 3:
            raise ValueError(f"expected 3 channel lobes, found {len(channels)}")
        if g1 not in ("table", "approx"):
            raise ValueError(f"g1 must be 'table' or 'approx', found {g1!r}")
        self.channels = []
        for ch in channels:
            d = dict(ch)
            for key in ("rho_d", "rho_s", "F0", "F1"):
                d[key] = float(d[key])
                if not np.isfinite(d[key]):
                    raise ValueError(f"channel parameter {key} is not finite: {d[key]!r}")
            if d["rho_d"] < 0 or d["rho_s"] < 0:
                raise ValueError(f"rho_d and rho_s must be >= 0, found {d['rho_d']}, {d['rho_s']}")
            self.channels.append(d)
        self.g1_approx = None if g1_approx is None else [dict(a) if a else None for a in g1_approx]
        self.g1 = g1
        self.name = name or "per-channel-microfacet"
        self.source = source
        self.lobes = [self._lobe(c) for c in range(3)]

    def _lobe(self, c: int) -> MicrofacetBRDF:
        ch = self.channels[c]
        dist = ch["distribution"]
        if self.g1 == "approx" and isinstance(dist, SGD) and self.g1_approx and self.g1_approx[c]:
            a = self.g1_approx[c]
            dist = SGDApproxG1(dist.alpha, dist.p, a["lambda"], a["c"], a["k"])
        return MicrofacetBRDF(dist, GeneralizedSchlickFresnel(ch["F0"], ch["F1"]),
                              diffuse=ch["rho_d"], specular=4.0 * ch["rho_s"] / np.pi,
                              correlated=False, name=f"{self.name}[{_CHANNELS[c]}]")

    # -- evaluation ----------------------------------------------------------------------------
    def eval(self, wi, wo) -> np.ndarray:
        """``f_c`` of Eq. 1 for each channel c (RGB), 0 below the horizon."""
        wi, wo = _as_dirs(wi, wo)
        geometry = half_vectors(wi, wo)
        return np.stack([lobe.eval_channel(c, wi, wo, *geometry)
                         for c, lobe in enumerate(self.lobes)], -1)

    # -- importance sampling (§4.5) ------------------------------------------------------------
    def _proposals(self):
        props = []
        for ch in self.channels:
            d = ch["distribution"]
            props.append(GGX(max(d.alpha, 1e-6)) if isinstance(d, SGD) else d)
        return props

    def _lobe_probabilities(self) -> np.ndarray:
        """[p_diffuse, p_spec_r, p_spec_g, p_spec_b] ∝ [Σρd, s_r, s_g, s_b] with
        ``s_c = ρs_c · max(1, F_c(θd = 0))``, the largest ``ρs F`` of Eq. 11 over θd.

        Deviation from §4.5 (``s_c = ρs_c``): that is the largest ``ρs F`` only when F ≤ 1.
        Fits with ``F1 < 0`` have ``F(0) = F0 − F1 > 1`` (``ρs → 0`` with ``ρs F`` fixed: e.g.
        ρs = 2e-4, F(0) = 423 on a mirror-like MERL channel), and weights ∝ ρs would leave
        their lobe almost never sampled. Any positive weights keep the mixture unbiased."""
        peak = [ch["rho_s"] * max(1.0, ch["F0"] - ch["F1"]) for ch in self.channels]
        w = np.array([sum(ch["rho_d"] for ch in self.channels)] + peak, dtype=np.float64)
        tot = w.sum()
        return w / tot if tot > 0 else np.array([1.0, 0.0, 0.0, 0.0])

    def _spec_pdf(self, prop, wi, wo) -> np.ndarray:
        h = wi + wo
        hn = np.linalg.norm(h, axis=-1)
        h = h / np.where(hn > 0, hn, 1.0)[..., None]
        oh = np.sum(wo * h, -1)
        ok = (hn > 0) & (oh > 0) & (h[..., 2] > 0)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            p = prop.D(h) * h[..., 2] / (4.0 * np.where(ok, oh, 1.0))   # D cos θm |∂ωm/∂ωo|
        return np.where(ok & np.isfinite(p), p, 0.0)

    def pdf(self, wi, wo) -> np.ndarray:
        wi, wo = _as_dirs(wi, wo)
        probs = self._lobe_probabilities()
        p = probs[0] * cosine_hemisphere_pdf(wo)
        for c, prop in enumerate(self._proposals()):
            if probs[c + 1] > 0:
                p = p + probs[c + 1] * self._spec_pdf(prop, wi, wo)
        return np.where((wi[..., 2] > 0) & (wo[..., 2] > 0), p, 0.0)

    def sample(self, wi, u) -> tuple[np.ndarray, np.ndarray]:
        wi, u = sample_arguments(wi, u)
        probs = self._lobe_probabilities()
        cdf = np.concatenate([[0.0], np.cumsum(probs)])
        cdf[-1] = 1.0
        lobe = np.clip(np.searchsorted(cdf, u[..., 0], side="right") - 1, 0, 3)
        lo, width = cdf[lobe], probs[lobe]
        u0 = np.clip((u[..., 0] - lo) / np.where(width > 0, width, 1.0), 0.0, 1.0 - 1e-16)
        u2 = np.stack([u0, u[..., 1]], -1)
        wo = cosine_hemisphere_sample(u2)
        for c, prop in enumerate(self._proposals()):
            sel = lobe == c + 1
            if sel.any():
                m = slope_to_normal(prop.sample(u2[sel]))
                w_sel = wi[sel]
                wo[sel] = 2.0 * np.sum(w_sel * m, -1, keepdims=True) * m - w_sel
        n = np.linalg.norm(wo, axis=-1, keepdims=True)
        wo = wo / np.where(n > 0, n, 1.0)
        return wo, self.pdf(wi, wo)

    # -- parameters / serialisation ------------------------------------------------------------
    def channel_params(self) -> list[dict[str, Any]]:
        """Per channel: distribution kind and parameters, ρd, ρs, F0, F1 (and Eq. 9 G1)."""
        out = []
        for c, ch in enumerate(self.channels):
            d = ch["distribution"]
            dp = {k: float(v) for k, v in d.params().items() if np.isscalar(v)}
            if "alpha" not in dp and "alpha_x" in dp and dp.get("alpha_y") == dp["alpha_x"] \
                    and not dp.get("rho"):
                dp = {"alpha": dp["alpha_x"]}             # isotropic Beckmann / GGX
            row = {"channel": _CHANNELS[c], "distribution": getattr(d, "kind", type(d).__name__),
                   **dp,
                   "rho_d": ch["rho_d"], "rho_s": ch["rho_s"], "F0": ch["F0"], "F1": ch["F1"]}
            if self.g1_approx and self.g1_approx[c]:
                row["g1_approx"] = dict(self.g1_approx[c])
            out.append(row)
        return out

    def params(self) -> dict:
        return {"channels": self.channel_params(), "g1": self.g1}

    def figures(self) -> dict:
        """Channel c's figures from lobe c (:func:`~brdffit.microfacet.model.channel_figures`;
        F0 is ``(4ρs/π)·F0`` of Bagher 2012 Eq. 1, the lobe's ks·F(0))."""
        return channel_figures(self.lobes)

    def to_state(self):
        chans, arrays = [], {}
        for c, ch in enumerate(self.channels):
            meta, arr = distribution_to_state(ch["distribution"])
            chans.append({"distribution": meta, **{k: ch[k] for k in ("rho_d", "rho_s", "F0", "F1")}})
            arrays.update({f"c{c}.{k}": v for k, v in arr.items()})
        return ({"channels": chans, "g1_approx": self.g1_approx, "g1": self.g1,
                 "name": self.name, "source": self.source}, arrays)

    @classmethod
    def from_state(cls, params, arrays):
        chans = []
        for c, ch in enumerate(params["channels"]):
            sub = {k[len(f"c{c}."):]: v for k, v in arrays.items() if k.startswith(f"c{c}.")}
            chans.append({**{k: ch[k] for k in ("rho_d", "rho_s", "F0", "F1")},
                          "distribution": distribution_from_state(ch["distribution"], sub)})
        return cls(chans, g1_approx=params.get("g1_approx"), g1=params.get("g1", "table"),
                   name=params.get("name"), source=params.get("source"))

    def with_g1(self, g1: str) -> "PerChannelMicrofacetBRDF":
        """The same model evaluated with G1 from the table or the Eq. 9 approximation."""
        m = PerChannelMicrofacetBRDF(self.channels, g1_approx=self.g1_approx, g1=g1,
                                     name=self.name, source=self.source)
        m.fit_info, m.fit_options = self.fit_info, self.fit_options
        return m

    def __repr__(self) -> str:
        parts = ", ".join(f"{r['channel']}: {r['distribution']} "
                          + " ".join(f"{k}={r[k]:.4g}" for k in r
                                     if k not in ("channel", "distribution", "g1_approx"))
                          for r in self.channel_params())
        return f"PerChannelMicrofacetBRDF({parts})"
