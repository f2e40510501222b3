"""``brdffit export FIT --to TARGET -o OUT``: a fit in a renderer's, engine's or shader's format.

``FIT`` is a fit file (:func:`brdffit.io.fitfile.save_fit`, ``.npz``), a parameter JSON
(:func:`brdffit.export.load_json`) or ``synthetic:NAME``. Targets (:data:`brdffit.export.TARGETS`):
``mitsuba`` (ready-to-render Python scene; built-in plugins or the project's plugin),
``mitsuba-xml`` (XML scene, built-in plugins only), ``gltf``, ``glsl``, ``merl``, ``rgl``,
``json``; plus ``npf-uber`` (several NPF fits packed as the Bagher 2016 uber-texture). The
summary (files, approximations, measured errors) is printed; ``--json`` prints it as JSON.
A model that cannot go to the target exits with status 1 and the reason.
"""

from __future__ import annotations

import json
from pathlib import Path

import typer

__all__ = ["register", "load_model", "run_export"]


def load_model(spec: str):
    """A model from a fit file, a parameter JSON or ``synthetic:NAME``."""
    if spec.startswith("synthetic:"):
        from ..synthetic import synthetic

        return synthetic(spec.split(":", 1)[1])
    if Path(spec).suffix.lower() == ".json":
        from ..export import load_json

        return load_json(spec)
    from ..io.fitfile import load_fit

    return load_fit(spec)


def run_export(fits: list[str], to: str, out: Path, options: dict | None = None) -> dict:
    """Load ``fits`` and export them to ``to`` at ``out``; returns the summary."""
    from ..errors import ExportError

    models = [load_model(f) for f in fits]
    if to == "npf-uber":
        from ..export.glsl import pack_npf_uber_texture

        return {"target": to, **pack_npf_uber_texture(models, out)}
    if len(models) != 1:
        raise ExportError(f"--to {to} exports one fit, found {len(models)} (only npf-uber packs "
                          "several)")
    from ..export import export

    return export(models[0], to, out, **(options or {}))


def register(app: typer.Typer) -> None:
    from ..export import TARGETS

    targets = list(TARGETS) + ["npf-uber"]

    @app.command("export")
    def export_cmd(
        fits: list[str] = typer.Argument(..., metavar="FIT...",
                                         help="Fit file (.npz), parameter JSON or synthetic:NAME."),
        to: str = typer.Option(..., "--to", help=f"Target: {', '.join(targets)}."),
        out: Path = typer.Option(..., "-o", "--out", help="Output file."),
        option: list[str] = typer.Option(None, "--option",
                                         help="Target option key=value (JSON values)."),
        as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON."),
    ) -> None:
        """Export a fit to Mitsuba 3, glTF 2.0, GLSL, MERL, RGL or JSON."""
        from .fit import parse_options

        if to not in targets:
            import click

            raise click.BadParameter(f"expected one of {', '.join(targets)}, found {to!r}",
                                     param_hint="--to")
        summary = run_export(fits, to, out, parse_options(option))
        if as_json:
            typer.echo(json.dumps(summary, default=str))
            return
        typer.echo(f"wrote {', '.join(summary.get('files', [str(out)]))} ({to})")
        for note in summary.get("notes", []):
            typer.echo(f"  approximation: {note}")
        for key in ("error", "fidelity"):
            if summary.get(key):
                typer.echo(f"  {key}: " + ", ".join(f"{k}={v:.4g}" if isinstance(v, float)
                                                    else f"{k}={v}"
                                                    for k, v in summary[key].items()))
