"""A model-independent sampling proposal for comparisons with common random numbers.

In a comparison, the reference and every model must be rendered with the
*same* light directions and the *same* densities, so that the difference of two images is
estimated with noise proportional to the difference itself (common random numbers, CRN).
With each model's own importance sampling this fails twice: the directions differ between
models (so the reference's Monte Carlo noise does not cancel in ``model − reference``), and
the MIS weights with the environment-map sampling differ too.

:class:`Proposal` is a density over the light direction ``wo`` given the view direction
``wi`` that is fitted once per *material* (to the reference) and then used for every model:

    p(wo | wi) = c · cos θo / π + Σ_k w_k · p_GGX(wo | wi; α_k),     c + Σ w_k = 1,

where ``p_GGX`` reflects ``wi`` about a GGX visible normal (Heitz 2018, JCGT 7(4); density
``G1(wi) D(h) / (4 cos θi)``). Mitsuba combines it with the environment map's own importance
sampling by MIS (power heuristic) exactly as it does for a BSDF's sampler; emitter sampling is
model-independent already. The renderer uses the proposal's ``sample``/``pdf`` and the
*model's* ``eval`` (:class:`.plugin.BRDFBSDF` with ``proposal=``, and the multi-model
integrator of :mod:`.core`), so the sampled directions, the pdfs, the MIS weights and the
number of random numbers drawn per path are identical for every model; only the BRDF values
differ.

Fitting (:func:`fit_proposal`, pure NumPy). The backscattering slice ``f(h, h)`` (θd = 0;
luminance, averaged over 4 azimuths so anisotropic BRDFs work too) on 256 θh nodes is
approximated by ``kd + Σ_j c_j D_GGX(θh; α_j) G2(θh) / (4 cos²θh)`` with non-negative least
squares over a dictionary of 48 α log-spaced in [0.001, 1] (relative weighting, so the tails
count as much as the peak); runs of adjacent non-zero α are merged into one lobe (α the
weighted geometric mean) and the ``max_lobes`` strongest kept. A unit-F0 lobe of this form
has a directional albedo ≈ 1 and the diffuse term ``π kd``, so the mixture weights are the
albedo shares, mixed with a defensive floor: ``c = 0.15 + 0.85 · share_diffuse`` (cosine
sampling covers the whole hemisphere, so the estimator stays unbiased for any model, however
far from the reference). This generalises :func:`.drjit_eval.fit_ggx_proxy` (one lobe, α ≥
0.005) to the multi-lobe, very sharp references of the MERL set.

Everything unbiased does not depend on the fit: a poor proposal only costs variance.
"""

from __future__ import annotations

import numpy as np
from . import drjit_eval as dj

__all__ = ["Proposal", "fit_proposal", "proposal_for", "backscatter_profile"]

_LUM = np.array([0.2126, 0.7152, 0.0722])
_ALPHAS = np.geomspace(0.001, 1.0, 48)


def backscatter_profile(brdf, n: int = 256):
    """``(theta_h, luminance)`` of ``brdf.eval(h, h)`` on ``n`` nodes ``θh = (i/n)² π/2``
    below 85°, averaged over 4 azimuths of ``h`` (exact for isotropic BRDFs)."""
    th = (np.arange(n) / n) ** 2 * (np.pi / 2)
    th = th[th < np.radians(85.0)]
    prof = np.zeros(th.size)
    for phi in (0.0, 0.25 * np.pi, 0.5 * np.pi, 0.75 * np.pi):
        h = np.stack([np.sin(th) * np.cos(phi), np.sin(th) * np.sin(phi), np.cos(th)], -1)
        v = np.nan_to_num(np.asarray(brdf.eval(h, h), dtype=np.float64), nan=0.0, posinf=0.0)
        prof += np.maximum(v.reshape(th.size, -1)[:, :3] @ _LUM if v.ndim > 1 and v.shape[-1] >= 3
                           else v.reshape(th.size), 0.0)
    return th, prof / 4.0


def _ggx_backscatter(th, alpha):
    """Unit-F0 GGX lobe at θd = 0: ``D(θ) G2(θ) / (4 cos²θ)`` (height-correlated Smith)."""
    c2 = np.cos(th) ** 2
    t2 = np.tan(th) ** 2
    d = 1.0 / (np.pi * alpha**2 * c2**2 * (1.0 + t2 / alpha**2) ** 2)
    lam = 0.5 * (np.sqrt(1.0 + alpha**2 * t2) - 1.0)
    return d / (1.0 + 2.0 * lam) / (4.0 * c2)


def fit_proposal(theta_h, profile, max_lobes: int = 2, diffuse_floor: float = 0.15) -> dict:
    """Fit the proposal's mixture to a backscattering luminance slice (see module docstring).

    Returns ``{"alphas": [...], "weights": [...], "cosine_weight": c, "residual": r}`` with
    ``c + Σ weights = 1``. A slice with no energy gives pure cosine sampling.
    """
    from scipy.optimize import nnls

    th = np.asarray(theta_h, dtype=np.float64)
    p = np.maximum(np.nan_to_num(np.asarray(profile, dtype=np.float64)), 0.0)
    if p.size < 4 or not p.max() > 0:
        return {"alphas": [], "weights": [], "cosine_weight": 1.0, "residual": float("nan")}
    w = 1.0 / np.maximum(p, 1e-3 * p.max())
    cols = [np.ones_like(th)] + [_ggx_backscatter(th, a) for a in _ALPHAS]
    A = np.stack(cols, -1)
    scale = np.maximum(np.abs(A * w[:, None]).max(0), 1e-300)
    coef, res = nnls(A * w[:, None] / scale, p * w, maxiter=50 * A.shape[1])
    coef = coef / scale
    kd, c = float(coef[0]), coef[1:]
    # merge runs of adjacent non-zero α into lobes
    lobes = []
    j = 0
    while j < c.size:
        if c[j] <= 0:
            j += 1
            continue
        k = j
        while k + 1 < c.size and c[k + 1] > 0:
            k += 1
        cw = c[j:k + 1]
        lobes.append((float(np.exp(np.sum(cw * np.log(_ALPHAS[j:k + 1])) / cw.sum())),
                      float(cw.sum())))
        j = k + 1
    lobes.sort(key=lambda x: -x[1])
    lobes = lobes[:max_lobes]
    energy = np.array([np.pi * kd] + [e for _, e in lobes])
    share = energy / energy.sum() if energy.sum() > 0 else np.r_[1.0, np.zeros(len(lobes))]
    cw = float(diffuse_floor + (1.0 - diffuse_floor) * share[0]) if lobes else 1.0
    weights = [float((1.0 - diffuse_floor) * s) for s in share[1:]]
    return {"alphas": [a for a, _ in lobes], "weights": weights, "cosine_weight": cw,
            "residual": float(res / max(np.linalg.norm(p * w), 1e-300))}


class Proposal:
    """Mixture of cosine sampling and GGX visible-normal reflection lobes (Dr.Jit).

    Same interface as the evaluators' sampling (:mod:`.drjit_eval`): ``sample(wi, u1, u2,
    alpha_scale, active) -> (wo, pdf)`` and ``pdf(wi, wo, alpha_scale, active)``, library
    convention (``wi`` the conditioning direction — the viewer in the renderer — ``wo``
    the sampled one, both in the local frame). ``u1`` picks the component, ``u2`` the
    direction, so every call consumes exactly one 1D and one 2D sample. ``alpha_scale`` is
    ignored (the proposal does not follow a roughness texture; unbiased all the same).
    """

    kind = "proposal"

    def __init__(self, alphas=(), weights=(), cosine_weight: float = 1.0, info: dict | None = None):
        alphas = [float(a) for a in alphas]
        weights = [float(w) for w in weights]
        if len(alphas) != len(weights) or any(a <= 0 for a in alphas) or any(w < 0 for w in weights):
            raise ValueError(f"expected positive alphas and non-negative weights of the same "
                             f"length, found {alphas} and {weights}")
        total = cosine_weight + sum(weights)
        if not cosine_weight > 0 or not total > 0:
            raise ValueError(f"expected a positive cosine weight, found {cosine_weight}")
        self.alphas = alphas
        self.weights = [w / total for w in weights]
        self.cosine_weight = float(cosine_weight) / total
        self.info = dict(info or {})

    @classmethod
    def from_brdf(cls, brdf, max_lobes: int = 2, diffuse_floor: float = 0.15) -> "Proposal":
        """Fit to a BRDF's backscattering slice (:func:`fit_proposal`)."""
        fit = fit_proposal(*backscatter_profile(brdf), max_lobes=max_lobes,
                           diffuse_floor=diffuse_floor)
        return cls(fit["alphas"], fit["weights"], fit["cosine_weight"],
                   info={"residual": fit["residual"], "fitted_to": getattr(brdf, "name", None)})

    def describe(self) -> str:
        lobes = ", ".join(f"GGX α={a:.4g} w={w:.3f}" for a, w in zip(self.alphas, self.weights))
        return f"proposal(cosine w={self.cosine_weight:.3f}" + (f"; {lobes})" if lobes else ")")

    def as_dict(self) -> dict:
        return {"cosine_weight": self.cosine_weight, "alphas": list(self.alphas),
                "weights": list(self.weights), **self.info}

    # -- Dr.Jit ----------------------------------------------------------------------------
    def pdf(self, wi, wo, alpha_scale=1.0, active=True):
        mi, dr = dj.mi, dj.dr
        up = (wi.z > 0) & (wo.z > 0)
        cosine_weight, alphas, weights = dj.kernel_params(self, "cosine_weight",
                                                          "alphas", "weights")
        p = cosine_weight * dr.maximum(wo.z, 0.0) * (1.0 / np.pi)
        if alphas:
            h = dr.normalize(wi + wo)
            cos_i = dr.maximum(wi.z, 1e-7)
            for a, w in zip(alphas, weights):
                g1 = 1.0 / (1.0 + dj.ggx_lambda(wi, a, a))
                p += w * g1 * dj.ggx_D(h, a, a) / (4.0 * cos_i)
        return dr.select(active & up, p, mi.Float(0.0))

    def sample(self, wi, u1, u2, alpha_scale=1.0, active=True):
        mi, dr = dj.mi, dj.dr
        wo = dj.cosine_sample(u2)
        edge, alphas, weights = dj.kernel_params(self, "cosine_weight", "alphas",
                                                 "weights")
        for a, w in zip(alphas, weights):
            m = dj.ggx_vndf_sample(wi, u2, a, a)
            r = 2.0 * dr.dot(wi, m) * m - wi
            wo = dr.select(u1 >= edge, r, wo)
            edge = edge + w   # not +=: that would change the cached opaque value in place
        return wo, self.pdf(wi, wo, alpha_scale, active)


_CACHE: dict = {}


def proposal_for(brdf, **kw) -> Proposal:
    """:meth:`Proposal.from_brdf`, cached on the BRDF object (held weakly when possible), so
    that all renders of one comparison share one proposal."""
    import weakref

    key = (id(brdf), tuple(sorted(kw.items())))
    hit = _CACHE.get(key)
    if hit is not None and hit[0]() is brdf:
        return hit[1]
    prop = Proposal.from_brdf(brdf, **kw)
    try:
        _CACHE[key] = (weakref.ref(brdf), prop)
    except TypeError:
        pass
    if len(_CACHE) > 16:
        for k in list(_CACHE)[:-16]:
            _CACHE.pop(k, None)
    return prop
