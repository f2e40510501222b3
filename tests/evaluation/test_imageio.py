"""EXR/PNG round trips, atomic writes, errors (no Mitsuba needed)."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.errors import BRDFFormatError
from brdffit.evaluation.imageio import (read_exr, read_image, read_png, write_exr, write_image,
                                        write_png)


@pytest.mark.parametrize("channels", [3, 4, 1])
def test_exr_round_trip(tmp_path, rng, channels):
    img = (rng.random((17, 23, channels)) * 1e3 - 1.0).astype(np.float32)
    img[0, 0, 0] = 1e-30
    p = write_exr(tmp_path / "a.exr", img)
    back = read_exr(p)
    assert back.shape == img.shape and back.dtype == np.float32
    np.testing.assert_array_equal(back, img)


def test_png_round_trip_and_quantisation(tmp_path, rng):
    img = rng.random((9, 11, 3))
    write_png(tmp_path / "a.png", img)
    back = read_png(tmp_path / "a.png")
    assert back.dtype == np.uint8 and back.shape == (9, 11, 3)
    np.testing.assert_array_equal(back, np.round(img * 255).astype(np.uint8))
    # out-of-range values are clipped, not wrapped
    write_png(tmp_path / "b.png", np.full((2, 2, 3), 7.0))
    assert np.all(read_png(tmp_path / "b.png") == 255)


@pytest.mark.parametrize("channels", [1, 3, 4])
def test_png_uint8_round_trip_identical(tmp_path, rng, channels):
    """Any uint8 image (noise and smooth gradients) decodes to the same pixels."""
    noise = rng.integers(0, 256, (33, 47, channels), dtype=np.uint8)
    ramp = np.broadcast_to(np.arange(47, dtype=np.uint8)[None, :, None] * 5, noise.shape)
    for k, img in enumerate((noise, ramp)):
        back = read_png(write_png(tmp_path / f"{k}.png", img))
        np.testing.assert_array_equal(back, img)


def test_write_image_dispatch(tmp_path):
    img = np.full((4, 4, 3), 50.0, np.float32)
    write_image(tmp_path / "x.png", img, exposure=0.02, gamma=2.2)
    v = read_image(tmp_path / "x.png")[0, 0, 0]
    assert v == round(0.5 ** (1 / 2.2) * 255)
    write_image(tmp_path / "x.exr", img)
    np.testing.assert_array_equal(read_image(tmp_path / "x.exr"), img)
    with pytest.raises(BRDFFormatError, match="expected an output image ending in .exr or .png"):
        write_image(tmp_path / "x.jpg", img)


def test_failed_write_leaves_nothing(tmp_path):
    with pytest.raises(BRDFFormatError, match="expected an image of shape"):
        write_exr(tmp_path / "bad.exr", np.zeros((2, 2, 5)))
    (tmp_path / "keep.exr").write_bytes(b"old")
    with pytest.raises(BRDFFormatError):
        write_png(tmp_path / "keep.exr", np.zeros((3, 3, 7)))
    assert (tmp_path / "keep.exr").read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.exr"]


def test_read_errors_name_the_file(tmp_path):
    bad = tmp_path / "junk.exr"
    bad.write_bytes(b"not an exr")
    with pytest.raises(BRDFFormatError, match="junk.exr"):
        read_exr(bad)
    with pytest.raises(BRDFFormatError, match="no such file"):
        read_png(tmp_path / "missing.png")


def test_reads_shared_envmap(shared_data):
    p = shared_data("envmaps", "studio.exr")
    img = read_exr(p)
    assert img.shape == (512, 1024, 3) and img.dtype == np.float32
    assert img.max() > 10 * np.median(img)  # HDR
