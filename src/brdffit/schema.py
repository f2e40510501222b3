"""Declarative state schemas of the serialisable models (what a valid fit file may hold).

A fit file (:mod:`brdffit.io.fitfile`) stores a model as JSON ``params`` plus named arrays
(:meth:`~brdffit.serialization.SerializableModel.to_state`). Before a model is rebuilt from a
file it did not write, brdffit checks that state against the model's **schema**: a table of
fields, each with its type, shape, dtype and physical range, in the spirit of Mitsuba 3's
plugin parameter tables. Each model kind and each registered component (distribution,
Fresnel) declares one as a class attribute::

    class GGX(...):
        state_schema = Schema(params={"alpha_x": Number(gt=0, le=ALPHA_MAX), ...})

and :func:`validate_state` walks it. A field that does not match raises
:class:`StateError` whose message names the field's JSON path, what was expected and what
was found, e.g. ``params.distribution.params.alpha_x: expected a finite number > 0 and
<= 100, found -1``; :func:`brdffit.io.fitfile.load_fit` turns it into a
:class:`~brdffit.errors.BRDFFormatError` naming the file.

Validation runs twice on load: first on the **array headers** only (:class:`ArrayHeader`:
shape and dtype read from the ``.npy`` headers, before any table is decompressed; shapes
have hard element bounds, so a declared 24 TiB array is rejected without reading it), then on
the loaded values (finiteness, ranges, monotonicity).

Building blocks: :class:`Number`, :class:`Integer`, :class:`RGB`, :class:`Text`,
:class:`Bool`, :class:`Choice`, :class:`Opt` (``null`` allowed), :class:`Nested` (an object
with its own schema), :class:`ListOf` (lists, optionally giving each item its own array
prefix ``c0.``, ``c1.``...), :class:`Component` (a ``{"kind", "params"}`` object whose
schema is that of the class registered under ``kind``), :class:`Array`; :class:`Schema`
collects them (unknown ``params`` keys are ignored; every array in the file must be declared
by some schema).

Physical bounds (generous: they reject nonsense, not unusual fits)
-----------------------------------------------------------------
=======================  ==============================  ========================================
constant                 value                           used for
=======================  ==============================  ========================================
``ALPHA_MAX``            100                             slope scales α, αx, αy, SGD α;
                                                         fitters stay below 3
``ALPHA_MIN``            1e-6                            their lower bound: α² and α⁴ stay
                                                         normal float32 numbers (a GLSL or glTF
                                                         target divides by them); far below
                                                         MERL's finest θh cell (1.9e-4 rad)
``TINY``                 1e-30                           any nonzero number: a smaller magnitude
                                                         (a denormal such as 5e-324) is refused,
                                                         it underflows to 0 in float32
``P_EXPONENT_MAX``       100                             SGD exponent ``|p|`` (fits: −2 … 4)
``ALBEDO_MAX``           10                              Lambertian ρd (≥ 0)
``SPECULAR_MAX``         1e3                             specular scales ks, SGD ρs (≥ 0)
``FRESNEL_MAX``          1e4                             Fresnel tables (≥ 0; the tabulated fit
                                                         clips its extracted curve at 100)
``INDEX_MAX``            100                             refractive indices η (> 0), k (≥ 0)
``FACTOR_MAX``           1e8                             NPF factors D, F, G, H, ρd, ρs and the
                                                         bivariate table B (≥ 0; fits are
                                                         max-normalised, ρs carries the peak:
                                                         up to 6e4 on MERL materials)
``TABLE_MAX``            1e15                            tabulated slope PDF P (≥ 0, not all 0)
``F1_MAX``               1e12                            ``|F1|`` of Bagher 2012 Eq. 11 (the fit
                                                         can return F1 ≪ 0 when ρs → 0)
=======================  ==============================  ========================================

The Fresnel ``f0`` of Schlick and ``F0`` of the generalised Schlick Fresnel are in [0, 1];
correlations ρ in (−1, 1); table sizes are bounded per kind (e.g. a tabulated P has at most
4096 radial nodes, 2D tables at most 65,536 entries).
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np

__all__ = ["StateError", "ArrayHeader", "Schema", "Number", "Numbers", "Integer", "RGB", "Text",
           "Bool",
           "Choice", "Opt", "Nested", "ListOf", "Component", "Array", "Any_",
           "validate_state", "schema_of", "ALPHA_MAX", "P_EXPONENT_MAX", "ALBEDO_MAX",
           "SPECULAR_MAX", "FRESNEL_MAX", "INDEX_MAX", "FACTOR_MAX", "TABLE_MAX", "F1_MAX",
           "ALPHA_MIN", "TINY",
           "MAX_ARRAY_ELEMENTS"]

ALPHA_MAX = 100.0
ALPHA_MIN = 1e-6
TINY = 1e-30
P_EXPONENT_MAX = 100.0
ALBEDO_MAX = 10.0
SPECULAR_MAX = 1e3
FRESNEL_MAX = 1e4
INDEX_MAX = 100.0
FACTOR_MAX = 1e8
TABLE_MAX = 1e15
F1_MAX = 1e12
#: elements of one array of a kind without a schema (generic check), 8 Mi
MAX_ARRAY_ELEMENTS = 1 << 23


class StateError(ValueError):
    """A model state that does not match its schema; ``field`` is the JSON path."""

    def __init__(self, field: str, message: str):
        self.field = field
        self.message = message
        super().__init__(f"{field}: {message}" if field else message)


@dataclass(frozen=True)
class ArrayHeader:
    """Shape and dtype of a stored array, known before its data are read."""

    shape: tuple
    dtype: np.dtype

    @property
    def size(self) -> int:
        return math.prod(self.shape)


# ------------------------------------------------------------------------------------------
# formatting
# ------------------------------------------------------------------------------------------
def show(value, limit: int = 60) -> str:
    """A short JSON-like rendering of a found value for messages."""
    if value is None:
        return "null"
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if isinstance(value, str):
        r = repr(value if len(value) <= limit else value[:limit] + "...")
        return f"the string {r}"
    if isinstance(value, numbers.Number):
        return repr(float(value)) if isinstance(value, (float, np.floating)) else str(value)
    if isinstance(value, Mapping):
        return f"an object with {len(value)} keys"
    if isinstance(value, (list, tuple)):
        if len(value) <= 4 and all(isinstance(v, (numbers.Number, str, type(None))) for v in value):
            s = "[" + ", ".join(repr(v) if isinstance(v, str) else show(v) for v in value) + "]"
            if len(s) <= limit:
                return s
        return f"a list of {len(value)} items"
    return f"a {type(value).__name__}"


def _bound_text(x: float) -> str:
    """A bound of a :class:`Number` as the error messages show it (``%g``)."""
    return f"{x:g}"


def _is_number(v) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_))


# ------------------------------------------------------------------------------------------
# scope: the arrays visible to a schema (a prefix into the file's arrays)
# ------------------------------------------------------------------------------------------
class Scope:
    """Arrays of the state under ``prefix``; records which arrays a schema claimed."""

    def __init__(self, arrays: Mapping[str, Any], prefix: str = "", claimed: set | None = None):
        self.arrays = arrays
        self.prefix = prefix
        self.claimed = set() if claimed is None else claimed

    def sub(self, prefix: str) -> "Scope":
        return Scope(self.arrays, self.prefix + prefix, self.claimed)

    def key(self, name: str) -> str:
        return self.prefix + name

    def under(self) -> list[str]:
        return [k for k in self.arrays if k.startswith(self.prefix)]


def array_field(key: str) -> str:
    return f"arrays[{key!r}]"


# ------------------------------------------------------------------------------------------
# value validators
# ------------------------------------------------------------------------------------------
class Validator:
    """Checks one JSON value; raises :class:`StateError` naming ``path``."""

    def check(self, value, path: str, scope: Scope) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def describe(self) -> str:  # pragma: no cover - abstract
        raise NotImplementedError


class Any_(Validator):
    """Any JSON value (free-form metadata)."""

    def check(self, value, path, scope):
        return None

    def describe(self):
        return "any value"


class Number(Validator):
    """A finite real number (not a boolean, not a string) within optional bounds, 0 or of a
    magnitude of at least :data:`TINY` (no denormals)."""

    def __init__(self, *, ge=None, gt=None, le=None, lt=None):
        self.ge, self.gt, self.le, self.lt = ge, gt, le, lt

    def _range(self) -> str:
        parts = []
        if self.gt is not None:
            parts.append(f"> {_bound_text(self.gt)}")
        if self.ge is not None:
            parts.append(f">= {_bound_text(self.ge)}")
        if self.lt is not None:
            parts.append(f"< {_bound_text(self.lt)}")
        if self.le is not None:
            parts.append(f"<= {_bound_text(self.le)}")
        return " and ".join(parts)

    def describe(self) -> str:
        r = self._range()
        return "a finite number" + (f" {r}" if r else "")

    def ok(self, v: float) -> bool:
        return ((self.gt is None or v > self.gt) and (self.ge is None or v >= self.ge)
                and (self.lt is None or v < self.lt) and (self.le is None or v <= self.le))

    def check(self, value, path, scope):
        if not _is_number(value) or not math.isfinite(float(value)) or not self.ok(float(value)):
            raise StateError(path, f"expected {self.describe()}, found {show(value)}")
        if 0.0 < abs(float(value)) < TINY:
            raise StateError(path, f"expected {self.describe()} of magnitude >= {TINY:g} (or "
                                   f"0), found {show(value)}")


class Integer(Number):
    """An integer (not a boolean) within optional bounds."""

    def describe(self) -> str:
        r = self._range()
        return "an integer" + (f" {r}" if r else "")

    def check(self, value, path, scope):
        if not isinstance(value, (int, np.integer)) or isinstance(value, (bool, np.bool_)) \
                or not self.ok(int(value)):
            raise StateError(path, f"expected {self.describe()}, found {show(value)}")


class _NumberOrList(Validator):
    """A number checked by ``Number(**bounds)`` or a list of such numbers: the list's form
    is the subclass's (:meth:`list_text`, :meth:`check_list`)."""

    def __init__(self, **bounds):
        self.item = Number(**bounds)

    def list_text(self) -> str:
        raise NotImplementedError

    def check_list(self, value, path, scope):
        raise NotImplementedError

    def describe(self) -> str:
        return f"{self.item.describe()} or {self.list_text()}"

    def check(self, value, path, scope):
        if _is_number(value):
            self.item.check(value, path, scope)
            return
        self.check_list(value, path, scope)


class RGB(_NumberOrList):
    """A number or a list of 3 numbers, each checked by ``Number(**bounds)``."""

    def list_text(self) -> str:
        return "a list of 3 of them"

    def check_list(self, value, path, scope):
        if not isinstance(value, (list, tuple)) or len(value) != 3:
            raise StateError(path, f"expected {self.describe()}, found {show(value)}")
        for i, v in enumerate(value):
            self.item.check(v, f"{path}[{i}]", scope)


class Numbers(_NumberOrList):
    """A number, or a (nested) list of at most ``max_size`` numbers, each checked by
    ``Number(**bounds)`` (e.g. per-texel roughness)."""

    def __init__(self, max_size: int = 4096, max_depth: int = 4, **bounds):
        super().__init__(**bounds)
        self.max_size, self.max_depth = max_size, max_depth

    def list_text(self) -> str:
        return f"a list of at most {self.max_size} of them"

    def check_list(self, value, path, scope):
        if not isinstance(value, list):
            raise StateError(path, f"expected {self.describe()}, found {show(value)}")
        stack, count = [(value, path, 1)], 0
        while stack:
            v, p, depth = stack.pop()
            if isinstance(v, list):
                if depth > self.max_depth or len(v) == 0:
                    raise StateError(p, f"expected {self.describe()}, found {show(v)}")
                stack.extend((x, f"{p}[{i}]", depth + 1) for i, x in enumerate(v))
            else:
                count += 1
                if count > self.max_size:
                    raise StateError(path, f"expected {self.describe()}, found more")
                self.item.check(v, p, scope)


class Text(Validator):
    """A string of at most ``max_len`` characters."""

    def __init__(self, max_len: int = 4096):
        self.max_len = max_len

    def describe(self):
        return f"a string of at most {self.max_len} characters"

    def check(self, value, path, scope):
        if not isinstance(value, str) or len(value) > self.max_len:
            raise StateError(path, f"expected {self.describe()}, found {show(value)}")


class Bool(Validator):
    """``true`` or ``false``."""

    def describe(self):
        return "true or false"

    def check(self, value, path, scope):
        if not isinstance(value, bool):
            raise StateError(path, f"expected {self.describe()}, found {show(value)}")


class Choice(Validator):
    """One of the given values."""

    def __init__(self, *values):
        self.values = values

    def describe(self):
        return "one of " + ", ".join(show(v) if not isinstance(v, str) else repr(v)
                                     for v in self.values)

    def check(self, value, path, scope):
        if isinstance(value, bool) or not isinstance(value, (str, int, float, type(None))) \
                or value not in self.values:
            raise StateError(path, f"expected {self.describe()}, found {show(value)}")


class Opt(Validator):
    """``null`` or a value accepted by ``inner``."""

    def __init__(self, inner: Validator):
        self.inner = inner

    def describe(self):
        return f"null or {self.inner.describe()}"

    def check(self, value, path, scope):
        if value is not None:
            self.inner.check(value, path, scope)


class Nested(Validator):
    """An object validated by its own :class:`Schema` (arrays under ``prefix``)."""

    def __init__(self, schema: "Schema | Callable[[], Schema]", prefix: str = ""):
        self._schema = schema
        self.prefix = prefix

    @property
    def schema(self) -> "Schema":
        return self._schema() if callable(self._schema) and not isinstance(self._schema, Schema) \
            else self._schema

    def describe(self):
        return "an object"

    def check(self, value, path, scope):
        self.schema.validate(value, path, scope.sub(self.prefix))


class ListOf(Validator):
    """A list of ``min_len``…``max_len`` items; item ``i`` sees the arrays under
    ``item_prefix.format(index=i)`` (e.g. ``"c{index}."``)."""

    def __init__(self, item: Validator, *, min_len: int = 0, max_len: int = 64,
                 item_prefix: str = ""):
        self.item, self.min_len, self.max_len, self.item_prefix = item, min_len, max_len, item_prefix

    def describe(self):
        n = (f"{self.min_len}" if self.min_len == self.max_len
             else f"{self.min_len} to {self.max_len}")
        return f"a list of {n} items"

    def check(self, value, path, scope):
        if not isinstance(value, list) or not self.min_len <= len(value) <= self.max_len:
            raise StateError(path, f"expected {self.describe()}, found {show(value)}")
        for i, v in enumerate(value):
            self.item.check(v, f"{path}[{i}]", scope.sub(self.item_prefix.format(index=i)))


class Component(Validator):
    """A ``{kind_key: KIND, params_key: {...}}`` object whose params and arrays follow the
    schema of the class ``lookup(KIND)`` (a registered distribution, Fresnel or model kind).

    ``lookup`` raises ``ValueError``/``KeyError`` for an unknown kind. ``prefix`` is the
    array prefix of the component (``"distribution."``).
    """

    def __init__(self, lookup: Callable[[str], type], *, prefix: str = "", kind_key: str = "kind",
                 params_key: str = "params", what: str = "component"):
        self.lookup, self.prefix = lookup, prefix
        self.kind_key, self.params_key, self.what = kind_key, params_key, what

    def describe(self):
        return f"a {self.what} object with a {self.kind_key!r}"

    def check(self, value, path, scope):
        if not isinstance(value, Mapping):
            raise StateError(path, f"expected {self.describe()}, found {show(value)}")
        kind = value.get(self.kind_key)
        kpath = f"{path}.{self.kind_key}"
        if not isinstance(kind, str) or not kind or len(kind) > 256:
            raise StateError(kpath, f"expected a {self.what} kind name, found {show(kind)}")
        try:
            cls = self.lookup(kind)
        except (KeyError, ValueError, TypeError, ImportError) as exc:
            msg = " ".join(str(exc).strip("'\"").split())[:300]
            raise StateError(kpath, msg or f"unknown {self.what} kind {kind!r}") from None
        params = value.get(self.params_key)
        params = {} if params is None else params
        validate_class_state(cls, params, f"{path}.{self.params_key}", scope.sub(self.prefix))


class Array(Validator):
    """A stored array ``NAME`` (relative to the scope's prefix).

    ``shape``: a tuple of ints and dimension names, or a list of such tuples (alternatives);
    a name (``"n"``) takes the same value everywhere in one schema and is bounded by
    ``dims={"n": (lo, hi)}`` of the :class:`Schema`. ``dtypes``: allowed dtype names.
    Value checks (on loaded data only): ``finite``, ``ge``/``le``, ``increasing`` (strictly,
    along the first axis of a 1D array), ``nonzero`` (at least one value > 0).
    """

    def __init__(self, shape, *, dtypes=("float32", "float64"), finite: bool = True,
                 ge=None, gt=None, le=None, increasing: bool = False, nonzero: bool = False,
                 required: bool = True):
        self.shapes = [tuple(s) for s in shape] if isinstance(shape, list) else [tuple(shape)]
        self.dtypes = tuple(np.dtype(d) for d in dtypes)
        self.finite, self.increasing, self.nonzero = finite, increasing, nonzero
        self.range = Number(ge=ge, gt=gt, le=le)
        self.required = required

    def _shape_text(self, dims) -> str:
        def one(s):
            body = ", ".join(str(d) for d in s)
            return f"({body},)" if len(s) == 1 else f"({body})"
        alts = " or ".join(one(s) for s in self.shapes)
        names = sorted({d for s in self.shapes for d in s if isinstance(d, str)})
        bounds = [f"{dims[n][0]} <= {n} <= {dims[n][1]}" for n in names if n in dims]
        return alts + (f" with {', '.join(bounds)}" if bounds else "")

    def check_array(self, arr, field: str, dims: Mapping, bound: dict) -> None:
        dtype = np.dtype(arr.dtype)
        if dtype.hasobject:
            raise StateError(field, "expected a numeric array, found an object array (pickled "
                                    "Python objects are never loaded)")
        if not any(dtype.kind == d.kind and dtype.itemsize == d.itemsize for d in self.dtypes):
            names = " or ".join(str(d) for d in self.dtypes)
            raise StateError(field, f"expected dtype {names}, found {dtype.str!r} ({dtype})")
        shape = tuple(int(s) for s in arr.shape)
        for spec in self.shapes:
            if len(spec) != len(shape):
                continue
            trial = dict(bound)
            good = True
            for want, got in zip(spec, shape):
                if isinstance(want, int):
                    good = want == got
                else:
                    lo, hi = dims.get(want, (0, MAX_ARRAY_ELEMENTS))
                    if trial.setdefault(want, got) != got or not lo <= got <= hi:
                        good = False
                if not good:
                    break
            if good:
                bound.update(trial)
                break
        else:
            raise StateError(field, f"expected shape {self._shape_text(dims)}, found {shape}")
        if isinstance(arr, np.ndarray):
            self.check_values(arr, field)

    def check_values(self, arr: np.ndarray, field: str) -> None:
        a = np.asarray(arr)
        if a.size == 0:
            return
        if self.finite and a.dtype.kind == "f" and not np.all(np.isfinite(a)):
            bad = "NaN" if np.any(np.isnan(a)) else "infinity"
            raise StateError(field, f"expected finite values, found {bad}")
        r = self.range
        lo = float(np.min(a))
        hi = float(np.max(a))
        if (r.gt is not None and lo <= r.gt) or (r.ge is not None and lo < r.ge):
            raise StateError(field, f"expected values {r._range()}, found minimum {lo:g}")
        if r.le is not None and hi > r.le:
            raise StateError(field, f"expected values {r._range()}, found maximum {hi:g}")
        if self.increasing and a.ndim == 1 and np.any(np.diff(a) <= 0):
            raise StateError(field, "expected strictly increasing values, found a value that "
                                    "does not increase")
        if self.nonzero and not np.any(a > 0):
            raise StateError(field, "expected at least one value > 0, found none")

    def describe(self):
        return "an array"

    def check(self, value, path, scope):  # arrays are declared in Schema.arrays, not params
        raise TypeError("Array fields belong in Schema(arrays=...)")


# ------------------------------------------------------------------------------------------
# schema
# ------------------------------------------------------------------------------------------
class Schema:
    """The state of one model kind or component: ``params`` fields and ``arrays``.

    Parameters
    ----------
    params:
        ``{key: Validator}``; keys listed in ``required`` must be present, the others may be
        absent (a present ``null`` is checked by the validator: wrap it in :class:`Opt`).
        Keys the schema does not name are ignored (they are not read by ``from_state``)
        unless ``strict``.
    arrays:
        ``{name: Array}`` relative to the scope's array prefix.
    dims:
        Bounds ``{name: (lo, hi)}`` of the dimension names used in array shapes.
    strict:
        Refuse ``params`` keys the schema does not name (for classes rebuilt as
        ``cls(**params)``, where an unknown key would be an unknown argument).
    checks:
        Extra callables ``check(params, arrays, path, field)`` for cross-field rules
        (``arrays`` maps the declared names to :class:`ArrayHeader` or loaded arrays,
        ``field(name)`` is an array's field name for messages); they raise
        :class:`StateError`.
    """

    def __init__(self, params: Mapping[str, Validator] | None = None, *,
                 required=(), arrays: Mapping[str, Array] | None = None,
                 dims: Mapping[str, tuple[int, int]] | None = None,
                 checks: tuple[Callable, ...] = (), strict: bool = False):
        self.strict = strict
        self.params = dict(params or {})
        self.required = tuple(required)
        self.arrays = dict(arrays or {})
        self.dims = dict(dims or {})
        self.checks = tuple(checks)
        unknown = set(self.required) - set(self.params)
        if unknown:
            raise TypeError(f"required keys without a validator: {sorted(unknown)}")

    def validate(self, params, path: str, scope: Scope) -> None:
        if not isinstance(params, Mapping):
            raise StateError(path, f"expected an object, found {show(params)}")
        for key in self.required:
            if key not in params:
                raise StateError(f"{path}.{key}", "missing")
        if self.strict:
            for key in params:
                if key not in self.params:
                    raise StateError(f"{path}.{str(key)[:80]}",
                                     f"unexpected key (expected {', '.join(self.params)})")
        for key, field in self.params.items():
            if key in params:
                field.check(params[key], f"{path}.{key}", scope)
        bound: dict[str, int] = {}
        found = {}
        for name, spec in self.arrays.items():
            key = scope.key(name)
            scope.claimed.add(key)
            if key not in scope.arrays:
                if spec.required:
                    raise StateError(array_field(key), "missing")
                continue
            spec.check_array(scope.arrays[key], array_field(key), self.dims, bound)
            found[name] = scope.arrays[key]
        for check in self.checks:
            check(params, found, path, lambda name: array_field(scope.key(name)))


def schema_of(cls) -> Schema | None:
    """The :class:`Schema` of ``cls``: its own ``state_schema`` or an inherited one, unless a
    class on the way defines its own state format (``to_state``/``from_state``/``params``)
    without declaring a schema (then ``None``: only the generic checks apply)."""
    for klass in getattr(cls, "__mro__", ()):
        d = vars(klass)
        if "state_schema" in d:
            s = d["state_schema"]
            return s() if callable(s) and not isinstance(s, Schema) else s
        if any(k in d for k in ("to_state", "from_state", "params")):
            return None
    return None


def _generic(params, path: str, scope: Scope) -> None:
    """Checks for a class without a schema: an object of params; numeric, finite arrays of
    at most :data:`MAX_ARRAY_ELEMENTS` elements under the scope's prefix."""
    if not isinstance(params, Mapping):
        raise StateError(path, f"expected an object, found {show(params)}")
    for key in scope.under():
        if key in scope.claimed:
            continue
        scope.claimed.add(key)
        arr = scope.arrays[key]
        field = array_field(key)
        dtype = np.dtype(arr.dtype)
        if dtype.hasobject:
            raise StateError(field, "expected a numeric array, found an object array (pickled "
                                    "Python objects are never loaded)")
        if dtype.kind not in "biuf":
            raise StateError(field, f"expected a numeric array, found dtype {dtype}")
        size = math.prod(int(s) for s in arr.shape)
        if size > MAX_ARRAY_ELEMENTS:
            raise StateError(field, f"expected at most {MAX_ARRAY_ELEMENTS} elements, found "
                                    f"shape {tuple(arr.shape)}")
        if isinstance(arr, np.ndarray) and dtype.kind == "f" and not np.all(np.isfinite(arr)):
            raise StateError(field, "expected finite values, found NaN or infinity")


def validate_class_state(cls, params, path: str, scope: Scope) -> None:
    """Validate ``params`` and the arrays in ``scope`` against the schema of ``cls``."""
    schema = schema_of(cls)
    if schema is None:
        _generic(params, path, scope)
    else:
        schema.validate(params, path, scope)


def validate_state(cls, params, arrays: Mapping[str, Any]) -> None:
    """Check a whole model state (``params`` and every array) against the schema of ``cls``.

    ``arrays`` maps names to loaded arrays or to :class:`ArrayHeader` (shape/dtype only).
    Raises :class:`StateError` for the first field that does not match, including arrays that
    no schema declares.
    """
    scope = Scope(arrays)
    validate_class_state(cls, params, "params", scope)
    extra = sorted(set(arrays) - scope.claimed)
    if extra:
        raise StateError(array_field(extra[0]),
                         f"unexpected array (not part of the {getattr(cls, 'fit_kind', '') or cls.__name__!s} "
                         f"state; {len(extra)} undeclared)")
