"""Orchestration of a comparison: fit (or load) models, render them and the reference with
the same scene and sample streams, measure, plot, and write the HTML report.

:func:`compare` handles one material and updates the report index; :func:`compare_many`
loops over several. The measurement protocol:

* reference and every model are rendered by the same renderer call with the same ``scene``,
  ``spp``, ``resolution`` and ``seed`` (identical camera, lights and random streams);
* the Monte Carlo **noise floor** is the PSNR/dE2000 between two renderings of the
  *reference* with seeds ``seed`` and ``seed + 1``: a model whose PSNR is near the floor is
  indistinguishable from the reference at these settings;
* rendered PSNR (Bagher et al. 2016 §5) on linear values over the reference's foreground
  mask, dE2000 on the tone-mapped images (:mod:`.metrics`);
* one tone-mapping exposure per material, computed on the reference (``exposure="auto"``,
  see :mod:`.tonemap`) and used for every PNG and every dE2000 map of that material;
* BRDF-space metrics (:func:`.metrics.brdf_metrics`) independent of rendering.

A model that fails to fit, load or render is recorded with its error message; the others
still make it into the report.
"""

from __future__ import annotations

import time
import traceback
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from ..errors import BRDFError
from ..fit.registry import fit_model, is_isotropic_only, model_params, small_json
from . import metrics as M
from . import plots as P
from . import report as R

__all__ = ["compare", "compare_many", "resolve_reference", "DEFAULT_MODELS"]

DEFAULT_MODELS = ("tabulated", "ggx", "beckmann", "sgd", "npf")

# ------------------------------------------------------------------------------------------
# inputs
# ------------------------------------------------------------------------------------------
def resolve_reference(source, material: str | None = None):
    """A reference BRDF: a BRDF object as is, else :func:`brdffit.io.load` of the spec (a file,
    a fit file, ``archive.zip:member``, ``synthetic:NAME``; ``material`` is appended as
    ``:material``)."""
    if hasattr(source, "eval"):
        return source
    spec = str(source)
    if material:
        spec = f"{spec}:{material}"
    from ..io import load

    return load(spec)


def _default_renderer():
    """:func:`brdffit.evaluation.render.render_ex` (Mitsuba 3): returns image and mask."""
    from .render import render_ex

    return render_ex


def _unpack_render(out):
    """Renderer output → (image (H, W, 3) float64, mask (H, W) bool)."""
    img = mask = None
    if isinstance(out, tuple):
        img, mask = out[0], (out[1] if len(out) > 1 else None)
    elif isinstance(out, Mapping):
        img, mask = out.get("image"), out.get("mask")
    else:
        img, mask = getattr(out, "image", out), getattr(out, "mask", None)
    img = np.asarray(img, dtype=np.float64)
    if img.ndim == 3 and img.shape[-1] == 4:
        if mask is None:
            mask = img[..., 3] > 0.5
        img = img[..., :3]
    if mask is None:
        mask = np.ones(img.shape[:2], bool)
    return img, np.asarray(mask).astype(bool).reshape(img.shape[:2])


def _tonemapper():
    try:
        from .tonemap import auto_exposure, tonemap
    except ImportError:  # pragma: no cover - tonemap.py is part of the package
        def auto_exposure(img, mask=None, target=1.0):
            v = np.asarray(img)[..., :3].max(-1)
            v = v[np.asarray(mask, bool)] if mask is not None else v.ravel()
            v = v[np.isfinite(v) & (v > 0)]
            return float(target / np.median(v)) if v.size else 0.02

        def tonemap(img, exposure=0.02, gamma=2.2, mask=None):
            return M.npf_tonemap(img, exposure, gamma)
    return auto_exposure, tonemap


def _write_png(path, img):
    try:
        from .imageio import write_png
    except ImportError:  # pragma: no cover
        from PIL import Image

        from .._atomic import atomic_path

        def write_png(path, img):
            a = np.asarray(img)
            if a.dtype != np.uint8:
                a = np.round(np.clip(a, 0, 1) * 255).astype(np.uint8)
            with atomic_path(path, suffix=".png") as tmp:
                Image.fromarray(a).save(tmp, format="PNG")
            return Path(path)
    return write_png(path, img)


def _write_exr(path, img):
    try:
        from .imageio import write_exr
    except ImportError:  # pragma: no cover
        return None
    return write_exr(path, np.asarray(img, np.float32))


def _safe_name(name: str) -> str:
    return R.slugify(name)


# ------------------------------------------------------------------------------------------
# the comparison
# ------------------------------------------------------------------------------------------
def compare(source, models: Sequence | Mapping = DEFAULT_MODELS, out_dir="report", *,
            material: str | None = None, name: str | None = None, scene: str = "sphere-env",
            spp: int = 64, resolution: int = 128, seed: int = 0, exposure="auto",
            gamma: float = 2.2, noise_floor: bool = True, brdf_metric_samples: int = 1 << 16,
            brdf_metrics: Sequence[str] = M.BRDFMetrics.ALL,
            fit_options: Mapping[str, Mapping] | None = None, save_fits: bool = True,
            write_exr: bool = True, renderer: Callable | None = None,
            render_options: Mapping | None = None, update_index: bool = True,
            progress: Callable[[str], None] | None = None) -> dict:
    """Compare models against one reference BRDF and write its report page.

    Parameters
    ----------
    source:
        The reference: a BRDF object, a fit file, ``synthetic:NAME`` or a load spec
        (``INPUT`` with ``material`` → ``INPUT:MATERIAL``).
    models:
        Model names to fit (``"tabulated"``, ``"ggx"``, … resolved by :func:`brdffit.fit.registry.get`),
        paths to saved fit files (``.npz``), ``"label=path.npz"``, or a mapping
        label → (BRDF object | fit-file path | model name).
    out_dir:
        Report directory; the material goes to ``out_dir/<slug>/`` and ``out_dir/index.html``
        is rebuilt from every material present (``update_index``).
    scene, spp, resolution, seed, render_options:
        Passed to the renderer (``render(brdf, scene=..., spp=..., resolution=..., seed=...,
        **render_options)`` returning a linear image and a foreground mask, as a tuple or an
        object with ``image``/``mask``; e.g. ``render_options={"envmap": "studio"}``).
        ``renderer`` replaces :func:`brdffit.evaluation.render.render_ex` (Mitsuba 3; tests use
        a tiny NumPy stand-in).
    exposure, gamma:
        Tone mapping of the PNGs and of the dE2000 conversion (Bagher et al. 2016 §5);
        ``"auto"`` picks one exposure from the reference (:func:`.tonemap.auto_exposure`).
    noise_floor:
        Also render the reference with ``seed + 1`` and report the PSNR/dE2000 between the
        two reference renderings.
    fit_options:
        Per-model keyword arguments of the fitters.
    brdf_metric_samples, brdf_metrics:
        Sample pairs of the cosine-weighted relative error and which BRDF-space metrics to
        compute (:class:`.metrics.BRDFMetrics`; the reference is prepared once).

    Returns the result dict that is also written to ``out_dir/<slug>/result.json``.
    """
    say = progress or (lambda msg: None)
    out_dir = Path(out_dir)
    reference = resolve_reference(source, material)
    mat_name = name or getattr(reference, "name", None) or (material or str(source))
    slug = _safe_name(mat_name)
    mdir = out_dir / slug
    mdir.mkdir(parents=True, exist_ok=True)
    render = renderer or _default_renderer()
    ropts = dict(render_options or {})
    auto_exposure, tonemap = _tonemapper()
    fit_options = dict(fit_options or {})

    # ---- resolve / fit models --------------------------------------------------------
    entries: list[tuple[str, Any]] = []
    if isinstance(models, Mapping):
        entries = list(models.items())
    else:
        for m in models:
            if isinstance(m, str) and "=" in m:
                label, what = m.split("=", 1)
                entries.append((label, what))
            elif isinstance(m, str) and m.endswith(".npz"):
                entries.append((Path(m).stem, m))
            else:
                entries.append((str(m), m))
    fitted: dict[str, Any] = {}
    records: list[dict] = []
    for label, what in entries:
        rec: dict[str, Any] = {"name": label, "status": "ok"}
        records.append(rec)
        try:
            if hasattr(what, "eval"):
                model, rec["fit_time"] = what, None
                rec["origin"] = "given"
            elif isinstance(what, (str, Path)) and str(what).endswith(".npz"):
                from ..io.fitfile import load_fit

                model = load_fit(what)
                rec["origin"] = f"loaded {what}"
                info = getattr(model, "fit_info", None) or {}
                rec["fit_time"] = _num(info.get("time", info.get("time_s")))  # NPF: time_s
            elif is_isotropic_only(str(what)) and not getattr(reference, "isotropic", False):
                rec.update(status="skipped", error=f"{what} fits isotropic BRDFs only")
                continue
            else:
                say(f"{mat_name}: fitting {label}")
                model, rec["fit_time"] = fit_model(str(what), reference, fit_options.get(label))
                rec["origin"] = "fitted"
            fitted[label] = model
            rec["model_class"] = type(model).__name__
            rec["params"] = model_params(model)
            info = getattr(model, "fit_info", None)
            if info:
                rec["fit_info"] = small_json(dict(info))
            if save_fits and rec["origin"] == "fitted":
                try:
                    from ..io.fitfile import SerializableModel, save_fit, table_bytes

                    if isinstance(model, SerializableModel) and model.fit_kind:
                        fp = save_fit(model, mdir / "fits" / f"{_safe_name(label)}.npz",
                                      source=getattr(reference, "source", None))
                        rec["fit_file"] = f"fits/{fp.name}"
                        rec["table_bytes"] = table_bytes(model)
                except Exception as exc:  # noqa: BLE001 – saving is a convenience
                    rec.setdefault("warnings", []).append(f"could not save fit: {exc}")
        except Exception as exc:  # noqa: BLE001 – one failing model must not sink the report
            rec.update(status="failed", error=f"fit/load failed: {type(exc).__name__}: {exc}")
            rec["traceback"] = traceback.format_exc(limit=4)

    # ---- render reference ------------------------------------------------------------
    scene_info = {"scene": scene, "spp": int(spp), "resolution": int(resolution), "seed": int(seed),
                  **{k: (v if isinstance(v, (int, float, str, bool)) else str(v))
                     for k, v in ropts.items()}}
    result: dict[str, Any] = {"material": mat_name, "slug": slug,
                              "source": getattr(reference, "source", None) or (
                                  str(source) if not hasattr(source, "eval") else None),
                              "scene": scene_info, "gamma": gamma, "models": records,
                              "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    say(f"{mat_name}: rendering reference")
    t0 = time.perf_counter()
    ref_img, mask = _unpack_render(render(reference, scene=scene, spp=spp, resolution=resolution,
                                          seed=seed, **ropts))
    t_ref = time.perf_counter() - t0
    exp = auto_exposure(ref_img, mask) if exposure == "auto" else float(exposure)
    result["exposure"] = exp

    def tm(img):
        return tonemap(img, exposure=exp, gamma=gamma)

    _write_png(mdir / "reference.png", tm(ref_img))
    result["reference"] = {"png": "reference.png", "render_time": t_ref,
                           "foreground_pixels": int(mask.sum())}
    if write_exr and _write_exr(mdir / "reference.exr", ref_img) is not None:
        result["reference"]["exr"] = "reference.exr"
    de_kw = {"tonemap": tm}
    if noise_floor:
        say(f"{mat_name}: noise floor")
        img2, _ = _unpack_render(render(reference, scene=scene, spp=spp, resolution=resolution,
                                        seed=seed + 1, **ropts))
        result["noise_floor_psnr"] = M.rendered_psnr(ref_img, img2, mask)
        result["noise_floor_de2000"] = M.mean_delta_e2000(ref_img, img2, mask, **de_kw)

    # ---- render and measure each model -----------------------------------------------
    bm = None
    for rec in records:
        if rec["status"] != "ok":
            continue
        label = rec["name"]
        model = fitted[label]
        fn = _safe_name(label)
        try:
            say(f"{mat_name}: rendering {label}")
            t0 = time.perf_counter()
            img, _ = _unpack_render(render(model, scene=scene, spp=spp, resolution=resolution,
                                           seed=seed, **ropts))
            rec["render_time"] = time.perf_counter() - t0
            rec["psnr"] = M.rendered_psnr(ref_img, img, mask)
            de = M.delta_e2000_image(ref_img, img, mask, **de_kw)
            rec["mean_de2000"] = float(np.nanmean(de))
            _write_png(mdir / f"{fn}.png", tm(img))
            _write_png(mdir / f"{fn}_de2000.png", M.colorize_delta_e(de))
            rec["png"], rec["de_png"] = f"{fn}.png", f"{fn}_de2000.png"
            if write_exr and _write_exr(mdir / f"{fn}.exr", img) is not None:
                rec["exr"] = f"{fn}.exr"
        except Exception as exc:  # noqa: BLE001
            rec.update(status="failed", error=f"render failed: {type(exc).__name__}: {exc}")
            rec["traceback"] = traceback.format_exc(limit=4)
            continue
        try:
            if bm is None:
                say(f"{mat_name}: preparing BRDF-space metrics")
                bm = M.BRDFMetrics(reference, brdf_metric_samples, seed, brdf_metrics)
                result["brdf_metrics_setup"] = bm.timings
            rec["brdf"] = bm.evaluate(model)
        except Exception as exc:  # noqa: BLE001
            rec["brdf"] = {"errors": {"all": f"{type(exc).__name__}: {exc}"}}

    # ---- plots -----------------------------------------------------------------------
    ok = {r["name"]: fitted[r["name"]] for r in records if r["status"] == "ok"}
    plots: dict[str, str] = {}
    for key, fn in (("lobes", lambda p: P.plot_lobes(reference, ok, p, title=mat_name)),
                    ("factors", lambda p: P.plot_factors(ok, p, title=mat_name)),
                    ("slices", lambda p: P.plot_slices(reference, ok, p, title=mat_name))):
        if not ok:
            break
        try:
            if fn(mdir / f"{key}.png") is not None:
                plots[key] = f"{key}.png"
        except Exception as exc:  # noqa: BLE001
            result.setdefault("notes", []).append(f"{key} plot failed: {type(exc).__name__}: {exc}")
    result["plots"] = plots

    R.write_result(mdir, result)
    P.plot_colorbar(out_dir / "assets" / "de_colorbar.png")
    R.write_material_page(out_dir, result)
    if update_index:
        R.write_index(out_dir)
    return result


def compare_many(sources: Iterable, models=DEFAULT_MODELS, out_dir="report", **kw) -> list[dict]:
    """:func:`compare` for several inputs (each a BRDF or spec), then one index rebuild.

    A material that fails entirely (cannot be loaded or the reference cannot be rendered) is
    reported in the returned list as ``{"material": ..., "error": ...}`` and skipped.
    """
    results = []
    for src in sources:
        try:
            results.append(compare(src, models, out_dir, update_index=False, **kw))
        except (BRDFError, OSError, ValueError, RuntimeError, KeyError) as exc:
            results.append({"material": str(getattr(src, "name", src)),
                            "error": f"{type(exc).__name__}: {exc}"})
    R.write_index(out_dir)
    return results


def _num(x):
    try:
        return None if x is None else float(x)
    except (TypeError, ValueError):
        return None
