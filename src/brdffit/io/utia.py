"""UTIA anisotropic BRDF tables (Filip & Vávra 2014, *Template-Based Sampling of Anisotropic
BRDFs*, Pacific Graphics 2014): read, write, interpolated lookup.

File layout (``.bin``, no header): ``48 φv × 6 θv × 48 φi × 6 θi × 3`` float64 in Fortran
order, i.e. in C terms ``[channel][θi][φi][θv][φv]`` with φv varying fastest. This matches
the UTIA reference loader (J. Filip's ``TBDRF.cpp`` and its Python port), which indexes
``channel·nr·nc + nc·(npi·iθi + iφi) + npv·iθv + iφv``. ``i`` is the **illumination** (light)
direction and ``v`` the **view** direction; in brdffit's protocol ``wi`` = illumination and
``wo`` = view. θ is sampled at 0:15:75°, φ at 0:7.5:352.5°, both azimuths in the frame of the
sample (specular reflection at φv = φi + 180°).

Values are passed through unchanged (the database stores BRDF values in its own linear RGB
units). Negative entries are treated as invalid samples, as in the MERL reader.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._atomic import atomic_write
from ..brdf import BRDF, _as_dirs
from ..errors import BRDFFormatError
from ._limits import check_plausible_float64, describe_exception, regular_file_size
from ..geometry import cartesian_to_spherical, spherical_to_cartesian
from .merl import _add_row, _gather_interp, _numba, _pack, _store_normalised

__all__ = ["UTIABRDF", "read_utia", "write_utia", "utia_theta", "utia_phi", "UTIA_SHAPE",
           "UTIA_FILE_SIZE"]

N_THETA, N_PHI = 6, 48
THETA_STEP = np.radians(15.0)
PHI_STEP = np.radians(7.5)
#: In-memory table shape: (θi, φi, θv, φv, RGB).
UTIA_SHAPE = (N_THETA, N_PHI, N_THETA, N_PHI, 3)
UTIA_FILE_SIZE = int(np.prod(UTIA_SHAPE)) * 8


def utia_theta() -> np.ndarray:
    """Elevations of the UTIA grid, 0:15:75° (radians)."""
    return np.arange(N_THETA) * THETA_STEP


def utia_phi() -> np.ndarray:
    """Azimuths of the UTIA grid, 0:7.5:352.5° (radians)."""
    return np.arange(N_PHI) * PHI_STEP


def _utia_kernel(table, ti, pi, tv, pv, out):  # pragma: no cover  (compiled by numba)
    nt, nph = 6, 48
    for s in range(ti.shape[0]):
        a = min(ti[s], nt - 1.0)
        b = pi[s]
        c = min(tv[s], nt - 1.0)
        d = pv[s]
        a0 = min(int(np.floor(a)), nt - 2)
        c0 = min(int(np.floor(c)), nt - 2)
        bf = np.floor(b)
        df = np.floor(d)
        fa = a - a0
        fb = b - bf
        fc = c - c0
        fd = d - df
        b0 = int(bf) % nph
        d0 = int(df) % nph
        acc0 = acc1 = acc2 = acc3 = 0.0
        for ka in range(2):
            wa = fa if ka == 1 else 1.0 - fa
            for kb in range(2):
                wb = fb if kb == 1 else 1.0 - fb
                ib = (b0 + kb) % nph
                for kc in range(2):
                    wc = fc if kc == 1 else 1.0 - fc
                    for kd in range(2):
                        wd = fd if kd == 1 else 1.0 - fd
                        idd = (d0 + kd) % nph
                        r = ((((a0 + ka) * nph + ib) * nt + (c0 + kc)) * nph) + idd
                        acc0, acc1, acc2, acc3 = _add_row(table, r, wa * wb * wc * wd,
                                                          acc0, acc1, acc2, acc3)
        _store_normalised(out, s, acc0, acc1, acc2, acc3)


if _numba is not None:
    _utia_kernel = _numba.njit(cache=True, nogil=True)(_utia_kernel)


def _utia_lookup_numpy(table, ti, pi, tv, pv):
    """NumPy reference of the quadrilinear lookup (same semantics as the compiled kernel)."""
    ti = np.minimum(ti, N_THETA - 1.0)
    tv = np.minimum(tv, N_THETA - 1.0)
    a0 = np.minimum(np.floor(ti), N_THETA - 2).astype(np.intp)
    c0 = np.minimum(np.floor(tv), N_THETA - 2).astype(np.intp)
    bf, df = np.floor(pi), np.floor(pv)
    fa, fb, fc, fd = ti - a0, pi - bf, tv - c0, pv - df
    b0 = bf.astype(np.intp) % N_PHI
    d0 = df.astype(np.intp) % N_PHI
    idx, wts = [], []
    for ka in (0, 1):
        wa = fa if ka else 1.0 - fa
        for kb in (0, 1):
            wb = fb if kb else 1.0 - fb
            ib = (b0 + kb) % N_PHI
            for kc in (0, 1):
                wc = fc if kc else 1.0 - fc
                for kd in (0, 1):
                    wd = fd if kd else 1.0 - fd
                    idx.append((((a0 + ka) * N_PHI + ib) * N_THETA + (c0 + kc)) * N_PHI
                               + (d0 + kd) % N_PHI)
                    wts.append(wa * wb * wc * wd)
    return _gather_interp(table, idx, wts)


class UTIABRDF(BRDF):
    """An anisotropic BRDF tabulated on the UTIA grid (Filip & Vávra 2014).

    ``values`` has shape ``(6 θi, 48 φi, 6 θv, 48 φv, 3)`` (illumination first, view second).

    Lookup: multilinear over the four angles in index space (θ/15°, φ/7.5°), φ periodic
    (period 360°), θ clamped to the grid: **above 75° the value at 75° is held constant** up
    to the horizon (the reference loader extrapolates linearly instead, which can go
    negative). Directions at or below the horizon give 0. Invalid (negative) samples are
    dropped from the interpolation and the remaining weights renormalised; 0 when none is
    valid.
    """

    format = "utia"
    isotropic = False
    measured_domain = "θi, θo ≤ 75° (the UTIA grid; beyond it the value at 75° is held)"

    def __init__(self, values, valid=None, *, name: str = "utia", source: str | None = None,
                 _raw: np.ndarray | None = None):
        values = np.asarray(values, dtype=np.float64)
        if values.shape != UTIA_SHAPE:
            raise BRDFFormatError(source, f"expected a UTIA table of shape {UTIA_SHAPE}, "
                                          f"found {values.shape}")
        ok = np.all(np.isfinite(values) & (values >= 0), axis=-1)
        valid = ok if valid is None else np.asarray(valid, dtype=bool)
        if valid.shape != UTIA_SHAPE[:-1]:
            raise BRDFFormatError(source, f"expected a validity mask of shape {UTIA_SHAPE[:-1]}, "
                                          f"found {valid.shape}")
        if (valid & ~ok).any():
            raise BRDFFormatError(source, "expected finite non-negative values at valid samples, "
                                          f"found {int((valid & ~ok).sum())} NaN/inf/negative")
        self._values = np.where(valid[..., None], values, 0.0)
        self._values.flags.writeable = False
        self._valid = valid.copy()
        self._valid.flags.writeable = False
        self._packed = _pack(self._values, self._valid)
        self._raw = _raw
        self.name = name
        self.source = source

    def utia_table(self) -> tuple[np.ndarray, np.ndarray]:
        """``(values (6, 48, 6, 48, 3), valid (6, 48, 6, 48))`` indexed (θi, φi, θv, φv)."""
        return self._values, self._valid

    @property
    def n_samples(self) -> int:
        return int(np.prod(UTIA_SHAPE[:-1]))

    @property
    def n_invalid(self) -> int:
        return int(self.n_samples - np.count_nonzero(self._valid))

    def eval_angles(self, theta_i, phi_i, theta_v, phi_v) -> np.ndarray:
        """Interpolated table value at angles (radians), ``(..., 3)``; θ ≥ 90° gives 0."""
        ti, pi, tv, pv = np.broadcast_arrays(*(np.asarray(a, np.float64)
                                               for a in (theta_i, phi_i, theta_v, phi_v)))
        shape = ti.shape
        above = (ti < np.pi / 2) & (tv < np.pi / 2)
        finite = np.isfinite(ti) & np.isfinite(pi) & np.isfinite(tv) & np.isfinite(pv)
        keep = (above & finite & (ti >= 0) & (tv >= 0)).ravel()
        u_ti = np.where(keep, ti.ravel(), 0.0) / THETA_STEP
        u_tv = np.where(keep, tv.ravel(), 0.0) / THETA_STEP
        u_pi = np.mod(np.where(keep, pi.ravel(), 0.0), 2 * np.pi) / PHI_STEP
        u_pv = np.mod(np.where(keep, pv.ravel(), 0.0), 2 * np.pi) / PHI_STEP
        if _numba is None:  # pragma: no cover
            out = _utia_lookup_numpy(self._packed, u_ti, u_pi, u_tv, u_pv)
        else:
            out = np.empty((u_ti.size, 3))
            _utia_kernel(self._packed, u_ti, u_pi, u_tv, u_pv, out)
        out[~keep] = 0.0
        return out.reshape(shape + (3,))

    def eval(self, wi, wo) -> np.ndarray:
        """f_r with ``wi`` the illumination and ``wo`` the view direction (local frame)."""
        wi, wo = _as_dirs(wi, wo)
        ti, pi = cartesian_to_spherical(wi)
        tv, pv = cartesian_to_spherical(wo)
        f = self.eval_angles(ti, pi, tv, pv)
        above = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        return np.where(above[..., None], f, 0.0)

    def measured(self, wi, wo) -> np.ndarray:
        """True for both elevations within the grid (θ ≤ 75°), above the horizon."""
        wi, wo = _as_dirs(wi, wo)
        lim = np.cos(utia_theta()[-1]) - 1e-9
        return (wi[..., 2] >= lim) & (wo[..., 2] >= lim) & (wi[..., 2] > 0) & (wo[..., 2] > 0)

    def describe(self) -> dict:
        d = super().describe()
        d.update(format="utia", n_samples=self.n_samples, n_invalid=self.n_invalid)
        return d


def read_utia(path) -> UTIABRDF:
    """Read a UTIA ``.bin`` file (raw float64, no header; see the module docstring).

    The size is checked before reading; NaN/inf, magnitudes above
    :data:`~brdffit.io._limits.MAX_ABS_VALUE` and subnormal values (a byte-swapped file: the
    format has no header to tell) raise :class:`~brdffit.errors.BRDFFormatError`.
    """
    path = Path(path)
    size = regular_file_size(path, "a UTIA .bin file")
    if size != UTIA_FILE_SIZE:
        what = "truncated file" if size < UTIA_FILE_SIZE else "trailing bytes"
        raise BRDFFormatError(path, f"expected {UTIA_FILE_SIZE} bytes (48x6x48x6x3 float64), "
                                    f"found {size} ({what})")
    try:
        raw = np.fromfile(path, dtype="<f8", count=UTIA_FILE_SIZE // 8)
    except OSError as exc:
        raise BRDFFormatError(path, f"expected a readable UTIA .bin file, found "
                                    f"{describe_exception(exc)}") from None
    if raw.size * 8 != UTIA_FILE_SIZE:
        raise BRDFFormatError(path, f"expected {UTIA_FILE_SIZE // 8} float64, found {raw.size}")
    check_plausible_float64(raw, path, "values")
    # C view [c][θi][φi][θv][φv] -> (θi, φi, θv, φv, c)
    values = np.moveaxis(raw.reshape(3, N_THETA, N_PHI, N_THETA, N_PHI), 0, -1)
    valid = np.all(values >= 0, axis=-1)
    raw.flags.writeable = False
    return UTIABRDF(values, valid, name=path.stem, source=str(path), _raw=raw)


def tabulate_utia_grid(brdf) -> tuple[np.ndarray, np.ndarray]:
    """Evaluate any BRDF at the UTIA grid: ``(values (6,48,6,48,3), valid (6,48,6,48))``.

    ``wi`` = illumination (θi, φi), ``wo`` = view (θv, φv).
    """
    table = getattr(brdf, "utia_table", None)
    if table is not None:
        return table()
    t, p = utia_theta(), utia_phi()
    ti, pi, tv, pv = np.meshgrid(t, p, t, p, indexing="ij")
    wi = spherical_to_cartesian(ti, pi)
    wo = spherical_to_cartesian(tv, pv)
    values = np.asarray(brdf.eval(wi, wo), dtype=np.float64)
    valid = np.all(np.isfinite(values) & (values >= 0), axis=-1)
    return np.where(valid[..., None], values, 0.0), valid


def write_utia(brdf, path) -> Path:
    """Tabulate ``brdf`` (any :class:`~brdffit.brdf.BRDF`, or a ``(values, valid)`` pair of
    shape ``(6, 48, 6, 48, 3)``) on the UTIA grid and write a ``.bin`` file atomically.

    Invalid samples are written as ``-1``. A :class:`UTIABRDF` read from a file is written
    back bit-exactly.
    """
    path = Path(path)
    raw = getattr(brdf, "_raw", None) if isinstance(brdf, UTIABRDF) else None
    if raw is None:
        if isinstance(brdf, tuple):
            values, valid = (np.asarray(a) for a in brdf)
        else:
            values, valid = tabulate_utia_grid(brdf)
        values = np.asarray(values, dtype=np.float64)
        if values.shape != UTIA_SHAPE or np.shape(valid) != UTIA_SHAPE[:-1]:
            raise BRDFFormatError(None, f"expected a UTIA table {UTIA_SHAPE}, found {values.shape}")
        valid = np.asarray(valid, bool)
        if (valid & ~np.all(np.isfinite(values) & (values >= 0), axis=-1)).any():
            raise BRDFFormatError(None, "expected finite non-negative values at valid samples, "
                                        "found NaN/inf/negative")
        raw = np.moveaxis(np.where(valid[..., None], values, -1.0), -1, 0)
    with atomic_write(path) as fh:
        fh.write(np.ascontiguousarray(raw, dtype="<f8").tobytes())
    return path


__all__.append("tabulate_utia_grid")
