"""Open the HTML report in headless Chromium and check that every image loaded.

The report pages record, on their <html> element after the load event, how many <img> they
have and how many did not load (``img.complete && img.naturalWidth > 0``); Chromium's
``--dump-dom`` gives us the DOM after the scripts ran.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

from brdffit.evaluation import compare as C
from tests.evaluation.test_metrics import Lambert, Phongish
from tests.evaluation.test_plots import FakeMicrofacet, FakeNPF
from tests.evaluation.test_report import _ref, standin_render

CHROMIUM = Path("/usr/bin/chromium")
pytestmark = pytest.mark.skipif(not CHROMIUM.exists(),
                                reason="needs Debian 'chromium' at /usr/bin/chromium "
                                       "(installed by `make sysdeps` as root)")


def chromium_args(profile: Path) -> list[str]:
    return [str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
            "--no-first-run", "--disable-background-networking", "--disable-component-update",
            "--disable-sync", "--disable-extensions", f"--user-data-dir={profile}",
            "--virtual-time-budget=5000"]


def dump_dom(page: Path, profile: Path) -> str:
    proc = subprocess.run(chromium_args(profile) + ["--dump-dom", page.resolve().as_uri()],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout


def image_status(dom: str) -> tuple[int, int, str]:
    m = re.search(r'<html[^>]*data-images-total="(\d+)"[^>]*data-images-broken="(\d+)"'
                  r'[^>]*data-images-broken-list="([^"]*)"', dom)
    assert m, "the page's load script did not run (no data-images-* attributes on <html>)"
    return int(m.group(1)), int(m.group(2)), m.group(3)


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("chromium_report")
    models = {"lambert": Lambert([0.3, 0.25, 0.2]), "microfacet": FakeMicrofacet(),
              "npf": FakeNPF(), "exact": Phongish(30)}
    res = C.compare(_ref(), models, out, renderer=standin_render, spp=8, resolution=32,
                    brdf_metric_samples=1 << 10)
    return out, res


def test_every_image_loads_in_chromium(report, tmp_path):
    out, res = report
    for page, min_images in ((out / "index.html", 1), (out / res["slug"] / "index.html", 12)):
        total, broken, lst = image_status(dump_dom(page, tmp_path / "profile"))
        assert broken == 0, f"{page}: images not loaded: {lst}"
        assert total >= min_images, f"{page}: expected >= {min_images} images, found {total}"


def test_chromium_detects_a_broken_image(report, tmp_path):
    """The check itself can fail: remove one image and it must be reported."""
    out, res = report
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    png = next(m for m in res["models"] if m["name"] == "lambert")["scenes"][0]["png"]
    (copy / res["slug"] / png).unlink()
    total, broken, lst = image_status(dump_dom(copy / res["slug"] / "index.html",
                                               tmp_path / "profile"))
    assert broken == 1 and png in lst


def test_index_table_sorts_on_click(tmp_path):
    """Click the PSNR header of the per-model table twice (descending) in Chromium."""
    from brdffit.evaluation import report as R

    out = tmp_path / "rep"
    for k, (name, alb) in enumerate((("bright", 0.8), ("mid", 0.5), ("dark", 0.2))):
        ref = Lambert([alb] * 3)
        ref.name = name
        C.compare(ref, {"a": Lambert([alb * 0.9] * 3), "b": Lambert([alb * (0.5 + 0.2 * k)] * 3)},
                  out, renderer=standin_render, spp=4, resolution=16, noise_floor=False,
                  brdf_metric_samples=1 << 8, brdf_metrics=("cos_rel_error",))
    text = (out / "index.html").read_text()
    # a copy of the index in the same folder with one extra script clicking the header
    click = ("<script>window.addEventListener('load',function(){var th=document.querySelectorAll("
             "'#materials thead th')[4];th.click();th.click();document.documentElement"
             ".setAttribute('data-order',Array.prototype.map.call(document.querySelectorAll("
             "'#materials tbody tr'),function(r){return r.cells[1].textContent.trim();}).join(','))"
             "});</script></body>")
    (out / "_click.html").write_text(text.replace("</body>", click))
    dom = dump_dom(out / "_click.html", tmp_path / "profile")
    m = re.search(r'data-order="([^"]*)"', dom)
    assert m, "click script did not run"
    order = m.group(1).split(",")
    summ = R.read_results(out)
    psnr_b = {r["material"]: [x for x in r["models"] if x["name"] == "b"][0]["psnr"] for r in summ}
    assert order == sorted(psnr_b, key=lambda n: -float(psnr_b[n]))
    assert order != sorted(psnr_b)  # the sort changed the (alphabetical) initial order
