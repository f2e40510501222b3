"""``brdffit convert IN OUT``: resample any loadable BRDF into a MERL or UTIA file.

``OUT.binary`` → MERL (:func:`brdffit.io.merl.resample_to_merl`, isotropic input only);
``OUT.bin`` → UTIA (:func:`brdffit.io.utia.write_utia`, any input). Outputs are written
atomically: a failed conversion leaves no partial file.
"""

from __future__ import annotations

from pathlib import Path

from .._atomic import WRITE_THROUGH, destination_kind
from ..errors import BRDFFormatError, printable
from ..io.merl import resample_to_merl
from ..io.utia import read_utia, write_utia
from ..loading import load
from ._checks import output_file

__all__ = ["convert_cmd", "convert"]

_OUTPUTS = {".binary": "merl", ".bin": "utia"}


def convert(spec, out) -> dict:
    """Load ``spec`` and write it to ``out`` (format from the extension); return a summary."""
    out = Path(out)
    # a device or FIFO has no extension: MERL, the format every tool reads
    kind = "merl" if destination_kind(out) in WRITE_THROUGH else _OUTPUTS.get(out.suffix.lower())
    if kind is None:
        raise BRDFFormatError(out, f"expected an output extension in {sorted(_OUTPUTS)} "
                                   f"(MERL .binary, UTIA .bin), found {out.suffix or 'none'!r}")
    brdf = load(spec)
    if kind == "merl":
        table = resample_to_merl(brdf, out)
        return {"out": str(out), "format": "merl", "n_samples": table.n_samples,
                "n_invalid": table.n_invalid, "name": getattr(brdf, "name", None)}
    write_utia(brdf, out)
    check = read_utia(out)
    return {"out": str(out), "format": "utia", "n_samples": check.n_samples,
            "n_invalid": check.n_invalid, "name": getattr(brdf, "name", None)}


def convert_cmd(src: str, dst: Path) -> None:
    """Run ``brdffit convert`` (its options: :func:`brdffit.cli._commands.convert`)."""
    output_file(dst, tuple(_OUTPUTS), option="OUT")
    info = convert(src, dst)
    print(printable(f"wrote {info['out']} ({info['format']}, {info['n_samples']} samples, "
                    f"{info['n_invalid']} invalid) from {src}"))
