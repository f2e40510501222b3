"""The compressive-weighted fitting objective of Bagher, Snyder & Nowrouzezahrai 2016 (§4.1).

``E = Σ_j w_j (ρ(θh, θd, φd)_j − ρ*_j)²`` (Eq. 7) over the MERL samples, with
``w_j = wV · wI · wC`` (Eq. 8):

* ``wV`` – the volume form of the (θh, θd, φd) → (i, o) map (Eq. 9, derived in the paper's
  appendix), ``sqrt(8 sin²θd (cos²θd + sin²θd cos²φd)) dθh dθd dφd`` with
  ``dθh = 2 θ'h dθ'h`` because the MERL grid is uniform in ``θ'h = sqrt(θh)`` (Eq. 6);
* ``wI = cos θi cos θo`` (Eq. 10);
* ``wC = (f(ρ*/ρ̄; α) / (ρ*/ρ̄))^p`` with ``f(x; α) = (1 − e^{−αx})/α`` (Eq. 11-12),
  ``p = 1.4``, ``α = log 2`` and ``ρ̄`` the ``wV·wI``-weighted median of the measurements
  (per colour channel).

Samples with θi or θo above 89° and invalid measurements are excluded (§4.1). Options switch
``wC`` off (Fig. 7) and restrict the angular range to θh, θd, θi, θo ≤ a bound (Fig. 15).

Deliberate deviation: ``wV`` is evaluated at the centre of the grid cell each MERL sample
represents under MERL's floor lookup (θ'h ∈ [i, i+1)/90, θd ∈ [j, j+1)·π/180,
φd ∈ [k, k+1)·π/180) and multiplied by the cell's parameter volume. Evaluated at the sample
itself, Eq. 9 is exactly zero on the whole θh = 0 and θd = 0 rows, which would leave the
factor components D₀ and F₀ without any equation in the AWLS updates (Eq. 14).

This module is also the objective "as a function of two BRDFs" for the metrics code:
:func:`compressive_objective` and :func:`weighted_mean_relative_error`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import asdict, dataclass

import numpy as np

from ..errors import FitError
from ..grid import (N_PHI_D, N_THETA_D, N_THETA_H, merl_phi_d, merl_theta_d, merl_theta_h,
                    tabulate_merl_grid)

__all__ = [
    "ObjectiveOptions", "ObjectiveData", "merl_grid_geometry", "volume_form_weight",
    "compressive_weight", "weighted_median", "prepare_objective", "objective_from_values",
    "compressive_objective", "weighted_mean_relative_error",
]


@dataclass(frozen=True)
class ObjectiveOptions:
    """Options of the objective (Bagher et al. 2016, §4.1).

    p, alpha:
        Power and compression of ``wC`` (Eq. 11-12); the paper always uses 1.4 and log 2.
    compressive:
        ``False`` drops ``wC`` (plain ``wV·wI``-weighted least squares, Fig. 7 bottom row).
    max_theta_io_deg:
        Samples with θi or θo strictly above this are excluded (89° in the paper).
    restrict_deg:
        If set, also exclude samples with θh, θd, θi or θo above it (Fig. 15 uses 80°).
    """

    p: float = 1.4
    alpha: float = math.log(2.0)
    compressive: bool = True
    max_theta_io_deg: float = 89.0
    restrict_deg: float | None = None

    def to_dict(self) -> dict:
        return asdict(self)


def merl_grid_geometry() -> dict[str, np.ndarray]:
    """Per-sample geometry of the 90×90×180 MERL grid.

    Returns ``theta_h, theta_d, phi_d, cos_i, cos_o`` (each ``(90, 90, 180)``), with the
    cosines from Eq. 1-2 (in the convention of :func:`brdffit.geometry.half_diff_to_io`,
    which swaps the roles of i and o with respect to the paper's Eq. 1-2; the model and the
    weights are symmetric in i and o so this does not matter), and ``w_volume``: Eq. 9 at the
    cell centres times the cell volume (see the module docstring). The arrays are computed
    once per process and read-only.
    """
    return dict(_merl_grid_geometry())


@functools.lru_cache(maxsize=1)
def _merl_grid_geometry() -> dict[str, np.ndarray]:
    th, td, pd = np.meshgrid(merl_theta_h(), merl_theta_d(), merl_phi_d(), indexing="ij")
    # the sines and cosines per axis, broadcast (the same values as on the full grid)
    h, d, p = merl_theta_h()[:, None, None], merl_theta_d()[None, :, None], merl_phi_d()
    ch, sh, cd, sd, cp = np.cos(h), np.sin(h), np.cos(d), np.sin(d), np.cos(p)
    cos_i = ch * cd - sh * sd * cp
    cos_o = ch * cd + sh * sd * cp
    geo = {"theta_h": th, "theta_d": td, "phi_d": pd, "cos_i": cos_i, "cos_o": cos_o,
           "w_volume": volume_form_weight()}
    for a in geo.values():
        a.setflags(write=False)
    return geo


def volume_form_weight() -> np.ndarray:
    """Eq. 9 integrated over each MERL cell (midpoint rule), shape ``(90, 90, 180)``.

    ``sqrt(8 sin²θd (cos²θd + sin²θd cos²φd)) · (dθh/dθ'h) · Δθ'h Δθd Δφd`` with
    ``θh = θ'h² π/2`` so ``dθh/dθ'h = π θ'h`` (θ'h normalised to [0, 1]).
    """
    tp = (np.arange(N_THETA_H) + 0.5) / N_THETA_H           # θ'h at cell centres, in [0, 1]
    td = (np.arange(N_THETA_D) + 0.5) * (np.pi / 2 / N_THETA_D)
    pd = (np.arange(N_PHI_D) + 0.5) * (np.pi / N_PHI_D)
    dth = np.pi * tp / N_THETA_H                              # dθh = π θ'h dθ'h, dθ'h = 1/90
    sd, cd = np.sin(td)[:, None], np.cos(td)[:, None]
    ang = np.sqrt(8.0 * sd**2 * (cd**2 + sd**2 * np.cos(pd)[None, :] ** 2))   # (90, 180)
    cell = (np.pi / 2 / N_THETA_D) * (np.pi / N_PHI_D)
    return dth[:, None, None] * ang[None, :, :] * cell


def compressive_weight(rho, rho_bar, p: float = 1.4, alpha: float = math.log(2.0)) -> np.ndarray:
    """``wC = (f(x; α)/x)^p`` with ``x = ρ*/ρ̄`` and ``f(x; α) = (1 − e^{−αx})/α`` (Eq. 11-12).

    Equals 1 at ``x = 0`` and decreases monotonically to 0; negative ``ρ*`` are treated as 0.
    """
    ax = np.atleast_1d(np.maximum(np.asarray(rho, dtype=np.float64), 0.0) / rho_bar)
    ax *= alpha
    small = ax <= 1e-12                        # f(x)/x → 1 − αx/2 (its series) near 0
    ratio = np.negative(ax)                    # in place from here: a table's (3, 1.2 M)
    np.expm1(ratio, out=ratio)                 # temporaries cost more than the arithmetic
    np.negative(ratio, out=ratio)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio /= ax
    ratio[small] = 1.0 - 0.5 * ax[small]
    np.power(ratio, p, out=ratio)
    return ratio if np.ndim(rho) or np.ndim(rho_bar) else ratio[0]


#: below this many values :func:`weighted_median` sorts what is left
_MEDIAN_SORT_BELOW = 1 << 12
#: :func:`weighted_median`'s bracket: from every this-many-th value, the values at these
#: shares of the subsample's weight
_MEDIAN_STRIDE = 64
_MEDIAN_BRACKET = (0.4, 0.6)


def weighted_median(values, weights) -> float:
    """Weighted median: the smallest value ``x`` whose cumulative weight ``Σ_{v ≤ x} w``
    reaches half the total (weights ≥ 0).

    By selection, in O(n) (a MERL table's 1.2 M samples in ≈ 10 ms, where a sort takes
    ≈ 170 ms): a bracket read off a strided subsample usually holds the answer (it is
    checked: one pass over the values), and then only the values within it are searched;
    there, the median of what is left (``np.partition``) splits the values into those
    below, equal to and above it, and the part whose weight holds the target is kept.
    Sums of different orders round differently: where the cumulative weight lands within
    rounding of half the total, the value returned may be the neighbouring one."""
    v = np.asarray(values, dtype=np.float64).ravel()
    w = np.asarray(weights, dtype=np.float64).ravel()
    if v.size == 0 or not np.any(w > 0):
        raise FitError("weighted median of an empty set (no sample with positive weight)")
    target = 0.5 * w.sum()
    if v.size > 16 * _MEDIAN_SORT_BELOW:
        v, w, target = _within_bracket(v, w, target)
    while v.size > _MEDIAN_SORT_BELOW:
        pivot = np.partition(v, v.size // 2)[v.size // 2]
        below = v < pivot
        w_below = w[below].sum()
        if w_below >= target:
            v, w = v[below], w[below]
            continue
        above = v > pivot
        w_at = w.sum() - w_below - w[above].sum()
        if w_below + w_at >= target:
            return float(pivot)
        target -= w_below + w_at
        v, w = v[above], w[above]
    order = np.argsort(v, kind="quicksort")
    cw = np.cumsum(w[order])
    k = int(np.searchsorted(cw, target))
    return float(v[order][min(k, v.size - 1)])


def _within_bracket(v, w, target):
    """``(v, w, target)`` of :func:`weighted_median` narrowed to the values in ``[lo, hi]``,
    the subsample's values at :data:`_MEDIAN_BRACKET` of its weight, when the weight below
    ``lo`` is under ``target`` and the weight up to ``hi`` reaches it (the answer is then in
    the bracket, at the target less the weight below); else unchanged."""
    sv, sw = v[::_MEDIAN_STRIDE], w[::_MEDIAN_STRIDE]
    order = np.argsort(sv, kind="quicksort")
    cw = np.cumsum(sw[order])
    if cw[-1] <= 0:
        return v, w, target
    at = np.searchsorted(cw, np.array(_MEDIAN_BRACKET) * cw[-1])
    lo, hi = sv[order][np.minimum(at, sv.size - 1)]
    below = v < lo
    inside = ~below & (v <= hi)
    w_below = np.sum(w, where=below)
    if w_below < target <= w_below + np.sum(w, where=inside):
        return v[inside], w[inside], target - w_below
    return v, w, target


@dataclass
class ObjectiveData:
    """The included samples of one measured table and their weights.

    ``mask`` ``(90, 90, 180)`` marks included samples; ``index`` their flat grid indices (in
    C order); ``w`` and ``z`` ``(3, N)`` the per-channel weights ``wV wI wC`` and
    measurements; ``rho_bar`` ``(3,)`` the weighted medians; ``cos_i``, ``cos_o`` ``(N,)``.
    """

    mask: np.ndarray
    index: np.ndarray
    w: np.ndarray
    z: np.ndarray
    rho_bar: np.ndarray
    cos_i: np.ndarray
    cos_o: np.ndarray
    options: ObjectiveOptions

    @property
    def n_samples(self) -> int:
        return int(self.index.size)

    def value(self, model_values) -> np.ndarray:
        """Per-channel ``E`` (Eq. 7) of model values on the grid ``(90, 90, 180, 3)``
        (or already gathered on the included samples, ``(3, N)``)."""
        mv = np.asarray(model_values, dtype=np.float64)
        if mv.shape == self.z.shape:
            r = mv - self.z
        else:
            r = mv.reshape(-1, 3)[self.index].T - self.z
        return np.einsum("cn,cn->c", self.w, r * r)

    def reference_energy(self) -> np.ndarray:
        """``Σ w ρ*²`` per channel (the objective of the all-zero model), for normalising."""
        return np.einsum("cn,cn->c", self.w, self.z * self.z)


#: the objectives prepared for read-only tables, ``(values, valid, options, data)``, newest
#: last (:func:`prepare_objective`)
_PREPARED: list[tuple] = []
_PREPARED_KEPT = 2


def prepare_objective(values, valid=None, options: ObjectiveOptions | None = None,
                      source: str | None = None) -> ObjectiveData:
    """Select the samples and compute the weights of Eq. 8 for a MERL-grid table.

    ``values`` ``(90, 90, 180, 3)`` (``ρ*``), ``valid`` ``(90, 90, 180)`` bool (default:
    finite and non-negative). Raises :class:`FitError` when no sample remains.

    A read-only table (a memoised tabulation, :func:`brdffit.grid.tabulate_merl_grid`: the
    fits and metrics of one material share it) is prepared once per options and returned
    read-only to later callers; the last :data:`_PREPARED_KEPT` are kept.
    """
    opts = options or ObjectiveOptions()
    values = np.asarray(values, dtype=np.float64)
    valid = None if valid is None else np.asarray(valid, dtype=bool)
    if values.flags.writeable or (valid is not None and valid.flags.writeable):
        return _prepare_objective(values, valid, opts, source)
    for v, m, o, data in _PREPARED:
        if v is values and m is valid and o == opts:
            return data
    data = _prepare_objective(values, valid, opts, source)
    for a in (data.mask, data.index, data.w, data.z, data.rho_bar, data.cos_i, data.cos_o):
        a.setflags(write=False)
    _PREPARED.append((values, valid, opts, data))
    del _PREPARED[:-_PREPARED_KEPT]
    return data


def _prepare_objective(values: np.ndarray, valid, opts: ObjectiveOptions,
                       source: str | None) -> ObjectiveData:
    if values.shape != (N_THETA_H, N_THETA_D, N_PHI_D, 3):
        raise FitError(f"{source or 'input'}: expected a MERL-grid table of shape "
                       f"(90, 90, 180, 3), found {values.shape}")
    finite = np.isfinite(values)
    finite = True if finite.all() else finite.all(axis=-1)     # the reduction only when needed
    if valid is None:
        valid = finite & np.all(values >= 0, axis=-1)
    valid = np.asarray(valid, dtype=bool) & finite
    geo = merl_grid_geometry()
    lim = math.cos(math.radians(opts.max_theta_io_deg))
    mask = valid & (geo["cos_i"] >= lim - 1e-12) & (geo["cos_o"] >= lim - 1e-12)
    if opts.restrict_deg is not None:
        r = math.radians(opts.restrict_deg)
        cr = math.cos(r)
        mask &= (geo["theta_h"] <= r + 1e-12) & (geo["theta_d"] <= r + 1e-12)
        mask &= (geo["cos_i"] >= cr - 1e-12) & (geo["cos_o"] >= cr - 1e-12)
    index = np.flatnonzero(mask.ravel())
    if index.size == 0:
        raise FitError(f"{source or 'input'}: expected valid MERL samples with θi, θo ≤ "
                       f"{opts.max_theta_io_deg}°, found none")
    z = np.maximum(values.reshape(-1, 3)[index].T, 0.0)          # (3, N)
    cos_i = geo["cos_i"].ravel()[index]
    cos_o = geo["cos_o"].ravel()[index]
    wvi = geo["w_volume"].ravel()[index] * cos_i * cos_o
    rho_bar = np.array([weighted_median(z[c], wvi) for c in range(3)])
    if opts.compressive:
        # a channel whose median is 0 (e.g. black): fall back to its weighted mean
        mean = (z * wvi).sum(axis=1) / wvi.sum()
        rho_bar = np.where(rho_bar > 0, rho_bar, np.where(mean > 0, mean, 1.0))
        w = compressive_weight(z, rho_bar[:, None], opts.p, opts.alpha)
        w *= wvi
    else:
        w = np.broadcast_to(wvi, z.shape).copy()
    return ObjectiveData(mask=mask, index=index, w=w, z=z, rho_bar=rho_bar,
                         cos_i=cos_i, cos_o=cos_o, options=opts)


def objective_from_values(model_values, values, valid=None,
                          options: ObjectiveOptions | None = None) -> dict:
    """Objective of a model tabulated on the MERL grid against a measured table."""
    data = prepare_objective(values, valid, options)
    e = data.value(model_values)
    ref = data.reference_energy()
    return {"objective": float(e.sum()), "per_channel": e.tolist(),
            "normalised": float(e.sum() / ref.sum()), "n_samples": data.n_samples,
            "rho_bar": data.rho_bar.tolist(), "options": data.options.to_dict()}


def compressive_objective(fit, reference, options: ObjectiveOptions | None = None) -> dict:
    """Eq. 7 for a fitted BRDF against a reference BRDF, both tabulated on the MERL grid.

    Weights (and the median ρ̄) come from the reference. Returns ``objective`` (sum over
    channels), ``per_channel``, ``normalised`` (divided by ``Σ w ρ*²``, i.e. relative to the
    all-zero model) and ``n_samples``.
    """
    ref_values, ref_valid = tabulate_merl_grid(reference)
    fit_values, _ = tabulate_merl_grid(fit)
    return objective_from_values(fit_values, ref_values, ref_valid, options)


def weighted_mean_relative_error(fit, reference, eps_fraction: float = 0.01,
                                   max_theta_io_deg: float = 89.0) -> dict:
    """Cosine-weighted mean relative error on the MERL grid.

    ``Σ wV wI |ρ − ρ*| / (ρ* + ε) / Σ wV wI`` per channel, with ``wV``, ``wI`` of Eq. 9-10
    (no compressive weight) and ``ε = eps_fraction · ρ̄`` (ρ̄ the weighted median, so that
    near-zero measurements do not dominate). Over the same samples as the objective.
    Unlike Eq. 7 without ``wC`` (an absolute error dominated by the specular peak), this
    measures the relative error over the whole BRDF, which is what rendering under
    broad lighting is sensitive to.
    """
    ref_values, ref_valid = tabulate_merl_grid(reference)
    fit_values, _ = tabulate_merl_grid(fit)
    return relative_error_from_values(fit_values, ref_values, ref_valid, eps_fraction,
                                      max_theta_io_deg)


def relative_error_from_values(fit_values, values, valid=None, eps_fraction: float = 0.01,
                               max_theta_io_deg: float = 89.0) -> dict:
    """:func:`weighted_mean_relative_error` on tables already on the MERL grid."""
    data = prepare_objective(values, valid, ObjectiveOptions(compressive=False,
                                                             max_theta_io_deg=max_theta_io_deg))
    f = np.asarray(fit_values, dtype=np.float64).reshape(-1, 3)[data.index].T
    w = data.w[0]
    eps = eps_fraction * data.rho_bar[:, None]
    rel = np.abs(f - data.z) / (data.z + eps)
    per = (rel * w).sum(axis=1) / w.sum()
    return {"relative_error": float(per.mean()), "per_channel": per.tolist()}


__all__.append("relative_error_from_values")
