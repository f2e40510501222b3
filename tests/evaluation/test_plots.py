"""Tests of brdffit.evaluation.plots: files are produced, lobes point the right way."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.evaluation import plots
from tests.evaluation.test_metrics import Lambert, Phongish

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


class FakeDist:
    """Beckmann-like D and a simple G1 (duck-typed ``distribution``)."""

    def __init__(self, a):
        self.a = a

    def D(self, m):
        c = np.clip(m[..., 2], 1e-6, 1)
        t2 = (1 - c * c) / (c * c)
        return np.exp(-t2 / self.a**2) / (np.pi * self.a**2 * c**4)

    def G1(self, w):
        return np.clip(w[..., 2], 0, 1) ** 0.1


class FakeFresnel:
    def eval(self, c):
        c = np.asarray(c, float)[..., None]
        return np.array([0.9, 0.6, 0.3]) + (1 - np.array([0.9, 0.6, 0.3])) * (1 - c) ** 5


class FakeMicrofacet(Phongish):
    def __init__(self):
        super().__init__(30)
        self.distribution = FakeDist(0.2)
        self.fresnel = FakeFresnel()


class FakeNPF(Lambert):
    def __init__(self):
        super().__init__([0.3, 0.3, 0.3])
        t = np.linspace(0, np.pi / 2, 90)
        self._tabs = {"D": np.exp(-t[:, None] * [3, 4, 5]), "F": np.ones((90, 3)) * 0.5,
                      "G": np.cos(t)}

    def factor_tables(self):
        return self._tabs


def _is_png(p):
    return p.is_file() and p.read_bytes()[:8] == PNG_MAGIC


def test_lobe_peaks_in_mirror_direction():
    for ti in (10.0, 30.0, 50.0):
        x, z = plots.lobe_curve(Phongish(50), ti)
        k = np.argmax(np.hypot(x, z))
        theta_o = np.degrees(np.arctan2(x[k], z[k]))
        assert theta_o == pytest.approx(-ti, abs=2.0)
    # a Lambertian lobe is a (cube-rooted) cosine: symmetric about the normal
    x, z = plots.lobe_curve(Lambert([0.5] * 3), 40.0)
    np.testing.assert_allclose(x, -x[::-1], atol=1e-12)


def test_plot_files_written(tmp_path):
    ref = Phongish(40)
    fits = {"glossy": FakeMicrofacet(), "lambert": Lambert([0.4, 0.3, 0.2]), "npf": FakeNPF()}
    p1 = plots.plot_lobes(ref, fits, tmp_path / "lobes.png")
    p2 = plots.plot_factors(fits, tmp_path / "factors.png")
    p3 = plots.plot_slices(ref, fits, tmp_path / "slices.png")
    assert all(_is_png(p) for p in (p1, p2, p3))
    assert not list(tmp_path.glob(".*"))  # no temporary files left behind


def test_plot_factors_none_without_factors(tmp_path):
    assert plots.plot_factors({"lambert": Lambert([0.5] * 3)}, tmp_path / "f.png") is None
    assert not (tmp_path / "f.png").exists()
    assert plots.npf_tables(FakeNPF())["D"].shape == (90, 3)
    assert plots.has_factors(FakeMicrofacet()) and not plots.has_factors(Lambert([1] * 3))


def test_slices_values():
    t, f = plots.slice_values(Lambert([0.5, 0.5, 0.5]), "backscatter")
    np.testing.assert_allclose(f, 0.5 / np.pi)
    with pytest.raises(ValueError):
        plots.slice_values(Lambert([0.5] * 3), "nope")


def test_npf_default_sample_angles():
    d = plots.npf_sample_angles("D", 90)
    assert d[0] == 0 and d[1] == pytest.approx((1 / 90) ** 2 * np.pi / 2)  # sqrt(θh) uniform
    assert np.degrees(plots.npf_sample_angles("G", 90))[-1] == pytest.approx(89.0)
    assert np.degrees(plots.npf_sample_angles("H", 180))[-1] == pytest.approx(179.0)


class PerChannel(Lambert):
    """A per-channel model (like the SGD fit): three lobes, each with its own factors."""

    def __init__(self):
        super().__init__([0.2] * 3)
        self.lobes = [FakeMicrofacet() for _ in range(3)]
        for a, lb in zip((0.1, 0.2, 0.3), self.lobes):
            lb.distribution = FakeDist(a)


def test_per_channel_models_have_factors(tmp_path):
    assert plots.has_factors(PerChannel())
    assert _is_png(plots.plot_factors({"sgd-like": PerChannel()}, tmp_path / "pc.png"))


@pytest.mark.parametrize("n_fits,title", [(1, None), (3, "a material"), (8, "a material")])
def test_fixed_layout_keeps_labels_inside_and_apart(monkeypatch, tmp_path, n_fits, title):
    """The fixed margins leave every panel's labels, ticks and title inside the figure and
    off the other panels (what ``tight_layout`` guaranteed by measuring them)."""
    boxes = []

    def check(fig, path, dpi=100):
        r = fig.canvas.get_renderer()
        fig.draw(r)
        w, h = fig.bbox.width, fig.bbox.height
        axes = [ax for ax in fig.axes if ax.axison]
        bbs = [ax.get_tightbbox(r) for ax in axes]
        for bb in bbs + [t.get_window_extent(r) for t in fig.texts]:
            assert bb.x0 >= -1 and bb.y0 >= -1 and bb.x1 <= w + 1 and bb.y1 <= h + 1
        for i, a in enumerate(bbs):
            for b in bbs[i + 1:]:
                ov = a.intersection(a, b)
                assert ov is None or ov.width * ov.height < 1.0
        boxes.append(len(bbs))
        plots._plt().close(fig)
        return path

    monkeypatch.setattr(plots, "save_figure", check)
    kinds = [FakeMicrofacet, FakeNPF, PerChannel, lambda: Lambert([0.4, 0.3, 0.2])]
    fits = {f"model-{k}": kinds[k % 4]() for k in range(n_fits)}
    plots.plot_lobes(Phongish(40), fits, tmp_path / "l.png", title=title)
    plots.plot_factors(fits, tmp_path / "f.png", title=title)
    plots.plot_slices(Phongish(40), fits, tmp_path / "s.png", title=title)
    assert len(boxes) == 3


def test_titles_pinned_except_above_an_offset_text(monkeypatch, tmp_path):
    """Titles sit at their panel's top edge; a nearly constant linear curve (whose axis
    shows an offset text) keeps matplotlib's placement, above that text."""
    seen = []

    def check(fig, path, dpi=100):
        r = fig.canvas.get_renderer()
        fig.draw(r)
        for ax in fig.axes:
            off = ax.yaxis.offsetText
            if ax.get_title() and off.get_visible() and off.get_text():
                seen.append(ax.get_title())
                assert ax.title.get_window_extent(r).y0 >= off.get_window_extent(r).y1 - 1
        plots._plt().close(fig)
        return path

    monkeypatch.setattr(plots, "save_figure", check)
    flat = FakeNPF()
    flat._tabs["F"] = 0.7 + 1e-7 * np.linspace(0, 1, 90)[:, None] * [1, 2, 3]
    plots.plot_factors({"flat": flat, "glossy": FakeMicrofacet()}, tmp_path / "f.png")
    assert seen == ["flat: F per channel"]
    fig, ax = plots._plt().subplots()
    assert not plots._may_show_offset(ax)       # the default view (0, 1): pinned
    plots._plt().close(fig)
