"""The parsing machinery of the ``brdffit`` command line (standard-library :mod:`argparse`).

What ``brdffit --help`` and ``brdffit NAME --help`` need and nothing the commands run:
:class:`UsageError` (exit status 2), the option value types (:func:`at_least`,
:func:`between`, :func:`positive`, :func:`path`...), the help formatter (80 columns, each
option's default and range), :func:`add_command` and :func:`add_render_options`, and the
model list of the help texts (:func:`models_help`, read from the registry's declarations
without importing any fitting module). The commands' parsers are in
:mod:`brdffit.cli._commands`.
"""

from __future__ import annotations

import argparse
import functools
import inspect
import os
import sys
import textwrap
from pathlib import Path

from ..errors import printable
from ..fit import registry


#: The models ``compare`` and ``batch`` fit unless ``--models`` says otherwise: the default
#: model of ``brdffit fit`` (engine-ready, physically valid by construction) first, then the
#: tabulated fit of Dupuy 2015 and its two analytic conversions.
DEFAULT_MODELS = "ggx-diffuse,tabulated,ggx,beckmann"

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


def add_command(commands, name: str, description: str, *,
                epilog: str | None = None) -> _Parser:
    """Add the command ``name`` to ``commands`` (the sub-parsers of
    :func:`brdffit.cli.build_parser`); returns its parser for the ``add_argument`` calls.

    ``description`` is the command's help text (cleaned as a docstring is); its first
    paragraph is the one-line help of the command list. What the command runs is
    ``NAME_cmd`` of the module ``brdffit.cli.NAME`` (:func:`brdffit.cli.main`)."""
    description = inspect.cleandoc(description)
    summary = description.split("\n\n", 1)[0].replace("\n", " ")
    parser = commands.add_parser(name, prog=f"brdffit {name}", help=summary,
                                 description=description, epilog=epilog, add_help=False)
    parser.add_argument("-h", "--help", action="help", help="Show this message and exit.")
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
