"""RGL material database ``.bsdf`` files (Dupuy & Jakob 2018), evaluated like Mitsuba 3.

Dupuy & Jakob, *An Adaptive Parameterization for Efficient Material Acquisition and
Rendering*, ACM TOG 37(6) (SIGGRAPH Asia 2018). The files are Mitsuba tensor files
(:mod:`brdffit.io.tensorfile`) holding

``theta_i`` (Nθ,), ``phi_i`` (Nφ,)
    The incident directions at which the material was measured (radians; float32).
``ndf`` (J, K), ``sigma`` (J, K)
    The microfacet distribution D(ωm) recovered by the acquisition's power iteration and the
    projected area σ(ω) = ∫ D(ωm) max(0, ω·ωm) dωm, on the grid of :meth:`RGLBRDF.ndf_table`.
``vndf`` (Nφ, Nθ, H, W)
    The visible-normal distribution per incident direction, the warp that maps the unit
    square to half vectors (``Marginal2D`` of Mitsuba, conditioned on (φi, θi)).
``luminance`` (Nφ, Nθ, h, w), ``rgb`` (Nφ, Nθ, 3, h, w) (or ``spectra`` + ``wavelengths``)
    The luminance and the RGB values of the reflectance in the *warped* (sample-space) domain.
``jacobian`` (1,) uint8
    When set, the value is multiplied by D(ωm) / (4 σ(ωi)) (see :meth:`RGLBRDF.eval`).
``description`` str, plus ``version`` and ``valid`` (a packed bit mask, unused by Mitsuba).

Evaluation reproduces Mitsuba 3's ``measured`` BSDF plugin (``src/bsdfs/measured.cpp``,
``Measured::eval``) and its continuous ``Marginal2D`` warps (``include/mitsuba/core/
distr_2d.h``, ``Marginal2D<Float, Dim, true>``: constructor, ``invert_continuous``,
``eval``, ``interpolate_weights`` with ``math::find_interval``) in vectorised NumPy float64
(Mitsuba computes in float32: the two agree to ~1e-5 relative).

Direction convention. Mitsuba's ``eval(si.wi, wo)`` conditions its tables on ``si.wi`` (the
direction towards the viewer: light leaves the surface along it) and returns the BSDF times
the cosine of ``wo`` (the direction towards the light). brdffit's ``eval(wi, wo)`` has ``wi``
towards the light and ``wo`` towards the viewer and returns f_r alone, so

``RGLBRDF.eval(wi, wo) = Measured.eval(si.wi = wo, wo = wi) / cos θ(wi)``

(negative values, present in some RGB tables, are clamped to 0 by ``eval`` only).
``sample``/``pdf`` port ``Measured::sample``/``Measured::pdf`` (luminance warp, then VNDF,
``Marginal2D::sample_continuous``) with si.wi = our ``wi``: by reciprocity they sample ``wo``
∝ f_r(wi, wo) cos θo. Spectral files (``spectra`` + ``wavelengths``) are evaluated per
wavelength by :meth:`RGLBRDF.eval_spectral_mitsuba` (Mitsuba's spectral variants) and, for
the RGB protocol, through :func:`spectral_to_srgb_weights` (our conversion).

Verified against Mitsuba 3.9 itself (``tests/io/test_rgl.py``, ``bench/bench_rgl.py``):
eval, pdf and sample agree to float32 round-off on the seven RGL files and on synthetic
anisotropic files with symmetry reductions 1, 2 and 4.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..brdf import BRDF, IsotropicBRDF, _as_dirs
from ..errors import BRDFFormatError
from .tensorfile import read_tensor_file

__all__ = ["RGLBRDF", "IsotropicRGLBRDF", "read_rgl", "AngularTable", "spectral_to_srgb_weights",
           "theta_to_u", "u_to_theta", "phi_to_u", "u_to_phi", "elevation"]

_CHUNK = 1 << 17


# ------------------------------------------------------------------ angular parameterisation
def theta_to_u(theta):
    """Mitsuba ``Measured::theta2u``: u = sqrt(θ · 2/π) (square-root mapping of [0, π/2])."""
    return np.sqrt(np.asarray(theta, np.float64) * (2.0 / np.pi))


def u_to_theta(u):
    """Mitsuba ``Measured::u2theta``: θ = u² · π/2."""
    return np.square(np.asarray(u, np.float64)) * (np.pi / 2.0)


def phi_to_u(phi):
    """Mitsuba ``Measured::phi2u``: u = (φ + π) / 2π (φ in [-π, π] -> [0, 1])."""
    return (np.asarray(phi, np.float64) + np.pi) * (0.5 / np.pi)


def u_to_phi(u):
    """Mitsuba ``Measured::u2phi``: φ = (2u − 1) π."""
    return (2.0 * np.asarray(u, np.float64) - 1.0) * np.pi


def phi_i_reduction(phi_i) -> int:
    """The symmetry reduction Mitsuba's ``Measured()`` derives from ``phi_i``: 0 (isotropic)
    for one or two slices, else ``rint(2π / (φ_last − φ_0))``."""
    phi_i = np.asarray(phi_i)
    if phi_i.size <= 2:
        return 0
    return int(np.rint(2.0 * np.pi / float(phi_i[-1] - phi_i[0])))


def elevation(d):
    """θ of unit vectors, computed as Mitsuba's ``Measured::elevation`` (stable near 0):
    2 asin(|d − n| / 2)."""
    d = np.asarray(d, np.float64)
    dist = np.sqrt(d[..., 0] ** 2 + d[..., 1] ** 2 + (d[..., 2] - 1.0) ** 2)
    return 2.0 * np.arcsin(np.clip(0.5 * dist, -1.0, 1.0))


# ------------------------------------------------------------------ Marginal2D (continuous)
class _Marginal2D:
    """NumPy port of Mitsuba 3's ``Marginal2D<Float, Dimension, Continuous=true>``.

    ``data`` has shape ``param_res + (H, W)``; x (fastest, width W) and y (height H) span
    [0, 1] with W−1 and H−1 bilinear patches. Parameter dimensions are interpolated linearly
    (``Distribution2D::interpolate_weights``: interval by ``find_interval``, weight clamped to
    [0, 1]; a parameter of resolution 1 is ignored). With ``normalize`` every slice is divided
    by the trapezoidal integral of its interpolant (its marginal CDF's last entry); the
    conditional CDF (H rows of W−1) and marginal CDF (H−1) are then built per slice as in the
    constructor of ``Marginal2D``. Only ``eval`` and ``invert`` (``invert_continuous``) are
    needed by ``Measured::eval``.
    """

    def __init__(self, data, param_values=(), normalize=True, enable_sampling=True):
        data = np.asarray(data, np.float64)
        nparams = len(param_values)
        self.param_values = [np.asarray(p, np.float64).ravel() for p in param_values]
        self.param_res = tuple(int(p.size) for p in self.param_values)
        if data.shape[:nparams] != self.param_res or data.ndim != nparams + 2:
            raise ValueError(f"data shape {data.shape} does not match params {self.param_res} + (H, W)")
        self.h, self.w = data.shape[-2:]
        if self.h < 2 or self.w < 2:
            raise ValueError("Marginal2D needs a resolution >= 2 in both axes")
        # strides in units of slices, 0 for parameters of resolution 1 (Distribution2D ctor)
        strides, slices = [0] * nparams, 1
        for i in range(nparams - 1, -1, -1):
            strides[i] = slices if self.param_res[i] > 1 else 0
            slices *= self.param_res[i]
        self.strides, self.slices = strides, slices
        d = data.reshape(slices, self.h, self.w)
        self.n_data = self.h * self.w
        if enable_sampling:
            sx, sy = 0.5 / (self.w - 1), 0.5 / (self.h - 1)
            cond = np.cumsum(sx * (d[:, :, :-1] + d[:, :, 1:]), axis=2)      # (S, H, W-1)
            row_tot = cond[:, :, -1]                                            # (S, H)
            marg = np.cumsum(sy * (row_tot[:, :-1] + row_tot[:, 1:]), axis=1)  # (S, H-1)
            norm = 1.0 / marg[:, -1] if normalize else np.ones(slices)
            with np.errstate(divide="ignore", invalid="ignore"):
                self.cond = (cond * norm[:, None, None]).ravel()
                self.marg = (marg * norm[:, None]).ravel()
                self.data = (d * norm[:, None, None]).ravel()
            self.n_cond = self.h * (self.w - 1)
            self.n_marg = self.h - 1
        else:
            if normalize:
                tot = (d[:, :-1, :-1] + d[:, :-1, 1:] + d[:, 1:, :-1] + d[:, 1:, 1:]).sum(axis=(1, 2))
                d = d / (tot * (0.5 / (self.w - 1)) * (0.5 / (self.h - 1)))[:, None, None]
            self.data = d.ravel()
            self.cond = self.marg = None

    # corners of the parameter cell: list of (slice index array, weight array)
    def corners(self, params):
        n = np.shape(params[0])[0] if params else 1
        out = [(np.zeros(n, np.int64), np.ones(n))]
        for dim, p in enumerate(params):
            if self.param_res[dim] == 1:
                continue
            vals = self.param_values[dim]
            idx = np.clip(np.searchsorted(vals, p, side="left"), 1, vals.size - 1) - 1
            p0, p1 = vals[idx], vals[idx + 1]
            w1 = np.clip((p - p0) / (p1 - p0), 0.0, 1.0)
            base = self.strides[dim] * idx
            new = []
            for s, w in out:
                new.append((s + base, w * (1.0 - w1)))
                new.append((s + base + self.strides[dim], w * w1))
            out = new
        return out

    @staticmethod
    def _lookup(table, size, corners, index):
        """Mitsuba ``Marginal2D::lookup``: multilinear blend over the parameter cell."""
        acc = None
        for s, w in corners:
            v = np.take(table, s * size + index) * w
            acc = v if acc is None else acc + v
        return acc

    def _cell(self, pos):
        pos = np.clip(pos, 0.0, 1.0) * np.array([self.w - 1, self.h - 1])
        ip = np.minimum(pos.astype(np.int64), np.array([self.w - 2, self.h - 2]))
        return ip, pos - ip

    def eval(self, pos, corners):
        """Bilinear interpolant at ``pos`` (N, 2) (``Marginal2D::eval`` / square_to_bilinear_pdf)."""
        ip, f = self._cell(pos)
        i = ip[:, 1] * self.w + ip[:, 0]
        lk = lambda o: self._lookup(self.data, self.n_data, corners, i + o)  # noqa: E731
        v00, v10, v01, v11 = lk(0), lk(1), lk(self.w), lk(self.w + 1)
        fx, fy = f[:, 0], f[:, 1]
        return (1 - fy) * ((1 - fx) * v00 + fx * v10) + fy * ((1 - fx) * v01 + fx * v11)

    def _columns(self, corners, i, fy):
        """The data of cell ``i`` (its corner texel's index) interpolated at ``fy`` along its
        left and right columns: ``(c0, c1)``."""
        v00 = self._lookup(self.data, self.n_data, corners, i)
        v10 = self._lookup(self.data, self.n_data, corners, i + 1)
        v01 = self._lookup(self.data, self.n_data, corners, i + self.w)
        v11 = self._lookup(self.data, self.n_data, corners, i + self.w + 1)
        return v00 + (v01 - v00) * fy, v10 + (v11 - v10) * fy

    def invert(self, sample, corners):
        """``Marginal2D::invert_continuous``: the sample in [0,1]² mapping to ``sample``."""
        ip, f = self._cell(sample)
        px, py = ip[:, 0], ip[:, 1]
        fx, fy = f[:, 0], f[:, 1]
        i = py * self.w + px
        lk = lambda t, n, idx: self._lookup(t, n, corners, idx)  # noqa: E731
        c0, c1 = self._columns(corners, i, fy)
        pdf = c0 + (c1 - c0) * fx
        # invert_segment(x, 1/(W-1), c0, c1)
        x = fx * (c0 + (c1 - c0) * (0.5 * fx)) / (self.w - 1)
        wm1 = self.w - 1
        off_cond = py * wm1
        has_prev = px > 0
        j = off_cond + np.maximum(px - 1, 0)
        prev0 = lk(self.cond, self.n_cond, j)
        prev1 = lk(self.cond, self.n_cond, j + wm1)
        x = x + np.where(has_prev, prev0 + (prev1 - prev0) * fy, 0.0)
        r0 = lk(self.cond, self.n_cond, off_cond + wm1 - 1)
        r1 = lk(self.cond, self.n_cond, off_cond + 2 * wm1 - 1)
        rl = r0 + (r1 - r0) * fy
        with np.errstate(divide="ignore", invalid="ignore"):
            x = x / rl
        y = fy * (r0 + (r1 - r0) * (0.5 * fy)) / (self.h - 1)
        has_row = py > 0
        y = y + np.where(has_row, lk(self.marg, self.n_marg, np.maximum(py - 1, 0)), 0.0)
        return np.stack([x, y], axis=-1), pdf

    @staticmethod
    def _lower_bound(n, start, end, pred):
        """``dr::binary_search``: first index in [start, end] where ``pred`` is false."""
        lo = np.full(n, start, np.int64)
        hi = np.full(n, end, np.int64)
        iterations = int(np.floor(np.log2(end - start))) + 1 if end > start else 0
        for _ in range(iterations):
            mid = (lo + hi) >> 1
            cond = pred(mid)
            lo, hi = np.where(cond, np.minimum(mid + 1, hi), lo), np.where(cond, hi, mid)
        return lo

    @staticmethod
    def _sample_segment(sample, inv_width, v0, v1):
        """``Marginal2D::sample_segment``: invert the CDF of a linear segment."""
        non_const = np.abs(v0 - v1) > 1e-4 * (v0 + v1)
        divisor = np.where(non_const, v0 - v1, v0 + v1)
        sample = sample * (2.0 * inv_width)
        sample = np.where(non_const, v0 - np.sqrt(np.maximum(v0 * v0 + sample * (v1 - v0), 0.0)),
                          sample)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(divisor != 0, sample / divisor, sample)

    def sample(self, u, corners):
        """``Marginal2D::sample_continuous``: warp uniform ``u`` (N, 2); returns (pos, pdf)."""
        eps = 2.0 ** -24                         # dr::Epsilon<float>, OneMinusEpsilon
        u = np.clip(np.asarray(u, np.float64), eps, 1.0 - eps)
        x, y = u[:, 0].copy(), u[:, 1].copy()
        n = x.shape[0]
        lk = lambda t, n, idx: self._lookup(t, n, corners, idx)  # noqa: E731
        wm1, nm = self.w - 1, self.n_marg
        row = self._lower_bound(n, 0, nm - 1, lambda i: lk(self.marg, nm, i) < y)
        y = y - np.where(row > 0, lk(self.marg, nm, np.maximum(row - 1, 0)), 0.0)
        off_cond = row * wm1
        r0 = lk(self.cond, self.n_cond, off_cond + wm1 - 1)
        r1 = lk(self.cond, self.n_cond, off_cond + 2 * wm1 - 1)
        y = self._sample_segment(y, self.h - 1, r0, r1)
        x = x * (r0 + (r1 - r0) * y)

        def cond_at(i):
            v0 = lk(self.cond, self.n_cond, off_cond + i)
            v1 = lk(self.cond, self.n_cond, off_cond + i + wm1)
            return v0 + (v1 - v0) * y

        col = self._lower_bound(n, 0, wm1, lambda i: cond_at(i) < x)
        x = x - np.where(col > 0, cond_at(np.maximum(col - 1, 0)), 0.0)
        c0, c1 = self._columns(corners, row * self.w + col, y)
        x = self._sample_segment(x, wm1, c0, c1)
        pos = np.stack([(col + x) / wm1, (row + y) / (self.h - 1)], axis=-1)
        return pos, c0 + (c1 - c0) * x


def spectral_to_srgb_weights(wavelengths) -> np.ndarray:
    """Weights ``W`` (3, L) with ``rgb = W @ spectrum`` for spectra sampled at ``wavelengths``.

    The spectrum is the piecewise-linear interpolant of the samples, clamped outside their
    range (as Mitsuba interpolates the ``spectra`` table), treated as a reflectance under CIE
    D65: linear sRGB = M_XYZ→sRGB · ∫ S D65 (x̄, ȳ, z̄) dλ / ∫ D65 ȳ dλ over 360–830 nm with the
    CIE 1931 2° observer (colour-science tables), so a flat spectrum c maps to (c, c, c)
    up to the rounding of the sRGB matrix. This conversion is ours: Mitsuba's RGB variants
    refuse spectral files.
    """
    import colour

    lam = np.asarray(wavelengths, np.float64).ravel()
    grid = np.arange(360.0, 831.0)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    cmf = np.stack([np.interp(grid, cmfs.wavelengths, cmfs.values[:, k]) for k in range(3)])
    d65 = colour.SDS_ILLUMINANTS["D65"]
    ill = np.interp(grid, d65.wavelengths, d65.values)
    hats = np.stack([np.interp(grid, lam, np.eye(lam.size)[k]) for k in range(lam.size)])
    xyz = (cmf * ill) @ hats.T / np.sum(cmf[1] * ill)         # (3, L); 1 nm steps cancel
    m = np.asarray(colour.RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB, np.float64)
    return m @ xyz


# ------------------------------------------------------------------ public classes
@dataclass(frozen=True)
class AngularTable:
    """A tabulated function of one direction on the RGL angular grid.

    ``values[j, k]`` is the value at ``theta[k] = (k/(K−1))² · π/2`` and
    ``phi[j] = −π + 2π j/(J−1)``, i.e. uniform in ``u_theta = sqrt(2θ/π)`` and in
    ``u_phi = (φ + π)/2π`` (Mitsuba ``Measured::u2theta``/``u2phi``). Values are bilinear in
    (u_theta, u_phi) between grid points (``Marginal2D<Float, 0>::eval`` as used by the plugin).
    For isotropic materials J = 2 and the two rows are equal (φ is irrelevant).
    """

    name: str
    values: np.ndarray
    theta: np.ndarray
    phi: np.ndarray
    u_theta: np.ndarray
    u_phi: np.ndarray
    doc: str

    def __call__(self, theta, phi=0.0) -> np.ndarray:
        """Interpolated value at polar angle ``theta`` and azimuth ``phi`` (radians)."""
        theta, phi = np.broadcast_arrays(np.asarray(theta, np.float64), np.asarray(phi, np.float64))
        warp = _Marginal2D(self.values, (), normalize=False, enable_sampling=False)
        u = np.stack([theta_to_u(np.clip(theta, 0, np.pi / 2)).ravel(),
                      phi_to_u(np.angle(np.exp(1j * phi.ravel())))], -1)
        return warp.eval(u, warp.corners([])).reshape(theta.shape)


_NDF_DOC = ("D(ωm): the microfacet normal distribution recovered by the acquisition's power "
            "iteration (Dupuy & Jakob 2018, after Dupuy et al. 2015), in 1/sr, as a function "
            "of the half vector's polar angle θm and azimuth φm in the local frame; normalised "
            "as Dupuy et al. 2015 Eq. 4, ∫ D(ωm) cos θm dωm = 1 (to ~1-2 % for the "
            "bilinear interpolant of the stored table; checked by tests).")
_SIGMA_DOC = ("σ(ω) = ∫ D(ωm) max(0, ω·ωm) dωm: the projected microfacet area seen from "
              "direction ω (θ, φ), dimensionless, σ(normal) = 1; the denominator of the Smith "
              "G1(ω) = cos θ / σ(ω) of Dupuy et al. 2015 Eq. 3 (consistency with the stored "
              "ndf checked by tests to ~3 %).")


class RGLBRDF(BRDF):
    """A measured RGL material (``*.bsdf``), evaluated as Mitsuba 3's ``measured`` plugin.

    Use :func:`read_rgl`. Attributes mirror the file's fields (``theta_i``, ``phi_i``,
    ``ndf``, ``sigma``, ``vndf``, ``luminance``, ``rgb``, ``jacobian``, ``description``, and
    ``wavelengths``/``spectra``/``valid``/``version`` when present); ``fields`` holds them all.
    """

    def __init__(self, fields: dict, source=None, name: str | None = None):
        self.fields = dict(fields)
        self.source = None if source is None else str(source)
        self._read_fields()
        self._check_fields()
        self.name = name or (Path(self.source).stem if self.source else "rgl")
        # Measured(): m_isotropic = phi_i.shape[0] <= 2
        self.isotropic = self.phi_i.size <= 2
        self.reduction = phi_i_reduction(self.phi_i)
        self._build_warps()

    def _need(self, key, ndim, dtype=np.float32) -> np.ndarray:
        """The field ``key``, an ``ndim``-D array of ``dtype``; raises BRDFFormatError."""
        f = self.fields
        if key not in f:
            raise BRDFFormatError(self.source, f"expected a field {key!r} in an RGL .bsdf "
                                               f"file, found fields {sorted(f)}")
        a = f[key]
        if not isinstance(a, np.ndarray) or a.ndim != ndim or a.dtype != dtype:
            got = (type(a).__name__ if not isinstance(a, np.ndarray)
                   else f"{a.dtype} array of shape {a.shape}")
            raise BRDFFormatError(self.source, f"expected field {key!r} as a {ndim}-D "
                                               f"{np.dtype(dtype)} array, found {got}")
        return a

    def _read_fields(self) -> None:
        """The attributes of the file's fields, the required ones type-checked."""
        path, f, need = self.source, self.fields, self._need
        self.theta_i = need("theta_i", 1)
        self.phi_i = need("phi_i", 1)
        self.ndf = need("ndf", 2)
        self.sigma = need("sigma", 2)
        self.vndf = need("vndf", 4)
        self.luminance = need("luminance", 4)
        jac = need("jacobian", 1, np.uint8)
        if jac.size != 1:
            raise BRDFFormatError(path, f"expected a jacobian flag of shape (1,), found {jac.shape}")
        self.jacobian = bool(jac[0])
        desc = f.get("description", "")
        self.description = (desc if isinstance(desc, str)
                            else bytes(np.asarray(desc, np.uint8)).decode("utf-8", "replace"))
        self.wavelengths = f.get("wavelengths")
        self.spectra = f.get("spectra")
        self.rgb = f.get("rgb")
        self.valid = f.get("valid")
        self.version = f.get("version")

    def _check_fields(self) -> None:
        """The shapes, ranges and signs of the tables; raises BRDFFormatError."""
        path, need = self.source, self._need
        nphi, nth = self.phi_i.size, self.theta_i.size
        if nphi < 1 or nth < 1:
            raise BRDFFormatError(path, f"expected at least one θi and φi, found {nth} and {nphi}")
        if not (np.all(np.diff(self.theta_i) > 0) and np.all(np.diff(self.phi_i) > 0)):
            raise BRDFFormatError(path, "expected strictly increasing theta_i and phi_i, found "
                                        f"{self.theta_i.tolist()} / {self.phi_i.tolist()}")
        if self.theta_i[0] < 0 or self.theta_i[-1] > np.pi / 2 + 1e-4:
            raise BRDFFormatError(path, f"expected theta_i in [0, π/2] radians, found "
                                        f"[{float(self.theta_i[0]):g}, {float(self.theta_i[-1]):g}]")
        if self.phi_i[0] < -2 * np.pi - 1e-4 or self.phi_i[-1] > 2 * np.pi + 1e-4:
            raise BRDFFormatError(path, f"expected phi_i in [-2π, 2π] radians, found "
                                        f"[{float(self.phi_i[0]):g}, {float(self.phi_i[-1]):g}]")
        if self.vndf.shape[:2] != (nphi, nth) or min(self.vndf.shape[2:]) < 2:
            raise BRDFFormatError(path, f"expected vndf of shape ({nphi}, {nth}, H>=2, W>=2), "
                                        f"found {self.vndf.shape}")
        lum = self.luminance.shape
        if lum[:2] != (nphi, nth) or lum[2] != lum[3] or lum[2] < 2:
            raise BRDFFormatError(path, f"expected luminance of shape ({nphi}, {nth}, n, n), "
                                        f"found {lum}")
        for key in ("ndf", "sigma"):
            if min(getattr(self, key).shape) < 2:
                raise BRDFFormatError(path, f"expected {key} of shape (J>=2, K>=2), found "
                                            f"{getattr(self, key).shape}")
        if self.rgb is not None:
            rgb = need("rgb", 5)
            if rgb.shape != (nphi, nth, 3) + lum[2:]:
                raise BRDFFormatError(path, f"expected rgb of shape {(nphi, nth, 3) + lum[2:]}, "
                                            f"found {rgb.shape}")
        elif self.spectra is not None:
            sp, wl = need("spectra", 5), need("wavelengths", 1)
            if sp.shape != (nphi, nth, wl.size) + lum[2:]:
                raise BRDFFormatError(path, f"expected spectra of shape "
                                            f"{(nphi, nth, wl.size) + lum[2:]}, found {sp.shape}")
        else:
            raise BRDFFormatError(path, "expected an 'rgb' or a 'spectra' field, found neither")
        for key in ("ndf", "sigma", "vndf", "luminance"):
            if np.any(getattr(self, key) < 0):
                raise BRDFFormatError(path, f"expected non-negative values in {key!r}, found "
                                            f"minimum {float(getattr(self, key).min())}")
        for key in ("vndf", "luminance"):
            if getattr(self, key).reshape(nphi * nth, -1).sum(axis=1).min() <= 0:
                raise BRDFFormatError(path, f"expected every {key} slice to have a positive "
                                            "integral, found an all-zero slice")

    def _build_warps(self) -> None:
        """The interpolants of Mitsuba's ``measured`` plugin and the RGB table (spectra
        converted to linear sRGB, :func:`spectral_to_srgb_weights`)."""
        path = self.source
        params = (self.phi_i, self.theta_i)
        self._ndf = _Marginal2D(self.ndf, (), normalize=False, enable_sampling=False)
        self._sigma = _Marginal2D(self.sigma, (), normalize=False, enable_sampling=False)
        self._vndf = _Marginal2D(self.vndf, params)
        self._luminance = _Marginal2D(self.luminance, params)   # used by sample/pdf only
        self._spectral = None
        if self.rgb is not None:
            rgb = self.rgb.astype(np.float64)
        else:
            if not np.all(np.diff(self.wavelengths) > 0):
                raise BRDFFormatError(path, "expected strictly increasing wavelengths, found "
                                            f"{self.wavelengths.tolist()}")
            self._spectral = _Marginal2D(self.spectra, params + (self.wavelengths,),
                                         normalize=False, enable_sampling=False)
            # linear in the table: converting texels first = converting evaluated spectra
            rgb = np.einsum("cl,ptlyx->ptcyx", spectral_to_srgb_weights(self.wavelengths),
                            self.spectra.astype(np.float64))
        # Warp2D3 over (φi, θi, channel) with channel values {0, 1, 2}: at an integer channel
        # the interpolation weight is exactly 0/1, so a per-texel RGB gather is identical.
        self._rgb_table = np.ascontiguousarray(np.moveaxis(rgb, 2, -1)).reshape(-1, 3)
        self._rgb_warp = _Marginal2D(rgb[:, :, 0], params, normalize=False, enable_sampling=False)

    # -------------------------------------------------------------- measured domain
    @property
    def theta_i_measured(self) -> float:
        """The largest measured incidence (radians): the last ``theta_i`` node, or the one
        before it when the last is 90° (light at grazing incidence cannot be measured; that
        row is an extrapolation, and values interpolated towards it grow like 1/cos θi)."""
        last = float(self.theta_i[-1])
        if self.theta_i.size > 1 and last >= np.radians(89.9):
            return float(self.theta_i[-2])
        return last

    @property
    def measured_domain(self) -> str:
        return f"θi ≤ {np.degrees(self.theta_i_measured):.1f}° (the file's measured incidences)"

    def measured(self, wi, wo) -> np.ndarray:
        """True for an incidence within the measured ``theta_i`` range, both directions above
        the horizon. (The file's ``valid`` bit mask is not used: see :meth:`valid_mask`.)"""
        wi, wo = _as_dirs(wi, wo)
        lim = np.cos(self.theta_i_measured) - 1e-9
        return (wi[..., 2] >= lim) & (wi[..., 2] > 0) & (wo[..., 2] > 0)

    # -------------------------------------------------------------- tables for other modules
    def ndf_table(self) -> AngularTable:
        """The stored NDF ``D(θm, φm)`` with its angular grid (see :class:`AngularTable`)."""
        return self._angular("ndf", self.ndf, _NDF_DOC)

    def sigma_table(self) -> AngularTable:
        """The stored projected area ``σ(θ, φ)`` with its angular grid (see :class:`AngularTable`)."""
        return self._angular("sigma", self.sigma, _SIGMA_DOC)

    @staticmethod
    def _angular(name, values, doc) -> AngularTable:
        j, k = values.shape
        ut, up = np.linspace(0.0, 1.0, k), np.linspace(0.0, 1.0, j)
        return AngularTable(name, values.astype(np.float64), u_to_theta(ut), u_to_phi(up),
                            ut, up, doc)

    def valid_mask(self) -> np.ndarray | None:
        """The ``valid`` field unpacked as booleans ``(Nφ, Nθ, n, n)``, one bit per texel of
        the warped tables, most significant bit first. ``None`` when absent or of another size.

        Mitsuba does not use the field, nor does brdffit. Read this way, in five of the seven
        RGL files of the test data it is set exactly on the texels whose outgoing direction
        (the reflection of ``wi`` about the VNDF-warped half vector) is above the horizon, and
        in two (``colodur_napoli_4f``, ``paper_white``) exactly on the others: it says nothing
        about the measurement beyond the horizon (:meth:`measured` is the measured domain).
        """
        if self.valid is None:
            return None
        bits = np.unpackbits(np.asarray(self.valid, np.uint8)).astype(bool)
        shape = self.luminance.shape
        return bits.reshape(shape) if bits.size == int(np.prod(shape)) else None

    def describe(self):
        d = super().describe()
        d.update(format="rgl-bsdf", description=self.description,
                 theta_i_deg=np.degrees(self.theta_i).round(3).tolist(), n_phi_i=int(self.phi_i.size),
                 vndf_resolution=list(self.vndf.shape[2:]), resolution=list(self.luminance.shape[2:]),
                 jacobian=self.jacobian, reduction=self.reduction,
                 color="rgb" if self.rgb is not None else "spectral")
        return d

    # -------------------------------------------------------------- evaluation
    def eval_mitsuba(self, wi_m, wo_m) -> np.ndarray:
        """``Measured::eval`` of Mitsuba 3 (float64 port): ``f(si.wi, wo) · cos θ(wo)``.

        ``wi_m`` is Mitsuba's ``si.wi`` (towards the viewer), ``wo_m`` its ``wo`` (towards the
        light). Returns RGB ``(..., 3)``, 0 unless both are above the horizon. For spectral
        files (which Mitsuba's RGB variants refuse) the RGB is that of
        :func:`spectral_to_srgb_weights` applied to the spectral value (see
        :meth:`eval_spectral_mitsuba` for the spectral evaluation itself).
        """
        wi_m, wo_m = _as_dirs(wi_m, wo_m)
        shape = wi_m.shape[:-1]
        a, b = wi_m.reshape(-1, 3), wo_m.reshape(-1, 3)
        out = np.zeros((a.shape[0], 3))
        for s in range(0, a.shape[0], _CHUNK):
            out[s:s + _CHUNK] = self._eval_flat(a[s:s + _CHUNK], b[s:s + _CHUNK])
        return out.reshape(shape + (3,))

    def eval_spectral_mitsuba(self, wi_m, wo_m, wavelengths) -> np.ndarray:
        """Spectral ``Measured::eval`` (Mitsuba's spectral variants): ``(..., L)`` values.

        ``wavelengths`` (nm) broadcast against the directions' leading shape plus a last axis
        of L wavelengths; the ``spectra`` table is interpolated linearly in wavelength (clamped
        outside the stored range), as ``Warp2D3`` does with parameters (φi, θi, λ).
        Only for spectral files (``spectra`` + ``wavelengths`` fields).
        """
        if self._spectral is None:
            raise BRDFFormatError(self.source, "expected a spectral file ('spectra' and "
                                               "'wavelengths' fields), found an RGB file")
        wi_m, wo_m = _as_dirs(wi_m, wo_m)
        shape = wi_m.shape[:-1]
        lam = np.asarray(wavelengths, np.float64)
        lam = np.broadcast_to(lam, shape + lam.shape[-1:]).reshape(-1, lam.shape[-1])
        wi, wo = wi_m.reshape(-1, 3).copy(), wo_m.reshape(-1, 3).copy()
        out = np.zeros(lam.shape)
        active = (wi[:, 2] > 0) & (wo[:, 2] > 0)
        if active.any():
            wi, wo, lam_a = wi[active], wo[active], lam[active]
            _, theta_i, phi_i, u_m = self._half_vector(wi, wo)
            sample, _ = self._vndf.invert(u_m, self._vndf.corners([phi_i, theta_i]))
            val = np.stack([self._spectral.eval(sample, self._spectral.corners(
                [phi_i, theta_i, lam_a[:, k]])) for k in range(lam.shape[1])], -1)
            out[active] = self._with_jacobian(val, u_m, theta_i, phi_i)
        return out.reshape(shape + (lam.shape[1],))

    def _eval_flat(self, wi, wo):
        out = np.zeros((wi.shape[0], 3))
        active = (wi[:, 2] > 0) & (wo[:, 2] > 0)
        if not active.any():
            return out
        wi, wo = wi[active].copy(), wo[active].copy()
        _, theta_i, phi_i, u_m = self._half_vector(wi, wo)
        params = [phi_i, theta_i]
        corners = self._vndf.corners(params)          # same params for vndf and rgb
        sample, _ = self._vndf.invert(u_m, corners)
        # m_spectra.eval(sample, {φi, θi, channel}): bilinear texel lookup, all channels at once
        w = self._rgb_warp
        ip, f = w._cell(sample)
        i = ip[:, 1] * w.w + ip[:, 0]
        fx, fy = f[:, :1], f[:, 1:]
        spec = 0.0
        for s, wt in corners:
            base = s * w.n_data + i
            t = self._rgb_table
            v00, v10 = np.take(t, base, axis=0), np.take(t, base + 1, axis=0)
            v01, v11 = np.take(t, base + w.w, axis=0), np.take(t, base + w.w + 1, axis=0)
            spec = spec + wt[:, None] * ((1 - fy) * ((1 - fx) * v00 + fx * v10)
                                         + fy * ((1 - fx) * v01 + fx * v11))
        out[active] = self._with_jacobian(spec, u_m, theta_i, phi_i)
        return out

    def _half_vector(self, wi, wo):
        """Fold ``wi`` and ``wo`` in place by the symmetry reduction (:meth:`_fold`); return
        their half vector ``m`` and :meth:`_warp_angles` ``(theta_i, phi_i, u_m)``."""
        if self.reduction >= 2:
            fx, fy = self._fold(wi)
            wi[:, 0] *= fx; wi[:, 1] *= fy; wo[:, 0] *= fx; wo[:, 1] *= fy  # noqa: E702
        m = wi + wo
        m /= np.linalg.norm(m, axis=-1, keepdims=True)
        return (m,) + self._warp_angles(wi, m)

    def _with_jacobian(self, val, u_m, theta_i, phi_i):
        """``val`` (N, C) times ``D(m) / (4 σ(wi))`` when the file's ``jacobian`` flag is set
        (the stored values are then divided by it, as Mitsuba's ``measured`` reads them)."""
        if not self.jacobian:
            return val
        u_wi = np.stack([theta_to_u(theta_i), phi_to_u(phi_i)], -1)
        d = self._ndf.eval(u_m, self._ndf.corners([]))
        sg = self._sigma.eval(u_wi, self._sigma.corners([]))
        with np.errstate(divide="ignore", invalid="ignore"):
            return val * (d / (4.0 * sg))[:, None]

    def _fold(self, wi):
        """Symmetry reduction of ``Measured``: per-sample sign multipliers for x and y.

        ``mulsign_neg(v, s)`` negates ``v`` where the sign bit of ``s`` is clear. With
        ``reduction`` 2, s = wi.y for both axes (rotation by π into φi ∈ [−π, 0]); with 4,
        s = (wi.x, wi.y) (mirrors into φi ∈ [−π, −π/2]). Identity otherwise.
        """
        if self.reduction < 2:
            one = np.ones(wi.shape[0])
            return one, one
        sy = wi[:, 1]
        sx = wi[:, 0] if self.reduction == 4 else sy
        return np.where(np.signbit(sx), 1.0, -1.0), np.where(np.signbit(sy), 1.0, -1.0)

    def _warp_angles(self, wi, m):
        theta_i, phi_i = elevation(wi), np.arctan2(wi[:, 1], wi[:, 0])
        theta_m, phi_m = elevation(m), np.arctan2(m[:, 1], m[:, 0])
        u_m = np.stack([theta_to_u(theta_m),
                        phi_to_u(phi_m - phi_i if self.isotropic else phi_m)], -1)
        u_m[:, 1] -= np.floor(u_m[:, 1])
        return theta_i, phi_i, u_m

    def pdf_mitsuba(self, wi_m, wo_m) -> np.ndarray:
        """``Measured::pdf``: solid-angle density of ``wo_m`` drawn by :meth:`sample_mitsuba`.

        vndf.invert gives the warped sample and the VNDF density in (u_θ, u_φ); times the
        luminance density there; divided by the Jacobian
        ``max(2π² u_θ sin θm, 1e-6) · 4 (wi·m)`` from (u_θ, u_φ) of the half vector to ωo.
        """
        wi_m, wo_m = _as_dirs(wi_m, wo_m)
        shape = wi_m.shape[:-1]
        wi, wo = wi_m.reshape(-1, 3).copy(), wo_m.reshape(-1, 3).copy()
        out = np.zeros(wi.shape[0])
        active = (wi[:, 2] > 0) & (wo[:, 2] > 0)
        if active.any():
            wi, wo = wi[active], wo[active]
            m, theta_i, phi_i, u_m = self._half_vector(wi, wo)
            corners = self._vndf.corners([phi_i, theta_i])
            sample, vndf_pdf = self._vndf.invert(u_m, corners)
            lum_pdf = self._luminance.eval(sample, corners)
            sin_m = np.sqrt(np.maximum(1.0 - m[:, 2] ** 2, 0.0))
            jac = np.maximum(2 * np.pi ** 2 * u_m[:, 0] * sin_m, 1e-6) * 4 * np.sum(wi * m, -1)
            with np.errstate(divide="ignore", invalid="ignore"):
                p = vndf_pdf * lum_pdf / jac
            out[active] = np.where(np.isfinite(p) & (p > 0), p, 0.0)
        return out.reshape(shape)

    def sample_mitsuba(self, wi_m, u) -> tuple[np.ndarray, np.ndarray]:
        """``Measured::sample`` (importance sampling by luminance then VNDF): ``(wo, pdf)``.

        ``u`` (..., 2) plays Mitsuba's ``sample2``; the luminance warp is fed ``(u.y, u.x)``,
        its output warped by the VNDF to the half vector's (u_θ, u_φ) (φ relative to φi for
        isotropic files), and ``wo`` is the reflection of ``wi`` about it. ``pdf`` is 0 for
        directions below the horizon.
        """
        wi_m = np.asarray(wi_m, np.float64)
        u = np.asarray(u, np.float64)
        shape = np.broadcast_shapes(wi_m.shape[:-1], u.shape[:-1])
        wi = np.broadcast_to(wi_m, shape + (3,)).reshape(-1, 3).copy()
        uu = np.broadcast_to(u, shape + (2,)).reshape(-1, 2)
        wo_out = np.zeros_like(wi)
        wo_out[:, 2] = 1.0
        pdf_out = np.zeros(wi.shape[0])
        active = wi[:, 2] > 0
        if active.any():
            wi, uu = wi[active], uu[active]
            fx, fy = self._fold(wi)
            wi[:, 0] *= fx
            wi[:, 1] *= fy
            theta_i, phi_i = elevation(wi), np.arctan2(wi[:, 1], wi[:, 0])
            corners = self._vndf.corners([phi_i, theta_i])
            s, lum_pdf = self._luminance.sample(uu[:, ::-1], corners)
            u_m, ndf_pdf = self._vndf.sample(s, corners)
            phi_m, theta_m = u_to_phi(u_m[:, 1]), u_to_theta(u_m[:, 0])
            if self.isotropic:
                phi_m = phi_m + phi_i
            st = np.sin(theta_m)
            m = np.stack([np.cos(phi_m) * st, np.sin(phi_m) * st, np.cos(theta_m)], -1)
            dot = np.sum(wi * m, -1)
            jac = np.maximum(2 * np.pi ** 2 * u_m[:, 0] * st, 1e-6) * 4 * dot
            wo = m * (2 * dot)[:, None] - wi
            wo[:, 0] *= fx
            wo[:, 1] *= fy
            with np.errstate(divide="ignore", invalid="ignore"):
                p = ndf_pdf * lum_pdf / jac
            ok = (wo[:, 2] > 0) & np.isfinite(p) & (p > 0)
            wo_out[active] = wo
            pdf_out[active] = np.where(ok, p, 0.0)
        return wo_out.reshape(shape + (3,)), pdf_out.reshape(shape)

    def sample(self, wi, u) -> tuple[np.ndarray, np.ndarray]:
        """Importance-sample ``wo`` given ``wi`` as Mitsuba's ``Measured::sample`` does.

        Mitsuba samples the light direction given ``si.wi`` ∝ f·cos of the sampled
        direction; by reciprocity the same warp, fed our ``wi`` as ``si.wi``, samples our
        ``wo`` ∝ f_r(wi, wo) cos θo. ``pdf`` is the solid-angle density (0 if invalid).
        """
        return self.sample_mitsuba(wi, u)

    def pdf(self, wi, wo) -> np.ndarray:
        """Solid-angle density of :meth:`sample` (``Measured::pdf`` with si.wi = ``wi``)."""
        return self.pdf_mitsuba(wi, wo)

    def eval(self, wi, wo) -> np.ndarray:
        """f_r(wi, wo) in 1/sr, RGB ``(..., 3)``: ``Measured::eval(si.wi=wo, wo=wi) / cos θi``.

        In ``Measured::eval``: fold (wi, wo) by the symmetry ``reduction`` (anisotropic files);
        ωm = normalize(si.wi + wo); u_wi = (theta2u θ(si.wi), phi2u φ(si.wi)),
        u_m = (theta2u θm, phi2u(φm − φ(si.wi)) for isotropic files, else phi2u φm) mod 1;
        sample = vndf.invert(u_m | φ(si.wi), θ(si.wi)); value = rgb.eval(sample | φ, θ, channel),
        times ``ndf.eval(u_m) / (4 sigma.eval(u_wi))`` when ``jacobian`` is set. That value is
        f_r · cos θ(wo), with Mitsuba's wo being our ``wi``: we divide by cos θi.

        Deliberate deviation: negative values are clamped to 0 (some RGB tables hold small
        negative texels, e.g. 21 % of ``chm_mint_rgb``'s, from out-of-gamut colour conversion;
        Mitsuba returns them unclamped, see :meth:`eval_mitsuba`). Where the tabulated value
        does not vanish at grazing light (cos θi → 0), f_r grows like 1/cos θi (not clamped);
        results are always finite.
        """
        wi, wo = _as_dirs(wi, wo)
        val = self.eval_mitsuba(wo, wi)
        cos_i = wi[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            f = val / cos_i[..., None]
        ok = (cos_i > 0)[..., None] & (wo[..., 2] > 0)[..., None] & (f > 0) & np.isfinite(f)
        return np.where(ok, f, 0.0)


class IsotropicRGLBRDF(RGLBRDF, IsotropicBRDF):
    """An isotropic RGL material (``phi_i`` has at most two entries): also offers ``eval_hd``."""


def read_rgl(path, name: str | None = None) -> RGLBRDF:
    """Read an RGL ``.bsdf`` file; returns :class:`IsotropicRGLBRDF` when isotropic.

    Raises :class:`~brdffit.errors.BRDFFormatError` on malformed files (via
    :func:`~brdffit.io.tensorfile.read_tensor_file` and the RGL field checks).
    """
    fields = read_tensor_file(path)
    nphi = fields["phi_i"].size if isinstance(fields.get("phi_i"), np.ndarray) else 0
    cls = IsotropicRGLBRDF if 1 <= nphi <= 2 else RGLBRDF
    try:
        return cls(fields, source=path, name=name)
    except MemoryError:  # tables within the file-size cap but too large for this machine
        raise BRDFFormatError(path, f"expected tables that fit in memory, found "
                                    f"{sum(getattr(v, 'nbytes', 0) for v in fields.values())} "
                                    f"bytes of fields whose warps do not (out of memory)") from None
