"""``brdffit fit INPUT[:MATERIAL] --model NAME [-o OUT] [--iterations N] [--json]``.

Loads the input with :func:`brdffit.load`, fits it with the model registered under
``NAME`` in :mod:`brdffit.fit.registry` (``brdffit models`` lists them) and prints a labelled
summary: the slope scales (αx, αy, ρ) and glTF roughness √α, F0 and the Lambertian albedo ρd
per channel (:func:`brdffit.fit.registry.figures`), the fit's error against its input
(:func:`quick_error`), the time, the model's own figures (eigenvalue, iterations...), and
where the fit file was written — or that it was *not* saved (no ``-o``). ``--json`` prints
the same as one JSON object (``output`` is ``null`` when not saved).

Extra fitting options go through ``--option key=value`` (values parsed as JSON when they
can be, e.g. ``--option tol=1e-6 --option anisotropic=true``); an option the model's fitting
function does not take is a usage error (exit status 2) listing the accepted ones
(:func:`accepted_options`), checked before the input is read. Without options the input is
read and validated *before* the fitting module is imported, so a rejected file fails fast.
"""

from __future__ import annotations

import contextlib
import json
import math
import re
import sys
import textwrap
import threading
import time
from pathlib import Path

from ..errors import ExportError, printable
from ..fit import registry
from ..fit.registry import check_options as check, figures, options_class
from ..loading import load
from ._checks import check_models, output_file, parse_options
from ._commands import DEFAULT_MODEL
from ._parsing import usage_error

__all__ = ["fit_cmd", "parse_options", "run_fit", "accepted_options",
           "check_options", "DEFAULT_MODEL"]

#: A fit's error (:func:`quick_error`) above this is called large and the other candidate
#: models are tried (median of the default on MERL-100: 13 %; the RGL interference
#: materials: 44-49 %).
LARGE_ERROR = 0.25
#: The models tried on a large error (fast, physically checked, isotropic ones last).
ALTERNATIVES = ("ggx-diffuse", "sgd", "npf-g-from-d")


def accepted_options(model: str) -> tuple[set, bool]:
    """``(names, open_ended)``: the options of model ``model`` a command line may give
    (its options dataclass, :func:`brdffit.fit.registry.options_class`, without the
    Python-only ones)."""
    from ..fit.options import option_table
    cls, open_ended = options_class(model)
    return {n for n, o in option_table(cls).items() if not o.python_only}, open_ended


def check_options(model: str, options: dict) -> dict:
    """The options checked (:func:`brdffit.fit.registry.check_options`): names, types and
    ranges; a bad one is a usage error (exit 2) naming it and what is accepted."""
    from ..fit.options import OptionError
    try:
        return check(model, options, command_line=True)
    except OptionError as exc:
        raise usage_error("--option", str(exc)) from None


def _unexpected_option(exc: TypeError, options: dict) -> str | None:
    """The user option a fitter rejected with ``TypeError: ... unexpected keyword argument``."""
    m = re.search(r"unexpected keyword argument '([^']+)'", str(exc))
    return m.group(1) if m and m.group(1) in options else None


#: Direction pairs of :func:`quick_error` (deterministic).
QUICK_ERROR_PAIRS = 1 << 14


#: Direction pairs per model evaluation of :func:`_grid_error`.
_EVAL_CHUNK = 8192

#: MERL-grid subsampling of :func:`quick_error` (every θh node, every 3rd θd, every 8th φd).
QUICK_ERROR_GRID_STRIDE = (1, 3, 8)


def _grid_error(values, valid, model) -> tuple[float, int]:
    """``(error, nodes)``: the cosine-weighted relative L1 error on the valid nodes of a
    MERL table (:data:`QUICK_ERROR_GRID_STRIDE`), each weighted by ``cos θi cos θo`` times
    the measure of its cell, ``dωi dωo = 4 cos θd sin θd sin θh dθh dφh dθd dφd`` (φh
    integrated out; θh = θ'h² π/2 so dθh = π θ'h dθ'h)."""
    import numpy as np

    from ..geometry import half_diff_to_io
    from ..grid import N_PHI_D, N_THETA_D, N_THETA_H, merl_phi_d, merl_theta_d, merl_theta_h

    si, sj, sk = QUICK_ERROR_GRID_STRIDE
    th, td, pd = merl_theta_h()[::si], merl_theta_d()[::sj], merl_phi_d()[::sk]
    tp = (np.arange(N_THETA_H)[::si] + 0.5) / N_THETA_H      # θ'h at the cell centres
    dth = np.pi * tp / N_THETA_H * si
    dtd, dpd = np.pi / 2 / N_THETA_D * sj, np.pi / N_PHI_D * sk
    cth, sth = np.cos(th)[:, None, None], np.sin(th)[:, None, None]
    ctd, std = np.cos(td)[None, :, None], np.sin(td)[None, :, None]
    cpd = np.cos(pd)
    along = cth * ctd                                        # (θh, θd, 1)
    across = (sth * std) * cpd                               # (θh, θd, φd)
    ci, co = along - across, along + across
    w = (np.clip(ci, 0, None) * np.clip(co, 0, None)
         * (4 * ctd * std * dtd * dpd) * (sth * dth[:, None, None]))
    keep = np.asarray(valid)[::si, ::sj, ::sk] & (w > 0)
    fr = np.asarray(values, dtype=np.float64)[::si, ::sj, ::sk][keep]
    th_k, td_k, pd_k = (np.broadcast_to(a, keep.shape)[keep]
                        for a in (th[:, None, None], td[None, :, None], pd))
    wi, wo = half_diff_to_io(th_k, 0.0, td_k, pd_k)
    wk = w[keep][:, None]
    den = float((np.abs(fr) * wk).sum())
    if den <= 0:
        raise ValueError("the input BRDF is 0 everywhere: no relative error")
    num = 0.0
    for k in range(0, len(wk), _EVAL_CHUNK):  # the model's temporaries stay small and reused
        part = slice(k, k + _EVAL_CHUNK)
        ft = np.nan_to_num(np.asarray(model.eval(wi[part], wo[part]), dtype=np.float64))
        num += float((np.abs(ft - fr[part]) * wk[part]).sum())
    return num / den, int(keep.sum())


def quick_error(reference, model, n_pairs: int = QUICK_ERROR_PAIRS) -> dict:
    """Cosine-weighted relative L1 error of ``model`` against ``reference``, the quantity of
    :func:`brdffit.evaluation.metrics.cosine_weighted_relative_error` (Σ over RGB of
    ``∫∫ |f_model − f_ref| cos θi cos θo dωi dωo`` over Σ ``∫∫ |f_ref| cos θi cos θo``),
    estimated quickly for the fit summary. 0 is a perfect fit, 1 an error as large as the
    input. Returns ``{"cos_rel_error", "method", "samples"}``.

    * A MERL table (``merl_table()``): quadrature on its own valid nodes (no interpolation of
      the input; :func:`_grid_error`).
    * Anything else: ``n_pairs`` fixed quasi-random direction pairs drawn ∝ cos θi cos θo
      (:func:`brdffit.brdf.cosine_pairs`) instead of the metric's 2^17 scrambled Sobol pairs
      (SciPy's generator costs ~0.3 s to import), those in the reference's measured domain
      only (:meth:`brdffit.brdf.BRDF.measured`).

    Both agree with the full metric within a few % (tests/cli/test_fit_cli.py).
    """
    import numpy as np

    table = getattr(reference, "merl_table", None)
    if callable(table):
        values, valid = table()
        err, n = _grid_error(values, valid, model)
        si, sj, sk = QUICK_ERROR_GRID_STRIDE
        return {"cos_rel_error": err, "samples": n,
                "method": f"{n} valid MERL nodes (every {si}/{sj}/{sk} θh/θd/φd)"}
    from ..brdf import cosine_pairs, measured_mask

    wi, wo = cosine_pairs(n_pairs)
    method = f"{n_pairs} fixed direction pairs"
    keep = measured_mask(reference, wi, wo)
    if keep is not None:
        wi, wo = wi[keep], wo[keep]
        method = (f"the {len(wi)} of {n_pairs} fixed direction pairs in the measured domain, "
                  f"{reference.measured_domain}")
    fr = np.nan_to_num(np.asarray(reference.eval(wi, wo), dtype=np.float64))
    ft = np.nan_to_num(np.asarray(model.eval(wi, wo), dtype=np.float64))
    den = float(np.abs(fr).sum())
    if den <= 0:
        raise ValueError("the input BRDF is 0 everywhere (in its measured domain): "
                         "no relative error")
    return {"cos_rel_error": float(np.abs(ft - fr).sum() / den), "samples": len(wi),
            "method": method}


def _figures_summary(fitted) -> dict:
    """The labelled figures of a fit (:func:`brdffit.fit.registry.figures`) with glTF
    roughness √α next to α."""
    fig = figures(fitted)
    out = {"alpha": None, "gltf_roughness": None, "alpha_kind": fig.get("alpha_kind"),
           "alpha_rgb": fig.get("alpha_rgb"), "f0": fig.get("f0"), "rho_d": fig.get("rho_d"),
           "table_bytes": fig.get("table_bytes"), "coat": fig.get("coat")}
    if fig.get("alpha"):
        ax, ay, rho = fig["alpha"]
        out["alpha"] = {"x": ax, "y": ay, "rho": rho}
        out["gltf_roughness"] = [math.sqrt(max(ax, 0.0)), math.sqrt(max(ay, 0.0))]
    elif fig.get("alpha_rgb"):
        out["gltf_roughness"] = [math.sqrt(max(a, 0.0)) for a in fig["alpha_rgb"]]
    return out


def _entry(model: str):
    """The registry entry of ``model``; an unknown name is a usage error."""
    try:
        return registry.get(model)
    except KeyError as exc:
        raise usage_error("--model", str(exc.args[0])) from None


def check_usage(model: str, options: dict) -> None:
    """Usage errors (exit 2) of a fit request, before any work: an unknown model (from the
    registry's declared names: no fitting module imported) and, only when there are
    options, an option the model's fitter does not take or a value of the wrong type or
    range (imports its module); ``options`` are updated with the checked values."""
    check_models([model], "--model")
    if options:
        _entry(model)
        options.update(check_options(model, options))


@contextlib.contextmanager
def _live_progress(enabled: bool):
    """A status line on the terminal (stderr) with the iteration and objective of a long fit
    (:mod:`brdffit.progress`); Rich is imported only when a fit reports progress."""
    if not enabled:
        yield
        return
    from ..progress import describe, listening  # a status line on a terminal only

    live: dict = {}

    def show(event: dict) -> None:
        if "status" not in live:
            from rich.console import Console

            live["status"] = Console(stderr=True).status("")
            live["status"].start()
        live["status"].update(f"fitting – {describe(event)}")

    with listening(show, min_interval=0.2):
        try:
            yield
        finally:
            if "status" in live:
                live["status"].stop()


def _in_background(fn, *args):
    """Run ``fn(*args)`` on a thread now; the returned callable waits for its result (or
    re-raises its error). Hashing the input (hashlib releases the GIL) overlaps the imports."""
    box: dict = {}

    def run() -> None:
        try:
            box["value"] = fn(*args)
        except BaseException as exc:  # noqa: BLE001 – re-raised in the caller's thread
            box["error"] = exc

    thread = threading.Thread(target=run, daemon=True)
    thread.start()

    def result():
        thread.join()
        if "error" in box:
            raise box["error"]
        return box["value"]

    return result


def run_fit(spec: str, model: str = DEFAULT_MODEL, out: Path | None = None,
            options: dict | None = None, *, error: bool = True) -> tuple[object, dict]:
    """Load ``spec``, fit it with ``model``, optionally save, and summarise; returns
    ``(fit, summary)``.

    The summary holds the labelled figures (``alpha`` {x, y, rho}, ``gltf_roughness``,
    ``f0``, ``rho_d``, ``table_bytes``), ``error`` (:func:`quick_error`, unless
    ``error=False``), ``time_s`` (the fit), ``timings_s`` (load, fit, save, error),
    ``output`` (``None`` when not saved), and the model's own summary under ``details``.
    """
    from ..io._checksum import source_checksum

    timings: dict[str, float] = {}
    # the input's hash for the fit file, on a thread while NumPy is imported (no NumPy in it)
    checksum = _in_background(source_checksum, spec) if out is not None else None
    t0 = time.perf_counter()
    brdf = load(spec)  # read and validated before the fitting stack is imported
    timings["load"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    entry = _entry(model)
    timings["import"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    try:
        fitted = entry.fit(brdf, **(options or {}))
    except TypeError as exc:  # an option the up-front check could not rule out
        bad = _unexpected_option(exc, options or {})
        if bad is None:
            raise
        names, _ = accepted_options(model)
        raise usage_error("--option", f"model {model!r} has no option {bad!r}; accepted: "
                                      f"{', '.join(sorted(names)) or 'none'}") from None
    elapsed = time.perf_counter() - t0
    timings["fit"] = elapsed
    summary: dict = {"input": spec, "model": model, "output": None}
    if out is not None:
        from ..serialization import SerializableModel
        from ..io.fitfile import save_fit

        if not isinstance(fitted, SerializableModel) or not fitted.fit_kind:
            raise ExportError(f"{out}: expected a model that can be saved as a fit file, found "
                              f"{type(fitted).__name__} (e.g. per-channel fits are not saved)")
        t0 = time.perf_counter()
        save_fit(fitted, out, source=spec, source_sha256=checksum(),
                 options=dict(getattr(fitted, "fit_options", None) or options or {}, model=model))
        timings["save"] = time.perf_counter() - t0
        summary["output"] = str(out)
    details = registry.summarize(model, fitted)
    details.pop("model", None)
    details.pop("time_s", None)
    summary.update(_figures_summary(fitted))
    summary["time_s"] = elapsed
    summary["error"] = None
    summary["warnings"] = None
    if error:
        from ..evaluation.validity import check_validity

        t0 = time.perf_counter()
        summary["warnings"] = [v.as_dict() for v in check_validity(fitted)]
        timings["checks"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        try:
            summary["error"] = quick_error(brdf, fitted)
        except Exception as exc:  # noqa: BLE001 - the fit is done; say why there is no figure
            summary["error"] = {"cos_rel_error": None, "why": f"{type(exc).__name__}: {exc}"}
        timings["error"] = time.perf_counter() - t0
        err = summary["error"].get("cos_rel_error")
        if err is not None and err > LARGE_ERROR:
            t0 = time.perf_counter()
            summary["warnings"].append(_large_error_advice(brdf, model, err, fitted))
            timings["alternatives"] = time.perf_counter() - t0
    summary["timings_s"] = timings
    summary["details"] = details
    return fitted, summary


def _large_error_advice(brdf, model: str, error: float, fitted) -> dict:
    """The ``quality`` warning of a fit whose error exceeds :data:`LARGE_ERROR`: the
    :data:`ALTERNATIVES` are fitted (defaults) and measured the same way, and the best one
    is named when it does better by a tenth or more; else what the fit misses is said
    (:func:`brdffit.evaluation.metrics.error_regions`)."""
    tried = {}
    for name in ALTERNATIVES:
        if name == model or (registry.is_isotropic_only(name)
                             and not getattr(brdf, "isotropic", False)):
            continue
        try:
            tried[name] = quick_error(brdf, registry.fit_model(name, brdf)[0])["cos_rel_error"]
        except Exception:  # noqa: BLE001 - an alternative that fails is simply not offered
            continue
    figures = ", ".join(f"{n} {100 * e:.1f} %" for n, e in tried.items() if e is not None)
    best = min(((e, n) for n, e in tried.items() if e is not None), default=None)
    message = f"the error {100 * error:.1f} % is large (above {100 * LARGE_ERROR:g} %)"
    if best is not None and best[0] < 0.9 * error:
        advice = (f"{best[1]} does better on this material: {100 * best[0]:.1f} % "
                  f"(--model {best[1]}; tried {figures})")
    else:
        from ..evaluation.metrics import error_regions

        try:
            missing = error_regions(brdf, fitted, n_samples=1 << 14)["diagnosis"]
        except Exception:  # noqa: BLE001 - the warning stands without its diagnosis
            missing = None
        advice = (f"no other model does better here ({figures or 'none could be fitted'}): "
                  + (missing or "the material has what these microfacet models lack (e.g. a "
                     "second specular lobe, retro-reflection, thin-film colours) or noisy "
                     "measurements"))
    return {"check": "quality", "figure": float(error), "message": message, "advice": advice}


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    return str(v)


def _rgb(v) -> str:
    return "  ".join(f"{c} {x:.4g}" for c, x in zip("RGB", v))


#: Keys of a model's own summary that the labelled lines already show.
_SHOWN = {"alpha", "fresnel_0", "F0", "rho_d", "model", "time_s"}


def format_summary(s: dict) -> list[str]:
    """The text ``brdffit fit`` prints for a :func:`run_fit` summary: one labelled line per
    figure, 80 columns."""
    out = [f"{s['input']}: {s['model']} fit in {s['time_s']:.3f} s"]

    def row(label: str, text: str, wrap: bool = True) -> None:
        if not wrap:  # a path: never broken
            out.append(f"  {label:<19} {text}")
            return
        out.extend(textwrap.wrap(text, 79, initial_indent=f"  {label:<19} ",
                                 subsequent_indent=" " * 22, break_on_hyphens=False)
                   or [f"  {label}"])

    kind = s.get("alpha_kind")
    if s.get("alpha"):
        a = s["alpha"]
        label = "α (GGX-equivalent)" if kind == "ggx-equivalent" else \
            f"α ({kind})" if kind else "α"
        row(label, f"αx {a['x']:.4g}  αy {a['y']:.4g}  ρ {a['rho']:.3g}")
        row("glTF roughness √α", ", ".join(f"{x:.4g}" for x in s["gltf_roughness"]))
    elif s.get("alpha_rgb"):
        row("α per channel", f"{_rgb(s['alpha_rgb'])}   ({kind})")
        row("glTF roughness √α", _rgb(s["gltf_roughness"]))
    else:
        row("α", "none (no analytic distribution)")
    row("F0 (ks·F at 0°)", _rgb(s["f0"]) if s.get("f0") else "undefined for this model")
    row("ρd (Lambert)", _rgb(s["rho_d"]) if s.get("rho_d") else "n/a")
    if s.get("coat"):
        c = s["coat"]
        row("coat", f"α {c['alpha']:.4g} (glTF clearcoat roughness {c['alpha'] ** 0.5:.4g}), "
                    f"weight {c['weight']:.4g}, F0 {c['f0']:g} (white)")
    err = s.get("error")
    if err and err.get("cos_rel_error") is not None:
        row("error vs input", f"{100 * err['cos_rel_error']:.2f} % (cosine-weighted relative "
                              f"L1 on {err['method']})")
    elif err:
        row("error vs input", f"not measured ({err.get('why')})")
    if s.get("table_bytes") is not None:
        row("tables", f"{s['table_bytes']} bytes")
    details = {k: v for k, v in (s.get("details") or {}).items()
               if v is not None and not isinstance(v, dict) and k not in _SHOWN}
    if details:
        row("model details", "; ".join(f"{k} {_fmt(v)}" for k, v in details.items()))
    if s.get("output"):
        row("saved to", str(s["output"]), wrap=False)
    else:
        row("NOT saved", "(no -o FILE.npz given)")
    physical = [w for w in s.get("warnings") or () if w["check"] != "quality"]
    if s.get("warnings") is None:
        row("physical checks", "not run (--no-error)")
    elif not physical:
        row("physical checks", "F ≤ 1, albedo ≤ 1, f ≥ 0, reciprocal: all passed")
    else:
        row("physical checks", f"FAILED: {', '.join(w['check'] for w in physical)} (the "
                               "warnings above say what to do)")
    for w in s.get("warnings") or ():
        if w["check"] == "quality":
            row("quality", f"{w['message']}; {w['advice']}")
    return out


def warning_lines(s: dict) -> list[str]:
    """One ``brdffit: warning:`` line per failed physical check of a :func:`run_fit`
    summary, naming the input, the model, the check, the figure and what to do."""
    return [f"brdffit: warning: {s['input']} ({s['model']} fit): {w['check']}: {w['message']}"
            + (f"; {w['advice']}" if w.get("advice") else "") for w in s.get("warnings") or ()]


def fit_cmd(spec: str, model: str = DEFAULT_MODEL, out: Path | None = None,
            iterations: int | None = None, option: list[str] | None = None,
            no_error: bool = False, as_json: bool = False) -> None:
    """Run ``brdffit fit`` (its options: :func:`brdffit.cli._commands.fit`)."""
    opts = parse_options(option)
    if iterations is not None:
        opts["iterations"] = iterations
    check_usage(model, opts)
    if out is not None:
        output_file(out, (".npz",), hint=" (fit files are .npz; for an engine: brdffit "
                                         "export FIT --to gltf|materialx|mitsuba|glsl|json)")
    with _live_progress(enabled=not as_json and sys.stderr.isatty()):
        _, summary = run_fit(spec, model, out, opts, error=not no_error)
    if as_json:
        from .._json import json_default

        print(json.dumps(summary, default=json_default, sort_keys=True))
        return
    for line in warning_lines(summary):
        print(printable(line), file=sys.stderr)
    for line in format_summary(summary):
        print(printable(line))
