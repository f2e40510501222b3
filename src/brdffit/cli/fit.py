"""``brdffit fit INPUT[:MATERIAL] --model NAME [-o OUT] [--iterations N] [--json]``.

Loads the input with :func:`brdffit.io.load`, fits it with the model registered under
``NAME`` in :mod:`brdffit.fit.registry` (``tabulated``, ``ggx``, ``beckmann`` from Dupuy et
al. 2015; other modules add theirs, e.g. ``sgd``, ``npf``), prints a short summary
(eigenvalue, fitted α's, Fresnel at normal incidence, time; ``--json`` prints it as one JSON
object) and, with ``-o``, writes the fit file (:func:`brdffit.io.fitfile.save_fit`).
Extra fitting options go through ``--option key=value`` (values parsed as JSON when they
can be, e.g. ``--option tol=1e-6 --option anisotropic=true``); an option the model's fitting
function does not take is a usage error (exit status 2) listing the accepted ones
(:func:`accepted_options`).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import typer

from .._json import json_default

__all__ = ["register", "parse_options", "run_fit", "accepted_options", "check_options"]


def parse_options(items: list[str] | None) -> dict:
    """``["k=v", ...]`` → dict, values parsed as JSON when possible (else strings)."""
    out: dict = {}
    import click

    for item in items or []:
        if "=" not in item:
            raise click.BadParameter(f"expected key=value, found {item!r}", param_hint="--option")
        key, val = item.split("=", 1)
        try:
            out[key.strip()] = json.loads(val)
        except json.JSONDecodeError:
            out[key.strip()] = val
    return out


def accepted_options(fn, _seen: frozenset = frozenset(), _skip: int = 1) -> tuple[set, bool]:
    """``(names, open_ended)``: the keyword options a fitting function accepts.

    The named parameters after the BRDF (private ``_x`` ones excluded); when the function
    takes ``**kwargs``, those of the module-level functions it forwards them to
    (``f(brdf, **kwargs)`` in its source), recursively. ``open_ended`` is True when some
    ``**kwargs`` could not be followed: then unknown names cannot be ruled out up front.
    """
    import ast
    import inspect
    import textwrap

    fn = inspect.unwrap(fn)
    if fn in _seen:
        return set(), False
    try:
        params = list(inspect.signature(fn).parameters.values())
    except (TypeError, ValueError):
        return set(), True
    names, var_kw = set(), None
    for i, p in enumerate(params):
        if p.kind is p.VAR_KEYWORD:
            var_kw = p.name
        elif (p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY) and i >= _skip
              and not p.name.startswith("_")):
            names.add(p.name)
    if var_kw is None:
        return names, False
    try:
        tree = ast.parse(textwrap.dedent(inspect.getsource(fn)))
    except (OSError, TypeError, SyntaxError):
        return names, True
    open_ended, forwarded = False, False
    for node in ast.walk(tree):
        if not (isinstance(node, ast.Call) and any(
                k.arg is None and isinstance(k.value, ast.Name) and k.value.id == var_kw
                for k in node.keywords)):
            continue
        forwarded = True
        callee = getattr(fn, "__globals__", {}).get(node.func.id) \
            if isinstance(node.func, ast.Name) else None
        if not callable(callee):
            open_ended = True
            continue
        sub, sub_open = accepted_options(callee, _seen | {fn}, len(node.args))
        names |= sub - {k.arg for k in node.keywords if k.arg}
        open_ended |= sub_open
    return names, open_ended or not forwarded


def check_options(model: str, options: dict) -> None:
    """Usage error (exit 2) naming an option ``model``'s fitter does not take, and the
    accepted ones."""
    from ..fit import registry
    from . import usage_error

    names, open_ended = accepted_options(registry.get(model).fit)
    unknown = sorted(set(options) - names)
    if unknown and not open_ended:
        raise usage_error("--option", f"model {model!r} has no option "
                                      f"{', '.join(map(repr, unknown))}; accepted: "
                                      f"{', '.join(sorted(names)) or 'none'}")


def _unexpected_option(exc: TypeError, options: dict) -> str | None:
    """The user option a fitter rejected with ``TypeError: ... unexpected keyword argument``."""
    import re

    m = re.search(r"unexpected keyword argument '([^']+)'", str(exc))
    return m.group(1) if m and m.group(1) in options else None


def run_fit(spec: str, model: str = "tabulated", out: Path | None = None,
            options: dict | None = None) -> tuple[object, dict]:
    """Load ``spec``, fit it with ``model`` and optionally save; returns ``(fit, summary)``."""
    from ..fit import registry
    from ..io import load

    entry = registry.get(model)
    brdf = load(spec)
    t0 = time.perf_counter()
    try:
        fitted = entry.fit(brdf, **(options or {}))
    except TypeError as exc:  # an option the up-front check could not rule out
        bad = _unexpected_option(exc, options or {})
        if bad is None:
            raise
        from . import usage_error

        names, _ = accepted_options(entry.fit)
        raise usage_error("--option", f"model {model!r} has no option {bad!r}; accepted: "
                                      f"{', '.join(sorted(names)) or 'none'}") from None
    elapsed = time.perf_counter() - t0
    summary = registry.summarize(model, fitted)
    summary["model"] = model
    summary["input"] = spec
    summary.setdefault("time_s", elapsed)
    if summary.get("time_s") is None:
        summary["time_s"] = elapsed
    if out is not None:
        from ..errors import ExportError
        from ..io.fitfile import SerializableModel, save_fit

        if not isinstance(fitted, SerializableModel) or not fitted.fit_kind:
            raise ExportError(f"{out}: expected a model that can be saved as a fit file, found "
                              f"{type(fitted).__name__} (e.g. per-channel fits are not saved)")
        save_fit(fitted, out, source=spec,
                 options=dict(getattr(fitted, "fit_options", None) or options or {}, model=model))
        summary["output"] = str(out)
    return fitted, summary


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    return str(v)


def register(app: typer.Typer) -> None:
    @app.command("fit")
    def fit_cmd(
        spec: str = typer.Argument(..., metavar="INPUT[:MATERIAL]",
                                   help="A BRDF file, collection.zip:material or synthetic:NAME."),
        model: str = typer.Option("tabulated", "--model", "-m",
                                  help="Model to fit (see brdffit.fit.registry): tabulated, "
                                       "ggx, beckmann, and those of other fitting modules."),
        out: Path = typer.Option(None, "--output", "-o", help="Write the fit file (.npz) here."),
        iterations: int = typer.Option(None, "--iterations", min=1,
                                       help="Power iterations / optimiser iterations."),
        option: list[str] = typer.Option(None, "--option", "-O",
                                         help="Extra fitting option key=value (repeatable)."),
        as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON."),
    ):
        """Fit a model to a measured BRDF and print a short summary."""
        from ..fit import registry

        import click  # the CLI entry point reports click's usage errors (exit status 2)

        try:
            entry = registry.get(model)
        except KeyError as exc:
            raise click.BadParameter(str(exc.args[0]), param_hint="--model") from None
        opts = parse_options(option)
        check_options(model, opts)
        if iterations is not None:
            names, open_ended = accepted_options(entry.fit)
            if "iterations" not in names and not open_ended:
                raise click.BadParameter(f"model {model!r} has no 'iterations' option",
                                         param_hint="--iterations")
            opts["iterations"] = iterations
        _, summary = run_fit(spec, model, out, opts)
        if as_json:
            typer.echo(json.dumps(summary, default=json_default, sort_keys=True))
            return
        typer.echo(f"{spec}: {model} fit in {summary.get('time_s', 0.0):.3f} s")
        for key in ("eigenvalue", "iterations", "relative_change", "beckmann_alpha", "ggx_alpha",
                    "alpha", "fresnel_0", "table", "rule", "output"):
            if summary.get(key) is not None:
                typer.echo(f"  {key:16s} {_fmt(summary[key])}")
        shown = {"eigenvalue", "iterations", "relative_change", "beckmann_alpha", "ggx_alpha",
                 "alpha", "fresnel_0", "table", "rule", "output", "model", "input", "time_s"}
        for key, val in summary.items():
            if key not in shown and val is not None and not isinstance(val, dict):
                typer.echo(f"  {key:16s} {_fmt(val)}")
