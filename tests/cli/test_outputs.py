"""``-o`` of every command: checked before any work, never replacing a device (issue 32)."""

from __future__ import annotations

import os
import stat
import time

import pytest

from brdffit.cli import main


def test_export_to_a_null_device_discards_and_leaves_the_device(null_device, capsys):
    """``-o /dev/null`` (here a null device of the test's own, see the fixture)."""
    out = str(null_device)
    assert main(["export", "synthetic:gold-ggx", "--to", "gltf", "-o", out]) == 0
    assert stat.S_ISCHR(os.stat(out).st_mode)
    assert main(["fit", "synthetic:gold-ggx", "-m", "ggx", "--no-error", "-o", out]) == 0
    assert stat.S_ISCHR(os.stat(out).st_mode)


def test_an_export_of_several_files_to_a_device_is_refused(null_device, capsys):
    assert main(["export", "synthetic:gold-ggx", "--to", "glsl", "-o", str(null_device)]) == 1
    err = capsys.readouterr().err
    assert "this export writes 2 files" in err and "found a character device" in err


@pytest.mark.parametrize("args, message", [
    (["fit", "synthetic:gold-ggx", "-o", "x.gltf"], "expected a file name ending in .npz"),
    (["export", "synthetic:gold-ggx", "--to", "gltf", "-o", "x.npz"], "ending in .gltf"),
    (["export", "synthetic:gold-ggx", "--to", "json", "-o", "x.gltf"], "--to gltf"),
    (["render", "synthetic:gold-ggx", "-o", "x.jpg"], "ending in .exr or .png"),
    (["convert", "synthetic:gold-ggx", "x.npz"], "ending in .binary or .bin"),
])
def test_an_output_named_for_another_format_is_a_usage_error(args, message, tmp_path,
                                                              monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(args) == 2
    assert message in capsys.readouterr().err and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("out, message", [
    ("missing/x.npz", "expected a folder missing, found none (create it first)"),
    ("/proc/x.npz", "/proc/x.npz: cannot write there"),
])
def test_an_unwritable_output_fails_before_the_fit(out, message, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    t0 = time.perf_counter()
    assert main(["fit", "synthetic:gold-ggx", "-m", "npf", "-o", out]) == 1
    assert time.perf_counter() - t0 < 5.0  # npf takes ~10 s: it never started
    err = capsys.readouterr().err
    assert message in err and ".tmp" not in err and len(err.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_a_fit_file_replaced_keeps_its_mode(tmp_path):
    out = tmp_path / "g.npz"
    out.write_bytes(b"old")
    out.chmod(0o600)
    assert main(["fit", "synthetic:gold-ggx", "-m", "ggx", "--no-error", "-o", str(out)]) == 0
    assert stat.S_IMODE(out.stat().st_mode) == 0o600 and out.read_bytes()[:2] == b"PK"
