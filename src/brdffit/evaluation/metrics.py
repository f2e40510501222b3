"""Error metrics between renderings and between BRDFs.

Image space
-----------
* :func:`rendered_psnr` – PSNR of Bagher, Snyder, Nowrouzezahrai 2016 (§5, "Results"):
  computed on the *linear* rendered values (no tone mapping), over foreground pixels only
  (pixels covered by the object), with the numerator taken as the maximum intensity of any
  RGB component of any foreground pixel of the ground-truth rendering.
* :func:`crn_psnr` – the same PSNR estimated from K independent batches rendered with common
  random numbers (reference and model share every random number within a batch), with its
  standard error; :func:`combine_psnr` – mean over scenes with the propagated error.
* :func:`delta_e2000_image` / :func:`mean_delta_e2000` – CIE dE2000 difference images as
  shown in the supplemental of Dupuy et al. 2015 (per-material "CIE dE00" rows), computed
  with ``colour-science`` after the conversion documented in :func:`to_lab`.
* :func:`colorize_delta_e` – the fixed colour map used for every dE image of a report
  (0 … :data:`DELTA_E_VMAX` mapped through matplotlib's ``inferno``; larger values saturate),
  so that images of different materials and models are comparable.

BRDF space (functions of two BRDFs, independent of rendering)
-------------------------------------------------------------
* :func:`cosine_weighted_relative_error` – defined and implemented here.
* ``normalized_l2(ref, fit)`` (Bagher, Soler, Holzschuch 2012 §6.3) and
  ``compressive_objective(fit, reference) -> dict`` (Bagher et al. 2016 Eq. 7-12; note its
  argument order and dict result) are re-exported as is from :mod:`brdffit.losses.l2`
  and :mod:`brdffit.losses.objective` (attribute access raises ``AttributeError`` naming
  the missing module otherwise). :class:`BRDFMetrics` wraps all three with the reference
  prepared once and scalar results.
* Not to be confused with ``objective.weighted_mean_relative_error`` (a weighted *mean of
  per-sample relative errors* on the MERL grid): the one here is a *ratio of integrals*.

Database summaries
------------------
* :func:`count_wins` – pairwise wins / ties / losses between models where a tie is a PSNR
  difference within 2 dB, as Bagher et al. 2016 §5 report "beats … 308 times and ties it 85
  times".
"""

from __future__ import annotations

import importlib
import time
from typing import Mapping, Sequence

import numpy as np

from ..brdf import hd_through_directions, measured_mask
from .tonemap import tonemap
from ..geometry import half_diff_to_io
from ..grid import eval_chunked, eval_hd_chunked, tabulate_merl_grid
from ..losses.l2 import L2Reference
from ..losses.objective import merl_grid_geometry, prepare_objective

__all__ = [
    "DELTA_E_VMAX", "DELTA_E_CMAP", "npf_tonemap", "foreground_mask", "rendered_psnr",
    "crn_psnr", "CRNReference", "combine_psnr", "psnr_from_mse", "DeltaE2000",
    "to_lab", "delta_e2000_image", "mean_delta_e2000", "colorize_delta_e",
    "cosine_weighted_relative_error", "measured_pairs", "error_regions", "region_of",
    "REGIONS", "count_wins", "brdf_metrics", "BRDFMetrics",
    "normalized_l2", "compressive_objective",
]

#: Upper end of the fixed dE2000 colour scale (values above saturate).
DELTA_E_VMAX = 10.0
#: Matplotlib colour map of the dE2000 images.
DELTA_E_CMAP = "inferno"

# Names re-exported lazily from sibling modules written elsewhere in the project.
_REEXPORTS = {
    "normalized_l2": ("l2", ("normalized_l2",)),
    "compressive_objective": ("objective", ("compressive_objective", "objective",
                                            "compressive_weighted_error")),
}


def __getattr__(name):
    if name in _REEXPORTS:
        mod_name, candidates = _REEXPORTS[name]
        try:
            mod = importlib.import_module(f"brdffit.losses.{mod_name}")
        except ModuleNotFoundError as exc:
            raise AttributeError(f"{name} needs brdffit.losses.{mod_name}, which is not "
                                 f"available: {exc}") from None
        for cand in candidates:
            if hasattr(mod, cand):
                return getattr(mod, cand)
        raise AttributeError(f"brdffit.losses.{mod_name} has none of {candidates}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# ------------------------------------------------------------------------------------------
# helpers
# ------------------------------------------------------------------------------------------
def npf_tonemap(img, exposure: float = 0.02, gamma: float = 2.2) -> np.ndarray:
    """Tone mapping of Bagher et al. 2016 §5, ``(1 - 2^(-exposure·x))^(1/gamma)``
    (:func:`brdffit.evaluation.tonemap.tonemap` with a fixed exposure)."""
    return tonemap(img, exposure, gamma)


def _check_pair(reference, test, mask):
    ref = np.asarray(reference, dtype=np.float64)
    tst = np.asarray(test, dtype=np.float64)
    if ref.ndim != 3 or ref.shape[-1] != 3:
        raise ValueError(f"reference image: expected shape (H, W, 3), found {ref.shape}")
    if tst.shape != ref.shape:
        raise ValueError(f"test image: expected shape {ref.shape} (as the reference), "
                         f"found {tst.shape}")
    if mask is None:
        m = np.ones(ref.shape[:2], dtype=bool)
    else:
        m = np.asarray(mask)
        if m.ndim == 3:
            m = m[..., 0]
        if m.shape != ref.shape[:2]:
            raise ValueError(f"foreground mask: expected shape {ref.shape[:2]}, found {m.shape}")
        m = m.astype(bool)
    if not m.any():
        raise ValueError("foreground mask: expected at least one foreground pixel, found none")
    return ref, tst, m


def foreground_mask(image=None, alpha=None, threshold: float = 0.5) -> np.ndarray:
    """Boolean foreground mask from an alpha/coverage channel (``alpha > threshold``).

    With only an ``(H, W, 4)`` image, its 4th channel is used.
    """
    if alpha is None:
        image = np.asarray(image)
        if image.ndim != 3 or image.shape[-1] != 4:
            raise ValueError(f"expected an (H, W, 4) image or an alpha channel, found {image.shape}")
        alpha = image[..., 3]
    return np.asarray(alpha) > threshold


# ------------------------------------------------------------------------------------------
# image metrics
# ------------------------------------------------------------------------------------------
def rendered_psnr(reference, test, mask=None) -> float:
    """Rendered PSNR in dB, as defined by Bagher et al. 2016 §5.

    ``PSNR = 10 log10(peak² / MSE)`` where MSE is the mean of ``(test - reference)²`` over
    every RGB component of every foreground pixel (linear values, no tone mapping), and
    ``peak`` is the maximum RGB component of the reference over the foreground. Not
    symmetric (the peak comes from the reference). Returns ``inf`` for identical images.

    Parameters
    ----------
    reference, test: (H, W, 3) linear images (the ground truth first).
    mask: (H, W) boolean foreground mask (``None``: all pixels).
    """
    ref, tst, m = _check_pair(reference, test, mask)
    r = ref[m]
    t = tst[m]
    peak = float(np.max(r))
    if not np.isfinite(peak) or peak <= 0:
        raise ValueError(f"reference foreground: expected a positive finite peak, found {peak}")
    mse = float(np.mean((t - r) ** 2))
    if not np.isfinite(mse):
        raise ValueError("test image: expected finite values on the foreground, found NaN/inf")
    if mse == 0.0:
        return float("inf")
    return float(10.0 * np.log10(peak * peak / mse))


_DB = 10.0 / np.log(10.0)


def psnr_from_mse(peak: float, mse: float) -> float:
    """``10 log10(peak² / mse)``; ``inf`` for ``mse == 0``."""
    if mse <= 0:
        return float("inf")
    return float(10.0 * np.log10(peak * peak / mse))


class CRNReference:
    """The reference side of :func:`crn_psnr`: its ``(K, H, W, 3)`` batches (a single
    ``(H, W, 3)`` image is one batch) on the foreground ``mask`` (default all pixels),
    gathered once as ``R`` ``(K, P)`` float64 (P values: pixels × channels); a comparison
    measures every model of a scene against the same reference batches."""

    def __init__(self, reference, mask=None):
        ref = np.asarray(reference)          # converted to float64 after masking
        ref = ref[None] if ref.ndim == 3 else ref
        if ref.ndim != 4 or ref.shape[-1] != 3:
            raise ValueError(f"expected two (K, H, W, 3) stacks of the same shape, found "
                             f"{ref.shape}")
        m = (np.ones(ref.shape[1:3], bool) if mask is None else np.asarray(mask).astype(bool))
        if m.shape != ref.shape[1:3]:
            raise ValueError(f"foreground mask: expected shape {ref.shape[1:3]}, found {m.shape}")
        if not m.any():
            raise ValueError("foreground mask: expected at least one foreground pixel, "
                             "found none")
        self.shape, self.index = ref.shape, np.flatnonzero(m)
        self.R = self._gather(ref)

    def _gather(self, stack: np.ndarray) -> np.ndarray:
        """``stack``'s foreground values ``(K, P)`` float64, in the order of ``stack[:, mask]``."""
        K = stack.shape[0]
        return stack.reshape(K, -1, 3).take(self.index, axis=1).reshape(K, -1).astype(np.float64)

    def differences(self, test) -> np.ndarray:
        """``D = test − reference`` on the foreground, ``(K, P)`` float64, checked finite."""
        tst = np.asarray(test)
        tst = tst[None] if tst.ndim == 3 else tst
        if tst.shape != self.shape:
            raise ValueError(f"expected two (K, H, W, 3) stacks of the same shape, found "
                             f"{self.shape} and {tst.shape}")
        D = self._gather(tst) - self.R
        if not np.all(np.isfinite(D)):
            raise ValueError("test image: expected finite values on the foreground, found NaN/inf")
        return D

    def psnr(self, test, peak: float | None = None) -> dict:
        """:func:`crn_psnr` of ``test`` against this reference."""
        return _crn_estimate(self.R, self.differences(test), peak)


def _jackknife_se(D: np.ndarray, D2: np.ndarray, S: np.ndarray, base: float) -> float:
    """Delete-one-batch jackknife standard error of :func:`crn_psnr`'s ``MSE_U`` (K ≥ 3
    batches, rows of ``D``; ``D2 = D²``, ``S = Σ_k D_k``, ``base = mean_P (S² − Q)``): U
    without batch k is ``mean_P[(S − D_k)² − (Q − D_k²)] / ((K−1)(K−2))``."""
    K = D.shape[0]
    loo = (base - 2.0 * (D @ S) / D.shape[1] + 2.0 * np.mean(D2, axis=1)) / ((K - 1) * (K - 2))
    return float(np.sqrt((K - 1) / K * np.sum(np.square(loo - loo.mean()))))


def crn_psnr(reference, test, mask=None, peak: float | None = None) -> dict:
    """Rendered PSNR (Bagher 2016 §5) with its standard error, from K independent batches.

    ``reference`` and ``test`` are ``(K, H, W, 3)`` stacks of linear renderings: batch ``k``
    of both rendered with the same seed and common random numbers (same directions, pdfs and
    MIS weights, :mod:`brdffit.evaluation.render.proposal`), different batches with
    independent seeds. ``mask``: ``(H, W)`` foreground (default all pixels).

    Estimator. Let ``D_k`` be the per-pixel, per-channel difference ``test_k − reference_k``
    over the foreground (P values) and ``Δ`` its expectation, the difference of the converged
    images. The quantity of interest is ``MSE = mean_P Δ²``. Each ``D_k = Δ + ε_k`` with
    zero-mean noise; with CRN the reference's own noise cancels in ``D_k`` and ``ε_k`` is of
    the order of ``Δ`` (it vanishes with it), so the estimator is not swamped by the noise of
    the images. Still, ``mean_P D_k²`` is biased upwards by ``mean_P Var(ε)``, and the MSE of
    the batch means by ``mean_P Var(ε)/K``. We remove that bias exactly with the U-statistic
    over pairs of independent batches (``E[D_j D_k] = Δ²`` for ``j ≠ k``)::

        MSE_U = mean_P (S² − Q) / (K (K − 1)),    S = Σ_k D_k,   Q = Σ_k D_k²,

    unbiased for any K ≥ 2 (``mse_plain = mean_P (S/K)²`` is reported as well, and
    ``noise_mse = mse_plain − MSE_U``, the removed variance term). Its standard error is the
    delete-one-batch jackknife (``se² = (K−1)/K Σ_k (U_(−k) − Ū)²``, K ≥ 3; the jackknife
    variance of a U-statistic is conservative), and the PSNR's by the delta method:
    ``psnr = 10 log10(peak² / MSE_U)``, ``psnr_se = (10 / ln 10) · se(MSE_U) / MSE_U``.

    ``peak`` (the PSNR numerator: max RGB component of the reference foreground) is taken
    from the mean of the K reference batches (the converged reference as well as we have it;
    the max of one noisy batch is biased upwards) and treated as a constant: it is the same
    for every model of a scene, so it shifts all their PSNRs alike.

    When ``D ≡ 0`` (a model rendered against itself) the PSNR is ``inf`` with se 0. When the
    difference is not resolved (``MSE_U ≤ 0``: it is below the noise of its own estimate), the
    returned ``psnr`` is the lower bound ``10 log10(peak² / (max(MSE_U, 0) + 2 se))`` and
    ``bound == "lower"``; ``resolved`` is ``MSE_U > 2 se``.

    Returns a dict: ``psnr``, ``psnr_se``, ``mse``, ``mse_se``, ``mse_plain``, ``noise_mse``,
    ``peak``, ``batches``, ``resolved``, ``bound`` (``None`` or ``"lower"``),
    ``psnr_plain`` (PSNR of the mean images, biased low).
    """
    return CRNReference(reference, mask).psnr(test, peak)


def _crn_estimate(R: np.ndarray, D: np.ndarray, peak: float | None) -> dict:
    """:func:`crn_psnr` from the reference's foreground values ``R`` and the differences
    ``D`` (:class:`CRNReference`)."""
    K = R.shape[0]
    if peak is None:
        peak = float(np.max(R.mean(0)))
    if not np.isfinite(peak) or peak <= 0:
        raise ValueError(f"reference foreground: expected a positive finite peak, found {peak}")
    S = D.sum(0)
    D2 = np.square(D)
    Q = D2.sum(0)
    mse_plain = float(np.mean(np.square(S / K)))
    out = {"batches": int(K), "peak": float(peak), "mse_plain": mse_plain,
           "psnr_plain": psnr_from_mse(peak, mse_plain)}
    if not np.any(D):
        return out | {"psnr": float("inf"), "psnr_se": 0.0, "mse": 0.0, "mse_se": 0.0,
                      "noise_mse": 0.0, "resolved": True, "bound": None}
    if K < 2:
        return out | {"psnr": out["psnr_plain"], "psnr_se": float("nan"), "mse": mse_plain,
                      "mse_se": float("nan"), "noise_mse": float("nan"), "resolved": False,
                      "bound": "lower"}
    base = np.mean(S * S - Q)
    mse = float(base / (K * (K - 1)))
    se = _jackknife_se(D, D2, S, base) if K >= 3 else float("nan")
    out |= {"mse": mse, "mse_se": se, "noise_mse": mse_plain - mse}
    if mse > 0:
        resolved = bool(np.isfinite(se) and mse > 2.0 * se)
        return out | {"psnr": psnr_from_mse(peak, mse),
                      "psnr_se": float(_DB * se / mse) if np.isfinite(se) else float("nan"),
                      "resolved": resolved, "bound": None}
    bound_mse = max(mse, 0.0) + (2.0 * se if np.isfinite(se) else mse_plain)
    return out | {"psnr": psnr_from_mse(peak, bound_mse), "psnr_se": float("nan"),
                  "resolved": False, "bound": "lower"}


def combine_psnr(per_scene: Sequence[Mapping]) -> dict:
    """Mean PSNR over scenes (Bagher 2016 §5 averages its four scenes) and its standard error
    ``sqrt(Σ se_s²) / S`` (scenes rendered with independent random numbers). A scene at
    ``inf`` makes the mean ``inf``; a scene given as a lower bound makes the mean one
    (``bound == "lower"``, se NaN)."""
    ps = [float(r["psnr"]) for r in per_scene]
    if not ps:
        return {"psnr": float("nan"), "psnr_se": float("nan"), "bound": None, "n_scenes": 0}
    ses = [float(r.get("psnr_se", float("nan"))) for r in per_scene]
    bound = "lower" if any(r.get("bound") == "lower" for r in per_scene) else None
    mean = float(np.mean(ps))
    if np.isinf(mean):
        se = 0.0 if all(np.isinf(p) for p in ps) else float("nan")
    elif bound:
        se = float("nan")
    else:
        finite = [s for p, s in zip(ps, ses) if np.isfinite(p)]
        se = float(np.sqrt(np.sum(np.square(finite))) / len(ps))
    return {"psnr": mean, "psnr_se": se, "bound": bound, "n_scenes": len(ps)}


def to_lab(img, exposure: float = 0.02, gamma: float = 2.2, tonemap=None) -> np.ndarray:
    """Linear rendering ``(H, W, 3)`` → CIE L*a*b* (D65) as it is displayed in the report.

    Conversion (the same for every image, so dE values are comparable):

    1. tone map with the operator of Bagher et al. 2016 §5 (``tonemap`` or
       :func:`npf_tonemap` with ``exposure``/``gamma``) – this is exactly the PNG shown;
    2. interpret the result as *encoded* sRGB (IEC 61966-2-1) and decode it with the sRGB
       EOTF to linear sRGB;
    3. linear sRGB → CIE XYZ (D65) → CIE L*a*b* with the D65 white point (colour-science).

    The renderer's linear RGB is taken to be linear sRGB primaries (the MERL/RGL data and
    Mitsuba's ``*_rgb`` variants use sRGB/Rec.709 primaries).
    """
    import colour

    tm = tonemap if tonemap is not None else (lambda x: npf_tonemap(x, exposure, gamma))
    encoded = np.clip(np.asarray(tm(np.asarray(img, dtype=np.float64)), dtype=np.float64), 0, 1)
    linear = colour.cctf_decoding(encoded, function="sRGB")
    xyz = colour.RGB_to_XYZ(linear, colour.RGB_COLOURSPACES["sRGB"], apply_cctf_decoding=False)
    white = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]
    return colour.XYZ_to_Lab(xyz, white)


def delta_e2000_image(reference, test, mask=None, exposure: float = 0.02, gamma: float = 2.2,
                      tonemap=None) -> np.ndarray:
    """Per-pixel CIE dE2000 (``colour.delta_E``, method ``CIE 2000``) between two renderings.

    Both images go through :func:`to_lab`. Background pixels (outside ``mask``) are NaN.
    Symmetric in its two image arguments.
    """
    ref, tst, m = _check_pair(reference, test, mask)
    return DeltaE2000(ref, m, exposure, gamma, tonemap).image(tst)


class DeltaE2000:
    """:func:`delta_e2000_image` against one reference, its L*a*b* computed once and only the
    foreground pixels converted (a comparison measures many models on the same reference)."""

    def __init__(self, reference, mask=None, exposure: float = 0.02, gamma: float = 2.2,
                 tonemap=None):
        ref = np.asarray(reference)     # to_lab converts the foreground to float64
        self.mask = (np.ones(ref.shape[:2], bool) if mask is None
                     else np.asarray(mask).astype(bool).reshape(ref.shape[:2]))
        self.shape = ref.shape
        self.kw = (exposure, gamma, tonemap)
        self.ref_lab = to_lab(ref[self.mask][None], *self.kw)[0]

    def image(self, test) -> np.ndarray:
        import colour

        tst = np.asarray(test)
        if tst.shape != self.shape:
            raise ValueError(f"test image: expected shape {self.shape} (as the reference), "
                             f"found {tst.shape}")
        de = colour.delta_E(self.ref_lab, to_lab(tst[self.mask][None], *self.kw)[0],
                            method="CIE 2000")
        out = np.full(self.shape[:2], np.nan)
        out[self.mask] = de
        return out


def mean_delta_e2000(reference, test, mask=None, **kw) -> float:
    """Mean dE2000 over the foreground pixels (see :func:`delta_e2000_image`)."""
    de = delta_e2000_image(reference, test, mask, **kw)
    return float(np.nanmean(de))


def colorize_delta_e(de, vmax: float = DELTA_E_VMAX, cmap: str = DELTA_E_CMAP,
                     background=(0, 0, 0)) -> np.ndarray:
    """Fixed colour map of a dE image → ``uint8`` ``(H, W, 3)``; NaN (background) → ``background``."""
    from matplotlib import colormaps

    de = np.asarray(de, dtype=np.float64)
    x = np.clip(np.nan_to_num(de, nan=0.0) / vmax, 0.0, 1.0)
    rgb = colormaps[cmap](x)[..., :3]
    rgb = np.where(np.isnan(de)[..., None], np.asarray(background, float) / 255.0, rgb)
    return np.round(rgb * 255).astype(np.uint8)


# ------------------------------------------------------------------------------------------
# BRDF-space metrics
# ------------------------------------------------------------------------------------------
def _sobol_pairs(n: int, seed: int):
    from scipy.stats import qmc

    m = max(1, int(np.ceil(np.log2(max(n, 2)))))
    u = qmc.Sobol(d=4, scramble=True, seed=seed).random_base2(m)
    u = np.clip(u, 1e-12, 1 - 1e-12)

    def cos_hemi(a, b):
        r = np.sqrt(a)
        phi = 2 * np.pi * b
        return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - a)], -1)

    return cos_hemi(u[:, 0], u[:, 1]), cos_hemi(u[:, 2], u[:, 3])


def measured_pairs(reference, wi, wo) -> tuple[np.ndarray, np.ndarray]:
    """The direction pairs within ``reference``'s measured domain (all of them when it has
    none); raises ``ValueError`` when none is."""
    keep = measured_mask(reference, wi, wo)
    if keep is None:
        return wi, wo
    if not keep.any():
        raise ValueError(f"reference BRDF: expected direction pairs within its measured domain "
                         f"({reference.measured_domain}), found none")
    return wi[keep], wo[keep]


def cosine_weighted_relative_error(reference, test, n_samples: int = 1 << 17, seed: int = 0,
                                   chunk: int = 1 << 15, per_channel: bool = False):
    """Cosine-weighted relative L1 error of ``test`` against ``reference`` (two BRDFs).

    Definition (this project's, not from the papers)::

        E_rel = Σ_c ∫∫ |f_test,c(i, o) − f_ref,c(i, o)| cos θi cos θo dωi dωo
                ─────────────────────────────────────────────────────────────
                Σ_c ∫∫ |f_ref,c(i, o)| cos θi cos θo dωi dωo

    over the product of upper hemispheres and the three RGB channels ``c``. The cosine
    weights make it the relative error of reflected energy under uniform illumination
    (numerator and denominator are both bounded by the albedo), so grazing samples – where
    measured data and Neural-BRDF networks are least reliable – weigh little. 0 means
    identical, 1 means an error as large as the reference itself (e.g. a black fit).

    Both integrals are estimated with the *same* ``n_samples`` scrambled-Sobol pairs drawn
    from the cosine-weighted hemisphere for ``i`` and ``o`` (density ``cos θi cos θo / π²``,
    which cancels the weights), so the estimate is deterministic for a ``seed``. Works for
    anisotropic BRDFs. ``per_channel=True`` returns the three per-channel ratios instead.

    Both integrals run over the reference's measured domain only
    (:meth:`brdffit.brdf.BRDF.measured`; the pairs outside it are dropped).
    """
    wi, wo = measured_pairs(reference, *_sobol_pairs(n_samples, seed))
    num = np.zeros(3)
    den = np.zeros(3)
    for s in range(0, wi.shape[0], chunk):
        a, b = wi[s:s + chunk], wo[s:s + chunk]
        fr = np.nan_to_num(np.asarray(reference.eval(a, b), dtype=np.float64))
        ft = np.nan_to_num(np.asarray(test.eval(a, b), dtype=np.float64))
        num += np.abs(ft - fr).sum(axis=0)
        den += np.abs(fr).sum(axis=0)
    if per_channel:
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), np.inf)
    if den.sum() <= 0:
        raise ValueError("reference BRDF: expected a non-zero reflectance, found 0 everywhere")
    return float(num.sum() / den.sum())


#: Regions of :func:`error_regions`, in the order they are assigned (a pair belongs to the
#: first that contains it): the specular peak (θh < 8°), retro-reflection (θd < 10°: light
#: and view within 20° of each other), grazing (θi or θo > 70°), the rest of the lobe's body.
REGIONS = ("specular peak", "retro-reflection", "grazing", "body")
_PEAK_DEG, _RETRO_DEG, _GRAZING_DEG = 8.0, 10.0, 70.0

#: What each region's error says is missing (:func:`error_regions`, ``diagnosis``), by the
#: sign of the fit's bias there (too dark, too bright).
_MISSING = {
    "specular peak": ("the measured peak is sharper and higher than the fit's lobe can be: "
                      "a second, narrower specular lobe is missing",
                      "the fit's peak is too high: the measured highlight is broader or "
                      "dimmer than one lobe of this shape (a heavier-tailed distribution)"),
    "retro-reflection": ("the material reflects back towards the light more than the model "
                         "can: a retro-reflective lobe is missing",
                         "the fit reflects back towards the light more than the material"),
    "grazing": ("the material is brighter at grazing angles than the model (sheen, a "
                "Fresnel rise the model's F lacks, or grazing measurement noise)",
                "the fit is brighter at grazing angles than the material (its Fresnel or "
                "shadowing, or grazing measurement noise)"),
    "body": ("the off-specular reflection is brighter than the model's diffuse and lobe "
             "tails (subsurface scattering, or angle-dependent colour such as thin-film "
             "interference)",
             "the fit's off-specular reflection is too bright (lobe tails too heavy, or a "
             "diffuse term where the material has angle-dependent colour)"),
}


def region_of(wi, wo) -> np.ndarray:
    """Index into :data:`REGIONS` of each direction pair ``(…,)``."""
    h = wi + wo
    h = h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
    th = np.degrees(np.arccos(np.clip(h[..., 2], -1.0, 1.0)))
    td = np.degrees(np.arccos(np.clip(np.sum(wi * h, -1), -1.0, 1.0)))
    grazing = np.degrees(np.arccos(np.clip(np.minimum(wi[..., 2], wo[..., 2]), -1.0, 1.0)))
    return np.select([th < _PEAK_DEG, td < _RETRO_DEG, grazing > _GRAZING_DEG],
                     [0, 1, 2], default=3)


def _colour_by_incidence(wi, vals) -> np.ndarray:
    """RGB shares of the energy of the pairs with θi < 30°, 30-60° and > 60° (3, 3)."""
    ti = np.degrees(np.arccos(np.clip(wi[..., 2], -1.0, 1.0)))
    out = np.full((3, 3), np.nan)
    for k, (lo, hi) in enumerate(((0, 30), (30, 60), (60, 90))):
        e = np.abs(vals[(ti >= lo) & (ti < hi)]).sum(0)
        if e.sum() > 0:
            out[k] = e / e.sum()
    return out


def _regions_from(region, ref_vals, test_vals, wi) -> dict:
    diff = np.abs(test_vals - ref_vals).sum(-1)
    ref = np.abs(ref_vals).sum(-1)
    test = np.abs(test_vals).sum(-1)
    total_err, total_ref = float(diff.sum()), float(ref.sum())
    out = {}
    for k, name in enumerate(REGIONS):
        sel = region == k
        out[name] = {"error_share": float(diff[sel].sum() / total_err) if total_err > 0 else 0.0,
                     "energy_share": float(ref[sel].sum() / total_ref) if total_ref > 0 else 0.0,
                     "fit_over_measured": (float(test[sel].sum() / ref[sel].sum())
                                           if ref[sel].sum() > 0 else None)}
    findings = []
    worst = max(REGIONS, key=lambda n: out[n]["error_share"] - out[n]["energy_share"])
    r = out[worst]
    if total_err > 0 and r["error_share"] >= 0.25 and r["error_share"] >= r["energy_share"] + 0.05:
        dark = r["fit_over_measured"] is not None and r["fit_over_measured"] < 1.0
        findings.append(f"{100 * r['error_share']:.0f} % of the error lies in the {worst} region "
                        f"({100 * r['energy_share']:.0f} % of the reflected energy; the fit "
                        f"{r['fit_over_measured'] or 0:.2f}× the measurement there): "
                        + _MISSING[worst][0 if dark else 1])
    ratios = [v["fit_over_measured"] for v in out.values()
              if v["fit_over_measured"] is not None and v["energy_share"] >= 0.05]
    if ratios and max(ratios) < 0.85:
        findings.append(f"the fit is darker than the measurement in every region "
                        f"({min(ratios):.2f}-{max(ratios):.2f}×): it misses part of the reflected "
                        "energy (the fits minimise the compressive objective, which weighs "
                        "bright samples down)")
    elif ratios and min(ratios) > 1.15:
        findings.append(f"the fit is brighter than the measurement in every region "
                        f"({min(ratios):.2f}-{max(ratios):.2f}×)")
    colour_ref = _colour_by_incidence(wi, ref_vals)
    colour_fit = _colour_by_incidence(wi, test_vals)
    shift_ref = float(np.nanmax(np.abs(colour_ref - colour_ref[0]).sum(-1)))
    shift_fit = float(np.nanmax(np.abs(colour_fit - colour_fit[0]).sum(-1)))
    if shift_ref > 0.15 and shift_fit < 0.6 * shift_ref:
        a, b = colour_ref[0], colour_ref[np.nanargmax(np.abs(colour_ref - colour_ref[0]).sum(-1))]
        findings.append("the measured colour changes with the angle of incidence (RGB shares "
                        f"{a[0]:.2f}/{a[1]:.2f}/{a[2]:.2f} at θi < 30° → "
                        f"{b[0]:.2f}/{b[1]:.2f}/{b[2]:.2f}), the fit's far less "
                        f"(shift {shift_fit:.2f} vs {shift_ref:.2f}): angle-dependent colour "
                        "such as thin-film interference, which these models do not have")
    return {"regions": out, "worst": worst, "colour_shift": {"measured": shift_ref,
                                                              "fit": shift_fit},
            "findings": findings, "diagnosis": "; ".join(findings) or None}


def error_regions(reference, test, n_samples: int = 1 << 16, seed: int = 0) -> dict:
    """Where the cosine-weighted error of ``test`` against ``reference`` lies.

    The pairs of :func:`cosine_weighted_relative_error` (measured domain only) are split into
    :data:`REGIONS`; per region: ``error_share`` (its part of Σ|f − f_ref| cos θi cos θo),
    ``energy_share`` (its part of the reference's Σ f_ref cos θi cos θo) and
    ``fit_over_measured`` (Σ f / Σ f_ref there). ``worst`` is the region whose error share most
    exceeds its energy share. ``findings`` (joined in ``diagnosis``, ``None`` when empty) say
    what the model misses: the worst region when it holds at least a quarter of the error
    (and 5 points more than its energy share), a fit darker (< 0.85×) or brighter (> 1.15×)
    than the measurement in every region, and a measured colour that changes with the angle
    of incidence (RGB shares of the energy at θi < 30°, 30-60°, > 60° differ by > 0.15 in
    L1) when the fit's changes by less than 0.6 of that (``colour_shift``). A heuristic
    reading of the residual, not a fit of the missing component.
    """
    return BRDFMetrics(reference, n_samples, seed, ("error_regions",)).error_regions(test)


def _merl_coords(flat_index) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(θh, θd, φd)`` of the MERL grid's samples at ``flat_index`` (of the 90×90×180 grid)."""
    geo = merl_grid_geometry()
    return tuple(geo[k].ravel()[flat_index] for k in ("theta_h", "theta_d", "phi_d"))


class BRDFMetrics:
    """BRDF-space metrics of several fits against one reference, the reference prepared once.

    ``BRDFMetrics(ref).evaluate(fit)`` returns a dict with

    * ``cos_rel_error`` – :func:`cosine_weighted_relative_error` (always; over the
      reference's measured domain, as the other two);
    * ``normalized_l2`` – Bagher et al. 2012 §6.3 via :class:`brdffit.losses.l2.L2Reference`
      (MERL-grid quadrature for isotropic references, Monte Carlo otherwise);
    * ``error_regions`` – :func:`error_regions`: where that error lies and what the model
      misses there;
    * ``compressive_objective`` – Eq. 7 of Bagher et al. 2016 with the weights of Eq. 8-12
      (:mod:`brdffit.losses.objective`), *normalised* by the objective of the all-zero
      model (``Σ w ρ*²``) so that it is comparable across materials; isotropic references only.

    A metric whose module is missing or that fails is ``None``, with the reason under
    ``errors``. ``metrics`` restricts which ones are computed.
    """

    ALL = ("cos_rel_error", "normalized_l2", "compressive_objective", "error_regions")

    def __init__(self, reference, n_samples: int = 1 << 16, seed: int = 0,
                 metrics: Sequence[str] = ALL):
        self.reference = reference
        self.metrics = tuple(metrics)
        self.errors: dict[str, str] = {}
        self.timings: dict[str, float] = {}
        self._n_samples, self._seed = n_samples, seed
        self._wi = self._wo = self._ref_vals = self._regions = None
        if {"cos_rel_error", "error_regions"} & set(self.metrics):
            self._pairs()
        self._last: tuple = (None, None)       # (fit, its values on the pairs)
        self._grid_nodes = None                 # the nodes both grid metrics read
        self._grid_directions = None            # and their (wi, wo)
        self._l2 = None
        if "normalized_l2" in self.metrics:
            t0 = time.perf_counter()
            try:
                iso = bool(getattr(reference, "isotropic", False)) and hasattr(reference, "eval_hd")
                self._l2 = L2Reference(reference, "grid" if iso else "mc", seed=seed)
            except Exception as exc:  # noqa: BLE001 – optional metric
                self.errors["normalized_l2"] = f"{type(exc).__name__}: {exc}"
            self.timings["normalized_l2_setup"] = time.perf_counter() - t0
        self._obj = None
        if "compressive_objective" in self.metrics:
            t0 = time.perf_counter()
            try:
                if not getattr(reference, "isotropic", False):
                    raise ValueError("the compressive objective needs an isotropic reference")
                vals, valid = tabulate_merl_grid(reference)
                self._obj = prepare_objective(vals, valid, source=getattr(reference, "name", None))
                self._obj_coords = _merl_coords(self._obj.index)
                self._obj_ref_energy = self._obj.reference_energy()
            except Exception as exc:  # noqa: BLE001
                self.errors["compressive_objective"] = f"{type(exc).__name__}: {exc}"
            self.timings["compressive_objective_setup"] = time.perf_counter() - t0

    def _pairs(self) -> None:
        """The sample pairs of ``cos_rel_error`` and ``error_regions`` over the reference's
        measured domain, its values and regions there: prepared at set-up when the chosen
        metrics read them, else by the first call that does (never when none does)."""
        if self._wi is not None:
            return
        t0 = time.perf_counter()
        self._wi, self._wo = measured_pairs(self.reference,
                                            *_sobol_pairs(self._n_samples, self._seed))
        self._ref_vals = np.nan_to_num(np.asarray(self.reference.eval(self._wi, self._wo),
                                                  float))
        self._regions = region_of(self._wi, self._wo)
        self.timings["cos_rel_error_setup"] = time.perf_counter() - t0

    def _grid_metric_values(self, test):
        """``(values at the L2 grid's nodes, values at the objective's samples)`` of ``test``
        from one ``eval_hd`` over the union of both node sets (the objective's samples and
        every ``phi_stride``-th φd plane), or ``None`` where that does not apply (either metric
        off, a Monte Carlo L2, a table read as stored)."""
        l2, obj = self._l2, self._obj
        if (l2 is None or obj is None or l2.method != "grid" or not hasattr(test, "eval_hd")
                or getattr(test, "merl_table", None) is not None):
            return None
        shape = obj.mask.shape
        if self._grid_nodes is None:
            need = np.zeros(shape, dtype=bool)
            need[:, :, ::l2.phi_stride] = True
            need.ravel()[obj.index] = True
            nodes = np.flatnonzero(need)
            self._grid_nodes = (nodes, _merl_coords(nodes))
        nodes, coords = self._grid_nodes
        full = np.full((int(np.prod(shape)), 3), np.nan)
        if hd_through_directions(test):        # convert the nodes once for every such fit
            if self._grid_directions is None:
                self._grid_directions = half_diff_to_io(coords[0], 0.0, coords[1], coords[2])
            full[nodes] = eval_chunked(test, *self._grid_directions)
        else:
            full[nodes] = eval_hd_chunked(test, *coords)
        return full.reshape(shape + (3,))[:, :, ::l2.phi_stride], full[obj.index]

    def _test_values(self, test) -> np.ndarray:
        self._pairs()
        if self._last[0] is not test:          # one evaluation per fit for every metric
            self._last = (test, np.nan_to_num(np.asarray(test.eval(self._wi, self._wo), float)))
        return self._last[1]

    def error_regions(self, test) -> dict:
        """:func:`error_regions` on the prepared sample pairs."""
        ft = self._test_values(test)
        return _regions_from(self._regions, self._ref_vals, ft, self._wi)

    def cos_rel_error(self, test, per_channel: bool = False):
        """:func:`cosine_weighted_relative_error` on the prepared sample pairs."""
        ft = self._test_values(test)
        num = np.abs(ft - self._ref_vals).sum(axis=0)
        den = np.abs(self._ref_vals).sum(axis=0)
        if per_channel:
            return np.where(den > 0, num / np.where(den > 0, den, 1.0), np.inf)
        if den.sum() <= 0:
            raise ValueError("reference BRDF: expected a non-zero reflectance, found 0 everywhere")
        return float(num.sum() / den.sum())

    def evaluate(self, test) -> dict:
        out: dict = {}
        errors = dict(self.errors)
        timings = {}
        shared = None
        if "normalized_l2" in self.metrics and "compressive_objective" in self.metrics:
            t0 = time.perf_counter()
            try:
                shared = self._grid_metric_values(test)
            except Exception:  # noqa: BLE001 – each metric then evaluates (and reports) alone
                shared = None
            timings["grid_evaluation"] = time.perf_counter() - t0
        for key in self.metrics:
            t0 = time.perf_counter()
            out[key] = None
            try:
                if key == "cos_rel_error":
                    out[key] = self.cos_rel_error(test)
                elif key == "error_regions":
                    out[key] = self.error_regions(test)
                elif key == "normalized_l2" and self._l2 is not None:
                    grid = None if shared is None else shared[0]
                    out[key] = float(self._l2.errors(test, grid_values=grid)[0].value)
                elif key == "compressive_objective" and self._obj is not None:
                    fv = (np.asarray(test.eval_hd(*self._obj_coords), dtype=np.float64)
                          if shared is None else shared[1])
                    fv = np.nan_to_num(fv).T
                    out[key] = float(self._obj.value(fv).sum() / self._obj_ref_energy.sum())
            except Exception as exc:  # noqa: BLE001 – optional metrics must not break a report
                errors[key] = f"{type(exc).__name__}: {exc}"
            timings[key] = time.perf_counter() - t0
        if errors:
            out["errors"] = errors
        out["seconds"] = timings
        return out


def brdf_metrics(reference, test, n_samples: int = 1 << 16, seed: int = 0,
                 metrics: Sequence[str] = BRDFMetrics.ALL) -> dict:
    """All available BRDF-space metrics of ``test`` against ``reference`` as a dict
    (see :class:`BRDFMetrics`; use that class directly for several fits)."""
    return BRDFMetrics(reference, n_samples, seed, metrics).evaluate(test)


# ------------------------------------------------------------------------------------------
# database summaries
# ------------------------------------------------------------------------------------------
def count_wins(psnr: Mapping[str, Sequence[float]], tie_db: float = 2.0, *,
               se: Mapping[str, Sequence[float]] | None = None, z: float = 2.0) -> dict:
    """Pairwise wins, ties and losses between models over a set of renderings.

    ``psnr`` maps model name → PSNR per rendering (same order for every model; NaN = missing,
    skipped pairwise). Model ``a`` *beats* ``b`` on a rendering when
    ``psnr_a > psnr_b + t``; they *tie* when ``|psnr_a − psnr_b| <= t``. The threshold ``t``
    is ``tie_db`` (Bagher et al. 2016 §5 use 2 dB) unless ``se`` (model name → standard error
    of each PSNR, dB) gives both standard errors of a pair: then ``t = z·sqrt(se_a² + se_b²)``,
    a difference within ``z`` combined standard errors of the measurement (z = 2: ≈ 95 %).
    ``inf`` (an exact match) ties with ``inf``.

    Returns ``{a: {b: {"wins": int, "ties": int, "losses": int, "n": int}}}`` for ``a != b``.

    >>> count_wins({"a": [40.0, 30.0], "b": [39.9, 35.0]}, se={"a": [0.1, 0.1], "b": [0.1, 0.1]})["a"]["b"]
    {'wins': 0, 'ties': 1, 'losses': 1, 'n': 2}
    """
    names = list(psnr)
    arrs = {k: np.asarray(v, dtype=np.float64) for k, v in psnr.items()}
    sizes = {a.shape for a in arrs.values()}
    if len(sizes) > 1:
        raise ValueError(f"expected the same number of renderings for every model, found {sizes}")
    errs = {k: (np.asarray(se[k], dtype=np.float64) if se is not None and k in se
                else np.full(arrs[k].shape, np.nan)) for k in names}
    out: dict = {}
    for a in names:
        out[a] = {}
        for b in names:
            if a == b:
                continue
            x, y = arrs[a], arrs[b]
            ok = ~(np.isnan(x) | np.isnan(y))
            x, y = x[ok], y[ok]
            t = z * np.hypot(errs[a][ok], errs[b][ok])
            t = np.where(np.isfinite(t), t, tie_db)
            both_inf = np.isinf(x) & np.isinf(y) & (np.sign(x) == np.sign(y))
            with np.errstate(invalid="ignore"):
                d = np.where(both_inf, 0.0, x - y)
            out[a][b] = {"wins": int(np.sum(d > t)), "ties": int(np.sum(np.abs(d) <= t)),
                         "losses": int(np.sum(d < -t)), "n": int(x.size)}
    return out
