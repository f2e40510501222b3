"""Normalised L2 error between two BRDFs (Bagher, Soler, Holzschuch 2012 §6.3, after NDM05).

    E = ( ∫∫ (m(i, o) − ρ(i, o))² cos θi cos θo dωi dωo )^{1/2}          (§6.3)

normalised by the maximum albedo ``max_θi ∫ m(i, o) cos θo dωo`` of the *reference* ``m``
("to ensure a fair comparison between bright and dark materials"). Computed per colour
channel; the scalar returned by :func:`normalized_l2` is the root-mean-square over the three
channels of ``E_c / A_c`` (``A_c`` = max albedo of channel c). The paper does not say how
it combines channels; this choice is documented in the result.

Quadrature (deterministic):

* ``"grid"`` (default, isotropic BRDFs): the MERL grid (``brdffit.grid``), 90 θh × 90 θd ×
  180 φd nodes (φd subsampled by ``phi_stride``). With the Rusinkiewicz measure
  ``dωi dωo = 4 cos θd dωh dωd`` and isotropy (∫dφh = 2π, φd ≡ φd + π by reciprocity)
  each node gets the exact measure of the cell centred on it (in the sqrt-mapped θh index,
  in θd and in φd: a midpoint rule),
  ``2π · 2Δφ · 4 · (cos θh_a − cos θh_b) · (sin²θd_b − sin²θd_a)/2``, times
  ``cos θi cos θo`` at the node (Σ w = π² to 0.02 %). Invalid samples of a measured table and samples outside
  the reference's measured domain (validity mask of :func:`brdffit.grid.tabulate_merl_grid`)
  are left out.
* ``"mc"``: ``n`` Sobol (scrambled with a fixed seed) pairs of cosine-distributed
  directions, ``E² = π² mean((m − ρ)²)`` over the pairs in the measured domain; works for
  anisotropic BRDFs too.

Option ``theta_max`` restricts the integral to ``θi, θo ≤ theta_max``: the Cook-Torrance
form of Eq. 1 grows like ``1/(cos θi cos θo)`` at grazing angles, and with a reference that
has no invalid grazing samples (Neural-BRDF networks, which are also least faithful there)
the full-domain error of sharp specular fits is dominated by the last degree before the
horizon. (Default: the full domain, as in the paper.)

The albedo uses :meth:`brdffit.brdf.BRDF.albedo` (stratified, fixed seed) at θi = 0°, 10°,
…, 80°.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..brdf import cosine_hemisphere_sample, measured_mask
from ..grid import (N_PHI_D, N_THETA_D, N_THETA_H, merl_node_values, merl_phi_d, merl_theta_d,
                    merl_theta_h, tabulate_merl_grid)
from ..geometry import half_diff_to_io

__all__ = ["normalized_l2", "L2Reference", "L2Result", "merl_grid_weights"]

_ALBEDO_THETA = np.radians(np.arange(0.0, 81.0, 10.0))


def merl_grid_weights(phi_stride: int = 1, theta_max: float | None = None
                      ) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
    """Quadrature weights of ``∫∫ f cos θi cos θo dωi dωo`` on the MERL grid.

    Returns ``(w, (θh, θd, φd))`` with ``w`` of shape ``(90, 90, 180 // phi_stride)``
    (node coordinates broadcastable to it). ``Σ w f`` approximates the integral for
    isotropic, reciprocal ``f``; ``Σ w ≈ π²``. ``theta_max`` (radians) restricts the domain
    to ``θi, θo ≤ theta_max`` (weights 0 elsewhere).
    """
    th = merl_theta_h()
    # cells centred on the nodes in the sqrt-mapped index (midpoint rule, 2nd order)
    u_edges = np.clip((np.arange(N_THETA_H + 1) - 0.5) / N_THETA_H, 0.0, None)
    u_edges[-1] = 1.0
    th_edges = u_edges**2 * (np.pi / 2)
    wh = np.cos(th_edges[:-1]) - np.cos(th_edges[1:])              # ∫ sin θh dθh over cell
    td = merl_theta_d()
    step = np.pi / 2 / N_THETA_D
    td_edges = np.clip((np.arange(N_THETA_D + 1) - 0.5) * step, 0.0, None)
    td_edges[-1] = np.pi / 2
    wd = 0.5 * (np.sin(td_edges[1:]) ** 2 - np.sin(td_edges[:-1]) ** 2)   # ∫ cos sin dθd
    pd = merl_phi_d()[::phi_stride]
    dphi = np.pi / N_PHI_D * phi_stride
    TH, TD, PD = np.meshgrid(th, td, pd, indexing="ij")
    wi, wo = half_diff_to_io(TH, 0.0, TD, PD)
    cc = np.clip(wi[..., 2], 0.0, None) * np.clip(wo[..., 2], 0.0, None)
    if theta_max is not None:
        cmin = np.cos(theta_max)
        cc = np.where((wi[..., 2] >= cmin) & (wo[..., 2] >= cmin), cc, 0.0)
    w = (2.0 * np.pi) * (2.0 * dphi) * 4.0 * wh[:, None, None] * wd[None, :, None] * cc
    return w, (th[:, None, None], td[None, :, None], pd[None, None, :])


@dataclasses.dataclass
class L2Result:
    """Outcome of :func:`normalized_l2`."""

    value: float                 # RMS over channels of E_c / A_c
    per_channel: np.ndarray      # E_c / A_c
    unnormalized: np.ndarray     # E_c
    max_albedo: np.ndarray       # A_c
    method: str
    combine: str = "rms over RGB of per-channel E/A"

    def __float__(self) -> float:
        return float(self.value)


def _grid_values(brdf, phi_stride: int) -> tuple[np.ndarray, np.ndarray]:
    table = getattr(brdf, "merl_table", None)
    if table is not None or phi_stride == 1:
        vals, valid = tabulate_merl_grid(brdf)
        return vals[:, :, ::phi_stride], valid[:, :, ::phi_stride]
    th = merl_theta_h()
    td = merl_theta_d()
    pd = merl_phi_d()[::phi_stride]
    TH, TD, PD = np.meshgrid(th, td, pd, indexing="ij")
    vals, valid = merl_node_values(brdf, slice(None), slice(None), slice(None, None, phi_stride))
    return vals, valid & np.all(np.isfinite(vals), axis=-1) & np.all(vals >= 0, axis=-1)


class L2Reference:
    """A reference BRDF prepared once (grid values or MC samples and max albedo).

    ``L2Reference(ref).error(fit)`` equals ``normalized_l2(ref, fit)`` but evaluates the
    reference only once when comparing several fits.
    """

    def __init__(self, ref, method: str = "grid", *, phi_stride: int = 2, n: int = 1 << 18,
                 seed: int = 0, albedo_samples: int = 16384, theta_max: float | None = None):
        if method not in ("grid", "mc"):
            raise ValueError(f"method must be 'grid' or 'mc', found {method!r}")
        if method == "grid" and not getattr(ref, "isotropic", False):
            raise ValueError("the 'grid' quadrature needs an isotropic reference; use method='mc'")
        self.ref = ref
        self.method = method
        self.phi_stride = int(phi_stride)
        alb = np.asarray(ref.albedo(_ALBEDO_THETA, n_samples=albedo_samples, seed=seed))
        self.max_albedo = np.max(alb, axis=0)
        if method == "grid":
            self.weights, _ = merl_grid_weights(self.phi_stride, theta_max)
            self.values, self.valid = _grid_values(ref, self.phi_stride)
        else:
            from scipy.stats import qmc

            u = qmc.Sobol(d=4, scramble=True, seed=seed).random(n)
            self.wi = cosine_hemisphere_sample(u[:, :2])
            self.wo = cosine_hemisphere_sample(u[:, 2:])
            self.values = np.asarray(ref.eval(self.wi, self.wo), dtype=np.float64)
            self.valid = np.all(np.isfinite(self.values), axis=-1)
            measured = measured_mask(ref, self.wi, self.wo)
            if measured is not None:
                self.valid &= measured
            if theta_max is not None:
                cmin = np.cos(theta_max)
                self.valid &= (self.wi[:, 2] >= cmin) & (self.wo[:, 2] >= cmin)

    def error(self, fit) -> L2Result:
        """Normalised L2 error of ``fit`` against the reference."""
        return self.errors(fit)[0]

    def errors(self, fit, theta_max=(), grid_values=None) -> list[L2Result]:
        """``[error over the reference's domain] + [error over θi, θo ≤ t for t in theta_max]``
        with one evaluation of ``fit`` (grid method only for ``theta_max``);
        ``grid_values``: ``fit`` at this reference's grid nodes (``(90, 90, 180/phi_stride,
        3)``), when already evaluated."""
        if self.method == "grid":
            fv = _grid_values(fit, self.phi_stride)[0] if grid_values is None else grid_values
            ok = self.valid & np.all(np.isfinite(fv), axis=-1)
            diff2 = np.where(ok[..., None], (np.where(ok[..., None], self.values, 0.0)
                                              - np.where(ok[..., None], fv, 0.0)) ** 2, 0.0)
            out = []
            for w in [self.weights] + [merl_grid_weights(self.phi_stride, t)[0]
                                       for t in theta_max]:
                out.append(self._result(np.einsum("ijk,ijkc->c", w, diff2)))
            return out
        if theta_max:
            raise ValueError("errors(theta_max=...) needs the 'grid' method")
        fv = np.asarray(fit.eval(self.wi, self.wo), dtype=np.float64)
        ok = self.valid & np.all(np.isfinite(fv), axis=-1)
        diff2 = np.where(ok[..., None], (np.where(ok[..., None], self.values, 0.0)
                                          - np.where(ok[..., None], fv, 0.0)) ** 2, 0.0)
        return [self._result(np.pi**2 * diff2.sum(axis=0) / len(ok))]

    def _result(self, e2) -> L2Result:
        e = np.sqrt(e2)
        a = np.where(self.max_albedo > 0, self.max_albedo, np.nan)
        per = e / a
        value = float(np.sqrt(np.nanmean(per**2))) if np.any(np.isfinite(per)) else float("nan")
        return L2Result(value=value, per_channel=per, unnormalized=e,
                        max_albedo=self.max_albedo.copy(), method=self.method)


def normalized_l2(ref, fit, method: str = "grid", **kwargs) -> float:
    """Normalised L2 error of Bagher 2012 §6.3 between BRDFs ``ref`` (measured) and ``fit``.

    See the module docstring for the quadrature and the channel combination; keyword
    arguments go to :class:`L2Reference` (``phi_stride``, ``n``, ``seed``). Use
    :class:`L2Reference` directly for the per-channel values or several fits.
    """
    return L2Reference(ref, method, **kwargs).error(fit).value
