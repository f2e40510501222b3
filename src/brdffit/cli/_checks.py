"""Run-time checks shared by the ``brdffit`` commands, made before any work.

Imported by the commands' modules when one runs (never by ``--help``): the output file of
``-o`` (:func:`output_file`), the size of a render (:func:`check_render_size`,
:func:`check_render_settings`), model names (:func:`check_models`) and ``--option
key=value`` pairs (:func:`parse_options`). Each bad value is a usage error (exit status 2)
naming its option.
"""

from __future__ import annotations

import json
from pathlib import Path

from ..fit import registry
from ._parsing import usage_error

#: Samples one render pass may hold: Dr.Jit arrays have at most 2³² entries.
MAX_SAMPLES_PER_PASS = (1 << 32) - 1


def output_file(path: Path, suffixes: tuple[str, ...], option: str = "-o",
                hint: str = "") -> str:
    """Check ``-o FILE`` before any work; returns its kind
    (:func:`brdffit._atomic.destination_kind`).

    A new path or a regular file must end in one of ``suffixes`` (else a usage error,
    exit 2, with ``hint``); a character device or a FIFO (``/dev/null``) is written
    through in the command's format; a directory, socket or block device, a missing folder
    or a folder where no file can be created is an :class:`~brdffit._atomic.OutputError`
    (exit 1). Nothing is created here."""
    from .._atomic import check_writable, destination_kind  # only commands that write

    kind = destination_kind(path)
    if kind in ("new", "regular file") and path.suffix.lower() not in suffixes:
        raise usage_error(option, f"expected a file name ending in {' or '.join(suffixes)}, "
                                  f"found {str(path.name)!r}{hint}")
    check_writable(path)
    return kind


def check_render_size(resolution: int, spp_per_pass: int, option: str = "--spp") -> None:
    """Usage error (exit 2) when ``resolution² × spp_per_pass`` exceeds what one Dr.Jit
    render pass can hold (:data:`MAX_SAMPLES_PER_PASS`)."""
    n = int(resolution) ** 2 * int(spp_per_pass)
    if n > MAX_SAMPLES_PER_PASS:
        raise usage_error(option, f"{resolution}² pixels × {spp_per_pass} samples = {n:,} "
                                  f"samples in one pass; at most {MAX_SAMPLES_PER_PASS:,} "
                                  "(lower --spp or --resolution)")


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


def parse_options(items: list[str] | None) -> dict:
    """``["k=v", ...]`` → dict, values parsed as JSON when possible (else strings)."""
    out: dict = {}
    for item in items or []:
        if "=" not in item:
            raise usage_error("--option", f"expected key=value, found {item!r}")
        key, val = item.split("=", 1)
        try:
            out[key.strip()] = json.loads(val)
        except json.JSONDecodeError:
            out[key.strip()] = val
    return out
