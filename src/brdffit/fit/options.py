"""The options of the fitters: one frozen dataclass per fitting function, checked before any work.

Each declared model of :data:`brdffit.fit.registry.MODELS` names its options class
(``options="options:TabulatedOptions"``, resolved on first use). A class's fields are the
keyword options of the fitting function, with its **types** (``int``, ``float``, ``bool``,
``str``, ``tuple[int, int]``, ``tuple[str, ...]``; a ``Literal`` of strings such as
:data:`RadialRule` lists a string option's **choices**, which the fitting function's
signature and its own check (:func:`check_choice`) share; ``| None`` accepts ``None``, which
means the function's own default) and its **defaults**, exactly those of the function's
signature (tests/fit/test_options.py checks them against it). Models fitted by the same
function share its class (``ggx`` and ``beckmann`` are the tabulated fit converted; the
NPF variants are one function). The **ranges** are one table, :data:`RANGES`, for every
fitter: an option name means the same thing wherever it appears.

:func:`check_values` is the one check of ``brdffit fit -O``, ``compare --fit-options``, the
demo's and the batch's options and :func:`brdffit.fit.fit`, by model name through
:func:`brdffit.fit.registry.check_options`. Options that take Python objects (callbacks,
objective settings, in-memory data) are marked :data:`PYTHON_ONLY` and are unknown names on
a command line. A fitter registered by a plug-in without a class gets one made from its
signature (:func:`signature_options`).

This module imports neither NumPy nor the fitting modules: ``brdffit models --options``
lists the options without loading the fitting stack.

>>> from brdffit.fit.registry import check_options
>>> check_options("ggx-diffuse", {"starts": 2, "theta_d_stride": 3})
{'starts': 2, 'theta_d_stride': 3}
>>> check_options("ggx-diffuse", {"phi_d_stride": -3})
Traceback (most recent call last):
...
brdffit.fit.options.OptionError: phi_d_stride: expected an integer in [1, 180], found -3
"""

import dataclasses
import inspect
import math
import types
import typing
from collections.abc import Mapping
from typing import Any, Literal, Union

__all__ = ["OptionError", "RANGES", "PYTHON_ONLY", "Option", "TabulatedOptions",
           "DiffuseOptions", "TwoSliceOptions", "CookTorranceOptions", "NPFOptions",
           "option_table", "signature_options", "check_values", "check_choice",
           "describe_option", "RadialRule", "Hotspot", "FresnelChoice", "F90", "Coat",
           "Weighting", "SliceOrFull", "NPFStart", "NPFInit"]


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
# -- the string options' choices: one ``Literal`` each, read by the checks below, the options
# classes, the fitting functions' signatures and their own checks (:func:`check_choice`)
#: radial rule of the tabulated fit (``"auto"``: MERL nodes for isotropic MERL-grid input)
RadialRule = Literal["auto", "merl", "gauss"]
#: the tabulated fit's hotspot term (G1 or G2 in the backscattering kernel)
Hotspot = Literal["G1", "G2"]
#: Fresnel term of the analytic fits
FresnelChoice = Literal["auto", "schlick", "dielectric", "conductor"]
#: the analytic fits' grazing reflectance: 1 or fitted
F90 = Literal["one", "free"]
#: the analytic fits' clear coat
Coat = Literal["auto", "off", "on"]
#: the weights of the two-slice fits' slice fit
Weighting = Literal["relative", "cosine"]
#: the two-slice fits' selection and linear solve: on the full data or the slices
SliceOrFull = Literal["full", "slice"]
#: the starts of the NPF fits (independent-G's ``starts``)
NPFStart = Literal["random", "ones", "sgd", "g-from-d", "slices"]
#: a single start of the NPF fits (``init``)
NPFInit = Literal["slices", "ones", "random"]

#: Field metadata of an option that takes a Python object (or only makes sense from
#: Python): accepted by :func:`brdffit.fit.fit`, an unknown name on a command line.
PYTHON_ONLY = {"python_only": True}


def _python(default=None):
    return dataclasses.field(default=default, metadata=PYTHON_ONLY)


# -- the options of each fitting function ---------------------------------------------------
@dataclasses.dataclass(frozen=True)
class TabulatedOptions:
    """Options of :func:`brdffit.fit.tabulated.fit_tabulated` (models ``tabulated``,
    ``ggx``, ``beckmann``; the last two convert the tabulated fit by slope moments)."""

    n: int = 90
    iterations: int | None = None
    tol: float | None = None
    anisotropic: bool | None = None
    per_channel: bool = False
    n_phi: int = 90
    rule: RadialRule = "auto"
    hotspot: Hotspot = "G2"
    max_iterations: int = 1000
    fresnel_max: float = 1.0
    p_floor: float = 1e-6
    fresnel_max_theta_deg: float | None = 89.0
    diffuse: bool = True


@dataclasses.dataclass(frozen=True)
class DiffuseOptions:
    """Options of :func:`brdffit.fit.analytic.fit_analytic_diffuse` (models
    ``ggx-diffuse``, ``beckmann-diffuse``; the distribution is the model's)."""

    anisotropic: bool | None = None
    fresnel: FresnelChoice = "auto"
    f90: F90 = "free"
    starts: int = 3
    moments: bool = True
    theta_d_stride: int | None = None
    phi_d_stride: int | None = None
    theta_h_stride: int = 3
    n_phi_h: int = 12
    objective: Any = _python()
    coat: Coat = "auto"
    name: str | None = None


@dataclasses.dataclass(frozen=True)
class TwoSliceOptions:
    """Options of :func:`brdffit.fit.sgd.fit_two_slice` (models ``sgd``, ``beckmann-2s``,
    ``ggx-2s``; the distribution is the model's)."""

    weighting: Weighting = "cosine"
    starts: int = 3
    grid: tuple[int, int] = (18, 8)
    g1_approximation: bool = True
    selection: SliceOrFull = "full"
    linear: SliceOrFull = "full"
    bounded: bool = True
    selection_strides: tuple[int, int] = (4, 15)
    scan_grid: bool = True
    refine: int = 1
    name: str | None = None


@dataclasses.dataclass(frozen=True)
class CookTorranceOptions:
    """Options of :func:`brdffit.fit.sgd.fit_cook_torrance` (models ``beckmann-ct``,
    ``ggx-ct``; the distribution is the model's)."""

    theta_d_stride: int = 4
    phi_stride: int = 15
    starts: int = 2
    name: str | None = None


@dataclasses.dataclass(frozen=True)
class NPFOptions:
    """Options of :func:`brdffit.fit.npf.fit_npf` (models ``npf``, ``npf-g-from-d``,
    ``npf-naive``, ``npf-bivariate``; the variant is the model's). ``None`` for
    ``max_iter``, ``polish``, ``polish_bound`` and ``dr_epsilon`` means the variant's
    default (:data:`brdffit.fit.npf.DEFAULT_MAX_ITER`, ``DEFAULT_POLISH``...)."""

    data: Any = _python()
    compressive: bool = True
    restrict_deg: float | None = None
    p: float = 1.4
    max_theta_io_deg: float = 89.0
    max_iter: int | None = None
    tol: float = 1e-6
    starts: tuple[NPFStart, ...] | None = None
    n_random: int = 4
    seed: int = 0
    g_smoothing: float = 1.0
    dr_epsilon: float | None = None
    start_max_iter: int | None = 100
    polish: int | None = None
    polish_bound: float | None = None
    extrapolate: bool = True
    init: NPFInit | None = None
    name: str | None = None
    callback: Any = _python()
    verbose: bool = _python(False)


# -- reading a class ---------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Option:
    """One option as the checks and the listings read it.

    ``kind``: ``"bool"``, ``"int"``, ``"float"``, ``"str"``, ``"int-pair"``, ``"names"`` (a
    sequence of strings) or ``"any"``; ``none_ok``: ``None`` is accepted (the function's
    default); ``python_only``: not an option of a command line; ``choices``: the values a
    ``"str"`` option or each name of a ``"names"`` option may take (its ``Literal``; empty:
    any string).
    """

    name: str
    kind: str
    none_ok: bool
    default: Any
    python_only: bool = False
    choices: tuple[str, ...] = ()


_SCALARS = ((bool, "bool"), (int, "int"), (float, "float"), (str, "str"))


def _choices(annotation) -> tuple[str, ...] | None:
    """The values of a ``Literal`` of strings, or ``None`` for any other type."""
    if typing.get_origin(annotation) is Literal:
        values = typing.get_args(annotation)
        if values and all(isinstance(v, str) for v in values):
            return values
    return None


def _kind_of(annotation, default) -> tuple[str, bool, tuple[str, ...]]:
    """``(kind, none_ok, choices)`` of a type (a union with ``None`` accepts ``None``; a
    ``Literal`` of strings is a ``"str"`` with those choices)."""
    args = typing.get_args(annotation)
    none_ok = default is None
    if typing.get_origin(annotation) in (Union, types.UnionType):
        none_ok |= type(None) in args
        args = [a for a in args if a is not type(None)]
        annotation = args[0] if len(args) == 1 else Any
        args = typing.get_args(annotation)
    if (choices := _choices(annotation)) is not None:
        return "str", none_ok, choices
    if typing.get_origin(annotation) in (tuple, list, typing.get_origin(typing.Sequence[str])):
        names = [a for a in args if a is not Ellipsis]
        if names and all(a is str for a in names):
            return "names", none_ok, ()
        if len(names) == 1 and (choices := _choices(names[0])) is not None:
            return "names", none_ok, choices
        if args == (int, int):
            return "int-pair", none_ok, ()
        return "any", True, ()
    for typ, kind in _SCALARS:
        if annotation is typ:
            return kind, none_ok, ()
    return "any", True, ()


def option_table(cls) -> dict[str, Option]:
    """The :class:`Option` of every field of an options dataclass ``cls``, in field order."""
    hints = typing.get_type_hints(cls)
    out = {}
    for f in dataclasses.fields(cls):
        kind, none_ok, choices = _kind_of(hints[f.name], f.default)
        out[f.name] = Option(f.name, kind, none_ok, f.default,
                             bool(f.metadata.get("python_only")), choices)
    return out


def signature_options(fn) -> tuple[type, bool]:
    """``(cls, open_ended)`` for a fitting function without a declared class (a plug-in's):
    a dataclass of its keyword parameters after the BRDF (private ``_x`` ones excluded),
    typed by their annotations or, without one, by their defaults. ``open_ended`` is True
    when the function takes ``**kwargs``: then unknown names cannot be ruled out up front."""
    try:
        params = list(inspect.signature(inspect.unwrap(fn)).parameters.values())[1:]
    except (TypeError, ValueError):
        return dataclasses.make_dataclass("NoOptions", []), True
    fields, open_ended = [], False
    for p in params:
        if p.kind is p.VAR_KEYWORD:
            open_ended = True
        elif p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY) and not p.name.startswith("_"):
            default = None if p.default is p.empty else p.default
            ann = p.annotation
            if ann is p.empty or isinstance(ann, str):
                ann = type(default) if isinstance(default, (bool, int, float, str)) else Any
            fields.append((p.name, ann, dataclasses.field(default=default)))
    name = f"{getattr(fn, '__name__', 'fit')}_options"
    return dataclasses.make_dataclass(name, fields, frozen=True), open_ended


def describe_option(option: Option) -> str:
    """One line about an option: ``name (kind, default D, range R)``."""
    kind = {"int-pair": "two integers", "names": "list of names"}.get(option.kind, option.kind)
    parts = [kind + (" or null" if option.none_ok and option.default is not None else "")]
    parts.append(f"default {option.default!r}" if option.default is not None
                 else "default: the fitter's")
    if option.choices:
        parts.append(("each " if option.kind == "names" else "") + "one of "
                     + ", ".join(map(repr, option.choices)))
    elif option.name in SPECIAL:
        parts.append(SPECIAL[option.name][1])
    elif option.name in RANGES and option.kind in ("int", "float"):
        parts.append(f"in {_range_text(option.name)}")
    return f"{option.name} ({', '.join(parts)})"


# -- checking values ---------------------------------------------------------------------------
def _range_text(name: str) -> str:
    low, high = RANGES[name]
    left = "(" if name in LOW_OPEN else "["
    right = ")" if math.isinf(high) else "]"

    def fmt(v) -> str:
        if math.isinf(v):
            return "inf"
        return str(int(v)) if float(v).is_integer() and abs(v) < 1e15 else f"{v:g}"

    return f"{left}{fmt(low)}, {fmt(high)}{right}"


def _expected(name: str, kind: str) -> str:
    what = "an integer" if kind == "int" else "a number"
    return what + (f" in {_range_text(name)}" if name in RANGES else "")


def _as_number(name: str, value, kind: str):
    """``value`` as an int or float (strings such as ``"1e-6"`` from a command line)."""
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise OptionError(f"{name}: expected {_expected(name, kind)}, found {value!r}")
    if isinstance(value, str):
        try:
            value = float(value)
        except ValueError:
            raise OptionError(f"{name}: expected a number, found {value!r}") from None
    if kind == "int" and isinstance(value, float):
        if not (math.isfinite(value) and value.is_integer()):
            raise OptionError(f"{name}: expected {_expected(name, kind)}, found {value!r}")
        value = int(value)
    elif kind == "float" and math.isnan(value):
        raise OptionError(f"{name}: expected {_expected(name, kind)}, found nan")
    return value


def _check_number(name: str, value, kind: str):
    value = _as_number(name, value, kind)
    if name in SPECIAL:
        test, expected = SPECIAL[name]
        if not test(value):
            raise OptionError(f"{name}: expected {expected}, found {value!r}")
    elif name in RANGES:
        low, high = RANGES[name]
        if not ((value > low if name in LOW_OPEN else value >= low) and value <= high):
            raise OptionError(f"{name}: expected {_expected(name, kind)}, found {value!r}")
    elif kind == "float" and not math.isfinite(value):
        raise OptionError(f"{name}: expected a finite number, found {value!r}")
    return value


def _check_pair(name: str, value) -> tuple:
    if not (isinstance(value, (list, tuple)) and len(value) == 2):
        raise OptionError(f"{name}: expected two integers, e.g. [18, 8], found {value!r}")
    if any(isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 10_000
           for v in value):
        raise OptionError(f"{name}: expected two integers in [1, 10000], found {value!r}")
    return tuple(value)


def _one_of(choices) -> str:
    """``'a', 'b' or 'c'``."""
    quoted = [repr(c) for c in choices]
    return quoted[0] if len(quoted) == 1 else ", ".join(quoted[:-1]) + " or " + quoted[-1]


def check_choice(name: str, value, choices) -> str:
    """``value`` if it is one of ``choices`` (a ``Literal`` of strings or a sequence), else
    :class:`OptionError` naming the option, the choices and the value. The one check of the
    string options, before any work (:func:`check_values`) and in the fitting functions."""
    allowed = _choices(choices) or tuple(choices)
    if not isinstance(value, str) or value not in allowed:
        raise OptionError(f"{name}: expected {_one_of(allowed)}, found {value!r}")
    return value


def _check_names(name: str, value, choices=()) -> tuple:
    if isinstance(value, str):
        value = [value]
    if not (isinstance(value, (list, tuple)) and value and len(value) <= 100
            and all(isinstance(v, str) and len(v) <= 200 for v in value)):
        example = choices[0] if choices else "ones"
        raise OptionError(f"{name}: expected a list of names, e.g. [\"{example}\"], found "
                          f"{value!r}")
    bad = [v for v in value if choices and v not in choices]
    if bad:
        raise OptionError(f"{name}: expected names among {_one_of(choices)}, found "
                          f"{bad[0]!r}")
    return tuple(value)


def check_value(option: Option, value):
    """``value`` of ``option`` checked (type, range, choices) and converted (``"1e-6"`` → 1e-6,
    ``5.0`` → 5 for an integer, lists → tuples)."""
    name, kind = option.name, option.kind
    if value is None:
        if option.none_ok:
            return None
        raise OptionError(f"{name}: expected a value, found null")
    if kind in ("int", "float"):
        return _check_number(name, value, kind)
    if kind == "bool":
        if not isinstance(value, bool):
            raise OptionError(f"{name}: expected true or false, found {value!r}")
        return value
    if kind == "str" and option.choices:
        return check_choice(name, value, option.choices)
    if kind == "str":
        if not isinstance(value, str) or len(value) > 200:
            raise OptionError(f"{name}: expected a string of at most 200 characters, found "
                              f"{value!r}")
        return value
    if kind == "int-pair":
        return _check_pair(name, value)
    if kind == "names":
        return _check_names(name, value, option.choices)
    return value


def check_values(cls, options: Mapping, *, model: str, open_ended: bool = False,
                 command_line: bool = False) -> dict:
    """The ``options`` of a fit checked against the options dataclass ``cls`` of model
    ``model`` (named in messages): names it declares, types and ranges; with
    ``command_line``, :data:`PYTHON_ONLY` options are unknown names; with ``open_ended``
    (a plug-in taking ``**kwargs``), unknown names pass unchecked. Returns only the
    options given, numbers from strings converted; raises :class:`OptionError` (one line,
    naming the option)."""
    table = option_table(cls)
    offered = {n: o for n, o in table.items() if not o.python_only}
    known = offered if command_line else table
    out = {}
    for name, value in options.items():
        if name not in known:
            if open_ended:
                out[name] = value
                continue
            raise OptionError(f"model {model!r} has no option {name!r}; accepted: "
                              f"{', '.join(sorted(offered)) or 'none'}")
        out[name] = check_value(known[name], value)
    return out
