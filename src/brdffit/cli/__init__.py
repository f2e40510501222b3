"""The ``brdffit`` command line (standard-library :mod:`argparse`).

Each sub-command lives in its own module of this package exposing ``register(commands)``,
which adds its parser with :func:`add_command` (the command's function, its one-line help
and description taken from the function's docstring, its options with ``add_argument``);
add new modules to ``_COMMAND_MODULES``. ``brdffit NAME ...`` imports only the module of
``NAME``; ``brdffit --help`` imports them all (none imports NumPy at module level).

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
import functools
import gc
import importlib
import inspect
import os
import sys
import textwrap
from pathlib import Path

from .. import __version__
from ..errors import BRDFError, printable
from .._blas import single_thread_env
from .._malloc import tune_this_process
from ..fit import registry

_COMMAND_MODULES = ["info", "convert", "fit", "models", "render", "compare", "batch", "export",
                    "demo"]

#: Exit status of ``brdffit`` (module docstring).
EXIT_OK, EXIT_ERROR, EXIT_USAGE, EXIT_FAILED_TASKS = 0, 1, 2, 3
EXIT_CODES = {EXIT_OK: "all done", EXIT_ERROR: "error", EXIT_USAGE: "usage error (unknown "
              "model, bad option or value, output folder locked)",
              EXIT_FAILED_TASKS: "some tasks failed (the rest is done)"}
_ABORTED = 130  # interrupted (Ctrl-C), as a shell reports SIGINT
#: The models ``compare`` and ``batch`` fit unless ``--models`` says otherwise: the default
#: model of ``brdffit fit`` (engine-ready, physically valid by construction) first, then the
#: tabulated fit of Dupuy 2015 and its two analytic conversions.
DEFAULT_MODELS = "ggx-diffuse,tabulated,ggx,beckmann"

_SUMMARY = "Fit compact microfacet models to measured BRDFs (MERL, RGL, UTIA, Neural-BRDF)."
_EXIT_TEXT = ("Exit status: 0 all done, 1 error, 2 usage (unknown model, bad option or value, "
              "output folder locked), 3 some tasks failed (the rest is done).")
_WIDTH = 80  # help text never wider (tests/cli/test_help_models.py)


class UsageError(Exception):
    """A bad command line (exit status 2): ``message`` about ``option`` (an option or
    argument name, or ``None``), shown under the usage line of ``parser``."""

    def __init__(self, message: str, option: str | None = None, parser=None):
        super().__init__(message)
        self.message, self.option, self.parser = message, option, parser

    def show(self, file=None) -> None:
        file = sys.stderr if file is None else file
        prog = "brdffit"
        if self.parser is not None:
            file.write(self.parser.format_usage())
            prog = self.parser.prog
        where = f"{self.option}: " if self.option else ""
        file.write(f"{prog}: error: {where}{printable(self.message)}\n")
        file.write(f"Try '{prog} -h' for help.\n")


def output_file(path: Path, suffixes: tuple[str, ...], option: str = "-o",
                hint: str = "") -> str:
    """Check ``-o FILE`` before any work; returns its kind (:func:`brdffit._atomic.destination_kind`).

    A new path or a regular file must end in one of ``suffixes`` (else a usage error,
    exit 2, with ``hint``); a character device or a FIFO (``/dev/null``) is written
    through in the command's format; a directory, socket or block device, a missing folder
    or a folder where no file can be created is an :class:`~brdffit._atomic.OutputError`
    (exit 1). Nothing is created here."""
    from .._atomic import WRITE_THROUGH, check_writable, destination_kind

    kind = destination_kind(path)
    if kind in ("new", "regular file") and path.suffix.lower() not in suffixes:
        raise usage_error(option, f"expected a file name ending in {' or '.join(suffixes)}, "
                                  f"found {str(path.name)!r}{hint}")
    check_writable(path)
    return kind


def usage_error(option: str | None, message: str) -> UsageError:
    """A bad command-line value: ``raise usage_error("--model", "...")`` exits with status 2."""
    return UsageError(message, option)


# -- value types (their errors are usage errors naming the option) ------------------------------
def _integer_in(low: int, high: int | None, range_text: str):
    """The ``type=`` of an integer option in ``[low, high]`` (``high`` ``None``: no upper
    bound); errors and ``--help`` show ``range_text``."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
        if value < low or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"{text!r} is not in the range {range_text}")
        return value

    parse.range_text = range_text
    parse.__name__ = "integer"
    return parse


def at_least(low: int):
    """The ``type=`` of an integer option ≥ ``low`` (``--help`` shows ``x>=low``)."""
    return _integer_in(low, None, f"x>={low}")


def between(low: int, high: int):
    """The ``type=`` of an integer option in ``[low, high]`` (``--help`` shows the range)."""
    return _integer_in(low, high, f"{low}..{high}")


def positive(high: float = 1e6):
    """The ``type=`` of a real option in ``(0, high]`` (finite; not NaN)."""
    def parse(text: str) -> float:
        value = number(text)
        if not 0.0 < value <= high:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number in (0, {high:g}]")
        return value

    parse.range_text = f"0<x<={high:g}"
    parse.__name__ = "number"
    return parse


def positive_or(*words: str, high: float = 1e6):
    """The ``type=`` of an option that is one of ``words`` or a number in ``(0, high]``."""
    as_number = positive(high)

    def parse(text: str):
        if text in words:
            return text
        try:
            return as_number(text)
        except argparse.ArgumentTypeError:
            raise argparse.ArgumentTypeError(
                f"{text!r} is not {', '.join(words)} or a number in (0, {high:g}]") from None

    parse.__name__ = "value"
    return parse


#: Upper bounds of the render options (``render``, ``compare``, ``batch --render``,
#: ``demo``): the image side (a 4096² film of 4 channels is 0.27 GB per copy), samples per
#: pixel, and the seed (Mitsuba's sampler takes 32 bits; a comparison adds up to 2²⁰ for
#: its batches and peaks).
MAX_RESOLUTION, MAX_SPP, MAX_SEED = 4096, 1 << 16, (1 << 31) - 1
#: Samples one render pass may hold: Dr.Jit arrays have at most 2³² entries.
MAX_SAMPLES_PER_PASS = (1 << 32) - 1


def check_render_size(resolution: int, spp_per_pass: int, option: str = "--spp") -> None:
    """Usage error (exit 2) when ``resolution² × spp_per_pass`` exceeds what one Dr.Jit
    render pass can hold (:data:`MAX_SAMPLES_PER_PASS`)."""
    n = int(resolution) ** 2 * int(spp_per_pass)
    if n > MAX_SAMPLES_PER_PASS:
        raise usage_error(option, f"{resolution}² pixels × {spp_per_pass} samples = {n:,} "
                                  f"samples in one pass; at most {MAX_SAMPLES_PER_PASS:,} "
                                  "(lower --spp or --resolution)")


def number(text: str) -> float:
    """The ``type=`` of a real-valued option (finite or infinite, not NaN)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if value != value:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number")
    return value


def integer(text: str) -> int:
    """The ``type=`` of an integer option."""
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None


def path(text: str) -> Path:
    """The ``type=`` of a file or folder option (no file system allows a NUL byte)."""
    if "\0" in text:
        raise argparse.ArgumentTypeError(f"{text!r} is not a valid path (NUL byte)")
    return Path(text)


# -- the parser -------------------------------------------------------------------------------
@functools.lru_cache(maxsize=8)
def _help_width(columns: str | None) -> int:
    """Help text width for the terminal (``COLUMNS`` first, also the cache key), at most 80
    columns. argparse makes a formatter for every ``add_argument``: the terminal is asked
    once per ``COLUMNS`` value."""
    import shutil

    return min(shutil.get_terminal_size((_WIDTH, 24)).columns, _WIDTH) - 1


class _HelpFormatter(argparse.HelpFormatter):
    """``--help`` at most 80 columns; option lines as ``-m, --model NAME``; each option's
    default and range as ``[default: 2; x>=1]``; description and epilog paragraphs re-wrapped,
    except those that start with a ``\\b`` line (kept as written: examples, the model list)."""

    def __init__(self, prog: str):
        super().__init__(prog, width=_help_width(os.environ.get("COLUMNS")),
                         max_help_position=26)

    def _format_action_invocation(self, action) -> str:
        if not action.option_strings or action.nargs == 0:
            return super()._format_action_invocation(action)
        value = self._format_args(action, action.dest.upper())
        return f"{', '.join(action.option_strings)} {value}"

    def _get_help_string(self, action) -> str:
        text = action.help or ""
        notes = []
        default = action.default
        if action.option_strings and action.nargs != 0 and default not in (
                None, argparse.SUPPRESS, "", [], ()):
            notes.append(f"default: {default}")
        low = getattr(action.type, "range_text", None)
        if low:
            notes.append(low)
        if action.required and action.option_strings:
            notes.append("required")
        if notes:
            text = f"{text}  [{'; '.join(notes)}]"
        return text.replace("%", "%%")  # argparse %-formats help texts

    def _split_lines(self, text: str, width: int) -> list[str]:
        # names such as sphere-courtyard are never broken at their hyphen
        return textwrap.wrap(" ".join(text.split()), width, break_on_hyphens=False)

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        blocks = []
        for block in text.strip("\n").split("\n\n"):
            if block.startswith("\b\n"):
                blocks.append("\n".join(indent + line for line in block[2:].splitlines()))
            else:
                blocks.append(textwrap.fill(" ".join(block.split()), width,
                                            initial_indent=indent, subsequent_indent=indent,
                                            break_on_hyphens=False))
        return "\n\n".join(blocks)


class _Parser(argparse.ArgumentParser):
    """An :class:`argparse.ArgumentParser` whose errors raise :class:`UsageError` (exit 2)
    instead of exiting the process."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", _HelpFormatter)
        kwargs.setdefault("allow_abbrev", False)  # `--mod` is not `--model`
        super().__init__(*args, **kwargs)
        self._positionals.title = "arguments"

    def error(self, message: str):
        raise UsageError(message, parser=self)


def _doc(fn) -> tuple[str, str]:
    """``(one-line help, description)`` of a command from its function's docstring."""
    doc = inspect.cleandoc(fn.__doc__ or "")
    return doc.split("\n\n", 1)[0].replace("\n", " "), doc


def add_command(commands, name: str, fn, *, epilog: str | None = None) -> _Parser:
    """Add the command ``name`` running ``fn(**options)`` to ``commands`` (the sub-parsers
    of :func:`build_parser`); returns its parser for the ``add_argument`` calls. ``fn``
    returns ``None`` (status 0) or an exit status."""
    summary, description = _doc(fn)
    parser = commands.add_parser(name, prog=f"brdffit {name}", help=summary,
                                 description=description, epilog=epilog, add_help=False)
    parser.add_argument("-h", "--help", action="help", help="Show this message and exit.")
    parser.set_defaults(_run=fn)
    return parser


def add_render_options(command, when: str = "") -> None:
    """``--scenes``, ``--spp``, ``--batches``, ``--resolution``: how ``compare`` and ``batch
    --render`` render (:class:`brdffit.batch.RenderSettings`); ``when`` prefixes each help
    (e.g. ``"--render: "``)."""
    def text(help_: str) -> str:
        return when + help_ if when else help_[0].upper() + help_[1:]

    command.add_argument("--scenes", default="paper", metavar="SCENES", help=text(
        "the scene suite 'paper' (Bagher 2016 §5: sphere-courtyard, sphere-studio, "
        "sphere-sunrise, knot-courtyard) or scene names, comma-separated: sphere-<map>, "
        "knot-<map>, sphere-env, knot, sphere-point, sphere-distant, sphere-svrough."))
    command.add_argument("--spp", type=between(1, MAX_SPP), default=64, metavar="N",
                         help=text("samples per pixel per scene, all batches together (a "
                                   "multiple of --batches)."))
    command.add_argument("--batches", type=between(1, 256), default=8, metavar="N",
                         help=text("independent batches per scene (the PSNR standard error "
                                   "needs ≥ 3; as many as --spp when it is smaller)."))
    command.add_argument("--resolution", type=between(8, MAX_RESOLUTION), default=256,
                         metavar="PX", help=text("image side in pixels."))


def check_render_settings(spp: int, batches: int, resolution: int,
                          batches_option: str | None = "--batches") -> int:
    """The batches a comparison renders (``batches``, or ``spp`` when there are fewer
    samples, as :func:`brdffit.evaluation.compare.compare` does), after the usage errors
    (exit 2) of its settings: ``spp`` not a multiple of them (every batch renders ``spp /
    batches`` samples per pixel: no silent rounding; ``batches_option`` ``None`` when the
    command has no such option) and a pass too large (:func:`check_render_size`)."""
    batches = min(batches, spp)
    if spp % batches:
        lower, upper = spp // batches * batches, -(-spp // batches) * batches
        options = " or ".join(f"--spp {v}" for v in dict.fromkeys((lower, upper)) if v > 0)
        of = f"--batches {batches}" if batches_option else f"the {batches} batches"
        raise usage_error("--spp", f"{spp} is not a multiple of {of}; use {options}")
    check_render_size(resolution, spp // batches)
    return batches


def check_models(names, option: str = "--models") -> list[str]:
    """``names`` if every one is a known model, else a usage error listing the known ones
    (an empty list passes: callers that need a model say so).

    Reads the registry's declared names (:func:`brdffit.fit.registry.known_names`) without
    importing any fitting module."""
    names = list(names)
    unknown = [name for name in names if name not in set(registry.known_names())]
    if unknown:
        raise usage_error(option, f"unknown model(s) {', '.join(map(repr, unknown))}; known "
                                  f"models: {', '.join(registry.known_names())} (brdffit "
                                  f"models describes them)")
    return names


@functools.lru_cache(maxsize=None)
def models_help(title: str = "Models") -> str:
    """The model list of ``--help`` texts: one line per declared model with its description
    (kept as written by the help formatter: the block starts with ``\\b``), 80 columns
    wide."""
    lines = ["\b", f"{title} (iso: isotropic inputs only; `brdffit models` for sizes and "
                    "times):"]
    for name in registry.known_names():
        info = registry.MODELS.get(name)
        desc = info.description if info is not None else ""
        iso = " (iso)" if info is not None and info.isotropic_only else ""
        lines.append(f"  {name:<17}{desc}{iso}")
    return "\n".join(lines)


def build_parser(commands=None) -> tuple[_Parser, dict[str, _Parser]]:
    """The ``brdffit`` parser with the commands of ``commands`` (module names of
    ``_COMMAND_MODULES``; default: all of them), and each command's parser by name."""
    root = _Parser(prog="brdffit", usage="brdffit [-h] [--version] [--debug] COMMAND [ARGS]...",
                   description=_SUMMARY, epilog=models_help(), add_help=False)
    root.add_argument("-h", "--help", action="help", help="Show this message and exit.")
    root.add_argument("--debug", action="store_true", help="Show full tracebacks on errors.")
    root.add_argument("--version", action="version", version=f"brdffit {__version__}",
                      help="Show the version and exit.")
    sub = root.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser,
                              required=True, help=argparse.SUPPRESS)
    for name in _COMMAND_MODULES if commands is None else commands:
        importlib.import_module(f"{__name__}.{name}").register(sub)
    parsers = dict(sub.choices)
    rows = [f"  {name:<9}{parser.description.split(chr(10) * 2)[0].replace(chr(10), ' ')}"
            for name, parser in parsers.items()]
    root.description = "\n\n".join([_SUMMARY, _EXIT_TEXT, "\b\nCommands:\n" + "\n".join(rows)])
    return root, parsers


def _command_name(argv: list[str]) -> str | None:
    """The command ``argv`` runs, when it is one of ours (the root has no option that takes
    a value, so the first argument that is not an option is the command)."""
    first = next((a for a in argv if not a.startswith("-")), None)
    return first if first in _COMMAND_MODULES else None


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
        run_command = options.pop("_run")
        options.pop("command")
        options.pop("debug", None)
        code = run_command(**options)
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
