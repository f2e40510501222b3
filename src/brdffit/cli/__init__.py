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

import functools
import gc
import importlib
import sys

# Start-up cost (issue 15.4): importing this package loads Typer (with its vendored Click)
# and the command modules, nothing else -- no NumPy, SciPy, Numba, Mitsuba, Dask, matplotlib
# or colour-science (tests/cli/test_startup.py). Commands import what they use when they run.
import typer

try:  # recent Typer vendors its own copy of Click; older ones use Click itself
    from typer._click import exceptions as _click_exceptions
except ImportError:  # pragma: no cover
    from click import exceptions as _click_exceptions

_EXIT = tuple({typer.Exit, getattr(_click_exceptions, "Exit", typer.Exit)})
_ABORT = tuple({typer.Abort, getattr(_click_exceptions, "Abort", typer.Abort)})
_USAGE = (_click_exceptions.ClickException,)

from ..errors import BRDFError
from .._blas import single_thread_env
from .._malloc import tune_this_process

_COMMAND_MODULES = ["info", "convert", "fit", "models", "render", "compare", "batch", "export",
                    "demo"]

#: Exit status of ``brdffit`` (module docstring).
EXIT_OK, EXIT_ERROR, EXIT_USAGE, EXIT_FAILED_TASKS = 0, 1, 2, 3
EXIT_CODES = {EXIT_OK: "all done", EXIT_ERROR: "error", EXIT_USAGE: "usage error (unknown "
              "model, bad option or value, output folder locked)",
              EXIT_FAILED_TASKS: "some tasks failed (the rest is done)"}


def usage_error(option: str, message: str):
    """A bad command-line value: ``raise usage_error("--model", "...")`` exits with status 2."""
    return typer.BadParameter(message, param_hint=option)


def check_models(names, option: str = "--models") -> list[str]:
    """``names`` if every one is a known model, else a usage error listing the known ones
    (an empty list passes: callers that need a model say so).

    Reads the registry's declared names (:func:`brdffit.fit.registry.known_names`) without
    importing any fitting module (only a fitting module that declares none of its models
    would be imported, to find its names)."""
    from ..fit import registry

    names = list(names)
    unknown = [name for name in names if name not in set(registry.known_names())]
    if unknown:
        registry.load_undeclared_modules()
        unknown = [name for name in unknown if name not in set(registry.known_names())]
    if unknown:
        raise usage_error(option, f"unknown model(s) {', '.join(map(repr, unknown))}; known "
                                  f"models: {', '.join(registry.known_names())} (brdffit "
                                  f"models describes them)")
    return names


@functools.lru_cache(maxsize=None)
def models_help(title: str = "Models") -> str:
    """The model list of ``--help`` texts: one line per declared model with its description
    (kept as is by Click: the block starts with ``\\b``), 80 columns wide."""
    from ..fit import registry

    lines = ["\b", f"{title} (iso: isotropic inputs only; `brdffit models` for sizes and "
                    "times):"]
    for name in registry.known_names():
        info = registry.MODELS.get(name)
        desc = info.description if info is not None else ""
        iso = " (iso)" if info is not None and info.isotropic_only else ""
        lines.append(f"  {name:<17}{desc}{iso}")
    return "\n".join(lines)


def _root(debug: bool = typer.Option(False, "--debug", help="Show full tracebacks on errors.")):
    """brdffit: measured BRDFs in, compact physically based microfacet models out."""


def build_app(commands=None) -> typer.Typer:
    """The ``brdffit`` Typer app with the commands of ``commands`` (module names of
    ``_COMMAND_MODULES``; default: all of them)."""
    new = typer.Typer(
        name="brdffit",
        help="Fit compact microfacet models to measured BRDFs (MERL, RGL, UTIA, Neural-BRDF)."
             "\n\nExit status: 0 all done, 1 error, 2 usage (unknown model, bad option or "
             "value, output folder locked), 3 some tasks failed (the rest is done).",
        epilog=models_help(),
        no_args_is_help=True,
        add_completion=False,
        pretty_exceptions_enable=False,
        rich_markup_mode=None,  # plain Click help: no Rich import (~80 ms), 80-column friendly
        context_settings={"help_option_names": ["-h", "--help"]},
    )
    new.callback()(_root)
    for name in _COMMAND_MODULES if commands is None else commands:
        try:
            module = importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:  # a command module not written yet
            if exc.name == f"{__name__}.{name}":
                continue
            raise
        module.register(new)
    return new


def __getattr__(name: str):
    if name == "app":  # the whole app, built on first use (main builds only what it runs)
        globals()["app"] = full = build_app()
        return full
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# -- the Click command, tuned ----------------------------------------------------------------
_TYPE_NAMES = {str: "TEXT", int: "INTEGER", float: "NUMBER", bool: "BOOLEAN"}


def _plain_type(param, ctx=None) -> str:
    """The value placeholder ``--help`` shows for an option: its metavar, else the plain
    type name (``TEXT``, ``INTEGER``, ``PATH``); nothing for an argument (its name is the
    placeholder). Replaces Typer's ``<str>``/``<bool>``/``<list[str]>`` labels."""
    if getattr(param, "param_type_name", "") == "argument":
        return ""
    if param.metavar:
        return param.metavar
    desc = getattr(param, "type_descriptor", None)
    ann = getattr(desc, "annotation", None)
    args = getattr(ann, "__args__", None)
    if args and len(args) == 1:  # list[X]
        ann = args[0]
    from pathlib import Path

    if isinstance(ann, type) and issubclass(ann, Path):
        return "PATH"
    return _TYPE_NAMES.get(ann, "VALUE")


def _fast_runtime_param(param):
    """A coercion of ``param``'s values without Pydantic, for the plain types this CLI uses
    (``str``, ``int``, ``float``, ``bool``, ``Path``, ``list`` of those; ``min``/``max``
    checked as Typer does), or ``None`` to keep Typer's own.

    Typer >= 0.2x validates every value with a Pydantic ``TypeAdapter``: importing Pydantic
    and building the adapters cost ~0.14 s of CPU per command, as much as the C++ tool takes
    for a whole tabulated fit. The behaviour is Typer's: the same accepted values, ranges and
    path checks (Typer's ``coerce_cli_path``), a ``BadParameter`` (exit status 2) otherwise.
    """
    try:
        from typer._coercion import RuntimeParam
        from typer._param_types import coerce_cli_path
    except ImportError:  # pragma: no cover - another Typer: keep its coercion
        return None
    desc = getattr(param, "type_descriptor", None)
    info = getattr(desc, "parameter_info", None)
    if desc is None or info is None or not hasattr(param, "_runtime_param"):
        return None
    try:
        if desc.is_choice or desc.is_file or desc.is_tuple or desc.is_datetime:
            return None
    except Exception:  # noqa: BLE001 - an unknown descriptor: keep Typer's
        return None
    if getattr(info, "parser", None) is not None or getattr(info, "click_type", None) is not None \
            or getattr(info, "clamp", False):
        return None
    from pathlib import Path

    ann = desc.annotation
    is_list = getattr(ann, "__origin__", None) is list
    leaf = ann.__args__[0] if is_list else ann
    if leaf not in (str, int, float, bool, Path):
        return None
    BadParameter = typer.BadParameter
    lo, hi = info.min, info.max

    def one(value, param, ctx):
        if leaf is str:
            if isinstance(value, bytes):
                value = value.decode("utf-8", "replace")
            return str(value)
        if leaf is Path:
            try:  # Typer's own checks (exists, file/dir, readable...), without Pydantic
                return Path(coerce_cli_path(value, info, path_type=None, param=param, ctx=ctx))
            except ValueError as exc:  # e.g. a NUL byte, which no file system allows
                raise BadParameter(f"{value!r} is not a valid path ({exc}).", ctx=ctx,
                                   param=param) from None
        if leaf is bool:
            if isinstance(value, bool):
                return value
            text = str(value).strip().lower()
            if text in ("1", "true", "t", "yes", "y", "on"):
                return True
            if text in ("", "0", "false", "f", "no", "n", "off"):
                return False
            raise BadParameter(f"{value!r} is not a valid boolean.", ctx=ctx, param=param)
        try:
            number = leaf(value) if not isinstance(value, leaf) else value
        except (TypeError, ValueError):
            kind = "an integer" if leaf is int else "a number"
            raise BadParameter(f"{value!r} is not {kind}.", ctx=ctx, param=param) from None
        if leaf is float and number != number:
            raise BadParameter(f"{value!r} is not a number.", ctx=ctx, param=param)
        if (lo is not None and number < lo) or (hi is not None and number > hi):
            rng = " and ".join(x for x in (f">= {lo}" if lo is not None else "",
                                           f"<= {hi}" if hi is not None else "") if x)
            raise BadParameter(f"{value!r} is not in the range {rng}.", ctx=ctx, param=param)
        return number

    class _Plain(RuntimeParam):
        def _coerce_value(self, value, param, ctx):
            if is_list or param.multiple or param.nargs == -1:
                return [one(v, param, ctx) for v in value]
            return one(value, param, ctx)

    return _Plain(parameter_info=info, annotation=ann)


def _tune_param(param) -> None:
    import types

    if hasattr(param, "display_type"):
        param.display_type = types.MethodType(_plain_type, param)
    if getattr(param, "_runtime_param", True) is None:
        fast = _fast_runtime_param(param)
        if fast is not None:
            param._runtime_param = fast


def _tune(command) -> None:
    """Plain type labels in ``--help`` and Pydantic-free value coercion for every parameter
    of ``command`` and its sub-commands (the help option too: Click makes it on demand)."""
    stack = [command]
    while stack:
        cmd = stack.pop()
        stack.extend(getattr(cmd, "commands", {}).values())
        for param in cmd.params:
            _tune_param(param)
        make_help = getattr(cmd, "get_help_option", None)
        if make_help is not None:
            def get_help_option(ctx, _make=make_help):
                option = _make(ctx)
                if option is not None:
                    _tune_param(option)
                return option

            cmd.get_help_option = get_help_option


def command(name: str | None = None):
    """The Click command of the ``brdffit`` app (:func:`_tune`-d): the whole app, or with
    ``name`` the app with that one command (what ``brdffit NAME ...`` runs: the other command
    modules are not imported and their Click commands not built)."""
    from typer.main import get_command

    cmd = get_command(build_app(None if name is None else [name]))
    _tune(cmd)
    return cmd


def _command_name(argv: list[str]) -> str | None:
    """The command ``argv`` runs, when it is one of ours (the root has no option that takes
    a value, so the first argument that is not an option is the command)."""
    first = next((a for a in argv if not a.startswith("-")), None)
    return first if first in _COMMAND_MODULES else None


def _click_usage_error(exc: BaseException) -> bool:
    """True for a usage error of Typer's Click or, when some command module imported it,
    of the real Click (not imported here: it is not needed to start)."""
    if isinstance(exc, _USAGE):
        return True
    real = sys.modules.get("click")
    return real is not None and isinstance(exc, real.ClickException)


def main(argv: list[str] | None = None) -> int:
    """Console-script entry point: runs the command and returns its exit status (module
    docstring). With ``standalone_mode=False`` Click *returns* the code of ``typer.Exit``
    (and raises everything else), so both are turned into a status here."""
    argv = list(sys.argv[1:] if argv is None else argv)
    single_thread_env()         # before NumPy loads: one BLAS thread (brdffit._blas)
    tune_this_process()         # arrays from the heap, not fresh pages (brdffit._malloc)
    debug = "--debug" in argv
    try:
        code = command(_command_name(argv)).main(args=argv, prog_name="brdffit",
                                                  standalone_mode=False)
    except _EXIT as exc:
        return exc.exit_code
    except _ABORT:
        print("brdffit: aborted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 – a bug or an unforeseen input: still one line
        if debug:
            raise
        if _click_usage_error(exc):
            exc.show()
            return exc.exit_code
        real = sys.modules.get("click")
        if real is not None and isinstance(exc, real.exceptions.Exit):
            return exc.exit_code
        if real is not None and isinstance(exc, real.exceptions.Abort):
            print("brdffit: aborted", file=sys.stderr)
            return 130
        if isinstance(exc, (BRDFError, OSError, ValueError)):
            print(f"brdffit: error: {exc}", file=sys.stderr)
        else:
            print(f"brdffit: error: {type(exc).__name__}: {exc} (--debug shows the traceback)",
                  file=sys.stderr)
        return EXIT_ERROR
    return code if isinstance(code, int) else EXIT_OK


def run() -> int:
    """The ``brdffit`` script and ``python -m brdffit``: :func:`main`, then ``gc.freeze()``
    just before the process exits. The interpreter's shutdown otherwise runs a last cyclic
    collection over every object the run created (modules, classes, Typer's command tree):
    18 ms of a 0.21 s tabulated fit process (8 %, measured: the same saving as skipping the
    shutdown with ``os._exit``). Unlike ``os._exit``, atexit handlers, stream flushing and
    module teardown still run; only ``__del__`` of objects in reference cycles still alive at
    exit may be skipped, which Python never guarantees anyway. Not in :func:`main`: a
    library caller (tests, notebooks) keeps its collector."""
    code = main()
    gc.freeze()
    return code


if __name__ == "__main__":  # pragma: no cover
    sys.exit(run())
