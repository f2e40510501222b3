"""JSON of a fitted model's parameters, with units and conventions, and the way back.

A file written by :func:`write_json` holds

``format``/``version``
    ``"brdffit-params"``, 1.
``conventions``
    How to read the numbers (also in ``docs/conventions.md``): α is the slope-space
    roughness (Walter 2007 / Dupuy 2015 Eq. 9, Mitsuba's ``alpha``; glTF roughness = √α),
    f_r in 1/sr without the cosine, RGB = the linear RGB of the source data, Fresnel tables
    as functions of θd in radians...
``parameters``
    Human-readable parameters per model kind: for a :class:`MicrofacetBRDF` the distribution
    (kind, ``alpha_x``, ``alpha_y``, ``rho``; or SGD ``alpha``, ``p``), the Fresnel (kind,
    parameters, and its value at normal incidence ``F(0°)`` and at 90° per channel), ``rho_d``
    (Lambertian albedo, term ρd/π), ``ks`` (specular scale); per channel for
    ``PerChannelMicrofacetBRDF`` (Bagher 2012 Eq. 1: ρd, ρs, α, p, F0, F1); ρd/ρs per channel
    and table sizes for NPF models (Bagher 2016 Eq. 3).
``state``
    The model's own ``to_state`` output (``params`` and named ``arrays`` as nested lists with
    dtype and shape), from which :func:`load_json` rebuilds the model exactly (JSON floats
    are written with ``repr`` precision, so float32 and float64 tables round-trip bit-exactly).

A hand-written file without ``state`` is accepted for a ``microfacet`` model whose
``parameters`` use the keys above (analytic distributions and Fresnel terms only).

Reading is as careful as for fit files: at most :data:`MAX_JSON_BYTES`, a regular file, the
nesting depth bounded (:data:`MAX_DEPTH`), the version an integer, arrays of numeric dtypes
only, and every model, from ``state`` or from ``parameters``, checked against its schema
(:mod:`brdffit.schema`) before it is used; every message names the file.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from .._atomic import atomic_write
from .._json import strict_json_default
from ..errors import BRDFFormatError, ExportError
from ._common import check_output_path, fail, is_elliptical, label, shown, writing
from ..fit import import_all
from ..io.fitfile import SerializableModel, model_registry
from ..microfacet.model import MicrofacetBRDF, SumBRDF, distribution_from_state, fresnel_from_state
from ..microfacet.npf_model import NPFBivariateBRDF, NPFMicrofacetBRDF, NPFNaiveBRDF
from ..microfacet.sgd_model import PerChannelMicrofacetBRDF
from .. import microfacet as _mf

__all__ = ["to_json_dict", "from_json_dict", "write_json", "load_json", "describe_parameters",
           "CONVENTIONS", "FORMAT"]

FORMAT = "brdffit-params"
VERSION = 1
#: Largest parameter JSON read (a tabulated fit's state is ~0.1 MB; an NPF bivariate ~2 MB).
MAX_JSON_BYTES = 64 << 20
#: Deepest nesting of objects and lists accepted (written files nest 6 levels).
MAX_DEPTH = 32
_NUMERIC_KINDS = "fiub"

CONVENTIONS = {
    "f_r": "BRDF value in 1/sr, NOT multiplied by cos(theta); 0 below the horizon",
    "frame": "local frame, normal = +z, x = tangent (u), both directions pointing away from "
             "the surface",
    "alpha": "slope-space roughness alpha (Walter 2007, Dupuy 2015 Eq. 9; Mitsuba 'alpha', "
             "'alpha_u' = alpha_x, 'alpha_v' = alpha_y); glTF/Disney roughness r = sqrt(alpha)",
    "rho": "slope correlation of the scale matrix S = [[ax^2, rho ax ay], [rho ax ay, ay^2]] "
           "(Dupuy 2015 App. C), dimensionless in (-1, 1)",
    "rgb": "linear RGB of the source data (MERL: its own RGB after the MERL colour scales; "
           "RGL: linear sRGB; synthetic: linear sRGB), no gamma",
    "fresnel": "F(cos theta_d) per channel; tabulated Fresnels are functions of theta_d in "
               "radians (piecewise linear); fitted tables may exceed 1 (they absorb scale)",
    "rho_d": "Lambertian albedo; the diffuse term is rho_d/pi",
    "ks": "RGB scale of the microfacet term (1 when absent)",
    "G": "Smith shadowing: height-correlated 1/(1 + L(i) + L(o)) (Dupuy 2015 Eq. 2) when "
         "'correlated' is true, else G1(i) G1(o)",
    "angles": "radians",
}


# -- human-readable parameters ---------------------------------------------------------------
def _rgb(x) -> list[float] | None:
    return None if x is None else [float(v) for v in np.broadcast_to(np.asarray(x, float), (3,))]


def _distribution_parameters(d) -> dict:
    kind = getattr(d, "kind", type(d).__name__)
    if is_elliptical(d):
        return {"kind": kind, "alpha_x": d.alpha_x, "alpha_y": d.alpha_y, "rho": d.rho,
                "units": "alpha: slope scale (dimensionless); rho: correlation"}
    p = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in d.params().items()}
    kind = p.pop("kind", kind)                   # e.g. "tabulated" (a label, not a number)
    out = {"kind": kind, **p}
    if kind in ("sgd", "sgd_eq9"):
        out["units"] = ("alpha: SGD shape alpha (Bagher 2012 Eq. 8, dimensionless); p: exponent; "
                        "lam, c, k: Eq. 9 G1 approximation")
    if kind in ("tabulated", "tabulated_aniso"):
        try:
            ax, ay, rho = d.ggx_parameters()
            out["ggx_equivalent"] = {"alpha_x": ax, "alpha_y": ay, "rho": rho}
        except Exception:  # noqa: BLE001 - informative only
            pass
    return out


def _fresnel_parameters(f) -> dict | None:
    if f is None:
        return None
    kind = getattr(f, "kind", type(f).__name__)
    p = f.params()
    out = {"kind": kind, **{k: v for k, v in p.items()}}
    out["F_normal"] = _rgb(f.eval(1.0))
    out["F_grazing"] = _rgb(f.eval(0.0))
    if hasattr(f, "theta_d"):
        out["theta_d"] = [float(t) for t in f.theta_d]
        out["values"] = np.asarray(f.values, float).tolist()
    return out


def describe_parameters(model) -> dict:
    """The readable ``parameters`` section for ``model`` (see module docstring)."""
    if isinstance(model, MicrofacetBRDF):
        return {"distribution": _distribution_parameters(model.distribution),
                "fresnel": _fresnel_parameters(model.fresnel),
                "rho_d": _rgb(model.diffuse), "ks": _rgb(model.specular),
                "correlated": bool(model.correlated)}
    if isinstance(model, SumBRDF):
        return {"components": [{"model": getattr(c, "fit_kind", type(c).__name__),
                                **describe_parameters(c)} for c in model.components]}
    if isinstance(model, PerChannelMicrofacetBRDF):
        return {"channels": model.channel_params(), "g1": model.g1,
                "formula": "Bagher 2012 Eq. 1 per channel: rho_d/pi + rho_s F D G1 G1 / "
                           "(pi cos_i cos_o) with F = F0 + (1 - F0)(1 - cos_d)^5 - F1 cos_d"}
    if type(model).__name__ == "PerChannelBRDF":
        return {"channels": [{"channel": "RGB"[c], **describe_parameters(m)}
                             for c, m in enumerate(model.models)],
                "formula": "channel c of the BRDF = channel c of models[c]"}
    if isinstance(model, (NPFMicrofacetBRDF, NPFNaiveBRDF)):
        f = model.factors()
        return {"rho_d": _rgb(f["rho_d"]), "rho_s": _rgb(f["rho_s"]),
                "tables": {k: list(np.shape(v)) for k, v in f.items() if k not in ("rho_d", "rho_s")},
                "formula": "Bagher 2016 Eq. 3/4 (note: rho_d here is the BRDF value, not an albedo)"}
    if isinstance(model, NPFBivariateBRDF):
        return {"tables": {"B": list(model.factors()["B"].shape)}}
    return {}


# -- whole document --------------------------------------------------------------------------
def _encode_array(a: np.ndarray) -> dict:
    a = np.asarray(a)
    if a.dtype.kind not in "fiub":
        raise TypeError(f"cannot encode array of dtype {a.dtype}")
    return {"dtype": a.dtype.str, "shape": list(a.shape), "data": a.ravel().tolist()}


def _decode_array(d, path) -> np.ndarray:
    try:
        dtype = np.dtype(d["dtype"])
        if dtype.kind not in _NUMERIC_KINDS:
            raise ValueError(f"dtype {str(dtype)!r} is not numeric")
        a = np.asarray(d["data"], dtype=dtype)
        return a.reshape(d["shape"])
    except (KeyError, TypeError, ValueError) as exc:
        raise BRDFFormatError(path, f"expected an array entry with dtype, shape and data, "
                                    f"found {type(d).__name__} ({exc})") from None


def to_json_dict(model) -> dict[str, Any]:
    """The JSON document of ``model`` (a :class:`~brdffit.io.fitfile.SerializableModel`)."""
    if not isinstance(model, SerializableModel) or not model.fit_kind:
        fail(model, "json", "only serialisable models (SerializableModel with a fit_kind: "
                            "MicrofacetBRDF, SumBRDF, PerChannelMicrofacetBRDF, PerChannelBRDF, "
                            "NPF models) can be written")
    params, arrays = model.to_state()
    return {"format": FORMAT, "version": VERSION, "conventions": CONVENTIONS,
            "model": model.fit_kind, "class": type(model).__name__,
            "name": getattr(model, "name", None), "source": getattr(model, "source", None),
            "parameters": describe_parameters(model),
            "state": {"params": params,
                      "arrays": {k: _encode_array(v) for k, v in arrays.items()}}}


def write_json(model, path, **_ignored) -> dict:
    """Write the parameters of ``model`` as JSON (atomically); returns a summary."""
    path = check_output_path(path)
    doc = to_json_dict(model)
    try:
        text = json.dumps(doc, indent=1, allow_nan=False, default=strict_json_default)  # ASCII: \u escapes
    except ValueError as exc:
        raise ExportError(f"cannot export {label(model)} to {shown(path)}: expected finite "
                          f"parameters, found NaN or infinity ({exc})") from None
    with writing(path), atomic_write(path, "wb") as fh:
        fh.write(text.encode("ascii"))
    return {"files": [str(path)], "target": "json", "model": doc["model"]}


def _from_parameters(p: dict, path):
    """A MicrofacetBRDF from a hand-written ``parameters`` section (analytic parts only)."""
    try:
        dp = {k: v for k, v in p["distribution"].items() if k not in ("kind", "units",
                                                                     "ggx_equivalent")}
        dist = distribution_from_state({"kind": p["distribution"]["kind"], "params": dp})
        fres = None
        if p.get("fresnel"):
            fp = {k: v for k, v in p["fresnel"].items()
                  if k not in ("kind", "F_normal", "F_grazing", "theta_d", "values", "n")}
            fk = p["fresnel"]["kind"]
            arrays = {}
            if "values" in p["fresnel"]:
                arrays = {"theta_d": np.asarray(p["fresnel"]["theta_d"], float),
                          "values": np.asarray(p["fresnel"]["values"], float)}
            fres = fresnel_from_state({"kind": fk, "params": fp}, arrays)
        model = MicrofacetBRDF(dist, fres, p.get("rho_d"), specular=p.get("ks"),
                               correlated=p.get("correlated", True))
        model.validate()  # the fit-file schema (brdffit.schema), as for a 'state' section
        return model
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise BRDFFormatError(path, f"expected microfacet parameters (distribution kind and "
                                    f"parameters, optional fresnel/rho_d/ks), found an error: "
                                    f"{exc}") from None


def from_json_dict(doc: dict, path=None):
    """Rebuild the model described by a document of :func:`to_json_dict`."""
    import_all()                            # registers the fitted model kinds

    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise BRDFFormatError(path, f"expected a JSON object with format {FORMAT!r}, found "
                                    f"{doc.get('format') if isinstance(doc, dict) else type(doc).__name__!r}")
    version = doc.get("version", 0)
    if not isinstance(version, int) or isinstance(version, bool) or not 0 <= version <= VERSION:
        raise BRDFFormatError(path, f"expected format version an integer in 0..{VERSION}, found "
                                    f"{json.dumps(version)[:40]}")
    kind = doc.get("model")
    state = doc.get("state")
    if not isinstance(kind, str) or not (state is None or isinstance(state, dict)):
        raise BRDFFormatError(path, f"expected a model kind (a string) and a 'state' object, "
                                    f"found {type(kind).__name__} and {type(state).__name__}")
    if state is None:
        if kind != "microfacet":
            raise BRDFFormatError(path, f"expected a 'state' section for model {kind!r} (only "
                                        f"'microfacet' can be rebuilt from 'parameters')")
        m = _from_parameters(doc.get("parameters") or {}, path)
    else:
        reg = model_registry()
        if kind not in reg:
            raise BRDFFormatError(path, f"expected a known model kind {sorted(reg)}, found {kind!r}")
        arrays = {k: _decode_array(v, path) for k, v in (state.get("arrays") or {}).items()}
        try:
            reg[kind].validate_state(state.get("params") or {}, arrays)   # brdffit.schema
            m = reg[kind].from_state(state.get("params") or {}, arrays)
        except (KeyError, TypeError, ValueError) as exc:
            raise BRDFFormatError(path, f"expected a valid {kind!r} state, found an error: {exc}") from None
    for attr in ("name", "source"):
        if doc.get(attr) is not None:
            try:
                setattr(m, attr, doc[attr])
            except AttributeError:  # pragma: no cover
                pass
    return m


def _depth(doc) -> int:
    """Nesting depth of a parsed JSON document (iterative)."""
    deepest, stack = 0, [(doc, 1)]
    while stack:
        node, depth = stack.pop()
        deepest = max(deepest, depth)
        if depth > MAX_DEPTH:
            break
        if isinstance(node, dict):
            stack.extend((v, depth + 1) for v in node.values())
        elif isinstance(node, list):
            stack.extend((v, depth + 1) for v in node if isinstance(v, (dict, list)))
    return deepest


def load_json(path):
    """Rebuild a model from a JSON file of :func:`write_json` (or hand-written, see module
    doc), checked as the module docstring says."""
    import os
    import stat

    path = Path(path)
    try:
        st = os.stat(path)
    except OSError as exc:
        raise BRDFFormatError(path, f"expected a readable file, found none ({exc.strerror})") \
            from None
    if not stat.S_ISREG(st.st_mode):
        raise BRDFFormatError(path, "expected a regular file, found something else (a folder, "
                                    "a device or a FIFO)")
    if st.st_size > MAX_JSON_BYTES:
        raise BRDFFormatError(path, f"expected at most {MAX_JSON_BYTES} bytes of JSON, found "
                                    f"{st.st_size}")
    try:
        with open(path, "rb") as fh:
            text = fh.read(MAX_JSON_BYTES + 1).decode("utf-8")
        doc = json.loads(text)
    except UnicodeDecodeError as exc:
        raise BRDFFormatError(path, f"expected UTF-8 text, found undecodable bytes at "
                                    f"{exc.start}") from None
    except json.JSONDecodeError as exc:
        raise BRDFFormatError(path, f"expected JSON, found a syntax error: {exc}") from None
    except RecursionError:
        raise BRDFFormatError(path, f"expected JSON nested at most {MAX_DEPTH} levels, found "
                                    "deeper nesting") from None
    if _depth(doc) > MAX_DEPTH:
        raise BRDFFormatError(path, f"expected JSON nested at most {MAX_DEPTH} levels, found "
                                    "deeper nesting")
    return from_json_dict(doc, path)
