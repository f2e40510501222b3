"""Neural-BRDF networks (Sztrajman, Rainer, Ritschel, Weyrich, CGF 2021) evaluated with NumPy.

Each network is a Keras ``Sequential`` model saved as HDF5 weights (``.h5``), with an optional
``.json`` sidecar holding the Keras model description (layers, units, activations). The
published networks are ``Dense(6→21, ReLU) → Dense(21→21, ReLU) → Dense(21→3, linear)``
followed by a ``Lambda`` computing ``exp(y) − 1``. Weights live at
``dense_k/dense_k/kernel:0`` (shape in×out) and ``dense_k/dense_k/bias:0``.

The input is the pair of Rusinkiewicz half and difference vectors with φh = 0,
``(sin θh, 0, cos θh, sin θd cos φd, sin θd sin φd, cos θd)``; the output is the RGB BRDF
value (not cosine-weighted) in MERL units after colour scaling. Outputs are clamped at 0
(the networks can return slightly negative values where the BRDF is near zero).

The networks are evaluated as they are, over the full φd range [0, 2π): they are not exactly
reciprocal (for ``merl_nbrdf.zip`` the median relative difference between φd and φd + π is
3-6 %), so :func:`brdffit.io.merl.resample_to_merl` sees the [0, π) half only. No
symmetrisation is applied.

Collections (``merl_nbrdf.zip``…) are read in memory, never extracted to disk.

Files are untrusted (:mod:`brdffit.io._limits`): files and zip members are capped in size
(also while inflating), member names that are absolute, contain ``..`` or control characters
are never used, a material stored twice is refused, and the HDF5 weights are parsed in an
isolated child process (:mod:`brdffit.io._h5sandbox`: libhdf5 can crash on a hostile file)
that accepts only datasets stored in the file (no external storage, virtual datasets, external
or soft links), of float type and bounded shape, checked before anything is read.
"""

from __future__ import annotations

import difflib
import json
import zipfile
from pathlib import Path, PurePosixPath

import numpy as np

from ..brdf import IsotropicBRDF
from ..errors import BRDFFormatError
from ._limits import (MAX_NETWORK_FILE_BYTES, MAX_NETWORK_LAYERS, MAX_SIDECAR_BYTES,
                      describe_exception, open_zip, read_file_capped, read_zip_member,
                      unsafe_member_reason)

__all__ = ["NBRDF", "read_nbrdf", "read_nbrdf_collection", "list_materials"]

_ACTIVATIONS = ("relu", "linear")

from .._jit import lazy_numba
from ._h5sandbox import parse_network_h5_isolated
from .merl import fast_half_diff

_numba = lazy_numba()  # Numba imported on the first compiled call (brdffit._jit)


def _dense_t(w, b, x, relu):  # pragma: no cover  (compiled by numba)
    """``relu?(w @ x + b)`` with samples on the last (contiguous, SIMD-friendly) axis."""
    nout, nin = w.shape
    m = x.shape[1]
    out = np.empty((nout, m), dtype=x.dtype)
    for j in range(nout):
        bj = b[j]
        for s in range(m):
            out[j, s] = bj
        for i in range(nin):
            wji = w[j, i]
            for s in range(m):
                out[j, s] += wji * x[i, s]
        if relu:
            for s in range(m):
                if out[j, s] < 0:
                    out[j, s] = 0
    return out


def _inputs_t(th, td, pd, xt):  # pragma: no cover  (compiled by numba)
    """Network inputs, one column per sample (see :meth:`NBRDF.eval_hd`)."""
    for s in range(th.shape[0]):
        sd = np.sin(td[s])
        xt[0, s] = np.sin(th[s])
        xt[1, s] = 0.0
        xt[2, s] = np.cos(th[s])
        xt[3, s] = sd * np.cos(pd[s])
        xt[4, s] = sd * np.sin(pd[s])
        xt[5, s] = np.cos(td[s])


def _finish(yt, out):  # pragma: no cover  (compiled by numba)
    """``out[s, c] = max(exp(y[c, s]) − 1, 0)`` in float64; NaN/inf → 0."""
    for s in range(yt.shape[1]):
        for c in range(3):
            v = np.expm1(np.float64(yt[c, s]))
            out[s, c] = v if (v > 0 and v < np.inf) else 0.0


if _numba is not None:
    _inputs_t = _numba.njit(cache=True, nogil=True)(_inputs_t)
    _finish = _numba.njit(cache=True, nogil=True)(_finish)
    # fastmath only lets the sums vectorise (reassociation); no transcendental is involved
    _dense_t = _numba.njit(cache=True, nogil=True, fastmath=True)(_dense_t)
else:  # pragma: no cover  (vectorised NumPy fall-backs)
    def _inputs_t(th, td, pd, xt):
        sd = np.sin(td)
        xt[:] = [np.sin(th), np.zeros_like(th), np.cos(th), sd * np.cos(pd), sd * np.sin(pd),
                 np.cos(td)]

    def _finish(yt, out):
        v = np.expm1(yt.T.astype(np.float64))
        out[:] = np.where(np.isfinite(v) & (v > 0), v, 0.0)


_DEFAULT_ACTIVATIONS = ["relu", "relu", "linear"]
_CHUNK = 1 << 14


class NBRDF(IsotropicBRDF):
    """An isotropic BRDF represented by a Neural-BRDF multilayer perceptron.

    Parameters
    ----------
    layers:
        ``[(kernel (in, out), bias (out,), activation), ...]`` with activations ``"relu"`` or
        ``"linear"``; the first layer takes 6 inputs, the last returns 3 outputs.
    precision:
        ``"float32"`` (default, the precision the networks were trained in) or ``"float64"``
        for the matrix products.
    """

    format = "nbrdf"

    def __init__(self, layers, *, name: str = "nbrdf", source: str | None = None,
                 precision: str = "float32"):
        if precision not in ("float32", "float64"):
            raise ValueError(f"precision must be 'float32' or 'float64', got {precision!r}")
        self._merl_grid_memo: list = []     # the weights never change: tabulate once (grid.py)
        checked = []
        n_in = 6
        for k, (kernel, bias, act) in enumerate(layers):
            kernel = np.asarray(kernel, dtype=np.float64)
            bias = np.asarray(bias, dtype=np.float64)
            if kernel.ndim != 2 or kernel.shape[0] != n_in or bias.shape != kernel.shape[1:]:
                raise BRDFFormatError(source, f"layer {k + 1}: expected kernel ({n_in}, n) and bias "
                                              f"(n,), found {kernel.shape} and {bias.shape}")
            if act not in _ACTIVATIONS:
                raise BRDFFormatError(source, f"layer {k + 1}: expected activation in "
                                              f"{_ACTIVATIONS}, found {act!r}")
            if not (np.isfinite(kernel).all() and np.isfinite(bias).all()):
                raise BRDFFormatError(source, f"layer {k + 1}: expected finite weights, found NaN/inf")
            checked.append((kernel, bias, act))
            n_in = kernel.shape[1]
        if not checked or n_in != 3:
            raise BRDFFormatError(source, f"expected a network with 6 inputs and 3 outputs, "
                                          f"found {len(checked)} layers ending with {n_in} outputs")
        self.layers = checked
        self.precision = precision
        self.name = name
        self.source = source

    @property
    def n_parameters(self) -> int:
        return int(sum(k.size + b.size for k, b, _ in self.layers))

    def _weights(self):
        dtype = np.float32 if self.precision == "float32" else np.float64
        cache = getattr(self, "_cast", None)
        if cache is None or cache[0] != dtype:
            cache = (dtype, [(np.ascontiguousarray(k.T, dtype=dtype), b.astype(dtype), a == "relu")
                             for k, b, a in self.layers])
            self._cast = cache
        return cache

    def _forward_t(self, xt: np.ndarray) -> np.ndarray:
        """MLP output ``(3, m)`` for inputs ``(6, m)`` (before ``exp(y) − 1``).

        Samples sit on the contiguous axis. A compiled kernel runs the products when numba
        is available (BLAS is slow for 6- and 21-wide products and oversubscribes a busy
        machine with threads); NumPy matrix products otherwise.
        """
        dtype, layers = self._weights()
        h = np.ascontiguousarray(xt, dtype=dtype)
        if _numba is not None:
            for wt, bias, relu in layers:
                h = _dense_t(wt, bias, h, relu)
            return h
        for wt, bias, relu in layers:
            h = wt @ h
            h += bias[:, None]
            if relu:
                np.maximum(h, 0, out=h)
        return h

    def eval(self, wi, wo) -> np.ndarray:
        """f_r(wi, wo) (Rusinkiewicz conversion compiled when numba is available)."""
        th, td, pd, above = fast_half_diff(wi, wo)
        return np.where(above[..., None], self.eval_hd(th, td, pd), 0.0)

    def eval_hd(self, theta_h, theta_d, phi_d) -> np.ndarray:
        """BRDF at Rusinkiewicz coordinates (radians): ``max(exp(MLP(x)) − 1, 0)``, ``(..., 3)``.

        The network input is ``(sin θh, 0, cos θh, sin θd cos φd, sin θd sin φd, cos θd)``
        (half and difference vectors with φh = 0, as the networks were trained).
        """
        th, td, pd = np.broadcast_arrays(np.asarray(theta_h, np.float64),
                                         np.asarray(theta_d, np.float64),
                                         np.asarray(phi_d, np.float64))
        shape = th.shape
        th, td, pd = th.ravel(), td.ravel(), pd.ravel()
        out = np.empty((th.size, 3))
        dtype = self._weights()[0]
        for s in range(0, th.size, _CHUNK):
            sl = slice(s, s + _CHUNK)
            xt = np.empty((6, th[sl].size), dtype=dtype)
            _inputs_t(th[sl], td[sl], pd[sl], xt)
            _finish(self._forward_t(xt), out[sl])
        return out.reshape(shape + (3,))

    def describe(self) -> dict:
        d = super().describe()
        d.update(format="nbrdf", n_parameters=self.n_parameters, precision=self.precision,
                 layers=[[int(k.shape[0]), int(k.shape[1]), a] for k, _, a in self.layers])
        return d


# -- parsing ------------------------------------------------------------------------------
# Files are untrusted: every size, shape, dtype, storage and link is checked before anything
# is read (see brdffit.io._limits for the caps and the promises); the HDF5 weights are parsed
# in a child process (brdffit.io._h5sandbox).
def _activations_from_json(text: bytes | str, where) -> list[str]:
    """Activations of the Dense layers of a Keras model description; checks the final Lambda."""
    def bad(found: str):
        return BRDFFormatError(where, f"expected a Keras model description (JSON), found {found}")

    try:
        model = json.loads(text)
    except (ValueError, RecursionError) as exc:  # JSONDecodeError, UnicodeDecodeError, depth
        raise bad(describe_exception(exc)) from None
    config = model.get("config") if isinstance(model, dict) else None
    layers = config.get("layers") if isinstance(config, dict) else config
    if not isinstance(layers, list):
        raise bad(f"no list of layers (config is {type(config).__name__})")
    if len(layers) > 4 * MAX_NETWORK_LAYERS:
        raise bad(f"{len(layers)} layers (at most {4 * MAX_NETWORK_LAYERS} expected)")
    acts = []
    for k, layer in enumerate(layers):
        if not isinstance(layer, dict) or not isinstance(layer.get("config", {}), dict):
            raise bad(f"layer #{k} as a {type(layer).__name__}, not an object with a config")
        cls = layer.get("class_name")
        if cls == "Dense":
            act = layer.get("config", {}).get("activation", "linear")
            acts.append(act if isinstance(act, str) else repr(act))
        elif cls not in ("Lambda", "InputLayer"):
            raise BRDFFormatError(where, f"expected Dense layers and a final Lambda, found a "
                                         f"{str(cls)[:60]!r} layer")
    return acts


def _layers_from_h5(blob: bytes, where) -> list[tuple[np.ndarray, np.ndarray]]:
    """The ``(kernel, bias)`` pairs of an HDF5 network, parsed in an isolated child process
    (:func:`brdffit.io._h5sandbox.parse_network_h5_isolated`: libhdf5 can crash on a hostile
    file)."""
    return parse_network_h5_isolated(blob, where)


def _build(layers, acts, *, name, source, precision) -> NBRDF:
    if acts is None:
        acts = _DEFAULT_ACTIVATIONS if len(layers) == 3 else ["relu"] * (len(layers) - 1) + ["linear"]
    if len(acts) != len(layers):
        raise BRDFFormatError(source, f"expected {len(acts)} Dense layers (from the JSON sidecar), "
                                      f"found {len(layers)} in the weights")
    return NBRDF([(k, b, a) for (k, b), a in zip(layers, acts)], name=name, source=source,
                 precision=precision)


def read_nbrdf(path, *, precision: str = "float32") -> NBRDF:
    """Read a Neural-BRDF network from an ``.h5`` file (with its ``.json`` sidecar if present).

    The sidecar, when next to the weights, supplies the layers' activations and is checked
    against the weights; without it the published architecture (ReLU, ReLU, linear) is used.
    The file (at most :data:`~brdffit.io._limits.MAX_NETWORK_FILE_BYTES`) is read in memory
    and validated before any weight is read: only datasets stored in the file, reached by
    hard links, of float type and of bounded shape are accepted.
    """
    path = Path(path)
    blob = read_file_capped(path, "a Neural-BRDF .h5 file", MAX_NETWORK_FILE_BYTES)
    layers = _layers_from_h5(blob, path)
    sidecar = path.with_suffix(".json")
    acts = None
    if sidecar.is_file():
        acts = _activations_from_json(
            read_file_capped(sidecar, "a Keras JSON sidecar", MAX_SIDECAR_BYTES), sidecar)
    return _build(layers, acts, name=path.stem, source=str(path), precision=precision)


def _open_zip(zip_path) -> zipfile.ZipFile:
    return open_zip(zip_path, "a Neural-BRDF .zip collection")


def _index(zf: zipfile.ZipFile):
    """``(materials, unsafe)``: material name -> ``.h5`` members (several when duplicated),
    and material name -> (member, reason) for members whose names are never used."""
    materials: dict[str, list[zipfile.ZipInfo]] = {}
    unsafe: dict[str, tuple[zipfile.ZipInfo, str]] = {}
    for info in zf.infolist():
        p = PurePosixPath(info.filename.replace("\\", "/"))
        if p.suffix != ".h5" or info.is_dir() or "__MACOSX" in p.parts:
            continue
        reason = unsafe_member_reason(info.filename)
        if reason is None and p.stem in ("", ".", ".."):
            reason = f"a material name {p.stem!r}"
        if reason is None:
            materials.setdefault(p.stem, []).append(info)
        else:
            unsafe.setdefault(p.stem, (info, reason))
    return materials, unsafe


def list_materials(zip_path) -> list[str]:
    """Sorted material names (``.h5`` members, without folder or suffix) of a collection.

    Members with unsafe names (absolute, ``..``, control characters) are not listed.
    """
    with _open_zip(zip_path) as zf:
        return sorted(_index(zf)[0])


def read_nbrdf_collection(zip_path, material: str, *, precision: str = "float32") -> NBRDF:
    """Read one network of a ``.zip`` collection in memory by material name.

    ``material`` may be the bare name (``gold-metallic-paint``), or carry the folder and/or the
    ``.h5`` suffix. An unknown name raises :class:`~brdffit.errors.BRDFFormatError` listing
    close matches. Nothing is extracted: members are read in memory with a cap on their
    inflated size; a material stored twice, or only under an unsafe member name (absolute,
    ``..``), is refused.
    """
    zip_path = Path(zip_path)
    key = PurePosixPath(str(material)).name
    if key.endswith(".h5"):
        key = key[:-3]
    with _open_zip(zip_path) as zf:
        materials, unsafe = _index(zf)
        if key not in materials:
            if key in unsafe:
                info, reason = unsafe[key]
                raise BRDFFormatError(zip_path, f"expected a safe member name for material "
                                                f"{key!r}, found the unsafe member "
                                                f"{info.filename!r} ({reason})")
            close = difflib.get_close_matches(key, list(materials), n=5, cutoff=0.5)
            hint = f"; close matches: {', '.join(close)}" if close else ""
            raise BRDFFormatError(zip_path, f"expected a material of this collection "
                                            f"({len(materials)} materials), found no {key!r}{hint}")
        infos = materials[key]
        if len(infos) > 1:
            raise BRDFFormatError(zip_path, f"expected one member for material {key!r}, found "
                                            f"{len(infos)}: {[i.filename for i in infos][:5]}")
        h5info = infos[0]
        where = f"{zip_path}:{key}"
        blob = read_zip_member(zf, h5info, where, MAX_NETWORK_FILE_BYTES)
        js = h5info.filename[:-3] + ".json"
        side = [i for i in zf.infolist() if i.filename == js]
        if len(side) > 1:
            raise BRDFFormatError(zip_path, f"expected one member {js!r}, found {len(side)}")
        sidecar = read_zip_member(zf, side[0], where, MAX_SIDECAR_BYTES) if side else None
    layers = _layers_from_h5(blob, where)
    acts = _activations_from_json(sidecar, where) if sidecar is not None else None
    return _build(layers, acts, name=key, source=where, precision=precision)
