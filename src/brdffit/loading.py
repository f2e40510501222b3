"""The spec router: :func:`load` reads a BRDF from a file spec or builds a named synthetic one.

``brdffit.load(spec)`` accepts every spec of :func:`brdffit.io.load` (a file, or
``collection.zip:material``) and ``synthetic:NAME`` (a built-in material of
:func:`brdffit.synthetic.synthetic`). It sits above :mod:`brdffit.synthetic` and
:mod:`brdffit.io` so that the readers need not know about the synthetic materials, which
build models.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

from . import io as _io
from .errors import BRDFFormatError
from .synthetic import list_synthetic, synthetic

if TYPE_CHECKING:
    from .brdf import BRDF

__all__ = ["load"]


def load(spec: str | os.PathLike, **options) -> BRDF:
    """Load a BRDF from a path or spec and return it (a :class:`~brdffit.brdf.BRDF`).

    ``spec`` is one of

    * a file: ``.binary`` (MERL), ``.h5`` (Neural-BRDF), ``.bsdf`` (RGL), ``.bin`` (UTIA),
      ``.npz`` (brdffit fit file); unknown extensions are recognised by content;
    * ``collection.zip:material`` (Neural-BRDF collection; the zip path may be relative,
      absolute, or a bare file name found on :func:`brdffit.io.data_search_path`);
    * ``synthetic:NAME`` (a built-in material of :func:`brdffit.synthetic.synthetic`).

    Keyword ``options`` go to the reader (e.g. ``interpolation="nearest"`` for MERL,
    ``precision="float64"`` for Neural-BRDF) or to the synthetic material's builder.
    """
    kind, _, member = _io.resolve_spec(spec)
    if kind != "synthetic":
        return _io.load(spec, **options)
    known = list_synthetic()
    if member not in known:
        raise BRDFFormatError(os.fspath(spec), f"expected a synthetic material "
                                               f"({', '.join(known)}), found none named "
                                               f"{member!r}")
    return synthetic(member, **options)
