"""``brdffit info FILE[:MATERIAL]``: what a BRDF file holds.

Prints the format, isotropy, sample counts (stored samples and invalid ones for tables,
network parameters for Neural-BRDF, table shapes for RGL), the per-channel value range and
the directional albedo (:meth:`brdffit.brdf.BRDF.albedo`) at 0, 30, 60 and 75° incidence;
``--json`` prints the same as one JSON object. A ``.zip`` collection without a material
lists its materials.
"""

from __future__ import annotations

import builtins
import json
import os

import numpy as np

from ..errors import printable
from ..geometry import spherical_to_cartesian
from ..grid import merl_phi_d, merl_theta_d, merl_theta_h
from ..io import resolve_spec
from ..io.nbrdf import list_materials
from ..loading import load

__all__ = ["info_cmd", "summarize", "ALBEDO_ANGLES_DEG"]

ALBEDO_ANGLES_DEG = (0.0, 30.0, 60.0, 75.0)


def _range_of(values, valid) -> dict:
    v = values.reshape(-1, values.shape[-1])
    if valid is not None:
        v = v[valid.reshape(-1)]
    if v.size == 0:
        return {"min": [None] * 3, "max": [None] * 3}
    return {"min": v.min(axis=0).tolist(), "max": v.max(axis=0).tolist()}


def _sampled_values(brdf):
    """Evaluate a BRDF without a stored table on a fixed, deterministic set of configurations;
    returns ``(values, how)``."""
    if getattr(brdf, "isotropic", False):
        # every 3rd MERL sample (θh = 0 included: the specular peak of glossy materials)
        th, td, pd = np.meshgrid(merl_theta_h()[::3], merl_theta_d()[::3], merl_phi_d()[::3],
                                 indexing="ij")
        return brdf.eval_hd(th.ravel(), td.ravel(), pd.ravel()), \
            f"evaluated at {th.size} MERL-grid configurations (every 3rd sample)"
    t = np.radians(np.arange(0.0, 90.0, 5.0))
    p = np.radians(np.arange(0.0, 360.0, 15.0))
    ti, pi, tv, pv = (a.ravel() for a in np.meshgrid(t, p, t, p, indexing="ij"))
    vals = brdf.eval(spherical_to_cartesian(ti, pi), spherical_to_cartesian(tv, pv))
    return vals, f"evaluated at {ti.size} (θi, φi, θv, φv) configurations (5°/15° steps)"


def summarize(brdf, spec=None, *, albedo_samples: int = 65536) -> dict:
    """A JSON-able summary of a BRDF (what ``brdffit info`` prints)."""
    desc = {k: v for k, v in brdf.describe().items()}
    fmt = getattr(brdf, "format", None) or desc.get("format")
    if str(spec or "").startswith("synthetic:"):
        fmt = "synthetic"
    elif fmt is None:
        model = type(brdf).__name__.lower()
        fmt = ("rgl" if "rgl" in model else
               "fit" if str(spec or "").lower().endswith(".npz") else "analytic")
    out = {"spec": None if spec is None else str(spec), "format": fmt,
           "name": getattr(brdf, "name", None), "model": type(brdf).__name__,
           "isotropic": bool(getattr(brdf, "isotropic", False)),
           "source": getattr(brdf, "source", None)}
    counts: dict = {}
    table = None
    if hasattr(brdf, "merl_table"):
        values, valid = brdf.merl_table()
        table = (values, valid)
        counts = {"grid": "MERL 90 θh x 90 θd x 180 φd", "n_samples": int(valid.size),
                  "n_invalid": int(valid.size - np.count_nonzero(valid))}
    elif hasattr(brdf, "utia_table"):
        values, valid = brdf.utia_table()
        table = (values, valid)
        counts = {"grid": "UTIA 6 θi x 48 φi x 6 θv x 48 φv", "n_samples": int(valid.size),
                  "n_invalid": int(valid.size - np.count_nonzero(valid))}
    elif hasattr(brdf, "n_parameters"):
        counts = {"n_parameters": int(brdf.n_parameters), "n_samples": None, "n_invalid": None}
    elif isinstance(getattr(brdf, "fields", None), dict):  # RGL tensor file
        shapes = {k: list(np.shape(v)) for k, v in brdf.fields.items()
                  if isinstance(v, np.ndarray) and k != "description"}
        n = int(np.prod(shapes["rgb"])) // 3 if "rgb" in shapes else None
        counts = {"field_shapes": shapes, "n_samples": n, "n_invalid": None}
        valid = getattr(brdf, "valid", None)
        if isinstance(valid, np.ndarray):  # the file's own 'valid' field, reported as is
            if valid.dtype == np.uint8 and n is not None and valid.size * 8 == n:
                bits = int(np.unpackbits(valid).sum())
                counts["valid_field"] = f"{bits} of the {n} texels set; not used"
                counts["valid_field_meaning"] = ("it marks the texels with wo above the "
                                                 "horizon, or the others")
            else:
                counts["valid_field"] = f"{int(np.count_nonzero(valid))} of {valid.size} set"
    else:
        counts = {"n_samples": None, "n_invalid": None}
    out["samples"] = counts
    out["measured_domain"] = getattr(brdf, "measured_domain", None)
    if table is not None:
        out["value_range"] = _range_of(*table)
        out["value_range_of"] = "stored valid samples"
    else:
        vals, how = _sampled_values(brdf)
        vals = np.asarray(vals, dtype=np.float64)
        finite = np.all(np.isfinite(vals), axis=-1)
        out["value_range"] = _range_of(vals, finite)
        out["value_range_of"] = how
    angles = np.array(ALBEDO_ANGLES_DEG)
    alb = brdf.albedo(np.radians(angles), n_samples=albedo_samples)
    out["albedo"] = {f"{a:g}": np.asarray(row, dtype=np.float64).tolist()
                     for a, row in zip(angles, alb)}
    for key in ("interpolation", "precision", "layers", "description"):
        if key in desc and desc[key] not in (None, ""):
            out[key] = desc[key]
    return out


def _fmt_rgb(v) -> str:
    return "(" + ", ".join("n/a" if x is None else f"{x:.4g}" for x in v) + ")"


def _print_summary(s: dict) -> None:
    """The summary, one line per figure; every string from the file or the user escaped
    (:func:`brdffit.errors.printable`)."""
    def print(line: str) -> None:  # noqa: A001 – every line of this command goes through here
        builtins.print(printable(line))

    print(f"{s['spec']}")
    print(f"  format      {s['format']}  ({s['model']})")
    print(f"  name        {s['name']}")
    print(f"  isotropic   {'yes' if s['isotropic'] else 'no'}")
    c = s["samples"]
    if "grid" in c:
        print(f"  grid        {c['grid']}")
    if c.get("n_samples") is not None:
        inv = "" if c.get("n_invalid") is None else f"  (invalid: {c['n_invalid']})"
        print(f"  samples     {c['n_samples']}{inv}")
    if "n_parameters" in c:
        print(f"  parameters  {c['n_parameters']}  (network; no stored samples)")
    if "valid_field" in c:
        print(f"  valid field {c['valid_field']}")
        if c.get("valid_field_meaning"):
            print(f"              ({c['valid_field_meaning']})")
    if s.get("measured_domain"):
        print(f"  measured    {s['measured_domain']}")
        print("              (fits weight only these directions; errors are computed over them)")
    if "field_shapes" in c:
        print("  fields      " + ", ".join(f"{k}{tuple(v)}" for k, v in c["field_shapes"].items()))
    for key in ("interpolation", "precision"):
        if key in s:
            print(f"  {key:<11} {s[key]}")
    r = s["value_range"]
    print(f"  value range min RGB {_fmt_rgb(r['min'])}, max RGB {_fmt_rgb(r['max'])}")
    print(f"              ({s['value_range_of']})")
    for k, (angle, rgb) in enumerate(s["albedo"].items()):  # one incidence per line: 80 columns
        print(f"  {'albedo' if k == 0 else '':<11} {angle:>2}°: {_fmt_rgb(rgb)}")


def info_cmd(spec: str, as_json: bool = False, albedo_samples: int = 65536) -> None:
    """Run ``brdffit info`` (its options: :func:`brdffit.cli._commands.info`)."""
    kind, path, member = resolve_spec(spec)
    if kind == "nbrdf-collection" and not member:
        names = list_materials(path)
        if as_json:
            print(json.dumps({"spec": spec, "format": "nbrdf-collection",
                              "path": os.fspath(path), "materials": names}))
        else:
            print(printable(f"{spec}: Neural-BRDF collection with {len(names)} materials "
                            f"(use {os.path.basename(spec)}:MATERIAL)"))
            for n in names:
                print(f"  {printable(n)}")
        return
    brdf = load(spec)
    summary = summarize(brdf, spec, albedo_samples=albedo_samples)
    if as_json:
        print(json.dumps(summary, default=str))
    else:
        _print_summary(summary)
