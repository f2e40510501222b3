"""``brdffit export FIT --to TARGET -o OUT``: a fit in a renderer's, engine's or shader's format.

``FIT`` is a fit file (:func:`brdffit.io.fitfile.save_fit`, ``.npz``), a parameter JSON
(:func:`brdffit.export.load_json`) or ``synthetic:NAME``. Targets (:data:`brdffit.export.TARGETS`):
``mitsuba`` (ready-to-render Python scene; built-in plugins or the project's plugin),
``mitsuba-xml`` (XML scene for a plain Mitsuba install: built-in plugins, else an RGL tensor
file for the stock ``measured`` plugin), ``gltf``, ``materialx``, ``usd`` (UsdPreviewSurface +
the OpenPBR MaterialX binding), ``glsl``, ``merl``, ``rgl``, ``json``; plus ``npf-uber`` (several NPF fits packed as the Bagher 2016 uber-texture). The
summary (files, approximations, measured errors) is printed; ``--json`` prints it as JSON.
A model that cannot go to the target, or an output that cannot be written, exits with status 1
and one line naming the file (nothing partial is left behind); an unknown target or
``--option`` (or a value of the wrong type) is a usage error (status 2).
"""

from __future__ import annotations

import inspect
import json
import math
import typing
from importlib import import_module
from pathlib import Path

from ..errors import ExportError, printable
from ..export import SUFFIXES, TARGETS, check_model, export, load_json
from ..export._common import check_output_path, shown
from ..io.fitfile import load_fit
from ..synthetic import synthetic
from ._checks import output_file, parse_options
from ._parsing import usage_error

__all__ = ["export_cmd", "load_model", "run_export", "target_options",
           "check_options"]


def load_model(spec: str):
    """A model from a fit file, a parameter JSON or ``synthetic:NAME``."""
    if spec.startswith("synthetic:"):
        return synthetic(spec.split(":", 1)[1])
    if Path(spec).suffix.lower() == ".json":
        return load_json(spec)
    return load_fit(spec)


def _writer(to: str):
    mod, fn = TARGETS[to]
    return getattr(import_module(mod, "brdffit.export"), fn)


def target_options(to: str) -> dict:
    """``{option: default}`` of the writer of target ``to`` (what ``--option`` accepts)."""
    params = inspect.signature(_writer(to)).parameters
    return {k: p.default for k, p in params.items()
            if k not in ("model", "models", "path") and p.kind is p.POSITIONAL_OR_KEYWORD
            and p.default is not p.empty}


def _choices(to: str) -> dict:
    """``{option: allowed values}`` of the writer's options annotated ``Literal[...]``."""
    try:
        hints = typing.get_type_hints(_writer(to))
    except (NameError, TypeError):          # an annotation that does not resolve: no choices
        return {}
    return {k: typing.get_args(h) for k, h in hints.items()
            if typing.get_origin(h) is typing.Literal}


def check_options(to: str, options: dict) -> None:
    """Raise ``ValueError`` (one line) for an option the target does not know or a value of
    the wrong type (the type of the option's default: boolean, integer, number, string) or,
    for an option annotated ``Literal[...]``, not one of its values."""
    known = target_options(to)
    choices = _choices(to)
    for key, val in options.items():
        if key not in known:
            raise ValueError(f"unknown option {key!r} for --to {to}; expected one of "
                             f"{', '.join(known) or '(none)'}")
        d = known[key]
        if key in choices:
            ok = any(type(val) is type(c) and val == c for c in choices[key])  # 1 is not True
            want = "one of " + ", ".join(repr(c) if isinstance(c, str) else json.dumps(c)
                                         for c in choices[key])
        elif isinstance(d, bool):
            ok, want = isinstance(val, bool), "true or false"
        elif isinstance(d, int):
            ok, want = isinstance(val, int) and not isinstance(val, bool), "an integer"
        elif isinstance(d, float):
            ok = (isinstance(val, (int, float)) and not isinstance(val, bool)
                  and math.isfinite(val))
            want = "a finite number"
        elif isinstance(d, str):
            ok, want = isinstance(val, str), "a string"
        else:
            ok, want = True, ""
        if not ok:
            raise ValueError(f"expected {key} to be {want}, found {val!r}")


def run_export(fits: list[str], to: str, out: Path, options: dict | None = None) -> dict:
    """Load ``fits`` and export them to ``to`` at ``out``; returns the summary."""
    out = check_output_path(out)
    models = [load_model(f) for f in fits]
    if to == "npf-uber":  # the GLSL writer (~0.1 s of imports) for this target only
        from ..export.glsl import pack_npf_uber_texture

        for m in models:
            check_model(m)
        return {"target": to, **pack_npf_uber_texture(models, out, **(options or {}))}
    if len(models) != 1:
        raise ExportError(f"--to {to} exports one fit, found {len(models)} (only npf-uber packs "
                          "several)")
    return export(models[0], to, out, **(options or {}))


def export_cmd(fits: list[str], to: str, out: Path, option: list[str] | None = None,
               as_json: bool = False) -> None:
    """Run ``brdffit export`` (its options: :func:`brdffit.cli._commands.export`)."""
    targets = list(TARGETS)
    if to not in targets:
        raise usage_error("--to", f"expected one of {', '.join(targets)}, found {to!r}")
    options = parse_options(option)
    try:
        check_options(to, options)
    except ValueError as exc:
        raise usage_error("--option", str(exc)) from None
    others = [t for t, ends in SUFFIXES.items() if out.suffix.lower() in ends and t != to]
    output_file(out, SUFFIXES[to], hint=f" (the file name of --to {others[0]})" if others
                else "")
    summary = run_export(fits, to, out, options)
    if as_json:
        print(json.dumps(summary, default=str))
        return
    print(f"wrote {', '.join(shown(f) for f in summary.get('files', [str(out)]))} ({to})")
    for note in summary.get("notes", []):
        print(f"  approximation: {printable(str(note))}")
    for key in ("error", "fidelity"):
        if summary.get(key):
            print(f"  {key}: " + ", ".join(f"{k}={v:.4g}" if isinstance(v, float)
                                           else f"{k}={v}"
                                           for k, v in summary[key].items()))
