"""Shifted Gamma Distribution fit and the classic analytic fits (Bagher, Soler, Holzschuch 2012).

Paper: *Accurate fitting of measured reflectances using a Shifted Gamma micro-facet
distribution*, CGF 31(4) 2012 (``../shared/papers/004_*.txt``).

Model (Eq. 1, per colour channel c, each channel with its own distribution — §5.1)::

    f_c(i, o) = ρd_c/π + ρs_c/π · F_c(i·h) D_c(θh) G1_c(θi) G1_c(θo) / (cos θi cos θo)

with the generalised Schlick Fresnel ``F = F0 + (1 − F0)(1 − cos θd)⁵ − F1 cos θd`` (Eq. 11)
and the separable Smith shadowing of §3.2: the model
:class:`~brdffit.microfacet.sgd_model.PerChannelMicrofacetBRDF`.

Two-slice fit (§5.2), per channel
---------------------------------
1. Backscattering slice θd = 0 (``m_h(θh)``, Eq. 7): fit ``ρh = ρd/π + Fr/π · D G1²/cos²θh``
   minimising Eq. 12 ``Σ w_i (m_h − ρh)²`` over (ρd, Fr, α, p). **Deviation**: instead of
   Levenberg-Marquardt on all four parameters, ρd and Fr (which enter linearly) are
   eliminated by a non-negative linear least-squares solve inside the residual ("variable
   projection"), and the remaining (ln α, p) are found by a grid search (18 × 8, shared by
   the three channels) followed by bounded trust-region least squares
   (``scipy.optimize.least_squares``, TRF) from the three best local minima of the grid.
   Same minimiser, far more robust and faster. The paper
   does not give its weights ``w_i``; by default (``weighting="cosine"``) they are the
   §6.3 measure restricted to the slice, ``cos²θh · sin θh dθh`` (cell of the MERL θh node),
   so that step 1 approximates the error the paper reports; ``weighting="relative"`` uses
   relative residuals ``(m − ρh)/(m + ε)``, ε = 1e-3 max m (better on a few diffuse
   materials, worse on most).
2. Specular slice θh = 0 (``m_d(θd)``): ``ρs F(θd) = (m_d − ρd/π) π cos²θd / (D(0) G1²(θd))``
   with the step-1 values, discarding θd > 70° (§4.4), then Eq. 11 fitted to it. Written as
   ``ρs F = A(1 − cos) + B(1 − cos)⁵ + E cos`` (A = ρs F0, B = ρs(1 − F0), E = ρs(F0 − F1))
   the fit is linear; we solve it with NNLS (A, B, E ≥ 0 ⇔ 0 ≤ F0 ≤ 1 and F ≥ 0 on
   [0, π/2]) — **deviation** from the paper's LM, same least-squares objective — and
   ``F(π/2) = 1`` gives ``ρs = A + B``, ``F0 = A/ρs``, ``F1 = (A − E)/ρs``.

Safeguards (**deviations**, on by default; ``selection="slice", linear="slice",
bounded=False`` restores the procedure above exactly)
-----------------------------------------------------------------------------------------
Why: on materials whose θh = 0 ridge rises with θd much faster than the rest of the lobe (the
measured specular peak narrows towards grazing, which no Cook-Torrance model with a fixed D
reproduces), step 2 attributes that rise to ``F``, and where the ridge drops after 70° (the
decrease §4.4 mentions) Eq. 11 fitted below 70° still climbs to ``F(π/2) = 1``: the model
ends up orders of magnitude too large near grazing, with ρs (the grazing value, since
``F(π/2) = 1``) far above 1 and nothing bounding the albedo. Step 1's ``cos²θh sin θh``
weights also give the peak (θh < 5°) little weight. Hence, per channel:

1. **Bounded albedo** (``bounded=True``): the directional albedo ``ρd + a_spec(θi)`` must
   not exceed 1 at θi = 0, 30, 50, 65, 75, 82, 86, 89°. ``a_spec`` is linear in
   ``(A, B, E)``; its coefficients come from a stratified quadrature over normals sampled
   from ``D cos θh`` (:func:`_albedo_rows`), so the bound is linear and the fit a small QP
   (NNLS, then SLSQP when a bound is active). (The simpler sufficient bound ``ρd + (4/π)
   max ρs F ≤ 1`` rejects valid rough materials: shadowing keeps their albedo well below.)
2. **Candidates**: the distinct local minima of step 1 (the paper's fit, ``starts`` of them)
   plus the ``starts`` best local minima of the step-1 grid (18 × 8 (ln α, p)) scored as in 3.
3. **Linear part on the full data** (``linear="full"``): for each candidate (α, p), ρd and
   ``(A, B, E)`` (hence ρs, F0, F1 through ``F(π/2) = 1``, Eq. 11 unchanged) by weighted
   non-negative least squares (with the bound of 1.) on a subsampled MERL grid instead of the
   θh = 0 slice; the paper's Eq. 10 holds for every (i, o), Dupuy et al. 2015 (supplemental
   Eq. 33-39) likewise extract F from all MERL samples. ``linear="slice"`` keeps step 2.
4. **Selection** (``selection="full"``): the candidate with the smallest weighted error on
   that grid wins, rather than the smallest slice residual. Weights: Bagher, Snyder,
   Nowrouzezahrai 2016 Eq. 8 (volume form × cos θi cos θo × compressive weight; θi, θo ≤
   89°) as in :mod:`brdffit.losses.objective` (the §6.3 L2 weights alone let the few
   largest grazing values decide). Grid: all 90 θh, every 4th θd below 76° and every θd
   from 76° (grazing rows vary fast), every 15th φd (≈ 20 000 samples with θi, θo ≤ 89°).
   ``refine=k`` (default 1) then refines the k best candidates by bounded TRF on this
   error over (ln α[, p]), the linear part eliminated (variable projection, unbounded
   NNLS from the normal equations, G1 from :data:`_G1_SCAN_NODES`); the refined
   candidates are scored as the others and the lowest cost wins
   (docs/design/sgd-fit.md).

Remaining differences from the paper: (α, p) may come from the grid scan rather than the
step-1 optimum or its refinement, and ρd, ρs, F0, F1 come from
the full data; the slices still drive step 1.

Computation: the grid scan solves every node's non-negative linear least squares from its
4 × 4 normal equations, built for all 144 nodes with two matrix products over the samples
per channel (:func:`_scan_linear`; the refinement builds its own channel's only), with G1
interpolated from every 4th G1 node (≤ 4e-5 absolute; the scan only ranks nodes, the
candidates are then evaluated with the full table);
D is evaluated on the 90 θh nodes and the G1 interpolation cells are precomputed; the G1
tables of the fixed grid nodes are memoised for the process (:func:`clear_caches`); the
bounded candidate evaluations (albedo rows, QP) are pruned exactly — a candidate whose
unbounded cost (a lower bound of its bounded cost) exceeds the k-th best bounded cost found
(k = max(``refine``, 1)) cannot be among the k best; shapes and G1 tables are shared by the
channels; the G1 of the search evaluate Eq. 6's integrand directly
(``sgd_mu_lambda(small_z_series=False)``, ≈ 1e-13 relative); the Eq. 9 approximation is
fitted with its analytic Jacobian.

Convergence report (``fit_info``, fields as the tabulated fit's): the iterative parts are
the step-1 local least-squares runs; ``converged`` says every run stopped on its tolerance
rather than its ``max_nfev`` cap (:func:`_sgd_convergence`).
Eq. 11 with ``F(π/2) = 1`` can report ``F0 = 1, F1 < 0`` (``ρs F`` decreasing towards
grazing, the §4.4 drop); the product ``ρs F`` is what the data determine.

The same procedure fits Beckmann and GGX (:func:`fit_beckmann_two_slice`,
:func:`fit_ggx_two_slice`; parameter α only, the paper's "our fitting method" of §6.3), and
:func:`fit_cook_torrance` is a full-data weighted least-squares fit of the same model with a
Beckmann/GGX distribution and Schlick Fresnel (F1 = 0) on a subsampled MERL grid, weighted by
the §6.3 quadrature weights (so it minimises the normalised L2 error directly).

G1 of the SGD comes from Eq. 6 by numerical quadrature (a table per channel, see
:class:`~brdffit.microfacet.sgd.SGD`); the fitted model also stores the Eq. 9 approximation
``(λ, c, k, θ0)`` per channel (``model.g1_approx``; ``g1="approx"`` evaluates with it).

Importance sampling (§4.5): lobe selection with probabilities proportional to ρd (diffuse,
cosine sampling) and ρs_c (specular lobe of channel c); the specular lobe of an SGD channel
samples the GGX distribution of the same α (the paper's proposal, since the SGD radial CDF
has no closed-form inverse), Beckmann/GGX channels sample their own distribution; the pdf
is the exact mixture density, so ``eval``/``sample``/``pdf`` are consistent.

Robustness: all parameters are bounded, initial values come from the data (grid search),
several starts are refined, non-finite data are masked; :class:`~brdffit.errors.FitError`
is raised only when no valid data or no finite solution exists. Never returns NaN.

Design notes (the diagnosis behind the safeguards, measured figures): docs/design/sgd-fit.md
"""

from __future__ import annotations

import functools
import time

import numpy as np
from scipy import optimize, special

from .._blas import with_single_blas_thread
from ..errors import FitError
from ..geometry import half_diff_to_io, slope_to_normal
from ..grid import merl_node_values, merl_phi_d, merl_theta_d, merl_theta_h
from ..microfacet.beckmann import Beckmann
from ..microfacet.gamma import upper_gamma
from ..microfacet.ggx import GGX
from ..microfacet.sgd import SGD, sgd_log_p22, sgd_mu_lambda
from ..microfacet.sgd_model import PerChannelMicrofacetBRDF
from .options import SliceOrFull, Weighting, check_choice
from .result import record
from ..losses.l2 import merl_grid_weights
from ..losses.objective import compressive_weight, volume_form_weight, weighted_median

__all__ = ["fit_sgd", "fit_beckmann_two_slice", "fit_ggx_two_slice", "fit_cook_torrance",
           "fit_beckmann_ct", "fit_ggx_ct", "fit_two_slice", "summary"]

_CHANNELS = ("r", "g", "b")
ALPHA_BOUNDS = {"sgd": (1e-4, 3.0), "beckmann": (1e-3, 3.0), "ggx": (1e-4, 3.0)}
P_BOUNDS = (-2.0, 4.0)
THETA_D_MAX = np.radians(70.0)          # §4.4: Fresnel data beyond 70° are discarded


# ------------------------------------------------------------------------------------------
# 1D microfacet terms (isotropic, as functions of θ) for the fits
# ------------------------------------------------------------------------------------------
def _sgd_log_norm(alpha: float, p: float) -> float:
    """``ln(α Γ(1−p, α))`` (memoised: a shape and its G1 nodes need the same one)."""
    return _log_norm_of(float(alpha), float(p))


@functools.lru_cache(maxsize=64)
def _log_norm_of(alpha: float, p: float) -> float:
    return float(np.log(alpha) + np.log(upper_gamma(1.0 - p, alpha)))


def _D_theta(kind: str, theta, alpha: float, p: float | None = None,
             log_norm: float | None = None) -> np.ndarray:
    """``D(θ)`` of Table 1 / §4.2 (``∫ D cos dω = 1``), θ in [0, π/2)."""
    theta = np.asarray(theta, dtype=np.float64)
    c = np.cos(theta)
    t2 = np.tan(theta) ** 2
    if kind == "sgd":
        return np.exp(sgd_log_p22(t2, alpha, p, log_norm)) / (np.pi * c**4)
    if kind == "beckmann":
        return np.exp(-t2 / alpha**2) / (np.pi * alpha**2 * c**4)
    if kind == "ggx":
        return alpha**2 / (np.pi * c**4 * (alpha**2 + t2) ** 2)
    raise ValueError(f"unknown distribution {kind!r}; expected 'sgd', 'beckmann' or 'ggx'")


def _G1_theta(kind: str, theta, alpha: float, p: float | None = None,
              log_norm: float | None = None) -> np.ndarray:
    """Smith ``G1(θ) = 1/(1 + Λ)`` (Eq. 6; closed forms for Beckmann and GGX)."""
    theta = np.asarray(theta, dtype=np.float64)
    ok = theta < np.pi / 2 - 1e-12
    th = np.where(ok, theta, 0.0)
    s = np.sin(th)
    with np.errstate(divide="ignore", invalid="ignore"):
        mu = np.where(s > 0, np.cos(th) / np.where(s > 0, s, 1.0), np.inf)
    if kind == "sgd":
        need = ok & (mu * mu < alpha * (62.0 + 4.0 * abs(p)))
        f = np.zeros_like(mu)
        if need.any():
            f[need] = sgd_mu_lambda(mu[need], alpha, p, h=0.3, log_norm=log_norm,
                                    small_z_series=False)
        with np.errstate(invalid="ignore"):
            g = np.where(need, mu / (mu + f), 1.0)
    else:
        a = mu / alpha
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            if kind == "beckmann":
                lam = np.where(a < 30, 0.5 * (np.exp(-a * a) / (a * np.sqrt(np.pi))
                                              - special.erfc(a)), 0.0)
            elif kind == "ggx":
                lam = 0.5 * (np.sqrt(1.0 + 1.0 / (a * a)) - 1.0)
            else:
                raise ValueError(f"unknown distribution {kind!r}")
            g = np.where(np.isinf(a), 1.0, 1.0 / (1.0 + lam))
    return np.where(ok, g, 0.0)


def _make_distribution(kind: str, alpha: float, p: float | None = None):
    if kind == "sgd":
        return SGD(alpha, p)
    if kind == "beckmann":
        return Beckmann(alpha)
    if kind == "ggx":
        return GGX(alpha)
    raise ValueError(f"unknown distribution {kind!r}")


# ------------------------------------------------------------------------------------------
# data
# ------------------------------------------------------------------------------------------
def _clean(v: np.ndarray, valid: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    v = np.asarray(v, dtype=np.float64)
    ok = np.isfinite(v)
    if valid is not None:
        ok &= valid
    return np.where(ok, np.maximum(v, 0.0), 0.0), ok


def _node_values(brdf, ih, jd):
    """The φd = 0 nodes ``θh[ih] × θd[jd]`` flattened: values ``(n, 3)``, measured ``(n, 1)``."""
    v, measured = merl_node_values(brdf, ih, jd, [0])
    return v.reshape(-1, v.shape[-1]), measured.reshape(-1, 1)


def two_slices(brdf) -> dict[str, np.ndarray]:
    """The θd = 0 slice ``m_h(θh)`` and the θh = 0 slice ``m_d(θd)`` on the MERL nodes.

    A measured MERL table (``merl_table``) is sliced directly (mean over its valid φd
    samples, invalid samples masked); any other isotropic BRDF is evaluated with
    ``eval_hd`` (negative values, e.g. of Neural-BRDF networks, are clamped at 0).
    Returns ``theta_h, m_h, valid_h`` (90, 90×3) and ``theta_d, m_d, valid_d``.
    """
    th, td = merl_theta_h(), merl_theta_d()
    table = getattr(brdf, "merl_table", None)
    if table is not None:
        values, valid = table() if callable(table) else table
        values = np.asarray(values, dtype=np.float64)
        out = {}
        for key, sl in (("h", (slice(None), 0)), ("d", (0, slice(None)))):
            v = values[sl]                            # (90, 180, 3)
            ok = np.asarray(valid)[sl][..., None] & np.isfinite(v) & (v >= 0)
            n = ok.sum(axis=1)
            mean = np.where(n > 0, np.where(ok, v, 0.0).sum(axis=1) / np.maximum(n, 1), 0.0)
            out["m_" + key], out["valid_" + key] = mean, n > 0
        m_h, valid_h, m_d, valid_d = out["m_h"], out["valid_h"], out["m_d"], out["valid_d"]
    else:
        if not getattr(brdf, "isotropic", False) or not hasattr(brdf, "eval_hd"):
            raise FitError(f"{getattr(brdf, 'name', brdf)!r}: the two-slice fit needs an "
                           f"isotropic BRDF with eval_hd, found {type(brdf).__name__}")
        m_h, valid_h = _clean(*_node_values(brdf, slice(None), [0]))
        m_d, valid_d = _clean(*_node_values(brdf, [0], slice(None)))
    return {"theta_h": th, "m_h": m_h, "valid_h": valid_h,
            "theta_d": td, "m_d": m_d, "valid_d": valid_d}


# ------------------------------------------------------------------------------------------
# linear sub-problems
# ------------------------------------------------------------------------------------------
def _nnls2(b: np.ndarray, y: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per column c: min_{a, f ≥ 0} Σ w² (y − a/π − f b)²; returns (coef (C, 2), cost (C,)).

    ``b`` (n,), ``y`` and ``w`` (n, C). Exact 2-variable NNLS (closed form, vectorised).
    """
    c1 = np.full(b.shape, 1.0 / np.pi)[:, None] * w
    c2 = b[:, None] * w
    yw = y * w
    s11 = np.sum(c1 * c1, 0)
    s22 = np.sum(c2 * c2, 0)
    s12 = np.sum(c1 * c2, 0)
    t1 = np.sum(c1 * yw, 0)
    t2 = np.sum(c2 * yw, 0)
    det = s11 * s22 - s12 * s12
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (s22 * t1 - s12 * t2) / det
        f = (s11 * t2 - s12 * t1) / det
        a_only = np.maximum(t1 / s11, 0.0)
        f_only = np.where(s22 > 0, np.maximum(t2 / s22, 0.0), 0.0)
    cand = [np.stack([a, f], -1), np.stack([a_only, 0 * a], -1), np.stack([0 * f, f_only], -1)]
    best_cost, best = None, None
    for k, cf in enumerate(cand):
        feasible = np.all(np.isfinite(cf), -1) & np.all(cf >= 0, -1) if k == 0 \
            else np.all(np.isfinite(cf), -1)
        cf = np.where(np.isfinite(cf), cf, 0.0)
        r = yw - c1 * cf[None, :, 0] - c2 * cf[None, :, 1]
        cost = np.where(feasible, np.sum(r * r, 0), np.inf)
        if best is None:
            best, best_cost = cf, cost
        else:
            better = cost < best_cost
            best = np.where(better[:, None], cf, best)
            best_cost = np.where(better, cost, best_cost)
    return best, best_cost


def _nnls2_single(b: np.ndarray, y: np.ndarray, w: np.ndarray) -> tuple[float, float]:
    """:func:`_nnls2` for one channel (1D ``y``, ``w``), without the batch overhead (it runs
    inside the step-1 least squares): the same three candidates — both free (feasible when
    finite and ≥ 0), ``f = 0`` and ``a = 0`` (feasible when finite, with ``_nnls2``'s
    convention that they are not when the joint solution is not finite) — and the same
    choice (smallest residual, first on ties; ``(0, 0)`` when none is feasible)."""
    c1 = w * (1.0 / np.pi)
    c2 = b * w
    yw = y * w
    s11, s22, s12 = np.float64(c1 @ c1), np.float64(c2 @ c2), np.float64(c1 @ c2)
    t1, t2 = np.float64(c1 @ yw), np.float64(c2 @ yw)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        det = s11 * s22 - s12 * s12
        a = (s22 * t1 - s12 * t2) / det
        f = (s11 * t2 - s12 * t1) / det
        a_only = np.maximum(t1 / s11, 0.0)
        f_only = np.maximum(t2 / s22, 0.0) if s22 > 0 else np.float64(0.0)
    fin_a, fin_f = bool(np.isfinite(a)), bool(np.isfinite(f))
    cands = ((a, f, fin_a and fin_f and a >= 0 and f >= 0),
             (a_only, 0.0, bool(np.isfinite(a_only)) and fin_a),
             (0.0, f_only, fin_f and bool(np.isfinite(f_only))))
    best, best_cost = (0.0, 0.0), np.inf
    for ca, cf, ok in cands:
        if not ok:
            continue
        r = yw - c1 * ca - c2 * cf
        cost = float(r @ r)
        if cost < best_cost:
            best, best_cost = (float(ca), float(cf)), cost
    return best


def _nnls2_costs(B: np.ndarray, y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """:func:`_nnls2` costs ``(G, C)`` for ``G`` basis functions ``B`` ``(G, n)`` at once
    (same closed form, vectorised over the basis functions)."""
    c1 = np.full(B.shape[1], 1.0 / np.pi)[:, None] * w          # (n, C)
    c2 = B[:, :, None] * w[None]                                # (G, n, C)
    yw = y * w
    s11 = np.sum(c1 * c1, 0)                                    # (C,)
    s22 = np.sum(c2 * c2, 1)                                    # (G, C)
    s12 = np.einsum("nc,gnc->gc", c1, c2)
    t1 = np.sum(c1 * yw, 0)
    t2 = np.einsum("gnc,nc->gc", c2, yw)
    yy = np.sum(yw * yw, 0)
    det = s11 * s22 - s12 * s12
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (s22 * t1 - s12 * t2) / det
        f = (s11 * t2 - s12 * t1) / det
        a_only = np.broadcast_to(np.maximum(t1 / s11, 0.0), s22.shape)
        f_only = np.where(s22 > 0, np.maximum(t2 / np.where(s22 > 0, s22, 1.0), 0.0), 0.0)
    best = None
    for k, (ca, cf) in enumerate(((a, f), (a_only, 0.0 * a), (0.0 * f, f_only))):
        ok = np.isfinite(ca) & np.isfinite(cf)
        if k == 0:
            ok &= (ca >= 0) & (cf >= 0)
        ca, cf = np.where(np.isfinite(ca), ca, 0.0), np.where(np.isfinite(cf), cf, 0.0)
        # ‖yw − ca c1 − cf c2‖² from the sums (exact expansion of the residual)
        cost = (yy - 2 * ca * t1 - 2 * cf * t2 + ca * ca * s11 + 2 * ca * cf * s12
                + cf * cf * s22)
        cost = np.where(ok, np.maximum(cost, 0.0), np.inf)
        best = cost if best is None else np.minimum(best, cost)
    return best


def _fresnel_nnls(c: np.ndarray, y: np.ndarray, rho_d: float | None = None,
                  rows: np.ndarray | None = None) -> tuple[float, float, float]:
    """Fit ``ρs F = A(1−c) + B(1−c)⁵ + E c`` (Eq. 11 reparametrised), A, B, E ≥ 0.

    Returns ``(A, B, E)``. With ``rho_d`` and albedo ``rows`` (:func:`_albedo_rows`), also
    ``ρd + rows · (A, B, E) ≤ 1`` (bounded directional albedo).
    """
    M = _fresnel_columns(c)
    if rho_d is None or rows is None:
        return tuple(float(v) for v in _bounded_lsq(M, y))
    caps = np.full(len(rows), max(1.0 - rho_d, 0.0))
    return tuple(float(v) for v in _bounded_lsq(M, y, rows[:, 1:], caps))


# ------------------------------------------------------------------------------------------
# two-slice fit
# ------------------------------------------------------------------------------------------
def _weights(kind_w: str, theta: np.ndarray, m: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Per-sample weights (n, 3) of Eq. 12 (square roots of w_i, applied to residuals);
    ``kind_w`` checked by :func:`_check_two_slice_choices`."""
    if kind_w == "relative":
        eps = 1e-3 * np.maximum(np.max(np.where(valid, m, 0.0), axis=0), 1e-12)
        w = 1.0 / (m + eps[None, :])
    else:
        # §6.3-like: cos θi cos θo = cos²θh at θd = 0, solid angle of the θh cell
        u = np.sqrt(theta / (np.pi / 2))
        du = 1.0 / len(theta)
        w = np.sqrt(np.cos(theta) ** 2 * np.sin(np.maximum(theta, 1e-6)) * np.pi * u * du)
        w = np.repeat(w[:, None], m.shape[1], axis=1)
    return np.where(valid, w, 0.0)


def _basis_h(kind, theta, alpha, p, g1=None):
    """``D G1² / (π cos²θh)`` of Eq. 7 (the Fr/π factor's function); ``g1``: precomputed
    ``G1(theta)`` (:func:`_grid_g1`)."""
    ln = _sgd_log_norm(alpha, p) if kind == "sgd" else None
    if g1 is None:
        g1 = _G1_theta(kind, theta, alpha, p, ln)
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        b = _D_theta(kind, theta, alpha, p, ln) * g1 ** 2 / (np.pi * np.cos(theta) ** 2)
    return np.where(np.isfinite(b), b, 0.0)


#: G1 tables of the fixed (α, p) nodes of the step-1 grid / grid scan (:func:`_grid_axes`),
#: at the MERL θh nodes and at :data:`_G1_SCAN_NODES`. Pure functions of constants, so they
#: are kept for the process (≤ 216 entries of 283 floats): a batch computes them once.
_GRID_G1: dict = {}


def clear_caches() -> None:
    """Forget the memoised grid G1 tables (benchmarks time fits from a cold start)."""
    _GRID_G1.clear()


def _grid_g1(kind: str, alpha: float, p: float | None) -> tuple[np.ndarray, np.ndarray]:
    """``(G1 at merl_theta_h(), G1 at _G1_SCAN_NODES)`` of a grid node, memoised."""
    key = (kind, float(alpha), None if p is None else float(p))
    hit = _GRID_G1.get(key)
    if hit is None:
        th = merl_theta_h()
        ln = _sgd_log_norm(alpha, p) if kind == "sgd" else None
        g = _G1_theta(kind, np.concatenate([th, _G1_SCAN_NODES]), alpha, p, ln)
        hit = (g[:len(th)], g[len(th):])
        if len(_GRID_G1) < 4096:
            _GRID_G1[key] = hit
    return hit


def _grid_starts(cost: np.ndarray) -> np.ndarray:
    """Flat indices of the grid's local minima (8-neighbourhood), best first, then the rest."""
    c = np.where(np.isfinite(cost), cost, np.inf)
    pad = np.pad(c, 1, constant_values=np.inf)
    n0, n1 = c.shape
    is_min = np.ones_like(c, dtype=bool)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di or dj:
                is_min &= c <= pad[1 + di:1 + di + n0, 1 + dj:1 + dj + n1]
    flat = c.ravel()
    mins = np.nonzero(is_min.ravel() & np.isfinite(flat))[0]
    mins = mins[np.argsort(flat[mins])]
    rest = np.setdiff1d(np.argsort(flat), mins, assume_unique=True)
    rest = rest[np.argsort(flat[rest])]
    return np.concatenate([mins, rest])


def _step1(kind: str, theta, m, w, n_grid: tuple[int, int], starts: int):
    """Fit (ρd, Fr, α[, p]) per channel to the θd = 0 slice (Eq. 7, 12)."""
    a_lo, a_hi = ALPHA_BOUNDS[kind]
    la, ps = _grid_axes(kind, n_grid)
    grid = [(lga, p) for lga in la for p in ps]
    merl_nodes = theta.shape == merl_theta_h().shape and np.array_equal(theta, merl_theta_h())
    B = np.stack([_basis_h(kind, theta, np.exp(lga), p,
                           _grid_g1(kind, float(np.exp(lga)), p)[0] if merl_nodes else None)
                  for lga, p in grid])
    costs = _nnls2_costs(B, m, w)                             # (G, 3)
    results = []
    for c in range(m.shape[1]):
        wc, mc = w[:, c:c + 1], m[:, c:c + 1]

        def resid(q):
            alpha = np.exp(q[0])
            p = q[1] if kind == "sgd" else None
            b = _basis_h(kind, theta, alpha, p)
            a_, f_ = _nnls2_single(b, mc[:, 0], wc[:, 0])
            r = (mc[:, 0] - a_ / np.pi - f_ * b) * wc[:, 0]
            return np.where(np.isfinite(r), r, 1e6)

        order = _grid_starts(costs[:, c].reshape(len(la), len(ps)))
        best, found, runs = None, [], []
        tried = 0
        for gi in order:
            if tried >= starts:
                break
            if not np.isfinite(costs[gi, c]):
                continue
            tried += 1
            lga, p = grid[gi]
            q0 = np.array([lga] if kind != "sgd" else [lga, p])
            lo = [np.log(a_lo)] + ([P_BOUNDS[0]] if kind == "sgd" else [])
            hi = [np.log(a_hi)] + ([P_BOUNDS[1]] if kind == "sgd" else [])
            try:
                res = optimize.least_squares(resid, q0, bounds=(lo, hi), method="trf",
                                             x_scale=1.0, diff_step=1e-4,
                                             xtol=STEP1_XTOL, ftol=STEP1_FTOL,
                                             max_nfev=STEP1_MAX_NFEV)
                x, cost = res.x, res.cost
                runs.append(_run_record(res))
            except (ValueError, FloatingPointError, np.linalg.LinAlgError) as exc:
                x, cost = q0, 0.5 * costs[gi, c]
                runs.append({"status": -1, "nfev": 0, "converged": False,
                             "message": f"{type(exc).__name__}: {exc}"})
            if not np.isfinite(cost):
                continue
            found.append((x, cost))
            if best is None or cost < best[1]:
                best = (x, cost)
        if best is None:
            raise FitError(f"step 1 (θd = 0 slice) found no finite {kind} fit for channel "
                           f"{_CHANNELS[c]}")
        cands = []
        for x, cost in sorted(found, key=lambda t: t[1]):
            if any(np.all(np.abs(x - y["x"]) < 1e-3) for y in cands):
                continue                                    # same local minimum twice
            alpha = float(np.exp(x[0]))
            p = float(x[1]) if kind == "sgd" else None
            b = _basis_h(kind, theta, alpha, p)
            coef, _ = _nnls2(b, mc, wc)
            cands.append({"x": x, "alpha": alpha, "p": p, "rho_d": float(coef[0, 0]),
                          "Fr": float(coef[0, 1]), "cost1": float(cost)})
        best = dict(cands[0])
        best["candidates"] = [{k: v for k, v in cd.items() if k != "x"} for cd in cands]
        best["runs"] = runs
        best.pop("x")
        results.append(best)
    return results


#: Step-1 local least squares (scipy TRF): termination tolerances and evaluation cap
STEP1_XTOL, STEP1_FTOL, STEP1_MAX_NFEV = 1e-10, 1e-12, 80


def _run_record(res) -> dict:
    """Convergence record of one ``scipy.optimize.least_squares`` run: status ≥ 1 is a
    tolerance stop (gtol/ftol/xtol), 0 the ``max_nfev`` cap."""
    return {"status": int(res.status), "nfev": int(res.nfev), "converged": bool(res.status > 0),
            "optimality": float(res.optimality), "message": str(res.message)}


def _step2(kind: str, theta_d, m_d, valid_d, s1: dict, rows: np.ndarray | None = None
           ) -> tuple[float, float, float]:
    """``(A, B, E)`` of Eq. 11 from the θh = 0 slice (§5.2 step 2, θd ≤ 70°)."""
    keep = valid_d & (theta_d <= THETA_D_MAX + 1e-9)
    td = theta_d[keep]
    D0 = float(_D_theta(kind, 0.0, s1["alpha"], s1["p"]))
    g = _G1_theta(kind, td, s1["alpha"], s1["p"])
    with np.errstate(divide="ignore", invalid="ignore"):
        y = (m_d[keep] - s1["rho_d"] / np.pi) * np.pi * np.cos(td) ** 2 / (D0 * g * g)
    ok = np.isfinite(y)
    if ok.sum() < 3:
        return 0.0, 0.0, 0.0
    return _fresnel_nnls(np.cos(td[ok]), y[ok], s1["rho_d"], rows)


# ------------------------------------------------------------------------------------------
# safeguards: bounded albedo and selection on the (subsampled) full MERL grid
# ------------------------------------------------------------------------------------------
SELECTION_STRIDES = (4, 15)            # θd, φd subsampling of the selection grid (24 840 nodes)
MAX_THETA_IO = np.radians(89.0)
GRAZING_DENSE = 76                     # θd node index (degrees) from which every node is used        # as the objective of Bagher et al. 2016 §4.1
# G1 nodes for the selection grid: dense near the horizon, where G1 falls to 0
_G1_NODES = np.pi / 2 * (1.0 - (1.0 - np.linspace(0.0, 1.0, 768)) ** 2)
# every 4th node for the grid scan (which only ranks the (α, p) nodes): G1 interpolation
# error ≤ 4e-5 absolute over θ ≤ 89° on the whole scan grid (768 nodes: ≤ 2.3e-6), 4× cheaper
_G1_SCAN_NODES = _G1_NODES[::4] if (len(_G1_NODES) - 1) % 4 == 0 else \
    np.append(_G1_NODES[::4], _G1_NODES[-1])


def _g1_nodes(kind: str, alpha: float, p: float | None, nodes: np.ndarray,
              cache: dict | None = None) -> np.ndarray:
    """``G1`` (Eq. 6) of one (α, p) at ``nodes``, memoised in ``cache`` (one fit's dict: the
    candidates' selection shapes and albedo rows need the same tables)."""
    key = (kind, float(alpha), None if p is None else float(p), id(nodes))
    if cache is not None and key in cache:
        return cache[key]
    ln = _sgd_log_norm(alpha, p) if kind == "sgd" else None
    g = _G1_theta(kind, nodes, alpha, p, ln)
    if cache is not None:
        cache[key] = g
    return g


def _fresnel_columns(cos_d: np.ndarray) -> np.ndarray:
    """``(1 − c, (1 − c)⁵, c)``: ``ρs F = A(1 − c) + B(1 − c)⁵ + E c`` (Eq. 11)."""
    return np.stack([1.0 - cos_d, (1.0 - cos_d) ** 5, cos_d], -1)


#: ρs / E below which ``ρs F = E cos θd`` (A = B = 0) is held as ρs = this × E, F0 = 1
_RHO_S_FLOOR = 1e-9


def _coefs_to_fresnel(A: float, B: float, E: float) -> tuple[float, float, float]:
    """``(ρs, F0, F1)`` from ``(A, B, E)`` with ``F(π/2) = 1`` (§5.2):
    ``ρs = A + B``, ``F0 = A / ρs``, ``F1 = (A − E) / ρs``.

    ``A = B = 0`` (``ρs F = E cos θd``, no grazing increase) is the limit ``ρs → 0``; it is
    held as ``ρs = ε E``, ``F0 = 1``, ``F1 = 1 − 1/ε`` (ε = :data:`_RHO_S_FLOOR`), i.e.
    ``ρs F = E cos θd + ε E (1 − cos θd)``: the fitted term to within ``ε E``."""
    rho_s = A + B
    if rho_s > _RHO_S_FLOOR * max(E, 0.0) and rho_s > 0:
        return float(rho_s), float(A / rho_s), float((A - E) / rho_s)
    if E > 0:
        rho_s = _RHO_S_FLOOR * E
        return float(rho_s), 1.0, float(1.0 - E / rho_s)
    return 0.0, 1.0, 0.0


def _bounded_lsq(M: np.ndarray, y: np.ndarray, cap_rows: np.ndarray | None = None,
                 cap: np.ndarray | None = None) -> np.ndarray:
    """``min ‖M x − y‖²`` subject to ``x ≥ 0`` and ``cap_rows · x ≤ cap`` (small dense QP).

    NNLS first (exact); when it violates the caps, SLSQP on the normal equations from the
    NNLS solution scaled into the feasible set (always feasible: the caps have ``cap ≥ 0`` and
    non-negative rows, so ``x = 0`` is feasible). Columns are normalised for conditioning.
    """
    scale = np.sqrt(np.sum(M * M, axis=0))
    scale = np.where(scale > 0, scale, 1.0)
    Ms = M / scale
    if Ms.shape[0] > 4 * Ms.shape[1]:        # tall: same minimiser on the R factor (fast)
        q, r = np.linalg.qr(Ms)
        Ms, y = r, q.T @ y
    x, _ = optimize.nnls(Ms, y, maxiter=50 * M.shape[1])
    if cap_rows is None:
        return x / scale
    R = cap_rows / scale[None, :]
    viol = R @ x - cap
    if np.all(viol <= 1e-12 * np.maximum(cap, 1e-300)):
        return x / scale
    with np.errstate(divide="ignore", invalid="ignore"):
        f = np.where(R @ x > 0, cap / (R @ x), np.inf)
    x0 = x * min(1.0, float(np.min(f)))
    H = Ms.T @ Ms
    g = Ms.T @ y
    res = optimize.minimize(lambda v: 0.5 * v @ H @ v - g @ v, x0, jac=lambda v: H @ v - g,
                            method="SLSQP", bounds=[(0.0, None)] * len(x0),
                            constraints=[{"type": "ineq", "fun": lambda v: cap - R @ v,
                                          "jac": lambda v: -R}],
                            options={"maxiter": 200, "ftol": 1e-14})
    v = np.maximum(res.x, 0.0) if np.all(np.isfinite(res.x)) else x0
    if np.any(R @ v > cap * (1 + 1e-9)) or 0.5 * v @ H @ v - g @ v > 0.5 * x0 @ H @ x0 - g @ x0:
        v = x0
    return v / scale


_ALBEDO_THETA = np.radians([0.0, 30.0, 50.0, 65.0, 75.0, 82.0, 86.0, 89.0])
_ALBEDO_N = 48                         # stratified 48 × 48 microfacet normals per direction


def _albedo_rows(kind: str, alpha: float, p: float | None, cache: dict | None = None
                 ) -> np.ndarray:
    """Directional albedo of ``ρd = 1`` and of each Fresnel column, rows ``(n_θi, 4)``.

    ``a(θi) = ∫ ρs F(i·h) D(h) G1(θi) G1(θo) 4 (i·h) / (π cos θi) dωh`` (Eq. 1 integrated
    against ``cos θo dωo = 4 (i·h) cos θo dωh``), by stratified quadrature over normals drawn
    from ``D cos θh`` (the distribution's own sampling), for ``ρs F`` = each column of
    :func:`_fresnel_columns`. ``rows @ (ρd, A, B, E) ≤ 1`` bounds the albedo by 1 at the
    :data:`_ALBEDO_THETA` incidences.
    """
    dist = _make_distribution(kind, alpha, p)
    n = _ALBEDO_N
    k = (np.arange(n) + 0.5) / n
    u = np.stack(np.meshgrid(k, k, indexing="ij"), -1).reshape(-1, 2)
    m = slope_to_normal(dist.sample(u))
    g = _g1_nodes(kind, alpha, p, _G1_NODES, cache)
    rows = []
    for t in _ALBEDO_THETA:
        wi = np.array([np.sin(t), 0.0, np.cos(t)])
        c = m @ wi
        oz = 2.0 * c * m[:, 2] - wi[2]
        ok = (c > 0) & (oz > 0) & (m[:, 2] > 0)
        go = np.interp(np.arccos(np.clip(oz, 0.0, 1.0)), _G1_NODES, g)
        gi = float(np.interp(t, _G1_NODES, g))
        with np.errstate(divide="ignore", invalid="ignore"):
            val = np.where(ok, gi * go * 4.0 * c / (np.pi * wi[2] * m[:, 2]), 0.0)
        a = np.mean(val[:, None] * _fresnel_columns(np.clip(c, 0.0, 1.0)), axis=0)
        rows.append([1.0, *np.where(np.isfinite(a), a, 0.0)])
    return np.array(rows)


def _selection_data(brdf, theta_d_stride: int, phi_stride: int) -> dict:
    """The reference on a subsampled MERL grid with the weights of Bagher et al. 2016 Eq. 8.

    ``w = wV wI wC`` exactly as :mod:`brdffit.losses.objective` (volume form of the
    MERL cell, ``cos θi cos θo``, compressive weight with ρ̄ the weighted median of the
    subsample, per channel; θi, θo ≤ 89°), every ``theta_d_stride``-th θd and
    ``phi_stride``-th φd node (weights scaled by the strides).
    """
    sd, sp = int(theta_d_stride), int(phi_stride)
    n_d = len(merl_theta_d())
    # every sd-th θd node below GRAZING_DENSE, every node above (the grazing rows vary fast)
    jd = np.union1d(np.arange(0, n_d, sd), np.arange(GRAZING_DENSE, n_d))
    width = np.diff(np.append(jd, n_d)).astype(np.float64)     # nodes each one stands for
    th = merl_theta_h()
    td = merl_theta_d()[jd]
    pd = merl_phi_d()[::sp]
    TH, TD, PD = np.meshgrid(th, td, pd, indexing="ij")
    wv = volume_form_weight()[:, jd, ::sp] * width[None, :, None] * sp
    v, measured = merl_node_values(brdf, slice(None), jd, slice(None, None, sp))
    v = np.asarray(v, dtype=np.float64)
    ok = measured[..., None] & np.isfinite(v) & (v >= 0)
    v = np.where(ok, v, 0.0)
    ok = np.broadcast_to(ok, v.shape)
    wi, wo = half_diff_to_io(TH, 0.0, TD, PD)
    ci, co = wi[..., 2], wo[..., 2]
    cmin = np.cos(MAX_THETA_IO)
    keep = (ci >= cmin - 1e-12) & (co >= cmin - 1e-12) & (ci > 0) & (co > 0)
    w = (wv * ci * co)[keep]
    d = {"theta_h": TH[keep], "cos_d": np.cos(TD[keep]), "ci": ci[keep], "co": co[keep],
         "m": v[keep], "ok": ok[keep]}
    m, ok = d["m"], d["ok"]
    W = np.zeros_like(m)
    for c in range(m.shape[1]):
        okc = ok[:, c] & (w > 0)
        if not okc.any():
            continue
        rb = weighted_median(m[okc, c], w[okc])
        if not rb > 0:
            rb = float(np.sum(m[okc, c] * w[okc]) / np.sum(w[okc]))
            rb = rb if rb > 0 else 1.0
        W[:, c] = np.where(okc, w * compressive_weight(m[:, c], rb), 0.0)
    d["sw"] = np.sqrt(W)
    d["theta_i"] = np.arccos(np.clip(d["ci"], -1.0, 1.0))
    d["theta_o"] = np.arccos(np.clip(d["co"], -1.0, 1.0))
    d["fres"] = _fresnel_columns(d["cos_d"])
    # precomputed lookups of _spec_shape: the θh node of each sample (D is evaluated on the
    # 90 nodes only), linear-interpolation cells of θi, θo in the G1 nodes, 1/(π ci co)
    d["ih"] = np.broadcast_to(np.arange(len(th))[:, None, None], TH.shape)[keep]
    for tag, nodes in (("", _G1_NODES), ("scan_", _G1_SCAN_NODES)):
        for key in ("i", "o"):
            t = d["theta_" + key]
            j = np.clip(np.searchsorted(nodes, t, side="right") - 1, 0, len(nodes) - 2)
            d[f"{tag}g1_cell_{key}"] = j
            d[f"{tag}g1_frac_{key}"] = (t - nodes[j]) / (nodes[j + 1] - nodes[j])
    with np.errstate(divide="ignore"):
        d["inv_cc"] = 1.0 / (np.pi * d["ci"] * d["co"])
    d["g1_cache"] = {}
    return d


def _interp_cells(g: np.ndarray, cell: np.ndarray, frac: np.ndarray) -> np.ndarray:
    """Linear interpolation of the node values ``g`` at precomputed cells (= ``np.interp``):
    ``g[j] + (g[j+1] − g[j]) · frac``, the differences taken once per node."""
    return g[cell] + np.diff(g)[cell] * frac


def _spec_shape(kind: str, alpha: float, p: float | None, data: dict,
                scan: bool = False, grid_node: bool = True) -> np.ndarray:
    """``D G1 G1 / (π cos θi cos θo)`` on the selection grid (G1 interpolated, Eq. 6).

    ``scan=True``: G1 from the coarser :data:`_G1_SCAN_NODES` (the grid scan and the
    refinement's steps only rank or move (α, p); the candidates are then evaluated with the
    full table), memoised for the process when ``grid_node`` (a node of the fixed grid)."""
    ln = _sgd_log_norm(alpha, p) if kind == "sgd" else None
    if scan and grid_node:
        g = _grid_g1(kind, alpha, p)[1]
    elif scan:
        g = _g1_nodes(kind, alpha, p, _G1_SCAN_NODES)
    else:
        g = _g1_nodes(kind, alpha, p, _G1_NODES, data.get("g1_cache"))
    tag = "scan_" if scan else ""
    gi = _interp_cells(g, data[tag + "g1_cell_i"], data[tag + "g1_frac_i"])
    go = _interp_cells(g, data[tag + "g1_cell_o"], data[tag + "g1_frac_o"])
    with np.errstate(over="ignore", invalid="ignore", under="ignore"):
        dh = _D_theta(kind, merl_theta_h(), alpha, p, ln)
        s = dh[data["ih"]] * gi * go * data["inv_cc"]
    return np.where(np.isfinite(s), s, 0.0)


_PAIRS = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def _gram_data(data: dict) -> dict:
    """Sample sums that give the normal equations of :func:`_linear_full` for any shape ``s``
    with two matrix-vector products per channel (``s @ lin[c]``, ``s² @ quad[c]``).

    With ``X = (1/π, s f0, s f1, s f2)`` (f the Eq. 11 columns) and ``W = sw²``:
    ``XᵀWX``, ``XᵀW m`` and ``mᵀW m`` per channel.
    """
    if "gram" in data:
        return data["gram"]
    W = data["sw"] ** 2                                   # (n, C)
    m, f = data["m"], data["fres"]
    C = m.shape[1]
    lin = [np.ascontiguousarray(np.concatenate([W[:, c:c + 1] * f,
                                                (W[:, c] * m[:, c])[:, None] * f], 1).T)
           for c in range(C)]
    quad = [np.ascontiguousarray(np.stack([W[:, c] * f[:, k] * f[:, l] for k, l in _PAIRS]))
            for c in range(C)]
    g = {"lin": lin, "quad": quad, "sW": W.sum(0), "sWm": (W * m).sum(0),
         "sWmm": (W * m * m).sum(0), "C": C}
    data["gram"] = g
    return g


def _scan_linear(data: dict, shapes: np.ndarray, solutions: bool = False,
                 channels: tuple[int, ...] | None = None):
    """Costs ``(N, C)`` of the unbounded non-negative least squares of :func:`_linear_full`
    (same minimiser) for ``N`` shapes at once — the weighted squared error :func:`_score` of
    its solution — from the normal equations of :func:`_gram_data` (two matrix products over
    the samples per channel for all shapes). Each 4 × 4 problem is solved by NNLS on the
    square root of its column-scaled Gram matrix. ``channels``: those only (``C`` = their
    number; all by default). ``solutions=True``: also the minimisers ``(N, C, 4)``
    (ρd, A, B, E).
    """
    g = _gram_data(data)
    channels = tuple(range(g["C"])) if channels is None else tuple(channels)
    C = len(channels)
    shapes = np.atleast_2d(shapes)
    squares = shapes * shapes
    N = shapes.shape[0]
    G = np.empty((N, C, 4, 4))
    b = np.empty((N, C, 4))
    for i, c in enumerate(channels):
        v1 = shapes @ g["lin"][c].T                        # (N, 6): W s f, W m s f
        v2 = squares @ g["quad"][c].T                      # (N, 6): W s² f_k f_l
        G[:, i, 0, 0] = g["sW"][c] / np.pi**2
        G[:, i, 0, 1:] = G[:, i, 1:, 0] = v1[:, :3] / np.pi
        for j, (k, l) in enumerate(_PAIRS):
            G[:, i, 1 + k, 1 + l] = G[:, i, 1 + l, 1 + k] = v2[:, j]
        b[:, i, 0] = g["sWm"][c] / np.pi
        b[:, i, 1:] = v1[:, 3:]
    yy = np.asarray(g["sWmm"], dtype=np.float64)[list(channels)]
    finite = np.all(np.isfinite(G), axis=(2, 3)) & np.all(np.isfinite(b), axis=2)
    G = np.where(finite[..., None, None], G, 0.0)
    b = np.where(finite[..., None], b, 0.0)
    scale = np.sqrt(np.maximum(np.diagonal(G, axis1=2, axis2=3), 0.0))
    scale = np.where(scale > 0, scale, 1.0)                # (N, C, 4)
    Gs = G / (scale[..., :, None] * scale[..., None, :])
    lam, V = np.linalg.eigh(Gs)
    big = lam > 1e-13 * np.maximum(lam[..., -1:], 1e-300)
    sq = np.sqrt(np.where(big, lam, 0.0))
    R = sq[..., :, None] * np.swapaxes(V, -1, -2)          # RᵀR = Gs (on its range)
    z = np.where(big, np.einsum("...ji,...j->...i", V, b / scale) / np.where(big, sq, 1.0), 0.0)
    cost = np.full((N, C), np.inf)
    X = np.zeros((N, C, 4))
    for i in range(N):
        for c in range(C):
            if not finite[i, c]:
                continue
            x, _ = optimize.nnls(R[i, c], z[i, c], maxiter=200)
            X[i, c] = x = x / scale[i, c]
            v = yy[c] - 2.0 * float(b[i, c] @ x) + float(x @ G[i, c] @ x)
            cost[i, c] = max(v, 0.0) if np.isfinite(v) else np.inf
    return (cost, X) if solutions else cost


def _score(data: dict, c: int, shape: np.ndarray, rho_d: float, abe) -> float:
    """Weighted squared error (Eq. 7 of Bagher 2016 on the subsample) of one channel."""
    pred = rho_d / np.pi + shape * (data["fres"] @ np.asarray(abe, dtype=np.float64))
    r = (pred - data["m"][:, c]) * data["sw"][:, c]
    v = float(np.sum(r * r))
    return v if np.isfinite(v) else np.inf


def _linear_full(data: dict, c: int, shape: np.ndarray, rows: np.ndarray | None = None):
    """ρd, (A, B, E) by weighted non-negative least squares on the selection grid
    (with ``rows`` from :func:`_albedo_rows`: subject to albedo ≤ 1)."""
    M = np.concatenate([np.full((len(shape), 1), 1.0 / np.pi),
                        shape[:, None] * data["fres"]], 1) * data["sw"][:, c:c + 1]
    y = data["m"][:, c] * data["sw"][:, c]
    caps = None if rows is None else np.ones(len(rows))
    x = _bounded_lsq(M, y, rows, caps)
    return float(x[0]), x[1:]


def _grid_axes(kind: str, n_grid: tuple[int, int]):
    a_lo, a_hi = ALPHA_BOUNDS[kind]
    la = np.linspace(np.log(a_lo), np.log(a_hi), n_grid[0])
    ps = np.linspace(P_BOUNDS[0] + 0.5, P_BOUNDS[1] - 0.5, n_grid[1]) if kind == "sgd" else [None]
    return la, ps


def _full_scan(kind: str, data: dict, n_grid: tuple[int, int], starts: int
               ) -> list[list[dict]]:
    """Selection-grid cost of every node of the step-1 grid; per channel, the ``starts`` best
    local minima as candidates ``{"alpha", "p"}`` (shape computed once for the 3 channels;
    linear part without the albedo bound, which is applied to the candidates only)."""
    la, ps = _grid_axes(kind, n_grid)
    nodes = [(float(lga), p) for lga in la for p in ps]
    shapes = np.stack([_spec_shape(kind, float(np.exp(lga)), p, data, scan=True)
                       for lga, p in nodes])
    costs = _scan_linear(data, shapes)
    out = []
    for c in range(costs.shape[1]):
        order = _grid_starts(costs[:, c].reshape(len(la), len(ps)))[:starts]
        out.append([{"alpha": float(np.exp(nodes[i][0])), "p": nodes[i][1], "source": "grid"}
                    for i in order if np.isfinite(costs[i, c])])
    return out


#: relative tolerances (x and cost) of the refinement: its objective is within 3e-5 of a
#: 1e-8 / 1e-10 refinement on 5 MERL materials, at 25-40 % less CPU (docs/design/sgd-fit.md)
REFINE_TOL = 1e-5


def _refine_full(kind: str, data: dict, c: int, cand: dict, max_nfev: int = 40) -> dict:
    """Bounded TRF on (ln α[, p]) of the selection-grid residual, linear part eliminated."""
    a_lo, a_hi = ALPHA_BOUNDS[kind]
    sgd = kind == "sgd"
    q0 = np.array([np.log(cand["alpha"])] + ([cand["p"]] if sgd else []))
    lo = [np.log(a_lo)] + ([P_BOUNDS[0]] if sgd else [])
    hi = [np.log(a_hi)] + ([P_BOUNDS[1]] if sgd else [])
    q0 = np.clip(q0, np.array(lo) + 1e-9, np.array(hi) - 1e-9)
    m, sw = data["m"][:, c], data["sw"][:, c]

    def resid(q):
        shape = _spec_shape(kind, float(np.exp(q[0])), float(q[1]) if sgd else None, data,
                            scan=True, grid_node=False)
        x = _scan_linear(data, shape, solutions=True, channels=(c,))[1][0, 0]
        r = (x[0] / np.pi + shape * (data["fres"] @ x[1:]) - m) * sw
        return np.where(np.isfinite(r), r, 1e6)

    try:
        res = optimize.least_squares(resid, q0, bounds=(lo, hi), method="trf", diff_step=1e-4,
                                     xtol=REFINE_TOL, ftol=REFINE_TOL, max_nfev=max_nfev)
        q, run = res.x, _run_record(res)
    except (ValueError, FloatingPointError, np.linalg.LinAlgError) as exc:
        q = q0
        run = {"status": -1, "nfev": 0, "converged": False,
               "message": f"{type(exc).__name__}: {exc}"}
    return {**cand, "alpha": float(np.exp(q[0])), "p": float(q[1]) if sgd else None,
            "source": cand.get("source", "slice") + "+refined", "run": run}


@with_single_blas_thread
def fit_two_slice(brdf, distribution: str = "sgd", *, weighting: Weighting = "cosine",
                  starts: int = 3, grid: tuple[int, int] = (18, 8), g1_approximation: bool = True,
                  selection: SliceOrFull = "full", linear: SliceOrFull = "full",
                  bounded: bool = True, selection_strides: tuple[int, int] = SELECTION_STRIDES,
                  scan_grid: bool = True, refine: int = 1,
                  name: str | None = None) -> PerChannelMicrofacetBRDF:
    """Two-slice fit of Bagher 2012 §5 with an SGD, Beckmann or GGX distribution, per channel.

    ``selection`` (``"full"``/``"slice"``), ``linear`` (``"full"``/``"slice"``), ``bounded``,
    ``scan_grid``, ``refine`` and ``selection_strides`` (θd, φd subsampling) control the
    safeguards of the module docstring; ``selection="slice", linear="slice", bounded=False``
    is the paper's procedure. Returns a :class:`PerChannelMicrofacetBRDF` (``fit_info`` has
    timings, the step-1 candidates and, per channel, the chosen candidate and its selection
    cost). Raises :class:`FitError` when the slices hold no valid data.
    """
    t0 = time.perf_counter()
    _check_two_slice_choices(distribution, weighting, selection, linear)
    sl = two_slices(brdf)
    label = getattr(brdf, "name", "brdf")
    m_h, valid_h = _theta_d0_slice(sl, label)
    w = _weights(weighting, sl["theta_h"], m_h, valid_h)
    n_grid = grid if distribution == "sgd" else (grid[0] * 2, 1)
    s1 = _step1(distribution, sl["theta_h"], m_h, w, n_grid, starts)
    t1 = time.perf_counter()
    data, scan = None, None
    if selection == "full":
        data = _selection_data(brdf, *selection_strides)
        if scan_grid and linear == "full":
            scan = _full_scan(distribution, data, n_grid, starts)
    scorer = _Scorer(distribution, sl, data, bounded, linear)
    all_cands = []
    for c in range(3):
        cands = [{**cd, "source": "slice"} for cd in s1[c]["candidates"]] \
            if selection == "full" else [s1[c]]
        all_cands.append(cands + (scan[c] if scan is not None else []))
    channels, chosen, refined = _select(scorer, all_cands, refine)
    t2 = time.perf_counter()
    approx = []
    if distribution == "sgd" and g1_approximation:
        for ch in channels:
            approx.append(ch["distribution"].g1_approximation(n=256))
    t3 = time.perf_counter()
    model = PerChannelMicrofacetBRDF(channels, g1_approx=approx or None,
                                     name=name or f"{label}-{distribution}-2slice",
                                     source=getattr(brdf, "source", None))
    # build the G1 tables now (part of the fit, as in the paper)
    for ch in channels:
        if isinstance(ch["distribution"], SGD):
            ch["distribution"]._lambda_table
    t4 = time.perf_counter()
    refine_runs = [cd["run"] for cd in refined if "run" in cd]
    info = {"method": f"two-slice ({distribution})", "weighting": weighting,
            "time": t4 - t0, "time_step1": t1 - t0, "time_step2": t2 - t1,
            "time_g1_approx": t3 - t2, "time_g1_tables": t4 - t3,
            "step1": [{k: v for k, v in r.items()} for r in s1],
            "selection": chosen,
            **_sgd_convergence([r["runs"] for r in s1], refine_runs)}
    record(model, info, success=info["success"], converged=info["converged"],
           message=info["message"], nit=info["nit"], time=info["time"])
    model.fit_options = {"distribution": distribution, "weighting": weighting,
                         "starts": starts, "grid": list(grid), "selection": selection,
                         "linear": linear, "bounded": bounded, "scan_grid": scan_grid,
                         "refine": refine,
                         "selection_strides": list(selection_strides)}
    _check_finite(model, label)
    return model


def _check_two_slice_choices(distribution, weighting, selection, linear) -> None:
    check_choice("weighting", weighting, Weighting)
    check_choice("selection", selection, SliceOrFull)
    check_choice("linear", linear, SliceOrFull)
    if linear == "full" and selection != "full":
        raise ValueError("linear='full' needs selection='full'")
    if distribution not in ALPHA_BOUNDS:
        raise ValueError(f"distribution must be one of {sorted(ALPHA_BOUNDS)}, found "
                         f"{distribution!r}")


def _theta_d0_slice(sl, label) -> tuple[np.ndarray, np.ndarray]:
    """``(m_h, valid_h)``: the θd = 0 slice per channel (0 where not valid) and its valid
    samples (finite, below the horizon); :class:`FitError` when a channel has fewer than 4
    valid samples or no positive one."""
    m_h = np.asarray(sl["m_h"], dtype=np.float64)
    if m_h.ndim == 1:
        m_h = m_h[:, None]
    valid_h = np.broadcast_to(np.asarray(sl["valid_h"]).reshape(len(m_h), -1), m_h.shape)
    valid_h = valid_h & np.isfinite(m_h) & (sl["theta_h"] < np.pi / 2 - 1e-6)[:, None]
    if np.any(valid_h.sum(axis=0) < 4) or not np.any(m_h[valid_h] > 0):
        raise FitError(f"{label}: the θd = 0 slice has too few valid samples "
                       f"(expected ≥ 4 per channel, found {valid_h.sum(axis=0).tolist()})")
    return np.where(valid_h, m_h, 0.0), valid_h


class _Scorer:
    """The step-2 evaluation of a candidate ``(α, p)`` for a channel: its linear
    coefficients (on the θh = 0 slice, or on the full selection data) and its selection
    cost; the specular shapes and the albedo rows of the bounds are cached per candidate
    (they do not depend on the channel)."""

    def __init__(self, distribution, sl, data, bounded, linear):
        self.distribution, self.sl, self.data = distribution, sl, data
        self.bounded, self.linear = bounded, linear
        self.m_d = np.asarray(sl["m_d"], dtype=np.float64).reshape(len(sl["theta_d"]), -1)
        self.valid_d = np.broadcast_to(np.asarray(sl["valid_d"]).reshape(len(self.m_d), -1),
                                       self.m_d.shape)
        self.rows: dict = {}
        self.shapes: dict = {}

    def shape_of(self, cand):
        key = (cand["alpha"], cand["p"])
        if key not in self.shapes:
            self.shapes[key] = _spec_shape(self.distribution, cand["alpha"], cand["p"],
                                           self.data)
        return self.shapes[key]

    def evaluate(self, c, cand):
        """``(score, ρd, (a, b, e))`` of candidate ``cand`` for channel ``c``."""
        data, rho_d = self.data, cand.get("rho_d", 0.0)
        abe, rows = None, None
        if self.bounded:
            key = (cand["alpha"], cand["p"])
            if key not in self.rows:
                self.rows[key] = _albedo_rows(self.distribution, cand["alpha"], cand["p"],
                                              None if data is None else data["g1_cache"])
            rows = self.rows[key]
        if self.linear == "slice":
            abe = _step2(self.distribution, self.sl["theta_d"], self.m_d[:, c],
                         self.valid_d[:, c], cand, rows)
        score = np.nan
        if data is not None:
            shape = self.shape_of(cand)
            if self.linear == "full":
                rho_d, abe = _linear_full(data, c, shape, rows)
            score = _score(data, c, shape, rho_d, abe)
        return score, rho_d, abe


def _by_score(t):
    return (np.nan_to_num(t[0], nan=np.inf), t[3])


def _select(scorer: _Scorer, all_cands, refine: int):
    """``(channels, chosen, refined)``: per channel the candidate of lowest selection cost
    (with ``refine`` local refinements of the best ones on the full data) as the channel's
    parameters, the record of the choice, and the refined candidates.

    Exact pruning of the bounded evaluations (the albedo rows are the costly part): the
    unbounded least-squares cost of a candidate is a lower bound of its bounded cost, so a
    candidate whose lower bound exceeds the best bounded cost found so far cannot win."""
    data, dist = scorer.data, scorer.distribution
    prune = bool(_PRUNE and scorer.bounded and scorer.linear == "full" and data is not None)
    lower, slack = {}, None
    if prune:
        keys = list(dict.fromkeys((cd["alpha"], cd["p"]) for cs in all_cands for cd in cs))
        lb = _scan_linear(data, np.stack([scorer.shape_of({"alpha": a, "p": p})
                                          for a, p in keys]))
        lower = {key: np.where(np.isfinite(lb[i]), lb[i], -np.inf) for i, key in enumerate(keys)}
        slack = 1e-10 * _gram_data(data)["sWmm"]       # rounding of the normal equations
    channels, chosen, refined = [], [], []
    for c in range(3):
        cands = all_cands[c]
        keep = max(refine, 1)
        scored = (_pruned_scores(scorer, c, cands, lower, slack[c], keep) if prune else
                  sorted(((*scorer.evaluate(c, cd), k, cd) for k, cd in enumerate(cands)),
                         key=_by_score))
        n_evaluated = len(scored)
        if refine and data is not None and scorer.linear == "full":
            for t in scored[:refine]:
                cd = _refine_full(dist, data, c, t[4])
                refined.append(cd)
                scored.append((*scorer.evaluate(c, cd), len(cands), cd))
                cands.append(cd)
            scored.sort(key=_by_score)
        score, rho_d, abe, k, cand = scored[0]
        rho_s, F0, F1 = _coefs_to_fresnel(*abe)
        channels.append({"distribution": _make_distribution(dist, cand["alpha"], cand["p"]),
                         "rho_d": rho_d, "rho_s": rho_s, "F0": F0, "F1": F1})
        chosen.append({"candidate": int(k), "n_candidates": len(cands),
                       "n_evaluated": n_evaluated,
                       "source": cand.get("source", "slice"), "selection_cost": float(score)})
    return channels, chosen, refined


def _pruned_scores(scorer: _Scorer, c, cands, lower, slack, keep: int = 1):
    """The candidates of channel ``c`` evaluated in the order of their lower bounds, until a
    lower bound exceeds the ``keep``-th best cost found (:func:`_select`: the ``keep`` best
    are then exact); sorted by cost."""
    order = sorted(range(len(cands)), key=lambda k: (
        lower[(cands[k]["alpha"], cands[k]["p"])][c], k))
    scored, costs = [], []
    for k in order:
        bar = costs[keep - 1] if len(costs) >= keep else np.inf
        if lower[(cands[k]["alpha"], cands[k]["p"])][c] > bar * (1 + 1e-6) + slack:
            break
        t = (*scorer.evaluate(c, cands[k]), k, cands[k])
        scored.append(t)
        costs = sorted(costs + [float(np.nan_to_num(t[0], nan=np.inf))])
    scored.sort(key=_by_score)
    return scored


_PRUNE = True                          # exact pruning of candidate evaluations (tests)


def _sgd_convergence(step1_runs: list[list[dict]], refine_runs: list[dict]) -> dict:
    """The convergence report of a two-slice fit (fields as the tabulated fit's).

    The iterative parts are the step-1 local least-squares runs (scipy TRF, per channel
    ``starts`` of them) and the optional ``refine`` runs; the rest (grid scan, linear solves,
    candidate selection) is direct. ``converged``: every run stopped on its tolerance
    (``ftol``/``xtol``/``gtol``), none on its ``max_nfev`` cap (``cap_reached``);
    ``iterations``/``nit``: function evaluations of all runs; ``final_relative_change``:
    not defined for these runs (None) — their first-order ``optimality`` is reported instead.
    """
    runs = [r for rs in step1_runs for r in rs] + list(refine_runs)
    n_conv = sum(r["converged"] for r in runs)
    capped = sum(r["status"] == 0 for r in runs)
    failed = sum(r["status"] < 0 for r in runs)
    converged = bool(runs) and n_conv == len(runs)
    if converged:
        msg = (f"converged: all {len(runs)} local least-squares runs stopped on their "
               "tolerance")
    else:
        msg = (f"NOT converged: {n_conv} of {len(runs)} local least-squares runs stopped on "
               f"their tolerance, {capped} at the max_nfev cap"
               + (f", {failed} raised" if failed else "")
               + "; the best candidate was still selected on the MERL subsample")
    nfev = sum(r.get("nfev", 0) for r in runs)
    opt = [r["optimality"] for r in runs if "optimality" in r]
    return {"converged": converged, "success": converged, "status": 0 if converged else 1,
            "message": msg,
            "criterion": (f"step-1 scipy least_squares (TRF) per start: ftol={STEP1_FTOL:g}, "
                          f"xtol={STEP1_XTOL:g}, cap max_nfev={STEP1_MAX_NFEV}; then direct "
                          "grid scan, bounded linear solves and selection (not iterative); "
                          f"refine: TRF per refined candidate, ftol=xtol={REFINE_TOL:g}"),
            "iterations": nfev, "nit": nfev, "max_iterations": STEP1_MAX_NFEV,
            "cap_reached": bool(capped), "final_relative_change": None,
            "optimality": max(opt) if opt else None, "n_local_runs": len(runs)}


def _check_finite(model: PerChannelMicrofacetBRDF, label: str) -> None:
    for row in model.channel_params():
        vals = [v for k, v in row.items() if isinstance(v, float)]
        if not all(np.isfinite(vals)):
            raise FitError(f"{label}: fit produced non-finite parameters {row}")


def fit_sgd(brdf, *, weighting: Weighting = "cosine", starts: int = 3,
            g1_approximation: bool = True, **kwargs) -> PerChannelMicrofacetBRDF:
    """Fit the SGD Cook-Torrance model of Bagher, Soler, Holzschuch 2012 (§5) per channel.

    Parameters
    ----------
    brdf : BRDF
        An isotropic BRDF (its θd = 0 and θh = 0 slices are read, Bagher 2012 §5).
    weighting : {"cosine", "relative"}
        Weights of the step-1 fit of the θd = 0 slice (Eq. 12): ``"cosine"`` (default,
        cos θi cos θo times the solid angle, §6.3-like) or ``"relative"`` (1/value, the
        relative error of the paper's Eq. 12).
    starts : int
        Best candidates of the (α, p) grid scan refined per channel (multi-start).
    g1_approximation : bool
        Also fit the closed-form G1 approximation of Eq. 9 ``(λ, c, k, θ0)`` per channel
        (what the renderer and the exports use); ``False`` keeps the numerical G1 (Eq. 6).
    **kwargs
        The options of :func:`fit_two_slice`: ``grid`` (the (α, p) scan), ``selection``,
        ``linear`` and ``bounded`` (``selection="slice", linear="slice", bounded=False`` is
        the paper's procedure; the defaults add the safeguards of the module docstring),
        ``selection_strides``, ``scan_grid``, ``refine``, ``name``.

    Returns
    -------
    PerChannelMicrofacetBRDF
        Per channel ``SGD(α, p)``, ρd, ρs, F0, F1 and the Eq. 9 G1 approximation, with
        ``fit_info`` (timings, candidates, the chosen candidate and its cost per channel,
        convergence report) and ``fit_options``.

    Examples
    --------
    >>> import brdffit
    >>> m = brdffit.fit_sgd(brdffit.synthetic("sgd-paint"))
    >>> type(m).__name__, len(m.channels)
    ('PerChannelMicrofacetBRDF', 3)
    """
    return fit_two_slice(brdf, "sgd", weighting=weighting, starts=starts,
                         g1_approximation=g1_approximation, **kwargs)


def fit_beckmann_two_slice(brdf, *, weighting: Weighting = "cosine", starts: int = 3,
                           **kwargs) -> PerChannelMicrofacetBRDF:
    """The two-slice procedure of Bagher 2012 §5 with a Beckmann distribution (§6.3)."""
    return fit_two_slice(brdf, "beckmann", weighting=weighting, starts=starts, **kwargs)


def fit_ggx_two_slice(brdf, *, weighting: Weighting = "cosine", starts: int = 3,
                      **kwargs) -> PerChannelMicrofacetBRDF:
    """The two-slice procedure of Bagher 2012 §5 with a GGX (Trowbridge-Reitz) distribution."""
    return fit_two_slice(brdf, "ggx", weighting=weighting, starts=starts, **kwargs)


# ------------------------------------------------------------------------------------------
# full-data weighted least squares Cook-Torrance
# ------------------------------------------------------------------------------------------
def _full_data(brdf, theta_d_stride: int, phi_stride: int):
    w, _ = merl_grid_weights(phi_stride)
    w = w[:, ::theta_d_stride] * theta_d_stride
    th = merl_theta_h()
    td = merl_theta_d()[::theta_d_stride]
    pd = merl_phi_d()[::phi_stride]
    TH, TD, PD = np.meshgrid(th, td, pd, indexing="ij")
    v, measured = merl_node_values(brdf, slice(None), slice(None, None, theta_d_stride),
                                   slice(None, None, phi_stride))
    v, ok = _clean(v, measured[..., None])
    wi, wo = half_diff_to_io(TH, 0.0, TD, PD)
    keep = (w > 0) & (wi[..., 2] > 1e-4) & (wo[..., 2] > 1e-4)
    return {"theta_h": TH[keep], "cos_d": np.cos(TD[keep]), "ci": wi[..., 2][keep],
            "co": wo[..., 2][keep], "w": w[keep], "m": v[keep], "ok": ok[keep]}


@with_single_blas_thread
def fit_cook_torrance(brdf, distribution: str = "beckmann", *, theta_d_stride: int = 4,
                      phi_stride: int = 15, starts: int = 2,
                      name: str | None = None) -> PerChannelMicrofacetBRDF:
    """Full-data weighted least-squares Cook-Torrance fit (Eq. 1, Schlick F, per channel).

    Unknowns per channel: ρd, ρs (linear, NNLS inside the residual) and α, F0 (outer bounded
    TRF least squares from a grid search). Data: the MERL grid subsampled in θd and φd;
    weights: the §6.3 quadrature weights ``cos θi cos θo dωi dωo`` (see
    :mod:`brdffit.losses.l2`), i.e. this minimises the unnormalised §6.3 error.
    """
    t0 = time.perf_counter()
    if distribution not in ("beckmann", "ggx"):
        raise ValueError(f"distribution must be 'beckmann' or 'ggx', found {distribution!r}")
    label = getattr(brdf, "name", "brdf")
    if not getattr(brdf, "isotropic", False):
        raise FitError(f"{label}: fit_cook_torrance needs an isotropic BRDF")
    data = _full_data(brdf, theta_d_stride, phi_stride)
    sw = np.sqrt(data["w"])
    th, cd, ci, co = data["theta_h"], data["cos_d"], data["ci"], data["co"]
    a_lo, a_hi = ALPHA_BOUNDS[distribution]

    def basis(alpha, F0):
        D = _D_theta(distribution, th, alpha)
        G = _G1_theta(distribution, np.arccos(ci), alpha) * _G1_theta(distribution, np.arccos(co), alpha)
        F = F0 + (1.0 - F0) * (1.0 - cd) ** 5
        with np.errstate(over="ignore", invalid="ignore"):
            b = F * D * G / (np.pi * ci * co)
        return np.where(np.isfinite(b), b, 0.0)

    W = sw[:, None] * data["ok"]
    if np.any(data["ok"].sum(axis=0) < 8):
        raise FitError(f"{label}: too few valid samples for the full-data fit")
    grid_a = np.linspace(np.log(a_lo), np.log(a_hi), 16)
    grid_f = np.array([0.03, 0.2, 0.6])
    grid = [(la, f) for la in grid_a for f in grid_f]
    costs = np.array([_nnls2(basis(np.exp(la), f), data["m"], W)[1] for la, f in grid])
    channels = []
    for c in range(3):
        mc, wc = data["m"][:, c:c + 1], W[:, c:c + 1]

        def resid(q):
            b = basis(np.exp(q[0]), q[1])
            coef, _ = _nnls2(b, mc, wc)
            r = (mc[:, 0] - coef[0, 0] / np.pi - coef[0, 1] * b) * wc[:, 0]
            return np.where(np.isfinite(r), r, 1e6)

        best = None
        for gi in np.argsort(costs[:, c])[:starts]:
            q0 = np.array(grid[gi])
            try:
                res = optimize.least_squares(resid, q0, bounds=([np.log(a_lo), 0.0],
                                                                [np.log(a_hi), 1.0]),
                                             diff_step=1e-4, max_nfev=100)
                x, cost = res.x, res.cost
            except (ValueError, FloatingPointError, np.linalg.LinAlgError):
                x, cost = q0, 0.5 * costs[gi, c]
            if np.isfinite(cost) and (best is None or cost < best[1]):
                best = (x, cost)
        if best is None:
            raise FitError(f"{label}: full-data {distribution} fit found no finite solution "
                           f"for channel {_CHANNELS[c]}")
        alpha, F0 = float(np.exp(best[0][0])), float(best[0][1])
        coef, _ = _nnls2(basis(alpha, F0), mc, wc)
        channels.append({"distribution": _make_distribution(distribution, alpha),
                         "rho_d": float(coef[0, 0]), "rho_s": float(coef[0, 1]),
                         "F0": F0, "F1": 0.0})
    model = PerChannelMicrofacetBRDF(channels, name=name or f"{label}-{distribution}-ct",
                                     source=getattr(brdf, "source", None))
    info = {"method": f"full-data weighted least squares ({distribution})",
            "time": time.perf_counter() - t0, "n_samples": int(len(th))}
    record(model, info, success=True, converged=None, message=info["method"],
           time=info["time"])
    model.fit_options = {"distribution": distribution, "theta_d_stride": theta_d_stride,
                         "phi_stride": phi_stride, "starts": starts}
    _check_finite(model, label)
    return model


# ------------------------------------------------------------------------------------------
# CLI registration
# ------------------------------------------------------------------------------------------
def summary(model) -> dict:
    """Per-channel fitted parameters (what ``brdffit fit`` prints)."""
    info = getattr(model, "fit_info", None) or {}
    out = {"model": model.fit_kind, "method": info.get("method"),
           "time_s": info.get("time")}
    for row in model.channel_params():
        ch = row["channel"]
        for k, v in row.items():
            if k in ("channel",):
                continue
            if k == "g1_approx":
                out[f"{ch}.g1_approx"] = {kk: row[k][kk] for kk in ("lambda", "c", "k", "theta0")}
            else:
                out[f"{ch}.{k}"] = v
    return out


def fit_beckmann_ct(brdf, **kw):
    """Cook-Torrance (Beckmann) full-data weighted least squares, per channel
    (:func:`fit_cook_torrance` with ``"beckmann"``)."""
    return fit_cook_torrance(brdf, "beckmann", **kw)


def fit_ggx_ct(brdf, **kw):
    """Cook-Torrance (GGX) full-data weighted least squares, per channel
    (:func:`fit_cook_torrance` with ``"ggx"``)."""
    return fit_cook_torrance(brdf, "ggx", **kw)
