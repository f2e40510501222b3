"""``brdffit models [--json] [--measure [--on SPEC]]``: the models and what they cost.

One entry per model of :data:`brdffit.fit.registry.MODELS` (read without importing any
fitting module): name, whether it fits isotropic inputs only, the typical size of its fit
file and of the tables inside it, the typical fit time, its one-line description and the
paper. The typical figures are *declared* in the registry, measured by
``bench/bench_cli.py --models`` (its source is printed under the table). ``--measure``
measures them now instead: it fits every model (or ``--models a,b``) to ``--on`` (default
``synthetic:gold-ggx``), saves each fit to a temporary folder and reports the fit-file and
table bytes, the fit's CPU time and the error against the input
(:func:`brdffit.cli.fit.quick_error`). ``--options`` adds each model's fitting options,
read from its options dataclass (:mod:`brdffit.fit.options`): name, type, default, range.
"""

from __future__ import annotations

import json
import sys
import textwrap
import time
from pathlib import Path

from ..fit import registry
from ..fit.registry import options_class
from ..loading import load
from ._checks import check_models

__all__ = ["models_cmd", "model_table", "measure", "model_options"]


def model_table() -> list[dict]:
    """One JSON-able row per known model (declared figures; no fitting module imported)."""
    rows = []
    for name in registry.known_names():
        info = registry.MODELS.get(name) or registry.describe(name)
        rows.append({"name": name, "description": info.description, "paper": info.paper,
                     "references": [registry.PAPERS.get(k.strip(), k.strip())
                                    for k in info.paper.split(",") if k.strip()],
                     "isotropic_only": info.isotropic_only,
                     "fit_file_bytes": info.typical_bytes,
                     "table_bytes": info.typical_table_bytes,
                     "fit_cpu_s": info.typical_time_s, "figures": "declared"})
    return rows


def model_options(name: str) -> list[dict]:
    """The options of model ``name`` a command line may give (``-O key=value``), from its
    options dataclass: ``{"name", "type", "default", "none_ok", "text"}`` per option."""
    from ..fit.options import describe_option, option_table
    cls, _ = options_class(name)
    return [{"name": o.name, "type": o.kind, "default": o.default, "none_ok": o.none_ok,
             "text": describe_option(o)}
            for o in option_table(cls).values() if not o.python_only]


def measure(rows: list[dict], spec: str, say=lambda msg: None) -> list[dict]:
    """Fit every model of ``rows`` to ``spec`` and replace the declared figures by measured
    ones (``figures: "measured on SPEC"``; a model that fails or does not apply says why)."""
    import tempfile

    from ..io.fitfile import save_fit
    from .fit import quick_error

    reference = load(spec)
    out = []
    with tempfile.TemporaryDirectory(prefix="brdffit-models-") as tmp:
        for row in rows:
            row = dict(row, fit_file_bytes=None, table_bytes=None, fit_cpu_s=None,
                       figures=f"measured on {spec}")
            name = row["name"]
            if row["isotropic_only"] and not getattr(reference, "isotropic", False):
                row["error"] = "not measured: fits isotropic inputs only"
                out.append(row)
                continue
            say(f"fitting {name} to {spec} ...")
            try:
                entry = registry.get(name)
                t0 = time.process_time()
                fitted = entry.fit(reference)
                row["fit_cpu_s"] = time.process_time() - t0
                path = Path(tmp) / f"{name}.npz"
                save_fit(fitted, path, source=spec, options={"model": name})
                row["fit_file_bytes"] = path.stat().st_size
                row["table_bytes"] = registry.table_bytes(fitted)
                row["cos_rel_error"] = quick_error(reference, fitted)["cos_rel_error"]
            except Exception as exc:  # noqa: BLE001 - one model failing is a row, not a crash
                row["error"] = f"{type(exc).__name__}: {exc}"
            out.append(row)
    return out


def _num(v, unit: str = "") -> str:
    if v is None:
        return "–"
    if isinstance(v, float):
        return f"{v:.3g}{unit}" if v < 10 else f"{v:.0f}{unit}"
    return f"{v}{unit}"


def format_table(rows: list[dict]) -> list[str]:
    """The text of ``brdffit models`` (80 columns): a line of figures and a line of
    description per model, then its options when the rows have them (``--options``)."""
    lines = [f"{'MODEL':<17}{'ISO':<4}{'FILE B':>8}{'TABLE B':>9}{'FIT CPU':>10}  PAPER"]
    for r in rows:
        lines.append(f"{r['name']:<17}{'yes' if r['isotropic_only'] else 'no':<4}"
                     f"{_num(r['fit_file_bytes']):>8}{_num(r['table_bytes']):>9}"
                     f"{_num(r['fit_cpu_s'], ' s'):>10}  {r['paper']}")
        extra = r.get("error") or (f"error vs input {100 * r['cos_rel_error']:.2f} %"
                                   if r.get("cos_rel_error") is not None else "")
        lines.append(f"  {r['description']}" + (f" ({extra})" if extra else ""))
        for o in r.get("options") or ():
            lines.extend(textwrap.wrap(o["text"], 79, initial_indent="    -O ",
                                       subsequent_indent="         "))
    return lines


def models_cmd(as_json: bool = False, do_measure: bool = False, on: str = "synthetic:gold-ggx",
               models: str = "", with_options: bool = False) -> None:
    """Run ``brdffit models`` (its options: :func:`brdffit.cli._commands.models`)."""
    rows = model_table()
    if models:
        keep = check_models([m.strip() for m in models.split(",") if m.strip()])
        rows = [r for r in rows if r["name"] in keep]
    if do_measure:
        rows = measure(rows, on, say=lambda msg: print(msg, file=sys.stderr))
    if with_options:
        rows = [dict(r, options=model_options(r["name"])) for r in rows]
    if as_json:
        print(json.dumps({"models": rows, "source": None if do_measure
                          else registry.TYPICAL_SOURCE}, indent=1))
        return
    for line in format_table(rows):
        print(line)
    notes = ["ISO: fits isotropic inputs only. FILE B: bytes of the fit file (.npz); "
             "TABLE B: bytes of the tables in it; FIT CPU: CPU seconds of one fit.",
             f"Measured now on {on}, on this machine." if do_measure else
             f"Typical figures (–: not measured): {registry.TYPICAL_SOURCE}; "
             "`brdffit models --measure` measures them on this machine.",
             "Papers:"]
    print("")
    for note in notes:
        print(textwrap.fill(note, 79))
    for key in sorted({k.strip() for r in rows for k in r["paper"].split(",")}):
        print(textwrap.fill(f"{key}: {registry.PAPERS.get(key, key)}", 79,
                            initial_indent="  ", subsequent_indent="    "))
