"""The HTML report with hostile names and links (issue 12, item 1): material and model names
are escaped everywhere (text and attributes), every link is a URL-quoted relative path inside
the report, and links that are not (``javascript:``, ``data:``, absolute or remote) are
dropped. Pages are checked with ``html.parser``, as a browser would tokenise them."""

from __future__ import annotations

from html.parser import HTMLParser

import pytest

from brdffit.evaluation import compare as C
from brdffit.evaluation import report as R
from tests.evaluation.test_metrics import Lambert, Phongish
from tests.evaluation.test_report import standin_render

HOSTILE = "<img src=x onerror=alert(1)>\"'&金 </script><script>alert(2)</script> ]]> {{x}} \\"
MODEL = "m<b onmouseover=alert(3)>\"'"

#: tags the report itself writes
ALLOWED = {"html", "head", "meta", "title", "style", "body", "p", "a", "h1", "h2", "h3", "div",
           "img", "b", "br", "table", "thead", "tbody", "tr", "th", "td", "code", "pre", "ul",
           "li", "script", "sub", "span", "details", "summary", "svg", "title", "rect",
           "polyline", "label", "input"}


class Page(HTMLParser):
    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.tags: list[tuple[str, dict]] = []
        self.text: list[str] = []
        self._in = []

    def handle_starttag(self, tag, attrs):
        self.tags.append((tag, dict(attrs)))

    def handle_startendtag(self, tag, attrs):
        self.tags.append((tag, dict(attrs)))

    def handle_data(self, data):
        self.text.append(data)


def parse(path) -> Page:
    p = Page()
    p.feed(path.read_text(encoding="utf-8"))
    p.close()
    return p


def assert_nothing_injected(page: Page):
    for tag, attrs in page.tags:
        assert tag in ALLOWED, f"unexpected tag <{tag}> {attrs}"
        for k, v in attrs.items():
            assert not k.startswith("on"), f"event handler attribute {k}={v!r} on <{tag}>"
            if k in ("href", "src"):
                assert v and ":" not in v.split("/", 1)[0], f"{k}={v!r} has a scheme"
                assert not v.startswith(("/", "\\")), f"absolute link {v!r}"
    scripts = [t for t, _ in page.tags if t == "script"]
    assert len(scripts) == 1                     # the report's own table-sorting script
    assert not [a for t, a in page.tags if t == "img" and a.get("src") == "x"]
    assert not [a for t, a in page.tags if t == "b" and a]


@pytest.fixture(scope="module")
def hostile_report(tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    ref = Phongish(30)
    ref.name = HOSTILE
    res = C.compare(ref, {MODEL: Lambert([0.3, 0.25, 0.2]), "exact": Phongish(30)}, out,
                    renderer=standin_render, spp=4, resolution=16, noise_floor=False,
                    brdf_metric_samples=1 << 8)
    return out, res


def test_hostile_material_and_model_names_are_text(hostile_report):
    out, res = hostile_report
    for page_path in (out / res["slug"] / "index.html", out / "index.html"):
        page = parse(page_path)
        assert_nothing_injected(page)
        text = "".join(page.text)
        assert MODEL in text
        if page_path.parent != out:
            assert HOSTILE in text                       # the readable name, exactly
        assert R.missing_links(page_path) == []
    # the name in attributes (alt, title, data-sort) is escaped, not cut: it reads back whole
    alts = [a.get("alt", "") for t, a in parse(out / res["slug"] / "index.html").tags if t == "img"]
    assert any(MODEL in a for a in alts)
    idx = parse(out / "index.html")
    assert any(HOSTILE.lower() in a.get("data-sort", "") for t, a in idx.tags if t == "td")


def _crafted(slug: str) -> dict:
    """A result.json as another tool (or an attacker) could have written it."""
    evil = "javascript:alert(4)"
    return {"material": HOSTILE, "slug": slug, "source": HOSTILE,
            "scene": {"resolution": 16, HOSTILE: HOSTILE}, "gamma": "2.2\" onload=\"alert(5)",
            "reference": {"png": "ref #1 ?金%.png"},
            "models": [
                {"name": MODEL, "status": "ok", "psnr": 30.0, "mean_de2000": 1.0,
                 "png": evil, "de_png": "data:text/html,<script>alert(6)</script>",
                 "fit_file": "fits/a b#c.npz", "params": {HOSTILE: HOSTILE}},
                {"name": "remote", "status": "ok", "psnr": 20.0, "png": "//evil.example/x.png",
                 "de_png": "/etc/passwd", "fit_file": "JAVASCRIPT:alert(7)"},
                {"name": "failed<i>", "status": "failed<u>", "error": HOSTILE}],
            "plots": {"lobes": "lobes 100%.png"}, "notes": [HOSTILE]}


def test_crafted_result_links_are_quoted_or_dropped(tmp_path):
    slug = "mat #1?"                      # a folder another tool made: not a slug of ours
    mdir = tmp_path / slug
    (mdir / "fits").mkdir(parents=True)
    for f in ("ref #1 ?金%.png", "lobes 100%.png", "fits/a b#c.npz"):
        (mdir / f).write_bytes(b"x")
    (tmp_path / "assets").mkdir()
    (tmp_path / "assets" / "de_colorbar.png").write_bytes(b"x")
    result = _crafted(slug)
    R.write_result(mdir, result)
    page_path = R.write_material_page(tmp_path, result)
    idx_path = R.write_index(tmp_path)
    for p in (page_path, idx_path):
        page = parse(p)
        assert_nothing_injected(page)
        links = [a.get("href") or a.get("src") for t, a in page.tags if t in ("a", "img")]
        low = " ".join(links).lower()
        assert "javascript" not in low and "data:" not in low and "evil.example" not in low
        assert "/etc/passwd" not in links
        # every link left resolves to a file of the report (URL-decoded)
        assert R.missing_links(p) == []
    page = parse(page_path)
    srcs = [a["src"] for t, a in page.tags if t == "img"]
    assert "ref%20%231%20%3F%E9%87%91%25.png" in srcs and "lobes%20100%25.png" in srcs
    hrefs = [a["href"] for t, a in page.tags if t == "a"]
    assert "fits/a%20b%23c.npz" in hrefs
    idx = parse(idx_path)
    assert "mat%20%231%3F/index.html" in [a["href"] for t, a in idx.tags if t == "a"]
    text = page_path.read_text(encoding="utf-8")
    assert "onload" not in text.replace("&quot; onload=&quot;", "")


def test_local_links_decode_percent_escapes(tmp_path):
    (tmp_path / "a b%.png").write_bytes(b"x")
    p = tmp_path / "x.html"
    p.write_text('<img src="a%20b%25.png"><img src="javascript:alert(1)">')
    assert R.local_links(p) == ["a b%.png", "javascript:alert(1)"]
    assert R.missing_links(p) == ["javascript:alert(1)"]
