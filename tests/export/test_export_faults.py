"""Exports on a full disk (issue 12, items 10-11): nothing partial is left behind, existing
outputs are kept, and the error is one line naming the output file, what was expected and
what was found.

The full disk is simulated two ways: ``builtins.open``/``io.open`` patched so that the k-th
file opened for writing takes a few bytes and then fails with ``ENOSPC`` (every k, so a
fault at every step of a multi-file export is tried), and a real limit on the file size
(``RLIMIT_FSIZE``) in a child process running the command line, where the C-level writers
(NumPy's ``tofile``) fail too.
"""

from __future__ import annotations

import builtins
import errno
import io
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import brdffit
from brdffit.cli import main
from brdffit.errors import ExportError
from brdffit.export import export
from brdffit.export import glsl as GL
from tests.export.test_glsl import _npf
from tests.export.test_hostile_names import _tabulated


class _FullFile:
    """A file object that accepts ``room`` more bytes (or characters) then raises ENOSPC."""

    def __init__(self, f, room: int):
        self._f = f
        self._room = room

    def write(self, data):
        n = len(data) if isinstance(data, str) else memoryview(data).nbytes
        if n > self._room:
            if self._room:
                self._f.write(data[: self._room] if isinstance(data, str)
                              else bytes(memoryview(data).cast("B")[: self._room]))
            self._room = 0
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self._room -= n
        return self._f.write(data)

    def writelines(self, lines):
        for x in lines:
            self.write(x)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._f.close()
        return False

    def __getattr__(self, name):
        return getattr(self._f, name)


class FullDisk:
    """Patch ``open`` so that the ``fail_at``-th file opened for writing under ``root`` (1-based;
    None: never) runs out of space after ``room`` bytes. ``opened`` lists the paths opened."""

    def __init__(self, monkeypatch, root: Path, fail_at: int | None, room: int = 64):
        self.root = str(Path(root).resolve())
        self.fail_at = fail_at
        self.room = room
        self.opened: list[str] = []
        real = builtins.open

        def fake_open(file, mode="r", *args, **kwargs):
            f = real(file, mode, *args, **kwargs)
            path = os.path.abspath(os.fsdecode(file)) if isinstance(file, (str, bytes, os.PathLike)) else ""
            if any(c in mode for c in "wax+") and path.startswith(self.root):
                self.opened.append(path)
                if len(self.opened) == self.fail_at:
                    return _FullFile(f, self.room)
            return f

        monkeypatch.setattr(builtins, "open", fake_open)
        monkeypatch.setattr(io, "open", fake_open)


def _listing(d: Path) -> dict:
    return {str(p.relative_to(d)): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()} | \
        {str(p.relative_to(d)) + "/": b"" for p in d.rglob("*") if p.is_dir()}


def _one_line_error(exc: ExportError, finals: list[Path]):
    msg = str(exc)
    assert "\n" not in msg
    assert any(msg.startswith(f"{p}: ") for p in finals), msg
    assert "no space left on device" in msg
    assert "Errno" not in msg


#: name -> (writer(out), output path relative to tmp, every file it writes)
def _cases():
    return {
        "mitsuba-plugin": (lambda out: export(brdffit.synthetic("sgd-paint"), "mitsuba", out),
                           "s.py", ["s.py", "s.fit.npz"]),
        "mitsuba-builtin": (lambda out: export(brdffit.synthetic("gold-ggx"), "mitsuba", out),
                            "g.py", ["g.py"]),
        "mitsuba-xml": (lambda out: export(brdffit.synthetic("gold-ggx"), "mitsuba-xml", out),
                        "g.xml", ["g.xml"]),
        "glsl-textures": (lambda out: export(_tabulated(), "glsl", out), "t.glsl",
                          ["t.glsl", "t.glsl.json", "t.l0_ndf.exr", "t.l0_fresnel.exr"]),
        "gltf": (lambda out: export(brdffit.synthetic("gold-ggx"), "gltf", out, fidelity=False),
                 "g.gltf", ["g.gltf"]),
        "json": (lambda out: export(brdffit.synthetic("gold-ggx"), "json", out), "g.json",
                 ["g.json"]),
        "rgl": (lambda out: export(brdffit.synthetic("gold-ggx"), "rgl", out, check=False,
                                   n_theta=4, n_ndf=32, vndf_res=16, rgb_res=8),
                "g.bsdf", ["g.bsdf"]),
        "npf-uber": (lambda out: GL.pack_npf_uber_texture([_npf(0, "a"), _npf(1, "b")], out,
                                                          exr=False),
                     "u.npy", ["u.npy", "u.json"]),
    }


@pytest.mark.parametrize("case", list(_cases()))
def test_full_disk_at_every_step_leaves_nothing(tmp_path, monkeypatch, case):
    write, rel, expected = _cases()[case]
    # a clean run: how many files are opened for writing, and which files result
    with monkeypatch.context() as mp:
        counter = FullDisk(mp, tmp_path, None)
        write(tmp_path / "clean" / rel)
    n_opens = len(counter.opened)
    assert n_opens >= len(expected)
    assert sorted(p.name for p in (tmp_path / "clean").iterdir()) == sorted(expected)
    finals = [tmp_path / "full" / e for e in expected]
    for k in range(1, n_opens + 1):
        d = tmp_path / "full"
        d.mkdir(exist_ok=True)
        before = _listing(d)
        with monkeypatch.context() as mp:
            FullDisk(mp, tmp_path, k)
            with pytest.raises(ExportError) as ei:
                write(d / rel)
        _one_line_error(ei.value, finals)
        assert _listing(d) == before, f"fault at write {k}/{n_opens} left {set(_listing(d)) - set(before)}"


@pytest.mark.parametrize("case", ["mitsuba-plugin", "glsl-textures", "npf-uber"])
def test_full_disk_keeps_previous_outputs(tmp_path, monkeypatch, case):
    """A failed re-export leaves the complete previous export as it was."""
    write, rel, expected = _cases()[case]
    with monkeypatch.context() as mp:
        counter = FullDisk(mp, tmp_path, None)
        write(tmp_path / rel)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(expected)
    before = _listing(tmp_path)
    for k in range(1, len(counter.opened) + 1):
        with monkeypatch.context() as mp:
            FullDisk(mp, tmp_path, k)
            with pytest.raises(ExportError):
                write(tmp_path / rel)
        assert _listing(tmp_path) == before


def test_issue_reproduction_mitsuba_fit_file_left(tmp_path, monkeypatch, capsys):
    """``export --to mitsuba -o s.py`` on a full disk: exit 1, one line naming the file,
    and no ``s.fit.npz`` left (the script is the second file written)."""
    monkeypatch.chdir(tmp_path)
    with monkeypatch.context() as mp:
        FullDisk(mp, tmp_path, 2)
        rc = main(["export", "synthetic:sgd-paint", "--to", "mitsuba", "-o", "s.py"])
    err = capsys.readouterr().err
    assert rc == 1
    assert err.startswith("brdffit: error: s.py: ") and len(err.strip().splitlines()) == 1, err
    assert "no space left on device" in err and "Errno" not in err
    assert list(tmp_path.iterdir()) == []


def test_other_failure_after_writing_cleans_up(tmp_path, monkeypatch):
    """Not only OSErrors: a failure of a later step (here the EXR writer of the uber-texture)
    removes what was already written."""
    from brdffit.evaluation import imageio

    def broken(path, img):
        Path(path).write_bytes(b"partial")
        raise RuntimeError("OpenEXR: cannot write")

    monkeypatch.setattr(imageio, "write_exr", broken)
    with pytest.raises(ExportError, match=r"u\.exr: could not write"):
        GL.pack_npf_uber_texture([_npf(0, "a")], tmp_path / "u.npy", exr=True)
    assert list(tmp_path.iterdir()) == []


def test_output_is_a_directory(tmp_path, capsys):
    (tmp_path / "x.json").mkdir()
    rc = main(["export", "synthetic:gold-ggx", "--to", "json", "-o", str(tmp_path / "x.json")])
    err = capsys.readouterr().err
    assert rc == 1 and err.startswith(f"brdffit: error: {tmp_path / 'x.json'}: ")
    assert "directory" in err and "Errno" not in err and len(err.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.json"]
    assert list((tmp_path / "x.json").iterdir()) == []


def test_unwritable_folder(tmp_path, capsys):
    if os.geteuid() == 0:
        pytest.skip("root ignores directory permissions")
    d = tmp_path / "ro"
    d.mkdir()
    d.chmod(0o500)
    try:
        rc = main(["export", "synthetic:gold-ggx", "--to", "glsl", "-o", str(d / "x.glsl")])
    finally:
        d.chmod(0o700)
    err = capsys.readouterr().err
    assert rc == 1 and str(d / "x.glsl") in err and "permission denied" in err
    assert list(d.iterdir()) == []


def test_parent_is_a_file(tmp_path, capsys):
    """``-o file.txt/x.glsl``: one line naming the output, nothing created."""
    (tmp_path / "file.txt").write_text("keep")
    out = tmp_path / "file.txt" / "x.glsl"
    rc = main(["export", "synthetic:gold-ggx", "--to", "glsl", "-o", str(out)])
    err = capsys.readouterr().err
    assert rc == 1 and err.startswith(f"brdffit: error: {out}: expected a folder "
                                      f"{out.parent}, found a regular file"), err
    assert len(err.strip().splitlines()) == 1 and "Errno" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file.txt"]
    assert (tmp_path / "file.txt").read_text() == "keep"


_CHILD = textwrap.dedent("""
    import resource, signal, sys
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)    # writes past the limit fail with EFBIG
    limit = int(sys.argv[1])
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    from brdffit.cli import main
    sys.exit(main(sys.argv[2:]))
""")


def _run_limited(limit: int, args: list[str], cwd: Path):
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1")
    return subprocess.run([sys.executable, "-c", _CHILD, str(limit), *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=300)


def test_real_file_size_limit_glsl_textures(tmp_path):
    """A real file-size limit while the EXR textures are written becomes one line naming the
    texture file, without temporary paths; nothing is left."""
    fit = tmp_path / "in"
    fit.mkdir()
    from brdffit.io.fitfile import save_fit

    save_fit(_tabulated("tab"), fit / "tab.npz")
    out = tmp_path / "out"
    out.mkdir()
    r = _run_limited(4096, ["export", str(fit / "tab.npz"), "--to", "glsl", "-o", "t.glsl"], out)
    assert r.returncode == 1, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("brdffit: error: t."), r.stderr
    assert "could not" in lines[0] and "requested" not in lines[0]
    assert "file too large" in lines[0] and "partial" not in lines[0]   # no temporary path
    assert list(out.iterdir()) == []


def test_real_file_size_limit_mitsuba(tmp_path):
    """The issue's case for real: the fit file (~0.8 kB) fits under the limit, the script
    (~2 kB) does not; neither is left."""
    r = _run_limited(1500, ["export", "synthetic:sgd-paint", "--to", "mitsuba", "-o", "s.py"],
                     tmp_path)
    assert r.returncode == 1, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("brdffit: error: s."), r.stderr
    assert "file too large" in lines[0] and "Errno" not in lines[0]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("to, ext", [("json", ".json"), ("mitsuba-xml", ".xml"),
                                     ("mitsuba", ".py"), ("glsl", ".gl")])
def test_longest_legal_file_name(tmp_path, to, ext):
    """A 255-byte name (the usual limit) is written: temporary names stay short. (glsl: the
    index ``<name>.json`` must fit too, so the shader's name is 250 bytes.)"""
    n = 255 if to != "glsl" else 250
    out = tmp_path / ("n" * (n - len(ext)) + ext)
    export(brdffit.synthetic("gold-ggx"), to, out)
    assert out.is_file()
    names = sorted(p.name for p in tmp_path.iterdir())
    assert all(not n.startswith(".") for n in names), names


@pytest.mark.parametrize("to", ["json", "glsl"])
def test_non_finite_parameters_are_one_line_errors(tmp_path, to):
    """A NaN that reached a model in memory (fit files are validated on load) is refused with
    one line naming the model, not written as ``nan`` into JSON or GLSL code."""
    import numpy as np

    m = brdffit.synthetic("gold-ggx")
    m.fresnel.eta = np.array([np.nan, 0.2, 0.3])
    with pytest.raises(ExportError) as ei:
        export(m, to, tmp_path / f"x.{to}")
    msg = str(ei.value)
    assert "\n" not in msg and "gold-ggx" in msg and "finite" in msg, msg
    assert list(tmp_path.iterdir()) == []
