"""MERL ``.binary`` BRDF tables (Matusik, Pfister, Brand, McMillan 2003): read, write, resample.

File layout (the MERL reference reader ``BRDFRead.cpp``): a header of three little-endian
int32 ``(90, 90, 180)`` = (n θh, n θd, n φd), then ``90·90·180·3`` float64, channel-major
(the whole R block, then G, then B). Inside a block the sample of indices
``(i_θh, i_θd, i_φd)`` sits at ``i_φd + 180·(i_θd + 90·i_θh)``. The stored numbers are
multiplied on read by the colour scales ``(1, 1.15, 1.66)/1500``; every value a
:class:`MERLBRDF` holds or returns is in these *scaled* "MERL units".

The grid (θh sampled uniformly in ``sqrt(θh/(π/2))``, φd folded into [0, π) by reciprocity)
is the one of :mod:`brdffit.grid`. Negative entries mark samples that were not measured (a
sample is invalid when any of its three channels is negative); they are kept as a validity
mask and never leak out of :meth:`MERLBRDF.eval_hd`. A table read from a file is scaled in
the buffer it was read into (one 35 MB array, not two: fresh memory is the dearest part of a
read); :func:`write_merl` writes it back bit-exactly by re-reading the file's own numbers when
they still give exactly this table.
"""

from __future__ import annotations

import copy
import os
from pathlib import Path

import numpy as np

from .._atomic import atomic_write
from ..brdf import IsotropicBRDF, _as_dirs
from ..errors import BRDFFormatError
from ._limits import check_plausible_float64, describe_exception, regular_file_size
from ..grid import (N_PHI_D, N_THETA_D, N_THETA_H, phi_d_to_index, tabulate_merl_grid,
                    theta_d_to_index, theta_h_to_index)
from ..geometry import io_to_half_diff

__all__ = ["MERLBRDF", "read_merl", "write_merl", "resample_to_merl", "MERL_SCALE",
           "MERL_SHAPE", "MERL_FILE_SIZE"]

#: Colour scales applied on read (MERL ``BRDFRead.cpp``: RED_SCALE, GREEN_SCALE, BLUE_SCALE).
MERL_SCALE = np.array([1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0])
MERL_SHAPE = (N_THETA_H, N_THETA_D, N_PHI_D)
_N = N_THETA_H * N_THETA_D * N_PHI_D
_HEADER_BYTES = 12
#: Exact size of a valid MERL file in bytes.
MERL_FILE_SIZE = _HEADER_BYTES + _N * 3 * 8
# Index snapping: a continuous index within this distance below an integer counts as that
# integer, so that grid angles computed in floating point land on their own sample.
_SNAP = 1e-7
_INTERPOLATIONS = ("trilinear", "nearest")


def _gather_interp(packed: np.ndarray, indices, weights) -> np.ndarray:
    """Weighted sum over table corners, renormalised over valid corners.

    ``packed`` is ``(N, C+1)``: the C channels already multiplied by validity, then the
    validity (0/1) itself. ``indices``/``weights`` are lists of equally shaped flat indices
    and weights (one per corner). Returns ``(..., C)``: ``Σ w·v·valid / Σ w·valid`` and 0
    where no corner with a positive weight is valid.
    """
    acc = None
    for idx, w in zip(indices, weights):
        term = packed[idx] * w[..., None]
        acc = term if acc is None else acc + term
    wsum = acc[..., -1:]
    ok = wsum > 1e-12
    return np.where(ok, acc[..., :-1] / np.where(ok, wsum, 1.0), 0.0)


# a compiled kernel makes the trilinear lookup ~10x faster; NumPy is the fall-back. Numba is
# imported on the first compiled call (brdffit._jit): reading a file does not need it.
from .._jit import lazy_numba

_numba = lazy_numba()


def _merl_trilinear_numpy(table, u, v, w):
    """Vectorised NumPy trilinear lookup (reference implementation, see :class:`MERLBRDF`)."""
    u = np.minimum(u, N_THETA_H - 1.0)
    v = np.minimum(v, N_THETA_D - 1.0)
    i0 = np.minimum(np.floor(u), N_THETA_H - 2).astype(np.intp)
    j0 = np.minimum(np.floor(v), N_THETA_D - 2).astype(np.intp)
    k0f = np.floor(w)
    fu, fv, fw = u - i0, v - j0, w - k0f
    k0 = k0f.astype(np.intp) % N_PHI_D
    k1 = (k0 + 1) % N_PHI_D
    idx, wts = [], []
    for di, wi_ in ((0, 1.0 - fu), (1, fu)):
        for dj, wj in ((0, 1.0 - fv), (1, fv)):
            base = N_PHI_D * ((j0 + dj) + N_THETA_D * (i0 + di))
            wij = wi_ * wj
            idx += [base + k0, base + k1]
            wts += [wij * (1.0 - fw), wij * fw]
    return _gather_interp(table, idx, wts)


def _add_row(table, r, wt, a0, a1, a2, a3):  # pragma: no cover  (compiled by numba)
    """The running sums of an interpolation plus ``wt`` times row ``r`` of a table whose
    columns are R, G, B and the weight of valid samples."""
    return (a0 + wt * table[r, 0], a1 + wt * table[r, 1], a2 + wt * table[r, 2],
            a3 + wt * table[r, 3])


def _store_normalised(out, s, a0, a1, a2, a3):  # pragma: no cover  (compiled by numba)
    """``out[s]`` = the interpolated RGB over the valid samples' weight (0 where none)."""
    if a3 > 1e-12:
        out[s, 0] = a0 / a3
        out[s, 1] = a1 / a3
        out[s, 2] = a2 / a3
    else:
        out[s, 0] = 0.0
        out[s, 1] = 0.0
        out[s, 2] = 0.0


if _numba is not None:
    _add_row = _numba.njit(cache=True, nogil=True, inline="always")(_add_row)
    _store_normalised = _numba.njit(cache=True, nogil=True, inline="always")(_store_normalised)


def _merl_trilinear_kernel(table, u, v, w, out):  # pragma: no cover  (compiled by numba)
    nh, nd, npd = 90, 90, 180
    for s in range(u.shape[0]):
        uu = min(u[s], nh - 1.0)
        vv = min(v[s], nd - 1.0)
        i0 = min(int(np.floor(uu)), nh - 2)
        j0 = min(int(np.floor(vv)), nd - 2)
        kf = np.floor(w[s])
        fu = uu - i0
        fv = vv - j0
        fw = w[s] - kf
        k0 = int(kf) % npd
        k1 = (k0 + 1) % npd
        a0 = a1 = a2 = a3 = 0.0
        for di in range(2):
            wi_ = fu if di == 1 else 1.0 - fu
            for dj in range(2):
                wj = fv if dj == 1 else 1.0 - fv
                base = npd * ((j0 + dj) + nd * (i0 + di))
                for dk in range(2):
                    wk = fw if dk == 1 else 1.0 - fw
                    r = base + (k1 if dk == 1 else k0)
                    a0, a1, a2, a3 = _add_row(table, r, wi_ * wj * wk, a0, a1, a2, a3)
        _store_normalised(out, s, a0, a1, a2, a3)


if _numba is not None:
    _merl_trilinear_kernel = _numba.njit(cache=True, nogil=True)(_merl_trilinear_kernel)


def _merl_trilinear(table, u, v, w):
    """Trilinear lookup on continuous MERL indices (compiled when numba is available and
    the work pays for loading it: :meth:`brdffit._jit.LazyDispatcher.worth_compiling`)."""
    if _numba is None or not _merl_trilinear_kernel.worth_compiling(np.size(u)):
        return _merl_trilinear_numpy(table, u, v, w)
    shape = u.shape
    out = np.empty((u.size, 3))
    _merl_trilinear_kernel(table, np.ascontiguousarray(u).ravel(),
                           np.ascontiguousarray(v).ravel(), np.ascontiguousarray(w).ravel(), out)
    return out.reshape(shape + (3,))


def _half_diff_kernel(wi, wo, th, td, pd):  # pragma: no cover  (compiled by numba)
    """Per-sample equivalent of :func:`brdffit.geometry.io_to_half_diff` (fewer trig calls)."""
    twopi = 2.0 * np.pi
    for s in range(wi.shape[0]):
        hx = wi[s, 0] + wo[s, 0]
        hy = wi[s, 1] + wo[s, 1]
        hz = wi[s, 2] + wo[s, 2]
        n = np.sqrt(hx * hx + hy * hy + hz * hz)
        if n < 1e-12:
            hx, hy, hz = 0.0, 0.0, 1.0
        else:
            hx, hy, hz = hx / n, hy / n, hz / n
        # rotations by -φh about z and -θh about y, with cos/sin taken from h itself
        st = np.sqrt(hx * hx + hy * hy)
        if st > 0:
            cp, sp = hx / st, hy / st
        else:
            cp, sp = 1.0, 0.0
        x = cp * wi[s, 0] + sp * wi[s, 1]
        y = -sp * wi[s, 0] + cp * wi[s, 1]
        z = wi[s, 2]
        theta_h = np.arccos(min(max(hz, -1.0), 1.0))
        ct, stt = min(max(hz, -1.0), 1.0), st
        dx = ct * x - stt * z
        dy = y
        dz = stt * x + ct * z
        n = np.sqrt(dx * dx + dy * dy + dz * dz)
        if n > 0:
            dx, dy, dz = dx / n, dy / n, dz / n
        th[s] = theta_h
        td[s] = np.arccos(min(max(dz, -1.0), 1.0))
        p = np.arctan2(dy, dx)
        pd[s] = p + twopi if p < 0 else p


if _numba is not None:
    _half_diff_kernel = _numba.njit(cache=True, nogil=True)(_half_diff_kernel)


def fast_half_diff(wi, wo):
    """``(θh, θd, φd, above)`` of direction pairs, as :func:`brdffit.geometry.io_to_half_diff`
    (compiled when numba is available and the work pays for loading it); ``above`` is
    ``wi_z > 0 and wo_z > 0``."""
    wi, wo = _as_dirs(wi, wo)
    shape = wi.shape[:-1]
    above = (wi[..., 2] > 0) & (wo[..., 2] > 0)
    if _numba is None or not _half_diff_kernel.worth_compiling(int(np.prod(shape))):
        th, _, td, pd = io_to_half_diff(wi, wo)
        return th, td, pd, above
    a = np.ascontiguousarray(wi).reshape(-1, 3)
    b = np.ascontiguousarray(wo).reshape(-1, 3)
    th, td, pd = (np.empty(a.shape[0]) for _ in range(3))
    _half_diff_kernel(a, b, th, td, pd)
    return th.reshape(shape), td.reshape(shape), pd.reshape(shape), above


def _nearest_sample(th, td, pd) -> np.ndarray:
    """Flat index of the stored sample MERL's own lookup reads at ``(θh, θd, φd)`` (finite
    angles): the floor of each continuous index (snapped up by ``_SNAP`` so that a node maps
    to itself), clamped to the table, φd periodic."""
    i = np.minimum(np.floor(theta_h_to_index(th) + _SNAP), N_THETA_H - 1).astype(np.intp)
    j = np.minimum(np.floor(theta_d_to_index(td) + _SNAP), N_THETA_D - 1).astype(np.intp)
    k = np.floor(phi_d_to_index(pd) + _SNAP).astype(np.intp) % N_PHI_D
    return k + N_PHI_D * (j + N_THETA_D * i)


def _pack(values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    flat_v = values.reshape(-1, values.shape[-1])
    flat_m = valid.reshape(-1)
    packed = np.empty((flat_v.shape[0], flat_v.shape[1] + 1))
    packed[:, :-1] = np.where(flat_m[:, None], flat_v, 0.0)
    packed[:, -1] = flat_m
    return packed


class MERLBRDF(IsotropicBRDF):
    """An isotropic BRDF tabulated on the MERL grid (Matusik et al. 2003).

    Parameters
    ----------
    values:
        ``(90, 90, 180, 3)`` BRDF values in scaled MERL units, indexed (θh, θd, φd, RGB).
    valid:
        ``(90, 90, 180)`` boolean mask of measured samples (default: every finite,
        non-negative sample).
    interpolation:
        ``"trilinear"`` (default) or ``"nearest"`` for :meth:`eval_hd`.

    Lookups
    -------
    ``"nearest"`` reproduces the MERL reference reader: each coordinate's continuous index
    (:func:`brdffit.grid.theta_h_to_index` etc.) is truncated, so a grid angle returns its own
    stored sample exactly (an invalid sample returns 0). ``"trilinear"`` interpolates
    linearly in (sqrt-θh index, θd index, φd index), samples sitting at integer indices,
    φd periodic with period π, θh and θd clamped to the first/last sample; the weights of
    invalid corners are dropped and the rest renormalised (0 when all eight are invalid).
    Deviation from MERL's reader: MERL returns the raw negative marker for an unmeasured
    sample; here it is never returned.
    """

    format = "merl"

    def __init__(self, values, valid=None, *, interpolation: str = "trilinear",
                 name: str = "merl", source: str | None = None, _file: Path | None = None,
                 _validated: bool = False):
        if _validated:              # read_merl: finite, ≥ 0 where valid, 0 elsewhere, shapes ok
            self._init_tables(values, valid)
            self._file, self._packed = _file, None
            self.interpolation, self.name, self.source = interpolation, name, source
            return
        values = np.asarray(values, dtype=np.float64)
        if values.shape != MERL_SHAPE + (3,):
            raise BRDFFormatError(source, f"expected a MERL table of shape {MERL_SHAPE + (3,)}, "
                                          f"found {values.shape}")
        finite = np.all(np.isfinite(values), axis=-1)
        if valid is None:
            valid = finite & np.all(values >= 0, axis=-1)
        valid = np.asarray(valid, dtype=bool)
        if valid.shape != MERL_SHAPE:
            raise BRDFFormatError(source, f"expected a validity mask of shape {MERL_SHAPE}, "
                                          f"found {valid.shape}")
        bad = valid & ~(finite & np.all(values >= 0, axis=-1))
        if bad.any():
            raise BRDFFormatError(source, f"expected finite non-negative values at valid samples, "
                                          f"found {int(bad.sum())} NaN/inf/negative")
        self._init_tables(np.where(valid[..., None], values, 0.0), valid.copy())
        self._file = _file
        self._packed = None
        self.interpolation = interpolation
        self.name = name
        self.source = source

    def _init_tables(self, values: np.ndarray, valid: np.ndarray) -> None:
        self._values, self._valid = values, valid
        self._values.flags.writeable = False
        self._valid.flags.writeable = False

    # -- table access ---------------------------------------------------------------------
    @property
    def interpolation(self) -> str:
        return self._interpolation

    @interpolation.setter
    def interpolation(self, mode: str) -> None:
        if mode not in _INTERPOLATIONS:
            raise ValueError(f"interpolation must be one of {_INTERPOLATIONS}, got {mode!r}")
        self._interpolation = mode

    def with_interpolation(self, mode: str) -> "MERLBRDF":
        """A view of the same table with another lookup mode (tables are shared)."""
        other = copy.copy(self)
        other.interpolation = mode
        return other

    def merl_table(self) -> tuple[np.ndarray, np.ndarray]:
        """``(values (90, 90, 180, 3), valid (90, 90, 180))``, read-only, in scaled MERL units.

        Invalid samples hold 0 in ``values``; use ``valid`` to exclude them.
        """
        return self._values, self._valid

    @property
    def n_samples(self) -> int:
        return _N

    @property
    def n_invalid(self) -> int:
        """Number of (θh, θd, φd) samples marked invalid (negative in the file)."""
        return int(_N - np.count_nonzero(self._valid))

    def _table(self) -> np.ndarray:
        if self._packed is None:
            self._packed = _pack(self._values, self._valid)
        return self._packed

    # -- evaluation -----------------------------------------------------------------------
    @property
    def measured_domain(self) -> str | None:
        """The samples not marked invalid, when some are (``None`` otherwise)."""
        n = self.n_invalid
        if n == 0:
            return None
        return f"the {_N - n} of {_N} table samples not marked invalid"

    def measured(self, wi, wo) -> np.ndarray:
        """True where the table sample nearest to ``(wi, wo)`` (MERL's own lookup) is valid,
        both directions above the horizon."""
        th, td, pd, above = fast_half_diff(wi, wo)
        return above & self.measured_hd(th, td, pd)

    def measured_hd(self, theta_h, theta_d, phi_d) -> np.ndarray:
        th, td, pd = np.broadcast_arrays(*(np.nan_to_num(np.asarray(a, np.float64))
                                           for a in (theta_h, theta_d, phi_d)))
        return self._valid.reshape(-1)[_nearest_sample(th, td, pd)]

    def eval(self, wi, wo) -> np.ndarray:
        """f_r(wi, wo) via the table lookup in Rusinkiewicz coordinates; 0 below the horizon."""
        th, td, pd, above = fast_half_diff(wi, wo)
        return np.where(above[..., None], self.eval_hd(th, td, pd), 0.0)

    def eval_hd(self, theta_h, theta_d, phi_d) -> np.ndarray:
        """BRDF at Rusinkiewicz coordinates (radians), ``(..., 3)`` in scaled MERL units."""
        th, td, pd = np.broadcast_arrays(np.asarray(theta_h, np.float64),
                                         np.asarray(theta_d, np.float64),
                                         np.asarray(phi_d, np.float64))
        finite = np.isfinite(th) & np.isfinite(td) & np.isfinite(pd)
        if not finite.all():  # NaN angles evaluate to 0 (and never index out of the table)
            th, td, pd = (np.where(finite, a, 0.0) for a in (th, td, pd))
            return np.where(finite[..., None], self.eval_hd(th, td, pd), 0.0)
        table = self._table()
        if self._interpolation == "nearest":
            return table[_nearest_sample(th, td, pd)][..., :3]  # invalid rows hold 0
        return _merl_trilinear(table, theta_h_to_index(th), theta_d_to_index(td),
                               phi_d_to_index(pd))

    def describe(self) -> dict:
        d = super().describe()
        d.update(format="merl", interpolation=self._interpolation, n_samples=self.n_samples,
                 n_invalid=self.n_invalid)
        return d


# -- reading ------------------------------------------------------------------------------
def _read_raw(path: Path) -> np.ndarray:
    """The validated ``(3, N)`` float64 numbers of a MERL file as stored (channel-major,
    unscaled, negative markers kept): header, size and plausibility checked first."""
    size = regular_file_size(path, "a MERL .binary file")
    if size < _HEADER_BYTES:
        raise BRDFFormatError(path, f"expected a MERL header of {_HEADER_BYTES} bytes, "
                                    f"found a file of {size} bytes (truncated)")
    try:
        with open(path, "rb") as fh:
            head = fh.read(_HEADER_BYTES)
            dims = np.frombuffer(head, dtype="<i4") if len(head) == _HEADER_BYTES else None
            found = None if dims is None else tuple(int(d) for d in dims)
            if found is not None and found != MERL_SHAPE:
                if tuple(int(d) for d in dims.byteswap()) == MERL_SHAPE:
                    problem = (f"a big-endian header {MERL_SHAPE} (byte-swapped file; MERL "
                               f"files are little-endian)")
                elif any(d <= 0 or d > 100_000 for d in found):
                    problem = f"absurd dimensions {found} in the header (not a MERL file?)"
                else:
                    problem = f"unsupported dimensions {found} in the header"
                raise BRDFFormatError(path, f"expected header {MERL_SHAPE}, found {problem}")
            if size != MERL_FILE_SIZE:
                what = "truncated file" if size < MERL_FILE_SIZE else "trailing bytes"
                raise BRDFFormatError(path, f"expected {MERL_FILE_SIZE} bytes for a {MERL_SHAPE} "
                                            f"table, found {size} ({what})")
            raw = np.fromfile(fh, dtype="<f8", count=3 * _N) if found is not None else None
    except OSError as exc:
        raise BRDFFormatError(path, f"expected a readable MERL .binary file, found "
                                    f"{describe_exception(exc)}") from None
    if raw is None or raw.size != 3 * _N:  # file shrank while reading
        raise BRDFFormatError(path, f"expected {3 * _N} float64 values, found "
                                    f"{0 if raw is None else raw.size} (file changed while read)")
    check_plausible_float64(raw, path, "values")
    return raw.reshape(3, _N)


def _valid_of(raw: np.ndarray) -> np.ndarray:
    """Samples with no negative channel (MERL's marker of a sample not measured)."""
    valid = raw[0] >= 0  # per channel: no (3, N) temporary to page-fault in
    for channel in raw[1:]:
        valid &= channel >= 0
    return valid


def _scale_in_place(raw: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``raw`` (3, N) turned into scaled MERL units, 0 at invalid samples, in its buffer."""
    raw *= MERL_SCALE[:, None]
    if not valid.all():
        raw[:, ~valid] = 0.0                        # MERL's negative marker: not measured
    return raw


def read_merl(path, interpolation: str = "trilinear") -> MERLBRDF:
    """Read a MERL ``.binary`` file into a :class:`MERLBRDF` (values scaled to MERL units).

    Raises :class:`~brdffit.errors.BRDFFormatError` naming the file for a missing or
    non-regular file, a bad header (other, absurd or byte-swapped dimensions), a size that
    does not match the header, NaN/inf values, or values that cannot be reflectance data
    (magnitude above :data:`~brdffit.io._limits.MAX_ABS_VALUE` or subnormal: typically a
    byte-swapped file). The header and the file size are checked before the table is read.
    """
    if interpolation not in _INTERPOLATIONS:
        raise ValueError(f"interpolation must be one of {_INTERPOLATIONS}, got {interpolation!r}")
    path = Path(path)
    raw = _read_raw(path)
    valid = _valid_of(raw)
    # scaled in the file's channel-planar order: values is a (θh, θd, φd, RGB) view whose
    # channels are each contiguous (no transpose copy; the fits read one channel at a time)
    planar = _scale_in_place(raw, valid)
    values = planar.reshape((3,) + MERL_SHAPE).transpose(1, 2, 3, 0)
    return MERLBRDF(values, valid.reshape(MERL_SHAPE),
                    interpolation=interpolation, name=path.stem, source=str(path),
                    _file=path, _validated=True)


def _file_numbers(table: MERLBRDF) -> np.ndarray | None:
    """The ``(3, N)`` numbers of the file ``table`` was read from, when that file still holds
    exactly this table (same validity, the same scaled values to the bit); else ``None``."""
    path = getattr(table, "_file", None)
    if path is None:
        return None
    try:
        raw = _read_raw(path)
    except BRDFFormatError:  # gone, replaced or damaged since it was read
        return None
    valid = _valid_of(raw)
    values, table_valid = table.merl_table()
    if not np.array_equal(valid, table_valid.reshape(-1)):
        return None
    scaled = _scale_in_place(raw.copy(), valid)
    same = all(np.array_equal(scaled[c], values[..., c].reshape(-1)) for c in range(3))
    return raw if same else None


# -- writing ------------------------------------------------------------------------------
def _table_of(obj) -> tuple[np.ndarray, np.ndarray]:
    if isinstance(obj, tuple) and len(obj) == 2:
        values, valid = obj
    elif isinstance(obj, np.ndarray):
        values, valid = obj, None
    elif getattr(obj, "isotropic", False) or hasattr(obj, "merl_table"):
        values, valid = tabulate_merl_grid(obj)
    else:
        raise BRDFFormatError(None, f"expected an isotropic BRDF or a (values, valid) MERL table, "
                                    f"found {type(obj).__name__}"
                                    + (" (anisotropic)" if hasattr(obj, "eval") else ""))
    values = np.asarray(values, dtype=np.float64)
    if values.shape != MERL_SHAPE + (3,):
        raise BRDFFormatError(None, f"expected a MERL table of shape {MERL_SHAPE + (3,)}, "
                                    f"found {values.shape}")
    if valid is None:
        valid = np.all(np.isfinite(values), axis=-1) & np.all(values >= 0, axis=-1)
    valid = np.asarray(valid, dtype=bool)
    if valid.shape != MERL_SHAPE:
        raise BRDFFormatError(None, f"expected a validity mask of shape {MERL_SHAPE}, "
                                    f"found {valid.shape}")
    bad = valid & ~np.all(np.isfinite(values) & (values >= 0), axis=-1)
    if bad.any():
        raise BRDFFormatError(None, f"expected finite non-negative values at valid samples, "
                                    f"found {int(bad.sum())} NaN/inf/negative")
    return values, valid


def write_merl(brdf_or_table, path) -> Path:
    """Write a MERL ``.binary`` file atomically and return its path.

    ``brdf_or_table`` is a :class:`MERLBRDF` (written bit-exactly as read when it came from
    a file that still holds that table: its own numbers are re-read), any isotropic BRDF
    (tabulated with :func:`brdffit.grid.tabulate_merl_grid`), a ``(values, valid)`` pair or
    a ``(90, 90, 180, 3)`` array in scaled MERL units. Values are divided by the colour
    scales; invalid samples are written as ``-1`` in all channels.
    """
    path = Path(path)
    raw = _file_numbers(brdf_or_table) if isinstance(brdf_or_table, MERLBRDF) else None
    if raw is None:
        values, valid = _table_of(brdf_or_table)
        raw = (values.reshape(_N, 3) / MERL_SCALE).T
        raw = np.where(valid.reshape(1, _N), raw, -1.0)
    header = np.array(MERL_SHAPE, dtype="<i4")
    with atomic_write(path) as fh:
        fh.write(header.tobytes())
        fh.write(np.ascontiguousarray(raw, dtype="<f8").tobytes())
    return path


def resample_to_merl(brdf, path=None, *, interpolation: str = "trilinear") -> MERLBRDF:
    """Tabulate an isotropic BRDF on the MERL grid; write it to ``path`` when given.

    ``interpolation`` (``"trilinear"`` or ``"nearest"``) is how the returned table is
    evaluated between its samples.

    Returns the :class:`MERLBRDF` (values at invalid/non-finite/negative evaluations are
    marked invalid). Raises :class:`~brdffit.errors.BRDFFormatError` for an anisotropic BRDF:
    the MERL grid cannot represent it.
    """
    if not getattr(brdf, "isotropic", False):
        raise BRDFFormatError(getattr(brdf, "source", None),
                              f"expected an isotropic BRDF for the MERL grid, found anisotropic "
                              f"{getattr(brdf, 'name', type(brdf).__name__)!r}")
    if isinstance(brdf, MERLBRDF):
        out = brdf.with_interpolation(interpolation)
    else:
        values, valid = tabulate_merl_grid(brdf)
        values = np.asarray(values, dtype=np.float64)
        valid = np.asarray(valid, bool) & np.all(np.isfinite(values) & (values >= 0), axis=-1)
        out = MERLBRDF(np.where(valid[..., None], values, 0.0), valid,
                       interpolation=interpolation, name=getattr(brdf, "name", "merl"),
                       source=getattr(brdf, "source", None))
    if path is not None:
        write_merl(out, path)
        out.source = os.fspath(path) if out.source is None else out.source
    return out
