"""Exports of fitted models to renderers, engines and shaders, and imports back.

One module per target (conventions of every target in ``docs/conventions.md``):

* :mod:`.json_params` – JSON of the analytic parameters with units/conventions, and
  :func:`load_json` (exact round trip of any serialisable model);
* :mod:`.mitsuba` – Mitsuba 3 scene snippets (XML and Python dict) with built-in plugins
  (``roughconductor`` + ``diffuse`` in a ``blendbsdf``) where the fit maps to one, and the
  project's Python BSDF plugin (``brdffit``) for tabulated, SGD and NPF fits, plus a
  ready-to-render example scene;
* :mod:`.gltf` – glTF 2.0 metallic-roughness material of GGX fits, and :class:`GLTFBRDF`,
  the glTF BRDF of the specification's Appendix B as a BRDF of the library (to measure
  the loss of fidelity);
* :mod:`.materialx` – MaterialX ``open_pbr_surface`` documents (``.mtlx``, validated by
  MaterialX itself) and :class:`~.materialx.OpenPBRBRDF` to measure their loss;
* :mod:`.usd` – USD (``.usda``): a ``UsdPreviewSurface`` material with the OpenPBR MaterialX
  binding on a preview sphere, checked by USD's validators;
* :mod:`.glsl` – GLSL functions (GGX/Beckmann/SGD with the Eq. 9 G1, tabulated and NPF
  models from textures) and the NPF "uber-texture" (Bagher 2016 Fig. 16); its NumPy
  translation, which the tests compare it with, is in the test kit
  (``tests/support/glsl_cpu.py``);
* :mod:`.merl` / :mod:`.rgl` – resampling to MERL ``.binary`` and RGL-style tensor files
  (``mitsuba-xml`` writes the latter for Mitsuba's ``measured`` plugin when no built-in
  plugin maps the model);
* ``npf-uber`` – one or several NPF fits packed as the uber-texture (:mod:`.glsl`);
* :mod:`.tables` – import of published SGD (CSV) and NPF (uber-texture) parameter tables.

:func:`export` dispatches on ``to`` (one of :data:`TARGETS`); :func:`report_exports` writes the
engine files a comparison report links (written by its callers between the fit and the report:
:func:`brdffit.batch.compare_with_exports`).
"""

from __future__ import annotations

from importlib import import_module
from pathlib import Path

from .._blas import with_single_blas_thread
from ..errors import BRDFError, ExportError

__all__ = ["export", "report_exports", "check_model", "TARGETS", "SUFFIXES", "load_json", "ExportError", "load_sgd_table", "load_npf_table",
           "pack_npf_uber_texture", "GLTFBRDF"]

_LAZY = {"load_sgd_table": ".tables", "load_npf_table": ".tables",
         "pack_npf_uber_texture": ".glsl", "GLTFBRDF": ".gltf"}


def __getattr__(name):
    if name in _LAZY:
        return getattr(import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

#: target name -> (module, function); every function is ``fn(model, path, **options) -> dict``
TARGETS = {
    "json": (".json_params", "write_json"),
    "mitsuba": (".mitsuba", "write_mitsuba_python"),
    "mitsuba-xml": (".mitsuba", "write_mitsuba_xml"),
    "gltf": (".gltf", "write_gltf"),
    "materialx": (".materialx", "write_materialx"),
    "usd": (".usd", "write_usd"),
    "glsl": (".glsl", "write_glsl"),
    "merl": (".merl", "export_merl"),
    "rgl": (".rgl", "export_rgl"),
    # one NPF fit or a list of them, packed as Bagher 2016's uber-texture (Fig. 16)
    "npf-uber": (".glsl", "pack_npf_uber_texture"),
}

#: target name -> the file-name endings of its main output (``brdffit export -o``)
SUFFIXES = {"json": (".json",), "mitsuba": (".py",), "mitsuba-xml": (".xml",),
            "gltf": (".gltf",), "materialx": (".mtlx",), "usd": (".usda",), "glsl": (".glsl",),
            "merl": (".binary",), "rgl": (".bsdf",), "npf-uber": (".npy",)}


@with_single_blas_thread
def export(model, to: str, path, **options) -> dict:
    """Write ``model`` in the target format ``to`` at ``path``; returns a summary dict
    (files written, approximations made and their measured error where applicable).

    Raises :class:`~brdffit.errors.ExportError` when the model cannot go to the target, and
    when an output cannot be written: one line naming the file (what was expected, what was
    found); a failed export leaves no partial output (see :mod:`._common`). Runs with one BLAS
    thread (:mod:`brdffit._blas`: the mappings' small least-squares problems).
    """
    from ._common import check_output_path

    if to not in TARGETS:
        raise ExportError(f"unknown export target {to!r}; expected one of {', '.join(TARGETS)}")
    path = check_output_path(path)
    for m in model if isinstance(model, (list, tuple)) else [model]:
        check_model(m)
    mod, fn = TARGETS[to]
    return getattr(import_module(mod, __name__), fn)(model, path, **options)


def report_exports(model, folder: Path, stem: str) -> list[str]:
    """Engine files of a fitted model next to a comparison report (JSON always; glTF and
    MaterialX where the model has that form): paths relative to the material folder. An
    export a model cannot have is skipped, never an error of the comparison. (Mitsuba XML is
    left out: its RGL tensor is ~3.5 MB per model; ``brdffit export FIT --to mitsuba-xml``
    writes it.)"""
    done = []
    for target, suffix, opts in (("json", ".json", {}), ("gltf", ".gltf", {"fidelity": False}),
                                 ("materialx", ".mtlx", {"fidelity": False})):
        try:
            info = export(model, target, folder / f"{stem}{suffix}", **opts)
        except (BRDFError, ImportError):
            continue
        done += [f"exports/{Path(f).name}" for f in info.get("files", [])]
    return done


def check_model(model) -> None:
    """:class:`ExportError` (one line) unless ``model`` passes its schema
    (:meth:`~brdffit.serialization.SerializableModel.validate`), as a fit file of it would:
    every export writes only numbers that its target can hold (finite, no denormals, slope
    scales whose squares are float32 numbers). Models without a schema pass as they are."""
    from ..serialization import SerializableModel
    from ._common import label

    if isinstance(model, SerializableModel) and model.fit_kind and model.has_schema():
        try:
            model.validate()
        except (ValueError, TypeError) as exc:
            raise ExportError(f"cannot export {label(model)}: its parameters are out of range "
                              f"({exc})") from None


def load_json(path):
    """Rebuild a model from a JSON written by :func:`brdffit.export.json_params.write_json`."""
    from .json_params import load_json as _load

    return _load(path)
