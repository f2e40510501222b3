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
0.05 rad at large θh (a purely logarithmic grid is 0.6 % off on the measured RGL
``chm_mint`` at θi = 80°). Checks: GGX α = 0.001 at θi = 80°, default grid vs a 2.5× finer
one: 2e-8; a Lambertian lobe: exact to 1e-15; ``∫ D cos θh`` of GGX over the visible cone
equals ``1/(1 + α²)`` to 1e-13 for α = 0.001 … 1. Piecewise-linear tables (NPF, MERL grid)
have kinks between their nodes, where the rule converges only as h²: ≤ 3e-4 relative at
the defaults (every model of :func:`model_zoo`, α = 0.001 … 1, θi = 0 … 80°).

Importance sampling can use i.i.d. uniforms or, with ``stratified=True``, 16 independent
batches of jittered-grid uniforms whose standard error is that of the batch means (4-8×
smaller for the same number of samples; the tests use it to keep se below 0.25 % cheaply).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .brdf import (cosine_hemisphere_pdf, cosine_hemisphere_sample, jittered_grid,
                   stratified_square)

__all__ = ["albedo_quadrature", "albedo_sampled", "sampled_albedo", "hold_diffuse", "estimator_values",
           "stratified_uniforms", "sample_mean", "check", "FurnaceResult", "furnace"]


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
    return rng.permutation(jittered_grid(rng, side, dim))


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


def estimator_values(f, wo, pdf, infinite: float = 0.0) -> np.ndarray:
    """Per-sample ``f cos θo / pdf`` (0 where ``pdf`` is 0 or not finite, or ``wo`` is below
    the horizon), ``(N, 3)``; a NaN value counts as 0, an infinite one as ``infinite``."""
    f = np.asarray(f, np.float64)
    pdf = np.asarray(pdf, np.float64)
    cz = np.asarray(wo, np.float64)[:, 2]
    good = (pdf > 0) & np.isfinite(pdf) & (cz > 0)
    with np.errstate(invalid="ignore", over="ignore"):
        val = f * (np.where(good, cz, 0.0) / np.where(good, pdf, 1.0))[:, None]
    val = np.where(np.isinf(val), infinite, val)
    return np.where(good[:, None] & np.isfinite(val), val, 0.0)


def sampled_albedo(brdf, theta_i, n_samples: int = 4096, seed: int = 0
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Directional albedo ``a(θi) = ∫ f_r cos θo dωo`` of any BRDF and its standard error, both
    ``(len(theta_i), 3)``: ``mean(f_r cos θo / pdf)`` over the ``stratified_square`` points
    mapped by the BRDF's own ``sample`` (cosine sampling when it has none). The white furnace
    of a BRDF that conserves energy reads ≤ 1 at every θi. An infinite weight counts as 1e30,
    so that a singular BRDF fails the furnace instead of vanishing from it (the physical
    checks of :mod:`brdffit.evaluation.validity` and the ggx-diffuse fit's ρd hold use it)."""
    theta_i = np.atleast_1d(np.asarray(theta_i, dtype=np.float64))
    grid = stratified_square(n_samples, seed)
    mean = np.empty((theta_i.size, 3))
    se = np.empty((theta_i.size, 3))
    for k, t in enumerate(theta_i):
        wi = np.broadcast_to(_incident(float(t)), (grid.shape[0], 3))
        try:
            wo, pdf = brdf.sample(wi, grid)
        except (NotImplementedError, AttributeError):
            wo = cosine_hemisphere_sample(grid)
            pdf = cosine_hemisphere_pdf(wo)
        wo, pdf = np.asarray(wo, dtype=np.float64), np.asarray(pdf, dtype=np.float64)
        ok = (pdf > 0) & (wo[:, 2] > 0) & np.isfinite(pdf)
        f = np.zeros((wo.shape[0], 3))
        if ok.any():
            f[ok] = np.asarray(brdf.eval(wi[ok], wo[ok]), dtype=np.float64)
        w = estimator_values(f, wo, pdf, infinite=1e30)
        mean[k], se[k] = w.mean(0), w.std(0, ddof=1) / np.sqrt(w.shape[0])
    return mean, se


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


#: incidences (degrees) and samples of the furnace a fitted ρd is held to (:func:`hold_diffuse`)
HOLD_ANGLES_DEG = (0.0, 30.0, 45.0, 60.0, 70.0, 75.0, 80.0, 85.0, 88.0)
HOLD_SAMPLES = 4096


def hold_diffuse(rho_d, specular_lobes) -> tuple[np.ndarray, np.ndarray]:
    """``(ρd, lowering)``: ρd per channel lowered where ``ρd + Σ a_spec(θi)`` exceeds 1 at an
    incidence of :data:`HOLD_ANGLES_DEG`, so that the directional albedo of the lobes plus a
    Lambertian ρd/π stays ≤ 1 (the Lambertian term adds exactly ρd to it at every θi).
    ``a_spec`` is the lobes' albedo (:func:`sampled_albedo`, :data:`HOLD_SAMPLES` samples);
    a lobe with F ≤ 1 and a Smith G never exceeds 1 alone. Only ρd moves (the lobes are
    kept), the least change that holds the furnace; ``lowering`` is what was taken off."""
    angles = np.radians(HOLD_ANGLES_DEG)
    spec = sum(sampled_albedo(lobe, angles, HOLD_SAMPLES)[0] for lobe in specular_lobes)
    cap = np.clip(1.0 - spec.max(axis=0), 0.0, None)
    rho_d = np.asarray(rho_d, dtype=np.float64)
    held = np.minimum(rho_d, cap)
    return held, rho_d - held


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
