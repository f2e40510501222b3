"""Non-parametric factor microfacet fits (Bagher, Snyder & Nowrouzezahrai 2016, ACM TOG).

:func:`fit_npf` fits, per colour channel, one of

* ``"independent-g"`` – Eq. 3 with an independent tabulated G (§4.3), several starts;
* ``"g-from-d"`` – Eq. 3 with G derived from D by Smith's integrals (Eq. 19 ff.);
* ``"naive"`` – Eq. 4 (D(θh) F(θd) H(φd));
* ``"bivariate"`` – Eq. 5 (B(θh, θd), one weighted-average step),

minimising the compressive-weighted objective (Eq. 7-12, :mod:`brdffit.losses.objective`)
with alternating weighted least squares (AWLS, §4.2; solvers in :mod:`._solver`).

Deviations from the paper (deliberate, documented):

* G is linearly interpolated in θ, so a sample touches two G components; the G(θi) and G(θo)
  updates solve the corresponding (tridiagonal) weighted least-squares normal equations
  exactly instead of Eq. 14's one-component-per-sample form, and the two systems are summed
  rather than their solutions averaged (identical for reciprocal data; see ``_solver``).
* Samples at φd and π − φd are folded into one (same θh, θd, swapped θi/θo, so the same
  model value): every least-squares update is unchanged, Eq. 7 changes by a constant that
  is added back, and each pass costs half.
* Independent-G does one G step per outer iteration (D, F, G, ρ), taken with an exact line
  search over-relaxed by ω = 1.9 (the objective along the G step is a quartic built in one
  pass, ``_solver.line_search_g``; the paper iterates G "until it converges or increases the
  objective"), and each sweep is followed by an accepted-only-if-better over-relaxation of
  all factors (``extrapolate``, default on). Together they make the fit converge where plain
  AWLS crawls along the near-ambiguity of F(θd) and G(θi)G(θo).
* G-from-D searches along a D step that increases the objective by parabolic interpolation
  started from the previous accepted step (``_solver.run_g_from_d``), and from its 50th
  sweep on over-relaxes each sweep as independent-G does (accepted only if better; the
  G-from-D *start* of independent-G runs the plain sweeps).
* G-from-D runs its AWLS from two starts, the data slices and all ones
  (:data:`G_FROM_D_STARTS`; the paper found its G-from-D fits stable from one start), each
  then :data:`G_FROM_D_SCREEN_POLISH` iterations of the polish, and per channel the lower
  one goes on polishing (the AWLS objective alone picked a start 5 % worse after the polish
  on one MERL material); ``fit_info["starts"]`` (with ``objective_after_screen``),
  ``["best_start_per_channel"]``, ``["start_basins"]`` and ``["screen_polish"]`` record
  them. Each start's sweeps stop where they crawl (:data:`G_FROM_D_WINDOW`).
* G-from-D's AWLS is followed by damped Newton iterations on all its parameters at once
  (``polish``, :data:`DEFAULT_POLISH`: 60 at most; ``_solver.polish_lm``). AWLS stops
  (relative decrease below ``tol``) where its alternating updates no longer help, which is
  not a minimum of Eq. 7 — and the paper's D update (Eq. 14) even holds G fixed although G
  is a function of D. The polish in (D, F, ρd, ρs), G following D through Smith's integrals
  with their exact first and second derivatives, F kept within a factor 2 of its AWLS value
  (``polish_bound``, :data:`POLISH_BOUNDED`), continues from there; when the cap is reached
  ``fit_info`` says "NOT converged" with the cap. ``polish=0`` is the paper's AWLS only.
* Independent-G's AWLS is followed by damped Newton iterations (``polish``, 100 at most;
  JᵀWJ plus the residual curvature ``Σ w r ∇²m``: Eq. 7 is a large-residual problem, where
  Gauss–Newton crawls) on all 272 parameters of a channel at once, each factor sample and ρs
  kept within a factor 2 of its AWLS value (``polish_bound``, :data:`DEFAULT_POLISH_BOUND`):
  unbounded, the polish follows the near-ambiguity of F(θd) and G(θi)G(θo) to degenerate
  factors.
* Objective weights at cell centres (see :mod:`brdffit.losses.objective`).
* The start "from the SGD fit" uses :func:`brdffit.fit.sgd.fit_sgd` when that module exists
  (the paper used its authors' earlier Bagher et al. 2012 fits); otherwise it is skipped and
  ``fit_info["starts"]`` says so.
* Independent-G's starts and how they are run. The paper ran eight starts to convergence
  (four random, all-ones, the SGD fit, the G-from-D fit, D from the retro-reflective slice:
  ``ALL_STARTS``, ``n_random``). Here every start given is *screened* for up to
  ``start_max_iter`` AWLS iterations, the best screened state **per channel** (the channels
  are independent problems) is continued, and the polish follows. ``starts=None`` screens
  :data:`DEFAULT_STARTS`, the paper's set (``n_random`` random, all-ones, the SGD fit, the
  data slices, the G-from-D fit). The G-from-D start (G-from-D's AWLS from the slices) is
  screened apart (:data:`PROTECTED_STARTS`): it is far ahead of the others in the first
  rounds, and ranked with them it stopped starts that overtake it later; compared at the
  end of the screening, it is the best start of two channels of pink-fabric (an objective
  13 % lower than without it) and, on the 46 other MERL materials measured, changes no fit
  by more than 0.02 %, for 1.11× the CPU (docs/design/npf-fit.md).
* The screening runs in rounds per channel (successive halving, :data:`SCREEN_ROUNDS`;
  not an option of :func:`fit_npf`, whose options mirror the registry's): after each round
  only the starts close to the channel's best run on in that channel; the k-th best start
  of every channel runs as one combined run (``_solver.combine_channels``), which goes on
  as each start's channel would alone, and the passes over the samples skip the channels
  not run. ``SCREEN_ROUNDS = False``: every start runs all ``start_max_iter`` iterations.
* The continuation stops by the AWLS rule of :mod:`._solver` or, earlier, when its objective
  fell by less than ``W·k·tol`` over the last ``W`` iterations (:data:`CONTINUATION_WINDOW`,
  ``W = 100, k = 5``); a channel whose own decrease over the window is below a third of
  that limit (of the summed objective) stops earlier and no longer costs
  (``_solver.ChannelMonitors``). Past that point AWLS crawls along the near-ambiguity of
  F(θd) and G(θi)G(θo). Every :data:`JUMP_EVERY` sweeps the continuation also over-relaxes
  along the displacement of those sweeps (``_solver._jump``, accepted only where Eq. 7
  decreases): along that crawl one sweep's displacement zigzags, twenty sweeps' points
  along the valley; it reaches lower AWLS objectives in a fraction of the iterations.
* ``fit_info["starts"]`` has one record per screened start (objective and iterations per
  channel, at the round where the channel was left; stop reasons; the first round's
  history); ``fit_info["best_start_per_channel"]`` the start each channel was continued
  from; ``fit_info["continuation"]`` the continuation's run (``jumps_accepted``);
  ``fit_info["start_basins"]`` (:func:`start_basins`) how far apart the screened starts
  ended per channel: distinct objectives (more than :data:`BASIN_TOLERANCE` apart, counted
  over the screened starts only, so at most their number) and the spread (largest over
  smallest), as far as the screening tells (the starts left after an early round count
  with their objective there).

Stopping rule: see :mod:`._solver` (relative decrease below ``tol`` for 3 iterations, exact
fit, or ``max_iter``; the polish: below ``tol`` for 2 iterations, no damped step lowering the
objective, or ``polish``).

Scale ambiguity: Eq. 3 is invariant under ``(ρs, D, F, G) → (ρs/(a b c²), a D, b F, c G)``;
the fit fixes it by max-normalising each factor (max component = 1, ρs absorbing the scale).
The naive model has the same ambiguity in (ρs, D, F, H).

Design notes (measured convergence, objectives and times behind the defaults):
docs/design/npf-fit.md
"""

from __future__ import annotations

import dataclasses
import os
import time
import typing
import warnings
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Iterable

import numpy as np

from ..._blas import with_single_blas_thread
from ..._cpus import usable_cpus
from ...brdf import BRDF, IsotropicBRDF
from ...errors import FitError
from ...losses.objective import ObjectiveOptions, prepare_objective
from ...grid import (merl_node_values, phi_d_to_index, tabulate_merl_grid, theta_d_to_index,
                     theta_h_to_index, usable)
from ...progress import step_callback
from ...microfacet.npf_model import (D_THETA_H, F_THETA_D, G_THETA, NPFBivariateBRDF,
                                     NPFMicrofacetBRDF, NPFNaiveBRDF)
from ..options import NPFInit, NPFStart, check_choice
from ..result import fit_result, record
from . import _solver
from ._solver import MFState, NaiveState, Samples
from ...loading import load

__all__ = ["fit_npf", "fit_npf_independent_g", "fit_npf_g_from_d", "fit_npf_naive",
           "fit_npf_bivariate", "VARIANTS", "ALL_STARTS", "DEFAULT_STARTS", "summary",
           "start_basins", "BASIN_TOLERANCE", "PROTECTED_STARTS", "G_FROM_D_START_MAX_ITER",
           "G_FROM_D_STARTS", "G_FROM_D_SCREEN_POLISH", "G_FROM_D_WINDOW",
           "CONTINUATION_WINDOW", "SCREEN_ROUNDS", "JUMP_EVERY"]

VARIANTS = ("independent-g", "g-from-d", "naive", "bivariate")
ALL_STARTS: tuple[str, ...] = typing.get_args(NPFStart)
#: the independent-G starts of ``starts=None``: the paper's eight
DEFAULT_STARTS = ("random", "ones", "sgd", "slices", "g-from-d")
#: starts that independent-G's screening runs for its first round only and ranks apart: an
#: informed start (a fit of the G-from-D model) leads the others in the first rounds and
#: would stop starts that overtake it later (yellow-paint: all-ones, 8 % lower in the end);
#: it joins the per-channel pick at the end of the screening, with its first round's
#: objective (where it wins, it is far ahead: pink-fabric, 25 % in one channel)
PROTECTED_STARTS = ("g-from-d",)
#: sweeps of the G-from-D AWLS that makes independent-G's G-from-D start (a start, not a
#: fit: on pink-fabric 60 sweeps lead to the same final fit as 300, for 1.2 s of CPU
#: instead of 3-5 s)
G_FROM_D_START_MAX_ITER = 60
DEFAULT_MAX_ITER = {"independent-g": 4000, "g-from-d": 300, "naive": 3000}
#: Levenberg–Marquardt iterations after AWLS by default (``polish``; a cap: the polish stops
#: earlier on its criterion, relative decrease < tol for 2 iterations; the cap is reported
#: when reached). Both variants take damped Newton steps within a trust region
#: (:data:`DEFAULT_POLISH_BOUND`, :data:`POLISH_BOUNDED`). G-from-D's sweeps stop where
#: Eq. 14's D step (G held fixed although G depends on D) no longer helps, not at a minimum
#: of Eq. 7; Newton with Smith's second derivative converges from there within 60 iterations
#: on most MERL materials, where 10 Gauss–Newton iterations mostly do not (docs/design/npf-fit.md).
DEFAULT_POLISH = {"independent-g": 100, "g-from-d": 60}
#: Trust region of the polish by default (``polish_bound``): each factor sample and ρs within
#: this factor of its AWLS value. Independent-G's Eq. 7 is nearly flat along
#: F(θd)/h(θd)²·G(θi)h(θi)·G(θo)h(θo) for any smooth h; unbounded, the polish follows it to
#: F(0) at the dynamic-range clamp and ρs 10-10⁶× the AWLS value: better objectives, but
#: factors that are no longer a Fresnel and a shadowing term. G-from-D has a weaker
#: direction of the same kind, F's grazing samples (F's max) rising against the rest with
#: ρs; there only F is bounded (:data:`POLISH_BOUNDED`), D stays free.
DEFAULT_POLISH_BOUND = {"independent-g": 2.0, "g-from-d": 2.0}
#: The factors the trust region bounds, per variant (``None``: D, F, G and ρs). G-from-D
#: bounds F only: bounding D too stops its Newton polish on the box's faces, at objectives
#: above those of 10 Gauss–Newton iterations on most MERL materials.
POLISH_BOUNDED = {"independent-g": None, "g-from-d": ("F",)}
#: G-from-D over-relaxes its sweeps (``extrapolate``) from this iteration on: by then the
#: materials whose plain sweeps converge have mostly done so at their own point, and the
#: others (a third of MERL, which plain sweeps leave at the cap) converge in 100-200
#: iterations
G_FROM_D_EXTRAPOLATE_AFTER = 50
#: G-from-D's starts by default (``init=None``): AWLS from each, then the per-channel pick
#: of :data:`G_FROM_D_SCREEN_POLISH`. Over MERL-100 the data slices alone ended more than 1 %
#: above the best-known objective on 6 materials (up to 4.4 %), on 4 of them where all-ones
#: reaches it (docs/design/npf-fit.md)
G_FROM_D_STARTS = ("slices", "ones")
#: G-from-D's starts are told apart after this many polish iterations each (the polish's
#: cap, ``polish``, counts them): after the AWLS alone the lower start ended higher after
#: the polish on violet-acrylic (5 % in one channel); after 4 iterations no material of
#: MERL-100 kept a start more than 1 % above the other's end (docs/design/npf-fit.md)
G_FROM_D_SCREEN_POLISH = 4
#: G-from-D's AWLS also stops when its objective fell by less than ``W · k · tol`` (relative)
#: over the last ``W`` sweeps, ``(W, k)`` = this (``None``: the 3-sweep rule alone). Plain
#: and over-relaxed sweeps crawl on a fifth of MERL (3e-5-1e-4 per sweep for 100-200 sweeps)
#: where the Newton polish after them goes faster. On the 36 MERL materials slowest or
#: closest to a miss, (20, 100) against (20, 50): no fit more than 0.02 % higher, five
#: 0.06-0.2 % lower, 7 % less CPU; (20, 200) ended colonial-maple-223 0.35 % higher
#: (docs/design/npf-fit.md)
G_FROM_D_WINDOW = (20, 100.0)
#: Independent-G's continuation of the best screened start also stops when its objective fell
#: by less than ``W · k · tol`` (relative) over the last ``W`` iterations, ``(W, k)`` =
#: this: the mean decrease per iteration below ``k · tol``. Past that point AWLS crawls along
#: the near-ambiguity of F(θd) and G(θi)G(θo) (1e-5-1e-6 per iteration for hundreds of
#: iterations on MERL) before the polish (docs/design/npf-fit.md).
CONTINUATION_WINDOW = (100, 5.0)
#: Independent-G's screening in rounds, per channel (successive halving; ``False``: one round):
#: every start runs the first round's ``n`` AWLS iterations; at each round's ``n`` only the
#: starts still run whose objective is within ``ratio`` of the channel's best, ``keep`` at
#: most (``None``: any number); the survivors run on to the next round's ``n``, the last to
#: ``start_max_iter``. On the 47 MERL materials of the independent-G yardstick, a first
#: round's ratio of 1.005 against 1.02: 0.88× the CPU (most starts of a channel were within
#: 2 % after 15 iterations and all ran to 50), no fit moved past 1 % of the best-known, the
#: largest rises 0.35 % (white-acrylic, white-paint); 10 iterations in the first round ended
#: black-oxidized-steel 1.8 % higher (docs/design/npf-fit.md).
SCREEN_ROUNDS = ((15, 1.005, None), (50, 1.005, 2))
#: Independent-G's continuation of the best start also over-relaxes along the displacement
#: of its last this-many sweeps, every this-many sweeps (``_solver.run_independent_g``'s
#: ``jump_every``): the continuation crawls along the near-ambiguity of F(θd) and G(θi)G(θo)
#: in small, steady steps (docs/design/npf-fit.md).
JUMP_EVERY = 20
#: model names of the registry and CLI -> variants (one naming scheme across CLI and API)
CLI_VARIANTS = {"npf": "independent-g", "npf-g-from-d": "g-from-d", "npf-naive": "naive",
                "npf-bivariate": "bivariate"}


def _resolve_input(brdf, data):
    if data is not None:
        values, valid = data
        return np.asarray(values, dtype=np.float64), valid, None
    if isinstance(brdf, str):
        brdf = load(brdf)
    values, valid = tabulate_merl_grid(brdf)
    return values, valid, brdf


def _slice_start(values, valid):
    """D from the θd = 0 slice, F from the θh = 0 slice (mean over φd), G = 1 (channel-first)."""
    return _start_from_slices(values[:, 0], valid[:, 0], values[0], valid[0])


def _model_slice_start(model):
    """:func:`_slice_start` of ``model`` tabulated on the MERL grid, from the two slices it
    reads only (2 × 16,200 nodes of the 1.46 M)."""
    (dv, dm), (fv, fm) = merl_node_values(model, jd=[0]), merl_node_values(model, ih=[0])
    return _start_from_slices(dv[:, 0], usable(dv, dm)[:, 0], fv[0], usable(fv, fm)[0])


def _start_from_slices(d_values, d_valid, f_values, f_valid):
    """:func:`_slice_start` from the θd = 0 slice ``(90 θh, 180 φd, 3)`` and the θh = 0 slice
    ``(90 θd, 180 φd, 3)`` of the tabulation and their valid masks."""
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)    # rows without data: NaN, then 0
        D, F = (np.nanmean(np.where(ok[..., None], np.maximum(v, 0.0), np.nan), axis=1).T
                for v, ok in ((d_values, d_valid), (f_values, f_valid)))   # (3, 90)
    D = np.where(np.isfinite(D), D, 0.0)
    F = np.where(np.isfinite(F), F, 0.0)
    D = np.maximum(D - 0.9 * D.min(axis=1, keepdims=True), 1e-3 * D.max(axis=1, keepdims=True))
    F = np.maximum(F, 1e-3 * np.maximum(F.max(axis=1, keepdims=True), 1e-300))
    return MFState(D=np.where(D > 0, D, 1.0), F=np.where(F > 0, F, 1.0), G=np.ones((3, 90)),
                   rho_d=np.zeros(3), rho_s=np.ones(3))


def _ones_start():
    return MFState(D=np.ones((3, 90)), F=np.ones((3, 90)), G=np.ones((3, 90)),
                   rho_d=np.zeros(3), rho_s=np.ones(3))


def _random_start(rng):
    return MFState(D=rng.uniform(0.05, 1.0, (3, 90)), F=rng.uniform(0.05, 1.0, (3, 90)),
                   G=rng.uniform(0.05, 1.0, (3, 90)), rho_d=np.zeros(3), rho_s=np.ones(3))


def _sgd_start(brdf, values, valid):
    """Factors of an SGD fit (Bagher et al. 2012) if ``brdffit.fit.sgd`` exists.

    Uses the fitted model's distribution ``D(m)``/``G1(w)`` and Fresnel when it exposes them
    (``distribution``/``fresnel`` attributes); otherwise the θd = 0 / θh = 0 slices of the
    fitted BRDF. Returns ``(state, note)``; state is None when unavailable.
    """
    try:
        from ..sgd import fit_sgd
    except ImportError as exc:
        return None, f"skipped: brdffit.fit.sgd not available ({exc})"
    if brdf is None:
        class _Table(IsotropicBRDF):
            name = "table"

            def merl_table(self):
                return values, valid

            def eval_hd(self, th, td, pd):  # pragma: no cover - fit_sgd should use the table
                i = np.minimum(theta_h_to_index(th).astype(int), 89)
                j = np.minimum(theta_d_to_index(td).astype(int), 89)
                k = np.minimum(phi_d_to_index(pd).astype(int), 179)
                return np.maximum(values[i, j, k], 0.0)

        brdf = _Table()
    try:
        model = fit_sgd(brdf)
    except Exception as exc:  # noqa: BLE001 - a failing optional start must not kill the fit
        return None, f"skipped: fit_sgd failed ({type(exc).__name__}: {exc})"
    dist = getattr(model, "distribution", None)
    fres = getattr(model, "fresnel", None)
    try:
        if dist is not None and fres is not None:
            m = np.stack([np.sin(D_THETA_H), 0 * D_THETA_H, np.cos(D_THETA_H)], -1)
            D = np.broadcast_to(np.asarray(dist.D(m), float)[:, None], (90, 3)).T
            F = np.asarray(fres.eval(np.cos(F_THETA_D)), float).reshape(90, -1)
            F = np.broadcast_to(F, (90, 3)).T
            w = np.stack([np.sin(G_THETA), 0 * G_THETA, np.cos(G_THETA)], -1)
            G = np.broadcast_to(np.asarray(dist.G1(w), float)[:, None], (90, 3)).T
            st = MFState(D=np.array(D), F=np.array(F), G=np.array(G), rho_d=np.zeros(3),
                         rho_s=np.ones(3))
            note = "from fit_sgd factors"
        else:
            st = _model_slice_start(model)
            note = "from slices of the fit_sgd model (no distribution/fresnel attributes)"
    except Exception as exc:  # noqa: BLE001
        return None, f"skipped: could not read factors of the SGD fit ({exc})"
    if not all(np.all(np.isfinite(a)) for a in (st.D, st.F, st.G)):
        return None, "skipped: SGD factors not finite"
    st.D, st.F, st.G = (np.maximum(a, 1e-6) for a in (st.D, st.F, st.G))
    return st, note


def _mf_model(st: MFState, variant, name, source):
    return NPFMicrofacetBRDF(st.D.T, st.F.T, st.G.T, st.rho_d, st.rho_s, variant=variant,
                             name=name, source=source)


def _check_state(arrays, what):
    for a in arrays:
        if not np.all(np.isfinite(a)):
            raise FitError(f"{what}: expected finite factors, found NaN/inf")
        if np.any(np.asarray(a) < 0):
            raise FitError(f"{what}: expected non-negative factors, found negative values")


def _n_threads() -> int:
    """Threads for the independent-G starts: the CPUs available, or ``$OMP_NUM_THREADS`` when
    set (Dask workers set it to their thread count, so a batch does not oversubscribe)."""
    env = os.environ.get("OMP_NUM_THREADS", "")
    if env.isdigit() and int(env) > 0:
        return int(env)
    return usable_cpus()


@with_single_blas_thread
def fit_npf(brdf=None, variant: str = "independent-g", *, data=None,
            compressive: bool = True, restrict_deg: float | None = None,
            p: float = 1.4, max_theta_io_deg: float = 89.0,
            max_iter: int | None = None, tol: float = 1e-6,
            starts: Iterable[NPFStart] | None = None, n_random: int = 4, seed: int = 0,
            g_smoothing: float = 1.0, dr_epsilon: float | None = None,
            start_max_iter: int | None = 100, polish: int | None = None,
            polish_bound: float | None = None, extrapolate: bool = True,
            init: NPFInit | None = None, name: str | None = None, callback=None,
            verbose: bool = False) -> BRDF:
    """Fit a non-parametric factor model (Bagher, Snyder & Nowrouzezahrai 2016).

    Parameters
    ----------
    brdf, data:
        An isotropic BRDF (tabulated on the MERL grid, :func:`brdffit.grid.tabulate_merl_grid`)
        or a load spec; or ``data = (values (90, 90, 180, 3), valid (90, 90, 180))``.
    variant:
        ``"independent-g"``, ``"g-from-d"``, ``"naive"`` or ``"bivariate"``, or the same
        by their model names ``"npf"``, ``"npf-g-from-d"``, ``"npf-naive"``,
        ``"npf-bivariate"`` (:data:`CLI_VARIANTS`).
    compressive, restrict_deg, p, max_theta_io_deg:
        Objective options (:class:`~brdffit.losses.objective.ObjectiveOptions`): wC on/off
        (Fig. 7), restricted angular range (Fig. 15), compressive power, θi/θo cut (89°).
    max_iter, tol:
        Stopping rule (see :mod:`._solver`); ``max_iter`` defaults per variant
        (independent-G 4000 in all, screening included; G-from-D 300; naive 3000).
    starts:
        Independent-G starts, any of ``ALL_STARTS`` (the paper's eight: ``n_random`` random,
        all-ones, SGD fit, G-from-D fit, data slices); ``None``: :data:`DEFAULT_STARTS` (all
        of them). The best screened state per channel is continued.
    start_max_iter:
        Independent-G: the starts are screened for up to this many AWLS iterations, in the
        rounds of :data:`SCREEN_ROUNDS`, then the per-channel best continues up to
        ``max_iter`` or until the AWLS rule or :data:`CONTINUATION_WINDOW` stops it
        (``None``: every start runs ``max_iter`` under the AWLS rule alone, as the paper).
    polish:
        Cap of the damped Newton (Levenberg–Marquardt) iterations after AWLS (module notes;
        default per variant, :data:`DEFAULT_POLISH`; ``0``: the paper's AWLS only).
    polish_bound:
        Trust region of the polish: the bounded factors (:data:`POLISH_BOUNDED`) stay
        within this factor of their AWLS values; ``0``: unbounded. Default per variant,
        :data:`DEFAULT_POLISH_BOUND`.
    extrapolate:
        Over-relaxation of all factors after each AWLS sweep, accepted only if it lowers the
        objective (extension, default on; off = the paper's sweeps). Independent-G: from the
        first sweep; G-from-D: from sweep :data:`G_FROM_D_EXTRAPOLATE_AFTER` (50) on.
    g_smoothing, dr_epsilon:
        σ (in G samples) of independent-G's Gaussian smoothing of G (0: none); the
        dynamic-range clamp (default 1e-6 for independent-G, 0 for the others).
    init, n_random, seed, name:
        Start of G-from-D / naive (``"slices"``, ``"ones"``, ``"random"``; ``None``: naive
        from the slices, G-from-D from :data:`G_FROM_D_STARTS`, module notes); random
        independent-G starts, the seed of random starts (deterministic), the model's name.
    callback, verbose:
        ``callback(iteration, objective)`` after every AWLS / LM iteration (not bivariate;
        also to progress listeners); print one line per independent-G start.

    Returns
    -------
    NPFMicrofacetBRDF, NPFNaiveBRDF or NPFBivariateBRDF, with ``fit_info`` and ``fit_options``.
    """
    variant, starts = _checked_choices(variant, init, starts)
    objective = ObjectiveOptions(p=p, compressive=compressive, restrict_deg=restrict_deg,
                                 max_theta_io_deg=max_theta_io_deg)
    pb = _problem(brdf, data, variant, name=name, seed=seed, callback=callback, eps=dr_epsilon,
                  objective=objective, max_iter=max_iter, tol=tol, polish=polish,
                  polish_bound=polish_bound)
    if variant == "bivariate":
        return _fit_bivariate(pb)
    if variant == "naive":
        return _fit_naive(pb, init or "slices")
    if variant == "g-from-d":
        return _fit_g_from_d(pb, init, extrapolate)
    return _fit_independent_g(pb, starts, n_random=n_random, g_smoothing=g_smoothing,
                              start_max_iter=start_max_iter, extrapolate=extrapolate,
                              verbose=verbose)


@dataclasses.dataclass
class _Problem:
    """What every variant of :func:`fit_npf` shares: the input on the MERL grid, the
    prepared objective (Eq. 7-12) and its reference energy, the model's name and source,
    the resolved stopping rule, dynamic-range clamp and polish, and the ``fit_info`` and
    ``fit_options`` being filled."""

    variant: str
    values: np.ndarray
    valid: np.ndarray
    brdf: BRDF | None
    obj: Any
    name: str
    source: str | None
    eps: float
    max_iter: int
    tol: float
    seed: int
    polish: int
    polish_bound: float | None
    callback: Any
    reference: np.ndarray       # the reference energy per channel (the objective's scale)
    info: dict
    options: dict
    t_start: float

    def finish(self, model, E, extra: dict):
        """``model`` with its ``fit_info`` (the runs' ``extra``, the convergence report,
        the objective of Eq. 7 per channel ``E``, the time) and ``fit_options``."""
        E = np.asarray(E, dtype=np.float64)
        info = self.info
        info.update(extra)
        info.update(_convergence(extra, self.tol, self.max_iter, self.variant))
        info.update(objective=float(E.sum()), objective_per_channel=E.tolist(),
                    normalised_objective=float(E.sum() / self.reference.sum()),
                    time=time.perf_counter() - self.t_start)
        model.fit_options = self.options
        return record(model, info, success=info["success"], converged=info["converged"],
                      message=info["message"], nit=info["nit"], fun=info["objective"],
                      time=info["time"])


def _problem(brdf, data, variant, *, name, seed, callback, objective, eps, max_iter, tol,
             polish, polish_bound) -> _Problem:
    """The :class:`_Problem` of a fit: the input read and tabulated, the objective prepared,
    the per-variant defaults of ``dr_epsilon``, ``max_iter``, ``polish`` and
    ``polish_bound`` applied (:data:`DEFAULT_MAX_ITER`, :data:`DEFAULT_POLISH`,
    :data:`DEFAULT_POLISH_BOUND`)."""
    t_start = time.perf_counter()
    values, valid, brdf_obj = _resolve_input(brdf, data)
    source = getattr(brdf_obj, "source", None) or (brdf if isinstance(brdf, str) else None)
    mat_name = name or getattr(brdf_obj, "name", None) or "npf"
    obj = prepare_objective(values, valid, objective, source=source)
    eps = eps if eps is not None else (1e-6 if variant == "independent-g" else 0.0)
    max_iter = max_iter or DEFAULT_MAX_ITER.get(variant, 1)
    polish = DEFAULT_POLISH.get(variant, 0) if polish is None else int(polish)
    if polish < 0:
        raise ValueError(f"polish: expected an integer >= 0, found {polish}")
    polish_bound = _polish_bound(polish_bound, variant)
    options = {"variant": variant, "objective": objective.to_dict(), "max_iter": max_iter,
               "tol": tol, "dr_epsilon": eps, "seed": seed}
    ref = obj.reference_energy()
    info: dict = {"variant": variant, "n_samples": obj.n_samples,
                  "rho_bar": obj.rho_bar.tolist(), "reference_energy": ref.tolist()}
    return _Problem(variant, values, valid, brdf_obj, obj, mat_name, source, eps, max_iter,
                    tol, seed, polish, polish_bound, callback, ref, info, options, t_start)


def _fit_bivariate(pb: _Problem):
    """Eq. 5: B(θh, θd) and F by one weighted least-squares solve per bin (closed form)."""
    B, E = _solver.fit_bivariate_table(pb.obj)
    _check_state([B], "bivariate fit")
    model = NPFBivariateBRDF(np.moveaxis(B, 0, -1), name=pb.name, source=pb.source)
    return pb.finish(model, E, {"iterations": 1, "line_searches": 0,
                                "history": [float(E.sum())], "stop_reason": "closed form"})


def _fit_naive(pb: _Problem, init: str):
    """Eq. 4: D(θh) F(θd) H(φd) by AWLS from the ``init`` start."""
    pb.options["init"] = init
    W, WZ = _solver.dense_tensors(pb.obj)
    st0 = _start_state(init, pb.values, pb.valid, np.random.default_rng(pb.seed))
    st = NaiveState(D=st0.D, F=st0.F, H=np.ones((3, 180)), rho_d=st0.rho_d, rho_s=st0.rho_s)
    res = _solver.run_naive(st, W, WZ, pb.reference, eps=pb.eps, tol=pb.tol,
                            max_iter=pb.max_iter,
                            callback=step_callback(pb.callback, "naive AWLS", pb.max_iter))
    st = res.state
    _check_state([st.D, st.F, st.H, st.rho_d, st.rho_s], "naive fit")
    E = _solver.naive_exact_objective(st, pb.obj)
    model = NPFNaiveBRDF(st.D.T, st.F.T, st.H.T, st.rho_d, st.rho_s, name=pb.name,
                         source=pb.source)
    return pb.finish(model, E, _run_info(res))


def _fit_g_from_d(pb: _Problem, init: str | None, extrapolate: bool):
    """Eq. 3 with G derived from D (Smith): AWLS from each start (:data:`G_FROM_D_STARTS`,
    or ``init`` alone), per channel the start that is lower after
    :data:`G_FROM_D_SCREEN_POLISH` polish iterations kept, then the rest of the polish."""
    starts = G_FROM_D_STARTS if init is None else (init,)
    pb.options.update(init=init, starts=list(starts), extrapolate=extrapolate,
                      polish=pb.polish, polish_bound=pb.polish_bound)
    smp = Samples.from_objective(pb.obj)
    rng = np.random.default_rng(pb.seed)
    after = G_FROM_D_EXTRAPOLATE_AFTER if extrapolate else None
    results = [_solver.run_g_from_d(_start_state(label, pb.values, pb.valid, rng), smp,
                                    eps=pb.eps, tol=pb.tol, max_iter=pb.max_iter,
                                    extrapolate_after=after, window=G_FROM_D_WINDOW,
                                    callback=step_callback(pb.callback, "G-from-D AWLS",
                                                           pb.max_iter))
               for label in starts]
    polish = dict(eps=pb.eps, tol=pb.tol, g_from_d=True, bound=pb.polish_bound)
    screen = max(0, min(G_FROM_D_SCREEN_POLISH, pb.polish - 1)) if len(starts) > 1 else 0
    screened = [_solver.polish_lm(r.state.copy(), smp, max_iter=screen, finish=False,
                                  bounded=POLISH_BOUNDED["g-from-d"], **polish)
                if _finite(r) else r for r in results] if screen else None
    st, E, extra, carry = _best_start_per_channel(starts, results, screened)
    if pb.polish > 0:
        st, E = _polish(st, E, smp, extra, polish=pb.polish, callback=pb.callback,
                        carry=carry, **polish)
    _check_state(_solver._state_arrays(st), "G-from-D fit")
    return pb.finish(_mf_model(st, "g-from-d", pb.name, pb.source), E, extra)


def _finite(res) -> bool:
    return all(np.all(np.isfinite(a)) for a in _solver._state_arrays(res.state))


def _best_start_per_channel(starts, results, screened=None):
    """``(state, E, extra, carry)``: per channel the run of ``results`` (AWLS, one per start
    of ``starts``) with the lowest objective, or, with ``screened`` (their first polish
    iterations, ``finish=False``), the lowest after those, and ``carry`` to continue the
    polish (None without); the channels are independent problems. ``extra``: the
    ``fit_info`` fields of the runs: ``starts`` (one record per start), ``start_basins``,
    ``best_start_per_channel``; ``iterations``, ``history`` and the AWLS ``stop_reason``
    those of the start kept in most channels (the first on a tie), ``sweeps_all_starts``
    the sweeps of all of them, ``screen_polish`` the iterations of the screen."""
    runs = screened or results
    finite = [_finite(r) for r in runs]
    if not any(finite):
        raise FitError("G-from-D fit: no start produced finite factors")
    E = np.array([r.E if ok else np.full(3, np.inf) for r, ok in zip(runs, finite)])
    pick = np.argmin(E, axis=0)
    records = [{"start": label, "status": "ok" if ok else "non-finite",
                "objective": float(r.E.sum()), "objective_per_channel": r.E.tolist(),
                **_run_info(r)} for label, r, ok in zip(starts, results, finite)]
    main = int(np.bincount(pick, minlength=len(results)).argmax())
    extra = {**_run_info(results[main]),
             "sweeps_all_starts": int(sum(r.iterations for r in results)),
             "starts": records, "best_start_per_channel": [starts[k] for k in pick]}
    if screened is None:
        st, E, carry = _solver.combine_polish(results, pick)
    else:
        for rec, r in zip(records, screened):
            rec["objective_after_screen"] = r.E.tolist()
        st, E, carry = _solver.combine_polish(screened, pick)
        extra["screen_polish"] = {"iterations": screened[main].iterations,
                                  "history": [float(h) for h in screened[main].history],
                                  "awls_objective_per_channel": [
                                      float(results[k].E[c]) for c, k in enumerate(pick)]}
    extra["start_basins"] = start_basins(records)
    return st, E, extra, carry


def _fit_independent_g(pb: _Problem, starts, *, n_random, g_smoothing, start_max_iter,
                       extrapolate, verbose):
    """Eq. 3 with an independent G (§4.3): every start screened for ``start_max_iter`` AWLS
    iterations (:func:`_multi_start`), the per-channel best continued up to ``max_iter``
    (:func:`_continue_best`), then the polish."""
    starts = DEFAULT_STARTS if starts is None else starts
    screen = start_max_iter if start_max_iter is not None else pb.max_iter
    screen = min(screen, pb.max_iter)
    rounds = _screen_rounds(SCREEN_ROUNDS, screen)
    pb.options.update(starts=list(starts), n_random=n_random, g_smoothing=g_smoothing,
                      start_max_iter=screen, screen_rounds=[list(r) for r in rounds],
                      polish=pb.polish, polish_bound=pb.polish_bound, extrapolate=extrapolate)
    smp = Samples.from_objective(pb.obj)
    start_states = _start_states(pb, starts, n_random, smp)

    def run(st, max_iter, what, window=None, active=None, carry=None):
        return _solver.run_independent_g(st, smp, eps=pb.eps, smoothing=g_smoothing,
                                         tol=pb.tol, max_iter=max_iter,
                                         extrapolate=extrapolate, window=window,
                                         jump_every=JUMP_EVERY if window else None,
                                         active=active, carry=carry,
                                         callback=step_callback(pb.callback, what, max_iter))

    runs, results = _multi_start(
        start_states, lambda label, st: run(st, rounds[0][0], f"start {label}"),
        verbose, f"{pb.source or pb.name}: independent-G fit")
    protected = {i for i, (label, _) in enumerate(results) if label in PROTECTED_STARTS}
    best, n_screened = _later_rounds(runs, results, rounds, screen, run, protected)
    extra = {"starts": runs, "best_start_per_channel": best[2],
             "start_basins": start_basins(runs)}
    bst, bE = _continue_best(best, extra, n_screened, screen, pb.max_iter,
                             lambda st, n, on: run(st, n, "best start, continued",
                                                   CONTINUATION_WINDOW, on))
    if pb.polish > 0:
        bst, bE = _polish(bst, bE, smp, extra, eps=pb.eps, polish=pb.polish, tol=pb.tol,
                          g_from_d=False, bound=pb.polish_bound, callback=pb.callback)
    _check_state(_solver._state_arrays(bst), "independent-G fit")
    return pb.finish(_mf_model(bst, "independent-g", pb.name, pb.source), bE, extra)


def _screen_rounds(value, screen: int) -> list[tuple[int, float, int | None]]:
    """The screening's rounds ``value`` (:data:`SCREEN_ROUNDS`) checked: :data:`SCREEN_ROUNDS`
    for ``None``, ``False`` for one round (every start runs all ``screen`` iterations); the
    rounds at or past ``screen`` dropped (the first is cut to ``screen``)."""
    value = SCREEN_ROUNDS if value is None else (((screen, 1.0, None),) if value is False
                                                 else value)
    rounds, last = [], 0
    try:
        for n, ratio, keep in value:
            n, ratio, keep = int(n), float(ratio), None if keep is None else int(keep)
            if n <= last or not ratio >= 1 or (keep is not None and keep < 1):
                raise ValueError
            rounds.append((n, ratio, keep))
            last = n
    except (TypeError, ValueError):
        rounds = []
    if not rounds:
        raise ValueError(f"screen_rounds: expected rounds (iterations, ratio >= 1, keep >= 1 "
                         f"or None) with increasing iterations >= 1, None or False, found "
                         f"{value!r}")
    return [(min(rounds[0][0], screen),) + rounds[0][1:]] + [r for r in rounds[1:]
                                                             if r[0] < screen]


def _start_states(pb: _Problem, starts, n_random, smp) -> list[tuple[str, MFState | None, str]]:
    """``(label, state, note)`` of every independent-G start, in the order of ``starts``
    (``state`` None: the start is unavailable, ``note`` says why); the G-from-D start's
    run is recorded in ``info["g_from_d_start"]``."""
    rng = np.random.default_rng(pb.seed)
    out: list[tuple[str, MFState | None, str]] = []
    for s in starts:
        if s == "random":
            for k in range(n_random):
                out.append((f"random-{k}", _random_start(rng),
                            f"uniform(0.05, 1), seed {pb.seed}"))
        elif s == "ones":
            out.append(("ones", _ones_start(), "all ones"))
        elif s == "slices":
            out.append(("slices", _slice_start(pb.values, pb.valid),
                        "D from θd=0, F from θh=0, G=1"))
        elif s == "sgd":
            st, note = _sgd_start(pb.brdf, pb.values, pb.valid)
            out.append(("sgd", st, note))
        elif s == "g-from-d":
            n = G_FROM_D_START_MAX_ITER
            gres = _solver.run_g_from_d(_slice_start(pb.values, pb.valid), smp, eps=0.0,
                                        tol=pb.tol, max_iter=n,
                                        extrapolate_after=G_FROM_D_EXTRAPOLATE_AFTER,
                                        window=G_FROM_D_WINDOW, callback=step_callback(
                                            None, "G-from-D for the g-from-d start", n))
            g, eps = gres.state, pb.eps
            pb.info["g_from_d_start"] = {"objective": float(gres.E.sum()),
                                         "iterations": gres.iterations, "time_s": gres.seconds}
            out.append(("g-from-d", MFState(np.maximum(g.D, eps), np.maximum(g.F, eps),
                                            np.maximum(g.G, eps), g.rho_d, g.rho_s),
                        "G-from-D fit"))
    return out


def _multi_start(start_states, run_start, verbose: bool, what: str):
    """The first round of the multi-start screening: ``run_start(label, state)`` for every
    available start, on parallel threads (the AWLS kernels release the GIL), merged in the
    fixed order of the starts so that the fit is deterministic. Returns ``(runs, results)``:
    a record per start and ``(label, RunResult)`` of those with finite factors. Raises
    :class:`FitError` when no start gives finite factors."""
    todo = [(label, st) for label, st, _ in start_states if st is not None]
    with ThreadPoolExecutor(max_workers=max(1, min(_n_threads(), len(todo)))) as pool:
        done = iter(list(pool.map(lambda t: run_start(*t), todo)))
    runs, results = [], []
    for label, st, note in start_states:
        if st is None:
            runs.append({"start": label, "status": note})
            continue
        res = next(done)
        ok = all(np.all(np.isfinite(a)) for a in _solver._state_arrays(res.state))
        info = _run_info(res)
        entry = {"start": label, "status": "ok" if ok else "non-finite", "note": note,
                 "objective": float(res.E.sum()), "objective_per_channel": res.E.tolist(),
                 **info, "iterations_per_channel": [res.iterations] * 3,
                 "stop_reason_per_channel": list(res.extra["stop_reason_per_channel"])}
        runs.append(entry)
        if verbose:
            print(f"[npf] start {label}: E={entry['objective']:.6g} it={res.iterations} "
                  f"t={res.seconds:.1f}s ({res.reason})")
        if ok:
            results.append((label, res))
    if not results:
        raise FitError(f"{what}: no start produced a valid model "
                       f"({[r.get('status') for r in runs]})")
    return runs, results


def _later_rounds(runs, results, rounds, screen: int, run, protected=frozenset()):
    """The screening's later rounds (:data:`SCREEN_ROUNDS`), per channel: after each round
    the starts within ``ratio`` of the channel's best, ``keep`` at most, run on to the next
    round's iterations (the last to ``screen``), the k-th best of every channel in one run
    (:func:`_solver.combine_channels`: a channel not run costs nothing; one that stopped by
    the AWLS rule is not run again). ``results``: ``(label, RunResult)`` of the first round.
    Updates the records ``runs``; returns ``((state, E, labels, done, history),
    iterations)``: per channel the best state, its objective, the start it came from and
    whether its run stopped by the AWLS rule, the summed objective of those runs per
    iteration; all the sweeps run. The starts in ``protected`` (indices into ``results``)
    run the first round only, are not ranked with the others and join the per-channel pick
    at the end."""
    held = [(i, res) for i, (_, res) in enumerate(results) if i in protected]
    free = [(i, res) for i, (_, res) in enumerate(results) if i not in protected]
    if not free:                                  # only protected starts: screened as any
        free, held = held, []
    cands = [list(free) for _ in range(3)]
    by_label = {r["start"]: r for r in runs}
    n_iter, done_at = sum(res.iterations for _, res in results), rounds[0][0]
    for (_, ratio, keep), until in zip(rounds, [r[0] for r in rounds[1:]] + [screen]):
        cands = [_survivors(cands[c], c, ratio, keep) for c in range(3)]
        for k in range(max(len(x) for x in cands) if until > done_at else 0):
            pick = [x[k] if k < len(x) else x[0] for x in cands]
            on = np.array([k < len(x) and not _converged(x[k][1], c)
                           for c, x in enumerate(cands)])
            if not on.any():
                continue
            st, carry = _solver.combine_channels([res for _, res in pick])
            res = run(st, until - done_at, "screening", active=on, carry=carry)
            n_iter += res.iterations
            for c in np.flatnonzero(on):
                cands[c][k] = (pick[c][0], res)
                rec = by_label[results[pick[c][0]][0]]
                rec["objective_per_channel"][c] = float(res.E[c])
                rec["iterations_per_channel"][c] += res.iterations
                rec["stop_reason_per_channel"][c] = res.extra["stop_reason_per_channel"][c]
        done_at = max(done_at, until)
    for rec in runs:
        if "objective_per_channel" in rec:
            rec["objective"] = float(np.sum(rec["objective_per_channel"]))
    best = [min(x + [h for h in held if np.isfinite(h[1].E[c])], key=lambda ir: ir[1].E[c])
            for c, x in enumerate(cands)]
    bst, carry = _solver.combine_channels([res for _, res in best])
    bE = np.array([res.E[c] for c, (_, res) in enumerate(best)], dtype=np.float64)
    done = np.array([_converged(res, c) for c, (_, res) in enumerate(best)])
    labels = [results[i][0] for i, _ in best]
    return (bst, bE, labels, done, carry["monitors"].history), n_iter


def _survivors(cands, c, ratio, keep):
    """The candidates ``(start, RunResult)`` of channel ``c`` whose objective is within
    ``ratio`` of the best, ``keep`` at most, best first."""
    ranked = sorted(((i, res) for i, res in cands if np.isfinite(res.E[c])),
                    key=lambda ir: ir[1].E[c]) or cands[:1]
    best = ranked[0][1].E[c]
    out = [(i, res) for i, res in ranked if res.E[c] <= ratio * best]
    return out[:keep] if keep is not None else out


def _converged(res, c) -> bool:
    """Whether channel ``c`` of the run ``res`` stopped by the AWLS rule."""
    return res.extra["stop_reason_per_channel"][c].startswith(_CONVERGED_REASONS)


#: screened start objectives closer than this (relative) count as one basin
BASIN_TOLERANCE = 0.01


def start_basins(runs, tol: float = BASIN_TOLERANCE) -> dict:
    """How far apart the screened starts ended, per channel: ``distinct`` (objectives more
    than ``tol`` apart, relative, after sorting: the basins the starts reached, as far as
    ``start_max_iter`` iterations tell) and ``spread`` (largest over smallest objective), over
    the ``starts`` that gave finite factors."""
    E = np.array([r["objective_per_channel"] for r in runs if r.get("status") == "ok"])
    if E.size == 0:
        return {"starts": 0, "distinct": [0, 0, 0], "spread": [None] * 3}
    srt = np.sort(E, axis=0)
    distinct = 1 + np.sum(srt[1:] > srt[:-1] * (1 + tol), axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        spread = np.where(srt[0] > 0, srt[-1] / srt[0], 1.0)
    return {"starts": len(E), "distinct": [int(d) for d in distinct],
            "spread": [float(x) for x in spread]}


def _continue_best(best, extra: dict, n_screened: int, screen: int, max_iter: int, run):
    """The per-channel best of the screened starts continued for the rest of ``max_iter``
    (``run(state, iterations, channels)``) in the channels whose screening did not stop by
    the AWLS rule; the result is kept per channel where it does not raise the objective.
    Fills ``extra`` (``iterations``: every sweep run, ``line_searches``, ``history``,
    ``stop_reason``, ``continuation``); returns ``(state, E)``."""
    bst, bE, _, done, history = best
    iters = n_screened
    history = [float(h) for h in history]
    if screen < max_iter and not done.all():
        res = run(bst, max_iter - screen, ~done)
        keep = np.isfinite(res.E) & (res.E <= bE * (1 + 1e-9))
        _solver._take(bst, res.state, keep)
        bE = np.where(keep, res.E, bE)
        extra["continuation"] = _run_info(res)
        iters += res.iterations
        history += [float(h) for h in res.history[1:]]
        reason = res.reason
    else:
        reason = "relative decrease (every channel's screening)" if done.all() else "max_iter"
    extra.update(iterations=int(iters), line_searches=int(iters), history=history,
                 stop_reason=reason)
    return bst, bE


def _polish_bound(value, variant) -> float | None:
    """``polish_bound`` checked: the variant's default for ``None``, no bound for 0."""
    if value is None:
        return DEFAULT_POLISH_BOUND.get(variant)
    try:
        bound = float(value)
    except (TypeError, ValueError):
        bound = float("nan")
    if bound == 0:
        return None
    if not (np.isfinite(bound) and bound > 1):
        raise ValueError(f"polish_bound: expected 0 (unbounded) or a number > 1, "
                         f"found {value!r}")
    return bound


def _polish(st: MFState, E, smp: Samples, extra: dict, *, eps, polish, tol, g_from_d, bound,
            callback, carry=None):
    """The Levenberg–Marquardt polish after AWLS (``_solver.polish_lm``): returns the state
    and objective, records ``extra["polish"]``, appends to ``extra["history"]``; the polish's
    stop becomes the fit's ``stop_reason`` (the AWLS's is kept in ``awls_stop_reason``).
    With ``carry`` it continues the screen's polish (``extra["screen_polish"]``), whose
    iterations count towards ``polish``."""
    bounded = POLISH_BOUNDED["g-from-d" if g_from_d else "independent-g"]
    screen = extra.get("screen_polish") if carry is not None else None
    done = screen["iterations"] if screen else 0
    pol = _solver.polish_lm(st, smp, eps=eps, max_iter=polish - done, tol=tol,
                            g_from_d=g_from_d, bound=bound, newton=True, bounded=bounded,
                            callback=step_callback(callback, "LM polish", polish - done),
                            carry=carry)
    awls_objective = float(np.sum(screen["awls_objective_per_channel"] if screen else E))
    st, E = pol.state, np.minimum(pol.E, E)              # only decreasing steps are taken
    extra["polish"] = {"iterations": done + pol.iterations, "max_iterations": polish,
                       "awls_objective": awls_objective, "method": "Newton", "bound": bound,
                       "bounded": list(bounded or ("D", "F", "G", "rho_s")),
                       "stop_reason": pol.reason, "run_time_s": pol.seconds}
    extra["history"] = (list(extra.get("history", []))
                        + (screen["history"][1:] if screen else [])
                        + [float(h) for h in pol.history[1:]])
    extra["awls_stop_reason"], extra["stop_reason"] = extra.get("stop_reason"), pol.reason
    return st, E


#: Stop reasons of ``_solver.Monitor`` (and the closed-form bivariate fit) that mean converged.
_CONVERGED_REASONS = ("relative decrease", "decrease over the last", "exact fit", "closed form",
                      "damping limit")


def _convergence(extra: dict, tol, max_iter, variant) -> dict:
    """The convergence fields of ``fit_info``, named as the tabulated fit's
    (:func:`brdffit.fit.tabulated`): ``converged``, ``success``, ``status``, ``message``,
    ``criterion``, ``tol``, ``nit``, ``max_iterations``, ``cap_reached``,
    ``final_relative_change`` (of the summed objective over the last iteration; for
    independent-G the stop of the run that produced the kept factors: the continuation of the
    best start, or the screened best starts when they converged; after the Levenberg–Marquardt
    polish, the polish's stop)."""
    reason = str(extra.get("stop_reason", "max_iter"))
    hist = [float(h) for h in extra.get("history", [])]
    last = (abs(hist[-2] - hist[-1]) / max(abs(hist[-1]), 1e-300)) if len(hist) >= 2 else 0.0
    nit = int(extra.get("iterations", len(hist) - 1 if hist else 0))
    cap, phase = max_iter, "AWLS"
    polish = extra.get("polish")
    if variant == "bivariate":
        criterion = "closed form (one weighted least-squares solve per (θh, θd) bin)"
    else:
        criterion = (f"relative decrease of the summed AWLS objective (E_prev - E) / E < tol "
                     f"= {tol:g} for 3 consecutive iterations (Monitor.patience), or an exact "
                     f"fit; safety cap max_iter = {max_iter}")
        if variant == "independent-g":
            n_win, factor = CONTINUATION_WINDOW
            criterion += (f"; the continuation of the best start also stops when its relative "
                          f"decrease over the last {n_win} iterations is < {n_win}·{factor:g}"
                          f"·tol = {n_win * factor * tol:g} (CONTINUATION_WINDOW), and a "
                          f"channel of it when its own decrease over them is < a third of "
                          f"that of the summed objective")
        elif variant == "g-from-d" and G_FROM_D_WINDOW is not None:
            n_win, factor = G_FROM_D_WINDOW
            criterion += (f"; each start's sweeps also stop when their relative decrease over "
                          f"the last {n_win} is < {n_win}·{factor:g}·tol = "
                          f"{n_win * factor * tol:g} (G_FROM_D_WINDOW)")
    if polish is not None:
        cap, phase = int(polish["max_iterations"]), "Levenberg–Marquardt polish"
        nit += int(polish["iterations"])
        method = polish.get("method", "Gauss–Newton")
        bounded = "/".join(polish.get("bounded") or ("D", "F", "G", "rho_s"))
        where = (f" within a factor {polish['bound']:g} of the AWLS values of {bounded} "
                 f"(polish_bound)" if polish.get("bound") else "")
        criterion += (f"; then the Levenberg–Marquardt polish ({method}{where}) until its "
                      f"relative decrease is < tol for 2 consecutive iterations or no damped "
                      f"step lowers the objective; safety cap polish = {cap}")
    converged = reason.startswith(_CONVERGED_REASONS)
    cap_reached = reason == "max_iter"
    if converged:
        msg = f"converged: {reason}"
    elif cap_reached:
        msg = (f"NOT converged: the {phase} cap of {cap} iterations was reached with relative "
               f"change {last:.2e}")
    else:
        msg = f"NOT converged: {reason}"
    return {"converged": bool(converged), "success": bool(converged),
            "status": 0 if converged else 1, "message": msg, "criterion": criterion,
            "tol": tol, "nit": nit,
            "max_iterations": max_iter + (cap if polish is not None else 0),
            "cap_reached": bool(cap_reached), "final_relative_change": float(last)}


def _run_info(res) -> dict:
    return {"iterations": res.iterations, "line_searches": res.line_searches,
            "line_search_evals": res.line_search_evals, "stop_reason": res.reason,
            "run_time_s": res.seconds, **res.extra,
            "history": [float(h) for h in res.history]}


def _checked_choices(variant, init, starts) -> tuple[str, tuple[str, ...] | None]:
    """``(variant, starts)``: the variant (a model name such as ``"npf"`` works too) and
    ``starts`` as a tuple (``None`` kept), ``init`` and each start checked against their
    choices (:data:`~brdffit.fit.options.NPFInit`, :data:`~brdffit.fit.options.NPFStart`)."""
    variant = CLI_VARIANTS.get(variant, variant)
    if variant not in VARIANTS:
        raise ValueError(f"variant: expected one of {VARIANTS} or the model names "
                         f"{tuple(CLI_VARIANTS)}, found {variant!r}")
    if init is not None:
        check_choice("init", init, NPFInit)
    if starts is None:
        return variant, None
    starts = tuple(starts)
    if not starts:
        raise ValueError("starts: expected a non-empty list of names, found ()")
    for name in starts:
        check_choice("starts", name, NPFStart)
    return variant, starts


def _start_state(init, values, valid, rng) -> MFState:
    """The start ``init`` (one of :data:`~brdffit.fit.options.NPFInit`, checked by
    :func:`fit_npf`)."""
    if init == "slices":
        return _slice_start(values, valid)
    if init == "ones":
        return _ones_start()
    return _random_start(rng)


def summary(model) -> dict:
    """Key figures of a fitted NPF model (for the CLI): objective, AWLS iterations, the
    Levenberg–Marquardt polish's iterations, whether the fit converged (and why not)."""
    info = model.fit_info or {}
    seconds = fit_result(model).time if isinstance(model.fit_info, dict) else None
    out = {"model": model.fit_kind, "variant": getattr(model, "variant", None),
           "objective": info.get("objective"),
           "normalised_objective": info.get("normalised_objective"),
           "iterations": info.get("iterations"), "line_searches": info.get("line_searches"),
           "polish_iterations": (info.get("polish") or {}).get("iterations"),
           "converged": info.get("converged"), "time_s": seconds}
    if info.get("converged") is False:
        out["message"] = info.get("message")
    return out


def _variant_fitter(variant: str, name: str):
    """``fit_npf`` with ``variant`` fixed, taking the command line's spelling of two options:
    ``iterations`` (``--iterations``) for ``max_iter`` and ``starts`` as a comma list."""
    def fit(brdf, **kw):
        if "iterations" in kw:
            kw["max_iter"] = int(kw.pop("iterations"))
        if isinstance(kw.get("starts"), str):
            kw["starts"] = tuple(x for x in kw["starts"].split(",") if x)
        return fit_npf(brdf, variant=variant, **kw)

    fit.__name__ = fit.__qualname__ = name
    fit.__doc__ = (f"fit_npf(variant={variant!r}): the {variant} factor model of Bagher, "
                   "Snyder & Nowrouzezahrai 2016 (the models of brdffit.fit.registry.MODELS).")
    return fit


fit_npf_independent_g = _variant_fitter("independent-g", "fit_npf_independent_g")
fit_npf_g_from_d = _variant_fitter("g-from-d", "fit_npf_g_from_d")
fit_npf_naive = _variant_fitter("naive", "fit_npf_naive")
fit_npf_bivariate = _variant_fitter("bivariate", "fit_npf_bivariate")
