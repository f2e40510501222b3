"""Analytic microfacet fits with a Lambertian lobe, on the whole measured data.

Models ``ggx-diffuse`` and ``beckmann-diffuse`` (:func:`fit_ggx_diffuse`,
:func:`fit_beckmann_diffuse`), both a :class:`~brdffit.microfacet.MicrofacetBRDF`::

    f_r(i, o) = ρd/π + F(θd) D(h) G(i, o) / (4 cos θi cos θo)           (Dupuy 2015 Eq. 1)

* ρd: Lambertian albedo per RGB channel (the term is ρd/π);
* D: GGX or Beckmann with slope scales (αx, αy, ρ) (Dupuy 2015 App. C) when the input is
  anisotropic, isotropic α when it is isotropic (``anisotropic=None`` follows
  ``brdf.isotropic``); α ∈ [``ALPHA_MIN``, 1] (glTF's roughness = √α ≤ 1);
* G: the height-correlated Smith term (Dupuy Eq. 2) of the distribution;
* F: Schlick ``F0 + (1 − F0)(1 − cos θd)⁵`` with F0 ∈ [0, 1] per channel
  (:class:`~brdffit.microfacet.SchlickFresnel`), or the exact dielectric Fresnel of one
  index η (``fresnel="dielectric"``), or the exact
  conductor Fresnel of a per-channel complex index ``η + i k`` (``fresnel="conductor"``,
  :class:`~brdffit.microfacet.ConductorFresnel`). ``f90="free"`` fits a per-channel
  specular scale ``ks ≤ 1`` as well (``specular=ks``: ``F = ks·Schlick(F0)``, ``F(90°) = ks``),
  so that F ≤ 1 at every angle by construction.

**Which Fresnel** (``fresnel="auto"``, the default, fits the three and keeps the lowest
objective, the conductor only when it is at least ``CONDUCTOR_MARGIN`` = 5 % below the best of
the other two). Schlick is what the engine formats carry exactly — glTF's metal and
dielectric Fresnel and OpenPBR's metal with ``specular_color`` = white are Schlick curves
(:mod:`brdffit.export.gltf`, :mod:`brdffit.export.materialx`) — and the model is *linear* in
(ρd, F0) for a fixed distribution, which makes that fit exact and robust (below). The
conductor adds six nonlinear, weakly determined parameters (η and k trade off against each
other for F0 ≳ 0.5), hence the margin; it is exported exactly to Mitsuba's
``roughconductor`` and as its Schlick curve (F0 = F(0°)) to glTF/MaterialX, with the loss
measured by the export. It is worth it on metals (2-4 dB of rendered PSNR over the Schlick
fit on MERL's metals). On ``synthetic:gold-ggx`` (a conductor) it recovers gold's (η, k)
within 0.1 %.

**The coat** (``coat="auto"``, the default; isotropic fits with ``f90="free"``). A second,
white specular lobe of index 1.5 — what glTF's ``KHR_materials_clearcoat`` and OpenPBR's
coat carry — is added to a Schlick base::

    f_r = ρd/π + ks S_b (F0 + (1 − F0) x⁵) + w S_c (0.04 + 0.96 x⁵),   w ∈ [0, 1]

(``S_b``, ``S_c`` the shapes of the base and coat distributions, one coat weight w for the
three channels; the coat is *added*, where glTF and OpenPBR layer it over the base — the
exporters measure that difference). For fixed (α_b, α_c) the model is linear in (ρd, A =
ks F0, C = ks (1 − F0)) per channel and w, solved exactly with its bounds; (ln α_b, ln α_c)
by a 24 × 24 scan of [ALPHA_MIN, 1]² and Nelder-Mead (0.3-0.6 s). The coated fit is kept when
its objective is at least ``COAT_MARGIN`` = 5 % below the best uncoated one (and by more
than ``COAT_MIN_GAIN`` of the data's energy): rendered, a coat that lowers the objective by
less than that gains little and loses on some materials, a coat below the margin gains on
nearly all (``bench/studies/coat_margin.py``). The coat takes the heavy tail of plastics,
phenolics and lacquered woods that one GGX lobe cannot.
(The coat search runs on every isotropic fit; ``coat="off"`` skips it, ``coat="on"`` keeps
any coat that lowers the objective.)

**Physically valid by construction.** Every Fresnel lobe has F ≤ 1 at every angle (ks ≤ 1:
the Schlick ``A + C ≤ 1`` per channel is a constraint of the exact linear solve, the exact
Fresnel forms bound ks by 1), and the white furnace holds: the fitted ρd is lowered, where
needed, so that ρd plus the specular lobes' directional albedo stays ≤ 1 at every incidence
of ``brdffit.furnace.HOLD_ANGLES_DEG`` (:func:`brdffit.furnace.hold_diffuse`;
``fit_info["rho_d_furnace_lowering"]``;
the objective reported is that of the held model). The checks of
:mod:`brdffit.evaluation.validity` then pass on every fit.

Objective
---------
The compressive-weighted least squares of Bagher, Snyder & Nowrouzezahrai 2016 **Eq. 7-12**
(:mod:`brdffit.losses.objective`): ``E = Σ_c Σ_j w_cj (f_c(j) − ρ*_cj)²`` with
``w = wV · wI · wC`` (volume form, ``cos θi cos θo``, compressive weight with p = 1.4,
α = log 2 and ρ̄ the ``wV wI``-weighted median per channel), samples with θi or θo > 89°
excluded — so highlights and dark regions both count. Isotropic input: the MERL
(θh, θd, φd) grid, all 90 θh nodes, every ``theta_d_stride``-th θd node below 72° and every
node above (grazing rows vary fast), every ``phi_d_stride``-th φd node (≈ 70 000 samples
with the defaults; the weights of :func:`brdffit.losses.objective.volume_form_weight` scaled
by the nodes each sample stands for). **Deviation**: a subsample instead of all 1.1 M
samples, for speed; the objective reported by ``bench/bench_analytic.py`` is the full-grid
one (:func:`brdffit.losses.objective.compressive_objective`). Anisotropic input: the same
weights on a 4D grid (θh, φh, θd, φd) with the 4D volume form
``dωi dωo = 4 cos θd sin θd sin θh dθh dφh dθd dφd`` in place of Eq. 9 (the isotropic
Eq. 9 is that form integrated over φh) — an extension, the paper has no anisotropic data.

Minimisation (variable projection)
----------------------------------
For a fixed distribution the model is linear in (ρd_c, F0_c) per channel:
``f_c = ρd_c·(1/π) + F0_c·S(1 − x⁵) + S x⁵`` with ``S = D G/(4 cos θi cos θo)`` and
``x = 1 − cos θd`` (``f90="free"``: ``f_c = ρd_c/π + A_c S + C_c S x⁵``, ``A = ks F0``,
``C = ks(1 − F0)``). Those are solved *exactly* with their bounds (ρd ∈ [0, ALBEDO_MAX],
F0 ∈ [0, 1]; A, C ≥ 0 with A + C = ks ≤ 1) by enumerating the active sets of the tiny
box-constrained quadratic problem (the face ``A + C = 1`` when its optimum has ks > 1), so only
the distribution parameters are searched:

* isotropic: ln α over a 32-node scan of [ALPHA_MIN, 1] (multi-start: the ``starts`` best
  local minima of the scan plus the Dupuy slope-moment α of :func:`fit_ggx` /
  :func:`fit_beckmann` — the paper's conversion, Dupuy 2015 App. C), each refined by a
  bounded Brent search between its neighbouring nodes;
* anisotropic: (ln αx, ln αy, ρ) by bounded trust-region least squares
  (``scipy.optimize.least_squares``, TRF) from the slope-moment (αx, αy, ρ), the best
  isotropic α and its 3 best scan minima (ρ = 0, αx = αy).

* dielectric (one index η), isotropic: for each α, η is profiled out on per-θd-node sums
  (a 17-node scan of ln(η − 1) and a bounded Brent search; (ρd, ks) exact for each η, as for
  the conductor below), and ln α by a bounded Brent search within a factor 2 of the Schlick
  α (the bracket moved, at most twice, when the minimum lands on its edge). Anisotropic: TRF
  on (ln αx, ln αy, ρ, η) from the Schlick optimum (η from its F0, and η = 1.5). The
  isotropic profile search is used because TRF with a finite-difference Jacobian over all
  residuals costs most of the fit time for no better objective.
* conductor: per channel, (ln η, ln(k + 0.01)) by bounded L-BFGS-B from the best 3 of the
  (η, k) matching the Schlick F0 and a coarse (η, k) grid, (ρd, ks) solved exactly inside;
  the objective is summed per θd node (the samples lie on MERL θd nodes, where F is one
  value), so each evaluation costs O(90), not O(samples); then ln α by a bounded Brent search
  within a factor 1.5 of the Schlick α (isotropic; an anisotropic fit keeps the Schlick
  distribution).

All parameters are bounded; a candidate with a non-finite error is discarded; the result is
never NaN (:class:`~brdffit.errors.FitError` when no finite candidate exists or the data has
no valid sample). ``fit_info`` holds the parameters, the subsample objective (also
normalised by the all-zero model's), the starts and the time.

Design notes (the measurements behind the Fresnel choice and the coat margin):
docs/design/analytic-fit.md
"""

from __future__ import annotations

import math
import time

import numpy as np
from scipy import optimize

from .._blas import with_single_blas_thread
from ..errors import FitError
from ..furnace import hold_diffuse
from ..geometry import half_diff_to_io
from ..brdf import measured_mask
from ..grid import (N_PHI_D, N_THETA_D, N_THETA_H, merl_node_values, merl_phi_d, merl_theta_d,
                    merl_theta_h)
from ..microfacet.coat import COAT_F0
from ..microfacet.shadowing import EllipticalSlopeDistribution
from ..schema import ALBEDO_MAX, INDEX_MAX
from .options import F90, Coat, FresnelChoice, check_choice
from .result import record
from ..losses.objective import (
    ObjectiveOptions, compressive_weight, volume_form_weight, weighted_median,
)
from ..microfacet import (Beckmann, ConductorFresnel, DielectricFresnel, GGX, MicrofacetBRDF,
                          SchlickFresnel, SumBRDF)
from ..microfacet.fresnel import conductor_reflectance, dielectric_reflectance
from ..microfacet.tabulated import TabulatedSlopeDistribution, radial_rule
from .tabulated import backscatter, fit_tabulated, luminance, solve_slope_pdf

__all__ = ["fit_analytic_diffuse", "fit_ggx_diffuse", "fit_beckmann_diffuse", "sample_set",
           "ALPHA_MIN", "ALPHA_MAX_FIT", "COAT_MARGIN", "summary"]

#: roughness bounds of the fits (α ≤ 1: glTF's roughness √α ≤ 1 keeps the export exact)
ALPHA_MIN, ALPHA_MAX_FIT = 2e-3, 1.0
#: θd rows from this MERL index on are all kept (grazing rows vary fast)
GRAZING_ROW = 72
RHO_MAX = 0.95
#: bounds of the dielectric index η and of the specular scale ks (ks ≤ 1: F ≤ 1 at every
#: angle, every exact and Schlick Fresnel reaching 1 at grazing)
ETA_BOUNDS = (1.001, 4.0)
KS_MAX = 1.0
_MAX_THETA_IO_DEG = 89.0
_SCAN = 32


# ------------------------------------------------------------------------------------------
# the data: samples, weights (Bagher 2016 Eq. 8)
# ------------------------------------------------------------------------------------------
def _clean(values, valid=None):
    v = np.asarray(values, dtype=np.float64)
    ok = np.all(np.isfinite(v), axis=-1) & np.all(v >= 0, axis=-1)
    if valid is not None:
        ok &= np.asarray(valid, dtype=bool)
    return np.where(ok[..., None], v, 0.0), ok


def _merl_rows(stride: int, grazing_stride: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """θd indices kept and the number of nodes each stands for."""
    jd = np.union1d(np.arange(0, N_THETA_D, max(int(stride), 1)),
                    np.arange(min(GRAZING_ROW, N_THETA_D), N_THETA_D, grazing_stride))
    return jd, np.diff(np.append(jd, N_THETA_D)).astype(np.float64)


def _isotropic_samples(brdf, theta_d_stride: int, phi_d_stride: int):
    jd, width = _merl_rows(theta_d_stride)
    sp = max(int(phi_d_stride), 1)
    kp = np.arange(0, N_PHI_D, sp)
    TH, TD, PD = np.meshgrid(merl_theta_h(), merl_theta_d()[jd], merl_phi_d()[kp], indexing="ij")
    wv = volume_form_weight()[:, jd][:, :, kp] * width[None, :, None] * sp
    v, ok = _clean(*merl_node_values(brdf, slice(None), jd, kp))
    wi, wo = half_diff_to_io(TH, 0.0, TD, PD)
    return wi.reshape(-1, 3), wo.reshape(-1, 3), v.reshape(-1, 3), ok.ravel(), wv.ravel()


def _anisotropic_samples(brdf, theta_h_stride: int, n_phi_h: int, theta_d_stride: int,
                         phi_d_stride: int):
    ih = np.arange(0, N_THETA_H, max(int(theta_h_stride), 1))
    th = merl_theta_h()[ih]
    # θh = (u²)π/2 with u = i/90: dθh = π u du, du = stride/90
    dth = np.pi * (ih / N_THETA_H) * (max(int(theta_h_stride), 1) / N_THETA_H)
    dth[0] = np.pi / 2 * (0.5 * max(int(theta_h_stride), 1) / N_THETA_H) ** 2   # first cell
    jd, width = _merl_rows(theta_d_stride, 2)
    td = merl_theta_d()[jd]
    sp = max(int(phi_d_stride), 1)
    pd = merl_phi_d()[::sp]
    ph = (np.arange(n_phi_h) + 0.5) * (2 * np.pi / n_phi_h)
    TH, PH, TD, PD = np.meshgrid(th, ph, td, pd, indexing="ij")
    cell = (dth[:, None, None, None] * (2 * np.pi / n_phi_h) * (np.pi / 2 / N_THETA_D)
            * width[None, None, :, None] * (np.pi / N_PHI_D) * sp)
    # 4D volume form of (θh, φh, θd, φd) -> (i, o); sin θd at the θd cell centre so the
    # θd = 0 row keeps a weight (as the isotropic objective does, see its docstring)
    tdc = td + 0.5 * np.pi / 2 / N_THETA_D
    wv = 4.0 * np.cos(TD) * np.sin(tdc)[None, None, :, None] * np.sin(np.maximum(TH, 1e-3)) * cell
    wi, wo = half_diff_to_io(TH, PH, TD, PD)
    wi, wo = wi.reshape(-1, 3), wo.reshape(-1, 3)
    v, ok = _clean(np.asarray(brdf.eval(wi, wo), dtype=np.float64), measured_mask(brdf, wi, wo))
    return wi, wo, v, ok, wv.ravel()


def sample_set(brdf, anisotropic: bool, *, theta_d_stride: int | None = None,
               phi_d_stride: int | None = None, theta_h_stride: int = 3, n_phi_h: int = 12,
               options=None) -> dict:
    """The fitting samples of ``brdf`` with the weights of Bagher 2016 Eq. 8 (module doc).

    Strides default to 3 (θd) and 10 (φd) for isotropic input, 6 and 20 for anisotropic
    input (with every 3rd θh, 12 φh and every 2nd grazing θd row: ≈ 70 000 samples either
    way).

    Returns ``wi, wo`` ``(N, 3)``, ``z`` ``(N, 3)`` (measurements clamped at 0), ``w``
    ``(N, 3)`` (``wV wI wC`` per channel, 0 for invalid samples) and ``rho_bar`` ``(3,)``.
    """
    opts = options or ObjectiveOptions()
    if theta_d_stride is None:
        theta_d_stride = 6 if anisotropic else 3
    if phi_d_stride is None:
        phi_d_stride = 20 if anisotropic else 10
    if anisotropic:
        wi, wo, z, ok, wv = _anisotropic_samples(brdf, theta_h_stride, n_phi_h, theta_d_stride,
                                                 phi_d_stride)
    else:
        wi, wo, z, ok, wv = _isotropic_samples(brdf, theta_d_stride, phi_d_stride)
    lim = math.cos(math.radians(opts.max_theta_io_deg))
    keep = ok & (wi[:, 2] >= lim - 1e-12) & (wo[:, 2] >= lim - 1e-12) & (wi[:, 2] > 0) \
        & (wo[:, 2] > 0) & (wv > 0)
    if opts.restrict_deg is not None:
        cr = math.cos(math.radians(opts.restrict_deg))
        keep &= (wi[:, 2] >= cr - 1e-12) & (wo[:, 2] >= cr - 1e-12)
    label = getattr(brdf, "name", None) or "input"
    if np.count_nonzero(keep) < 16:
        raise FitError(f"{label}: expected valid samples with θi, θo ≤ {opts.max_theta_io_deg}°, "
                       f"found {int(np.count_nonzero(keep))}")
    wi, wo, z, wv = wi[keep], wo[keep], z[keep], wv[keep]
    wvi = wv * wi[:, 2] * wo[:, 2]
    rho_bar = np.empty(3)
    w = np.empty_like(z)
    for c in range(3):
        rb = weighted_median(z[:, c], wvi)
        if not rb > 0:
            mean = float(np.sum(z[:, c] * wvi) / np.sum(wvi))
            rb = mean if mean > 0 else 1.0
        rho_bar[c] = rb
        w[:, c] = wvi * (compressive_weight(z[:, c], rb, opts.p, opts.alpha)
                         if opts.compressive else 1.0)
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    cos_d = np.clip(np.sum(wi * h, -1), 0.0, 1.0)
    x5 = (1.0 - cos_d) ** 5
    return {"wi": wi, "wo": wo, "h": h, "cos_d": cos_d, "x5": x5, "z": z, "w": w, "rho_bar": rho_bar,
            "n": int(z.shape[0]), "anisotropic": bool(anisotropic),
            "ref_energy": float(np.sum(w * z * z))}


# ------------------------------------------------------------------------------------------
# the linear part: exact box-constrained least squares per channel
# ------------------------------------------------------------------------------------------
def _distribution(kind: str, ax: float, ay: float | None = None, rho: float = 0.0):
    cls = GGX if kind == "ggx" else Beckmann
    return cls(ax, ax if ay is None else ay, rho)


def _isotropic_geometry(data) -> dict:
    """The sample set's ``tan θi``, ``tan θo``, ``tan²θh`` and ``1/(4 cos⁴θh cos θi cos θo)``
    (computed once, kept in ``data``): an isotropic lobe is a function of these alone."""
    geo = data.get("_isotropic_geometry")
    if geo is None:
        wi, wo, h = data["wi"], data["wo"], data["h"]

        def tan2(w):
            return (w[:, 0] ** 2 + w[:, 1] ** 2) / w[:, 2] ** 2

        geo = {"tan_i": np.sqrt(tan2(wi)), "tan_o": np.sqrt(tan2(wo)), "tan2_h": tan2(h),
               "scale": 1.0 / (4.0 * h[:, 2] ** 4 * wi[:, 2] * wo[:, 2])}
        data["_isotropic_geometry"] = geo
    return geo


def _spec_shape(dist, data) -> np.ndarray:
    """``S = D(h) G2(i, o) / (4 cos θi cos θo)`` (height-correlated Smith, Dupuy Eq. 2); an
    isotropic lobe from the polar angles alone (:func:`_isotropic_geometry`: the same values
    to rounding, 2-4× faster — the searches evaluate hundreds of lobes)."""
    with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
        if isinstance(dist, EllipticalSlopeDistribution) and dist.isotropic:
            geo = _isotropic_geometry(data)
            G = 1.0 / (1.0 + dist.Lambda_of_tan(geo["tan_i"]) + dist.Lambda_of_tan(geo["tan_o"]))
            S = dist.D_cos4(geo["tan2_h"]) * G * geo["scale"]
        else:
            wi, wo = data["wi"], data["wo"]
            G = 1.0 / (1.0 + dist.Lambda(wi) + dist.Lambda(wo))
            S = dist.D(data["h"]) * G / (4.0 * wi[:, 2] * wo[:, 2])
    return np.where(np.isfinite(S), S, 0.0)


def _box_qp(H, g, lo, hi):
    """``argmin ½xᵀHx − gᵀx`` on the box ``lo ≤ x ≤ hi`` (1 to 3 variables) by enumerating
    the active sets (each variable free, at ``lo`` or at ``hi``): exact for the convex case.
    Returns ``(x, value)`` (``(None, inf)`` when nothing is finite)."""
    k = len(g)
    if k <= 2:
        return _box_qp_small(H, g, lo, hi)
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    try:                                  # strictly feasible stationary point: the minimum
        x = np.linalg.solve(H, g)
        if np.all((x > lo) & (x < hi)) and np.all(np.linalg.eigvalsh(H) > 0):
            v = 0.5 * x @ H @ x - g @ x
            if np.isfinite(v):
                return x, v
    except np.linalg.LinAlgError:
        pass
    best, best_v = None, np.inf
    for code in range(3 ** k):
        state = [(code // 3 ** i) % 3 for i in range(k)]        # 0 free, 1 lo, 2 hi
        if any(s == 2 and not np.isfinite(hi[i]) for i, s in enumerate(state)):
            continue
        x = np.array([lo[i] if s == 1 else hi[i] if s == 2 else 0.0 for i, s in enumerate(state)])
        free = [i for i, s in enumerate(state) if s == 0]
        if free:
            fixed = [i for i in range(k) if i not in free]
            rhs = g[free] - H[np.ix_(free, fixed)] @ x[fixed]
            Hf = H[np.ix_(free, free)]
            try:
                xf = np.linalg.solve(Hf, rhs)
            except np.linalg.LinAlgError:
                xf = np.linalg.lstsq(Hf, rhs, rcond=None)[0]
            if np.any(xf < lo[free] - 1e-12) or np.any(xf > hi[free] + 1e-12):
                continue
            x[free] = np.clip(xf, lo[free], hi[free])
        v = 0.5 * x @ H @ x - g @ x
        if np.isfinite(v) and v < best_v:
            best, best_v = x, v
    return best, best_v


def _box_qp_small(H, g, lo, hi):
    """:func:`_box_qp` for 1 or 2 variables in scalar arithmetic (the conductor fit calls it
    thousands of times): the convex minimum is the interior stationary point when feasible,
    else the best over the edges, each a clipped 1D minimum."""
    k = len(g)
    lo_, hi_ = [float(v) for v in lo], [float(v) for v in hi]

    def clip(v, i):
        return min(max(v, lo_[i]), hi_[i])

    def value(x):
        if k == 1:
            return 0.5 * H[0][0] * x[0] * x[0] - g[0] * x[0]
        return (0.5 * (H[0][0] * x[0] * x[0] + 2.0 * H[0][1] * x[0] * x[1] + H[1][1] * x[1] * x[1])
                - g[0] * x[0] - g[1] * x[1])

    H = [[float(v) for v in row] for row in np.asarray(H, float)]
    g = [float(v) for v in g]
    if k == 1:
        x0 = clip(g[0] / H[0][0], 0) if H[0][0] > 0 else (hi_[0] if g[0] > 0 and np.isfinite(hi_[0])
                                                           else lo_[0])
        v = value([x0])
        return (np.array([x0]), v) if np.isfinite(v) else (None, np.inf)
    cands = []
    det = H[0][0] * H[1][1] - H[0][1] * H[1][0]
    if det > 0:
        x0 = (g[0] * H[1][1] - g[1] * H[0][1]) / det
        x1 = (g[1] * H[0][0] - g[0] * H[1][0]) / det
        if lo_[0] <= x0 <= hi_[0] and lo_[1] <= x1 <= hi_[1]:
            v = value([x0, x1])
            if np.isfinite(v):
                return np.array([x0, x1]), v
    for i in (0, 1):                     # variable i on a bound, the other clipped optimum
        j = 1 - i
        for b in (lo_[i], hi_[i]):
            if not np.isfinite(b):
                continue
            xj = (clip((g[j] - H[j][i] * b) / H[j][j], j) if H[j][j] > 0
                  else lo_[j])
            x = [0.0, 0.0]
            x[i], x[j] = b, xj
            cands.append(x)
    best, best_v = None, np.inf
    for x in cands:
        v = value(x)
        if np.isfinite(v) and v < best_v:
            best, best_v = x, v
    return (None, np.inf) if best is None else (np.array(best), best_v)


def _fresnel_values(fresnel: str, eta, data) -> np.ndarray | None:
    """Dielectric F(θd; η) of one index at the samples
    (:func:`~brdffit.microfacet.fresnel.dielectric_reflectance`; ``None`` for Schlick)."""
    if fresnel != "dielectric":
        return None
    return dielectric_reflectance(data["cos_d"], float(eta))


def _weighted_sums(data) -> tuple:
    """``(w, w z, Σ w, Σ w z, Σ w z²)`` per channel, computed once per sample set."""
    if "_sums" not in data:
        w, z = data["w"], data["z"]
        wz = w * z
        data["_sums"] = (w, wz, w.sum(0), wz.sum(0), np.einsum("nc,nc->c", wz, z))
    return data["_sums"]


def _on_unit_sum_faces(solve, H, g, lo, hi, faces):
    """``solve`` (a box QP ``(H, g, lo, hi) -> (x, value)`` of ``½xᵀHx − gᵀx``) restricted to
    ``x[c] = 1 − x[a]`` for every ``(a, c)`` in ``faces``: the Schlick ``A + C = ks ≤ 1``
    (F ≤ 1 at every angle) held with equality. Substitutes ``x = P y + q`` and solves for ``y``
    (``x[a] ∈ [lo, 1]``), returning the full ``(x, value)``. When the box optimum of a convex
    QP violates one such constraint, the constrained optimum lies on its face, so this is
    exact for one face and feasible for several."""
    n = len(g)
    dropped = {c for _, c in faces}
    keep = [i for i in range(n) if i not in dropped]
    P, q = np.zeros((n, len(keep))), np.zeros(n)
    P[keep, np.arange(len(keep))] = 1.0
    lo_r, hi_r = np.asarray(lo, float)[keep], np.asarray(hi, float)[keep].copy()
    for a, c in faces:
        P[c, keep.index(a)] = -1.0
        q[c] = 1.0
        hi_r[keep.index(a)] = min(hi_r[keep.index(a)], 1.0)
    y, v = solve(P.T @ H @ P, P.T @ (g - H @ q), lo_r, hi_r)
    if y is None:
        return None, np.inf
    return P @ y + q, v + 0.5 * q @ H @ q - g @ q


def _linear(S, data, fresnel: str, f90: str, Fd=None):
    """Per channel the exact optimum of the linear parameters for the shape ``S``.

    Schlick, ``f90="free"``: ``f = ρd/π + A S + C S x⁵`` (A = ks F0, C = ks (1 − F0) ≥ 0);
    ``f90="one"``: ``f = ρd/π + F0 S (1 − x⁵) + S x⁵``. Dielectric: ``f = ρd/π + ks S F(η)``
    (``f90="one"``: ks = 1). Returns ``{"rho_d", "F0", "ks", "E"}`` or ``None``.

    The normal equations of the three channels come from one product of the weights with
    the columns, their pairwise products and the offset terms (the constant diffuse column's
    sums are those of the sample set, :func:`_weighted_sums`)."""
    x5 = data["x5"]
    if fresnel == "schlick" and f90 == "one":
        cols, offset = [S * (1.0 - x5)], S * x5
        lo, hi = [0.0, 0.0], [ALBEDO_MAX, 1.0]
    elif fresnel == "schlick":
        cols, offset = [S, S * x5], None
        lo, hi = [0.0, 0.0, 0.0], [ALBEDO_MAX, np.inf, np.inf]
    elif f90 == "one":
        cols, offset = [], S * Fd
        lo, hi = [0.0], [ALBEDO_MAX]
    else:
        cols, offset = [S * Fd], None
        lo, hi = [0.0, 0.0], [ALBEDO_MAX, KS_MAX]
    w, wz, w_sum, wz_sum, wzz_sum = _weighted_sums(data)
    k = len(cols)
    pairs = [(i, j) for i in range(k) for j in range(i, k)]
    vecs = cols + [cols[i] * cols[j] for i, j in pairs]
    if offset is not None:
        vecs += [offset, offset * offset] + [col * offset for col in cols]
    V = np.stack(vecs, -1)
    Wv, Zv = w.T @ V, wz.T @ V                               # (3, len(vecs))
    d = 1.0 / np.pi                                          # the diffuse column
    rho_d, F0, ks, E = np.zeros(3), np.zeros(3), np.ones(3), 0.0
    for c in range(3):
        H = np.empty((k + 1, k + 1))
        g = np.empty(k + 1)
        H[0, 0], g[0], yy = d * d * w_sum[c], d * wz_sum[c], wzz_sum[c]
        H[0, 1:] = H[1:, 0] = d * Wv[c, :k]
        g[1:] = Zv[c, :k]
        for n, (i, j) in enumerate(pairs):
            H[i + 1, j + 1] = H[j + 1, i + 1] = Wv[c, k + n]
        if offset is not None:                               # y = z − offset
            o = k + len(pairs)
            g[0] -= d * Wv[c, o]
            g[1:] -= Wv[c, o + 2:]
            yy += Wv[c, o + 1] - 2.0 * Zv[c, o]
        x, v = _box_qp(H, g, lo, hi)
        if x is not None and fresnel == "schlick" and f90 != "one" and x[1] + x[2] > 1.0:
            x, v = _on_unit_sum_faces(_box_qp, H, g, lo, hi, [(1, 2)])
        if x is None:
            return None
        E += max(float(yy + 2.0 * v), 0.0)
        rho_d[c] = x[0]
        if fresnel == "schlick" and f90 == "one":
            F0[c] = x[1]
        elif fresnel == "schlick":
            ks[c] = x[1] + x[2]
            F0[c] = x[1] / ks[c] if ks[c] > 0 else 0.0
        elif f90 != "one":
            ks[c] = x[1]
    if not np.isfinite(E):
        return None
    return {"rho_d": rho_d, "F0": np.clip(F0, 0.0, 1.0),
            "ks": None if f90 == "one" else np.clip(ks, 0.0, KS_MAX), "E": E}


def _shape_of(kind, params, data):
    """``S`` of the distribution of ``params = (αx, αy, ρ, ·)``, ``None`` when invalid."""
    try:
        return _spec_shape(_distribution(kind, *params[:3]), data)
    except ValueError:
        return None


def _evaluate(kind, params, data, fresnel, f90):
    """``(E, linear part)`` of ``params = (αx, αy, ρ, η)``; ``(inf, None)`` if invalid."""
    S = _shape_of(kind, params, data)
    if S is None:
        return np.inf, None
    eta = params[3]
    Fd = _fresnel_values(fresnel, eta, data)
    lin = _linear(S, data, fresnel, f90, Fd)
    if lin is None:
        return np.inf, None
    lin["S"], lin["Fd"] = S, Fd
    return lin["E"], lin


def _prediction(lin, data, fresnel, eta) -> np.ndarray:
    """Model values ``(N, 3)`` of a solved linear part."""
    S = lin["S"][:, None]
    ks = 1.0 if lin["ks"] is None else lin["ks"]
    if fresnel == "schlick":
        F = ks * (lin["F0"] + (1.0 - lin["F0"]) * data["x5"][:, None])
    else:
        F = ks * lin["Fd"][:, None]
    return lin["rho_d"] / np.pi + S * F


# ------------------------------------------------------------------------------------------
# conductor Fresnel: per channel (η, k) by bounded least squares, (ρd, ks) exact inside
# ------------------------------------------------------------------------------------------
#: ``fresnel="auto"`` takes the conductor only when its objective is this much lower than
#: the best Schlick / dielectric one (module docstring)
CONDUCTOR_MARGIN = 0.05
#: lower bound of the conductor's η (the schema's bound is > 0; measured metals have ≥ 0.05)
CONDUCTOR_ETA_MIN = 0.01
_K_SHIFT = 0.01          # k is searched as ln(k + 0.01): k = 0 (a dielectric) is reachable
#: coarse grid of conductor indices screened before the descents (local minima are common)
_ETA_GRID = (0.05, 0.2, 0.5, 0.9, 1.2, 1.5, 2.5, 5.0, 20.0)
_K_GRID = (0.0, 0.05, 0.3, 1.0, 3.0, 8.0)


def _conductor_starts(f0: float) -> list[tuple[float, float]]:
    """(η, k) with normal-incidence reflectance ``f0``: a metal-like index (η = 0.2), a
    dielectric (k = 0) and η = 1.5 with the k that gives ``f0`` (when one does)."""
    f0 = float(np.clip(f0, 1e-4, 0.999))
    out = []
    for eta in (0.2, 1.5):
        k2 = (f0 * (eta + 1.0) ** 2 - (eta - 1.0) ** 2) / (1.0 - f0)
        if k2 > 0:
            out.append((eta, float(np.sqrt(k2))))
    s = np.sqrt(f0)
    out.append((float(np.clip((1.0 + s) / (1.0 - s), CONDUCTOR_ETA_MIN, INDEX_MAX)), 0.0))
    return out


def _node_sums(S, data):
    """Sums over the samples of each θd node (the samples lie on MERL θd nodes, so F(θd) is
    one value per node): ``cos θd`` of the nodes, and per node and channel Σw, ΣwS, ΣwS²,
    Σwz, ΣwSz, Σwz². A Fresnel objective is then exact in O(nodes), not O(samples)."""
    if "_nodes" not in data:
        data["_nodes"] = np.unique(np.round(data["cos_d"], 12), return_inverse=True)
    cos_nodes, inv = data["_nodes"]
    n = cos_nodes.size
    w, wz = _weighted_sums(data)[:2]
    z = data["z"]
    sums = {}
    for name, per_sample in (("W", w), ("S1", w * S[:, None]), ("SS", w * (S * S)[:, None]),
                             ("Z1", wz), ("SZ", wz * S[:, None]), ("Z2", wz * z)):
        sums[name] = np.stack([np.bincount(inv, per_sample[:, c], minlength=n)
                               for c in range(3)], -1)
    return cos_nodes, sums


def _node_linear(sm, c: int, F, f90: str):
    """Channel ``c`` of ``ρd/π + ks S F`` with the per-node Fresnel values ``F``: ``(E, x)``,
    ``x`` = the exact box-constrained (ρd, ks) (``f90="one"``: (ρd,), ks = 1) and ``E`` its
    objective, from the node sums of :func:`_node_sums`; ``(inf, None)`` when not finite."""
    W, S1, SS, Z1, SZ, Z2 = (sm[k][:, c] for k in ("W", "S1", "SS", "Z1", "SZ", "Z2"))
    ip = 1.0 / np.pi
    if f90 == "one":              # ks = 1: E(ρd) = Σ w (ρd/π + S F − z)²
        H = np.array([[W.sum() * ip * ip]])
        g = np.array([(Z1 - F * S1).sum() * ip])
        const = float((F * F * SS).sum() - 2.0 * (F * SZ).sum())
        x, v = _box_qp(H, g, [0.0], [ALBEDO_MAX])
    else:
        fs1 = float((F * S1).sum()) * ip
        H = np.array([[W.sum() * ip * ip, fs1], [fs1, float((F * F * SS).sum())]])
        g = np.array([Z1.sum() * ip, float((F * SZ).sum())])
        const = 0.0
        x, v = _box_qp(H, g, [0.0, 0.0], [ALBEDO_MAX, KS_MAX])
    if x is None:
        return np.inf, None
    return max(float(Z2.sum()) + const + 2.0 * v, 0.0), x


def _conductor_channel(nodes, c: int, f90: str, starts):
    """Channel ``c`` of ``ρd/π + ks S F_conductor(θd; η, k)``: ``(E, η, k, ρd, ks)``, the
    best bounded L-BFGS-B descent over (ln η, ln(k + 0.01)) from ``starts``, (ρd, ks)
    solved exactly (box-constrained) for each (η, k) from the node sums."""
    cos_nodes, sm = nodes
    z2 = float(sm["Z2"][:, c].sum())
    scale = z2 if z2 > 0 else 1.0          # the objective relative to the all-zero model's

    def solve(q):
        eta, k = float(np.exp(q[0])), float(np.exp(q[1])) - _K_SHIFT
        k = k if k > 1e-9 else 0.0        # exp(ln 0.01) − 0.01 is not exactly 0
        E, x = _node_linear(sm, c, conductor_reflectance(cos_nodes, eta, k), f90)
        return E, x, eta, k

    lo = np.array([np.log(CONDUCTOR_ETA_MIN), np.log(_K_SHIFT)])
    hi = np.array([np.log(INDEX_MAX), np.log(INDEX_MAX + _K_SHIFT)])
    best = None
    if len(starts) > 1:          # cold: the given starts and a coarse (η, k) grid, best 3
        pool = list(starts) + [(e, k) for e in _ETA_GRID for k in _K_GRID]
        costs = [solve(np.clip([np.log(e), np.log(k + _K_SHIFT)], lo, hi))[0] for e, k in pool]
        starts = [pool[i] for i in np.argsort(costs)[:3]]
    for eta0, k0 in starts:
        q0 = np.clip([np.log(eta0), np.log(k0 + _K_SHIFT)], lo, hi)
        try:
            q = optimize.minimize(lambda q: solve(q)[0] / scale, q0, method="L-BFGS-B",
                                  bounds=list(zip(lo, hi)),
                                  options={"ftol": 1e-12, "gtol": 1e-10, "maxiter": 100}).x
        except (ValueError, FloatingPointError, np.linalg.LinAlgError):
            q = q0
        E, x, eta, k = solve(q)
        if x is not None and np.isfinite(E) and (best is None or E < best[0]):
            best = (E, eta, k, float(x[0]), 1.0 if f90 == "one" else float(x[1]))
    return best


def _conductor_at(kind, params, data, f90, starts_per_channel):
    """The conductor fit for the distribution ``params``: ``(E, lin)`` or ``(inf, None)``."""
    S = _shape_of(kind, params, data)
    if S is None:
        return np.inf, None
    nodes = _node_sums(S, data)
    out = [_conductor_channel(nodes, c, f90, starts_per_channel[c]) for c in range(3)]
    if any(o is None for o in out):
        return np.inf, None
    E, eta, k, rho_d, ks = (np.array(v) for v in zip(*out))
    return float(E.sum()), {"rho_d": rho_d, "ks": None if f90 == "one" else ks, "eta": eta,
                            "k": k, "S": S, "F0": None, "Fd": None, "E": float(E.sum())}


def _search_conductor(kind, data, f90, schlick_best, anisotropic):
    """Per-channel conductor (η, k) from the Schlick optimum (three starts per channel), then
    (isotropic) ln α refined by a bounded Brent search within a factor 1.5 of the Schlick α
    (warm starts, plus the three starts at the end); an anisotropic fit keeps the Schlick
    distribution."""
    ax, ay, rho, _ = schlick_best[1]
    lin = schlick_best[2]
    f0 = lin["F0"] * (1.0 if lin["ks"] is None else lin["ks"])
    starts = [_conductor_starts(f) for f in np.clip(f0, 0.0, 1.0)]
    E, best = _conductor_at(kind, (ax, ay, rho, None), data, f90, starts)
    tried = [{"fresnel": "conductor", "start": "schlick optimum", "alpha": ax, "objective": E}]
    if best is None or anisotropic:
        return (None if best is None else (E, (ax, ay, rho, None), best)), tried
    warm = [[(float(best["eta"][c]), float(best["k"][c]))] for c in range(3)]

    def cost(q):
        a = float(np.exp(q))
        return _conductor_at(kind, (a, a, 0.0, None), data, f90, warm)[0]

    res = optimize.minimize_scalar(cost, bounds=(max(np.log(ax) - np.log(1.5), np.log(ALPHA_MIN)),
                                                 min(np.log(ax) + np.log(1.5), 0.0)),
                                   method="bounded", options={"xatol": 1e-3})
    a = float(np.exp(res.x))
    both = [warm[c] + starts[c] for c in range(3)]
    E2, lin2 = _conductor_at(kind, (a, a, 0.0, None), data, f90, both)
    tried.append({"fresnel": "conductor", "start": "alpha refined", "alpha": a, "objective": E2})
    if lin2 is not None and E2 < E:
        return (E2, (a, a, 0.0, None), lin2), tried
    return (E, (ax, ay, rho, None), best), tried


# ------------------------------------------------------------------------------------------
# dielectric Fresnel, isotropic: η profiled out on the node sums, ln α by Brent
# ------------------------------------------------------------------------------------------
#: scan of the dielectric index before its Brent refinement: η − 1 from 1e-3 to 3
_ETA_SCAN = np.log(np.geomspace(ETA_BOUNDS[0] - 1.0, ETA_BOUNDS[1] - 1.0, 17))
#: the α bracket of the dielectric search: a factor 2 around the Schlick α, moved (at most
#: twice) when the minimum lands on its edge
_DIELECTRIC_BRACKET, _DIELECTRIC_MOVES = np.log(2.0), 2


def _dielectric_at(kind, alpha: float, data, f90: str) -> tuple[float, float | None]:
    """``(E, η)``: the best index for the isotropic roughness ``alpha``, (ρd, ks) exact per
    channel for each η from the node sums (:func:`_node_linear`); η by a 17-node scan of
    ln(η − 1) and a bounded Brent search between the neighbours of its best node."""
    S = _shape_of(kind, (alpha, alpha, 0.0), data)
    if S is None:
        return np.inf, None
    cos_nodes, sm = _node_sums(S, data)

    def cost(q):
        F = dielectric_reflectance(cos_nodes, 1.0 + float(np.exp(q)))
        return sum(_node_linear(sm, c, F, f90)[0] for c in range(3))

    E = np.array([cost(q) for q in _ETA_SCAN])
    if not np.any(np.isfinite(E)):
        return np.inf, None
    i = int(np.nanargmin(np.where(np.isfinite(E), E, np.nan)))
    best_e, best_q = float(E[i]), float(_ETA_SCAN[i])
    res = optimize.minimize_scalar(cost, bounds=(_ETA_SCAN[max(i - 1, 0)],
                                                 _ETA_SCAN[min(i + 1, _ETA_SCAN.size - 1)]),
                                   method="bounded", options={"xatol": 1e-6})
    if np.isfinite(res.fun) and res.fun < best_e:
        best_e, best_q = float(res.fun), float(res.x)
    return best_e, float(np.clip(1.0 + np.exp(best_q), *ETA_BOUNDS))


def _search_dielectric(kind, data, f90, schlick_alpha: float):
    """Isotropic dielectric fit: ln α by a bounded Brent search within a factor 2 of the
    Schlick α (the bracket moved when the minimum is on its edge), η profiled out
    (:func:`_dielectric_at`); ``(best, tried)``, best = (E, params, lin) or ``None``."""
    lo_all, hi_all = np.log(ALPHA_MIN), np.log(ALPHA_MAX_FIT)
    centre = float(np.clip(np.log(schlick_alpha), lo_all, hi_all))

    def cost(q):
        return _dielectric_at(kind, float(np.exp(q)), data, f90)[0]

    q = centre
    for _ in range(_DIELECTRIC_MOVES + 1):
        lo = max(centre - _DIELECTRIC_BRACKET, lo_all)
        hi = min(centre + _DIELECTRIC_BRACKET, hi_all)
        res = optimize.minimize_scalar(cost, bounds=(lo, hi), method="bounded",
                                       options={"xatol": 1e-6})
        q = float(res.x) if np.isfinite(res.fun) else centre
        edge = 0.05 * _DIELECTRIC_BRACKET
        if lo + edge < q < hi - edge or q <= lo_all + edge or q >= hi_all - edge:
            break
        centre = q
    alpha = float(np.exp(q))
    _, eta = _dielectric_at(kind, alpha, data, f90)
    if eta is None:
        return None, []
    e, lin = _evaluate(kind, (alpha, alpha, 0.0, eta), data, "dielectric", f90)
    tried = [{"fresnel": "dielectric", "start": "schlick optimum",
              "params_start": [schlick_alpha, schlick_alpha, 0.0, None],
              "params": [alpha, alpha, 0.0, eta], "objective": e}]
    if lin is None or not np.isfinite(e):
        return None, tried
    return (e, (alpha, alpha, 0.0, eta), lin), tried


# ------------------------------------------------------------------------------------------
# the coat: a second, white specular lobe of index 1.5 (glTF clearcoat, OpenPBR coat)
# ------------------------------------------------------------------------------------------
#: ``coat="auto"`` keeps the coated candidate only when its objective is this much below the
#: best uncoated one (module docstring: the evidence for the margin)
COAT_MARGIN = 0.05
#: ... and by at least this fraction of the data's energy (Σ w z²: below, an exact fit's noise)
COAT_MIN_GAIN = 1e-6
_COAT_SCAN = 24


def _coat_solve(H, g, zz, bound: float = np.inf):
    """Bounded least squares of the coated model for one (α_base, α_coat): per channel
    (ρd, A, C) and one coat weight w for the three channels (``H`` (10, 10), ``g`` (10,),
    ``zz`` = Σ w z²): ``(E, x)``, x = (ρd, A, C) × 3 then w; ρd ∈ [0, ALBEDO_MAX],
    A, C ≥ 0 with A + C = ks ≤ 1 (the base's F ≤ 1; :func:`_on_unit_sum_faces`), w ∈ [0, 1].
    Bounded-variable least squares on the Cholesky factor of ``H`` (:func:`_bvls`), skipped
    when the unconstrained minimum is feasible (then it is the answer: the problem is convex)
    or is not below ``bound`` (then no feasible point is: ``(inf, None)``)."""
    factor = _cholesky(H, g)
    if factor is None:
        return np.inf, None
    L, rhs = factor
    if zz - rhs @ rhs > bound + 1e-9 * zz:
        return np.inf, None
    lo, hi = np.zeros(g.size), np.array([ALBEDO_MAX, np.inf, np.inf] * 3 + [1.0])
    x = np.linalg.solve(L.T, rhs)
    if not np.all((x >= lo) & (x <= hi)):
        x, _ = _bvls(H, g, lo, hi, factor)
    faces: list[tuple[int, int]] = []
    while x is not None:                 # F ≤ 1: ks = A + C ≤ 1 per channel
        over = [(3 * c + 1, 3 * c + 2) for c in range(3)
                if x[3 * c + 1] + x[3 * c + 2] > 1.0 + 1e-12
                and (3 * c + 1, 3 * c + 2) not in faces]
        if not over:
            break
        faces += over
        x, _ = _on_unit_sum_faces(_bvls, H, g, lo, hi, faces)
    if x is None:
        return np.inf, None
    E = float(zz - 2.0 * g @ x + x @ H @ x)
    return (max(E, 0.0), x) if np.isfinite(E) else (np.inf, None)


def _cholesky(H, g):
    """``(L, L⁻¹ g)`` with ``L Lᵀ = H`` (regularised by 1e-13 of its mean diagonal), or
    ``None`` when ``H`` is not positive definite."""
    n = g.size
    try:
        L = np.linalg.cholesky(H + 1e-13 * np.trace(H) / n * np.eye(n))
    except np.linalg.LinAlgError:
        return None
    return L, np.linalg.solve(L, g)


def _bvls(H, g, lo, hi, factor=None):
    """``argmin ½xᵀHx − gᵀx`` on the box ``lo ≤ x ≤ hi`` by bounded-variable least squares on
    the Cholesky factor of ``H`` (``factor``: :func:`_cholesky`'s, when already made):
    ``(x, value)``, ``(None, inf)`` when ``H`` is not positive definite (the interface of
    :func:`_box_qp`)."""
    from scipy.optimize import lsq_linear

    factor = factor or _cholesky(H, g)
    if factor is None:
        return None, np.inf
    L, rhs = factor
    x = np.clip(lsq_linear(L.T, rhs, bounds=(lo, hi), tol=1e-12, method="bvls").x, lo, hi)
    return x, 0.5 * x @ H @ x - g @ x


def _coat_system(cols_c, data):
    """Per channel the normal equations of the columns ``cols_c`` (N, k): ``(H (3, k, k),
    g (3, k))`` with the sample weights."""
    w, wz = _weighted_sums(data)[:2]
    H = np.stack([(cols_c * w[:, c:c + 1]).T @ cols_c for c in range(3)])
    return H, wz.T @ cols_c


def _coat_joint(H, g, ib, ic):
    """The (10, 10) joint system of base columns ``ib`` (diffuse, S, S x⁵ of one α) per
    channel and the shared coat column ``ic``."""
    J = np.zeros((10, 10))
    v = np.zeros(10)
    for c in range(3):
        idx = list(ib) + [ic]
        loc = [3 * c, 3 * c + 1, 3 * c + 2, 9]
        J[np.ix_(loc, loc)] += H[c][np.ix_(idx, idx)]
        v[loc] += g[c][idx]
    return J, v


def _search_coat(kind, data):
    """Isotropic ``ρd/π + ks S_b Schlick(F0) + w S_c Schlick(COAT_F0)``: the linear part
    exact for each (α_b, α_c) (:func:`_coat_solve`), (ln α_b, ln α_c) by a 24 × 24 scan of
    [ALPHA_MIN, 1]² (normal equations of all the scan's columns formed once) then
    Nelder-Mead; ``(E, (α_b, α_c), x)`` or ``None``."""
    zz = float(_weighted_sums(data)[4].sum())
    x5 = data["x5"]
    coat_fresnel = COAT_F0 + (1.0 - COAT_F0) * x5
    alphas = np.exp(np.linspace(np.log(ALPHA_MIN), np.log(ALPHA_MAX_FIT), _COAT_SCAN))
    cols = [np.full(data["n"], 1.0 / np.pi)]
    for a in alphas:
        S = _spec_shape(_distribution(kind, a), data)
        cols += [S, S * x5, S * coat_fresnel]
    H, g = _coat_system(np.stack(cols, 1), data)
    best = (np.inf, None)
    for i in range(_COAT_SCAN):
        for j in range(_COAT_SCAN):
            E, _ = _coat_solve(*_coat_joint(H, g, (0, 1 + 3 * i, 2 + 3 * i), 3 + 3 * j), zz,
                               bound=best[0])
            if E < best[0]:
                best = (E, (i, j))
    if best[1] is None:
        return None
    lo, hi = np.log(ALPHA_MIN), np.log(ALPHA_MAX_FIT)

    def solve(q):
        ab, ac = (float(v) for v in np.exp(q))
        Sb = _spec_shape(_distribution(kind, ab), data)
        Sc = _spec_shape(_distribution(kind, ac), data)
        Hq, gq = _coat_system(np.stack([cols[0], Sb, Sb * x5, Sc * coat_fresnel], 1), data)
        return _coat_solve(*_coat_joint(Hq, gq, (0, 1, 2), 3), zz)

    def cost(q):
        return solve(q)[0] if np.all((q >= lo) & (q <= hi)) else np.inf

    q0 = np.log([alphas[best[1][0]], alphas[best[1][1]]])
    res = optimize.minimize(cost, q0, method="Nelder-Mead",
                            options={"xatol": 3e-3, "fatol": 1e-12 * max(best[0], 1e-300),
                                     "maxiter": 150, "maxfev": 100})
    q = res.x if np.isfinite(res.fun) and res.fun < best[0] else q0
    E, x = solve(q)
    if x is None or not np.isfinite(E):
        return None
    return E, tuple(float(v) for v in np.exp(q)), x


# ------------------------------------------------------------------------------------------
# the search over the distribution (and η) parameters
# ------------------------------------------------------------------------------------------
def _local_minima(E: np.ndarray) -> list[int]:
    idx = [i for i in range(len(E)) if np.isfinite(E[i])
           and (i == 0 or E[i] <= E[i - 1]) and (i == len(E) - 1 or E[i] <= E[i + 1])]
    return sorted(idx, key=lambda i: E[i])


def _scan_isotropic(kind, data, fresnel, f90, moment_alpha, starts, eta=1.5):
    """ln α scan and bounded Brent refinements: ``(best, tried)``, best = (E, params, lin)."""
    la = np.linspace(np.log(ALPHA_MIN), np.log(ALPHA_MAX_FIT), _SCAN)
    E = np.array([_evaluate(kind, (float(np.exp(a)), None, 0.0, eta), data, fresnel, f90)[0]
                  for a in la])
    step = la[1] - la[0]
    cands = [("scan", la[i]) for i in _local_minima(E)[:max(int(starts), 1)]]
    if moment_alpha is not None and np.isfinite(moment_alpha) and moment_alpha > 0:
        cands.append(("moments", float(np.clip(np.log(moment_alpha), la[0], la[-1]))))
    if not cands:
        raise FitError("no finite objective at any roughness of the scan")

    def cost(q):
        return _evaluate(kind, (float(np.exp(q)), None, 0.0, eta), data, fresnel, f90)[0]

    tried, best = [], None
    for src, l0 in cands:
        res = optimize.minimize_scalar(cost, bounds=(max(l0 - step, la[0]),
                                                     min(l0 + step, la[-1])),
                                       method="bounded", options={"xatol": 1e-5})
        alpha = float(np.exp(res.x if np.isfinite(res.fun) else l0))
        e, lin = _evaluate(kind, (alpha, alpha, 0.0, eta), data, fresnel, f90)
        tried.append({"fresnel": fresnel, "start": src, "alpha_start": float(np.exp(l0)),
                      "alpha": alpha, "objective": e})
        if lin is not None and np.isfinite(e) and (best is None or e < best[0]):
            best = (e, (alpha, alpha, 0.0, eta), lin)
    return best, tried


def _least_squares(kind, data, fresnel, f90, starts, anisotropic: bool):
    """Bounded TRF on (ln αx[, ln αy, ρ][, η]) from each start ``(label, (αx, αy, ρ, η))``."""
    sw = np.sqrt(data["w"])
    use_eta = fresnel == "dielectric"

    def pack(p):
        q = [np.log(p[0])] + ([np.log(p[1]), p[2]] if anisotropic else [])
        return np.array(q + ([p[3]] if use_eta else []))

    def unpack(q):
        ax = float(np.exp(q[0]))
        ay, rho = (float(np.exp(q[1])), float(q[2])) if anisotropic else (ax, 0.0)
        return ax, ay, rho, float(q[-1]) if use_eta else 1.5

    lo = [np.log(ALPHA_MIN)] + ([np.log(ALPHA_MIN), -RHO_MAX] if anisotropic else []) \
        + ([ETA_BOUNDS[0]] if use_eta else [])
    hi = [np.log(ALPHA_MAX_FIT)] + ([np.log(ALPHA_MAX_FIT), RHO_MAX] if anisotropic else []) \
        + ([ETA_BOUNDS[1]] if use_eta else [])
    lo, hi = np.array(lo), np.array(hi)
    bad = np.full(sw.size, 1e3)

    def resid(q):
        p = unpack(q)
        e, lin = _evaluate(kind, p, data, fresnel, f90)
        if lin is None:
            return bad
        r = ((_prediction(lin, data, fresnel, p[3]) - data["z"]) * sw).ravel()
        return np.where(np.isfinite(r), r, 1e3)

    tried, best = [], None
    for src, p0 in starts:
        q0 = np.clip(pack(p0), lo + 1e-9, hi - 1e-9)
        try:
            q = optimize.least_squares(resid, q0, bounds=(lo, hi), method="trf",
                                       diff_step=1e-3, xtol=1e-8, ftol=1e-10,
                                       max_nfev=40).x
        except (ValueError, FloatingPointError, np.linalg.LinAlgError):
            q = q0
        p = unpack(q)
        e, lin = _evaluate(kind, p, data, fresnel, f90)
        tried.append({"fresnel": fresnel, "start": src, "params_start": list(unpack(q0)),
                      "params": list(p), "objective": e})
        if lin is not None and np.isfinite(e) and (best is None or e < best[0]):
            best = (e, p, lin)
    return best, tried


def _eta_of_f0(f0) -> float:
    s = float(np.sqrt(np.clip(np.mean(f0), 0.0, 0.5)))
    return float(np.clip((1.0 + s) / (1.0 - s), *ETA_BOUNDS))


def _search(kind, data, fresnel, f90, mom, starts, anisotropic):
    """Schlick first (scan, moment start, anisotropic refinement), then the dielectric
    Fresnel from the Schlick optimum; returns ``(best per Fresnel, tried)``."""
    results, tried = {}, []
    best, t = _scan_isotropic(kind, data, "schlick", f90,
                              None if (mom is None or anisotropic) else float(mom[0]), starts)
    tried += t
    if anisotropic:
        st = [("isotropic", best[1])]
        if mom is not None and all(np.isfinite(mom)):
            st.insert(0, ("moments", (max(mom[0], ALPHA_MIN), max(mom[1], ALPHA_MIN),
                                      float(np.clip(mom[2], -RHO_MAX, RHO_MAX)), 1.5)))
        b2, t = _least_squares(kind, data, "schlick", f90, st, True)
        tried += t
        if b2 is not None and b2[0] < best[0]:
            best = b2
    results["schlick"] = best
    if fresnel == "conductor":
        b4, t = _search_conductor(kind, data, f90, best, anisotropic)
        tried += t
        return ({"conductor": b4} if b4 is not None else {}), tried
    if fresnel in ("auto", "dielectric"):
        ax, ay, rho, _ = best[1]
        if anisotropic:
            f0 = best[2]["F0"] * (1.0 if best[2]["ks"] is None else best[2]["ks"])
            eta0 = _eta_of_f0(f0)
            st = [("schlick optimum", (ax, ay, rho, eta0))]
            if abs(eta0 - 1.5) > 0.05:
                st.append(("eta 1.5", (ax, ay, rho, 1.5)))
            b3, t = _least_squares(kind, data, "dielectric", f90, st, anisotropic)
        else:
            b3, t = _search_dielectric(kind, data, f90, ax)
        tried += t
        if b3 is not None:
            results["dielectric"] = b3
    if fresnel == "auto":
        b4, t = _search_conductor(kind, data, f90, best, anisotropic)
        tried += t
        if b4 is not None:
            results["conductor"] = b4
    if fresnel == "schlick":
        results.pop("dielectric", None)
    elif fresnel == "dielectric" and "dielectric" in results:
        results.pop("schlick")
    return results, tried


def _moment_start(brdf, kind: str, anisotropic: bool):
    """The Dupuy 2015 slope-moment conversion (App. C) of the tabulated NDF: (αx, αy, ρ).

    Isotropic input: only the NDF of :func:`~brdffit.fit.tabulated.fit_tabulated` is needed
    (backscattering at a 90-node Gauss rule, 4 power iterations, Eq. 14-18 / Alg. 3), not its
    Fresnel table; anisotropic input: the full tabulated fit."""
    def conv(dist):
        return dist.ggx_parameters() if kind == "ggx" else dist.beckmann_parameters()

    try:
        with np.errstate(all="ignore"):
            if anisotropic:
                return conv(fit_tabulated(brdf, anisotropic=True).distribution)
            _, theta, _, _ = radial_rule(N_THETA_H, "gauss")
            rgb, ok = backscatter(brdf, theta)
            b = luminance(np.where(np.isfinite(rgb), rgb, 0.0))
            b = np.where(ok & np.isfinite(b), np.maximum(b, 0.0), 0.0)
            if not np.any(b > 0):
                return None
            p, _, _ = solve_slope_pdf(b, rule="gauss", iterations=4)
            out = conv(TabulatedSlopeDistribution(p, rule="gauss"))
        return out if all(np.isfinite(out)) else None
    except (FitError, ValueError, FloatingPointError, np.linalg.LinAlgError):
        return None


@with_single_blas_thread
def fit_analytic_diffuse(brdf, distribution: str = "ggx", *, anisotropic: bool | None = None,
                         fresnel: FresnelChoice = "auto", f90: F90 = "free", starts: int = 3,
                         moments: bool = True, theta_d_stride: int | None = None,
                         phi_d_stride: int | None = None, theta_h_stride: int = 3,
                         n_phi_h: int = 12, objective=None, coat: Coat = "auto",
                         name: str | None = None) -> MicrofacetBRDF | SumBRDF:
    """Fit ``ρd/π + ks F D G/(4 cos θi cos θo)`` to ``brdf`` (see the module docstring).

    Parameters
    ----------
    distribution:
        ``"ggx"`` or ``"beckmann"``.
    anisotropic:
        Fit (αx, αy, ρ); default: when ``brdf.isotropic`` is false.
    fresnel:
        ``"schlick"`` (per-channel F0), ``"dielectric"`` (exact dielectric Fresnel of one
        index η, Walter 2007 Eq. 22), ``"conductor"`` (exact conductor Fresnel of a
        per-channel index η + i k) or ``"auto"`` (default: the three, the lowest objective
        wins, the conductor only by a margin of ``CONDUCTOR_MARGIN``).
    f90:
        ``"free"`` (default): a per-channel specular scale ks, i.e. F(90°) = ks
        (``MicrofacetBRDF(specular=ks)``); ``"one"``: ks = 1 (textbook Schlick/dielectric).
    starts:
        Number of local minima of the roughness scan refined (besides the moment start).
    moments:
        Also start from the Dupuy 2015 slope-moment conversion (costs one tabulated fit).
    theta_d_stride, phi_d_stride, theta_h_stride, n_phi_h:
        Density of the fitting samples (``theta_h_stride``, ``n_phi_h``: anisotropic only).
    objective:
        :class:`~brdffit.losses.objective.ObjectiveOptions` (default: the paper's).
    coat:
        ``"auto"`` (default): also fit a second, white specular lobe of index 1.5 (a clear
        coat) and keep it when it lowers the objective by ``COAT_MARGIN``; ``"off"``;
        ``"on"``: keep it whenever it is found. Isotropic fits with ``f90="free"`` only.
    name:
        Name of the fitted model (default ``"<input>-<distribution>-diffuse"``).

    Returns
    -------
    MicrofacetBRDF
        See :func:`fit_ggx_diffuse`.
    """
    t0 = time.perf_counter()
    kind = _check_choices(distribution, fresnel, f90, coat)
    if anisotropic is None:
        anisotropic = not bool(getattr(brdf, "isotropic", False))
    label = getattr(brdf, "name", None) or "brdf"
    if coat == "on" and (anisotropic or f90 != "free"):
        raise ValueError(f"{label}: coat='on' needs an isotropic fit with f90='free'")
    if not anisotropic and not getattr(brdf, "isotropic", False):
        raise FitError(f"{label}: an isotropic fit needs an isotropic BRDF (eval_hd); "
                       "use anisotropic=True")
    data = sample_set(brdf, bool(anisotropic), theta_d_stride=theta_d_stride,
                      phi_d_stride=phi_d_stride, theta_h_stride=theta_h_stride,
                      n_phi_h=n_phi_h, options=objective)
    t1 = time.perf_counter()
    mom = _moment_start(brdf, kind, bool(anisotropic)) if moments else None
    t2 = time.perf_counter()
    try:
        results, tried = _search(kind, data, fresnel, f90, mom, starts, bool(anisotropic))
    except FitError as exc:
        raise FitError(f"{label}: {kind}-diffuse fit: {exc}") from None
    model, E = _one_lobe_model(kind, results, data, bool(anisotropic), label,
                               name or f"{label}-{kind}-diffuse", getattr(brdf, "source", None))
    model.fit_info.update(
        moment_start=None if mom is None else [float(m) for m in mom], starts=tried,
        time_samples=t1 - t0, time_moments=t2 - t1, time=time.perf_counter() - t0, coat=None)
    model.fit_options = {"model": f"{kind}-diffuse", "distribution": kind,
                         "anisotropic": bool(anisotropic), "fresnel": fresnel, "f90": f90,
                         "starts": int(starts), "moments": bool(moments),
                         "theta_d_stride": theta_d_stride, "phi_d_stride": phi_d_stride,
                         "coat": coat}
    if coat == "off" or anisotropic or f90 != "free":
        return _done(model, model.fit_info)
    return _with_coat(model, E, kind, data, coat, t0)


def _check_choices(distribution, fresnel, f90, coat) -> str:
    """The distribution's kind (``"ggx"`` or ``"beckmann"``), the choices checked."""
    kind = str(distribution).lower()
    if kind not in ("ggx", "beckmann"):
        raise ValueError(f"distribution must be 'ggx' or 'beckmann', found {distribution!r}")
    check_choice("fresnel", fresnel, FresnelChoice)
    check_choice("f90", f90, F90)
    check_choice("coat", coat, Coat)
    return kind


def _one_lobe_model(kind, results, data, anisotropic, label, name, source):
    """``(model, objective)``: the one-lobe model of the best Fresnel form of ``results``
    (``{form: (objective, (αx, αy, ρ, η), linear parameters)}``; the conductor only by a
    margin of :data:`CONDUCTOR_MARGIN`, for its six more parameters), its ρd held under the
    furnace (:func:`brdffit.furnace.hold_diffuse`), with the first part of its ``fit_info``."""
    finite = {k: v for k, v in results.items() if v is not None and np.isfinite(v[0])}
    if not finite:
        raise FitError(f"{label}: {kind}-diffuse fit found no finite solution")
    chosen = min((k for k in finite if k != "conductor"), key=lambda k: finite[k][0],
                 default="conductor")
    if "conductor" in finite and finite["conductor"][0] < (1.0 - CONDUCTOR_MARGIN) * finite[chosen][0]:
        chosen = "conductor"          # six more parameters: only for a clear gain (see the doc)
    E, (ax, ay, rho, eta), lin = finite[chosen]
    if not anisotropic:
        ay, rho = ax, 0.0
    rho_d, ks = lin["rho_d"], lin["ks"]
    if chosen == "schlick":
        F = SchlickFresnel(lin["F0"])
        f0_eff = lin["F0"] * (1.0 if ks is None else ks)
    elif chosen == "conductor":
        F = ConductorFresnel(lin["eta"], lin["k"])
        f0_eff = F.eval(1.0) * (1.0 if ks is None else ks)
        eta = lin["eta"]
    else:
        F = DielectricFresnel(eta)
        f0_eff = F.eval(1.0) * (1.0 if ks is None else ks)
    values = [ax, ay, rho, *np.ravel(eta), *rho_d, *f0_eff, *(ks if ks is not None else []),
              *(lin["k"] if chosen == "conductor" else [])]
    if not all(np.isfinite(values)):
        raise FitError(f"{label}: {kind}-diffuse fit produced non-finite parameters")
    dist = _distribution(kind, ax, ay, rho)
    rho_d, lowered = hold_diffuse(rho_d, [MicrofacetBRDF(dist, F, specular=ks)])
    model = MicrofacetBRDF(dist, F, diffuse=rho_d, specular=ks, correlated=True, name=name,
                           source=source)
    if lowered.any():
        E = _objective_of(model, data)
    model.fit_info = {
        "method": f"{kind} + Lambert, {chosen} Fresnel, compressive objective (Bagher 2016 "
                  "Eq. 7-12), variable projection",
        "fresnel": chosen, "alpha_x": ax, "alpha_y": ay, "rho": rho,
        "eta": (eta if chosen == "dielectric" else
                np.asarray(eta).tolist() if chosen == "conductor" else None),
        "k": lin["k"].tolist() if chosen == "conductor" else None, "rho_d": rho_d.tolist(),
        "F0": f0_eff.tolist(), "ks": None if ks is None else ks.tolist(), "objective": float(E),
        "objective_normalised": float(E / data["ref_energy"]) if data["ref_energy"] > 0 else None,
        "objective_by_fresnel": {k: float(v[0]) for k, v in finite.items()},
        "rho_d_furnace_lowering": lowered.tolist(), "n_samples": data["n"],
        "anisotropic": bool(anisotropic)}
    return model, E


def _with_coat(model, E, kind, data, coat, t0):
    """``model`` or, when a second, white specular lobe (a clear coat of F0
    :data:`COAT_F0`) lowers the objective ``E`` by :data:`COAT_MARGIN` (any amount for
    ``coat="on"``) and by more than :data:`COAT_MIN_GAIN` of the data's energy, the
    ``SumBRDF`` of the refitted base lobe and the coat lobe; ``fit_info["coat"]`` says what
    was found and whether it was kept."""
    t3 = time.perf_counter()
    found = _search_coat(kind, data)
    if found is None:                     # no finite coated candidate: the search still took time
        model.fit_info["time"] = time.perf_counter() - t0
        return _done(model, model.fit_info)
    E_coat, (a_base, a_coat), x = found
    rho_d, A, C = x[0:9:3], x[1:9:3], x[2:9:3]
    ks = A + C
    F0 = np.where(ks > 0, A / np.where(ks > 0, ks, 1.0), 0.0)
    base_dist, base_fresnel = _distribution(kind, a_base), SchlickFresnel(np.clip(F0, 0.0, 1.0))
    coat_lobe = MicrofacetBRDF(_distribution(kind, a_coat), SchlickFresnel(np.full(3, COAT_F0)),
                               specular=np.full(3, float(x[9])), correlated=True, name="coat")
    rho_d, lowered = hold_diffuse(rho_d, [MicrofacetBRDF(base_dist, base_fresnel, specular=ks),
                                           coat_lobe])
    base = MicrofacetBRDF(base_dist, base_fresnel, diffuse=rho_d, specular=ks, correlated=True,
                          name="base")
    coated = SumBRDF([base, coat_lobe], name=model.name, source=model.source)
    if lowered.any():
        E_coat = _objective_of(coated, data)
    margin = 0.0 if coat == "on" else COAT_MARGIN
    # a gain below COAT_MIN_GAIN of the data's energy is numerical noise (an exact fit)
    gain = (E - E_coat) / data["ref_energy"] if data["ref_energy"] > 0 else 0.0
    coat_info = {"alpha": a_coat, "weight": float(x[9]), "f0": COAT_F0,
                 "objective": float(E_coat), "objective_without": float(E),
                 "margin": margin, "kept": bool(E_coat < (1.0 - margin) * E
                                                and gain > COAT_MIN_GAIN),
                 "time": time.perf_counter() - t3}
    info = model.fit_info
    info.update(coat=coat_info, time=time.perf_counter() - t0)
    if not coat_info["kept"]:
        return _done(model, info)
    info.update(
        method=f"{kind} + Lambert + coat ({kind}, white, F0 {COAT_F0}), Schlick Fresnel, "
               "compressive objective (Bagher 2016 Eq. 7-12), variable projection",
        fresnel="schlick", alpha_x=a_base, alpha_y=a_base, rho=0.0, eta=None, k=None,
        rho_d=rho_d.tolist(), rho_d_furnace_lowering=lowered.tolist(), F0=A.tolist(),
        ks=ks.tolist(), objective=float(E_coat),
        objective_normalised=(float(E_coat / data["ref_energy"]) if data["ref_energy"] > 0
                              else None))
    info["objective_by_fresnel"]["schlick+coat"] = float(E_coat)
    coated.fit_options = model.fit_options
    return _done(coated, info)


def _done(model, info: dict):
    """``model`` with ``info`` and its outcome recorded (:func:`brdffit.fit.result.record`):
    the fit is a bounded multi-start search with exact linear solves, which has no
    convergence criterion of its own (``converged`` None); the message names the method and
    ``fun`` is the objective of the model returned."""
    return record(model, info, success=True, converged=None, message=info["method"],
                  fun=info["objective"], time=info["time"])


def _objective_of(model, data) -> float:
    """The objective ``Σ_c Σ_j w_cj (f_c(j) − ρ*_cj)²`` of a built model on the sample set."""
    f = np.asarray(model.eval(data["wi"], data["wo"]), dtype=np.float64)
    return float(np.sum(data["w"] * (f - data["z"]) ** 2))


def fit_ggx_diffuse(brdf, **kwargs) -> MicrofacetBRDF | SumBRDF:
    """GGX + Lambert (ρd/π) with a Schlick (per-channel F0) or dielectric Fresnel, fitted
    over the whole data with the compressive objective (Bagher 2016): the engine-ready model.

    Parameters
    ----------
    brdf : BRDF
        Any BRDF (isotropic, or anisotropic with ``anisotropic=True``).
    **kwargs
        The options of :func:`fit_analytic_diffuse`: ``anisotropic``, ``fresnel``
        (``"auto"``, ``"schlick"``, ``"dielectric"``, ``"conductor"``), ``f90``
        (``"free"``, ``"one"``), ``coat`` (``"auto"``, ``"off"``, ``"on"``),
        ``starts``, ``moments``, sample strides, ``objective``, ``name``.

    Returns
    -------
    MicrofacetBRDF or SumBRDF
        GGX(αx, αy, ρ), the chosen Fresnel, ``diffuse`` = ρd and ``specular`` = ks, with
        ``fit_info`` (objective, Fresnel chosen, starts, coat, time); when the coat is kept
        (module docstring), a ``SumBRDF`` of that lobe and the coat lobe
        (:func:`~brdffit.microfacet.coat.coat_parts`).

    Examples
    --------
    >>> import brdffit
    >>> m = brdffit.fit_ggx_diffuse(brdffit.synthetic("gold-ggx"))
    >>> round(float(m.distribution.alpha_x), 2)
    0.12
    """
    return fit_analytic_diffuse(brdf, "ggx", **kwargs)


def fit_beckmann_diffuse(brdf, **kwargs) -> MicrofacetBRDF | SumBRDF:
    """Beckmann + Lambert (ρd/π), fitted like :func:`fit_ggx_diffuse`: the same parameters
    (``brdf``, the options of :func:`fit_analytic_diffuse`) and result, with a Beckmann
    distribution.

    Examples
    --------
    >>> from brdffit import fit_beckmann_diffuse, synthetic
    >>> alpha = fit_beckmann_diffuse(synthetic("plastic-beckmann")).distribution.alpha_x
    >>> round(float(alpha), 3)
    0.18
    """
    return fit_analytic_diffuse(brdf, "beckmann", **kwargs)


def summary(model) -> dict:
    """The fitted parameters and time (what ``brdffit fit`` prints)."""
    info = dict(getattr(model, "fit_info", None) or {})
    return {"model": (getattr(model, "fit_options", None) or {}).get("model"),
            "alpha": [info.get("alpha_x"), info.get("alpha_y"), info.get("rho")],
            "fresnel": info.get("fresnel"), "eta": info.get("eta"), "k": info.get("k"),
            "rho_d": info.get("rho_d"), "F0": info.get("F0"), "ks": info.get("ks"),
            "objective_normalised": info.get("objective_normalised"),
            "coat": info.get("coat"), "time_s": info.get("time")}
