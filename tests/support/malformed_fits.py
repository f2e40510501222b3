"""Generators of malformed fit files (``.npz`` + JSON header) for the robustness suite.

Nothing here is shipped as data: every case *writes* its file into a folder on demand.
:func:`cases` returns :class:`Case` objects — ``name``, ``write(folder) -> path`` and
``mentions`` (phrases the one-line error must contain besides the file name, usually the
field) — iterated by ``tests/io/test_fitfile_malformed.py`` (in process and through the CLI
under a memory limit) and by ``bench/bench_robustness.py``.

Families (``Case.family``):

* ``container`` – not a zip, truncated, empty, no header, foreign or duplicated members,
  encryption/compression flags, a 3 MB member that inflates to 3.2 GB (a deflate bomb), a
  ``.npy`` header declaring a 24 TiB array, sizes that disagree with the ``.npy`` header, a
  corrupt deflate stream, a bad CRC, pickled object arrays, unknown ``.npy`` versions;
* ``header`` – JSON that is not UTF-8, not JSON, not an object (a list), nested 100,000
  deep, 5 MiB long, with a huge integer; wrong or missing ``format``; ``version`` negative,
  zero, a string, ``true``, a float, newer; unknown or non-string ``model``; ``params`` not
  an object;
* ``state`` – a header that lies about the model: α negative, zero, NaN, 1e300, a string or
  ``true``; |ρ| ≥ 1; unknown component kinds; negative, NaN, infinite Fresnel tables (an
  albedo of −1.9); tables of the wrong shape or dtype (int64, complex, float16); negative NPF
  factors; missing or undeclared arrays; malformed per-channel and sum models.

The valid base models are built directly (no fitting), so writing all cases takes well under
a second except the deflate bomb (≈ 0.1 s: its 3 MB stream is assembled from one compressed
block, and its CRC is computed algebraically).
"""

from __future__ import annotations

import dataclasses
import json
import struct
import zlib
from pathlib import Path
from typing import Callable

import numpy as np
from brdffit.microfacet import GGX, MicrofacetBRDF, SchlickFresnel, SumBRDF, TabulatedFresnel
from brdffit.microfacet.fresnel import GeneralizedSchlickFresnel
from brdffit.microfacet.npf_model import (
    D_THETA_H, F_THETA_D, G_THETA, NPFBivariateBRDF, NPFMicrofacetBRDF, NPFNaiveBRDF,
)
from brdffit.microfacet.per_channel import PerChannelBRDF
from brdffit.microfacet.sgd import SGD
from brdffit.microfacet.sgd_model import PerChannelMicrofacetBRDF
from brdffit.microfacet.tabulated import FittedFresnel, TabulatedSlopeDistribution, radial_rule

__all__ = ["Case", "cases", "cli_subset", "write_npz", "write_zip", "valid_fit",
           "BASE_MODELS"]


@dataclasses.dataclass(frozen=True)
class Case:
    """One malformed fit file: ``write(folder)`` creates it and returns its path."""

    name: str
    family: str
    write: Callable[[Path], Path]
    mentions: tuple[str, ...]
    description: str


# ------------------------------------------------------------------------------------------
# valid base models (built directly, no fitting)
# ------------------------------------------------------------------------------------------
def _ggx():
    return MicrofacetBRDF(GGX(0.2, 0.3, 0.1), SchlickFresnel(0.04), diffuse=(0.1, 0.2, 0.3))


def _tab_fresnel():
    t = np.linspace(0.0, np.pi / 2, 90)
    v = 0.05 + 0.95 * (1.0 - np.cos(t))[:, None] ** 5 * np.array([1.0, 0.9, 0.8])
    return MicrofacetBRDF(GGX(0.2), TabulatedFresnel(t, v))


def _tabulated():
    _, _, r, _ = radial_rule(32, "merl")
    p = GGX(0.3).pdf(np.stack([r, np.zeros_like(r)], -1))
    t = np.arange(90) * (np.pi / 180)
    return MicrofacetBRDF(TabulatedSlopeDistribution(p),
                          FittedFresnel(0.1 + 0.9 * (1.0 - np.cos(t))[:, None] ** 5
                                        * np.ones(3)))


def _sgd():
    return MicrofacetBRDF(SGD(0.15, 1.2), GeneralizedSchlickFresnel(0.06, 0.02), diffuse=0.05)


def _npf_tables():
    D = np.exp(-(np.tan(D_THETA_H)[:, None] / np.array([0.2, 0.3, 0.4])) ** 2) + 1e-3
    F = 0.4 + 0.6 * (1.0 - np.cos(F_THETA_D))[:, None] ** 5 * np.ones(3)
    G = (1.0 - 0.4 * (G_THETA / G_THETA[-1]) ** 2)[:, None] * np.ones(3)
    return D, F, G


def _npf():
    D, F, G = _npf_tables()
    return NPFMicrofacetBRDF(D, F, G, [0.05, 0.08, 0.02], [0.6, 0.4, 0.9])


def _npf_naive():
    D, F, _ = _npf_tables()
    return NPFNaiveBRDF(D, F, np.ones((180, 3)), [0.05, 0.08, 0.02], [0.6, 0.4, 0.9])


def _npf_bivariate():
    D, F, _ = _npf_tables()
    return NPFBivariateBRDF(0.5 * D[:, None, :] * F[None, :, :] + 0.03)


def _sum():
    return SumBRDF([MicrofacetBRDF(GGX(0.04), SchlickFresnel(0.9), specular=0.35),
                    MicrofacetBRDF(GGX(0.35), SchlickFresnel((0.95, 0.64, 0.54)), specular=0.6)])


def _per_channel_sgd():
    chans = [{"distribution": GGX(a), "rho_d": 0.1, "rho_s": 0.3, "F0": 0.9, "F1": -0.5}
             for a in (0.1, 0.2, 0.3)]
    return PerChannelMicrofacetBRDF(chans)


def _per_channel_tab():
    return PerChannelBRDF([MicrofacetBRDF(GGX(a), SchlickFresnel(0.5)) for a in (0.1, 0.2, 0.3)])


#: name → factory of the valid models the cases start from (one per fit kind and layout)
BASE_MODELS: dict[str, Callable] = {
    "ggx": _ggx, "tab-fresnel": _tab_fresnel, "tabulated": _tabulated, "sgd": _sgd,
    "npf": _npf, "npf-naive": _npf_naive, "npf-bivariate": _npf_bivariate, "sum": _sum,
    "per-channel-sgd": _per_channel_sgd, "per-channel-tab": _per_channel_tab,
}


def _state(base: str) -> tuple[dict, dict[str, np.ndarray]]:
    """The header and arrays :func:`brdffit.io.fitfile.save_fit` would write for ``base``."""
    model = BASE_MODELS[base]()
    params, arrays = model.to_state()
    header = {"format": "brdffit-fit", "version": 1, "model": model.fit_kind,
              "name": getattr(model, "name", None), "params": params,
              "source": {"spec": None, "sha256": None}, "options": {}, "fit_info": {},
              "brdffit_version": "0.1.0", "created": "2026-01-01T00:00:00+00:00"}
    header = json.loads(json.dumps(header, default=lambda o: np.asarray(o).tolist()))
    return header, {k: np.asarray(v) for k, v in arrays.items()}


def valid_fit(folder, base: str = "tab-fresnel", name: str | None = None) -> Path:
    """Write the valid fit file of base model ``base`` (for fuzzing and as a control)."""
    header, arrays = _state(base)
    return write_npz(Path(folder) / (name or f"valid-{base}.npz"), header, arrays)


# ------------------------------------------------------------------------------------------
# writers that do not validate
# ------------------------------------------------------------------------------------------
def _npy_bytes(arr: np.ndarray) -> bytes:
    import io

    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.asanyarray(arr), allow_pickle=True)
    return buf.getvalue()


def _header_blob(header) -> bytes:
    if isinstance(header, (bytes, bytearray)):
        return bytes(header)
    return json.dumps(header, allow_nan=True).encode("utf-8")


def write_npz(path, header, arrays: dict, *, deflate: bool = False) -> Path:
    """An ``.npz`` like ``numpy.savez``: ``__header__`` (a JSON-able object, or raw bytes
    stored as uint8) plus ``arrays`` (ndarrays, or raw ``bytes`` used as a member's content).
    Nothing is checked; object arrays are pickled."""
    import zipfile

    path = Path(path)
    members = {}
    if header is not None:
        members["__header__.npy"] = _npy_bytes(np.frombuffer(_header_blob(header), np.uint8))
    for k, v in arrays.items():
        members[f"{k}.npy"] = bytes(v) if isinstance(v, (bytes, bytearray)) else _npy_bytes(v)
    method = zipfile.ZIP_DEFLATED if deflate else zipfile.ZIP_STORED
    with zipfile.ZipFile(path, "w", compression=method) as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    return path


def write_zip(path, members: list[dict]) -> Path:
    """A zip written field by field, so that sizes, CRCs and flags can lie.

    Each member: ``name``, ``data`` (the stored bytes: raw, or a raw deflate stream),
    ``method`` (0 stored, 8 deflate...), ``crc``, ``size`` (declared uncompressed size),
    optional ``flags``. Sizes must stay below 4 GiB (no zip64).
    """
    out = bytearray()
    central = bytearray()
    for m in members:
        name = m["name"].encode("utf-8")
        data = m["data"]
        flags, method = m.get("flags", 0), m.get("method", 0)
        crc, size = m["crc"] & 0xFFFFFFFF, m["size"]
        offset = len(out)
        out += struct.pack("<IHHHHHIIIHH", 0x04034B50, 20, flags, method, 0, 0x21,
                           crc, len(data), size, len(name), 0) + name + data
        central += struct.pack("<IHHHHHHIIIHHHHHII", 0x02014B50, 20, 20, flags, method, 0,
                               0x21, crc, len(data), size, len(name), 0, 0, 0, 0, 0,
                               offset) + name
    out += central + struct.pack("<IHHHHIIH", 0x06054B50, 0, 0, len(members), len(members),
                                 len(central), len(out), 0)
    path = Path(path)
    path.write_bytes(bytes(out))
    return path


def _stored(name: str, data: bytes, **kw) -> dict:
    return {"name": name, "data": data, "method": 0, "crc": zlib.crc32(data), "size": len(data),
            **kw}


def _deflated(name: str, data: bytes, **kw) -> dict:
    co = zlib.compressobj(6, zlib.DEFLATED, -15)
    return {"name": name, "data": co.compress(data) + co.flush(), "method": 8,
            "crc": zlib.crc32(data), "size": len(data), **kw}


def _members_of(header, arrays) -> list[dict]:
    out = [_stored("__header__.npy", _npy_bytes(np.frombuffer(_header_blob(header), np.uint8)))]
    out += [_stored(f"{k}.npy", _npy_bytes(v)) for k, v in arrays.items()]
    return out


# -- the deflate bomb ---------------------------------------------------------------------------
def _crc_zeros_operator(chunk: int) -> tuple[list[int], int]:
    """``crc32(zeros(chunk), c) = L(c) ^ k``: the GF(2)-linear part L (as 32 column images)
    and the constant k."""
    z = bytes(chunk)
    k = zlib.crc32(z, 0)
    return [zlib.crc32(z, 1 << i) ^ k for i in range(32)], k


def _apply(cols: list[int], c: int) -> int:
    out = 0
    i = 0
    while c:
        if c & 1:
            out ^= cols[i]
        c >>= 1
        i += 1
    return out


def deflate_bomb_member(name: str, n_float32: int = 800_000_000, chunk: int = 1 << 20) -> dict:
    """A ``.npy`` member of ``n_float32`` zeros (3.2 GB by default) as a ~3 MB deflate stream.

    The stream is one compressed block of ``chunk`` zero bytes, sync-flushed, repeated: the
    compressor's state is the same after each, so the blocks are byte-identical. The CRC is
    exact (computed with the affine GF(2) map of one chunk).
    """
    hdr = _npy_bytes(np.zeros(0, np.float32))
    head = bytearray(hdr)
    # rewrite the shape in the .npy header (same length: pad with spaces)
    text = head[10:].decode("latin1")
    new = text.replace("(0,)", f"({n_float32},)")
    new = new.rstrip("\n").rstrip(" ")
    new = new + " " * (len(text) - 1 - len(new)) + "\n"
    head[10:] = new.encode("latin1")
    total = n_float32 * 4
    co = zlib.compressobj(9, zlib.DEFLATED, -15)
    first = co.compress(bytes(head) + bytes(chunk - len(head))) + co.flush(zlib.Z_SYNC_FLUSH)
    rep = co.compress(bytes(chunk)) + co.flush(zlib.Z_SYNC_FLUSH)
    rep2 = co.compress(bytes(chunk)) + co.flush(zlib.Z_SYNC_FLUSH)
    if rep != rep2:  # pragma: no cover - zlib always reaches a steady state here
        raise RuntimeError("deflate blocks of zeros are not periodic")
    n_full, rest = divmod(total - (chunk - len(head)), chunk)
    n_rep = n_full  # chunks of zeros after the first one
    last = co.compress(bytes(rest)) + co.flush()
    # the two reps already produced count as chunks: emit first + rep * n_rep + last
    data = first + rep * n_rep + last
    crc = zlib.crc32(bytes(head) + bytes(chunk - len(head)))
    cols, k = _crc_zeros_operator(chunk)
    for _ in range(n_rep):
        crc = _apply(cols, crc) ^ k
    crc = zlib.crc32(bytes(rest), crc)
    return {"name": name, "data": data, "method": 8, "crc": crc,
            "size": len(head) + total}


def _npy_with_shape(arr: np.ndarray, shape_text: str) -> bytes:
    """``arr``'s .npy bytes with the header's shape replaced by ``shape_text`` (a lie)."""
    raw = bytearray(_npy_bytes(arr))
    hlen = struct.unpack("<H", raw[8:10])[0]
    text = raw[10:10 + hlen].decode("latin1")
    start = text.index("'shape': ") + len("'shape': ")
    end = text.index(")", start) + 1
    body = text[:start] + shape_text + text[end:]
    body = body.rstrip("\n").rstrip(" ")
    pad = (-(10 + len(body) + 1)) % 64
    body = body + " " * pad + "\n"
    return bytes(raw[:8]) + struct.pack("<H", len(body)) + body.encode("latin1") \
        + bytes(raw[10 + hlen:])


class _Pickled:
    """Unpickling this object would create the file ``MARKER`` in the working directory."""

    MARKER = "PICKLE_EXECUTED"

    def __reduce__(self):
        return (open, (self.MARKER, "w"))


# ------------------------------------------------------------------------------------------
# the cases
# ------------------------------------------------------------------------------------------
def _state_case(name, base, edit, mentions, description, family="state") -> Case:
    def write(folder):
        header, arrays = _state(base)
        edit(header, arrays)
        return write_npz(Path(folder) / f"{name}.npz", header, arrays)
    return Case(name, family, write, tuple(mentions), description)


def _header_case(name, edit, mentions, description, base="ggx") -> Case:
    return _state_case(name, base, edit, mentions, description, family="header")


def _raw_case(name, make, mentions, description, family="container") -> Case:
    def write(folder):
        path = Path(folder) / f"{name}.npz"
        make(path)
        return path
    return Case(name, family, write, tuple(mentions), description)


def _set(path_keys, value):
    def edit(header, arrays):
        obj = header
        for k in path_keys[:-1]:
            obj = obj[k]
        obj[path_keys[-1]] = value
    return edit


def _arr(key, fn):
    def edit(header, arrays):
        arrays[key] = fn(arrays[key])
    return edit


def _container_cases() -> list[Case]:
    C = []

    def valid_bytes(base="tab-fresnel"):
        import tempfile

        with tempfile.TemporaryDirectory() as d:
            return valid_fit(d, base).read_bytes()

    C.append(_raw_case("empty-file", lambda p: p.write_bytes(b""), (".npz",),
                       "a 0-byte file"))
    C.append(_raw_case("not-a-zip", lambda p: p.write_bytes(b"hello, this is not a zip\n" * 40),
                       (".npz",), "text instead of a zip archive"))
    C.append(_raw_case("truncated-half", lambda p: p.write_bytes(valid_bytes()[:len(valid_bytes()) // 2]),
                       (".npz",), "a valid fit file cut in half (no central directory)"))
    C.append(_raw_case("truncated-tail",
                       lambda p: p.write_bytes(valid_bytes()[:-7]), (".npz",),
                       "a valid fit file missing its last 7 bytes"))

    def no_header(p):
        _, arrays = _state("ggx")
        write_npz(p, None, {"x": np.zeros(3)})
    C.append(_raw_case("no-header", no_header, ("__header__",), "an .npz without __header__"))

    def foreign(p):
        header, arrays = _state("ggx")
        m = _members_of(header, arrays) + [_stored("evil.sh", b"rm -rf /\n")]
        write_zip(p, m)
    C.append(_raw_case("foreign-member", foreign, (".npy", "evil.sh"),
                       "a member that is not a .npy array"))

    def dup(p):
        header, arrays = _state("ggx")
        m = _members_of(header, arrays)
        write_zip(p, m + [m[0]])
    C.append(_raw_case("duplicate-member", dup, ("duplicated",), "__header__.npy twice"))

    def many(p):
        header, arrays = _state("ggx")
        m = _members_of(header, arrays)
        m += [_stored(f"t{i}.npy", _npy_bytes(np.zeros(1))) for i in range(300)]
        write_zip(p, m)
    C.append(_raw_case("too-many-members", many, ("members",), "300 extra tiny members"))

    def header_member_with(**fields):
        def make(p):
            header, arrays = _state("ggx")
            m = _members_of(header, arrays)
            m[0].update(fields)
            write_zip(p, m)
        return make
    C.append(_raw_case("encrypted-member", header_member_with(flags=1), ("encrypted",),
                       "the header member flagged as encrypted"))
    C.append(_raw_case("bzip2-member", header_member_with(method=12), ("compression",),
                       "a member claiming bzip2 compression"))

    def bomb(p):
        header, arrays = _state("tab-fresnel")
        m = _members_of(header, {k: v for k, v in arrays.items() if k != "fresnel.values"})
        write_zip(p, m + [deflate_bomb_member("fresnel.values.npy")])
    C.append(_raw_case("deflate-bomb-3GB", bomb, ("fresnel.values.npy", "declares"),
                       "a ~3 MB file whose Fresnel table inflates to 3.2 GB"))

    def lying_small(p):
        # central directory says 1 kB, the deflate stream inflates to 3.2 GB
        header, arrays = _state("tab-fresnel")
        m = _members_of(header, {k: v for k, v in arrays.items() if k != "fresnel.values"})
        b = deflate_bomb_member("fresnel.values.npy", n_float32=50_000_000)
        b["size"] = 1024
        write_zip(p, m + [b])
    C.append(_raw_case("bomb-understated-size", lying_small, ("fresnel.values",),
                       "a 200 MB deflate stream whose directory entry claims 1 kB"))

    def tib(p):
        header, arrays = _state("tab-fresnel")
        arrays["fresnel.values"] = _npy_with_shape(arrays["fresnel.values"],
                                                   "(549755813888, 6)")      # float64: 24 TiB
        write_npz(p, header, arrays)
    C.append(_raw_case("declared-24TiB", tib, ("fresnel.values", "shape"),
                       "a .npy header declaring a 24 TiB float array in a 2 kB member"))

    def tib_generic(p):
        header, arrays = _state("npf")
        arrays["D"] = _npy_with_shape(arrays["D"], "(1099511627776, 6)")   # float32: 24 TiB
        write_npz(p, header, arrays)
    C.append(_raw_case("declared-24TiB-npf", tib_generic, ("'D'", "shape"),
                       "an NPF D table declaring 24 TiB"))

    def size_mismatch(p):
        header, arrays = _state("tab-fresnel")
        raw = _npy_bytes(arrays["fresnel.values"])
        arrays["fresnel.values"] = raw + bytes(4096)       # more data than declared
        write_npz(p, header, arrays)
    C.append(_raw_case("trailing-data", size_mismatch, ("fresnel.values",),
                       "a member holding 4 kB more than its .npy header declares"))

    def short_data(p):
        header, arrays = _state("tab-fresnel")
        raw = _npy_bytes(arrays["fresnel.values"])
        arrays["fresnel.values"] = raw[:-100]
        write_npz(p, header, arrays)
    C.append(_raw_case("short-data", short_data, ("fresnel.values",),
                       "a member 100 bytes shorter than its .npy header declares"))

    def corrupt_deflate(p):
        header, arrays = _state("tab-fresnel")
        m = _members_of(header, {k: v for k, v in arrays.items() if k != "fresnel.values"})
        d = _deflated("fresnel.values.npy", _npy_bytes(arrays["fresnel.values"]))
        data = bytearray(d["data"])
        data[0] = 0xFF                               # BTYPE = 3: an invalid block type
        d["data"] = bytes(data)
        write_zip(p, m + [d])
    C.append(_raw_case("corrupt-deflate", corrupt_deflate, ("fresnel.values",),
                       "a deflate stream with an invalid block type (zlib.error)"))

    def corrupt_deflate_header(p):
        header, arrays = _state("ggx")
        m = _members_of(header, arrays)
        d = _deflated("__header__.npy", m[0]["data"])
        data = bytearray(d["data"])
        data[len(data) // 2:] = b"\xff" * (len(data) - len(data) // 2)
        d["data"] = bytes(data)
        write_zip(p, [d] + m[1:])
    C.append(_raw_case("corrupt-deflate-header", corrupt_deflate_header, ("__header__",),
                       "the header's deflate stream overwritten half-way"))

    def bad_crc(p):
        header, arrays = _state("tab-fresnel")
        m = _members_of(header, arrays)
        for e in m:
            if e["name"] == "fresnel.values.npy":
                data = bytearray(e["data"])
                data[-5] ^= 0x55
                e["data"] = bytes(data)           # CRC kept from the original data
        write_zip(p, m)
    C.append(_raw_case("bad-crc", bad_crc, ("fresnel.values",),
                       "table bytes changed after the CRC was computed"))

    def pickled(p):
        header, arrays = _state("tab-fresnel")
        obj = np.empty(2, dtype=object)
        obj[0] = _Pickled()
        obj[1] = 1.0
        arrays["fresnel.values"] = obj
        write_npz(p, header, arrays)
    C.append(_raw_case("pickled-object-array", pickled, ("fresnel.values", "object"),
                       "an object array whose unpickling would create PICKLE_EXECUTED"))

    def pickled_header(p):
        header, arrays = _state("ggx")
        obj = np.empty(1, dtype=object)
        obj[0] = _Pickled()
        write_npz(p, None, {"__header__": obj, **arrays})
    C.append(_raw_case("pickled-header", pickled_header, ("__header__", "object"),
                       "the header itself is a pickled object array"))

    def fresnel_npy_patched(start: int, data: bytes):
        def make(p):
            header, arrays = _state("tab-fresnel")
            raw = bytearray(_npy_bytes(arrays["fresnel.values"]))
            raw[start:start + len(data)] = data
            arrays["fresnel.values"] = bytes(raw)
            write_npz(p, header, arrays)
        return make
    C.append(_raw_case("bad-npy-magic", fresnel_npy_patched(0, b"NOTNPY"), ("fresnel.values",),
                       "a member without the .npy magic"))
    C.append(_raw_case("npy-version-9", fresnel_npy_patched(6, b"\x09"), ("fresnel.values",),
                       "a .npy header of an unknown format version"))
    C.append(_raw_case("npy-header-code", fresnel_npy_patched(10, b"__import__"),
                       ("fresnel.values",),
                       "a .npy header dictionary replaced by Python code"))

    def header_float(p):
        header, arrays = _state("ggx")
        blob = np.frombuffer(json.dumps(header).encode(), np.uint8).astype(np.float64)
        write_npz(p, None, {"__header__": blob, **arrays})
    C.append(_raw_case("header-float64", header_float, ("__header__",),
                       "the header stored as float64 instead of uint8"))

    def header_huge(p):
        header, arrays = _state("ggx")
        header["fit_info"] = {"log": "x" * (5 << 20)}
        write_npz(p, header, arrays)
    C.append(_raw_case("header-5MiB", header_huge, ("header",),
                       "a valid header padded to 5 MiB", family="header"))
    return C


def _header_cases() -> list[Case]:
    C = []

    def raw_case(name, blob, mentions, description):
        def write(folder):
            _, arrays = _state("ggx")
            return write_npz(Path(folder) / f"{name}.npz", blob, arrays)
        return Case(name, "header", write, tuple(mentions), description)

    C.append(raw_case("header-not-utf8", b"\xff\xfe{\"format\": 1}", ("UTF-8",),
                      "header bytes that are not UTF-8"))
    C.append(raw_case("header-not-json", b"{format: brdffit-fit", ("JSON",),
                      "header text that is not JSON"))
    C.append(raw_case("header-json-list", b"[1, 2, 3]", ("JSON object", "list"),
                      "a header that is a JSON list (AttributeError before)"))
    C.append(raw_case("header-json-string", b"\"brdffit-fit\"", ("JSON object",),
                      "a header that is a JSON string"))
    C.append(raw_case("header-nested-100k", b"[" * 100000 + b"]" * 100000, ("JSON",),
                      "a header nested 100,000 levels deep"))
    deep = json.dumps({"format": "brdffit-fit", "version": 1, "model": "microfacet",
                       "params": {}, "fit_info": {}})[:-1] + ', "x": ' + "[" * 200 + "]" * 200 + "}"
    C.append(raw_case("header-nested-200", deep.encode(), ("nested",),
                      "a header with a list nested 200 levels deep"))
    C.append(raw_case("header-huge-int", b'{"format": "brdffit-fit", "version": 1' + b"0" * 50000
                      + b"}", ("JSON",), "a 50,000-digit version number"))
    C.append(_header_case("format-missing", lambda h, a: h.pop("format"), ("format",),
                          "no format key"))
    C.append(_header_case("format-unknown", _set(["format"], "pickle-fit"), ("format",),
                          "an unknown format name"))
    for name, v in (("negative", -3), ("zero", 0), ("string", "1"), ("true", True),
                    ("float", 1.0), ("null", None), ("list", [1])):
        C.append(_header_case(f"version-{name}", _set(["version"], v), ("version",),
                              f"version {v!r}"))
    C.append(_header_case("version-newer", _set(["version"], 99), ("version", "newer"),
                          "a version from the future"))
    C.append(_header_case("model-unknown", _set(["model"], "os.system"), ("model", "os.system"),
                          "an unknown model kind"))
    C.append(_header_case("model-not-string", _set(["model"], ["microfacet"]), ("model",),
                          "a model kind that is a list"))
    C.append(_header_case("params-list", _set(["params"], [1, 2]), ("params",),
                          "params that are a list"))
    C.append(_header_case("fit-info-string", _set(["fit_info"], "oops"), ("fit_info",),
                          "fit_info that is a string"))
    return C


def _state_cases() -> list[Case]:
    C = []
    A = ["params", "distribution", "params", "alpha_x"]
    fa = "params.distribution.params.alpha_x"
    for name, v in (("negative", -1), ("zero", 0), ("nan", float("nan")), ("1e300", 1e300),
                    ("string", "0.3"), ("true", True), ("inf", float("inf"))):
        C.append(_state_case(f"alpha-{name}", "ggx", _set(A, v), (fa,), f"GGX alpha_x = {v!r}"))
    C.append(_state_case("rho-one", "ggx", _set(["params", "distribution", "params", "rho"], 1.0),
                         ("params.distribution.params.rho",), "GGX correlation rho = 1"))
    C.append(_state_case("rho-minus-1.5", "ggx",
                         _set(["params", "distribution", "params", "rho"], -1.5),
                         ("params.distribution.params.rho",), "GGX correlation rho = -1.5"))
    C.append(_state_case("distribution-kind-unknown", "ggx",
                         _set(["params", "distribution", "kind"], "evil"),
                         ("params.distribution.kind", "evil"), "unknown distribution kind"))
    C.append(_state_case("distribution-missing", "ggx",
                         lambda h, a: h["params"].pop("distribution"),
                         ("params.distribution",), "no distribution"))
    C.append(_state_case("schlick-f0-2", "ggx", _set(["params", "fresnel", "params", "f0"], 2.0),
                         ("params.fresnel.params.f0",), "Schlick F0 = 2"))
    C.append(_state_case("diffuse-negative", "ggx", _set(["params", "diffuse"], [0.1, -0.2, 0.3]),
                         ("params.diffuse[1]",), "a negative diffuse albedo"))
    C.append(_state_case("diffuse-4-channels", "ggx", _set(["params", "diffuse"], [0.1] * 4),
                         ("params.diffuse",), "a diffuse albedo with 4 channels"))
    C.append(_state_case("correlated-string", "ggx", _set(["params", "correlated"], "yes"),
                         ("params.correlated",), "correlated = 'yes'"))
    fv = "'fresnel.values'"
    C.append(_state_case("fresnel-negative", "tab-fresnel",
                         _arr("fresnel.values", lambda v: -1.9 * np.ones_like(v)), (fv, "minimum"),
                         "a Fresnel table of -1.9 everywhere (albedo < 0)"))
    C.append(_state_case("fresnel-nan", "tab-fresnel",
                         _arr("fresnel.values", lambda v: np.where(np.arange(v.shape[0])[:, None] == 7,
                                                                   np.nan, v)),
                         (fv, "NaN"), "a NaN in the Fresnel table"))
    C.append(_state_case("fresnel-inf", "tab-fresnel",
                         _arr("fresnel.values", lambda v: v + np.inf), (fv,),
                         "an infinite Fresnel table"))
    C.append(_state_case("fresnel-huge", "tab-fresnel",
                         _arr("fresnel.values", lambda v: v * 1e30), (fv, "maximum"),
                         "a Fresnel table of 1e30"))
    C.append(_state_case("fresnel-shape", "tab-fresnel",
                         _arr("fresnel.values", lambda v: np.ones((90, 4))), (fv, "shape"),
                         "a Fresnel table with 4 channels"))
    C.append(_state_case("fresnel-grid-mismatch", "tab-fresnel",
                         _arr("fresnel.values", lambda v: v[:45]), (fv, "shape"),
                         "45 Fresnel values for a 90-point grid"))
    C.append(_state_case("fresnel-int64", "tab-fresnel",
                         _arr("fresnel.values", lambda v: np.ones(v.shape, np.int64)), (fv, "dtype"),
                         "an int64 Fresnel table"))
    C.append(_state_case("fresnel-complex", "tab-fresnel",
                         _arr("fresnel.values", lambda v: v.astype(np.complex128)), (fv, "dtype"),
                         "a complex Fresnel table"))
    C.append(_state_case("fresnel-grid-decreasing", "tab-fresnel",
                         _arr("fresnel.theta_d", lambda t: t[::-1].copy()),
                         ("'fresnel.theta_d'", "increasing"), "a decreasing θd grid"))
    C.append(_state_case("fresnel-missing-array", "tab-fresnel",
                         lambda h, a: a.pop("fresnel.values"), (fv, "missing"),
                         "the Fresnel values array is absent"))
    C.append(_state_case("extra-array", "ggx",
                         lambda h, a: a.update(payload=np.zeros(10)), ("'payload'", "unexpected"),
                         "an array that no schema declares"))
    C.append(_state_case("fitted-fresnel-negative", "tabulated",
                         _arr("fresnel.values", lambda v: v - 3.0), (fv,),
                         "a negative extracted Fresnel of a tabulated fit"))
    C.append(_state_case("tabulated-p-negative", "tabulated",
                         _arr("distribution.P", lambda p: -p), ("'distribution.P'",),
                         "a negative tabulated slope PDF"))
    C.append(_state_case("tabulated-p-zero", "tabulated",
                         _arr("distribution.P", lambda p: np.zeros_like(p)), ("'distribution.P'",),
                         "an all-zero tabulated slope PDF"))
    C.append(_state_case("tabulated-p-3d", "tabulated",
                         _arr("distribution.P", lambda p: np.ones((4, 4, 4), np.float32)),
                         ("'distribution.P'", "shape"), "a 3D slope PDF"))
    C.append(_state_case("tabulated-p-huge", "tabulated",
                         _arr("distribution.P", lambda p: np.ones(100_000, np.float32)),
                         ("'distribution.P'", "shape"), "100,000 radial nodes (slow to load)"))
    C.append(_state_case("tabulated-rule-unknown", "tabulated",
                         _set(["params", "distribution", "params", "rule"], "evil"),
                         ("params.distribution.params.rule",), "an unknown radial rule"))
    C.append(_state_case("tabulated-alpha-negative", "tabulated",
                         _set(["params", "distribution", "params", "alpha_x"], -2.0),
                         ("params.distribution.params.alpha_x",), "a negative table roughness"))
    C.append(_state_case("sgd-p-huge", "sgd", _set(["params", "distribution", "params", "p"], 1e9),
                         ("params.distribution.params.p",), "SGD p = 1e9"))
    C.append(_state_case("sgd-alpha-negative", "sgd",
                         _set(["params", "distribution", "params", "alpha"], -0.1),
                         ("params.distribution.params.alpha",), "SGD alpha < 0"))
    C.append(_state_case("schlick-F1-nan", "sgd",
                         _set(["params", "fresnel", "params", "F1"], [0.1, float("nan"), 0.1]),
                         ("params.fresnel.params.F1[1]",), "a NaN in the generalised Schlick F1"))
    for key in ("D", "F", "G"):
        C.append(_state_case(f"npf-{key}-negative", "npf", _arr(key, lambda v: v - 2.0),
                             (f"'{key}'", "minimum"), f"a negative NPF {key} factor"))
    C.append(_state_case("npf-rho-nan", "npf", _arr("rho", lambda v: v * np.nan), ("'rho'", "NaN"),
                         "NaN albedos"))
    C.append(_state_case("npf-rho-shape", "npf", _arr("rho", lambda v: v[:1]), ("'rho'", "shape"),
                         "rho without ρs"))
    C.append(_state_case("npf-G-shape", "npf", _arr("G", lambda v: v[:45]), ("'G'", "shape"),
                         "45 G samples"))
    C.append(_state_case("npf-D-float16", "npf", _arr("D", lambda v: v.astype(np.float16)),
                         ("'D'", "dtype"), "a float16 D table"))
    C.append(_state_case("npf-F-missing", "npf", lambda h, a: a.pop("F"), ("'F'", "missing"),
                         "no F table"))
    C.append(_state_case("npf-variant-object", "npf", _set(["params", "variant"], {"x": 1}),
                         ("params.variant",), "variant that is an object"))
    C.append(_state_case("naive-H-shape", "npf-naive", _arr("H", lambda v: v[:90]), ("'H'", "shape"),
                         "90 instead of 180 H samples"))
    C.append(_state_case("bivariate-B-shape", "npf-bivariate",
                         _arr("B", lambda v: np.ones((90, 90, 4), np.float32)), ("'B'", "shape"),
                         "a 4-channel bivariate table"))
    C.append(_state_case("bivariate-B-negative", "npf-bivariate", _arr("B", lambda v: v - 1.0),
                         ("'B'", "minimum"), "a negative bivariate table"))
    C.append(_state_case("sum-empty", "sum", _set(["params", "components"], []),
                         ("params.components",), "a sum of no lobes"))
    C.append(_state_case("sum-unknown-component", "sum",
                         _set(["params", "components", 0, "model"], "evil"),
                         ("params.components[0].model",), "a lobe of an unknown kind"))
    C.append(_state_case("sum-lobe-alpha-negative", "sum",
                         _set(["params", "components", 1, "params", "distribution", "params",
                               "alpha_x"], -0.3),
                         ("params.components[1].params.distribution.params.alpha_x",),
                         "a negative α in the second lobe"))
    def nested_sum(header, arrays):
        lobe = _state("ggx")[0]["params"]

        def nest(level):
            if level == 0:
                return {"model": "microfacet", "params": lobe}
            return {"model": "microfacet_sum",
                    "params": {"components": [nest(level - 1) for _ in range(16)]}}
        header["params"] = nest(3)["params"]
        arrays.clear()
    C.append(_state_case("sum-4096-lobes", "sum", nested_sum, ("params.components", "lobes"),
                         "sums of sums of 16 lobes each: 4096 lobes in a 1.2 MB header"))
    C.append(_state_case("per-channel-rho-d-negative", "per-channel-sgd",
                         _set(["params", "channels", 0, "rho_d"], -0.5),
                         ("params.channels[0].rho_d",), "a negative per-channel ρd"))
    C.append(_state_case("per-channel-F0-2", "per-channel-sgd",
                         _set(["params", "channels", 2, "F0"], 2.0),
                         ("params.channels[2].F0",), "a Fresnel F0 of 2"))
    C.append(_state_case("per-channel-two-channels", "per-channel-sgd",
                         lambda h, a: h["params"]["channels"].pop(),
                         ("params.channels",), "two channels instead of three"))
    C.append(_state_case("per-channel-g1-string", "per-channel-sgd",
                         _set(["params", "g1"], "exec"), ("params.g1",), "g1 = 'exec'"))
    C.append(_state_case("per-channel-tab-two-models", "per-channel-tab",
                         lambda h, a: h["params"]["models"].pop(), ("params.models",),
                         "a per-channel tabulated fit with two models"))
    C.append(_state_case("per-channel-tab-alpha-nan", "per-channel-tab",
                         _set(["params", "models", 1, "distribution", "params", "alpha_y"],
                              float("nan")),
                         ("params.models[1].distribution.params.alpha_y",),
                         "NaN roughness in the green channel"))
    return C


def cases() -> list[Case]:
    """Every malformed fit file case (container, header and state families)."""
    return _container_cases() + _header_cases() + _state_cases()


#: names of a representative subset run through the CLI (each family, the worst offenders)
CLI_SUBSET = ("deflate-bomb-3GB", "declared-24TiB", "corrupt-deflate", "pickled-object-array",
              "truncated-half", "header-json-list", "header-nested-100k", "header-5MiB",
              "version-true", "version-negative", "alpha-1e300", "alpha-string",
              "fresnel-negative", "npf-D-float16", "sum-lobe-alpha-negative")


def cli_subset() -> list[Case]:
    """The :data:`CLI_SUBSET` cases (≤ 15), in that order."""
    by_name = {c.name: c for c in cases()}
    return [by_name[n] for n in CLI_SUBSET]
