"""Fresnel reflectance terms ``F(cos θd) -> RGB (..., 3)``.

All classes accept a scalar (broadcast to the three channels) or an RGB triple per
parameter, and are subclasses of :class:`brdffit.microfacet.base.Fresnel`.

* :class:`SchlickFresnel` – Schlick 1994: ``F = F0 + (1 − F0)(1 − cos θd)⁵``.
* :class:`GeneralizedSchlickFresnel` – Bagher, Soler & Holzschuch 2012 **Eq. 11**:
  ``F = F0 + (1 − F0)(1 − cos θd)⁵ − F1 cos θd`` (``F1 = 0`` gives Schlick; note that
  ``F(0°) = F0 − F1`` and ``F(90°) = 1``).
* :class:`DielectricFresnel` – exact unpolarised Fresnel of a dielectric interface with
  relative index η (Walter et al. 2007 Eq. 22), total internal reflection for η < 1.
* :class:`ConductorFresnel` – exact unpolarised Fresnel for a complex index ``η + i k``
  (average of |r_s|² and |r_p|² with ``cos θt = √(1 − sin²θ/(η + ik)²)``; Born & Wolf §14.2).
* :class:`TabulatedFresnel` – piecewise-linear in θd over a given grid (e.g. the Fresnel
  curves extracted by Dupuy 2015 §4.4 or Bagher 2016), clamped outside the grid.

Serialisation: ``params()`` gives JSON-able parameters (``cls(**params())`` rebuilds the
object); :class:`TabulatedFresnel` also has ``to_state``/``from_state`` for its tables. Each
class declares the ``state_schema`` a fit file must follow (:mod:`brdffit.schema`): Schlick
``f0`` and generalised-Schlick ``F0`` in [0, 1], ``|F1|`` ≤ ``F1_MAX``; indices ``eta`` in
(0, ``INDEX_MAX``], ``k`` in [0, ``INDEX_MAX``]; tables: a strictly increasing θd grid in
[0, π/2] of 2 to 8192 nodes and values in [0, ``FRESNEL_MAX``].
"""

from __future__ import annotations

import numpy as np

from ..schema import F1_MAX, FRESNEL_MAX, INDEX_MAX, RGB, Array, Integer, Schema
from .base import Fresnel

__all__ = ["SchlickFresnel", "GeneralizedSchlickFresnel", "DielectricFresnel",
           "ConductorFresnel", "TabulatedFresnel", "GOLD_ETA", "GOLD_K", "conductor_reflectance",
           "dielectric_reflectance"]

#: Approximate RGB complex index of gold (linear sRGB primaries), as commonly tabulated for
#: rendering (e.g. from Johnson & Christy 1972 spectral data reduced to RGB).
GOLD_ETA = (0.143119, 0.374957, 1.44248)
GOLD_K = (3.98316, 2.38572, 1.60322)


def _rgb(name: str, value, lo: float | None = None, hi: float | None = None,
         cls: str = "") -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        arr = np.full(3, float(arr))
    if arr.shape != (3,):
        raise ValueError(f"{cls}: {name} must be a scalar or an RGB triple, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{cls}: {name} must be finite, got {arr.tolist()}")
    if lo is not None and np.any(arr < lo):
        raise ValueError(f"{cls}: {name} must be >= {lo}, got {arr.tolist()}")
    if hi is not None and np.any(arr > hi):
        raise ValueError(f"{cls}: {name} must be <= {hi}, got {arr.tolist()}")
    return arr


def _cos(cos_theta_d) -> np.ndarray:
    return np.clip(np.asarray(cos_theta_d, dtype=np.float64), 0.0, 1.0)[..., None]


def _schlick(c, f0) -> np.ndarray:
    """``f0 + (1 − f0)(1 − c)⁵`` (Schlick 1994), ``c`` already clamped."""
    x = 1.0 - c
    x5 = x * x
    x5 *= x5
    x5 *= x
    return f0 + (1.0 - f0) * x5


class _RGBParameters(Fresnel):
    """A Fresnel given by the RGB arrays named in ``rgb_params``: its ``params()`` maps each
    name to its list, its repr shows each rounded to 4 decimals."""

    rgb_params: tuple[str, ...] = ()

    def params(self) -> dict:
        return {k: getattr(self, k).tolist() for k in self.rgb_params}

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={np.round(getattr(self, k), 4).tolist()}" for k in self.rgb_params)
        return f"{type(self).__name__}({args})"


class SchlickFresnel(_RGBParameters):
    """Schlick's approximation ``F0 + (1 − F0)(1 − cos θd)⁵`` (Schlick 1994)."""

    kind = "schlick"
    rgb_params = ("f0",)
    state_schema = Schema({"f0": RGB(ge=0, le=1)}, required=("f0",), strict=True)

    def __init__(self, f0):
        self.f0 = _rgb("f0", f0, 0.0, 1.0, "SchlickFresnel")

    def eval(self, cos_theta_d) -> np.ndarray:
        return _schlick(_cos(cos_theta_d), self.f0)

    def eval_channel(self, c: int, cos_theta_d) -> np.ndarray:
        return _schlick(_cos(cos_theta_d)[..., 0], self.f0[c])


class GeneralizedSchlickFresnel(_RGBParameters):
    """Bagher et al. 2012 Eq. 11: ``F0 + (1 − F0)(1 − cos θd)⁵ − F1 cos θd``.

    Values are returned as computed (they may leave [0, 1] for extreme ``F1``; a fit is
    expected to keep ``0 <= F1 <= F0``).
    """

    kind = "generalized_schlick"
    rgb_params = ("F0", "F1")
    state_schema = Schema({"F0": RGB(ge=0, le=1), "F1": RGB(ge=-F1_MAX, le=F1_MAX)},
                          required=("F0",), strict=True)

    def __init__(self, F0, F1=0.0):
        self.F0 = _rgb("F0", F0, cls="GeneralizedSchlickFresnel")
        self.F1 = _rgb("F1", F1, cls="GeneralizedSchlickFresnel")

    def eval(self, cos_theta_d) -> np.ndarray:
        c = _cos(cos_theta_d)
        return _schlick(c, self.F0) - self.F1 * c

    def eval_channel(self, c: int, cos_theta_d) -> np.ndarray:
        cos = _cos(cos_theta_d)[..., 0]
        return _schlick(cos, self.F0[c]) - self.F1[c] * cos


class DielectricFresnel(_RGBParameters):
    """Exact unpolarised dielectric Fresnel, relative index ``eta = n_t / n_i`` (> 0).

    ``F = ½ ((g − c)/(g + c))² (1 + ((c(g + c) − 1)/(c(g − c) + 1))²)`` with
    ``g² = η² − 1 + c²`` (Walter et al. 2007 Eq. 22); ``F = 1`` when ``g² < 0`` (TIR).
    """

    kind = "dielectric"
    rgb_params = ("eta",)
    state_schema = Schema({"eta": RGB(gt=0, le=INDEX_MAX)}, required=("eta",), strict=True)

    def __init__(self, eta):
        self.eta = _rgb("eta", eta, cls="DielectricFresnel")
        if np.any(self.eta <= 0):
            raise ValueError(f"DielectricFresnel: eta must be > 0, got {self.eta.tolist()}")

    def eval(self, cos_theta_d) -> np.ndarray:
        return dielectric_reflectance(_cos(cos_theta_d), self.eta)


def dielectric_reflectance(c, eta) -> np.ndarray:
    """Unpolarised Fresnel reflectance of a dielectric of relative index ``eta`` at
    ``cos θ = c`` (broadcast; ``c`` clamped to [0, 1] by the caller): Walter et al. 2007
    Eq. 22 (the formula of :class:`DielectricFresnel`), 1 under total internal reflection.

    >>> round(float(dielectric_reflectance(1.0, 1.5)), 4)
    0.04
    """
    c = np.asarray(c, dtype=np.float64)
    g2 = np.asarray(eta, dtype=np.float64)**2 - 1.0 + c * c
    tir = g2 < 0
    g = np.sqrt(np.where(tir, 0.0, g2))
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (g - c) / (g + c)
        b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
        F = 0.5 * a * a * (1.0 + b * b)
    F = np.where(np.isfinite(F), F, 1.0)          # c = 0 and η = 1 corner cases
    return np.where(tir, 1.0, np.clip(F, 0.0, 1.0))


def conductor_reflectance(c, eta, k) -> np.ndarray:
    """Unpolarised Fresnel reflectance of a conductor ``eta + i k`` at ``cos θ = c``
    (broadcast; ``c`` clamped to [0, 1] by the caller).

    Exact, in real arithmetic: with ``s² = 1 − c²``, ``t0 = η² − k² − s²``,
    ``a² + b² = √(t0² + 4η²k²)``, ``a = √((a² + b² + t0)/2)``:
    ``Rs = (a²+b² − 2ac + c²)/(a²+b² + 2ac + c²)``,
    ``Rp = Rs (c²(a²+b²) − 2acs² + s⁴)/(c²(a²+b²) + 2acs² + s⁴)`` (the classic closed form
    of |r_s|², |r_p|², e.g. Cook & Torrance 1982 / PBRT); ``F = (Rs + Rp)/2`` in [0, 1].

    >>> round(float(conductor_reflectance(1.0, 1.5, 0.0)), 4)      # dielectric, normal incidence
    0.04
    """
    c = np.asarray(c, dtype=np.float64)
    eta, k = np.asarray(eta, dtype=np.float64), np.asarray(k, dtype=np.float64)
    c2 = c * c
    s2 = 1.0 - c2
    eta2, k2 = eta**2, k**2
    t0 = eta2 - k2 - s2
    a2b2 = np.sqrt(t0 * t0 + 4.0 * eta2 * k2)
    a = np.sqrt(np.maximum(0.5 * (a2b2 + t0), 0.0))
    t1 = a2b2 + c2
    t2 = 2.0 * a * c
    with np.errstate(divide="ignore", invalid="ignore"):
        Rs = (t1 - t2) / (t1 + t2)
        t3 = c2 * a2b2 + s2 * s2
        t4 = t2 * s2
        Rp = Rs * (t3 - t4) / (t3 + t4)
    F = 0.5 * (Rs + Rp)
    return np.clip(np.where(np.isfinite(F), F, 1.0), 0.0, 1.0)


class ConductorFresnel(_RGBParameters):
    """Exact unpolarised Fresnel of a conductor with complex index ``eta + i k`` (RGB).

    ``r_s = (cos θ − n cos θt)/(cos θ + n cos θt)``, ``r_p = (n cos θ − cos θt)/(n cos θ + cos θt)``,
    ``n cos θt = √(n² − sin²θ)`` (principal branch), ``F = (|r_s|² + |r_p|²)/2``.
    With ``k = 0`` and ``eta > 1`` it equals :class:`DielectricFresnel`.
    """

    kind = "conductor"
    rgb_params = ("eta", "k")
    state_schema = Schema({"eta": RGB(gt=0, le=INDEX_MAX), "k": RGB(ge=0, le=INDEX_MAX)},
                          required=("eta", "k"), strict=True)

    def __init__(self, eta, k):
        self.eta = _rgb("eta", eta, cls="ConductorFresnel")
        self.k = _rgb("k", k, 0.0, cls="ConductorFresnel")
        if np.any(self.eta <= 0):
            raise ValueError(f"ConductorFresnel: eta must be > 0, got {self.eta.tolist()}")
        self._n = self.eta + 1j * self.k

    def eval(self, cos_theta_d) -> np.ndarray:
        """:func:`conductor_reflectance` of the RGB index, ``(..., 3)``."""
        return conductor_reflectance(_cos(cos_theta_d), self.eta, self.k)


class TabulatedFresnel(Fresnel):
    """Fresnel given at increasing ``theta_d_grid`` (radians, ``(N,)``) with RGB ``values``.

    Linear interpolation in θd, constant extrapolation outside the grid.
    """

    kind = "tabulated"
    state_schema = Schema(
        {"n": Integer(ge=2, le=8192)},
        arrays={"theta_d": Array(("n",), ge=0, le=np.pi / 2 + 1e-6, increasing=True),
                "values": Array([("n", 3), ("n",)], ge=0, le=FRESNEL_MAX)},
        dims={"n": (2, 8192)})

    def __init__(self, theta_d_grid, values):
        t = np.asarray(theta_d_grid, dtype=np.float64)
        v = np.asarray(values, dtype=np.float64)
        if t.ndim != 1 or t.size < 2:
            raise ValueError(f"TabulatedFresnel: expected a 1D θd grid with >= 2 entries, "
                             f"got shape {t.shape}")
        if v.ndim == 1:
            v = np.repeat(v[:, None], 3, axis=1)
        if v.shape != (t.size, 3):
            raise ValueError(f"TabulatedFresnel: expected values of shape ({t.size}, 3), "
                             f"got {v.shape}")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(v))):
            raise ValueError("TabulatedFresnel: grid and values must be finite")
        if np.any(np.diff(t) <= 0):
            raise ValueError("TabulatedFresnel: θd grid must be strictly increasing")
        self.theta_d = t
        self.values = v

    def eval(self, cos_theta_d) -> np.ndarray:
        td = np.arccos(np.clip(np.asarray(cos_theta_d, dtype=np.float64), 0.0, 1.0))
        flat = td.reshape(-1)
        out = np.stack([np.interp(flat, self.theta_d, self.values[:, ch]) for ch in range(3)], -1)
        return out.reshape(td.shape + (3,))

    def params(self) -> dict:
        return {"n": int(self.theta_d.size)}

    def to_state(self) -> tuple[dict, dict[str, np.ndarray]]:
        return {"n": int(self.theta_d.size)}, {"theta_d": self.theta_d, "values": self.values}

    @classmethod
    def from_state(cls, params: dict, arrays: dict[str, np.ndarray]) -> "TabulatedFresnel":
        return cls(arrays["theta_d"], arrays["values"])

    def __repr__(self) -> str:
        return f"TabulatedFresnel(n={self.theta_d.size})"
