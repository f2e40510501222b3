"""The ``brdffit`` command line.

Each sub-command lives in its own module of this package exposing ``register(app)``; add new
modules to ``_COMMAND_MODULES``. Errors from the library print one line to stderr and exit
with status 1 (2 for usage errors); ``--debug`` shows the traceback instead.
"""

from __future__ import annotations

import importlib
import sys

import click
import typer

try:  # recent Typer vendors its own copy of Click; older ones use Click itself
    from typer._click import exceptions as _typer_click
except ImportError:  # pragma: no cover
    _typer_click = click.exceptions

_EXIT = tuple({click.exceptions.Exit, typer.Exit})
_ABORT = tuple({click.exceptions.Abort, typer.Abort})
_USAGE = tuple({click.ClickException, _typer_click.ClickException})

from ..errors import BRDFError

_COMMAND_MODULES = ["info", "convert", "fit", "render", "compare", "batch", "export", "demo"]

app = typer.Typer(
    name="brdffit",
    help="Fit compact microfacet models to measured BRDFs (MERL, RGL, UTIA, Neural-BRDF).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


@app.callback()
def _root(debug: bool = typer.Option(False, "--debug", help="Show full tracebacks on errors.")):
    """brdffit: measured BRDFs in, compact physically based microfacet models out."""


def _load_commands() -> None:
    for name in _COMMAND_MODULES:
        try:
            module = importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:  # a command module not written yet
            if exc.name == f"{__name__}.{name}":
                continue
            raise
        module.register(app)


_load_commands()


def main(argv: list[str] | None = None) -> int:
    """Console-script entry point."""
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv
    try:
        app(args=argv, prog_name="brdffit", standalone_mode=False)
    except _EXIT as exc:
        return exc.exit_code
    except _ABORT:
        print("brdffit: aborted", file=sys.stderr)
        return 130
    except _USAGE as exc:
        if debug:
            raise
        exc.show()
        return exc.exit_code
    except (BRDFError, OSError, ValueError) as exc:
        if debug:
            raise
        print(f"brdffit: error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
