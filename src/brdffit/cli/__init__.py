"""The ``brdffit`` command line.

Each sub-command lives in its own module of this package exposing ``register(app)``; add new
modules to ``_COMMAND_MODULES``.

Exit status (:data:`EXIT_CODES`, also in ``brdffit --help``):

* 0 — all done;
* 1 — error: bad or missing data, a file that cannot be written, a cluster that cannot run
  the batch, any unexpected exception (one line on stderr; ``--debug`` shows the traceback);
* 2 — usage: unknown command, model or option, a bad option value, or (batch) an output
  folder locked by another batch;
* 3 — some tasks failed (``batch``, ``compare``, ``demo``): the others were done and written,
  the failures are recorded (``batch``: re-run with ``--retry-failed``).

Commands signal usage errors with :func:`usage_error` and partial failure with
``raise typer.Exit(3)``; :func:`main` turns everything into these codes.
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

#: Exit status of ``brdffit`` (module docstring).
EXIT_OK, EXIT_ERROR, EXIT_USAGE, EXIT_FAILED_TASKS = 0, 1, 2, 3
EXIT_CODES = {EXIT_OK: "all done", EXIT_ERROR: "error", EXIT_USAGE: "usage error (unknown "
              "model, bad option or value, output folder locked)",
              EXIT_FAILED_TASKS: "some tasks failed (the rest is done)"}


def usage_error(option: str, message: str) -> click.BadParameter:
    """A bad command-line value: ``raise usage_error("--model", "...")`` exits with status 2."""
    return click.BadParameter(message, param_hint=option)


def check_models(names, option: str = "--models") -> list[str]:
    """``names`` if every one is a registered model, else a usage error listing the known
    (an empty list passes: callers that need a model say so)."""
    from ..fit import registry

    unknown = []
    for name in names:
        try:
            registry.get(name)
        except KeyError:
            unknown.append(name)
    if unknown:
        raise usage_error(option, f"unknown model(s) {', '.join(map(repr, unknown))}; known "
                                  f"models: {', '.join(registry.list_fitters())}")
    return list(names)


app = typer.Typer(
    name="brdffit",
    help="Fit compact microfacet models to measured BRDFs (MERL, RGL, UTIA, Neural-BRDF).\n\n"
         "Exit status: 0 all done, 1 error, 2 usage (unknown model, bad option or value, "
         "output folder locked), 3 some tasks failed (the rest is done).",
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
    """Console-script entry point: runs the command and returns its exit status (module
    docstring). With ``standalone_mode=False`` Click *returns* the code of ``typer.Exit``
    (and raises everything else), so both are turned into a status here."""
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv
    try:
        code = app(args=argv, prog_name="brdffit", standalone_mode=False)
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
        return EXIT_ERROR
    except Exception as exc:  # noqa: BLE001 – a bug or an unforeseen input: still one line
        if debug:
            raise
        print(f"brdffit: error: {type(exc).__name__}: {exc} (--debug shows the traceback)",
              file=sys.stderr)
        return EXIT_ERROR
    return code if isinstance(code, int) else EXIT_OK


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
