"""``brdffit render`` end to end (small image)."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.cli import main
from brdffit.evaluation.render import available


@pytest.mark.render
@pytest.mark.skipif(not available(), reason="Mitsuba 3 LLVM back-end unavailable")
def test_cli_render_png_and_exr(tmp_path, capsys):
    from brdffit.evaluation.imageio import read_exr, read_png

    png = tmp_path / "gold.png"
    assert main(["render", "synthetic:gold-ggx", "--spp", "8", "--resolution", "32",
                 "-o", str(png)]) == 0
    img = read_png(png)
    assert img.shape == (32, 32, 4)
    fg = img[..., 3] == 255
    assert fg.mean() > 0.3 and img[fg][:, :3].mean() > 20
    assert img[fg][:, 0].mean() > img[fg][:, 2].mean()  # gold is warm
    out = capsys.readouterr().out
    assert "closed-form" in out

    exr = tmp_path / "gold.exr"
    assert main(["render", "synthetic:gold-ggx", "--spp", "8", "--resolution", "32",
                 "--scene", "sphere-point", "--mode", "table", "-o", str(exr)]) == 0
    lin = read_exr(exr)
    assert lin.shape == (32, 32, 4) and np.isfinite(lin).all() and lin[..., :3].max() > 0
    assert "merl-table" in capsys.readouterr().out


@pytest.mark.render
@pytest.mark.skipif(not available(), reason="Mitsuba 3 LLVM back-end unavailable")
def test_cli_render_fit_file(tmp_path, capsys):
    from brdffit.evaluation.imageio import read_exr
    from brdffit.io.fitfile import save_fit
    from brdffit.microfacet import GGX, MicrofacetBRDF, SchlickFresnel

    fit = save_fit(MicrofacetBRDF(GGX(0.3), SchlickFresnel([0.1, 0.5, 0.9]), diffuse=0.05),
                   tmp_path / "fit.npz")
    out = tmp_path / "fit.exr"
    assert main(["render", str(fit), "--spp", "4", "--resolution", "24", "--scene",
                 "sphere-distant", "-o", str(out)]) == 0
    img = read_exr(out)
    fg = img[..., 3] > 0.999
    assert fg.any() and img[fg][:, 2].mean() > img[fg][:, 0].mean()  # blue Fresnel
    assert "closed-form" in capsys.readouterr().out


@pytest.mark.render
@pytest.mark.skipif(not available(), reason="Mitsuba 3 LLVM back-end unavailable")
def test_cli_roughness_texture(tmp_path):
    """A constant texture of 2 renders gold-ggx (α = 0.12) exactly like the same model with
    α = 0.24 (Eq. 9), sample for sample; without the texture it differs."""
    from brdffit.evaluation.imageio import read_exr, write_exr
    from brdffit.evaluation.render import Renderer, psnr
    from brdffit.microfacet import GGX, MicrofacetBRDF
    from brdffit.synthetic import synthetic

    write_exr(tmp_path / "tex.exr", np.full((4, 8, 1), 2.0, np.float32))
    out = tmp_path / "t.exr"
    args = ["--spp", "16", "--resolution", "32"]
    assert main(["render", "synthetic:gold-ggx", *args, "--roughness-texture",
                 str(tmp_path / "tex.exr"), "-o", str(out)]) == 0
    img = read_exr(out)[..., :3]
    gold = synthetic("gold-ggx")
    assert gold.distribution.alpha_x == pytest.approx(0.12)
    rough = MicrofacetBRDF(GGX(0.24), gold.fresnel)
    ref = Renderer(rough, spp=16, resolution=32).render(0)
    plain = Renderer(gold, spp=16, resolution=32).render(0)
    assert psnr(ref.image, img, ref.mask) > 60.0
    assert psnr(ref.image, plain.image, ref.mask) < 40.0


def test_cli_render_errors(tmp_path, capsys):
    assert main(["render", "synthetic:gold-ggx", "-o", str(tmp_path / "x.jpg")]) != 0
    assert main(["render", str(tmp_path / "missing.binary"), "-o", str(tmp_path / "x.png")]) == 1
    err = capsys.readouterr().err
    assert "missing.binary" in err
    assert not list(tmp_path.iterdir())
