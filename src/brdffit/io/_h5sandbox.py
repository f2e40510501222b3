"""Neural-BRDF HDF5 weights, parsed in an isolated child process.

libhdf5 is a C library that is not memory-safe on hostile files: a single changed byte in a
dataset's object header (its filter-pipeline message retyped to an unknown message type) makes
HDF5 2.0 segfault when the dataset is opened, and other corruptions silently damage its heap
and crash a *later* parse. Python cannot catch either. :func:`parse_network_h5_isolated`
therefore hands the file's bytes to a fresh ``python -I`` child that

* limits itself first (address space 1 GiB, or less if the parent is limited; 5 s of CPU),
* opens the bytes in memory with h5py and validates everything before reading (hard links
  only, datasets stored in the file, IEEE float types, bounded shapes, gzip/shuffle/fletcher32
  only, each chunk inflated here with a cap: :mod:`brdffit.io._limits`),
* returns the weights as an ``.npz`` on its standard output, or the problem on exit status 3.

A crash, a signal, the CPU limit or the wall-clock timeout becomes a
:class:`~brdffit.errors.BRDFFormatError` naming the file. The child is a new interpreter per
file (a crashed or corrupted library state never reaches the next file); it costs about 0.2 s
(imports of NumPy and h5py). This isolates faults (crashes, hangs, memory blowups), it is not a
security sandbox against code execution through a libhdf5 exploit.
"""

from __future__ import annotations

import io
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np

from ..errors import BRDFFormatError
from ._limits import (MAX_LAYER_UNITS, MAX_NETWORK_FILE_BYTES, MAX_NETWORK_LAYERS,
                      MAX_NETWORK_WEIGHTS, describe_exception, h5_child, h5_dataset_shape,
                      h5_hard_child, h5_read_dataset, h5_string_list_attr)

__all__ = ["parse_network_h5", "parse_network_h5_isolated", "CHILD_MEMORY_LIMIT",
           "CHILD_CPU_SECONDS", "CHILD_TIMEOUT"]

#: Address-space limit of the parsing child (bytes).
CHILD_MEMORY_LIMIT = 1 << 30
#: CPU-time limit of the parsing child (seconds): a valid network takes ~0.3 s with imports.
CHILD_CPU_SECONDS = 5
#: Wall-clock limit (seconds), generous for a busy machine: the CPU limit is the real bound.
CHILD_TIMEOUT = 120.0
_PROBLEM = 3   # exit status: the file is bad, standard output holds the problem
_INTERNAL = 4  # exit status: the child itself failed (standard error holds why)

def _layer_names(root, where) -> list[str]:
    names = h5_string_list_attr(root, "layer_names", where, max_len=4 * MAX_NETWORK_LAYERS)
    if not names:
        keys = []
        for k in root.keys():  # link names only: nothing is followed
            if k.startswith("dense"):
                keys.append(k)
                if len(keys) > MAX_NETWORK_LAYERS:
                    raise BRDFFormatError(where, f"expected at most {MAX_NETWORK_LAYERS} Dense "
                                                 f"layers, found more 'dense*' groups")
        names = sorted(keys, key=lambda k: (len(k), k))
    return names


def _weight_datasets(f, where) -> list[tuple[str, object, object]]:
    """``[(layer, kernel dataset, bias dataset)]``, validated, nothing read yet."""
    root = f
    if f.id.links.exists(b"model_weights"):
        root = h5_child(f, "model_weights", where, what="group")
    found = []
    for name in _layer_names(root, where):
        group = h5_child(root, name, where, what="layer group")
        wnames = h5_string_list_attr(group, "weight_names", where, max_len=16)
        if not wnames:
            inner = h5_hard_child(group, name)
            if inner is not None and h5_hard_child(inner, "kernel:0") is not None:
                wnames = [f"{name}/kernel:0", f"{name}/bias:0"]
            else:
                continue  # weightless layer (the exp(y)-1 Lambda)
        kernel = [w for w in wnames if w.endswith("kernel:0")]
        bias = [w for w in wnames if w.endswith("bias:0")]
        if len(kernel) != 1 or len(bias) != 1:
            raise BRDFFormatError(where, f"layer {name!r}: expected one kernel and one bias, "
                                         f"found weights {wnames[:8]}")
        k = h5_child(group, kernel[0], where, what=f"kernel of layer {name!r}")
        b = h5_child(group, bias[0], where, what=f"bias of layer {name!r}")
        found.append((name, k, b))
        if len(found) > MAX_NETWORK_LAYERS:
            raise BRDFFormatError(where, f"expected at most {MAX_NETWORK_LAYERS} Dense layers, "
                                         f"found more")
    if not found:
        raise BRDFFormatError(where, "expected Dense layer weights in the HDF5 file, found none")
    n_in, total = 6, 0
    for name, k, b in found:
        ks = h5_dataset_shape(k, where, f"the kernel of layer {name!r}", ndim=2,
                              max_dim=MAX_LAYER_UNITS, max_elements=MAX_NETWORK_WEIGHTS)
        bs = h5_dataset_shape(b, where, f"the bias of layer {name!r}", ndim=1,
                              max_dim=MAX_LAYER_UNITS, max_elements=MAX_NETWORK_WEIGHTS)
        if ks[0] != n_in or bs != ks[1:]:
            raise BRDFFormatError(where, f"layer {name!r}: expected kernel ({n_in}, n) and bias "
                                         f"(n,), found {ks} and {bs}")
        n_in = ks[1]
        total += ks[0] * ks[1] + bs[0]
    if total > MAX_NETWORK_WEIGHTS:
        raise BRDFFormatError(where, f"expected a network of at most {MAX_NETWORK_WEIGHTS} "
                                     f"weights, found {total}")
    return found


def parse_network_h5(fileobj, where) -> list[tuple[np.ndarray, np.ndarray]]:
    """The validated ``(kernel, bias)`` float64 pairs of a Keras HDF5 file, **in this process**
    (use :func:`parse_network_h5_isolated` for files brdffit did not write)."""
    import h5py

    try:
        with h5py.File(fileobj, "r") as f:
            return [(h5_read_dataset(k, where, f"the kernel of layer {name!r}",
                                     max_raw_bytes=MAX_NETWORK_FILE_BYTES),
                     h5_read_dataset(b, where, f"the bias of layer {name!r}",
                                     max_raw_bytes=MAX_NETWORK_FILE_BYTES))
                    for name, k, b in _weight_datasets(f, where)]
    except BRDFFormatError:
        raise
    except Exception as exc:  # the HDF5 library's errors on a damaged file (OSError, KeyError...)
        raise BRDFFormatError(where, f"expected Keras HDF5 weights, could not read them "
                                     f"({describe_exception(exc)})") from None


# -- the child ----------------------------------------------------------------------------
_BOOT = """\
import resource, sys
for lim, val in ((resource.RLIMIT_AS, int(sys.argv[2])), (resource.RLIMIT_CPU, int(sys.argv[3]))):
    soft, hard = resource.getrlimit(lim)
    new = val if soft == resource.RLIM_INFINITY else min(soft, val)
    if hard != resource.RLIM_INFINITY:
        new = min(new, hard)
    resource.setrlimit(lim, (new, hard))
sys.path.insert(0, sys.argv[1])
from brdffit.io._h5sandbox import _child_main
_child_main()
"""


def _child_main() -> None:  # pragma: no cover  (runs in the child; covered by the tests)
    out = sys.stdout.buffer
    try:
        blob = sys.stdin.buffer.read(MAX_NETWORK_FILE_BYTES + 1)
        if len(blob) > MAX_NETWORK_FILE_BYTES:
            raise BRDFFormatError(None, f"expected at most {MAX_NETWORK_FILE_BYTES} bytes, "
                                        f"found more")
        layers = parse_network_h5(io.BytesIO(blob), None)
    except BRDFFormatError as exc:
        out.write(exc.problem.encode("utf-8", "backslashreplace"))
        out.flush()
        os._exit(_PROBLEM)
    except BaseException as exc:  # MemoryError under the limit, ...
        out.write(f"expected Keras HDF5 weights, could not read them "
                  f"({describe_exception(exc)})".encode("utf-8", "backslashreplace"))
        out.flush()
        os._exit(_PROBLEM)
    buf = io.BytesIO()
    np.savez(buf, **{f"{kind}{k}": a for k, (kern, bias) in enumerate(layers)
                     for kind, a in (("k", kern), ("b", bias))})
    out.write(buf.getvalue())
    out.flush()
    os._exit(0)


def _package_parent() -> str:
    return str(Path(__file__).resolve().parents[2])


def parse_network_h5_isolated(blob: bytes, where) -> list[tuple[np.ndarray, np.ndarray]]:
    """:func:`parse_network_h5` of ``blob`` (the bytes of an ``.h5`` file) in a child process.

    Raises :class:`~brdffit.errors.BRDFFormatError` naming ``where`` for a bad file, and also
    when the child crashes (signal), exceeds its limits or times out.
    """
    if not sys.executable:  # pragma: no cover  (embedded interpreters)
        return parse_network_h5(io.BytesIO(blob), where)
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
           "MKL_NUM_THREADS": "1"}
    argv = [sys.executable, "-I", "-c", _BOOT, _package_parent(), str(CHILD_MEMORY_LIMIT),
            str(CHILD_CPU_SECONDS)]
    try:
        proc = subprocess.run(argv, input=blob, capture_output=True, timeout=CHILD_TIMEOUT,
                              env=env)
    except subprocess.TimeoutExpired:
        raise BRDFFormatError(where, f"expected Keras HDF5 weights, found a file whose parsing "
                                     f"took more than {CHILD_TIMEOUT:g} s (stopped)") from None
    except OSError as exc:
        raise BRDFFormatError(where, f"expected Keras HDF5 weights, could not start the "
                                     f"isolated HDF5 reader ({describe_exception(exc)})") from None
    if proc.returncode == _PROBLEM:
        raise BRDFFormatError(where, proc.stdout.decode("utf-8", "replace")[:2000])
    if proc.returncode < 0:
        sig = -proc.returncode
        try:
            name = signal.Signals(sig).name
        except ValueError:
            name = f"signal {sig}"
        what = ("ran out of its CPU time" if sig == signal.SIGXCPU
                else f"got the HDF5 reader killed ({name}: out of CPU time or memory)"
                if sig == signal.SIGKILL else f"crashed the HDF5 library ({name})")
        raise BRDFFormatError(where, f"expected Keras HDF5 weights, found a file that {what} "
                                     f"(parsed in an isolated process)")
    if proc.returncode != 0:
        err = proc.stderr.decode("utf-8", "replace").strip().splitlines()
        raise BRDFFormatError(where, f"expected Keras HDF5 weights, the isolated HDF5 reader "
                                     f"failed with status {proc.returncode}"
                                     + (f" ({err[-1][:200]})" if err else ""))
    try:
        with np.load(io.BytesIO(proc.stdout), allow_pickle=False) as z:
            n = len(z.files) // 2
            if len(z.files) != 2 * n or not 0 < n <= MAX_NETWORK_LAYERS:
                raise ValueError(f"{len(z.files)} arrays")
            layers = [(np.asarray(z[f"k{k}"], np.float64), np.asarray(z[f"b{k}"], np.float64))
                      for k in range(n)]
    except Exception as exc:  # pragma: no cover  (a child that does not follow the protocol)
        raise BRDFFormatError(where, f"expected Keras HDF5 weights, the isolated HDF5 reader "
                                     f"returned unreadable output ({describe_exception(exc)})"
                              ) from None
    return layers
