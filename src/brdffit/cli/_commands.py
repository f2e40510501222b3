"""The parsers of the ``brdffit`` commands: what ``brdffit --help`` and ``brdffit NAME --help``
show and what the command line accepts.

One function per command adds its parser to the sub-parsers of
:func:`brdffit.cli.build_parser` (:data:`PARSERS`, in the order of ``brdffit --help``):
its description (the first paragraph is the one-line help of the command list), its
arguments and options with their types, defaults and ranges. Nothing here imports NumPy or
a command's runner (``brdffit.cli.NAME``, imported by :func:`brdffit.cli.main` when the
command runs); the runners take their defaults from here.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..export import TARGETS
from ._parsing import (DEFAULT_MODELS, MAX_RESOLUTION, MAX_SEED, MAX_SPP, add_command,
                       add_render_options, at_least, between, models_help, path, positive,
                       positive_or)

#: The model of ``brdffit fit`` without ``--model``: GGX + Lambert (+ coat), fitted over the
#: whole data (:mod:`brdffit.fit.analytic`). Chosen over the tabulated fit because it is
#: engine-ready (glTF, MaterialX, Mitsuba's built-in plugins) and, unlike a specular-only
#: model, has a diffuse term: on the RGL measurements the tabulated default put the diffuse
#: base into F (F0 up to 2) with 13-105 % error where ggx-diffuse gave 4-52 %.
DEFAULT_MODEL = "ggx-diffuse"
#: The models of ``brdffit demo``: the paper's models and the engine-ready GGX + Lambert
#: (+ coat).
DEMO_MODELS = "tabulated,ggx,beckmann,ggx-diffuse,sgd,npf-g-from-d,npf"


def _input(cmd, name: str = "spec", metavar: str = "INPUT[:MATERIAL]",
           text: str = "A BRDF file, collection.zip:material or synthetic:NAME.") -> None:
    """The argument ``name``: a BRDF to read (:func:`brdffit.load`)."""
    cmd.add_argument(name, metavar=metavar, help=text)


def _models(cmd, default: str, text: str) -> None:
    """``-m/--models A,B``: comma-separated model names."""
    cmd.add_argument("-m", "--models", default=default, metavar="A,B", help=text)


def info(commands) -> None:
    """The parser of ``brdffit info``."""
    cmd = add_command(commands, "info",
                      "Format, sample counts, value range and albedo of a BRDF file.")
    _input(cmd, metavar="FILE[:MATERIAL]")
    cmd.add_argument("--json", dest="as_json", action="store_true",
                     help="Print one JSON object.")
    cmd.add_argument("--albedo-samples", type=between(16, 1 << 22), default=65536, metavar="N",
                     help="Monte Carlo samples per albedo angle.")


def convert(commands) -> None:
    """The parser of ``brdffit convert``."""
    cmd = add_command(commands, "convert",
                      "Resample a BRDF to a MERL (.binary) or UTIA (.bin) file.")
    _input(cmd, "src", metavar="IN")
    cmd.add_argument("dst", type=path, metavar="OUT",
                     help="Output file: .binary (MERL) or .bin (UTIA).")


def fit(commands) -> None:
    """The parser of ``brdffit fit``."""
    cmd = add_command(commands, "fit",
                      "Fit a model to a measured BRDF; print its parameters and error.",
                      epilog=models_help())
    _input(cmd)
    cmd.add_argument("-m", "--model", default=DEFAULT_MODEL, metavar="NAME",
                     help="Model to fit (list below); the default is engine-ready: GGX + "
                          "Lambert (+ a clear coat where it pays), physically checked.")
    cmd.add_argument("-o", "--output", dest="out", type=path, metavar="FILE.npz",
                     help="Write the fit file here (default: not saved).")
    cmd.add_argument("--iterations", type=at_least(1), metavar="N",
                     help="Power / optimiser iterations (model's default).")
    cmd.add_argument("-O", "--option", action="append", metavar="KEY=VALUE",
                     help="Extra fitting option (repeatable).")
    cmd.add_argument("--no-error", action="store_true",
                     help="Skip the error against the input and the physical checks (the "
                          "fastest fit).")
    cmd.add_argument("--json", dest="as_json", action="store_true",
                     help="Print the summary as JSON.")


def models(commands) -> None:
    """The parser of ``brdffit models``."""
    cmd = add_command(commands, "models", """
        List the models: paper, isotropy, fit size and time.

        The sizes and times are typical figures declared in the registry (measured by
        bench/bench_cli.py --models, see below) unless --measure measures them now.
        """)
    cmd.add_argument("--json", dest="as_json", action="store_true",
                     help="Print the rows as JSON.")
    cmd.add_argument("--measure", dest="do_measure", action="store_true",
                     help="Fit each model now and measure its figures.")
    cmd.add_argument("--on", default="synthetic:gold-ggx", metavar="INPUT",
                     help="--measure: the input to fit.")
    _models(cmd, "", "Only these models (comma-separated).")
    cmd.add_argument("--options", dest="with_options", action="store_true",
                     help="Also list each model's fitting options (-O KEY=VALUE): type, "
                          "default, range.")


def render(commands) -> None:
    """The parser of ``brdffit render``."""
    cmd = add_command(commands, "render",
                      "Render a BRDF or fit with Mitsuba 3 to an EXR or PNG image.")
    cmd.add_argument("spec", metavar="INPUT_OR_FIT",
                     help="BRDF file/spec (brdffit.load) or a fit .npz.")
    cmd.add_argument("-o", "--output", type=path, required=True, metavar="IMAGE",
                     help="Output image (.exr or .png).")
    cmd.add_argument("--scene", default="sphere-env", metavar="SCENE",
                     help="sphere-env, sphere-point, sphere-distant, knot, sphere-svrough.")
    cmd.add_argument("--envmap", metavar="MAP",
                     help="Environment: a name of ../shared/data/envmaps (studio, city, ...), "
                          "an EXR path, or 'procedural' (default).")
    cmd.add_argument("--spp", type=between(1, MAX_SPP), default=256, metavar="N",
                     help="Samples per pixel.")
    cmd.add_argument("--resolution", type=between(8, MAX_RESOLUTION), default=256,
                     metavar="PX", help="Image width = height.")
    cmd.add_argument("--seed", type=between(0, MAX_SEED), default=0, metavar="N",
                     help="Sampler seed.")
    cmd.add_argument("--mode", default="auto", metavar="MODE",
                     help="auto (closed form when available), table, closed.")
    cmd.add_argument("--exposure", type=positive_or("auto"), default="auto", metavar="EV",
                     help="PNG tone-mapping exposure (a positive number or 'auto').")
    cmd.add_argument("--gamma", type=positive(10.0), default=2.2, metavar="G",
                     help="PNG tone-mapping gamma.")
    cmd.add_argument("--roughness-texture", type=path, metavar="IMAGE",
                     help="Roughness-scale texture for microfacet models (Dupuy 2015 Eq. 9): "
                          "an EXR whose first channel is the α multiplier, or a PNG with "
                          "multiplier 2·value/255 (mid-grey = 1). Default for --scene "
                          "sphere-svrough: built-in.")
    cmd.add_argument("--resampling-error", dest="report_error", action="store_true",
                     help="Also measure the Dr.Jit evaluator's error vs brdf.eval.")


def compare(commands) -> None:
    """The parser of ``brdffit compare``."""
    cmd = add_command(commands, "compare",
                      "Fit, render and measure models against a reference (HTML report).",
                      epilog=models_help())
    _input(cmd, text="Reference BRDF: a file, collection.zip[:material], synthetic:NAME or a "
                     "fit file.")
    _models(cmd, DEFAULT_MODELS, "Comma-separated model names to fit (list below), and/or "
                                 "saved fits as NAME=fit.npz or fit.npz.")
    cmd.add_argument("-o", "--out", type=path, default=Path("report"), metavar="DIR",
                     help="Report directory.")
    add_render_options(cmd)
    # hidden: the single-scene form of --scenes NAME
    cmd.add_argument("--scene", help=argparse.SUPPRESS)
    cmd.add_argument("--seed", type=between(0, MAX_SEED - (1 << 20)), default=0, metavar="N",
                     help="Seed of the sample streams (all models).")
    cmd.add_argument("--exposure", type=positive_or("scene", "auto"), default="scene",
                     metavar="EV",
                     help="Tone-mapping exposure: 'scene' (fixed per scene), 'auto' (from "
                          "each scene's reference) or a positive number.")
    cmd.add_argument("--gamma", type=positive(10.0), metavar="G",
                     help="Tone-mapping gamma (default: the scene's, 2.2).")
    # ignored (standard errors replaced the noise floor); accepted for old command lines
    cmd.add_argument("--noise-floor", action=argparse.BooleanOptionalAction, default=True,
                     help=argparse.SUPPRESS)
    cmd.add_argument("--envmap", metavar="MAP",
                     help="Environment map of the plain sphere-env/knot scenes: a name of "
                          "../shared/data/envmaps or an EXR (default procedural).")
    cmd.add_argument("--limit", type=at_least(1), metavar="N",
                     help="With a collection: only its first N materials.")
    cmd.add_argument("--fit-options", metavar="JSON",
                     help='Fitter keyword arguments as JSON per model, e.g. '
                          '\'{"npf": {"max_iter": 100}}\'.')
    cmd.add_argument("-q", "--quiet", action="store_true", help="No progress messages.")


def export(commands) -> None:
    """The parser of ``brdffit export``."""
    cmd = add_command(commands, "export",
                      "Export a fit to Mitsuba 3, glTF, MaterialX, USD, GLSL or JSON.")
    cmd.add_argument("fits", nargs="+", metavar="FIT",
                     help="Fit file (.npz), parameter JSON or synthetic:NAME.")
    cmd.add_argument("--to", required=True, help=f"Target: {', '.join(TARGETS)}.")
    cmd.add_argument("-o", "--out", type=path, required=True, help="Output file.")
    cmd.add_argument("--option", action="append",
                     help="Target option key=value (JSON values), e.g. --option "
                          "optimize=false with --to gltf: the rule-based parameters instead of "
                          "those fitted to what the specification, Blender and three.js "
                          "render; an unknown key lists the target's options.")
    cmd.add_argument("--json", dest="as_json", action="store_true",
                     help="Print the summary as JSON.")


def demo(commands) -> None:
    """The parser of ``brdffit demo``."""
    cmd = add_command(commands, "demo", """
        Fit and render built-in synthetic materials; write a report.

        No external data or network is needed. Example: brdffit demo --out demo-out
        Exit status: 0 all done, 1 error, 2 usage, 3 some fits failed (the rest is written).
        """, epilog=models_help())
    cmd.add_argument("-o", "--out", default="demo-out", metavar="DIR", help="Report folder.")
    cmd.add_argument("--data", default="", metavar="SOURCE",
                     help="Run on real data instead: a folder, a Neural-BRDF .zip collection "
                          "or a list file.")
    cmd.add_argument("--limit", type=at_least(0), default=0, metavar="N",
                     help="With --data: first N materials only.")
    _models(cmd, DEMO_MODELS, "Models to fit (list below).")
    cmd.add_argument("--spp", type=between(1, MAX_SPP), default=64, metavar="N",
                     help="Samples per pixel of the renderings (in up to 8 batches: a "
                          "multiple of 8, or fewer than 8).")
    cmd.add_argument("--resolution", type=between(8, MAX_RESOLUTION), default=128,
                     metavar="PX", help="Image size in pixels.")
    cmd.add_argument("-j", "--jobs", type=between(0, 64), default=0, metavar="N",
                     help="Materials at a time, each in its own process (0: one per CPU).")


def batch(commands) -> None:
    """The parser of ``brdffit batch``."""
    cmd = add_command(commands, "batch", """
        Fit every material of SOURCE with every model (Dask, resumable).

        Writes OUT/fits/, OUT/records/ and OUT/summary.csv (one row per material and
        model: α and glTF roughness, F0, ρd, errors, PSNR ± se and dE2000 when rendered,
        time, status, fit file, and the recommended model of each material).

        \b
        Example:
          brdffit batch merl_nbrdf.zip -m tabulated,ggx --limit 10 --out runs/merl

        With --render, each material is also rendered once its fits are done, and
        OUT/report/index.html compares every model over the database. Exit status: 0 all
        done, 1 error, 2 usage or OUT locked by another batch, 3 some tasks failed.
        """, epilog=models_help())
    cmd.add_argument("source", metavar="SOURCE",
                     help="Folder of measured files, a Neural-BRDF .zip collection, a list "
                          "file, or synthetic:[a,b].")
    _models(cmd, DEFAULT_MODELS, "Comma-separated model names (list below).")
    cmd.add_argument("-o", "--out", required=True, metavar="DIR",
                     help="Output folder (created; re-runs resume).")
    cmd.add_argument("--only", default="", metavar="A,B",
                     help="Comma-separated material names to keep.")
    cmd.add_argument("--limit", type=at_least(0), default=0, metavar="N",
                     help="Keep only the first N materials (0: all).")
    cmd.add_argument("--scheduler", default="", metavar="ADDRESS",
                     help="Address of an existing Dask scheduler, e.g. tcp://host:8786 "
                          "(default: a local cluster). Its workers must share OUT and the data "
                          "at the same paths and run the same brdffit version.")
    cmd.add_argument("--workers", type=between(1, 256), default=2, metavar="N",
                     help="Local cluster: worker processes.")
    cmd.add_argument("--memory-limit", default="", metavar="SIZE",
                     help="Local cluster: memory per worker, e.g. 8GiB.")
    cmd.add_argument("--retries", type=between(0, 100), default=2, metavar="N",
                     help="Local cluster: how many more times a task that kills its worker "
                          "(out of memory...) is tried before it is recorded as failed.")
    cmd.add_argument("--no-metrics", action="store_true", help="Skip BRDF-space metrics.")
    cmd.add_argument("--render", action="store_true",
                     help="Also render every material and its fits (Mitsuba 3) and write the "
                          "HTML report to OUT/report/.")
    add_render_options(cmd, when="--render: ")
    cmd.add_argument("--retry-failed", action="store_true",
                     help="Redo tasks recorded as failed.")
    cmd.add_argument("--wait-lock", action="store_true",
                     help="If another batch is writing to OUT, wait for it (default: exit with "
                          "status 2).")
    cmd.add_argument("-q", "--quiet", action="store_true", help="No progress bar.")


#: Each command's parser by name, in the order of ``brdffit --help``.
PARSERS = {"info": info, "convert": convert, "fit": fit, "models": models, "render": render,
           "compare": compare, "batch": batch, "export": export, "demo": demo}
