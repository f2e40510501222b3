"""Tabulated microfacet fit by power iteration (Dupuy, Heitz, Iehl, Poulin, Ostromoukhov 2015).

Pipeline of :func:`fit_tabulated`:

1. **Backscattering** ``b(o) = f_r(o, o)`` of the input (luminance, or one channel) at the
   elevation nodes of a radial rule (:func:`brdffit.microfacet.tabulated.radial_rule`) and, for
   anisotropic fits, at ``Nφ`` azimuths. For MERL-grid input with the ``"merl"`` rule and
   ``N = 90`` the nodes *are* the MERL ``θh`` samples at ``θd = 0`` (supplemental Eq. 20-22),
   so every backscattering sample is read once.
2. **Slope PDF** ``P``: the Fredholm equation ``F0 P(õ) = ∫ K(o, h) P(h̃) dωh`` with
   ``K = 4 f_r(o,o) cos⁵θo <o,h>₊ sec⁴θh`` (Eq. 14-15), discretised (Eq. 16-17) and solved by
   power iteration from all ones (Eq. 18, Algorithm 1). In slope space the kernel reads
   ``4 b(o) cos⁶θo (1 + õ·h̃)₊`` against ``dh̃``. Isotropic: the radial form (Eq. 21-23,
   Algorithm 3) with the azimuthal integral in closed form. Anisotropic: the 2D form on a
   ``(θ, φ)`` grid; the kernel is circulant in ``φ`` so ``K·p`` is an FFT convolution and the
   ``N² = 8100²`` matrix is never formed.
3. **Normalisation** (Eq. 8) of the *interpolated* P, continuous lookup, ``σ``/``G1``
   tables (Eq. 3) and sampling tables (Appendix A; visible normals for isotropic P):
   see :class:`~brdffit.microfacet.tabulated.TabulatedSlopeDistribution`. Roughness editing
   (Eq. 9, scalar or per-texel arrays):
   :func:`brdffit.microfacet.conversions.with_roughness`.
4. **Fresnel** per channel: ``F(θd) = E[f_r / f_r,id | θd]`` (Eq. 19-20) with
   ``f_r,id = D G2 / (4 cos θi cos θo)`` (Eq. 1 with F = 1 and the height-correlated Eq. 2),
   averaged over every valid MERL sample (supplemental Eq. 33-39) for isotropic input. For
   materials outside microfacet theory this is a *residual*, not a physical Fresnel
   reflectance (Dupuy 2015 §4.4); it is clamped to ``[0, fresnel_max]`` and never NaN. The
   paper's F is a ratio to the model and unbounded: on diffuse materials it absorbs the
   diffuse part and exceeds 1 (F0 up to 2 on RGL ``paper_white``); the default
   ``fresnel_max`` = 1 keeps a reflectance (with a Smith G and a normalised D, F ≤ 1 keeps
   the lobe's directional albedo ≤ 1).

The dominant eigenvalue is ``F0`` in the paper's notation (reported in ``fit_info``).

Deliberate deviations / options (documented in the parameters): a Gauss-Legendre radial rule
for accuracy (``rule="gauss"``, default for non-MERL input), the ``hotspot="G2"``
backscattering model (default) consistent with the height-correlated Smith term used for
rendering (the paper's Eq. 11 with G1 is ``hotspot="G1"``),
a **converged stop by default** and per-channel distributions.

**Convergence.** The paper runs 4 power iterations (Alg. 1). That is not converged on real
data (relative change still ~3.5e-3 on MERL materials, GGX round-trip α errors up to ~1 %), so
the default stops on a criterion instead: the relative change ``max|p_k − p_{k−1}| / max p_k``
of the normalised iterate ≤ ``tol`` = :data:`DEFAULT_TOL` (1e-6), with a safety cap of
``max_iterations`` (1000) reported in ``fit_info`` when hit (``converged``/``success`` False,
``cap_reached`` True, ``message``). The paper's fixed mode is ``iterations=4`` (``tol`` None).

Conversions to analytic roughness by slope moments (Appendix C) are in
:mod:`brdffit.microfacet.conversions`; :func:`fit_beckmann` and :func:`fit_ggx` fit and convert.
"""

from __future__ import annotations

import time

import numpy as np

from .._blas import with_single_blas_thread
from ..brdf import BRDF, IsotropicBRDF, cosine_pairs, measured_mask
from ..errors import FitError
from ..furnace import hold_diffuse
from ..geometry import half_diff_to_io
from ..grid import (N_PHI_D, N_THETA_H, merl_phi_d, merl_theta_d, merl_theta_h,
                    tabulate_merl_grid)
from ..losses.l2 import merl_grid_weights
from ..losses.objective import weighted_median
from ..microfacet.conversions import to_beckmann, to_ggx
from ..microfacet.per_channel import PerChannelBRDF
from ..microfacet.tabulated import (FittedFresnel, TabulatedSlopeDistribution,
                                    azimuthal_clamped_cosine_integral, radial_rule)
from .options import Hotspot, RadialRule, check_choice
from .result import record
from ..microfacet import MicrofacetBRDF

__all__ = ["fit_tabulated", "fit_ggx", "fit_beckmann", "solve_slope_pdf", "iteration_plan",
           "convergence_info", "extract_fresnel", "luminance", "backscatter", "DEFAULT_TOL",
           "PAPER_ITERATIONS"]

LUMINANCE_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709 / linear sRGB


def luminance(rgb) -> np.ndarray:
    """Rec. 709 luminance ``Y`` of linear RGB ``(..., 3)`` (the paper fits one distribution
    from a luminance of the backscatter, §3)."""
    return np.asarray(rgb, dtype=np.float64) @ LUMINANCE_WEIGHTS


def _channel(rgb, channel):
    rgb = np.asarray(rgb, dtype=np.float64)
    return luminance(rgb) if channel is None else rgb[..., int(channel)]


def _fill_invalid(u, b, ok, where: str):
    """Replace invalid backscattering samples by interpolation over the valid ones."""
    if np.all(ok):
        return b
    if not np.any(ok):
        raise FitError(f"{where}: no valid backscattering sample (expected finite values ≥ 0)")
    out = b.copy()
    if b.ndim == 1:
        out[~ok] = np.interp(u[~ok], u[ok], b[ok])
        return out
    for j in range(b.shape[1]):  # anisotropic: per azimuth column (Nφ ≤ a few hundred)
        okj = ok[:, j]
        if np.any(okj):
            out[~okj, j] = np.interp(u[~okj], u[okj], b[okj, j])
        else:
            out[:, j] = np.nan
    bad = ~np.isfinite(out)
    if np.any(bad):  # whole columns missing: azimuthal mean of the valid columns
        out[bad] = np.broadcast_to(np.nanmean(out, axis=1, keepdims=True), out.shape)[bad]
    return out


def backscatter(brdf: BRDF, theta, phi=None, rule: str | None = None):
    """RGB backscattering ``f_r(o, o)`` at elevations ``theta`` (and azimuths ``phi``).

    Returns ``(values, valid)``: ``(Nθ, 3)`` or ``(Nθ, Nφ, 3)`` and a boolean mask. A MERL
    table (``merl_table`` attribute) read at its own ``θh`` nodes (``rule="merl"``, N = 90)
    returns the stored samples ``(θh_k, θd = 0)`` with their validity; outside the
    measured domain (:meth:`brdffit.brdf.BRDF.measured`) values are marked invalid.
    """
    theta = np.asarray(theta, dtype=np.float64)
    table = getattr(brdf, "merl_table", None)
    if (table is not None and phi is None and rule == "merl" and theta.size == N_THETA_H):
        values, valid = table() if callable(table) else table
        vals = np.asarray(values[:, 0, 0, :], dtype=np.float64)
        ok = np.asarray(valid[:, 0, 0], dtype=bool) & np.all(np.isfinite(vals), -1)
        return vals, ok
    if phi is None:
        o = np.stack([np.sin(theta), np.zeros_like(theta), np.cos(theta)], -1)
    else:
        th, ph = np.meshgrid(theta, np.asarray(phi, dtype=np.float64), indexing="ij")
        o = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    vals = np.asarray(brdf.eval(o, o), dtype=np.float64)
    ok = np.all(np.isfinite(vals), -1)
    measured = measured_mask(brdf, o, o)
    return vals, ok if measured is None else ok & measured


#: Default stopping tolerance of the power iteration: the relative change
#: ``max|p_k − p_{k−1}| / max p_k`` of the normalised iterate (see :func:`solve_slope_pdf`).
#: Measured (bench/bench_tabulated.py, defaults): fit_ggx/fit_beckmann recover α within 6e-7
#: relative (isotropic) and 0.40 % (anisotropic: the 90 × 90 grid's limit) in ≤ 12 iterations; the
#: 100 Neural-BRDF MERL networks need 3-12 (median 10), the 7 RGL materials 4-9.
DEFAULT_TOL = 1e-6
#: Safety cap of the tolerance-based power iteration (reported in ``fit_info`` when hit).
DEFAULT_MAX_ITERATIONS = 1000
#: The paper's fixed number of power iterations (Dupuy 2015 §3.3/Alg. 1: "4 iterations").
PAPER_ITERATIONS = 4
CRITERION = "relative change max|p_k - p_(k-1)| / max p_k of the normalised slope PDF <= tol"


def iteration_plan(iterations: int | None = None, tol: float | None = None,
                   max_iterations: int = DEFAULT_MAX_ITERATIONS) -> tuple[int, float | None]:
    """``(cap, tol)`` of the power iteration for the user's ``iterations``/``tol``.

    * neither given (the default): iterate until the relative change is ≤ :data:`DEFAULT_TOL`,
      at most ``max_iterations`` (the safety cap);
    * ``tol`` only: the same with that tolerance;
    * ``iterations`` only (e.g. the paper's ``iterations=4``, or ``iterations=4, tol=None``):
      exactly ``iterations`` multiplications by ``K``, no tolerance (the paper's fixed mode);
    * both: stop at ``tol`` or after ``iterations``, whichever comes first.
    """
    if iterations is not None and int(iterations) < 1:
        raise ValueError(f"iterations must be ≥ 1 or None, got {iterations!r}")
    if tol is not None and not (np.isfinite(tol) and tol >= 0):
        raise ValueError(f"tol must be a finite number ≥ 0 or None, got {tol!r}")
    if iterations is None:
        return max(int(max_iterations), 1), (DEFAULT_TOL if tol is None else float(tol))
    return int(iterations), (None if tol is None else float(tol))


def convergence_info(changes, iterations: int | None, tol: float | None,
                     max_iterations: int = DEFAULT_MAX_ITERATIONS) -> dict:
    """The convergence report of one power iteration, in :class:`scipy.optimize.OptimizeResult`
    spirit: ``converged``, ``success``, ``status``, ``message``, ``criterion``, ``tol``,
    ``iterations`` (= ``nit``), ``max_iterations`` (the cap in force), ``cap_reached``,
    ``final_relative_change`` and ``relative_change`` (one value per iteration).

    In the fixed-iteration mode (``tol`` None) ``converged`` says whether the final change
    also meets :data:`DEFAULT_TOL`; ``success`` is True (the requested iterations were run).
    With a tolerance, ``success == converged`` and ``status`` is 1 when the cap was hit
    before the tolerance (scipy's "maximum number of iterations" status).
    """
    cap, tol_eff = iteration_plan(iterations, tol, max_iterations)
    changes = [float(c) for c in changes]
    last = changes[-1] if changes else float("nan")
    n = len(changes)
    if tol_eff is None:
        converged = bool(last <= DEFAULT_TOL)
        criterion = f"fixed number of iterations ({cap}, the paper's mode)"
        msg = (f"{n} fixed power iterations (Dupuy 2015 mode); final relative change {last:.2e}"
               f" {'≤' if converged else '>'} the default tolerance {DEFAULT_TOL:g}"
               f"{'' if converged else ': not converged'}")
        success, status, cap_reached = True, 0, False
    else:
        converged = bool(last <= tol_eff)
        criterion = CRITERION.replace("tol", f"tol = {tol_eff:g}")
        cap_reached = bool(not converged and n >= cap)
        if converged:
            msg = (f"converged: relative change {last:.2e} ≤ tol {tol_eff:g} after {n} power "
                   "iterations")
        else:
            msg = (f"NOT converged: the cap of {cap} power iterations was reached with relative "
                   f"change {last:.2e} > tol {tol_eff:g}")
        success, status = converged, (0 if converged else 1)
    return {"converged": converged, "success": bool(success), "status": status,
            "message": msg, "criterion": criterion, "tol": tol_eff, "iterations": n, "nit": n,
            "max_iterations": cap, "cap_reached": cap_reached, "final_relative_change": last,
            "relative_change": changes}


def _kernel(b, r, w_r, row, g2: bool):
    """``(apply, integral)``: the power iteration's operator ``p → K p`` and ``∫ p`` on the
    radial rule ``(r, w_r)`` (Eq. 16-18, 22-24; ``row`` = 4 b cos⁶θ; ``g2``: the
    height-correlated hotspot of :func:`solve_slope_pdf`)."""
    if b.ndim == 1:
        # K'_ij = 4 b_i cos⁶θi w_j J(tanθi tanθj)   (Eq. 23 in slope form, closed-form φ integral)
        J = azimuthal_clamped_cosine_integral(r[:, None] * r[None, :])
        if g2:
            J = 2.0 * J - 2.0 * np.pi
        K = row[:, None] * (J * w_r[None, :])

        def apply(p):
            return K @ p

        def integral(p):
            return 2.0 * np.pi * np.dot(w_r, p)
    else:
        n_phi = b.shape[1]
        dphi = 2.0 * np.pi * np.arange(n_phi) / n_phi
        k = np.maximum(1.0 + (r[:, None, None] * r[None, :, None]) * np.cos(dphi), 0.0)
        kh = np.fft.rfft(k, axis=-1)

        def integral(p):
            return float(np.sum(w_r[:, None] * p) * 2.0 * np.pi / n_phi)

        def apply(p):
            ph = np.fft.rfft(p * w_r[:, None], axis=-1)
            # einsum, not a batched matmul: the latter goes through multi-threaded OpenBLAS,
            # measured 200x slower (3.3 s vs 0.015 s CPU per solve) on a loaded 2-core machine
            s = np.fft.irfft(np.einsum("ijm,jm->im", kh, ph), n=n_phi, axis=-1)
            s *= 2.0 * np.pi / n_phi
            if g2:
                s = 2.0 * s - integral(p)
            return np.maximum(row * s, 0.0)

    return apply, integral


def solve_slope_pdf(b, rule: str = "merl", iterations: int | None = None,
                    tol: float | None = None, max_iterations: int = DEFAULT_MAX_ITERATIONS,
                    hotspot: Hotspot = "G2"):
    """Power iteration for the slope PDF from backscattering ``b`` (Eq. 14-18, Alg. 1/3).

    Parameters
    ----------
    b:
        Scalar backscattering at the nodes of ``radial_rule(len(b), rule)``: ``(N,)`` for
        the isotropic radial form (Eq. 22-24) or ``(Nθ, Nφ)`` (normal azimuth
        ``2πj/Nφ``) for the anisotropic form (Eq. 16-18).
    iterations, tol, max_iterations:
        Stopping rule (:func:`iteration_plan`). Default: iterate until the relative change
        ``max|p_k − p_{k−1}| / max p_k`` of the normalised iterate is ≤ ``tol``
        (:data:`DEFAULT_TOL` = 1e-6 when None), at most ``max_iterations`` (safety cap).
        ``iterations=4`` (``tol`` None): the paper's fixed 4 multiplications by ``K``.
        Both given: stop at ``tol`` or after ``iterations``.
    hotspot:
        ``"G1"``: backscattering ``F0 D G1 / (4 cos²)`` (Eq. 11-12, the paper). ``"G2"``:
        ``F0 D G2(o,o) / (4 cos²)`` with the height-correlated Eq. 2, i.e. consistent with
        rendering: ``F0 P = 4 b cos⁶ (2 S[P] − ∫P)``; the kernel stays positive since
        ``J ≥ 2π``, so Perron-Frobenius still applies (an extension, not in the paper).

    Returns ``(p, eigenvalue, changes)`` with ``p`` normalised (Eq. 8) by the rule and the
    relative change of every iteration (:func:`convergence_info` turns them into a report).
    """
    b = np.asarray(b, dtype=np.float64)
    n_theta = b.shape[0]
    _, theta, r, w_r = radial_rule(n_theta, rule)
    c = np.cos(theta)
    row = 4.0 * b * (c**6 if b.ndim == 1 else c[:, None] ** 6)
    check_choice("hotspot", hotspot, Hotspot)
    n_iter, tol = iteration_plan(iterations, tol, max_iterations)
    apply, integral = _kernel(b, r, w_r, row, hotspot == "G2")
    p = np.ones_like(b)
    p /= integral(p)
    changes: list[float] = []
    lam = float("nan")
    for _ in range(n_iter):
        q = apply(p)
        lam = integral(q)  # ∫ K p with ∫ p = 1: the eigenvalue estimate
        if not np.isfinite(lam) or lam <= 0:
            raise FitError("power iteration produced a zero or non-finite vector "
                           "(expected positive backscattering somewhere)")
        q = q / lam
        change = float(np.max(np.abs(q - p)) / np.max(q))
        changes.append(change)
        p = q
        if tol is not None and change <= tol:
            break
    return p, lam, changes


# ------------------------------------------------------------------------------------------
# Fresnel extraction (Eq. 19-20, supplemental Eq. 33-39)
# ------------------------------------------------------------------------------------------
def _sigma_of_cos(dist: TabulatedSlopeDistribution, m: int = 2048):
    """σ of an isotropic unit table tabulated on a uniform grid of ``cos θ`` ∈ [0, 1]."""
    cg = np.linspace(0.0, 1.0, m)
    sg = np.sqrt(np.maximum(1.0 - cg * cg, 0.0))
    w = np.stack([sg, np.zeros_like(cg), cg], -1)
    return dist._sigma_unit(w)


def _lookup_uniform(table, x):
    m = len(table) - 1
    xi = np.clip(x, 0.0, 1.0) * m
    i0 = np.minimum(xi.astype(np.int64), m - 1)
    f = xi - i0
    return table[i0] * (1.0 - f) + table[i0 + 1] * f


_SIGMA_M = 16384
_N_PHI_HALF = 91  # φd ≤ π/2: the MERL samples 0..90 (π − φd of sample k is sample 180 − k)
#: θh rows per block of :func:`_merl_fresnel_sums`: the geometry and the float64 weight of a
#: block (≈ 2 MB together) are made, used and reused block after block, where whole-grid
#: arrays (≈ 27 MB) would be page-faulted in by every process (a cold tabulated fit of a MERL
#: file: 23 ms instead of 52)
_ROWS_PER_BLOCK = 10


def _merl_geometry(rows: slice) -> dict:
    """Geometry of the MERL θh rows ``rows`` for ``φd ≤ π/2`` (shape ``(rows, 90, 91)``):
    ``cos θi``, ``cos θo`` (float32, φh = 0), lookup indices into a uniform ``cos θ``
    table, and the above-horizon mask. The other half follows by symmetry
    (:func:`_mirror_phi_d`)."""
    th, td, pd = merl_theta_h()[rows], merl_theta_d(), merl_phi_d()[:_N_PHI_HALF]
    # cos θi,o = cos θh cos θd ∓ sin θh sin θd cos φd computed in float32 (faster than
    # float64): |Δ| ≤ 1.2e-7 moves a lookup index by one on 0.04 % of the samples
    a = (np.cos(th)[:, None] * np.cos(td)[None, :]).astype(np.float32)[:, :, None]
    bb = ((np.sin(th)[:, None] * np.sin(td)[None, :]).astype(np.float32)[:, :, None]
          * np.cos(pd).astype(np.float32)[None, None, :])
    geo = {"ci": a - bb, "co": np.add(a, bb, out=bb)}
    for key in ("i", "o"):
        # nearest sample of a dense uniform table of σ(cos θ) (|Δcos| ≤ 3e-5)
        x = np.clip(geo["c" + key], 0.0, 1.0)
        x *= _SIGMA_M - 1
        geo["i" + key] = np.rint(x, out=x).astype(np.int16)
    geo["up"] = (geo["ci"] > 0) & (geo["co"] > 0)
    return geo


def _mirror_phi_d(half: np.ndarray) -> np.ndarray:
    """``(…, 180)`` from the ``φd ≤ π/2`` half ``(…, 91)`` of a quantity symmetric under
    ``φd → π − φd`` (the swap of θi and θo: sample ``k`` takes the value of ``180 − k``)."""
    full = np.empty(half.shape[:-1] + (N_PHI_D,), dtype=half.dtype)
    full[..., :_N_PHI_HALF] = half
    full[..., _N_PHI_HALF:] = half[..., _N_PHI_HALF - 2:0:-1]
    return full


def _weighted_sums_per_theta_d(values, weight, data_ok=None) -> np.ndarray:
    """``Σ_{θh, φd} values · weight`` per θd, ``(90, 3)``, counting only ``data_ok``
    samples when given (a sample left out may hold NaN)."""
    if all(values[..., c].flags["C_CONTIGUOUS"] for c in range(3)):  # channel-planar
        return np.stack([np.einsum("hdp,hdp->d", values[..., c] if data_ok is None
                                   else np.where(data_ok, values[..., c], 0.0), weight)
                         for c in range(3)], -1)
    v = values if data_ok is None else np.where(data_ok[..., None], values, 0.0)
    return np.matmul(weight[:, :, None, :], v)[:, :, 0, :].sum(0)  # channel-last


def _merl_fresnel_sums(values, valid, dist, p_floor, max_theta_deg):
    """Sums of ``f / f_id`` over the valid MERL samples of each θd and their counts.

    ``f/f_id = f · 4 cos⁴θh (σi co + σo ci − ci co) / P(θh)`` (Eq. 19-20; the
    height-correlated Smith ``G = 1/(1 + Λi + Λo)`` with ``σ = cos θ (1 + Λ)``, as the
    anisotropic branch). The geometric weight is symmetric under ``φd → π − φd``
    (θi ↔ θo), so it is computed on half the grid and mirrored, block after block of θh
    rows. A NaN/inf sample makes the sums non-finite: they are then recomputed without the
    non-finite samples.
    """
    th = merl_theta_h()
    sigma_tab = _sigma_of_cos(dist, _SIGMA_M).astype(np.float32)
    p_h = dist._p_unit_polar(np.tan(th))
    usable_h = p_h >= p_floor * p_h.max()
    scale = np.where(usable_h, 4.0 * np.cos(th) ** 4 / np.where(usable_h, p_h, 1.0),
                     0.0).astype(np.float32)
    c_min = None if max_theta_deg is None else np.float32(np.cos(np.radians(max_theta_deg)))
    values = np.asarray(values)
    n_h, n_d = values.shape[:2]

    def accumulate(data_ok):
        sums, counts = np.zeros((n_d, 3)), np.zeros(n_d, dtype=np.int64)
        for h0 in range(0, n_h, _ROWS_PER_BLOCK):
            rows = slice(h0, min(h0 + _ROWS_PER_BLOCK, n_h))
            geo = _merl_geometry(rows)
            ci, co = geo["ci"], geo["co"]
            weight = sigma_tab[geo["ii"]] * co
            weight += sigma_tab[geo["io"]] * ci
            weight -= ci * co
            weight *= scale[rows, None, None]
            usable = geo["up"] & usable_h[rows, None, None]
            if c_min is not None:
                usable &= (ci >= c_min) & (co >= c_min)
            weight[~usable] = 0.0
            ok = None if data_ok is None else data_ok[rows]
            sums += _weighted_sums_per_theta_d(values[rows],
                                               _mirror_phi_d(weight.astype(np.float64)), ok)
            if ok is None:  # every sample counts: twice each interior φd of the half grid
                per_phi = usable.sum(axis=0)
                counts += 2 * per_phi.sum(-1) - per_phi[:, 0] - per_phi[:, -1]
            else:
                counts += (_mirror_phi_d(usable) & ok).sum(axis=(0, 2))
        return sums, counts

    data_ok = None if valid is None or np.all(valid) else np.asarray(valid, dtype=bool)
    sums, counts = accumulate(data_ok)
    if not np.all(np.isfinite(sums)):  # NaN/inf samples (they propagate): invalid, not zeros
        finite = np.all(np.isfinite(values), axis=-1)
        sums, counts = accumulate(finite if data_ok is None else data_ok & finite)
    return sums, counts


def extract_fresnel(brdf: BRDF, dist: TabulatedSlopeDistribution, *, merl=None,
                    p_floor: float = 1e-6, fresnel_max: float = 100.0,
                    aniso_grid: tuple[int, int, int] = (16, 12, 16),
                    max_theta_deg: float | None = None) -> np.ndarray:
    """Microfacet Fresnel ``F(θd)`` per channel at the 90 MERL ``θd`` (Eq. 19-20).

    Isotropic: the mean of ``f_r/f_r,id`` over every valid MERL sample ``(θh, θd, φd)`` with
    both directions above the horizon (supplemental Eq. 33-39; the MERL table is read as
    stored when the input has one, else evaluated with :func:`brdffit.grid.tabulate_merl_grid`).
    Samples where the fitted ``P(θh)`` is below ``p_floor·max P`` are skipped (the ratio is
    undefined there), and so are samples with θi or θo above ``max_theta_deg`` when given. Anisotropic: the same mean over a ``(θh, φh, φd)`` grid of
    ``aniso_grid`` samples per θd (θh on the MERL u² spacing).

    This is a residual, not a physical Fresnel, when the input is not a microfacet BRDF
    (Dupuy 2015 §4.4). Returns ``(90, 3)``, clamped to ``[0, fresnel_max]``; θd rows with no
    usable sample copy the nearest row that has one.
    """
    td = merl_theta_d()
    if dist.isotropic and (merl is not None or getattr(brdf, "isotropic", False)):
        values, valid = merl if merl is not None else tabulate_merl_grid(brdf)
        sums, counts = _merl_fresnel_sums(values, valid, dist, p_floor, max_theta_deg)
    else:
        n_h, n_ph, n_pd = aniso_grid
        th = (np.arange(n_h) / n_h) ** 2 * (np.pi / 2)
        phh = 2.0 * np.pi * np.arange(n_ph) / n_ph
        pd = 2.0 * np.pi * np.arange(n_pd) / n_pd
        sums = np.zeros((len(td), 3))
        counts = np.zeros(len(td), dtype=np.int64)
        TH, PH, PD = np.meshgrid(th, phh, pd, indexing="ij")
        h = np.stack([np.sin(TH) * np.cos(PH), np.sin(TH) * np.sin(PH), np.cos(TH)], -1)
        D = dist.D(h)
        usable = D * np.cos(TH) ** 4 >= p_floor * float(dist.table.max())
        for j, t in enumerate(td):  # 90 θd slices, each fully vectorised
            wi, wo = half_diff_to_io(TH, PH, t, PD)
            ci, co = wi[..., 2], wo[..., 2]
            ok = (ci > 0) & (co > 0) & usable
            f = np.asarray(brdf.eval(wi, wo), dtype=np.float64)
            ok &= np.all(np.isfinite(f), -1)
            measured = measured_mask(brdf, wi, wo)
            if measured is not None:
                ok &= measured
            lam = dist.Lambda(wi) + dist.Lambda(wo)
            with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
                fid = D * 1.0 / (1.0 + lam) / (4.0 * ci * co)
                ratio = f / fid[..., None]
            ok &= np.isfinite(fid) & (fid > 0)
            sums[j] = np.sum(np.where(ok[..., None], ratio, 0.0), axis=(0, 1, 2))
            counts[j] = ok.sum()
    F = np.full((len(td), 3), np.nan)
    good = counts > 0
    if not np.any(good):
        raise FitError("Fresnel extraction: no usable sample (expected valid data where the "
                       "fitted NDF is non-zero)")
    F[good] = sums[good] / counts[good, None]
    idx = np.arange(len(td))
    nearest = np.array([idx[good][np.argmin(np.abs(idx[good] - i))] for i in idx])
    F = F[nearest]
    F = np.where(np.isfinite(F), F, 0.0)
    return np.clip(F, 0.0, fresnel_max)


# ------------------------------------------------------------------------------------------
# The fit
# ------------------------------------------------------------------------------------------
def _make_model(dist, F, name, source):
    return MicrofacetBRDF(dist, FittedFresnel(F), name=name, source=source)


def _fit_one(brdf, channel, *, n, n_phi, rule, iterations, tol, max_iterations, anisotropic,
             hotspot, merl, fresnel_kwargs):
    t0 = time.perf_counter()
    u, theta, _, _ = radial_rule(n, rule)
    if anisotropic:
        phi = 2.0 * np.pi * np.arange(n_phi) / n_phi
        rgb, ok = backscatter(brdf, theta, phi)
    else:
        rgb, ok = backscatter(brdf, theta, None, rule=rule)
    b = _channel(rgb, channel)
    ok = ok & np.isfinite(b)
    b = _fill_invalid(u, np.where(ok, b, 0.0), ok, getattr(brdf, "source", None) or
                      getattr(brdf, "name", "input"))
    b = np.maximum(b, 0.0)  # negative measurements (noise, networks) clamp at 0
    if not np.any(b > 0):
        raise FitError(f"{getattr(brdf, 'name', 'input')}: backscattering is zero everywhere "
                       "(expected a positive value somewhere)")
    t1 = time.perf_counter()
    p, lam, changes = solve_slope_pdf(b, rule=rule, iterations=iterations, tol=tol,
                                      max_iterations=max_iterations, hotspot=hotspot)
    dist = TabulatedSlopeDistribution(p, rule=rule)  # sampling tables: on first use
    t2 = time.perf_counter()
    F = extract_fresnel(brdf, dist, merl=merl, **fresnel_kwargs)
    t3 = time.perf_counter()
    info = {"eigenvalue": float(lam)}
    info.update(convergence_info(changes, iterations, tol, max_iterations))
    info.update({"time_backscatter": t1 - t0, "time_power_iteration": t2 - t1,
                 "time_fresnel": t3 - t2, "F0": float(luminance(F[0])),
                 "normalisation": float(dist._integral(dist.table))})
    return dist, F, info


_CONVERGENCE_KEYS = ("converged", "success", "status", "message", "criterion", "tol",
                     "iterations", "nit", "max_iterations", "cap_reached",
                     "final_relative_change")


def _merge_convergence(infos) -> dict:
    """Convergence report of a per-channel fit: all channels must converge; the worst channel
    (most iterations / largest final change) is reported, each channel's in ``channels``."""
    worst = max(infos, key=lambda i: (not i["converged"], i["final_relative_change"]))
    out = {k: worst[k] for k in _CONVERGENCE_KEYS}
    out.update({"converged": all(i["converged"] for i in infos),
                "success": all(i["success"] for i in infos),
                "cap_reached": any(i["cap_reached"] for i in infos),
                "iterations": max(i["iterations"] for i in infos),
                "nit": max(i["nit"] for i in infos),
                "final_relative_change": max(i["final_relative_change"] for i in infos),
                "message": "; ".join(f"{'RGB'[c]}: {i['message']}" for c, i in enumerate(infos)),
                "relative_change": worst["relative_change"]})
    return out


# ------------------------------------------------------------------------------------------
# The Lambertian term
# ------------------------------------------------------------------------------------------
#: Direction pairs of the ρd fit when the input has no MERL grid (cosine-distributed, in the
#: measured domain), and the offset of their sequence (the CLI's error estimate uses 0.5).
DIFFUSE_PAIRS, DIFFUSE_PAIRS_START = 16384, 0.25
#: On a MERL grid, ρd is fitted on the nodes of every θh, every 3rd θd from the 2nd and
#: every 8th φd (90 × 30 × 23 nodes; the CLI's error estimate reads the θd rows from the 1st).
DIFFUSE_THETA_D_ROWS, DIFFUSE_PHI_STRIDE = slice(1, None, 3), 8
#: At most this many refits of the lobe on ``f − ρd/π``; a refit is kept when it lowers the
#: error by more than ``DIFFUSE_MIN_GAIN`` (relative).
MAX_DIFFUSE_REFITS, DIFFUSE_MIN_GAIN = 6, 1e-3
#: A ρd below this (an albedo of 1e-4, far below any measurement's accuracy) is 0: no term.
DIFFUSE_MIN = 1e-4
#: Each refit after the first starts from ρd plus this multiple of the last change of ρd (the
#: plain iteration ρd ← π·median(f − f_lobe(ρd)) contracts by about 0.6 per step).
_STEP_GAIN = 1.5


class _WithoutLambert(BRDF):
    """``f − ρd/π``: what a Lambertian term ρd/π leaves of ``brdf`` to the microfacet lobe
    (the measured domain kept; a MERL table stays a table, read at its own samples)."""

    def __init__(self, brdf: BRDF, rho_d):
        self.brdf, self.offset = brdf, np.asarray(rho_d, dtype=np.float64) / np.pi
        self.name, self.source = getattr(brdf, "name", "brdf"), getattr(brdf, "source", None)
        self.measured_domain = getattr(brdf, "measured_domain", None)
        if callable(getattr(brdf, "merl_table", None)):
            self.merl_table = self._merl_table

    def _merl_table(self):
        values, valid = self.brdf.merl_table()
        return np.asarray(values, dtype=np.float64) - self.offset, valid

    def eval(self, wi, wo) -> np.ndarray:
        return np.asarray(self.brdf.eval(wi, wo), dtype=np.float64) - self.offset

    def measured(self, wi, wo) -> np.ndarray:
        return self.brdf.measured(wi, wo)


class _IsotropicWithoutLambert(_WithoutLambert, IsotropicBRDF):
    def eval_hd(self, theta_h, theta_d, phi_d) -> np.ndarray:
        return np.asarray(self.brdf.eval_hd(theta_h, theta_d, phi_d), np.float64) - self.offset

    def measured_hd(self, theta_h, theta_d, phi_d) -> np.ndarray:
        return self.brdf.measured_hd(theta_h, theta_d, phi_d)


def _without_lambert(brdf: BRDF, rho_d) -> _WithoutLambert:
    cls = _IsotropicWithoutLambert if isinstance(brdf, IsotropicBRDF) else _WithoutLambert
    return cls(brdf, rho_d)


def _set_diffuse(model, rho_d) -> None:
    for lobe in getattr(model, "models", [model]):      # a PerChannelBRDF: each channel's
        lobe.diffuse = None if not np.any(rho_d > 0) else np.array(rho_d, dtype=np.float64)


def _diffuse_data(brdf: BRDF, merl):
    """``(wi, wo, f, w)``: the pairs ρd is fitted on and their weights in the cosine-weighted
    L1 error. A MERL grid (``merl``): its valid nodes of :data:`DIFFUSE_THETA_D_ROWS` and
    every :data:`DIFFUSE_PHI_STRIDE`-th φd, weighted by
    :func:`brdffit.losses.l2.merl_grid_weights` (no evaluation of the input); else :data:`DIFFUSE_PAIRS` cosine-distributed pairs of the measured domain, each
    of weight 1."""
    if merl is not None:
        values, valid = merl
        rows, cols = DIFFUSE_THETA_D_ROWS, slice(None, None, DIFFUSE_PHI_STRIDE)
        w, (th, td, pd) = merl_grid_weights(DIFFUSE_PHI_STRIDE)
        w, td = w[:, rows], td[:, rows]
        values = np.asarray(values, dtype=np.float64)[:, rows, cols]
        keep = (np.asarray(valid, dtype=bool)[:, rows, cols] & (w > 0)
                & np.all(np.isfinite(values), -1))
        th, td, pd = (np.broadcast_to(a, keep.shape)[keep] for a in (th, td, pd))
        wi, wo = half_diff_to_io(th, 0.0, td, pd)
        return wi, wo, values[keep], w[keep]
    wi, wo = cosine_pairs(DIFFUSE_PAIRS, DIFFUSE_PAIRS_START)
    keep = measured_mask(brdf, wi, wo)
    if keep is not None:
        wi, wo = wi[keep], wo[keep]
    f = np.nan_to_num(np.asarray(brdf.eval(wi, wo), dtype=np.float64))
    return wi, wo, f, np.ones(len(wi))


def _split_diffuse(brdf: BRDF, model, info: dict, refit, merl=None):
    """``(model, info)`` with a Lambertian term ρd/π added to the fitted lobe.

    On the pairs of :func:`_diffuse_data`, ρd/π per channel is the weighted median of the
    residual ``f − f_lobe``: the constant that minimises the cosine-weighted L1 error, the
    product's error measure (0 below :data:`DIFFUSE_MIN`). While ρd > 0, the lobe is
    refitted on ``f − ρ/π`` (``refit(ρ)``, backscatter and Fresnel alike) and ρd taken
    again, with ``ρ`` the last ρd plus :data:`_STEP_GAIN` times its last change (an
    extrapolated fixed-point step); a refit is kept while it lowers the error on those pairs
    by more than :data:`DIFFUSE_MIN_GAIN`, at most :data:`MAX_DIFFUSE_REFITS` times. The
    final ρd is held by the white furnace (:func:`brdffit.furnace.hold_diffuse`; the error
    after the hold is the last of ``errors`` when it lowered ρd).

    Deviation from Dupuy 2015: the paper's model has no diffuse term, its Fresnel residual
    absorbs it (§4.4). With F ≤ 1 that energy would be lost; the term keeps it and the model
    physical. On materials that need none, ρd is 0 and the lobe is the paper's.
    """
    wi, wo, f, w = _diffuse_data(brdf, merl)
    scale = float((np.abs(f) * w[:, None]).sum())

    def with_lambert(lobe):
        f_lobe = np.nan_to_num(np.asarray(lobe.eval(wi, wo), dtype=np.float64))
        residual = f - f_lobe
        rho_d = np.pi * np.array([weighted_median(residual[:, c], w) for c in range(3)])
        rho_d = np.where(rho_d >= DIFFUSE_MIN, rho_d, 0.0)
        return rho_d, error_of(residual, rho_d)

    def error_of(residual, rho_d):
        return float((np.abs(residual - rho_d / np.pi) * w[:, None]).sum() / scale
                     if scale > 0 else 0.0)

    rho_d, error = with_lambert(model)
    errors, refits, step = [error], 0, None
    while refits < MAX_DIFFUSE_REFITS and np.any(rho_d > 0):
        target = rho_d if step is None else rho_d + step * _STEP_GAIN
        candidate, candidate_info = refit(np.maximum(target, 0.0))
        c_rho_d, c_error = with_lambert(candidate)
        errors.append(c_error)
        if c_error >= error * (1.0 - DIFFUSE_MIN_GAIN):
            break
        step = c_rho_d - rho_d
        model, info, rho_d, error = candidate, candidate_info, c_rho_d, c_error
        refits += 1
    lowered = np.zeros(3)
    if rho_d.any():
        rho_d, lowered = hold_diffuse(rho_d, [model])
        if lowered.any():
            f_lobe = np.nan_to_num(np.asarray(model.eval(wi, wo), dtype=np.float64))
            errors.append(error_of(f - f_lobe, rho_d))
    _set_diffuse(model, rho_d)
    info["diffuse"] = {"rho_d": rho_d.tolist(), "furnace_lowering": lowered.tolist(),
                       "refits": refits, "errors": errors, "pairs": int(len(w))}
    return model, info


@with_single_blas_thread
def fit_tabulated(brdf: BRDF, n: int = 90, iterations: int | None = None,
                  tol: float | None = None, anisotropic: bool | None = None,
                  per_channel: bool = False, n_phi: int = 90, rule: RadialRule = "auto",
                  hotspot: Hotspot = "G2", max_iterations: int = DEFAULT_MAX_ITERATIONS,
                  fresnel_max: float = 1.0, p_floor: float = 1e-6,
                  fresnel_max_theta_deg: float | None = 89.0, diffuse: bool = True) -> BRDF:
    """Fit the tabulated microfacet model of Dupuy et al. 2015 to ``brdf``.

    Parameters
    ----------
    brdf:
        Any :class:`~brdffit.brdf.BRDF` (MERL tables, networks, analytic models...).
    n, n_phi:
        Elevation nodes (paper: 90 for MERL, 360 for Table 1); azimuth nodes when 2D.
    iterations, tol, max_iterations:
        Stopping rule of the power iteration (:func:`iteration_plan`, module docstring's
        **Convergence**): by default converged, to ``tol`` (:data:`DEFAULT_TOL` when None)
        within ``max_iterations``; ``iterations=4`` (``tol`` None) is the paper's mode; both
        given: stop at ``tol`` or after ``iterations``.
    anisotropic:
        2D ``(θ, φ)`` fit (``n × n_phi``) or 1D radial fit; default ``not brdf.isotropic``.
    per_channel:
        One distribution per RGB channel (a ``PerChannelBRDF``); default one distribution
        from the luminance of the backscatter (the paper's choice).
    rule:
        Radial rule: ``"merl"`` (rectangles on θ = (π/2)u², supplemental Eq. 17-22),
        ``"gauss"`` (Gauss-Legendre in u: exact eigenvalue and moments, better for heavy
        tails) or ``"auto"``: ``"merl"`` for isotropic fits of MERL-grid input
        (``merl_table``) with ``n = 90`` (read at their own samples, supplemental Eq. 20-22),
        else ``"gauss"``.
    hotspot:
        Backscattering shadowing: ``"G2"`` (default; Eq. 2, the height-correlated term the
        model is evaluated with, so the fit reproduces the input's backscattering) or ``"G1"``
        (the paper's Eq. 11: α −2 % at GGX α = 0.2, −16 % at α = 0.8 on a G2 microsurface).
    fresnel_max:
        Upper clamp of the extracted Fresnel table. Default 1: a reflectance, which keeps the
        lobe's directional albedo ≤ 1; the paper's unbounded ratio (module docstring, step 4)
        is kept with ``fresnel_max`` > 1, and the validity checks then report it.
    p_floor:
        Samples where the fitted slope PDF is below ``p_floor · max P`` are left out of the
        Fresnel average (the ratio is undefined there).
    fresnel_max_theta_deg:
        Samples with θi or θo above this angle are left out of the Fresnel average (default
        89°, the cut of Bagher et al. 2016 Eq. 7-12; ``None`` uses every sample as the paper):
        measured tables are least reliable at grazing angles (docs/design/tabulated-fit.md).
    diffuse:
        Add a Lambertian term ρd/π for what the lobe cannot carry (default;
        :func:`_split_diffuse`): the least-absolute-deviation ρd of the residual, held by the
        white furnace, with the lobe refitted on ``f − ρd/π`` while that lowers the error.
        ``False``: the paper's lobe alone.

    Returns
    -------
    BRDF
        A ``MicrofacetBRDF(TabulatedSlopeDistribution, TabulatedFresnel, diffuse=ρd)`` (a
        ``PerChannelBRDF`` of three with ``per_channel=True``), physically valid by
        construction with the defaults (F ≤ 1, directional albedo ≤ 1), with
        ``fit_options`` and ``fit_info``: the eigenvalue (F0 of the paper), timings, the
        convergence report of :func:`convergence_info` and ``diffuse`` (ρd, the refits and
        the errors of :func:`_split_diffuse`). The sampling tables are built on first use.
    """
    t0 = time.perf_counter()
    check_choice("hotspot", hotspot, Hotspot)
    anisotropic = not bool(getattr(brdf, "isotropic", False)) if anisotropic is None else anisotropic
    rule, merl = _rule_and_grid(brdf, n, anisotropic, rule)
    _, tol_eff = iteration_plan(iterations, tol, max_iterations)  # validates early
    kw = dict(n=n, n_phi=n_phi, rule=rule, iterations=iterations, tol=tol,
              max_iterations=max_iterations, anisotropic=anisotropic, hotspot=hotspot,
              fresnel_kwargs={"fresnel_max": fresnel_max, "p_floor": p_floor,
                              "max_theta_deg": fresnel_max_theta_deg})
    model, info = _fit_channels(brdf, merl, per_channel, kw)
    if diffuse:
        model, info = _split_diffuse(brdf, model, info, _refit(brdf, merl, per_channel, kw),
                                     merl)
    info["time"] = info["time_total"] = time.perf_counter() - t0
    if merl is not None:
        info["merl_grid"] = True
    model.fit_options = _fit_options(kw, tol_eff, per_channel, diffuse)
    return record(model, info, success=info["success"], converged=info["converged"],
                  message=info["message"], nit=info["nit"], time=info["time"])


def _rule_and_grid(brdf: BRDF, n: int, anisotropic: bool, rule: str):
    """``(rule, merl)``: ``"auto"`` resolved (``"merl"`` for isotropic fits of MERL-grid input
    with ``n = 90``, else ``"gauss"``) and the MERL-grid table of an isotropic input of an
    isotropic fit (:func:`~brdffit.grid.tabulate_merl_grid`; else ``None``)."""
    check_choice("rule", rule, RadialRule)
    if rule == "auto":
        has_merl = getattr(brdf, "merl_table", None) is not None
        rule = "merl" if (has_merl and n == N_THETA_H and not anisotropic) else "gauss"
    merl = None
    if not anisotropic and getattr(brdf, "isotropic", False):
        merl = tabulate_merl_grid(brdf)
    return rule, merl


def _refit(brdf: BRDF, merl, per_channel: bool, kw: dict):
    """The refit of :func:`_split_diffuse`: ``refit(ρd)`` fits the lobe to ``f − ρd/π``."""
    def refit(rho_d):
        residual = (None if merl is None else
                    (merl[0] - np.asarray(rho_d) / np.pi, merl[1]))
        return _fit_channels(_without_lambert(brdf, rho_d), residual, per_channel, kw)

    return refit


def _fit_options(kw: dict, tol_eff, per_channel: bool, diffuse: bool) -> dict:
    """``fit_options`` of :func:`fit_tabulated` from the options ``kw`` of :func:`_fit_one`
    and the effective tolerance ``tol_eff``."""
    iterations, anisotropic, fresnel = kw["iterations"], kw["anisotropic"], kw["fresnel_kwargs"]
    return {
        "n": int(kw["n"]), "iterations": None if iterations is None else int(iterations),
        "tol": tol_eff, "anisotropic": bool(anisotropic), "per_channel": bool(per_channel),
        "n_phi": int(kw["n_phi"]) if anisotropic else None, "rule": kw["rule"],
        "hotspot": kw["hotspot"], "max_iterations": int(kw["max_iterations"]),
        "fresnel_max": fresnel["fresnel_max"], "p_floor": fresnel["p_floor"],
        "fresnel_max_theta_deg": fresnel["max_theta_deg"], "diffuse": bool(diffuse)}


def _fit_channels(data: BRDF, merl, per_channel: bool, kw: dict) -> tuple[BRDF, dict]:
    """``(model, fit_info)`` of :func:`_fit_one` on ``data`` (and its MERL grid ``merl``)
    with the options ``kw``: one distribution from the luminance, or one per channel in a
    :class:`PerChannelBRDF` (their convergence reports merged, :func:`_merge_convergence`)."""
    name = getattr(data, "name", "brdf")
    source = getattr(data, "source", None)
    if not per_channel:
        dist, F, info = _fit_one(data, None, merl=merl, **kw)
        return _make_model(dist, F, name, source), info
    models, infos = [], []
    for c in range(3):
        dist, F, info = _fit_one(data, c, merl=merl, **kw)
        models.append(_make_model(dist, F, f"{name}[{'RGB'[c]}]", source))
        infos.append(info)
    info = {"channels": infos, "eigenvalue": [i["eigenvalue"] for i in infos]}
    info.update(_merge_convergence(infos))
    return PerChannelBRDF(models, name=name, source=source), info


def fit_beckmann(brdf: BRDF, **kwargs) -> MicrofacetBRDF:
    """Beckmann fit by slope moments (Dupuy et al. 2015 App. C): :func:`fit_tabulated`, then
    :func:`~brdffit.microfacet.conversions.to_beckmann` (same Fresnel table).

    Parameters
    ----------
    brdf : BRDF
        Any BRDF (isotropic or not).
    **kwargs
        Every option of :func:`fit_tabulated` (``n``, ``iterations``, ``tol``,
        ``anisotropic``, ``rule``, ``max_iterations``, ...), for the tabulated fit the
        moments are taken from.

    Returns
    -------
    MicrofacetBRDF
        Beckmann(αx, αy, ρ) with the tabulated Fresnel; ``fit_info`` is the tabulated fit's
        (convergence of its power iteration).

    Examples
    --------
    >>> import brdffit
    >>> plastic = brdffit.synthetic("plastic-beckmann")       # Beckmann α = 0.18 + Lambert
    >>> round(float(brdffit.fit_beckmann(plastic).distribution.alpha_x), 2)
    1.03
    >>> round(float(brdffit.fit_beckmann_diffuse(plastic).distribution.alpha_x), 2)
    0.18

    The tabulated lobe is fitted to the backscattering, diffuse part included, and its slope
    moments keep much of that in the distribution (the Lambertian term of :func:`fit_tabulated`
    takes only what the lobe leaves); a material with a diffuse part is fitted by
    :func:`brdffit.fit.analytic.fit_beckmann_diffuse`.
    """
    return to_beckmann(fit_tabulated(brdf, **kwargs))


def fit_ggx(brdf: BRDF, **kwargs) -> MicrofacetBRDF:
    """GGX fit by slope moments (Dupuy et al. 2015 App. C): :func:`fit_tabulated`, then
    :func:`~brdffit.microfacet.conversions.to_ggx` (same Fresnel table); the parameters are
    those of :func:`fit_beckmann`. For an engine material fitted over the whole data with a
    Lambert term, see :func:`brdffit.fit.analytic.fit_ggx_diffuse`.

    Returns
    -------
    MicrofacetBRDF
        GGX(αx, αy, ρ) with the tabulated Fresnel; ``fit_info`` is the tabulated fit's.

    Examples
    --------
    >>> import brdffit
    >>> gold = brdffit.synthetic("gold-ggx")                  # GGX α = 0.12, conductor
    >>> round(float(brdffit.fit_ggx(gold).distribution.alpha_x), 3)
    0.12
    """
    return to_ggx(fit_tabulated(brdf, **kwargs))


# ------------------------------------------------------------------------------------------
# Summaries and registration with brdffit.fit.registry
# ------------------------------------------------------------------------------------------
def summary(model) -> dict:
    """Key figures of a tabulated / converted fit: eigenvalue (F0 of the paper), fitted
    α's (Appendix C conversions), Fresnel at normal incidence, iterations and time."""
    info = dict(getattr(model, "fit_info", None) or {})
    out: dict = {"model": None, "eigenvalue": info.get("eigenvalue"),
                 "iterations": info.get("iterations"),
                 "relative_change": (info.get("relative_change") or [None])[-1],
                 "converged": info.get("converged"),
                 "time_s": info.get("time")}
    if info.get("converged") is False:
        out["message"] = info.get("message")
    dist = getattr(model, "distribution", None)
    fres = getattr(model, "fresnel", None)
    if isinstance(dist, TabulatedSlopeDistribution):
        out["model"] = "tabulated"
        out["table"] = list(dist.table.shape)
        out["rule"] = dist.rule
        bx, by, br = dist.beckmann_parameters()
        gx, gy, gr = dist.ggx_parameters()
        out["beckmann_alpha"] = [bx, by, br]
        out["ggx_alpha"] = [gx, gy, gr]
    elif dist is not None:
        out["model"] = type(dist).__name__.lower()
        out["alpha"] = [getattr(dist, "alpha_x", None), getattr(dist, "alpha_y", None),
                        getattr(dist, "rho", None)]
    elif isinstance(model, PerChannelBRDF):
        out["model"] = "tabulated-per-channel"
        out["eigenvalue"] = info.get("eigenvalue")
        fres = None
        out["fresnel_0"] = [float(m.fresnel.eval(np.array(1.0))[c])
                            for c, m in enumerate(model.models)]
    if fres is not None:
        out["fresnel_0"] = np.asarray(fres.eval(np.array(1.0)), dtype=float).tolist()
    return out
