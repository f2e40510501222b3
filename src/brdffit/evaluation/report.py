"""Static HTML comparison report: one page per material and an index across materials.

Layout of a report directory ``OUT``::

    OUT/index.html                 index: per-model summary + per-material table (sortable)
    OUT/assets/de_colorbar.png     the fixed dE2000 colour scale
    OUT/<slug>/result.json         everything measured for one material (input of the pages)
    OUT/<slug>/index.html          material page
    OUT/<slug>/*.png, *.exr, fits/  renderings, dE maps, plots, saved fits

Pages are plain HTML with a small inline stylesheet and inline JavaScript (table sorting),
no external resource and no CDN, every link relative: they open from ``file://`` offline.
The index is rebuilt from every ``OUT/*/result.json`` each time (:func:`write_index`), so
adding a material to an existing report updates the index. Every file is written
atomically (:mod:`brdffit._atomic`).

The per-material layout follows the supplemental of Dupuy et al. 2015 (renderings, CIE dE00
maps, lobes in the incidence plane, fitted microfacet functions), extended with the metrics
of Bagher et al. 2016 §5 (rendered PSNR) and Bagher et al. 2012 §6.3 (normalised L2).
"""

from __future__ import annotations

import html
import json
import math
import re
from pathlib import Path
from typing import Iterable

import numpy as np

from .._atomic import atomic_write
from .._json import float_or_none as _num, json_default, standard_json
from ..errors import printable
from .metrics import count_wins
from ..paths import slug
from .report_viewer import viewer_sections

__all__ = ["RESULT_NAME", "slugify", "write_result", "read_results", "write_material_page",
           "write_index", "local_links", "missing_links", "summarize"]

RESULT_NAME = "result.json"

_CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',Helvetica,Arial,sans-serif;margin:1.2em;
color:#222;background:#fafafa}
h1{font-size:1.4em}h2{font-size:1.15em;margin-top:1.6em;border-bottom:1px solid #ccc}
table{border-collapse:collapse;font-size:.85em;margin:.5em 0}
th,td{border:1px solid #ccc;padding:.25em .5em;text-align:right;vertical-align:middle}
th{background:#eee;cursor:pointer;user-select:none}th.sorted-asc::after{content:' \\25B2'}
th.sorted-desc::after{content:' \\25BC'}td.l,th.l{text-align:left}
.grid{display:flex;flex-wrap:wrap;gap:10px}
.cell{text-align:center;font-size:.8em;width:min-content}
.cell img{display:block;image-rendering:auto;border:1px solid #999;background:#000}
.best{font-weight:bold;background:#e6f4e6}.fail{color:#b00}
.badge{display:inline-block;padding:0 .35em;border-radius:.3em;font-size:85%;background:#fde8c8;color:#7a4100}
.badge.ok{background:#e6f4e6;color:#215a21}
img.plot{max-width:100%;border:1px solid #ddd;background:#fff}
img.thumb{width:64px;height:64px;border:1px solid #999}
pre{font-size:.75em;background:#f0f0f0;padding:.4em;max-width:60em;overflow:auto;white-space:pre-wrap}
.note{color:#555;font-size:.85em;max-width:60em}
"""

_SORT_JS = """
<script>
// Click a header to sort its table (numeric when the cells are numbers, text otherwise).
document.querySelectorAll('table.sortable').forEach(function (table) {
  table.querySelectorAll('thead th').forEach(function (th, col) {
    th.addEventListener('click', function () {
      var body = table.tBodies[0];
      var rows = Array.prototype.slice.call(body.rows);
      var asc = !th.classList.contains('sorted-asc');
      table.querySelectorAll('thead th').forEach(function (h) {
        h.classList.remove('sorted-asc', 'sorted-desc'); });
      th.classList.add(asc ? 'sorted-asc' : 'sorted-desc');
      function key(r) {
        var c = r.cells[col]; var v = c.getAttribute('data-sort');
        if (v === null) v = c.textContent.trim();
        var x = parseFloat(v);
        return isNaN(x) ? v.toLowerCase() : x;
      }
      rows.sort(function (a, b) {
        var x = key(a), y = key(b);
        if (typeof x !== typeof y) { x = String(x); y = String(y); }
        return (x < y ? -1 : x > y ? 1 : 0) * (asc ? 1 : -1);
      });
      rows.forEach(function (r) { body.appendChild(r); });
    });
  });
});
// Show only the rows of the materials table whose material name contains the filter text.
function filterRows(text) {
  var t = text.toLowerCase();
  var table = document.getElementById('materials');
  if (!table) return;
  Array.prototype.forEach.call(table.tBodies[0].rows, function (r) {
    var name = r.cells.length > 1 ? r.cells[1].textContent.toLowerCase() : '';
    r.style.display = name.indexOf(t) >= 0 ? '' : 'none';
  });
}
var filterBox = document.getElementById('filter');
if (filterBox) filterBox.addEventListener('input', function () { filterRows(filterBox.value); });
// After loading, record on <html> how many images loaded (used by the headless-browser check).
window.addEventListener('load', function () {
  var imgs = Array.prototype.slice.call(document.images);
  var bad = imgs.filter(function (i) { return !(i.complete && i.naturalWidth > 0); });
  var root = document.documentElement;
  root.setAttribute('data-images-total', String(imgs.length));
  root.setAttribute('data-images-broken', String(bad.length));
  root.setAttribute('data-images-broken-list', bad.map(function (i) {
    return i.getAttribute('src'); }).join('|'));
});
</script>
"""


# ------------------------------------------------------------------------------------------
# result files
# ------------------------------------------------------------------------------------------
def slugify(name: str) -> str:
    """A file-system and URL safe directory name for a material: :func:`brdffit.paths.slug`
    (the package's one name-to-path function; distinct names never share a folder)."""
    return slug(name)


def write_result(material_dir, result: dict) -> Path:
    """Write ``result.json`` of one material atomically."""
    path = Path(material_dir) / RESULT_NAME
    with atomic_write(path, "w") as fh:
        json.dump(standard_json(result), fh, indent=1, default=json_default, allow_nan=False)
    return path


def read_results(out_dir) -> list[dict]:
    """Every ``OUT/*/result.json`` (sorted by material), each with ``slug`` set to its folder."""
    out = []
    for p in sorted(Path(out_dir).glob(f"*/{RESULT_NAME}")):
        try:
            res = json.loads(p.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError):
            continue  # a broken result of one material must not hide the others
        res["slug"] = p.parent.name
        out.append(res)
    return sorted(out, key=lambda r: str(r.get("material", r["slug"])).lower())


# ------------------------------------------------------------------------------------------
# formatting helpers
# ------------------------------------------------------------------------------------------
def _fmt(x, digits: int = 2, unit: str = "") -> str:
    v = _num(x)
    if v is None:
        return "–"
    if math.isinf(v):
        return "∞" if v > 0 else "−∞"
    if math.isnan(v):
        return "nan"
    if v != 0 and (abs(v) < 10 ** (-digits) or abs(v) >= 1e5):
        return f"{v:.{digits}e}{unit}"
    return f"{v:.{digits}f}{unit}"


def _sortkey(x) -> str:
    v = _num(x)
    if v is None or math.isnan(v):
        return ""
    return repr(1e300 if v == math.inf else -1e300 if v == -math.inf else v)


def _e(s) -> str:
    """Text for HTML: control and invisible format characters (ESC, NUL, bidirectional
    overrides) escaped as visible ``\\x1b``-style text, then HTML-escaped."""
    return html.escape(printable(str(s)), quote=True)


def _td(x, digits=2, cls="", unit=""):
    c = f' class="{cls}"' if cls else ""
    return f'<td{c} data-sort="{_e(_sortkey(x))}">{_e(_fmt(x, digits, unit))}</td>'


def _page(title: str, body: str) -> str:
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<meta name=\"viewport\" content=\"width=device-width\"><title>{_e(title)}</title>"
            f"<style>{_CSS}</style></head><body>\n{body}\n{_SORT_JS}</body></html>\n")


def _url(path) -> str | None:
    """A relative link to a file of the report: each path segment percent-encoded (spaces,
    ``#``, ``?``, ``%``, quotes, non-ASCII), or ``None`` for anything that is not a relative
    path (a scheme such as ``javascript:``/``data:``, ``//host``, an absolute path, a
    backslash or a control character): result files may come from elsewhere (untrusted)."""
    from urllib.parse import quote

    s = str(path) if path is not None else ""
    if (not s or re.match(r"^[A-Za-z][A-Za-z0-9+.-]*:", s) or s.startswith("/") or "\\" in s
            or not s.isprintable()):
        return None
    return "/".join(quote(seg, safe="") for seg in s.split("/"))


def _img(src, alt, cls="", width=None) -> str:
    url = _url(src)
    if url is None:                       # not a file of the report: no link, say so
        return f'<span class="fail">{_e(alt)}: link removed ({_e(src)})</span>'
    w = f' width="{int(width)}"' if width else ""
    c = f' class="{cls}"' if cls else ""
    return f'<img src="{_e(url)}" alt="{_e(alt)}"{c}{w} loading="eager">'


def _models(result) -> list[dict]:
    return list(result.get("models") or [])


def _ok(m) -> bool:
    return m.get("status", "ok") == "ok"


def _pm(value, se=None, bound=None, digits: int = 2) -> str:
    """``psnr ± se`` (``≥ psnr`` for a lower bound, the value alone without a finite se)."""
    v = _num(value)
    if v is None:
        return "–"
    if bound == "lower":
        return "≥ " + _fmt(v, digits)
    e = _num(se)
    if e is None or math.isnan(e) or math.isinf(v):
        return _fmt(v, digits)
    return f"{_fmt(v, digits)} ± {_fmt(e, digits)}"


def _td_pm(m, cls="", thumb: str = "") -> str:
    """A table cell ``PSNR ± se`` of a model (or one of its scenes), sortable by the PSNR,
    optionally under a thumbnail (``thumb``: HTML)."""
    if not isinstance(m, dict) or _num(m.get("psnr")) is None:
        return f'<td data-sort="">{thumb}–</td>'
    c = f' class="{cls}"' if cls else ""
    return (f'<td{c} data-sort="{_e(_sortkey(m.get("psnr")))}">{thumb}'
            f'{_e(_pm(m.get("psnr"), m.get("psnr_se"), m.get("psnr_bound", m.get("bound"))))}</td>')


def _validity_badge(m: dict, full: bool = False) -> str:
    """The physical checks of a model (:mod:`.validity`, ``m["validity"]``) as a badge: the
    failed checks with their figures (each message in the tooltip, or written out with
    ``full``), "valid" when all passed, ``""`` for results without checks."""
    checks = m.get("validity") if isinstance(m, dict) else None
    if not isinstance(checks, list):
        return ""
    if not checks:
        return '<span class="badge ok" title="F ≤ 1, albedo ≤ 1, f ≥ 0, reciprocal">valid</span>'
    items = [c for c in checks if isinstance(c, dict)]
    label = ", ".join(f"{c.get('check')} {_fmt(c.get('figure'), 3)}" for c in items)
    text = "; ".join(f"{c.get('check')}: {c.get('message')}"
                     + (f" ({c.get('advice')})" if c.get("advice") else "") for c in items)
    badge = f'<span class="badge" title="{_e(text)}">⚠ {_e(label)}</span>'
    return badge + (f'<br><span class="note">{_e(text)}</span>' if full else "")


def _thumb(slug: str, m: dict, result: dict) -> str:
    """The model's rendering of the first scene as a 64-pixel thumbnail (``""`` if none)."""
    png = m.get("png")
    scenes = _scenes(result)
    if scenes:
        png = _model_scene(m, str(scenes[0].get("name"))).get("png")
    if not isinstance(png, str) or _url(png) is None:     # the file's own link must be safe
        return ""
    return _img(f"{slug}/{png}", f"{m.get('name')} rendering", cls="thumb") + "<br>"


def _batch_recommendations(path: Path) -> dict[str, str]:
    """``{material: recommended model}`` from a batch's ``summary.json`` next to the report
    (:mod:`brdffit.batch_summary`); ``{}`` when there is none or it cannot be read."""
    try:
        rec = json.loads(Path(path).read_text(encoding="utf-8")).get("recommended") or {}
    except (OSError, ValueError, AttributeError):
        return {}
    return {str(k): str(v.get("model")) for k, v in rec.items()
            if isinstance(v, dict) and v.get("model")}


def _scenes(result) -> list[dict]:
    """The result's scene list (new results), ``[]`` for single-scene results of old versions."""
    sc = result.get("scenes")
    return [s for s in sc if isinstance(s, dict)] if isinstance(sc, list) else []


def _model_scene(m, name) -> dict:
    sc = m.get("scenes")
    for e in sc if isinstance(sc, list) else []:
        if isinstance(e, dict) and e.get("scene") == name:
            return e
    return {}


# ------------------------------------------------------------------------------------------
# material page
# ------------------------------------------------------------------------------------------
def write_material_page(out_dir, result: dict, colorbar: str | None = "../assets/de_colorbar.png"
                        ) -> Path:
    """Write ``OUT/<slug>/index.html`` for one material from its result dict."""
    slug = result.get("slug") or slugify(result.get("material", "material"))
    mdir = Path(out_dir) / slug
    name = result.get("material", slug)
    ref = result.get("reference") or {}
    res = (result.get("scene") or {}).get("resolution") or 256
    disp = int(min(256, max(96, int(res))))
    models = _models(result)
    ok_psnr = [_num(m.get("psnr")) for m in models if _ok(m) and _num(m.get("psnr")) is not None]
    best = max(ok_psnr) if ok_psnr else None

    parts = [f"<p><a href=\"../index.html\">← all materials</a></p><h1>{_e(name)}</h1>"]
    src = result.get("source")
    scene = result.get("scene") or {}
    scenes = _scenes(result)
    if scenes:
        tone = ("Tone mapping (Bagher et al. 2016 §5), one fixed exposure per scene for every "
                "image: " + _e("; ".join(f"{sc.get('name')}: exposure {_fmt(sc.get('exposure'), 4)}, "
                                         f"gamma {_fmt(sc.get('gamma'), 1)}" for sc in scenes)) + ". ")
    else:
        tone = (f"Tone mapping (Bagher et al. 2016 §5): exposure {_e(_fmt(result.get('exposure'), 4))},"
                f" gamma {_e(result.get('gamma', 2.2))}, the same for every image. ")
    parts.append('<p class="note">' + (f"Source: <code>{_e(src)}</code>. " if src else "")
                 + "Settings: " + _e(", ".join(f"{k}={v}" for k, v in scene.items()))
                 + ". " + tone
                 + ("PSNR ± standard error: each scene is rendered in independent batches with "
                    "common random numbers (reference and models along the same paths); the "
                    "PSNR of a scene is estimated from the batches without their noise bias, "
                    "± its standard error, and a model's PSNR is the mean over the scenes. "
                    if scenes else "")
                 + (f"Monte Carlo noise floor (reference rendered with two seeds): "
                    f"PSNR {_e(_fmt(result.get('noise_floor_psnr')))} dB, dE2000 "
                    f"{_e(_fmt(result.get('noise_floor_de2000')))}."
                    if result.get("noise_floor_psnr") is not None else "")
                 + "</p>")

    # renderings and dE maps, metrics
    if scenes:
        parts += _scene_sections(scenes, models, disp, colorbar)
        parts += viewer_sections(out_dir, mdir, result, disp, _cell)
    else:
        parts += _single_scene_sections(ref, models, disp, colorbar)
    parts.append(_metrics_table(models, scenes, best))
    if isinstance(result.get("measured_domain"), str):
        parts.append('<p class="note">BRDF-space metrics (cos-weighted error, normalised L2, '
                     "compressive objective) over the measured domain only: "
                     f"{_e(result['measured_domain'])}.</p>")
    parts.append(_error_regions_section(models))

    # plots
    plots = result.get("plots") or {}
    titles = {"lobes": "BRDF lobes in the incidence plane (cube root applied)",
              "factors": "Fitted microfacet functions",
              "slices": "Backscattering (θd = 0) and θh = 0 slices"}
    for key, title in titles.items():
        if plots.get(key):
            parts.append(f"<h2>{_e(title)}</h2>{_img(plots[key], title, cls='plot')}")

    # parameters, convergence, files
    parts += _parameter_sections(models, mdir)
    if result.get("notes"):
        parts.append("<h2>Notes</h2><ul>" + "".join(f"<li>{_e(n)}</li>" for n in result["notes"])
                     + "</ul>")
    path = mdir / "index.html"
    with atomic_write(path, "w") as fh:
        fh.write(_page(f"brdffit compare – {name}", "\n".join(parts)))
    return path


# ------------------------------------------------------------------------------------------
# parameters, convergence and files of the fits
# ------------------------------------------------------------------------------------------
def _rgb3(v, digits=3) -> str:
    if not isinstance(v, (list, tuple)) or not v:
        return "–"
    return ", ".join(_fmt(x, digits) for x in v[:3])


def _coat_text(coat) -> str:
    """The clear-coat lobe of a coated fit (``figures()["coat"]``): α, glTF clearcoat
    roughness √α, weight and F0; ``–`` without one."""
    if not isinstance(coat, dict) or _num(coat.get("alpha")) is None:
        return "–"
    a = _num(coat.get("alpha"))
    return (f"α {_fmt(a, 4)} (roughness {_fmt(math.sqrt(a), 4) if a >= 0 else '–'}), weight "
            f"{_fmt(coat.get('weight'), 3)}, F0 {_fmt(coat.get('f0'), 3)}")


def _params_table(models) -> str:
    """α (slope scale) and glTF roughness √α side by side, F0 and ρd per channel, bytes."""
    rows = []
    for m in models:
        f = (m.get("params") or {}).get("figures") if isinstance(m.get("params"), dict) else None
        if not isinstance(f, dict):
            continue
        a = f.get("alpha") if isinstance(f.get("alpha"), list) else None
        argb = f.get("alpha_rgb") if isinstance(f.get("alpha_rgb"), list) else None
        if a:
            alpha = f"αx {_fmt(a[0], 4)}, αy {_fmt(a[1], 4)}, ρ {_fmt(a[2], 3)}"
            rough = ", ".join(_fmt(math.sqrt(x), 4) if _num(x) is not None and x >= 0 else "–"
                              for x in a[:2])
        elif argb:
            alpha = "per channel " + _rgb3(argb, 4)
            rough = "–"
        else:
            alpha, rough = "–", "–"
        rows.append(f'<tr><td class="l">{_e(m.get("name"))}</td>'
                    f'<td class="l">{_e(f.get("alpha_kind") or "–")}</td>'
                    f'<td class="l">{_e(alpha)}</td><td>{_e(rough)}</td>'
                    f'<td>{_e(_rgb3(f.get("f0")))}</td><td>{_e(_rgb3(f.get("rho_d")))}</td>'
                    f'<td class="l">{_e(_coat_text(f.get("coat")))}</td>'
                    + _td(f.get("table_bytes"), 0)
                    + f'<td class="l">{_validity_badge(m, full=True) or "–"}</td></tr>')
    if not rows:
        return ""
    return ("<table class=\"sortable\" id=\"params\"><thead><tr><th class=\"l\">model</th>"
            "<th class=\"l\">distribution</th><th class=\"l\">α (slope scale)</th>"
            "<th>glTF roughness √α (x, y)</th><th>F0 (R, G, B)</th><th>ρd (R, G, B)</th>"
            "<th class=\"l\">coat</th><th>table bytes</th><th class=\"l\">physical checks</th></tr></thead><tbody>"
            + "".join(rows) + "</tbody></table>"
            '<p class="note">α: the slope-space scale of GGX/Beckmann (Mitsuba\'s alpha); glTF '
            "and MaterialX roughness = √α; F0: Fresnel reflectance at normal incidence (of the "
            "base lobe when there is a coat); coat: the second, white specular lobe of a "
            "coated fit (glTF KHR_materials_clearcoat, OpenPBR coat); ρd: "
            "Lambertian albedo (ρd/π); SGD: the shape α of Bagher 2012 Eq. 8 per channel. "
            "Physical checks: Fresnel ≤ 1 per channel, directional albedo ≤ 1 (white "
            "furnace, 1 % tolerance), no negative value, reciprocity "
            "(brdffit.evaluation.validity).</p>")


def _sparkline(hist: dict, width: int = 220, height: int = 60) -> str:
    """An inline SVG of a fit's history (log10 of the value against the iteration)."""
    it = [x for x in hist.get("iteration", []) if isinstance(x, (int, float))]
    val = [x for x in hist.get("value", []) if isinstance(x, (int, float))]
    pts = [(i, math.log10(v)) for i, v in zip(it, val) if v > 0 and math.isfinite(v)]
    if len(pts) < 2:
        return ""
    x0, x1 = pts[0][0], pts[-1][0]
    ys = [y for _, y in pts]
    y0, y1 = min(ys), max(ys)
    sx = (width - 8) / max(x1 - x0, 1)
    sy = (height - 8) / max(y1 - y0, 1e-12)
    poly = " ".join(f"{4 + (x - x0) * sx:.1f},{height - 4 - (y - y0) * sy:.1f}" for x, y in pts)
    label = (f"{hist.get('quantity', 'value')}: {val[0]:.3g} → {val[-1]:.3g} over "
             f"{it[-1]} iterations (log scale)")
    return (f'<svg width="{width}" height="{height}" role="img" aria-label="{_e(label)}">'
            f'<title>{_e(label)}</title><rect width="{width}" height="{height}" fill="#fff" '
            f'stroke="#ccc"/><polyline fill="none" stroke="#2060c0" stroke-width="1.5" '
            f'points="{poly}"/></svg>')


def _convergence_table(models) -> str:
    rows = []
    for m in models:
        c = m.get("convergence")
        if not isinstance(c, dict):
            continue
        conv = {True: "yes", False: "NO (cap reached)", None: "no criterion"}.get(
            c.get("converged"), "–")
        spark = _sparkline(c["history"]) if isinstance(c.get("history"), dict) else ""
        rows.append(f'<tr><td class="l">{_e(m.get("name"))}</td><td class="l">{_e(conv)}</td>'
                    + _td(c.get("nit"), 0) + _td(c.get("fun"), 4) + _td(c.get("time"), 2, unit=" s")
                    + f'<td class="l">{_e(c.get("message"))}</td>'
                    f'<td class="l">{spark or "closed form / no history"}</td></tr>')
    if not rows:
        return ""
    return ("<h2>Convergence</h2><table class=\"sortable\" id=\"convergence\"><thead><tr>"
            "<th class=\"l\">model</th><th class=\"l\">converged</th><th>iterations</th>"
            "<th>final objective</th><th>fit time</th><th class=\"l\">stop reason</th>"
            "<th class=\"l\">history</th></tr></thead><tbody>" + "".join(rows)
            + "</tbody></table><p class=\"note\">History: the objective per AWLS iteration "
            "(NPF; the starts, then the continuation of the best) or the relative change of "
            "the power iteration (tabulated), log scale.</p>")


def _files_list(m, mdir: Path) -> str:
    """Links to the files of one model: fit file, exports, EXR renderings (those that exist)."""
    files = []
    if m.get("fit_file"):
        files.append(m["fit_file"])
    files += [f for f in (m.get("exports") or []) if isinstance(f, str)]
    for sc in m.get("scenes") or []:
        if isinstance(sc, dict) and isinstance(sc.get("exr"), str):
            files.append(sc["exr"])
    links = []
    for f in files:
        u = _url(f)
        if u is not None and (mdir / f).is_file():
            links.append(f'<a href="{_e(u)}">{_e(Path(f).name)}</a>')
    return ", ".join(links)


def _parameter_sections(models, mdir: Path) -> list[str]:
    parts = []
    table = _params_table(models)
    if table:
        parts.append("<h2>Fitted parameters</h2>" + table)
    conv = _convergence_table(models)
    if conv:
        parts.append(conv)
    files = [(m, _files_list(m, mdir)) for m in models]
    if any(f for _, f in files):
        parts.append("<h2>Files</h2><ul>" + "".join(
            f"<li><b>{_e(m.get('name'))}</b>: {f}</li>" for m, f in files if f) + "</ul>"
            '<p class="note">Fit files load with <code>brdffit.load_fit</code> (or any '
            "<code>brdffit</code> command); <code>.gltf</code>/<code>.mtlx</code>: engine "
            "materials (glTF 2.0, MaterialX OpenPBR); <code>.json</code>: every parameter.</p>")
    raw = []
    for m in models:
        p, info = m.get("params"), m.get("fit_info")
        if p or info:
            raw.append(f"<details><summary>{_e(m.get('name'))}: all parameters and the fit "
                       "report (JSON)</summary><pre>"
                       + _e(json.dumps({"params": p, "fit_info": info}, indent=1,
                                       ensure_ascii=False, default=json_default)[:20000])
                       + "</pre></details>")
    if raw:
        parts.append("<h3>Full parameters</h3>" + "".join(raw))
    return parts


def _cell(src, alt, disp, caption) -> str:
    return f'<div class="cell">{_img(src, alt, width=disp)}{caption}</div>'


def _fail_cell(m, disp, error=None) -> str:
    return (f'<div class="cell fail" style="width:{disp}px"><b>{_e(m.get("name"))}</b><br>'
            f"{_e(m.get('status', 'failed') if error is None else 'failed')}: "
            f"{_e(error if error is not None else m.get('error', 'no image'))}</div>")


def _scene_sections(scenes, models, disp, colorbar) -> list[str]:
    """Per scene: the reference and every model (PSNR ± se), then the dE2000 maps."""
    parts = []
    for sc in scenes:
        name = str(sc.get("name"))
        ref = sc.get("reference") if isinstance(sc.get("reference"), dict) else {}
        head = (f"<h2>Scene {_e(name)}</h2><p class=\"note\">"
                + _e("; ".join(str(x) for x in (sc.get("note"), f"map {sc.get('envmap')}"
                                                if sc.get("envmap") else None,
                                                f"peak {_fmt(ref.get('peak'), 4)}"
                                                if ref.get("peak") is not None else None) if x))
                + "</p>")
        if sc.get("error"):
            parts.append(head + f'<p class="fail">not rendered: {_e(sc.get("error"))}</p>')
            continue
        cells = []
        if ref.get("png"):
            cells.append(_cell(ref["png"], f"reference rendering, {name}", disp,
                               "<b>Reference</b><br>&nbsp;"))
        de_cells = []
        for m in models:
            e = _model_scene(m, name)
            if _ok(m) and e.get("png"):
                cells.append(_cell(e["png"], f"{m.get('name')} rendering, {name}", disp,
                                   f"<b>{_e(m.get('name'))}</b><br>PSNR "
                                   f"{_e(_pm(e.get('psnr'), e.get('psnr_se'), e.get('bound')))} dB"))
                if e.get("de_png"):
                    de_cells.append(_cell(e["de_png"], f"{m.get('name')} dE2000 map, {name}", disp,
                                          f"<b>{_e(m.get('name'))}</b><br>mean dE "
                                          f"{_e(_fmt(e.get('mean_de2000')))}"))
            else:
                cells.append(_fail_cell(m, disp, e.get("error") if _ok(m) else None))
        parts.append(head + '<div class="grid">' + "".join(cells) + "</div>")
        if de_cells:
            if colorbar:
                de_cells.append(f'<div class="cell">{_img(colorbar, "dE2000 colour scale")}</div>')
            parts.append(f"<h3>CIE dE2000 difference to the reference, {_e(name)}</h3>"
                         '<div class="grid">' + "".join(de_cells) + "</div>")
    return parts


def _single_scene_sections(ref, models, disp, colorbar) -> list[str]:
    """Results of versions without a scene suite: one rendering per model."""
    parts = []
    cells = []
    if ref.get("png"):
        cells.append(_cell(ref["png"], "reference rendering", disp, "<b>Reference</b><br>&nbsp;"))
    for m in models:
        if _ok(m) and m.get("png"):
            cells.append(_cell(m["png"], str(m.get("name")) + " rendering", disp,
                               f"<b>{_e(m.get('name'))}</b><br>PSNR "
                               f"{_e(_pm(m.get('psnr'), m.get('psnr_se')))} dB"))
        else:
            cells.append(_fail_cell(m, disp))
    parts.append('<h2>Renderings</h2><div class="grid">' + "".join(cells) + "</div>")
    cells = []
    for m in models:
        if _ok(m) and m.get("de_png"):
            cells.append(_cell(m["de_png"], str(m.get("name")) + " dE2000 map", disp,
                               f"<b>{_e(m.get('name'))}</b><br>mean dE {_e(_fmt(m.get('mean_de2000')))}"))
    if cells:
        if colorbar:
            cells.append(f'<div class="cell">{_img(colorbar, "dE2000 colour scale")}</div>')
        parts.append('<h2>CIE dE2000 difference to the reference</h2><div class="grid">'
                     + "".join(cells) + "</div>")
    return parts


def _error_regions_section(models) -> str:
    """Where the most faithful fit's BRDF-space error lies, region by region, and what that
    says is missing (:func:`brdffit.evaluation.metrics.error_regions`); '' without data."""
    cands = [m for m in models if _ok(m) and isinstance(m.get("brdf"), dict)
             and isinstance(m["brdf"].get("error_regions"), dict)
             and _num(m["brdf"].get("cos_rel_error")) is not None]
    if not cands:
        return ""
    m = min(cands, key=lambda c: c["brdf"]["cos_rel_error"])
    reg = m["brdf"]["error_regions"]
    rows = "".join(
        f'<tr><td class="l">{_e(name)}</td>' + _td(100 * _num(v.get("error_share")), 1, unit=" %")
        + _td(100 * _num(v.get("energy_share")), 1, unit=" %")
        + _td(v.get("fit_over_measured"), 2, unit="×") + "</tr>"
        for name, v in (reg.get("regions") or {}).items() if isinstance(v, dict)
        and _num(v.get("error_share")) is not None and _num(v.get("energy_share")) is not None)
    findings = [f for f in (reg.get("findings") or []) if isinstance(f, str)]
    return (f"<h2>Where the error lies: {_e(m.get('name'))} "
            f"({_e(_fmt(100 * m['brdf']['cos_rel_error'], 1))} %, the most faithful fit)</h2>"
            '<table><thead><tr><th class="l">region</th><th>share of the error</th>'
            "<th>share of the reflected energy</th><th>fit / measured</th></tr></thead><tbody>"
            + rows + "</tbody></table>"
            + ("<ul>" + "".join(f"<li>{_e(f)}</li>" for f in findings) + "</ul>"
               if findings else '<p class="note">No region stands out.</p>')
            + '<p class="note">Cosine-weighted pairs of the measured domain; regions: specular '
            "peak θh &lt; 8°, retro-reflection θd &lt; 10°, grazing θi or θo &gt; 70°, the body "
            "elsewhere (each pair in the first that holds it). A heuristic reading of the "
            "residual, not a fit of the missing component.</p>")


def _metrics_table(models, scenes, best) -> str:
    names = [str(sc.get("name")) for sc in scenes]
    rows = []
    ncol = 7 + len(names)
    for m in models:
        b = m.get("brdf") if isinstance(m.get("brdf"), dict) else {}
        cls = "best" if best is not None and _num(m.get("psnr")) == best else ""
        if not _ok(m):
            rows.append(f'<tr class="fail"><td class="l">{_e(m.get("name"))}</td>'
                        f'<td class="l" colspan="{ncol}">{_e(m.get("status", "failed"))}: '
                        f'{_e(m.get("error"))}</td></tr>')
            continue
        rows.append(f'<tr class="{cls}"><td class="l">{_e(m.get("name"))}</td>'
                    + _td_pm(m) + "".join(_td_pm(_model_scene(m, n)) for n in names)
                    + _td(m.get("mean_de2000"))
                    + _td(b.get("cos_rel_error"), 4) + _td(b.get("normalized_l2"), 4)
                    + _td(b.get("compressive_objective"), 4)
                    + _td(m.get("fit_time"), 2, unit=" s") + _td(m.get("table_bytes"), 0) + "</tr>")
    scene_heads = "".join(f"<th>{_e(n)} PSNR</th>" for n in names)
    return ("<h2>Metrics</h2><table class=\"sortable\" id=\"metrics\"><thead><tr>"
            "<th class=\"l\">model</th><th>PSNR (dB)"
            + (", mean over scenes" if names else "") + "</th>" + scene_heads
            + "<th>mean dE2000</th><th>cos-weighted rel. error</th><th>normalised L2</th>"
            "<th>compressive objective</th><th>fit time</th><th>table bytes</th></tr></thead><tbody>"
            + "".join(rows) + "</tbody></table>"
            '<p class="note">PSNR: linear values, foreground pixels, peak = max RGB component of '
            "the (converged) reference foreground (Bagher et al. 2016 §5); ± one standard error "
            "(batches rendered with common random numbers: U-statistic MSE, jackknife, delta "
            "method; it includes the reference peak's residual uncertainty); ≥ = a lower bound "
            "when the difference is below its own noise. dE2000 on the tone-mapped images read "
            "as sRGB (D65), mean over scenes. Cosine-weighted relative error: "
            "Σ∫∫|f−f<sub>ref</sub>| cosθ<sub>i</sub> cosθ<sub>o</sub> / Σ∫∫|f<sub>ref</sub>| "
            "cosθ<sub>i</sub> cosθ<sub>o</sub>. Normalised L2: Bagher et al. 2012 §6.3. "
            "Compressive objective: Bagher et al. 2016 Eq. 7–12 divided by that of the all-zero "
            "model. – = not available.</p>")


# ------------------------------------------------------------------------------------------
# index
# ------------------------------------------------------------------------------------------
#: a tie is a PSNR difference within this many combined standard errors (≈ 95 %)
TIE_Z = 2.0


def _tied_with_best(models: list[dict], tie_db: float = 2.0) -> set:
    """Names of the models whose PSNR is the best or tied with it, by the rule of the wins /
    ties table (:func:`.metrics.count_wins` with ``TIE_Z``: within ``TIE_Z`` combined
    standard errors, ``tie_db`` without them)."""
    scored = {m.get("name"): (_num(m.get("psnr")), _num(m.get("psnr_se"))) for m in models
              if _num(m.get("psnr")) is not None}
    if not scored:
        return set()
    top = max(scored, key=lambda n: scored[n][0])
    wins = count_wins({n: [p] for n, (p, _) in scored.items()}, tie_db,
                      se={n: [math.nan if se is None else se] for n, (_, se) in scored.items()},
                      z=TIE_Z)
    return {top} | {n for n in scored if n != top and wins[top][n]["ties"]}


def _link(slug: str, rel, text: str) -> str:
    """A link to a file of the material's folder (``text`` when the path is not safe)."""
    if isinstance(rel, str) and _url(rel) is not None and _url(slug) is not None:
        return f'<a href="{_e(_url(slug))}/{_e(_url(rel))}">{_e(text)}</a>'
    return _e(text)


def _use_cell(slug: str, models: list[dict], tied: set) -> str:
    """Which file to use, per material: the **engine** file (the glTF of the best-rendered
    model that has one, with its checks), the **most faithful** fit (highest PSNR; every
    model tied with it named) and the **smallest** fit among those tied with the best (its
    fit-file table bytes; the smallest overall when none is tied), with sizes and fit
    times."""
    ok = [m for m in models if _ok(m)]
    if not ok:
        return "–"
    scored = sorted((m for m in ok if _num(m.get("psnr")) is not None),
                    key=lambda m: -_num(m.get("psnr")))
    lines = []

    def facts(m) -> str:
        bits = []
        size = _num(m.get("table_bytes"))
        if size is not None:
            bits.append(f"{int(size):,} B of tables" if size else "parameters only")
        if _num(m.get("fit_time")) is not None:
            bits.append(f"fit {_fmt(m.get('fit_time'), 2)} s")
        return f" ({', '.join(bits)})" if bits else ""

    engine = next((m for m in scored + ok if any(
        isinstance(x, str) and x.endswith(".gltf") for x in (m.get("exports") or []))), None)
    if engine is not None:
        gltf = next(x for x in engine["exports"] if str(x).endswith(".gltf"))
        valid = "" if not engine.get("validity") else " ⚠"
        lines.append(f"engine: {_link(slug, gltf, str(engine.get('name')) + ' (glTF)')}{valid}")
    if scored:
        best = scored[0]
        others = sorted(n for n in tied if n != best.get("name"))
        lines.append(f"most faithful: {_link(slug, best.get('fit_file'), str(best.get('name')))}"
                     + _e(facts(best)) + (f" – tied with {_e(', '.join(others))}" if others
                                          else ""))
    pool = [m for m in ok if m.get("name") in tied] or ok
    sized = [m for m in pool if _num(m.get("table_bytes")) is not None]
    if sized:
        small = min(sized, key=lambda m: (_num(m["table_bytes"]), -(_num(m.get("psnr")) or 0)))
        lines.append(f"smallest{' of those' if tied else ''}: "
                     f"{_link(slug, small.get('fit_file'), str(small.get('name')))}"
                     + _e(facts(small)))
    return "<br>".join(lines)


def summarize(results: Iterable[dict], tie_db: float = 2.0) -> dict:
    """Per-model mean/median PSNR and dE2000 and pairwise wins/ties over materials, and the
    median standard error of the models' PSNR (results with ``psnr_se``).

    Two models tie on a material when their PSNRs differ by at most ``TIE_Z`` combined
    standard errors (``2·sqrt(se_a² + se_b²)``, the measured noise of that comparison), or by
    at most ``tie_db`` when a standard error is missing (results of older versions).

    Returns ``{"models": [...], "per_model": {name: {...}}, "wins": count_wins(...)}``.
    Materials where a model failed count as missing (NaN) for that model.
    """
    results = list(results)
    names: list[str] = []
    for r in results:
        for m in _models(r):
            if m.get("name") not in names:
                names.append(m.get("name"))
    psnr = {n: np.full(len(results), np.nan) for n in names}
    de = {n: np.full(len(results), np.nan) for n in names}
    se = {n: np.full(len(results), np.nan) for n in names}
    cre = {n: np.full(len(results), np.nan) for n in names}
    for i, r in enumerate(results):
        for m in _models(r):
            if _ok(m):
                p, d, e = _num(m.get("psnr")), _num(m.get("mean_de2000")), _num(m.get("psnr_se"))
                psnr[m["name"]][i] = np.nan if p is None else p
                de[m["name"]][i] = np.nan if d is None else d
                se[m["name"]][i] = np.nan if e is None else e
                b = m.get("brdf") if isinstance(m.get("brdf"), dict) else {}
                c = _num(b.get("cos_rel_error"))
                cre[m["name"]][i] = np.nan if c is None else c
    per = {}
    for n in names:
        p, d = psnr[n], de[n]
        pf = p[~np.isnan(p)]  # +inf (an exact match) is kept: the mean is then +inf
        df = d[np.isfinite(d)]
        ef = se[n][np.isfinite(se[n]) & np.isfinite(p)]
        per[n] = {"n": int(pf.size),
                  "mean_psnr": float(np.mean(pf)) if pf.size else None,
                  "median_psnr": float(np.median(pf)) if pf.size else None,
                  "mean_de2000": float(np.mean(df)) if df.size else None,
                  "median_de2000": float(np.median(df)) if df.size else None,
                  "median_psnr_se": float(np.median(ef)) if ef.size else None,
                  "mean_cos_rel_error": (float(np.nanmean(cre[n]))
                                         if np.isfinite(cre[n]).any() else None)}
    wins = count_wins(psnr, tie_db, se=se, z=TIE_Z) if names else {}
    return {"models": names, "per_model": per, "wins": wins,
            "n_materials": len(results), "tie_db": tie_db, "tie_z": TIE_Z}


def write_index(out_dir, title: str = "brdffit comparison report") -> Path:
    """(Re)build ``OUT/index.html`` from every material result found under ``OUT``."""
    out_dir = Path(out_dir)
    results = read_results(out_dir)
    summ = summarize(results)
    names = summ["models"]
    parts = [f"<h1>{_e(title)}</h1>",
             f'<p class="note">{len(results)} material(s). Click a column header to sort. '
             "PSNR (Bagher et al. 2016 §5) in dB, higher is better (± its standard error, "
             "when the comparison measured it); dE2000 (mean over the foreground), lower is "
             "better.</p>"]
    batch_links = [f'<a href="../{f}">{f}</a>' for f in ("summary.csv", "summary.json")
                   if (out_dir.parent / f).is_file()]
    recommended = _batch_recommendations(out_dir.parent / "summary.json")
    if batch_links:
        parts.append('<p class="note">Batch tables (one row per material and model: α, glTF '
                     "roughness, F0, ρd, errors, PSNR ± se, fit time, fit file): "
                     + ", ".join(batch_links) + ".</p>")
    parts.append(_per_model_table(summ))
    if len(names) > 1:
        parts.append(_wins_table(summ))
    parts.append(_materials_table(results, names, recommended))
    path = out_dir / "index.html"
    with atomic_write(path, "w") as fh:
        fh.write(_page(title, "\n".join(parts)))
    summ_path = out_dir / "summary.json"
    with atomic_write(summ_path, "w") as fh:
        json.dump(standard_json(summ), fh, indent=1, default=json_default, allow_nan=False)
    return path


def _per_model_table(summ: dict) -> str:
    """The index's per-model table of :func:`summarize`'s ``per_model`` figures."""
    rows = []
    for n in summ["models"]:
        s = summ["per_model"][n]
        rows.append(f'<tr><td class="l">{_e(n)}</td>' + _td(s["n"], 0) + _td(s["mean_psnr"])
                    + _td(s["median_psnr"]) + _td(s.get("median_psnr_se"), 3)
                    + _td(s["mean_de2000"]) + _td(s["median_de2000"])
                    + _td(s.get("mean_cos_rel_error"), 4) + "</tr>")
    return ("<h2>Per model</h2><table class=\"sortable\" id=\"summary\"><thead><tr>"
            "<th class=\"l\">model</th><th>materials</th><th>mean PSNR</th>"
            "<th>median PSNR</th><th>median standard error</th>"
            "<th>mean dE2000</th><th>median dE2000</th>"
            "<th>mean cos-weighted rel. error (BRDF space)</th></tr></thead>"
            "<tbody>" + "".join(rows) + "</tbody></table>")


def _wins_table(summ: dict) -> str:
    """The index's wins / ties / losses matrix (row model vs column model)."""
    names = summ["models"]
    head = "".join(f"<th>{_e(b)}</th>" for b in names)
    rows = []
    for a in names:
        cells = []
        for b in names:
            if a == b:
                cells.append("<td>–</td>")
                continue
            w = summ["wins"][a][b]
            cells.append(f'<td data-sort="{w["wins"]}">{w["wins"]} / {w["ties"]} / '
                         f'{w["losses"]}</td>')
        rows.append(f'<tr><td class="l">{_e(a)}</td>{"".join(cells)}</tr>')
    return ("<h2>Wins / ties / losses (row vs column; tie = PSNRs within "
            f"{summ['tie_z']:g}·√(se<sub>a</sub>² + se<sub>b</sub>²), their measured "
            f"standard errors, or {summ['tie_db']:g} dB where one is missing)</h2>"
            "<table class=\"sortable\" id=\"wins\"><thead>"
            f"<tr><th class=\"l\">model</th>{head}</tr></thead><tbody>"
            + "".join(rows) + "</tbody></table>")


def _materials_table(results: list[dict], names: list, recommended: dict) -> str:
    """The index's table of materials: reference thumbnail, link to the material's page,
    PSNR ± se and dE per model, the batch's recommended model (when known) and which file
    to use. Results of older versions may carry a noise floor instead of errors: it gets a
    column when any result has one."""
    legacy_floor = any(_num(r.get("noise_floor_psnr")) is not None for r in results)
    head = "".join(f"<th>{_e(n)} PSNR</th><th>{_e(n)} dE</th>" for n in names)
    rows = [_material_row(r, names, legacy_floor, recommended) for r in results]
    return ("<h2>Materials</h2>"
            '<p><label>Filter: <input id="filter" type="search" placeholder="material '
            'name"></label></p>'
            "<table class=\"sortable\" id=\"materials\"><thead><tr>"
            "<th class=\"l\">reference</th><th class=\"l\">material</th>"
            + ("<th>noise floor PSNR (old results)</th>" if legacy_floor else "")
            + ("<th class=\"l\">recommended model</th>" if recommended else "")
            + head + "<th class=\"l\">which file to use</th></tr></thead><tbody>" + "".join(rows) + "</tbody></table>"
            '<p class="note">Which file to use: <b>engine</b>, the glTF material of the '
            "best-rendered fit that has one (⚠: it failed a physical check, see its "
            "page); <b>most faithful</b>, the fit with the highest PSNR; <b>smallest</b>, the "
            "fit with the fewest table bytes among those tied with the best (a tie: PSNRs "
            f"within {TIE_Z:g} combined standard errors, or 2 dB without them).</p>")


def _material_row(r: dict, names: list, legacy_floor: bool, recommended: dict) -> str:
    """One row of :func:`_materials_table` (result ``r``)."""
    slug = r["slug"]
    ref = r.get("reference") or {}
    thumb = (_img(slug + "/" + ref["png"], str(r.get("material", slug)) + " reference", cls="thumb")
             if isinstance(ref.get("png"), str) and _url(ref["png"]) is not None else "")
    by = {m.get("name"): m for m in _models(r)}
    tied = _tied_with_best([m for m in by.values() if _ok(m)])
    cells = []
    for n in names:
        m = by.get(n)
        if m is None or not _ok(m):
            cells.append('<td class="fail" data-sort="">' + (_e(m.get("status", "failed")) if m else "–") + "</td><td></td>")
            continue
        cls = "best" if n in tied else ""
        badge = _validity_badge(m) + "<br>" if m.get("validity") else ""  # failed checks
        if n in tied and len(tied) > 1:
            badge += f'<span class="badge ok" title="within {TIE_Z:g} standard errors of ' \
                     f'the best (or 2 dB without them)">tie</span><br>'
        cells.append(_td_pm(m, cls=cls, thumb=_thumb(slug, m, r) + badge)
                     + _td(m.get("mean_de2000")))
    return (f'<tr><td class="l">{thumb}</td><td class="l" data-sort="{_e(str(r.get("material", slug)).lower())}">'
            + (f'<a href="{_e(_url(slug))}/index.html">{_e(r.get("material", slug))}</a></td>'
               if _url(slug) else f'{_e(r.get("material", slug))}</td>')
            + (_td(r.get("noise_floor_psnr")) if legacy_floor else "")
            + (f'<td class="l">{_e(recommended.get(str(r.get("material")), "–"))}</td>'
               if recommended else "")
            + "".join(cells)
            + f'<td class="l use">{_use_cell(slug, list(by.values()), tied)}</td></tr>')


# ------------------------------------------------------------------------------------------
# link checking (used by the tests and the bench)
# ------------------------------------------------------------------------------------------
_LINK_RE = re.compile(r"""(?:src|href)\s*=\s*["']([^"'#]+)""", re.IGNORECASE)


def local_links(html_path) -> list[str]:
    """Every relative ``src``/``href`` of a page, HTML- and URL-decoded (external schemes are
    reported as is)."""
    from urllib.parse import unquote

    text = Path(html_path).read_text(encoding="utf-8")
    return [unquote(html.unescape(u)) for u in _LINK_RE.findall(text)]


def missing_links(html_path) -> list[str]:
    """Relative links of a page that do not resolve to an existing file, plus any absolute or
    remote link (a report must not have either)."""
    html_path = Path(html_path)
    bad = []
    for u in local_links(html_path):
        if re.match(r"^[a-z][a-z0-9+.-]*:", u, re.I) or u.startswith("/"):
            bad.append(u)
            continue
        if not (html_path.parent / u).is_file():
            bad.append(u)
    return bad
