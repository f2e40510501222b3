"""The ``brdffit`` command line (standard-library :mod:`argparse`): the dispatcher.

Every command has its parser, what ``brdffit --help`` and ``brdffit NAME --help`` show
(:mod:`brdffit.cli._commands`, built with :mod:`brdffit.cli._parsing`), and its runner,
the module ``brdffit.cli.NAME`` whose ``NAME_cmd(**options)`` does the work and which
imports what it uses at its top. :func:`main` builds the parser (only the command's own
parser when the command line names one), parses, then imports the command's runner: the
help texts and the usage errors found by the parser import no runner. A new command adds
its parser to :data:`brdffit.cli._commands.PARSERS` and its runner module.

Exit status (:data:`EXIT_CODES`, also in ``brdffit --help``):

* 0 — all done;
* 1 — error: bad or missing data, a file that cannot be written, a cluster that cannot run
  the batch, any unexpected exception (one line on stderr; ``--debug`` shows the traceback);
* 2 — usage: unknown command, model or option, a bad option value, or (batch) an output
  folder locked by another batch;
* 3 — some tasks failed (``batch``, ``compare``, ``demo``): the others were done and written,
  the failures are recorded (``batch``: re-run with ``--retry-failed``).

Commands signal usage errors with ``raise usage_error("--option", "...")`` and other
statuses by returning them (``return EXIT_FAILED_TASKS``); :func:`main` turns everything
into these codes.

Why not Typer/Click (a CLI that starts at once): importing Typer took ~30 ms of a
0.2 s ``brdffit fit`` process (the authors' C++ does the whole job in 0.145 s), and its value
coercion needed Pydantic or private hooks; :mod:`argparse` imports in ~2 ms.
"""

from __future__ import annotations

import argparse
import gc
import importlib
import sys

from .. import __version__
from ..errors import BRDFError, printable
from .._blas import single_thread_env
from .._malloc import tune_this_process
from ._commands import PARSERS
from ._parsing import UsageError, _Parser, models_help


#: Exit status of ``brdffit`` (module docstring).
EXIT_OK, EXIT_ERROR, EXIT_USAGE, EXIT_FAILED_TASKS = 0, 1, 2, 3
EXIT_CODES = {EXIT_OK: "all done", EXIT_ERROR: "error", EXIT_USAGE: "usage error (unknown "
              "model, bad option or value, output folder locked)",
              EXIT_FAILED_TASKS: "some tasks failed (the rest is done)"}
_ABORTED = 130  # interrupted (Ctrl-C), as a shell reports SIGINT

#: The environment variables brdffit reads (``brdffit --help`` lists them).
ENVIRONMENT = {
    "BRDFFIT_DATA": "folders searched for relative load specs",
    "BRDFFIT_ENVMAP_DIR": "the HDR environment maps of the render scenes",
    "BRDFFIT_RENDER_THREADS": "threads per render (unset: all CPUs; batch: a share)",
    "BRDFFIT_LLVM_TARGET": "avx2: render kernels for AVX2, not the host CPU",
    "BRDFFIT_DRJIT_DEBUG": "1: bounds-check every gather of a render (slow)",
    "BRDFFIT_BLENDER_PYTHON": "a Python that imports bpy (Blender round trip)",
    "BRDFFIT_NPM_PREFIX": "the folder whose node_modules has three (three.js)",
    "BRDFFIT_CHROMIUM": "the Chromium of the three.js round trip",
}

_SUMMARY = "Fit compact microfacet models to measured BRDFs (MERL, RGL, UTIA, Neural-BRDF)."
_EXIT_TEXT = ("Exit status: 0 all done, 1 error, 2 usage (unknown model, bad option or value, "
              "output folder locked), 3 some tasks failed (the rest is done).")


def build_parser(commands=None) -> tuple[_Parser, dict[str, _Parser]]:
    """The ``brdffit`` parser with the commands of ``commands`` (names of
    :data:`~brdffit.cli._commands.PARSERS`; default: all of them), and each command's parser
    by name."""
    root = _Parser(prog="brdffit", usage="brdffit [-h] [--version] [--debug] COMMAND [ARGS]...",
                   description=_SUMMARY, epilog=models_help() + "\n\n" + _environment_help(),
                   add_help=False)
    root.add_argument("-h", "--help", action="help", help="Show this message and exit.")
    root.add_argument("--debug", action="store_true", help="Show full tracebacks on errors.")
    root.add_argument("--version", action="version", version=f"brdffit {__version__}",
                      help="Show the version and exit.")
    sub = root.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser,
                              required=True, help=argparse.SUPPRESS)
    for name in PARSERS if commands is None else commands:
        PARSERS[name](sub)
    parsers = dict(sub.choices)
    rows = [f"  {name:<9}{parser.description.split(chr(10) * 2)[0].replace(chr(10), ' ')}"
            for name, parser in parsers.items()]
    root.description = "\n\n".join([_SUMMARY, _EXIT_TEXT, "\b\nCommands:\n" + "\n".join(rows)])
    return root, parsers


def _environment_help() -> str:
    """The :data:`ENVIRONMENT` block of ``brdffit --help``, kept as written (``\\b``)."""
    return "\n".join(["\b", "Environment:"] + [f"  {name:<23}{text}"
                                                 for name, text in ENVIRONMENT.items()])


def _command_name(argv: list[str]) -> str | None:
    """The command ``argv`` runs, when it is one of ours (the root has no option that takes
    a value, so the first argument that is not an option is the command)."""
    first = next((a for a in argv if not a.startswith("-")), None)
    return first if first in PARSERS else None


def _runner(name: str):
    """``NAME_cmd`` of the runner module ``brdffit.cli.NAME`` of the command ``name``, the
    module imported now: a command's run-time imports are made when it runs, never by
    ``--help`` or another command."""
    return getattr(importlib.import_module(f"{__name__}.{name}"), f"{name}_cmd")


def main(argv: list[str] | None = None) -> int:
    """Console-script entry point: runs the command and returns its exit status (module
    docstring). Nothing here exits the process: ``--help`` and usage errors return 0 / 2."""
    argv = list(sys.argv[1:] if argv is None else argv)
    single_thread_env()         # before NumPy loads: one BLAS thread (brdffit._blas)
    tune_this_process()         # arrays from the heap, not fresh pages (brdffit._malloc)
    debug = "--debug" in argv
    parsers: dict = {}
    try:
        root, parsers = build_parser([name] if (name := _command_name(argv)) else None)
        if not argv:
            root.print_help()
            return EXIT_USAGE
        parsed, extra = root.parse_known_args(argv)
        if extra:  # reported under the command's usage, not the root's
            raise UsageError(f"unrecognized arguments: {' '.join(extra)}",
                             parser=parsers.get(parsed.command))
        options = vars(parsed)
        name = options.pop("command")
        options.pop("debug", None)
        code = _runner(name)(**options)
    except SystemExit as exc:  # argparse after --help
        return exc.code if isinstance(exc.code, int) else EXIT_OK
    except UsageError as exc:
        if exc.parser is None:
            exc.parser = parsers.get(_command_name(argv))
        exc.show()
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("brdffit: aborted", file=sys.stderr)
        return _ABORTED
    except Exception as exc:  # noqa: BLE001 – a bug or an unforeseen input: still one line
        if debug:
            raise
        if isinstance(exc, (BRDFError, OSError, ValueError)):
            print(f"brdffit: error: {printable(str(exc))}", file=sys.stderr)
        else:
            print(f"brdffit: error: {type(exc).__name__}: {printable(str(exc))} (--debug shows "
                  "the traceback)", file=sys.stderr)
        return EXIT_ERROR
    return code if isinstance(code, int) else EXIT_OK


#: The cyclic collector's youngest-generation threshold in a ``brdffit`` process (Python's
#: default: 700 allocations). Start-up (NumPy and the command's modules: ~160,000 objects
#: that live until exit) otherwise triggers hundreds of young collections, each promoting
#: survivors that the older generations then scan again: 3-6 ms of a 0.15 s tabulated fit
#: process, as much as disabling the collector (docs/design/startup-and-speed.md). Cyclic
#: garbage is still collected, after at most this many allocations.
GC_YOUNG_THRESHOLD = 50_000


def run() -> int:
    """The ``brdffit`` script and ``python -m brdffit``: :func:`main` with the collector's
    young threshold raised (:data:`GC_YOUNG_THRESHOLD`), then ``gc.freeze()`` just before
    the process exits. The interpreter's shutdown otherwise runs a last cyclic
    collection over every object the run created (modules, classes, the parsers):
    18 ms of a 0.21 s tabulated fit process (8 %, measured: the same saving as skipping the
    shutdown with ``os._exit``). Unlike ``os._exit``, atexit handlers, stream flushing and
    module teardown still run; only ``__del__`` of objects in reference cycles still alive at
    exit may be skipped, which Python never guarantees anyway. Not in :func:`main`: a
    library caller (tests, notebooks) keeps its collector."""
    gc.set_threshold(GC_YOUNG_THRESHOLD, *gc.get_threshold()[1:])
    code = main()
    gc.freeze()
    return code


if __name__ == "__main__":  # pragma: no cover
    sys.exit(run())
