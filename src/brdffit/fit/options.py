"""The options of the fitters: their names, types and ranges, checked before any work.

A fitter's options are the keyword parameters of its function (after the BRDF) and, when it
takes ``**kwargs``, those of the functions it forwards them to (:func:`fitter_parameters`).
Each option's **type** comes from its annotation (``int``, ``float``, ``bool``, ``str``,
``tuple[int, int]``, ``Iterable[str]``; ``| None`` accepts ``None`` = the default) and its
**range** from :data:`RANGES`, one table for every fitter (an option name means the same
thing wherever it appears). :func:`check_fitter_options` is the one check of ``brdffit fit
-O``, ``compare --fit-options``, the demo's and the batch's options and
:func:`brdffit.fit.fit`, by model name through :func:`brdffit.fit.registry.check_options`
(this module knows fitting functions, not the registry).

>>> from brdffit.fit.registry import check_options
>>> check_options("ggx-diffuse", {"starts": 2, "theta_d_stride": 3})
{'starts': 2, 'theta_d_stride': 3}
>>> check_options("ggx-diffuse", {"phi_d_stride": -3})
Traceback (most recent call last):
...
brdffit.fit.options.OptionError: phi_d_stride: expected an integer in [1, 180], found -3
"""

from __future__ import annotations

import ast
import inspect
import math
import textwrap
from collections.abc import Mapping

__all__ = ["OptionError", "RANGES", "fitter_parameters", "check_fitter_options", "option_kind"]


class OptionError(ValueError):
    """A fitter option that does not exist, or a value of the wrong type or out of range."""


#: ``name: (low, high)`` of the numeric options (inclusive; ``low_open`` names below are
#: exclusive at ``low``). Upper bounds are what the data and the memory allow: the MERL grid
#: has 90 θh × 90 θd × 180 φd nodes, tables of ``n`` nodes per axis hold ``n²`` floats.
RANGES: dict[str, tuple[float, float]] = {
    # data strides and grids (MERL: 90 θh, 90 θd, 180 φd nodes)
    "theta_h_stride": (1, 90), "theta_d_stride": (1, 90), "phi_d_stride": (1, 180),
    "phi_stride": (1, 180), "n_phi_h": (1, 360),
    # table sizes of the tabulated fit (n × n_phi nodes)
    "n": (8, 1024), "n_phi": (1, 1024),
    # iteration caps and counts of starts
    "iterations": (1, 100_000), "max_iterations": (1, 100_000), "max_iter": (1, 100_000),
    "start_max_iter": (1, 100_000), "polish": (0, 100_000), "refine": (0, 100),
    "starts": (1, 100), "n_random": (0, 100),
    # the seed of the random starts: NumPy's generators take any 64-bit value, the
    # renderer's sampler 32 bits; one range for all
    "seed": (0, 2**32 - 1),
    # tolerances and floors
    "tol": (0.0, 1.0), "p_floor": (0.0, 1.0), "dr_epsilon": (0.0, 1.0),
    "fresnel_max": (0.0, 1e6), "fresnel_max_theta_deg": (0.0, 90.0),
    "max_theta_io_deg": (0.0, 90.0), "restrict_deg": (0.0, 90.0),
    "g_smoothing": (0.0, 1e6), "p": (0.0, 10.0),
}
#: Options whose valid values are not an interval: ``name: (test, what is expected)``.
SPECIAL = {"polish_bound": (lambda v: v == 0 or 1 < v <= 1e6,
                            "0 (no trust region) or a number in (1, 1e6]")}
#: Options whose lower bound is excluded (a tolerance of 0 never stops, an exponent of 0 is
#: no compression).
LOW_OPEN = {"tol", "p_floor", "dr_epsilon", "fresnel_max", "max_theta_io_deg",
            "restrict_deg", "p", "fresnel_max_theta_deg"}
#: Parameters that are not options of a command line (objects, callbacks).
NOT_OPTIONS = {"callback", "data", "objective", "source", "verbose"}


def fitter_parameters(fn, _seen: frozenset = frozenset(), _skip: int = 1
                      ) -> tuple[dict[str, inspect.Parameter], bool]:
    """``(parameters, open_ended)``: the keyword options a fitting function accepts.

    The named parameters after the BRDF (private ``_x`` ones excluded); when the function
    takes ``**kwargs``, those of the module-level functions it forwards them to
    (``f(brdf, **kwargs)`` in its source), recursively. ``open_ended`` is True when some
    ``**kwargs`` could not be followed: then unknown names cannot be ruled out up front.
    """
    fn = inspect.unwrap(fn)
    if fn in _seen:
        return {}, False
    try:
        params = list(inspect.signature(fn).parameters.values())
    except (TypeError, ValueError):
        return {}, True
    found: dict[str, inspect.Parameter] = {}
    var_kw = None
    for i, p in enumerate(params):
        if p.kind is p.VAR_KEYWORD:
            var_kw = p.name
        elif (p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY) and i >= _skip
              and not p.name.startswith("_")):
            found[p.name] = p
    if var_kw is None:
        return found, False
    try:
        tree = ast.parse(textwrap.dedent(inspect.getsource(fn)))
    except (OSError, TypeError, SyntaxError):
        return found, True
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
        sub, sub_open = fitter_parameters(callee, _seen | {fn}, len(node.args))
        given = {k.arg for k in node.keywords if k.arg}
        for name, p in sub.items():
            if name not in given:
                found.setdefault(name, p)
        open_ended |= sub_open
    return found, open_ended or not forwarded


def option_kind(param: inspect.Parameter) -> tuple[str, bool]:
    """``(kind, none_ok)`` of a parameter: kind ``"bool"``, ``"int"``, ``"float"``,
    ``"str"``, ``"int-pair"``, ``"names"`` (a sequence of strings) or ``"any"``."""
    ann = param.annotation
    text = ann if isinstance(ann, str) else ("" if ann is param.empty else
                                             getattr(ann, "__name__", str(ann)))
    default = param.default
    none_ok = "None" in text or default is None
    if "tuple[int, int]" in text:
        return "int-pair", none_ok
    if "Iterable[str]" in text or "Sequence[str]" in text or "list[str]" in text:
        return "names", none_ok
    words = set(text.replace("|", " ").replace("[", " ").replace("]", " ").split())
    for kind in ("bool", "float", "int", "str"):
        if kind in words:
            return kind, none_ok
    if isinstance(default, bool):
        return "bool", none_ok
    for typ, kind in ((int, "int"), (float, "float"), (str, "str")):
        if isinstance(default, typ):
            return kind, none_ok
    return "any", True


def _range_text(name: str) -> str:
    low, high = RANGES[name]
    left = "(" if name in LOW_OPEN else "["
    right = ")" if math.isinf(high) else "]"
    def fmt(v) -> str:
        if math.isinf(v):
            return "inf"
        return str(int(v)) if float(v).is_integer() and abs(v) < 1e15 else f"{v:g}"

    return f"{left}{fmt(low)}, {fmt(high)}{right}"


def _check_number(name: str, value, kind: str):
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise OptionError(f"{name}: expected {'an integer' if kind == 'int' else 'a number'}"
                          f"{' in ' + _range_text(name) if name in RANGES else ''}, found "
                          f"{value!r}")
    if isinstance(value, str):  # "inf", "1e-6" from a command line
        try:
            value = float(value)
        except ValueError:
            raise OptionError(f"{name}: expected a number, found {value!r}") from None
    if kind == "int":
        if isinstance(value, float):
            if not (math.isfinite(value) and value.is_integer()):
                raise OptionError(f"{name}: expected an integer"
                                  f"{' in ' + _range_text(name) if name in RANGES else ''}, "
                                  f"found {value!r}")
            value = int(value)
    elif math.isnan(value):
        raise OptionError(f"{name}: expected a number"
                          f"{' in ' + _range_text(name) if name in RANGES else ''}, found nan")
    if name in SPECIAL:
        test, expected = SPECIAL[name]
        if not test(value):
            raise OptionError(f"{name}: expected {expected}, found {value!r}")
    elif name in RANGES:
        low, high = RANGES[name]
        ok = (value > low if name in LOW_OPEN else value >= low) and value <= high
        if not ok:
            what = "an integer" if kind == "int" else "a number"
            raise OptionError(f"{name}: expected {what} in {_range_text(name)}, found {value!r}")
    elif kind == "float" and not math.isfinite(value):
        raise OptionError(f"{name}: expected a finite number, found {value!r}")
    return value


def check_value(name: str, param: inspect.Parameter, value):
    """``value`` of option ``name`` checked (and ``"1e-6"``-like strings made numbers)."""
    kind, none_ok = option_kind(param)
    if value is None:
        if none_ok:
            return None
        raise OptionError(f"{name}: expected a value, found null")
    if kind in ("int", "float"):
        return _check_number(name, value, kind)
    if kind == "bool":
        if not isinstance(value, bool):
            raise OptionError(f"{name}: expected true or false, found {value!r}")
        return value
    if kind == "str":
        if not isinstance(value, str) or len(value) > 200:
            raise OptionError(f"{name}: expected a string (the fitter's choices), found "
                              f"{value!r}")
        return value
    if kind == "int-pair":
        if not (isinstance(value, (list, tuple)) and len(value) == 2):
            raise OptionError(f"{name}: expected two integers, e.g. [18, 8], found {value!r}")
        out = []
        for v in value:
            if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 10_000:
                raise OptionError(f"{name}: expected two integers in [1, 10000], found "
                                  f"{value!r}")
            out.append(v)
        return tuple(out)
    if kind == "names":
        if isinstance(value, str):
            value = [value]
        if not (isinstance(value, (list, tuple)) and value and len(value) <= 100
                and all(isinstance(v, str) and len(v) <= 200 for v in value)):
            raise OptionError(f"{name}: expected a list of names, e.g. [\"ones\"], found "
                              f"{value!r}")
        return tuple(value)
    return value


def check_fitter_options(fn, options: Mapping, *, model: str,
                         command_line: bool = False) -> dict:
    """The options of a fit with the fitting function ``fn`` (of the model named ``model``,
    for messages), checked: names the fitter takes, types and ranges (module docstring);
    with ``command_line``, the parameters that take Python objects (:data:`NOT_OPTIONS`) are
    unknown names. Returns the options with numbers from strings converted; raises
    :class:`OptionError` (one line, naming the option)."""
    params, open_ended = fitter_parameters(fn)
    offered = {n: p for n, p in params.items() if n not in NOT_OPTIONS}
    if command_line:
        params = offered
    out = {}
    for name, value in options.items():
        if name not in params:
            if open_ended:
                out[name] = value
                continue
            raise OptionError(f"model {model!r} has no option {name!r}; accepted: "
                              f"{', '.join(sorted(offered)) or 'none'}")
        out[name] = check_value(name, params[name], value)
    return out
