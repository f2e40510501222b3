"""Serialisable models: the base class, the registry of fit kinds and its plugin table.

This module sits *below* both the readers/writers (:mod:`brdffit.io.fitfile`) and the models
(:mod:`brdffit.microfacet`, :mod:`brdffit.fit`): models subclass :class:`SerializableModel`
from here, and the fit-file loader finds the class of a kind here, so neither imports the
other (the dependency is one-way: io never imports the model packages at import time and
the model packages never import io).

Kinds are found in two ways:

* a class that subclasses :class:`SerializableModel` with a ``fit_kind`` registers itself when
  its module is imported (:func:`model_registry`);
* :data:`PLUGINS` maps every built-in kind to the ``"module:Class"`` that defines it, so that
  :func:`resolve_kind` can import exactly that module when a file names the kind (a plugin
  table in the style of Mitsuba 3's). :func:`register_plugin` adds entries for new kinds.

Every model kind declares a :class:`~brdffit.schema.Schema` of its state
(``state_schema``); :meth:`SerializableModel.validate_state` checks a state against it.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any, ClassVar, Mapping

import numpy as np

from .schema import schema_of, validate_state

__all__ = ["SerializableModel", "model_registry", "resolve_kind", "register_plugin", "PLUGINS",
           "builtin_kinds"]

_REGISTRY: dict[str, type] = {}

#: fit kind → ``"module:Class"`` of the built-in models (imported on demand by the loader)
PLUGINS: dict[str, str] = {
    "microfacet": "brdffit.microfacet.model:MicrofacetBRDF",
    "microfacet_sum": "brdffit.microfacet.model:SumBRDF",
    "npf": "brdffit.microfacet.npf_model:NPFMicrofacetBRDF",
    "npf-naive": "brdffit.microfacet.npf_model:NPFNaiveBRDF",
    "npf-bivariate": "brdffit.microfacet.npf_model:NPFBivariateBRDF",
    "tabulated_per_channel": "brdffit.microfacet.per_channel:PerChannelBRDF",
    "per_channel_microfacet": "brdffit.microfacet.sgd_model:PerChannelMicrofacetBRDF",
}
_BUILTIN = frozenset(PLUGINS)


def builtin_kinds() -> list[str]:
    """The fit kinds brdffit itself defines (the keys of the original plugin table)."""
    return sorted(_BUILTIN)


def register_plugin(kind: str, target: str) -> None:
    """Declare that fit kind ``kind`` is defined by ``target`` = ``"package.module:Class"``."""
    if not isinstance(target, str) or target.count(":") != 1:
        raise ValueError(f"plugin target must be 'module:Class', got {target!r}")
    PLUGINS[str(kind)] = target


class SerializableModel:
    """Mixin for fitted models that can be saved with :func:`brdffit.io.fitfile.save_fit`.

    Subclasses set ``fit_kind`` (unique string), implement :meth:`to_state` and
    :meth:`from_state`, and declare ``state_schema`` (:class:`~brdffit.schema.Schema`), which
    the loader checks before :meth:`from_state` sees a file's state. ``fit_info``
    (eigenvalue, timings, convergence...) and ``fit_options`` are saved in the header when
    present.
    """

    fit_kind: ClassVar[str] = ""
    fit_info: dict | None = None
    fit_options: dict | None = None

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        kind = cls.__dict__.get("fit_kind")
        if kind:
            if kind in _REGISTRY and _REGISTRY[kind].__qualname__ != cls.__qualname__:
                raise TypeError(f"fit_kind {kind!r} registered twice")
            _REGISTRY[kind] = cls

    def to_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """Return ``(params, arrays)``: JSON-able parameters and named arrays."""
        raise NotImplementedError

    @classmethod
    def from_state(cls, params: dict[str, Any], arrays: dict[str, np.ndarray]):
        """Rebuild the model from :meth:`to_state` output."""
        raise NotImplementedError

    @classmethod
    def validate_state(cls, params, arrays: Mapping[str, Any]) -> None:
        """Check ``(params, arrays)`` against this kind's schema (``arrays`` may hold
        :class:`~brdffit.schema.ArrayHeader` entries); raises
        :class:`~brdffit.schema.StateError` naming the field."""
        validate_state(cls, params, arrays)

    def validate(self) -> None:
        """Check this model against its schema, as a fit file of it would be checked on load
        (:meth:`validate_state` of :meth:`to_state`): the one validation path of models made
        in Python, read from parameter JSON or from fit files."""
        params, arrays = self.to_state()
        type(self).validate_state(params, arrays)

    @classmethod
    def has_schema(cls) -> bool:
        """True when the kind declares its own (or an inherited) state schema."""
        return schema_of(cls) is not None


def _import_target(kind: str, target: str) -> type:
    module, _, name = target.partition(":")
    try:
        mod = import_module(module)
    except ImportError as exc:
        raise ValueError(f"model kind {kind!r} needs module {module}, which could not be "
                         f"imported ({exc})") from exc
    cls = getattr(mod, name, None)
    if not (isinstance(cls, type) and issubclass(cls, SerializableModel)):
        raise ValueError(f"plugin {target!r} of model kind {kind!r} is not a SerializableModel")
    if cls.fit_kind != kind:
        raise ValueError(f"plugin {target!r} declares fit_kind {cls.fit_kind!r}, not {kind!r}")
    return cls


def resolve_kind(kind: str) -> type:
    """The class of fit kind ``kind``: registered already, or imported from :data:`PLUGINS`.

    Raises ``KeyError`` for an unknown kind (the message lists the known ones) and
    ``ValueError`` when the plugin's module cannot provide it.
    """
    if not isinstance(kind, str):
        raise KeyError(f"model kind must be a string, found {type(kind).__name__}")
    cls = _REGISTRY.get(kind)
    if cls is not None:
        return cls
    target = PLUGINS.get(kind)
    if target is None:
        raise KeyError(f"unknown model kind {kind!r}; known: {sorted(set(PLUGINS) | set(_REGISTRY))}")
    return _import_target(kind, target)


def model_registry() -> dict[str, type]:
    """Every model kind (``fit_kind`` → class): the plugin table's kinds, imported, and the
    classes registered by modules imported so far."""
    for kind, target in list(PLUGINS.items()):
        if kind not in _REGISTRY:
            try:
                _import_target(kind, target)
            except ValueError:
                continue
    return dict(_REGISTRY)
