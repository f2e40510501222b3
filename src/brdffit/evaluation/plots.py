"""Comparison plots (matplotlib, Agg back-end), every PNG written atomically.

* :func:`plot_lobes` – BRDF lobes in the incidence plane with the cube root applied, reference
  against each fit, incidence 10°, 30°, 50°, 70° (Bagher, Soler, Holzschuch 2012 Fig. 9; the
  "BRDF Lobes in the Incidence Plane (Cubic Root Applied)" rows of the Dupuy et al. 2015
  supplemental). The plotted quantity is ``(f_r(i, o) cos θo)^(1/3)`` averaged over RGB
  (the cosine-weighted lobe – the reflected radiance shape – is what those figures show;
  documented choice since the papers do not state it).
* :func:`plot_factors` – fitted microfacet factors of every fit that has them: Fresnel (R, G,
  B) over θd, NDF ``D`` over θh (log scale), Smith ``G1`` over θ (Dupuy 2015 supplemental,
  "Fitted Microfacet Functions"; per-channel models such as the SGD fit of Bagher et al. 2012
  draw each channel's own D and G1 in that channel's colour); and NPF tables ``D``, ``F``, ``G`` per colour channel
  (Bagher, Snyder, Nowrouzezahrai 2016 Fig. 6).
* :func:`plot_slices` – the backscattering slice (θd = 0, over θh) and the θh = 0 slice
  (over θd), data against fits, log scale.

Models are used through duck typing: a fit may expose ``distribution`` (``D(m)``, ``G1(w)``),
``fresnel`` (``eval(cos θd)``), or NPF factor tables (see :func:`npf_tables`); what does not
exist is not plotted.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np

from .._atomic import atomic_path
from ..geometry import half_diff_to_io
from .metrics import DELTA_E_CMAP, DELTA_E_VMAX

__all__ = ["plot_lobes", "plot_factors", "plot_slices", "npf_tables", "has_factors",
           "LOBE_INCIDENCES_DEG", "save_figure", "plot_colorbar", "lobe_curve", "npf_sample_angles",
           "slice_values"]

LOBE_INCIDENCES_DEG = (10.0, 30.0, 50.0, 70.0)
_ANGLE_COLOURS = ("#1f77b4", "#2ca02c", "#ff7f0e", "#d62728")
_MODEL_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
                  "#7f7f7f", "#bcbd22", "#17becf")
_RGB = ("#d62728", "#2ca02c", "#1f77b4")


def _plt():
    import matplotlib

    if matplotlib.get_backend().lower() != "agg":
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path, dpi: int = 100) -> Path:
    """Save a matplotlib figure as PNG atomically and close it."""
    plt = _plt()
    path = Path(path)
    try:
        with atomic_path(path, suffix=".png") as tmp:
            fig.savefig(tmp, format="png", dpi=dpi)
    finally:
        plt.close(fig)
    return path


#: Height (inches) of a figure title (``suptitle`` at font size 9) above the panels' titles.
_SUPTITLE_IN = 0.29


def _fixed_layout(fig, nrow: int, ncol: int, left: float, right: float, bottom: float,
                  top: float, wgap: float, hgap: float, title: str | None = None) -> None:
    """Place a figure's ``nrow`` × ``ncol`` panels with fixed margins and gaps in inches
    (``top`` without a title; a title adds :data:`_SUPTITLE_IN`). The values are those
    :meth:`Figure.tight_layout` finds for these plots' labels, fixed: measuring every tick
    label is most of a plot's cost."""
    _pin_titles(fig)
    w, h = fig.get_size_inches()
    top += _SUPTITLE_IN if title else 0.0
    axw = (w - left - right - (ncol - 1) * wgap) / ncol
    axh = (h - bottom - top - (nrow - 1) * hgap) / nrow
    fig.subplots_adjust(left=left / w, right=1 - right / w, bottom=bottom / h, top=1 - top / h,
                        wspace=wgap / axw, hspace=hgap / axh)


def _may_show_offset(ax) -> bool:
    """Whether a panel's y axis may get an offset or ×10ⁿ text above it (matplotlib's
    ``ScalarFormatter`` on a linear axis whose view is narrow for its magnitude, or whose
    values are below 10⁻⁴ or above 10⁶); the test errs on the side of yes."""
    if ax.get_yscale() != "linear":
        return False
    lo, hi = ax.get_ylim()
    big = max(abs(lo), abs(hi))
    return not 1e-3 <= big < 1e5 or hi - lo < 1e-2 * big


def _pin_titles(fig) -> None:
    """Panel titles at the top edge of their panel, which is where matplotlib puts them
    unless a y-axis offset text is in the way (:func:`_may_show_offset`: those keep the
    automatic placement, which measures the axis at every draw)."""
    for ax in fig.axes:
        if ax.get_title() and not _may_show_offset(ax):
            ax.set_title(ax.get_title(), fontsize=ax.title.get_fontsize(), y=1.0)


def _eval(brdf, wi, wo) -> np.ndarray:
    f = np.asarray(brdf.eval(wi, wo), dtype=np.float64)
    return np.maximum(np.nan_to_num(f, nan=0.0, posinf=0.0, neginf=0.0), 0.0)


def _incidence_plane(theta_i_deg: float, n: int = 361):
    """``wi`` at ``θi`` in the xz plane and ``wo`` sweeping the plane, θo ∈ [-90°, 90°]."""
    ti = np.radians(theta_i_deg)
    wi = np.array([np.sin(ti), 0.0, np.cos(ti)])
    to = np.linspace(-np.pi / 2, np.pi / 2, n)
    wo = np.stack([np.sin(to), np.zeros_like(to), np.cos(to)], -1)
    return np.broadcast_to(wi, wo.shape), wo, to


def lobe_curve(brdf, theta_i_deg: float, n: int = 361):
    """Cube-root lobe ``(f_r cos θo)^(1/3)`` (RGB mean) in the incidence plane as ``(x, z)``.

    ``x = r sin θo``, ``z = r cos θo`` with ``θo`` signed (negative on the mirror side of
    ``wi``, which sits at positive x).
    """
    wi, wo, to = _incidence_plane(theta_i_deg, n)
    f = _eval(brdf, wi, wo).mean(axis=-1) * np.maximum(np.cos(to), 0.0)
    r = np.cbrt(f)
    return r * np.sin(to), r * np.cos(to)


def plot_lobes(reference, fits: Mapping[str, object], path, incidences=LOBE_INCIDENCES_DEG,
               title: str | None = None) -> Path:
    """One panel per fit: cube-root lobes of the reference (dashed black) and the fit
    (coloured by incidence angle) in the incidence plane. See the module docstring."""
    plt = _plt()
    names = list(fits)
    ncol = max(1, min(3, len(names)))
    nrow = max(1, -(-len(names) // ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.6 * ncol, 2.3 * nrow), squeeze=False)
    for ax in axes.ravel()[len(names):]:
        ax.set_axis_off()
    ref_curves = [lobe_curve(reference, t) for t in incidences]
    rmax = max(float(np.max(np.hypot(x, z))) for x, z in ref_curves) or 1.0
    for ax, name in zip(axes.ravel(), names):
        for t, col, (xr, zr) in zip(incidences, _ANGLE_COLOURS, ref_curves):
            ax.plot(xr, zr, "--", color="k", lw=0.9)
            xf, zf = lobe_curve(fits[name], t)
            ax.plot(xf, zf, "-", color=col, lw=1.2, label=f"{t:g}°")
            ti = np.radians(t)
            ax.plot([0, 0.15 * rmax * np.sin(ti)], [0, 0.15 * rmax * np.cos(ti)], ":", color=col,
                    lw=0.8)
        ax.set_aspect("equal")
        ax.set_xlim(-1.05 * rmax, 1.05 * rmax)
        ax.set_ylim(0, 1.05 * rmax)
        ax.set_title(name, fontsize=9)
        ax.tick_params(labelsize=6)
    axes[0][0].legend(fontsize=6, loc="upper right", title="θi (ref dashed)", title_fontsize=6)
    if title:
        fig.suptitle(title, fontsize=9)
    _fixed_layout(fig, nrow, ncol, 0.43, 0.15, 0.17, 0.18, 0.40, 0.20, title)
    return save_figure(fig, path)


# ------------------------------------------------------------------------------------------
# factors
# ------------------------------------------------------------------------------------------
def npf_tables(model) -> dict[str, np.ndarray] | None:
    """NPF factor tables ``{"D": (n, 3), "F": (n, 3), "G": (n, 3)}`` of a model, or ``None``.

    Looks, in order, for a ``factor_tables()`` / ``factors()`` method returning a dict, or
    attributes ``D_table``/``F_table``/``G_table`` or ``d_table``/``f_table``/``g_table``.
    Tables may be ``(n,)`` or ``(n, 3)``. Unless the dict has ``theta_D``/``theta_F``/
    ``theta_G``/``theta_H``, the sample positions are those of Bagher et al. 2016 (Eq. 6,
    §4.3): D on the MERL θh grid ``θh = (i/n)² π/2`` (uniform in ``sqrt(θh)``), F and G at
    ``θ = i · (π/2)/n`` (1° steps for n = 90), the naive model's H at ``φd = i · π/n``.
    """
    for meth in ("factor_tables", "factors"):
        fn = getattr(model, meth, None)
        if callable(fn):
            try:
                tabs = fn()
            except Exception:  # noqa: BLE001
                tabs = None
            if isinstance(tabs, Mapping) and any(k in tabs for k in "DFGH"):
                return {k: np.asarray(v, float) for k, v in tabs.items()}
    found = {}
    for k in "DFG":
        for attr in (f"{k}_table", f"{k.lower()}_table"):
            v = getattr(model, attr, None)
            if v is not None and not callable(v):
                found[k] = np.asarray(v, float)
                break
    if found:
        return found
    return None


def npf_sample_angles(key: str, n: int) -> np.ndarray:
    """Default sample positions (radians) of NPF table ``key`` with ``n`` samples."""
    i = np.arange(n)
    if key == "D":
        return (i / n) ** 2 * (np.pi / 2)
    if key == "H":
        return i * (np.pi / n)
    return i * (np.pi / 2 / n)


def _channel_lobes(model):
    """Per-colour-channel microfacet lobes (e.g. the SGD fit of Bagher et al. 2012 §5.1,
    one distribution and Fresnel per channel): a ``lobes`` list of 3 objects with
    ``distribution``/``fresnel``, else ``None``."""
    lobes = getattr(model, "lobes", None)
    if isinstance(lobes, (list, tuple)) and len(lobes) == 3 and all(
            getattr(lb, "distribution", None) is not None for lb in lobes):
        return list(lobes)
    return None


def _specular_fresnel(lobe, cos_d) -> np.ndarray:
    """``ks·F(θd)`` of a lobe, ``(n, channels)``: the reflectance whose value at θd = 0 is
    the F0 of the parameters table (:func:`brdffit.fit.registry.figures`)."""
    if hasattr(lobe, "_fresnel"):
        F = np.asarray(lobe._fresnel(cos_d), float)
    else:
        F = np.asarray(lobe.fresnel.eval(cos_d), float)
        ks = getattr(lobe, "specular", None)
        if ks is not None:
            F = F * np.asarray(ks, float)
    return F.reshape(np.size(cos_d), -1)


def _plot_channel_lobes(axF, axD, axG, name, lobes, th, m, ls):
    """Factors of a per-channel model: channel c's own ks·F, D and G1 in colour c."""
    for c, lobe in enumerate(lobes):
        lab = f"{name} (per channel)" if c == 0 else None
        try:
            F = _specular_fresnel(lobe, np.cos(th))
            axF.plot(np.degrees(th), F[:, c if F.shape[1] == 3 else 0], ls, color=_RGB[c], lw=1)
        except Exception:  # noqa: BLE001
            pass
        try:
            D = np.asarray(lobe.distribution.D(m), float)
            axD.semilogy(np.degrees(th), np.maximum(D, 1e-8), ls, color=_RGB[c], lw=1, label=lab)
        except Exception:  # noqa: BLE001
            pass
        try:
            G = np.asarray(lobe.distribution.G1(m), float)
            axG.plot(np.degrees(th), G, ls, color=_RGB[c], lw=1, label=lab)
        except Exception:  # noqa: BLE001
            pass


def has_factors(model) -> bool:
    """True when a model exposes anything :func:`plot_factors` can draw."""
    return (getattr(model, "distribution", None) is not None
            or getattr(model, "fresnel", None) is not None or npf_tables(model) is not None
            or _channel_lobes(model) is not None)


def _angles(n):
    return np.linspace(0.0, np.pi / 2, n)


def plot_factors(fits: Mapping[str, object], path, n: int = 200, title: str | None = None):
    """Fresnel ``ks·F`` (R, G, B: the colour is the channel, the line style the model; its
    value at θd = 0 is the parameters table's F0) over θd, D over θh and Smith G1 over θ for
    every fit that has them, plus one row of NPF D/F/G per channel for each NPF-like fit.
    Returns the path, or ``None`` when no fit exposes any factor (no file is written then)."""
    plt = _plt()
    micro = {k: m for k, m in fits.items() if getattr(m, "distribution", None) is not None
             or getattr(m, "fresnel", None) is not None or _channel_lobes(m)}
    npf = {k: t for k, t in ((k, npf_tables(m)) for k, m in fits.items()) if t is not None}
    nrows = (1 if micro else 0) + len(npf)
    if nrows == 0:
        return None
    fig, axes = plt.subplots(nrows, 3, figsize=(10, 2.6 * nrows), squeeze=False)
    th = _angles(n)
    row = 0
    if micro:
        _plot_microfacet_factors(axes[0], micro, th)
        row = 1
    for name, tabs in npf.items():
        _plot_npf_tables(axes[row], name, tabs)
        row += 1
    for ax in axes.ravel():
        ax.tick_params(labelsize=7)
    if title:
        fig.suptitle(title, fontsize=9)
    _fixed_layout(fig, nrows, 3, 0.50, 0.15, 0.54, 0.36, 0.48, 0.76, title)
    return save_figure(fig, path)


def _plot_microfacet_factors(axes_row, micro: Mapping[str, object], th: np.ndarray) -> None:
    """The first row of :func:`plot_factors`: Fresnel, D and G1 of every fit of ``micro``
    (line style per model, in the model's colour for D and G1) over the angles ``th``."""
    from matplotlib.lines import Line2D

    axF, axD, axG = axes_row
    m = np.stack([np.sin(th), np.zeros_like(th), np.cos(th)], -1)
    styles = ("-", "--", ":", "-.")
    fresnel_keys = []   # one legend entry per model: its line style, in black
    for k, (name, model) in enumerate(micro.items()):
        col = _MODEL_COLOURS[k % len(_MODEL_COLOURS)]
        ls = styles[k % len(styles)]
        lobes = _channel_lobes(model)
        if lobes:
            _plot_channel_lobes(axF, axD, axG, name, lobes, th, m, ls)
            fresnel_keys.append(Line2D([], [], ls=ls, color="k", lw=1,
                                       label=f"{name} (per channel)"))
            continue
        if getattr(model, "fresnel", None) is not None or hasattr(model, "_fresnel"):
            try:
                F = _specular_fresnel(model, np.cos(th))
                for c in range(min(3, F.shape[1])):
                    axF.plot(np.degrees(th), F[:, c], ls, color=_RGB[c], lw=1)
                fresnel_keys.append(Line2D([], [], ls=ls, color="k", lw=1, label=name))
            except Exception:  # noqa: BLE001 – a factor that cannot be evaluated is skipped
                pass
        dist = getattr(model, "distribution", None)
        if dist is not None:
            try:
                D = np.asarray(dist.D(m), float)
                axD.semilogy(np.degrees(th), np.maximum(D, 1e-8), ls, color=col, lw=1, label=name)
            except Exception:  # noqa: BLE001
                pass
            try:
                G = np.asarray(dist.G1(m), float)
                axG.plot(np.degrees(th), G, ls, color=col, lw=1, label=name)
            except Exception:  # noqa: BLE001
                pass
    axF.set(title="Fresnel ks·F (colour: R, G, B)", xlabel="θd (°)")
    axD.set(title="NDF D", xlabel="θh (°)")
    axG.set(title="Smith G1", xlabel="θ (°)", ylim=(0, 1.05))
    if fresnel_keys:
        axF.legend(handles=fresnel_keys, fontsize=6)
    for ax in (axD, axG):
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=6)


def _plot_npf_tables(axes_row, name: str, tabs: dict) -> None:
    """One NPF row of :func:`plot_factors`: the D, F and G (or H) tables of fit ``name``
    per channel (:func:`npf_tables`); an axis without its table is switched off."""
    third = ("G", "θ") if "G" in tabs or "H" not in tabs else ("H", "φd")
    for j, (key, label) in enumerate((("D", "θh"), ("F", "θd"), third)):
        ax = axes_row[j]
        tab = tabs.get(key)
        if tab is None:
            ax.set_axis_off()
            continue
        tab = tab.reshape(tab.shape[0], -1)
        x = np.asarray(tabs.get(f"theta_{key}", npf_sample_angles(key, tab.shape[0])), float)
        for c in range(min(3, tab.shape[1])):
            col = _RGB[c] if tab.shape[1] > 1 else "k"
            if key == "D":
                ax.semilogy(np.degrees(x), np.maximum(tab[:, c], 1e-8), color=col, lw=1)
            else:
                ax.plot(np.degrees(x), tab[:, c], color=col, lw=1)
        ax.set(title=f"{name}: {key} per channel", xlabel=f"{label} (°)")


# ------------------------------------------------------------------------------------------
# slices
# ------------------------------------------------------------------------------------------
def _eval_hd(brdf, theta_h, theta_d, phi_d):
    fn = getattr(brdf, "eval_hd", None)
    if callable(fn):
        try:
            return np.maximum(np.nan_to_num(np.asarray(fn(theta_h, theta_d, phi_d), float)), 0.0)
        except NotImplementedError:
            pass
    wi, wo = half_diff_to_io(theta_h, np.zeros_like(theta_h), theta_d, phi_d)
    return _eval(brdf, wi, wo)


def slice_values(brdf, which: str, n: int = 180) -> tuple[np.ndarray, np.ndarray]:
    """``(angles, f (n, 3))`` on the backscattering slice (``which="backscatter"``: θd = 0,
    over θh) or the ``"theta_h0"`` slice (θh = 0, over θd, φd = π/2)."""
    t = np.linspace(0.0, np.radians(89.0), n)
    z = np.zeros_like(t)
    if which == "backscatter":
        return t, _eval_hd(brdf, t, z, z)
    if which == "theta_h0":
        return t, _eval_hd(brdf, z, t, np.full_like(t, np.pi / 2))
    raise ValueError(f"slice: expected 'backscatter' or 'theta_h0', found {which!r}")


def _log_label_room(ax) -> float:
    """Room (inches) left of a log-scale panel for its tick labels and y label: matplotlib's
    ``LogFormatterSciNotation`` also labels minor ticks (``2×10⁻¹``, wider than ``10⁻¹``)
    when the view spans less than one decade (its ``minor_thresholds``)."""
    lo, hi = ax.get_ylim()
    return 0.68 if hi >= 10.0 * lo else 1.08


def plot_slices(reference, fits: Mapping[str, object], path, title: str | None = None) -> Path:
    """Backscattering (θd = 0) and θh = 0 slices, data (black) vs fits, log scale, one row per
    RGB channel mean (left: over θh, right: over θd)."""
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.2), squeeze=False)
    for ax, which, xl, tt in ((axes[0][0], "backscatter", "θh (°)", "backscattering θd = 0"),
                              (axes[0][1], "theta_h0", "θd (°)", "θh = 0")):
        t, f = slice_values(reference, which)
        ax.semilogy(np.degrees(t), np.maximum(f.mean(-1), 1e-6), "k-", lw=2, label="data")
        for k, (name, model) in enumerate(fits.items()):
            _, g = slice_values(model, which)
            ax.semilogy(np.degrees(t), np.maximum(g.mean(-1), 1e-6), "-",
                        color=_MODEL_COLOURS[k % len(_MODEL_COLOURS)], lw=1, label=name)
        ax.set(title=tt + " (RGB mean)", xlabel=xl, ylabel="f_r (1/sr)")
        ax.tick_params(labelsize=7)
    axes[0][1].legend(fontsize=6)
    if title:
        fig.suptitle(title, fontsize=9)
    _fixed_layout(fig, 1, 2, _log_label_room(axes[0][0]), 0.15, 0.54, 0.36,
                  _log_label_room(axes[0][1]), 0.0, title)
    return save_figure(fig, path)


def plot_colorbar(path, vmax: float | None = None, cmap: str | None = None,
                  label: str = "CIE dE2000") -> Path:
    """The fixed dE2000 colour scale of the report (:data:`metrics.DELTA_E_VMAX`,
    :data:`metrics.DELTA_E_CMAP`) as a small horizontal colour bar PNG."""
    from matplotlib import colormaps
    from matplotlib.colors import Normalize
    from matplotlib.cm import ScalarMappable

    plt = _plt()
    vmax = DELTA_E_VMAX if vmax is None else vmax
    fig, ax = plt.subplots(figsize=(2.6, 0.75))
    fig.colorbar(ScalarMappable(Normalize(0, vmax), colormaps[cmap or DELTA_E_CMAP]), cax=ax,
                 orientation="horizontal", extend="max")
    ax.set_xlabel(label, fontsize=8)
    ax.tick_params(labelsize=7)
    fig.tight_layout()
    return save_figure(fig, path)
