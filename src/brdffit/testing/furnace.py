"""Furnace test of BRDF samplers: importance-sampled directional albedo against quadrature.

For an incidence ``wi`` the directional albedo ``a(wi) = ∫ f(wi, wo) cos θo dωo`` (per RGB
channel) is computed twice:

* **by importance sampling**, the estimator a renderer uses: ``mean(f cos θo / pdf)`` over
  directions drawn with the sampler under test (samples with pdf 0 count as 0), with its
  standard error ``std/√N`` (:func:`albedo_sampled` for library BRDFs;
  :func:`brdffit.evaluation.render.translate.albedo_drjit` for Dr.Jit evaluators);
* **by deterministic quadrature** of the same ``f`` (:func:`albedo_quadrature`).

An unbiased sampler (the pdf it reports is the density it draws from, positive wherever
``f > 0``) makes the two agree up to the Monte Carlo error; a pdf that is too small
somewhere (a clamp, a lost digit, the pdf of another lobe) shows up as a positive bias, an
unreachable region as a negative one. :func:`check` applies the criterion
``|estimate − quadrature| ≤ max(tol · quadrature, k · se)`` per channel.

Quadrature
----------
Microfacet-like lobes are sharp around the half vector ``h = n``, at every incidence, so the
integral is taken over the half vector: ``wo = 2(wi·h)h − wi``, ``dωo = 4 (wi·h) dωh``.
The azimuth ``φh`` uses the trapezoid (midpoint) rule, spectrally accurate for the periodic
integrand. For each ``φh`` the polar angle runs over the visible part, ``θh ∈ (0, θ*(φh))``
where ``θ*`` is the closed-form horizon of ``wo``: ``wo·n = cos(2θh − β)·R`` with
``tan β = tan θi cos φh``, so ``θ* = (π/2 + β)/2`` (the integrand is smooth up to that
boundary, where it vanishes with cos θo). ``θh`` is integrated with composite Gauss-Legendre
in ``v = ln θh + θh/δ`` (δ = 0.2) from ``θ_min = 10⁻⁶`` (the cap below adds a one-node
term): logarithmic near the normal, where a lobe of any width α is a bump of width O(1) in
``ln θh`` centred near ``ln α``, so one grid serves α from 10⁻³ to 1 alike; steps of
0.05 rad at large θh (a purely logarithmic grid was 0.6 % off on the measured RGL
``chm_mint`` at θi = 80°). Checks: GGX α = 0.001 at θi = 80°, default grid vs a 2.5× finer
one: 2e-8; a Lambertian lobe: exact to 1e-15; ``∫ D cos θh`` of GGX over the visible cone
equals ``1/(1 + α²)`` to 1e-13 for α = 0.001 … 1. Piecewise-linear tables (NPF, MERL grid)
have kinks between their nodes, where the rule converges only as h²: ≤ 3e-4 relative at
the defaults (every model of :func:`model_zoo`, α = 0.001 … 1, θi = 0 … 80°).

Importance sampling can use i.i.d. uniforms or, with ``stratified=True``, 16 independent
batches of jittered-grid uniforms whose standard error is that of the batch means (4-8×
smaller for the same number of samples; the tests use it to keep se below 0.25 % cheaply).
:func:`model_zoo` builds one model per sampler/translator at a given roughness.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

__all__ = ["albedo_quadrature", "albedo_sampled", "estimator_values", "stratified_uniforms",
           "check", "FurnaceResult", "furnace", "model_zoo"]


def _incident(theta_i: float) -> np.ndarray:
    return np.array([np.sin(theta_i), 0.0, np.cos(theta_i)])


def albedo_quadrature(f, theta_i: float, *, theta_min: float = 1e-6, panel: float = 0.25,
                      order: int = 8, n_phi: int = 256, delta: float = 0.2,
                      chunk: int = 1 << 18) -> np.ndarray:
    """``∫ f(wi, wo) cos θo dωo`` (RGB) for ``wi`` at polar angle ``theta_i`` (φi = 0).

    ``f(wi, wo) -> (N, 3)`` takes ``(N, 3)`` directions in the library convention. Quadrature
    in the half vector (module docstring): ``n_phi`` midpoint nodes in φh, composite
    ``order``-point Gauss-Legendre on panels of width ``panel`` in
    ``v = ln θh + θh/delta`` over ``[v(theta_min), v(θ*(φh))]`` (logarithmic near the normal,
    steps of ``panel · delta`` radians at large θh, where a logarithmic grid alone is too
    coarse for measured data near grazing), plus the cap ``θh < theta_min`` as one node.
    """
    from scipy.special import lambertw

    ti = float(theta_i)
    wi = _incident(ti)
    ph = (np.arange(n_phi) + 0.5) * (2.0 * np.pi / n_phi)
    beta = np.arctan2(np.sin(ti) * np.cos(ph), np.cos(ti))
    th_max = 0.5 * (0.5 * np.pi + beta)                  # wo on the horizon
    lo = np.log(theta_min) + theta_min / delta
    hi = np.log(th_max) + th_max / delta
    n_pan = max(int(np.ceil((hi.max() - lo) / panel)), 1)
    x, w = np.polynomial.legendre.leggauss(order)
    edges = np.linspace(0.0, 1.0, n_pan + 1)
    half = 0.5 * np.diff(edges)
    s = ((0.5 * (edges[:-1] + edges[1:]))[:, None] + half[:, None] * x[None]).ravel()
    ws = (half[:, None] * w[None]).ravel()
    V = lo + s[None, :] * (hi - lo)[:, None]             # (n_phi, n_s) values of v
    # θ = W(e^v / δ) δ solves ln θ + θ/δ = v; dθ/dv = θ / (1 + θ/δ)
    th = delta * np.real(lambertw(np.exp(V) / delta))
    W = ws[None, :] * (hi - lo)[:, None] * th / (1.0 + th / delta) * np.sin(th)
    # cap θh < theta_min: one node at the area centroid radius
    th = np.concatenate([np.full((n_phi, 1), theta_min / np.sqrt(2.0)), th], 1)
    W = np.concatenate([np.full((n_phi, 1), 0.5 * theta_min**2), W], 1)
    W = W * (2.0 * np.pi / n_phi)
    P = np.broadcast_to(ph[:, None], th.shape)
    st = np.sin(th)
    h = np.stack([st * np.cos(P), st * np.sin(P), np.cos(th)], -1).reshape(-1, 3)
    W = W.ravel()
    ih = h @ wi
    wo = 2.0 * ih[:, None] * h - wi
    wo[:, 2] = np.maximum(wo[:, 2], 0.0)
    wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
    weight = W * 4.0 * ih * wo[:, 2]                     # dωo = 4 (wi·h) dωh, times cos θo
    out = np.zeros(3)
    for a in range(0, W.size, chunk):
        sl = slice(a, a + chunk)
        val = np.asarray(f(np.broadcast_to(wi, wo[sl].shape), wo[sl]), dtype=np.float64)
        val = np.nan_to_num(val, nan=0.0, posinf=0.0, neginf=0.0)
        out += np.einsum("nc,n->c", np.broadcast_to(val, (val.shape[0], 3)), weight[sl])
    return out


def stratified_uniforms(rng, n: int, dim: int) -> np.ndarray:
    """``side**dim ≤ n`` jittered-grid points in ``[0, 1)^dim`` (one uniform point per cell
    of a regular grid, ``side = ⌊n^(1/dim)⌋``), in random order."""
    side = max(int(np.floor(n ** (1.0 / dim) + 1e-9)), 1)
    g = np.stack(np.meshgrid(*([np.arange(side)] * dim), indexing="ij"), -1).reshape(-1, dim)
    return rng.permutation((g + rng.random(g.shape)) / side)


def albedo_sampled(brdf, theta_i: float, n: int = 1 << 18, seed: int = 0,
                   batch: int = 1 << 18, stratified: bool = False,
                   batches: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """Importance-sampled albedo of a library BRDF with its own ``sample``/``eval``:
    ``(mean, standard error)``, both RGB. Samples with pdf 0 (invalid) contribute 0.

    ``stratified``: ``batches`` independent batches of jittered-grid uniforms
    (:func:`stratified_uniforms`, ``n/batches`` each); the standard error is that of the
    batch means (honest, and 4-8× smaller than i.i.d. sampling for the same ``n``)."""
    rng = np.random.default_rng(seed)
    wi1 = _incident(float(theta_i))

    def values(u):
        wi = np.broadcast_to(wi1, (len(u), 3))
        wo, pdf = brdf.sample(wi, u)
        wo = np.asarray(wo, np.float64)
        return estimator_values(np.asarray(brdf.eval(wi, wo), np.float64), wo,
                                np.asarray(pdf, np.float64))

    return sample_mean(values, rng, n, 2, batch=batch, stratified=stratified, batches=batches)


def sample_mean(values, rng, n: int, dims: int, *, batch: int = 1 << 18,
                stratified: bool = False, batches: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard error (RGB) of ``values(u)`` over ``n`` uniforms ``u`` in
    ``[0, 1)^dims``: i.i.d. in chunks of ``batch``, or ``batches`` independent batches of
    jittered-grid uniforms (:func:`stratified_uniforms`) with the standard error of the batch
    means. Shared by the Python and the Dr.Jit furnace estimators."""
    if stratified:
        u = np.stack([stratified_uniforms(rng, n // batches, dims) for _ in range(batches)])
        means = values(u.reshape(-1, dims)).reshape(batches, -1, 3).mean(1)  # one launch
        return means.mean(0), means.std(0, ddof=1) / np.sqrt(batches)
    s1, s2, done = np.zeros(3), np.zeros(3), 0
    while done < n:
        m = min(batch, n - done)
        val = values(rng.random((m, dims)))
        s1 += val.sum(0)
        s2 += (val * val).sum(0)
        done += m
    mean = s1 / n
    return mean, np.sqrt(np.maximum(s2 / n - mean**2, 0.0) / max(n - 1, 1))


def estimator_values(f, wo, pdf) -> np.ndarray:
    """Per-sample ``f cos θo / pdf`` (0 where ``pdf`` is 0 or not finite, or ``wo`` is below
    the horizon), ``(N, 3)``."""
    f = np.asarray(f, np.float64)
    pdf = np.asarray(pdf, np.float64)
    cz = np.asarray(wo, np.float64)[:, 2]
    good = (pdf > 0) & np.isfinite(pdf) & (cz > 0)
    val = f * (np.where(good, cz, 0.0) / np.where(good, pdf, 1.0))[:, None]
    return np.where(good[:, None] & np.isfinite(val), val, 0.0)


@dataclasses.dataclass
class FurnaceResult:
    """One furnace comparison (one incidence): RGB estimate, its standard error, quadrature."""

    theta_i: float
    estimate: np.ndarray
    se: np.ndarray
    quadrature: np.ndarray
    tol: float = 0.01
    k: float = 4.0

    @property
    def rel_error(self) -> np.ndarray:
        """``|estimate − quadrature| / quadrature`` per channel (0 where both vanish)."""
        q = np.maximum(np.abs(self.quadrature), 1e-300)
        return np.where(np.abs(self.quadrature) > 0, np.abs(self.estimate - self.quadrature) / q,
                        np.where(self.estimate == 0, 0.0, np.inf))

    @property
    def rel_se(self) -> np.ndarray:
        return self.se / np.maximum(np.abs(self.quadrature), 1e-300)

    @property
    def passed(self) -> bool:
        return bool(check(self.estimate, self.se, self.quadrature, self.tol, self.k))

    def __str__(self) -> str:
        return (f"θi={np.degrees(self.theta_i):4.1f}° est={np.round(self.estimate, 6).tolist()} "
                f"quad={np.round(self.quadrature, 6).tolist()} "
                f"rel.err={np.round(self.rel_error, 5).tolist()} "
                f"rel.se={np.round(self.rel_se, 5).tolist()} {'PASS' if self.passed else 'FAIL'}")


def check(estimate, se, quadrature, tol: float = 0.01, k: float = 4.0) -> bool:
    """True when every channel satisfies ``|est − quad| ≤ max(tol·|quad|, k·se)``."""
    estimate, se, quadrature = (np.asarray(a, np.float64) for a in (estimate, se, quadrature))
    return bool(np.all(np.abs(estimate - quadrature) <= np.maximum(tol * np.abs(quadrature),
                                                                  k * se)))


def furnace(brdf, thetas_deg=(0.0, 40.0, 80.0), n: int = 1 << 18, seed: int = 0,
            tol: float = 0.01, k: float = 4.0, stratified: bool = False,
            **quad_kw) -> list[FurnaceResult]:
    """Furnace test of a library BRDF's ``sample``/``pdf`` at incidences ``thetas_deg``."""
    out = []
    for j, t in enumerate(np.radians(np.atleast_1d(thetas_deg))):
        est, se = albedo_sampled(brdf, t, n=n, seed=seed + j, stratified=stratified)
        q = albedo_quadrature(brdf.eval, t, **quad_kw)
        out.append(FurnaceResult(float(t), est, se, q, tol, k))
    return out


# -- a zoo of the library's models at a given roughness (tests and bench/bench_furnace.py) ----
def _ggx_slope_table(n: int = 90) -> np.ndarray:
    """Unit GGX slope pdf ``1/(π(1 + r²)²)`` on the MERL radial nodes (a tabulated fit)."""
    from ..microfacet.tabulated import radial_rule

    r = radial_rule(n, "merl")[2]
    return 1.0 / (np.pi * (1.0 + r * r) ** 2)


def _ggx_slope_table_2d(n: int = 40, n_phi: int = 40, ay: float = 0.5) -> np.ndarray:
    """Elliptical GGX slope pdf (αx, αy) = (1, ``ay``) on an anisotropic (θ, φ) table."""
    from ..microfacet.tabulated import radial_rule

    r = radial_rule(n, "merl")[2][:, None]
    phi = 2.0 * np.pi * np.arange(n_phi)[None, :] / n_phi
    q = (r * np.cos(phi)) ** 2 + (r * np.sin(phi) / ay) ** 2
    return 1.0 / (np.pi * ay * (1.0 + q) ** 2)


@functools.lru_cache(maxsize=1)
def _unit_tables():
    """The unit-roughness tabulated distributions of the zoo (shared by every α, so that
    their lazily built sampling tables are built once; the 2D table's visible-normal
    normaliser is built here, before ``with_roughness`` copies share it)."""
    from ..microfacet.tabulated import TabulatedSlopeDistribution

    iso = TabulatedSlopeDistribution(_ggx_slope_table())
    aniso = TabulatedSlopeDistribution(_ggx_slope_table_2d())
    n = np.array([0.0, 0.0, 1.0])
    iso.pdf_visible(n, n)         # builds the sampler's normaliser tables
    aniso.pdf_visible(n, n)
    return iso, aniso


def model_zoo(alpha: float) -> dict:
    """The library's BRDF models with (main) lobe roughness ``alpha``, one per render
    translator / sampler: name → BRDF.

    ``ggx`` (closed form, Schlick, diffuse), ``beckmann`` (closed form, conductor Fresnel →
    table Fresnel), ``ggx-aniso``/``beckmann-aniso`` (αy = 2α capped at 1, ρ ≠ 0), ``sgd``
    (SGD(α, 0.84) radial table, generalised Schlick, diffuse), ``tabulated`` (tabulated slope
    pdf of Dupuy 2015 scaled by α), ``tabulated-aniso`` (a 2D table: elliptical GGX (1, 0.5)
    scaled by α, rendered through the generic 4D table), ``sum`` (GGX α + GGX min(10α, 1) +
    diffuse),
    ``per-channel-sgd`` (Bagher 2012 lobes of widths R α, G 0.05, B 0.5),
    ``per-channel-tabulated`` (tabulated fits R α, G 0.05, B 0.5), ``npf``, ``npf-naive``,
    ``npf-bivariate`` (Bagher 2016 tables of a GGX α lobe).
    """
    from ..microfacet.sgd_model import PerChannelMicrofacetBRDF
    from ..microfacet.per_channel import PerChannelBRDF
    from ..microfacet import (GGX, Beckmann, ConductorFresnel, MicrofacetBRDF, SchlickFresnel,
                              SumBRDF)
    from ..microfacet.fresnel import GeneralizedSchlickFresnel
    from ..microfacet.npf_model import (D_THETA_H, F_THETA_D, G_THETA, NPFBivariateBRDF,
                                        NPFMicrofacetBRDF, NPFNaiveBRDF, H_PHI_D)
    from ..microfacet.sgd import SGD

    a = float(alpha)
    a2 = min(2.0 * a, 1.0)
    widths = (a, 0.05, 0.5)
    tab, tab2d = _unit_tables()
    gold = ConductorFresnel([0.143, 0.374, 1.442], [3.983, 2.386, 1.603])
    out = {
        "ggx": MicrofacetBRDF(GGX(a), SchlickFresnel([0.9, 0.6, 0.3]), diffuse=[0.1, 0.1, 0.2]),
        "beckmann": MicrofacetBRDF(Beckmann(a), gold),
        "ggx-aniso": MicrofacetBRDF(GGX(a, a2, 0.3), None, diffuse=0.05),
        "beckmann-aniso": MicrofacetBRDF(Beckmann(a2, a, -0.4), SchlickFresnel(0.5)),
        "sgd": MicrofacetBRDF(SGD(a, 0.84), GeneralizedSchlickFresnel(0.9, -0.3),
                              diffuse=[0.2, 0.04, 0.03], specular=0.5),
        "tabulated": MicrofacetBRDF(tab.with_roughness(a), gold),
        "sum": SumBRDF([MicrofacetBRDF(GGX(a), None, specular=0.6),
                        MicrofacetBRDF(GGX(min(10.0 * a, 1.0)), SchlickFresnel([0.9, 0.5, 0.2]),
                                       diffuse=[0.05, 0.1, 0.1])]),
        "per-channel-sgd": PerChannelMicrofacetBRDF(
            [dict(distribution=SGD(w, 0.84), rho_d=d, rho_s=0.05, F0=1.0, F1=-0.3)
             for w, d in zip(widths, (0.2, 0.04, 0.03))]),
        "tabulated-aniso": MicrofacetBRDF(
            tab2d.with_roughness(a), None,
            diffuse=0.05),
        "per-channel-tabulated": PerChannelBRDF(
            [MicrofacetBRDF(tab.with_roughness(w), SchlickFresnel(0.8), diffuse=0.05)
             for w in widths]),
    }
    # NPF tables of a GGX α lobe (D on the MERL θh grid, F Schlick, G Smith GGX, H flat)
    ggx = GGX(a)
    m = np.stack([np.sin(D_THETA_H), 0.0 * D_THETA_H, np.cos(D_THETA_H)], -1)
    D = ggx.D(m)[:, None] * np.array([1.0, 0.8, 0.6]) / ggx.D(np.array([0.0, 0.0, 1.0]))
    F = (0.5 + 0.5 * (1.0 - np.cos(F_THETA_D)) ** 5)[:, None] * np.ones(3)
    wg = np.stack([np.sin(G_THETA), 0.0 * G_THETA, np.cos(G_THETA)], -1)
    G = ggx.G1(wg)[:, None] * np.ones(3)
    rho_s = np.array([0.3, 0.3, 0.3]) * float(ggx.D(np.array([0.0, 0.0, 1.0]))) / 4.0
    out["npf"] = NPFMicrofacetBRDF(D, F, G, [0.05, 0.04, 0.03], rho_s)
    H = (1.0 + 0.2 * np.cos(2.0 * H_PHI_D))[:, None] * np.ones(3)
    out["npf-naive"] = NPFNaiveBRDF(D, F, H, [0.05, 0.04, 0.03], rho_s)
    th, td = np.meshgrid(D_THETA_H, F_THETA_D, indexing="ij")
    B = (np.interp(th, D_THETA_H, D[:, 0])[..., None] * F[None, :, :] * rho_s
         / np.maximum(np.cos(th) ** 2, 1e-3)[..., None] + np.array([0.05, 0.04, 0.03]))
    out["npf-bivariate"] = NPFBivariateBRDF(B)
    for k, v in out.items():
        v.name = k
    return out
