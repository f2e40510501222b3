"""Non-parametric factor BRDF models of Bagher, Snyder & Nowrouzezahrai 2016 (ACM TOG).

* :class:`NPFMicrofacetBRDF` – Eq. 3, per colour channel
  ``ρ = ρd + ρs D(θh) F(θd) G(θi) G(θo) / (cos θi cos θo)`` with 90-sample tables D (uniform
  in ``θ'h = sqrt(θh)``, Eq. 6, i.e. the MERL θh grid), F (uniform in θd, the MERL θd grid)
  and G (uniform in θ, ``θ_k = k°``, k = 0…89, linearly interpolated in θi and θo, §4.3).
  Size: ``3 · (3·90 + 2) · 4 = 3,264`` bytes of float32 (§3): tables ``D, F, G`` of shape
  (90, 3) and ``rho`` = (ρd, ρs) of shape (2, 3).
* :class:`NPFNaiveBRDF` – Eq. 4, ``ρ = ρd + ρs D(θh) F(θd) H(φd)``, H with 180 samples over
  φd ∈ [0, π) (periodic by reciprocity): 4,344 bytes.
* :class:`NPFBivariateBRDF` – Eq. 5, ``ρ = B(θh, θd)`` on the 90 × 90 MERL (θ'h, θd) grid,
  3 channels: 97,200 bytes.

Between samples, D and F are interpolated linearly in the continuous MERL index (on MERL
samples this is exact, as in the paper); G is linear in θ. Deliberate deviation for directions
outside the fitted range: beyond the last G sample (89°) G is tapered linearly to 0 at 90°,
which keeps ``G/cos θ`` bounded at grazing angles (the paper fits and renders only up to 89°).

Importance sampling (all three models): a mixture of cosine-weighted hemisphere sampling
(diffuse part) and half-vector sampling from a tabulated, piecewise-constant (per θ'h cell)
density proportional to an upper bound of the specular factor in θh times cos θh, with φh
uniform, followed by reflection of ``wi`` about the half vector (the CDF-based approach of the
paper's rendering appendix reduced to the factor that carries the peak). ``pdf`` is the exact
density of ``sample`` (the half vector ±h ambiguity is resolved by using the upper-hemisphere
representative, for which both give the same ``wo``); reflections below the horizon are
returned with pdf 0 (invalid samples), so ``pdf`` integrates to the valid fraction.

:func:`smith_g_from_d` implements G-from-D (§4.3, Eq. 19 and the Λ formulas after it) with
15-point Gauss–Legendre quadrature.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from ..brdf import IsotropicBRDF, _as_dirs, cosine_hemisphere_pdf, cosine_hemisphere_sample
from ..geometry import io_to_half_diff
from ..grid import N_PHI_D, N_THETA_D, N_THETA_H
from ..schema import FACTOR_MAX, Array, Opt, Schema, Text
from ..serialization import SerializableModel
from . import _npf_kernels

def _factor(n: int) -> Array:
    """A fit-file factor table: (n, 3) (or (n,)), finite, in [0, FACTOR_MAX]."""
    return Array([(n, 3), (n,)], ge=0, le=FACTOR_MAX)


#: ρd, ρs as stored: (2, 3), finite, in [0, FACTOR_MAX]
_RHO = Array((2, 3), ge=0, le=FACTOR_MAX)
_META = {"name": Opt(Text()), "layout": Opt(Text())}

__all__ = ["NPFMicrofacetBRDF", "NPFNaiveBRDF", "NPFBivariateBRDF", "smith_g_from_d",
           "smith_g_jacobian", "smith_g_curvature", "normalise_d", "G_THETA", "D_THETA_H",
           "F_THETA_D", "H_PHI_D"]

N_G = 90
#: θh of the D samples (the MERL θh grid, uniform in θ'h = sqrt(θh), Eq. 6)
D_THETA_H = (np.arange(N_THETA_H) / N_THETA_H) ** 2 * (np.pi / 2)
#: θd of the F samples
F_THETA_D = np.arange(N_THETA_D) * (np.pi / 2 / N_THETA_D)
#: θ of the G samples (k degrees, k = 0…89)
G_THETA = np.arange(N_G) * (np.pi / 180.0)
#: φd of the H samples
H_PHI_D = np.arange(N_PHI_D) * (np.pi / N_PHI_D)


# -- table look-ups ---------------------------------------------------------------------------
def _lerp(table: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Linear interpolation of ``table`` (n, C) at continuous indices ``u`` (clamped; NaN
    reads row 0: callers mask those samples)."""
    n = table.shape[0]
    u = np.clip(np.nan_to_num(u, nan=0.0), 0.0, n - 1.0)
    i0 = np.minimum(u.astype(np.int64), n - 2)
    t = (u - i0)[..., None]
    return table[i0] * (1.0 - t) + table[i0 + 1] * t


def _u_theta_h(theta_h):
    return np.sqrt(np.clip(theta_h, 0.0, np.pi / 2) / (np.pi / 2)) * N_THETA_H


def _u_theta_d(theta_d):
    return np.clip(theta_d, 0.0, np.pi / 2) / (np.pi / 2 / N_THETA_D)


def _g_with_90(G: np.ndarray) -> np.ndarray:
    """G's samples and the knot at 90°, where G is 0 (the taper beyond the last sample)."""
    return np.concatenate([G, np.zeros((1,) + G.shape[1:])], axis=0)


def _lerp_g(G: np.ndarray, theta) -> np.ndarray:
    """G at θ (radians), linear in θ, tapered to 0 at 90° beyond the last sample."""
    return _lerp(_g_with_90(G), np.clip(theta, 0.0, np.pi / 2) * (180.0 / np.pi))


def _lerp_periodic(table: np.ndarray, u: np.ndarray) -> np.ndarray:
    n = table.shape[0]
    u = np.mod(u, n)
    i0 = np.floor(u).astype(np.int64) % n
    t = (u - np.floor(u))[..., None]
    return table[i0] * (1.0 - t) + table[(i0 + 1) % n] * t


def _hd_cosines(theta_h, theta_d, phi_d):
    """Broadcast Rusinkiewicz angles and return them with ``cos θi``, ``cos θo``
    (``cos θh cos θd ∓ sin θh sin θd cos φd``, the φh-independent form)."""
    th, td, pd = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64)
                                       for x in (theta_h, theta_d, phi_d)))
    a = np.cos(th) * np.cos(td)
    b = np.sin(th) * np.sin(td) * np.cos(pd)
    return th, td, pd, a - b, a + b


def _as_table(x, n, name) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim == 1:
        a = np.repeat(a[:, None], 3, axis=1)
    if a.shape != (n, 3):
        raise ValueError(f"{name}: expected shape ({n}, 3) or ({n},), found {a.shape}")
    return a


def _as_rgb(x, name) -> np.ndarray:
    a = np.broadcast_to(np.asarray(x, dtype=np.float64), (3,)).copy()
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: expected finite values, found {a}")
    return a


# -- G from D (§4.3) --------------------------------------------------------------------------
_GL_X, _GL_W = np.polynomial.legendre.leggauss(15)


def normalise_d(D) -> tuple[np.ndarray, np.ndarray]:
    """``D̄ = 2π ∫ D(θ) cos θ sin θ dθ`` (Eq. 19) and ``D̃ = D / D̄`` for tables (90, C).

    D is piecewise linear in θ'h between samples (constant beyond the last one); the integral
    is computed exactly enough with 4-point Gauss–Legendre per θ'h cell.
    """
    D = np.asarray(D, dtype=np.float64)
    squeeze = D.ndim == 1
    D2 = D[:, None] if squeeze else D
    x, w = np.polynomial.legendre.leggauss(4)
    cells = np.arange(N_THETA_H)
    tp = (cells[:, None] + 0.5 + 0.5 * x[None, :]) / N_THETA_H           # θ' in [0, 1]
    theta = tp**2 * (np.pi / 2)
    vals = _lerp(D2, tp * N_THETA_H)                                      # (90, 4, C)
    jac = np.pi * tp / N_THETA_H * 0.5                                     # dθ = π θ' dθ'
    integrand = vals * (np.cos(theta) * np.sin(theta) * jac)[..., None]
    dbar = 2.0 * np.pi * np.einsum("ikc,k->c", integrand, w)
    dtilde = D2 / np.where(dbar > 0, dbar, 1.0)
    return (dbar[0], dtilde[:, 0]) if squeeze else (dbar, dtilde)


def _smith_lambda(dt) -> np.ndarray:
    """Smith's Λ at the G samples 1..89 for normalised tables ``dt`` = D̃ (90, C): the
    quadrature of :func:`smith_g_from_d`, linear in ``dt``."""
    theta = G_THETA[1:]                                                     # (89,)
    mu = 1.0 / np.tan(theta)
    a = np.arctan(mu)
    omega = a[:, None] + (np.pi / 2 - a)[:, None] * (_GL_X[None, :] + 1.0) * 0.5   # (89, 15)
    r = np.tan(omega)
    psi = (np.pi / 2) * (_GL_X + 1.0) * 0.5                                # (15,)
    q2 = np.tan(psi) ** 2
    u = r[..., None] ** 2 + q2                                             # (89, 15, 15)
    th = np.arctan(np.sqrt(u))
    p22 = _lerp(dt, _u_theta_h(th)) * (np.cos(th) ** 4)[..., None]         # (89, 15, 15, C)
    p2 = 2.0 * (np.pi / 4) * np.einsum("abgc,g->abc", p22 * (q2 + 1.0)[None, None, :, None],
                                      _GL_W)                              # (89, 15, C)
    integrand = ((r - mu[:, None]) * (1.0 + r**2))[..., None] * p2
    return np.einsum("abc,b->ac", integrand, _GL_W) * ((np.pi / 2 - a) * 0.5 / mu)[:, None]


@functools.cache
def _smith_operator() -> tuple[np.ndarray, np.ndarray]:
    """``(L (89, 90), w (90,))`` with ``Λ = L D / (w·D)`` for a table D (both integrals are
    linear in D: ``w·D`` is D̄ of Eq. 19, ``L`` the Λ quadrature applied to each unit table).
    Built once per process (one quadrature of 90 columns, ≈ 20 ms)."""
    unit = np.eye(N_THETA_H)
    dbar, _ = normalise_d(unit)
    return _smith_lambda(unit), dbar


def smith_g_from_d(D) -> np.ndarray:
    """G on the 90 G samples from a tabulated D (Bagher et al. 2016, §4.3).

    ``D̃ = D/D̄`` (Eq. 19); ``G(θ) = 1/(1 + Λ(cot θ))`` with
    ``Λ(μ) = 1/μ ∫_{atan μ}^{π/2} (tan ω − μ)(1 + tan² ω) p2(tan ω) dω``,
    ``p2(r) = 2 ∫_0^{π/2} p22(r² + tan² ψ)(tan² ψ + 1) dψ``,
    ``p22(u) = D̃(atan √u) cos⁴(atan √u)``, each integral by 15-point Gauss–Legendre
    quadrature (as the paper), D̃ linearly interpolated (in θ'h). ``D`` is (90,) or (90, C);
    the result has the same shape. ``G(0) = 1``. A D that is identically 0 gives G = 1.

    Λ is linear in D̃ and D̄ linear in D, so the quadrature is applied once to the 90 unit
    tables (:func:`_smith_operator`) and G follows from a matrix product (the same numbers
    to rounding, ≈ 1e-16).
    """
    D = np.maximum(np.asarray(D, dtype=np.float64), 0.0)
    squeeze = D.ndim == 1
    D2 = D[:, None] if squeeze else D
    lam, _ = _smith_lambda_of(D2)
    G = np.ones_like(D2)
    G[1:] = 1.0 / (1.0 + lam)
    return G[:, 0] if squeeze else G


def _smith_lambda_of(D2) -> tuple[np.ndarray, np.ndarray]:
    """Λ (89, C) ≥ 0 of non-negative tables D2 (90, C), and D̄ (C,) (1 where D̄ = 0)."""
    L, w = _smith_operator()
    dbar = w @ D2
    dbar = np.where(dbar > 0, dbar, 1.0)
    return np.maximum((L @ D2) / dbar, 0.0), dbar


def smith_g_jacobian(D) -> tuple[np.ndarray, np.ndarray]:
    """``(G (C, 90), ∂G/∂D (C, 90, 90))`` for tables ``D`` (C, 90) ≥ 0 (channels first, as
    the NPF solver holds them): from ``Λ = L D / (w·D)``, ``∂Λ/∂D = (L − Λ wᵀ)/(w·D)`` and
    ``∂G/∂D = −G² ∂Λ/∂D`` (G(0) = 1 is constant; L ≥ 0, so the clamp of Λ at 0 only
    removes rounding and is not differentiated)."""
    L, w = _smith_operator()
    D2 = np.maximum(np.asarray(D, dtype=np.float64), 0.0).T             # (90, C)
    lam, dbar = _smith_lambda_of(D2)                                    # (89, C), (C,)
    G = np.ones_like(D2)
    G[1:] = 1.0 / (1.0 + lam)
    dlam = (L[None] - lam.T[:, :, None] * w[None, None, :]) / dbar[:, None, None]
    J = np.zeros((D2.shape[1], N_THETA_H, N_THETA_H))
    J[:, 1:] = -(G[1:].T ** 2)[:, :, None] * dlam
    return G.T, J


def smith_g_curvature(D, e) -> np.ndarray:
    """``Σ_k e_k ∂²G_k/∂D ∂D`` (C, 90, 90) for tables ``D`` (C, 90) ≥ 0 and weights ``e``
    (C, 90) (e.g. an objective's gradient in G: Newton's Hessian through G = G(D) needs it).

    With ``s = w·D``, ``Λ = L D / s`` (:func:`smith_g_jacobian`) and ``Λ' = ∂Λ/∂D``:
    ``∂²Λ_k/∂D_i∂D_j = −(w_j Λ'_ki + w_i Λ'_kj)/s`` and, G = 1/(1 + Λ),
    ``∂²G_k/∂D_i∂D_j = 2 G_k³ Λ'_ki Λ'_kj + G_k² (w_j Λ'_ki + w_i Λ'_kj)/s``, so the sum is
    ``2 Λ'ᵀ diag(e G³) Λ' + (u wᵀ + w uᵀ)/s`` with ``u = Λ'ᵀ (e G²)``. G(0) = 1 is
    constant (``e_0`` is ignored)."""
    L, w = _smith_operator()
    D2 = np.maximum(np.asarray(D, dtype=np.float64), 0.0).T             # (90, C)
    e = np.asarray(e, dtype=np.float64)[:, 1:]                          # (C, 89)
    lam, dbar = _smith_lambda_of(D2)
    G = 1.0 / (1.0 + lam.T)                                             # (C, 89)
    dlam = (L[None] - lam.T[:, :, None] * w[None, None, :]) / dbar[:, None, None]
    u = np.einsum("ck,cki->ci", e * G**2, dlam)
    cross = u[:, :, None] * w[None, None, :] / dbar[:, None, None]
    return (2.0 * np.einsum("cki,ck,ckj->cij", dlam, e * G**3, dlam)
            + cross + np.swapaxes(cross, 1, 2))


# -- importance sampling ----------------------------------------------------------------------
_CELL_EDGES = (np.arange(N_THETA_H + 1) / N_THETA_H) ** 2 * (np.pi / 2)     # θh cell edges


class _HalfVectorSampling:
    """Mixture of cosine sampling and tabulated half-vector sampling (see module docstring)."""

    def _identify(self, variant: str, name: str, source: str | None) -> None:
        """Set the model's variant, name and source; the sampling table is built on first
        use."""
        self.variant = variant
        self.name = name
        self.source = source
        self._h_cdf = None

    def _spec_profile(self) -> np.ndarray:
        """Non-negative scalar profile over the 90 θh knots (upper bound of the specular
        part's θh dependence)."""
        raise NotImplementedError

    def _diffuse_fraction(self) -> float:
        raise NotImplementedError

    def _build_sampler(self):
        s = np.maximum(np.asarray(self._spec_profile(), dtype=np.float64), 0.0)
        s = np.concatenate([s, s[-1:]])                                   # knot at π/2
        t = np.maximum(s[:-1], s[1:]) * np.cos(_CELL_EDGES[:-1])
        dcos = np.cos(_CELL_EDGES[:-1]) - np.cos(_CELL_EDGES[1:])
        # a floor carrying 0.1 % of the mass, uniform in solid angle (a floor relative to the
        # peak *density*, 1e-4 × max, put 99 % of the half vectors of an α = 0.001 lobe
        # outside the lobe, whose cells are 1e-7 sr wide: standard error 10 % at 2^18 samples)
        t = t + 1e-3 * max(float(np.sum(t * dcos)), 1e-300)
        mass = t * dcos
        total = mass.sum()
        self._h_density = t / (2.0 * np.pi * total)                       # pdf of h per cell
        self._h_cdf = np.concatenate([[0.0], np.cumsum(mass) / total])
        self._mix = float(np.clip(self._diffuse_fraction(), 0.05, 0.95))

    def _ensure_sampler(self):
        if getattr(self, "_h_cdf", None) is None:
            self._build_sampler()

    def _h_pdf(self, h):
        th = np.arccos(np.clip(np.abs(h[..., 2]), -1.0, 1.0))
        cell = np.minimum(_u_theta_h(th).astype(np.int64), N_THETA_H - 1)
        return self._h_density[cell]

    def sample(self, wi, u):
        self._ensure_sampler()
        wi = np.asarray(wi, dtype=np.float64)
        u = np.asarray(u, dtype=np.float64)
        shape = np.broadcast_shapes(wi.shape[:-1], u.shape[:-1])
        wi = np.broadcast_to(wi, shape + (3,))
        u = np.broadcast_to(u, shape + (2,))
        s = self._mix
        diffuse = u[..., 0] < s
        u0 = np.where(diffuse, u[..., 0] / s, (u[..., 0] - s) / (1.0 - s))
        u0 = np.clip(u0, 0.0, np.nextafter(1.0, 0.0))
        wo_d = cosine_hemisphere_sample(np.stack([u0, u[..., 1]], axis=-1))
        # half vector: cell from the CDF, then cos θ uniform inside the cell (constant density
        # per solid angle within a cell), φ uniform
        cell = np.clip(np.searchsorted(self._h_cdf, u0, side="right") - 1, 0, N_THETA_H - 1)
        lo, hi = self._h_cdf[cell], self._h_cdf[cell + 1]
        frac = np.clip((u0 - lo) / np.maximum(hi - lo, 1e-300), 0.0, 1.0)
        ca, cb = np.cos(_CELL_EDGES[cell]), np.cos(_CELL_EDGES[cell + 1])
        ct = ca - frac * (ca - cb)
        st = np.sqrt(np.maximum(0.0, 1.0 - ct * ct))
        phi = 2.0 * np.pi * u[..., 1]
        h = np.stack([st * np.cos(phi), st * np.sin(phi), ct], axis=-1)
        wo_s = 2.0 * np.sum(wi * h, axis=-1, keepdims=True) * h - wi
        wo = np.where(diffuse[..., None], wo_d, wo_s)
        return wo, self.pdf(wi, wo)

    def pdf(self, wi, wo):
        self._ensure_sampler()
        wi, wo = _as_dirs(wi, wo)
        h = wi + wo
        n = np.linalg.norm(h, axis=-1, keepdims=True)
        h = np.where(n > 1e-12, h / np.where(n > 1e-12, n, 1.0), np.array([0.0, 0.0, 1.0]))
        h = np.where((h[..., 2] < 0)[..., None], -h, h)
        wih = np.abs(np.sum(wi * h, axis=-1))
        p_spec = np.where(wih > 1e-12, self._h_pdf(h) / (4.0 * np.maximum(wih, 1e-12)), 0.0)
        p = self._mix * cosine_hemisphere_pdf(wo) + (1.0 - self._mix) * p_spec
        # reflections below the horizon are invalid samples (pdf 0), as everywhere in brdffit
        return np.where((wi[..., 2] > 0) & (wo[..., 2] > 0), p, 0.0)


def _albedo_normal_incidence(brdf) -> float:
    """Mean RGB albedo at normal incidence by quadrature in the half vector: for ``wi = n``
    and an isotropic BRDF the integrand depends on θh only, ``θo = 2θh``,
    ``dωo = 4 cos θh dωh``; composite 8-point Gauss-Legendre on panels of 0.25 in
    ``ln θh`` ∈ [ln 1e-6, ln π/4] (a cosine-sampled estimate misses a lobe of α = 0.001)."""
    x, w = np.polynomial.legendre.leggauss(8)
    lo, hi = np.log(1e-6), np.log(np.pi / 4)
    edges = np.linspace(lo, hi, int(np.ceil((hi - lo) / 0.25)) + 1)
    half = 0.5 * np.diff(edges)
    v = ((0.5 * (edges[:-1] + edges[1:]))[:, None] + half[:, None] * x).ravel()
    wv = (half[:, None] * w).ravel()
    th = np.exp(v)
    wo = np.stack([np.sin(2 * th), np.zeros_like(th), np.cos(2 * th)], -1)
    wi = np.broadcast_to([0.0, 0.0, 1.0], wo.shape)
    f = np.nan_to_num(np.asarray(brdf.eval(wi, wo), np.float64)).mean(axis=-1)
    return float(np.sum(f * np.cos(2 * th) * 4 * np.cos(th) * 2 * np.pi * np.sin(th) * th * wv))


def _estimate_diffuse_fraction(brdf, diffuse_albedo: float) -> float:
    """Mixture weight of the cosine lobe: diffuse albedo / total albedo at normal incidence."""
    total = _albedo_normal_incidence(brdf)
    if not np.isfinite(total) or total <= 0:
        return 0.5
    return diffuse_albedo / total


# -- the models -------------------------------------------------------------------------------
class _DiffuseFigures:
    """``figures()`` of a factor model with a diffuse term ``ρd`` (``f = ρd + …``, so the
    Lambertian albedo is π ρd); no α, no F0: the factors are defined up to a scale
    (Bagher 2016 §4.3)."""

    def figures(self) -> dict:
        return {"rho_d": [float(np.pi * x) for x in np.asarray(self.rho_d, dtype=np.float64)]}


def _factor_arrays(model, third: str) -> dict[str, np.ndarray]:
    """The fit-file arrays of a three-factor model: D, F and ``third`` (``"G"`` or ``"H"``)
    as float32, and ``rho`` = (ρd, ρs) (2, 3)."""
    return {"D": model.D.astype(np.float32), "F": model.F.astype(np.float32),
            third: getattr(model, third).astype(np.float32),
            "rho": np.stack([model.rho_d, model.rho_s]).astype(np.float32)}


def _rho_of(arrays) -> np.ndarray:
    """(ρd, ρs) (2, 3) of a fit file's ``rho``; raises ValueError for another shape."""
    rho = np.asarray(arrays["rho"], dtype=np.float64)
    if rho.shape != (2, 3):
        raise ValueError(f"rho: expected shape (2, 3), found {rho.shape}")
    return rho


class NPFMicrofacetBRDF(_DiffuseFigures, _HalfVectorSampling, SerializableModel, IsotropicBRDF):
    """Non-parametric factor microfacet BRDF (Bagher et al. 2016, Eq. 3).

    Parameters: tables ``D`` (90, 3), ``F`` (90, 3), ``G`` (90, 3) (see the module docstring
    for their abscissae), ``rho_d`` and ``rho_s`` (3,). ``variant`` records how G was fitted
    (``"independent-g"`` or ``"g-from-d"``). The scale of each factor is only defined up to the
    model's ambiguity ``(ρs, D, F, G) ~ (ρs/(a b c²), a D, b F, c G)``; fitted models are
    max-normalised (max of each factor = 1, ρs absorbs the scale, §4.3).
    """

    fit_kind = "npf"
    #: fit-file state (:mod:`brdffit.schema`): D, F, G (90, 3) and rho (2, 3), all finite and
    #: in [0, FACTOR_MAX] (fits are max-normalised; ρs carries the scale)
    state_schema = Schema({"variant": Text(max_len=64), **_META},
                          arrays={"D": _factor(N_THETA_H), "F": _factor(N_THETA_D),
                                  "G": _factor(N_G), "rho": _RHO})

    def __init__(self, D, F, G, rho_d, rho_s, *, variant: str = "independent-g",
                 name: str = "npf", source: str | None = None):
        self.D = _as_table(D, N_THETA_H, "D")
        self.F = _as_table(F, N_THETA_D, "F")
        self.G = _as_table(G, N_G, "G")
        self.rho_d = _as_rgb(rho_d, "rho_d")
        self.rho_s = _as_rgb(rho_s, "rho_s")
        self._identify(str(variant), name, source)

    # evaluation
    def _spec(self, theta_h, theta_d, theta_i, theta_o, cos_i, cos_o):
        d = _lerp(self.D, _u_theta_h(theta_h))
        f = _lerp(self.F, _u_theta_d(theta_d))
        g = _lerp_g(self.G, theta_i) * _lerp_g(self.G, theta_o)
        cc = cos_i * cos_o
        ok = (cos_i > 0) & (cos_o > 0)
        inv = np.where(ok, 1.0 / np.where(ok, cc, 1.0), 0.0)[..., None]
        return d * f * g * inv

    def eval(self, wi, wo):
        wi, wo = _as_dirs(wi, wo)
        th, _, td, _ = io_to_half_diff(wi, wo)
        ci, co = wi[..., 2], wo[..., 2]
        ti, to = np.arccos(np.clip(ci, -1, 1)), np.arccos(np.clip(co, -1, 1))
        f = self.rho_d + self.rho_s * self._spec(th, td, ti, to, ci, co)
        return np.where(((ci > 0) & (co > 0))[..., None], f, 0.0)

    def eval_hd(self, theta_h, theta_d, phi_d):
        out = _npf_kernels.run(_npf_kernels.microfacet_hd,
                               (self.D, self.F, _g_with_90(self.G), self.rho_d, self.rho_s),
                               theta_h, theta_d, phi_d)
        if out is not None:
            return out
        th, td, pd, ci, co = _hd_cosines(theta_h, theta_d, phi_d)
        ti, to = np.arccos(np.clip(ci, -1, 1)), np.arccos(np.clip(co, -1, 1))
        f = self.rho_d + self.rho_s * self._spec(th, td, ti, to, ci, co)
        return np.where(((ci > 0) & (co > 0))[..., None], f, 0.0)

    # sampling
    def _spec_profile(self):
        return (self.rho_s * self.D * self.F.max(axis=0) * self.G.max(axis=0) ** 2).mean(axis=1)

    def _diffuse_fraction(self):
        return _estimate_diffuse_fraction(self, float(np.pi * self.rho_d.mean()))

    # serialisation
    def to_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        arrays = _factor_arrays(self, "G")
        return {"variant": self.variant, "name": self.name,
                "layout": "D[θ'h],F[θd],G[θ=k°] (90,3); rho=(ρd,ρs) (2,3)"}, arrays

    @classmethod
    def from_state(cls, params, arrays):
        rho = _rho_of(arrays)
        return cls(arrays["D"], arrays["F"], arrays["G"], rho[0], rho[1],
                   variant=params.get("variant", "independent-g"),
                   name=params.get("name", "npf"))

    def factors(self) -> dict[str, np.ndarray]:
        return {"D": self.D, "F": self.F, "G": self.G, "rho_d": self.rho_d, "rho_s": self.rho_s}

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        d.update(variant=self.variant, rho_d=self.rho_d.tolist(), rho_s=self.rho_s.tolist())
        return d


class NPFNaiveBRDF(_DiffuseFigures, _HalfVectorSampling, SerializableModel, IsotropicBRDF):
    """The naive orthogonal factor model (Bagher et al. 2016, Eq. 4):
    ``ρ = ρd + ρs D(θh) F(θd) H(φd)``, H tabulated at 180 φd samples in [0, π)."""

    fit_kind = "npf-naive"
    #: fit-file state: D, F (90, 3), H (180, 3), rho (2, 3), finite, in [0, FACTOR_MAX]
    state_schema = Schema(dict(_META), arrays={"D": _factor(N_THETA_H), "F": _factor(N_THETA_D),
                                               "H": _factor(N_PHI_D), "rho": _RHO})

    def __init__(self, D, F, H, rho_d, rho_s, *, name: str = "npf-naive",
                 source: str | None = None):
        self.D = _as_table(D, N_THETA_H, "D")
        self.F = _as_table(F, N_THETA_D, "F")
        self.H = _as_table(H, N_PHI_D, "H")
        self.rho_d = _as_rgb(rho_d, "rho_d")
        self.rho_s = _as_rgb(rho_s, "rho_s")
        self._identify("naive", name, source)

    def eval_hd(self, theta_h, theta_d, phi_d):
        out = _npf_kernels.run(_npf_kernels.naive_hd,
                               (self.D, self.F, self.H, self.rho_d, self.rho_s),
                               theta_h, theta_d, phi_d)
        if out is not None:
            return out
        th, td, pd, ci, co = _hd_cosines(theta_h, theta_d, phi_d)
        spec = (_lerp(self.D, _u_theta_h(th)) * _lerp(self.F, _u_theta_d(td))
                * _lerp_periodic(self.H, np.mod(pd, np.pi) / (np.pi / N_PHI_D)))
        return np.where(((ci > 0) & (co > 0))[..., None], self.rho_d + self.rho_s * spec, 0.0)

    def _spec_profile(self):
        return (self.rho_s * self.D * self.F.max(axis=0) * self.H.max(axis=0)).mean(axis=1)

    def _diffuse_fraction(self):
        return _estimate_diffuse_fraction(self, float(np.pi * self.rho_d.mean()))

    def to_state(self):
        arrays = _factor_arrays(self, "H")
        return {"name": self.name, "layout": "D,F (90,3); H[φd=k°] (180,3); rho (2,3)"}, arrays

    @classmethod
    def from_state(cls, params, arrays):
        rho = _rho_of(arrays)
        return cls(arrays["D"], arrays["F"], arrays["H"], rho[0], rho[1],
                   name=params.get("name", "npf-naive"))

    def factors(self) -> dict[str, np.ndarray]:
        return {"D": self.D, "F": self.F, "H": self.H, "rho_d": self.rho_d, "rho_s": self.rho_s}


class NPFBivariateBRDF(_HalfVectorSampling, SerializableModel, IsotropicBRDF):
    """The bivariate model (Romeiro et al. 2008 as used by Bagher et al. 2016, Eq. 5):
    ``ρ = B(θh, θd)``, B (90, 90, 3) on the MERL (θ'h, θd) grid, bilinear in between."""

    fit_kind = "npf-bivariate"
    #: fit-file state: B (90, 90, 3), finite, in [0, FACTOR_MAX]
    state_schema = Schema(dict(_META), arrays={"B": Array((N_THETA_H, N_THETA_D, 3), ge=0,
                                                          le=FACTOR_MAX)})

    def __init__(self, B, *, name: str = "npf-bivariate", source: str | None = None):
        B = np.asarray(B, dtype=np.float64)
        if B.shape != (N_THETA_H, N_THETA_D, 3):
            raise ValueError(f"B: expected shape (90, 90, 3), found {B.shape}")
        self.B = B
        self._identify("bivariate", name, source)

    def eval_hd(self, theta_h, theta_d, phi_d):
        out = _npf_kernels.run(_npf_kernels.bivariate_hd, (self.B,), theta_h, theta_d, phi_d)
        if out is not None:
            return out
        th, td, pd, ci, co = _hd_cosines(theta_h, theta_d, phi_d)
        uh = np.clip(np.nan_to_num(_u_theta_h(th), nan=0.0), 0.0, N_THETA_H - 1.0)
        ud = np.clip(np.nan_to_num(_u_theta_d(td), nan=0.0), 0.0, N_THETA_D - 1.0)
        i0 = np.minimum(uh.astype(np.int64), N_THETA_H - 2)
        j0 = np.minimum(ud.astype(np.int64), N_THETA_D - 2)
        s = (uh - i0)[..., None]
        t = (ud - j0)[..., None]
        B = self.B
        v = ((1 - s) * (1 - t) * B[i0, j0] + s * (1 - t) * B[i0 + 1, j0]
             + (1 - s) * t * B[i0, j0 + 1] + s * t * B[i0 + 1, j0 + 1])
        return np.where(((ci > 0) & (co > 0))[..., None], v, 0.0)

    def _spec_profile(self):
        return self.B.max(axis=1).mean(axis=1)

    def _diffuse_fraction(self):
        return 0.25

    def to_state(self):
        return {"name": self.name, "layout": "B[θ'h, θd] (90,90,3)"}, \
            {"B": self.B.astype(np.float32)}

    @classmethod
    def from_state(cls, params, arrays):
        return cls(arrays["B"], name=params.get("name", "npf-bivariate"))

    def factors(self) -> dict[str, np.ndarray]:
        return {"B": self.B}

