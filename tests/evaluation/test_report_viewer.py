"""The report's live viewer without a browser: the page's parts, escaping, the map sent to
three.js, the bundle (committed, reproducible, copied once per report).

The browser test is test_report_viewer_chromium.py.
"""

from __future__ import annotations

import html
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from brdffit.evaluation import report as R
from brdffit.evaluation import report_viewer as V

ROOT = Path(__file__).resolve().parents[2]
HOSTILE = 'a</script><script>alert(1)</script><!-- & "q" \u2028 <img src=x onerror=alert(2)>'


def _material_doc():
    return {"asset": {"version": "2.0"},
            "materials": [{"name": HOSTILE, "pbrMetallicRoughness": {
                "baseColorFactor": [0.5, 0.1, 0.1, 1.0], "metallicFactor": 0.0,
                "roughnessFactor": 0.4}}],
            "meshes": [{"primitives": []}], "buffers": [{"byteLength": 4, "uri": "x.bin"}]}


def _result(out: Path, name: str = HOSTILE, gltf: bool = True, base: str = "sphere-env",
            slug: str = "mat") -> dict:
    mdir = out / slug
    (mdir / "exports").mkdir(parents=True, exist_ok=True)
    (mdir / "exports" / "m.gltf").write_text(json.dumps(_material_doc()))
    (mdir / "ref.png").write_bytes(b"")
    return {"material": slug, "slug": slug, "scene": {"resolution": 96},
            "scenes": [{"name": "sphere-env", "base": base, "envmap": None, "exposure": 0.5,
                        "gamma": 2.2, "reference": {"png": "ref.png"}}],
            "models": [{"name": name, "status": "ok",
                        "exports": ["exports/m.gltf"] if gltf else []},
                       {"name": "outside", "status": "ok", "exports": ["../../etc.gltf"]}]}


def _data(page: str) -> dict:
    m = re.search(r'<script type="application/json" id="brdffit-viewer-data">(.*?)</script>',
                  page, re.S)
    assert m
    return json.loads(m.group(1))


def test_hostile_names_stay_data(tmp_path):
    page = R.write_material_page(tmp_path, _result(tmp_path)).read_text()
    # the JSON element is the only place the viewer reads; nothing in it can end it
    m = re.search(r'id="brdffit-viewer-data">(.*?)</script>', page, re.S)
    assert not re.search(r"[<>&]", m.group(1))
    data = _data(page)
    assert [d["name"] for d in data["models"]] == [HOSTILE]      # the file outside is skipped
    assert data["models"][0]["gltf"]["materials"][0]["name"] == HOSTILE
    assert "<script>alert" not in page and "<img src=x" not in page
    # the preview mesh and its external buffer are left out: the viewer has its own sphere
    assert set(data["models"][0]["gltf"]) == {"asset", "materials"}
    assert R.missing_links(tmp_path / "mat" / "index.html") == ["../index.html"]  # not written


def test_section_settings_and_bundle_copied_once(tmp_path):
    for slug in ("mat", "mat2"):
        page = R.write_material_page(tmp_path, _result(tmp_path, slug=slug)).read_text()
        assert '<script src="../assets/three-viewer.js"></script>' in page
        assert 'data-brdffit-viewer="brdffit-viewer-data"' in page
        assert "needs JavaScript and WebGL" in page       # what shows with JavaScript off
        assert page.count('src="ref.png"') == 2           # the reference stays an image
    assets = sorted(p.name for p in tmp_path.rglob("*.js"))
    assert assets == ["three-viewer.js"]
    assert (tmp_path / V.ASSET).read_bytes() == V.BUNDLE.read_bytes()
    data = _data(page)
    assert data["exposure"] == 0.5 and data["gamma"] == 2.2 and data["size"] == 96
    assert data["camera"] == {"origin": [0.0, 0.0, 4.2], "target": [0.0, 0.0, 0.0],
                              "up": [0.0, 1.0, 0.0], "fov": 30.0}
    env = data["environment"]
    assert (env["width"], env["height"]) == (V.ENV_WIDTH, V.ENV_WIDTH // 2)


@pytest.mark.parametrize("case", ["no-gltf", "no-env-scene"])
def test_no_section_without_export_or_env_scene(tmp_path, case):
    res = _result(tmp_path, gltf=case != "no-gltf",
                  base="sphere-distant" if case == "no-env-scene" else "sphere-env")
    page = R.write_material_page(tmp_path, res).read_text()
    assert "brdffit-viewer" not in page and not (tmp_path / V.ASSET).exists()


def test_missing_bundle_says_so_in_one_line(tmp_path, monkeypatch):
    monkeypatch.setattr(V, "_bundle_bytes", lambda: None)
    page = R.write_material_page(tmp_path, _result(tmp_path)).read_text()
    lines = [ln for ln in page.splitlines() if "Live viewer not available" in ln]
    assert len(lines) == 1 and "<canvas" not in page and "three-viewer.js" not in page


def test_environment_keeps_the_power_and_turns_to_three(tmp_path):
    from brdffit.evaluation.render.scenes import load_envmap

    full, small = load_envmap(None).astype(np.float64), V.environment_image(None, 64)
    assert small.shape == (32, 64, 3)

    def power(img):      # ∫ L dω over the sphere, per channel
        h = img.shape[0]
        w = np.sin((np.arange(h) + 0.5) / h * np.pi)[:, None, None]
        return (img * w).sum((0, 1)) / w.sum() / img.shape[1]

    assert np.allclose(power(small), power(full), rtol=1e-6)
    # three: v = 0 at the nadir, u = atan2(z, x)/2π + 1/2; Mitsuba: row 0 at the zenith,
    # u = atan2(x, -z)/2π. The direction +x is Mitsuba's column w/4 and three's column w/2.
    img = np.zeros((4, 8, 3), np.float32)
    img[0, 2] = 1.0                                  # near the zenith, towards +x
    t = V.three_equirect(img)
    assert t[3, 4].tolist() == [1.0, 1.0, 1.0] and t.sum() == 3.0
    raw = np.frombuffer(__import__("base64").b64decode(
        V.environment_data(None, 64)["rgb_f16"]), "<f2").reshape(32, 64, 3)
    assert np.allclose(raw, V.three_equirect(small), rtol=1e-3)


def test_bundle_is_committed_with_its_versions_and_licence():
    text = V.BUNDLE.read_text(encoding="utf-8")
    make = (ROOT / "Makefile").read_text()
    three = re.search(r"^THREE_VERSION := (\S+)", make, re.M).group(1)
    esbuild = re.search(r"^ESBUILD_VERSION := (\S+)", make, re.M).group(1)
    assert text.startswith(f"/* brdffit report viewer: viewer.js + three {three} ")
    assert f"esbuild {esbuild}" in text.splitlines()[0]
    assert "SPDX-License-Identifier: MIT" in text and "Three.js Authors" in text
    assert not re.search(r"^\s*(import|export)\s", text, re.M)     # a classic script


def test_bundle_rebuilds_identically(tmp_path):
    npm = ROOT / ".npm" / "node_modules"
    make = (ROOT / "Makefile").read_text()
    pins = {n: re.search(rf"^{n.upper()}_VERSION := (\S+)", make, re.M).group(1)
            for n in ("three", "esbuild")}
    for name, version in pins.items():
        pkg = npm / name / "package.json"
        if not pkg.is_file() or json.loads(pkg.read_text())["version"] != version:
            pytest.skip(f"needs {name}@{version} in .npm (make npmdeps)")
    out = tmp_path / "bundle.js"
    subprocess.run([sys.executable, str(ROOT / "tools" / "build_viewer_bundle.py"), "--out",
                    str(out)], check=True, capture_output=True, timeout=120)
    assert out.read_bytes() == V.BUNDLE.read_bytes(), \
        "viewer.bundle.js is stale: run python tools/build_viewer_bundle.py"


def test_json_script_escapes():
    s = V.json_script({"n": "</script><!--&"}, 'x"y')
    assert s.startswith('<script type="application/json" id="x&quot;y">')
    body = s[s.index(">") + 1:-len("</script>")]
    assert json.loads(body) == {"n": "</script><!--&"} and not re.search(r"[<>&]", body)
    assert html.unescape(s).count("</script>") == 1
