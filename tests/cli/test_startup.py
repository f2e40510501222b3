"""A CLI that starts at once (issue 15.4): what `import brdffit`, `brdffit --help` and a
tabulated fit import, in fresh interpreters; rejected inputs fail before the fitting stack
is imported; the NumPy spline that replaced scipy.interpolate in the tabulated NDF."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

#: Never imported by `import brdffit` or `brdffit --help` (issue 15.4).
HEAVY = ("mitsuba", "drjit", "dask", "distributed", "matplotlib", "colour", "numba",
         "llvmlite", "scipy", "h5py", "pydantic", "rich", "PIL")

_RUN = """
import json, sys
code = None
{body}
mods = sorted({{m.split('.')[0] for m in sys.modules}} | {{m for m in sys.modules
                                                        if m.startswith('brdffit')}})
print("\\n@@" + json.dumps({{"code": code, "modules": mods}}))
"""


def _modules_after(body: str, cwd=None) -> tuple[int | None, set[str]]:
    proc = subprocess.run([sys.executable, "-c", _RUN.format(body=body)], capture_output=True,
                          text=True, timeout=300, cwd=cwd)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout.rsplit("\n@@", 1)[1])
    return out["code"], set(out["modules"])


def _cli(argv) -> str:
    return f"from brdffit.cli import main\ncode = main({argv!r})"


def test_import_brdffit_is_light():
    _, mods = _modules_after("import brdffit")
    assert not mods & set(HEAVY), mods & set(HEAVY)
    assert "numpy" not in mods


@pytest.mark.parametrize("argv", [["--help"], ["fit", "--help"], ["batch", "--help"],
                                  ["models"]])
def test_help_and_models_are_light(argv):
    code, mods = _modules_after(_cli(argv))
    assert code == 0
    assert not mods & set(HEAVY), mods & set(HEAVY)
    assert "numpy" not in mods
    assert not any(m.startswith("brdffit.fit.") and m != "brdffit.fit.registry" for m in mods)


@pytest.fixture(scope="module")
def merl_file(tmp_path_factory):
    from brdffit import synthetic
    from brdffit.io.merl import resample_to_merl

    path = tmp_path_factory.mktemp("merl") / "gold.binary"
    resample_to_merl(synthetic("gold-ggx"), path)
    return path


def test_tabulated_fit_of_a_merl_file_imports_no_scipy_numba_or_pydantic(merl_file, tmp_path):
    out = tmp_path / "f.npz"
    code, mods = _modules_after(_cli(["fit", str(merl_file), "--model", "tabulated",
                                      "-o", str(out)]))
    assert code == 0 and out.is_file()
    assert not mods & set(HEAVY), mods & set(HEAVY)
    assert "brdffit.fit.npf" not in mods and "brdffit.fit.sgd" not in mods
    # only the command that runs is imported and built
    assert "brdffit.cli.fit" in mods
    assert not {f"brdffit.cli.{m}" for m in ("batch", "compare", "demo", "export", "render",
                                             "info", "convert", "models")} & mods


def test_the_script_entry_point_writes_and_flushes_everything(merl_file, tmp_path):
    """`python -m brdffit` runs :func:`brdffit.cli.run` (main, then gc.freeze before the
    exit): the fit file is complete, stdout flushed, the exit status main's; the console
    script is the same function."""
    out = tmp_path / "f.npz"
    proc = subprocess.run([sys.executable, "-m", "brdffit", "fit", str(merl_file), "--model",
                           "tabulated", "-o", str(out), "--json"], capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    from brdffit.io import load

    assert np.isclose(load(str(out)).fit_info["eigenvalue"], summary["details"]["eigenvalue"])
    bad = subprocess.run([sys.executable, "-m", "brdffit", "fit", str(tmp_path / "missing")],
                         capture_output=True, text=True, timeout=300)
    assert bad.returncode == 1 and bad.stderr.count("\n") == 1
    import tomllib
    from pathlib import Path

    scripts = tomllib.loads((Path(__file__).parents[2] / "pyproject.toml").read_text())
    assert scripts["project"]["scripts"]["brdffit"] == "brdffit.cli:run"


def test_the_script_raises_the_collectors_young_threshold_and_main_does_not():
    """:func:`brdffit.cli.run` (the script) raises the young-generation threshold for the
    process (start-up collections); :func:`main` (a library caller) leaves the collector as
    it found it; the collector stays enabled."""
    code = ("import gc, sys\n"
            "from brdffit.cli import GC_YOUNG_THRESHOLD, main, run\n"
            "before = gc.get_threshold()\n"
            "main(['--version'])\n"
            "assert gc.get_threshold() == before, gc.get_threshold()\n"
            "sys.argv = ['brdffit', '--version']\n"
            "assert run() == 0\n"
            "print(gc.get_threshold()[0] == GC_YOUNG_THRESHOLD > before[0],"
            " gc.get_threshold()[1:] == before[1:], gc.isenabled())")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split()[-3:] == ["True", "True", "True"], proc.stdout


def test_the_fit_file_records_the_inputs_sha256_hashed_without_numpy(merl_file, tmp_path):
    """``brdffit fit -o`` hashes its input on a thread started before NumPy is imported: the
    hashing module imports no NumPy, and the fit file holds the input's SHA-256."""
    import hashlib

    from brdffit.io.fitfile import read_fit_header

    _, mods = _modules_after("import brdffit.io._checksum")
    assert "numpy" not in mods and "brdffit.io._checksum" in mods
    out = tmp_path / "f.npz"
    proc = subprocess.run([sys.executable, "-m", "brdffit", "fit", str(merl_file), "--model",
                           "tabulated", "-o", str(out), "--no-error"], capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    header = read_fit_header(out)
    assert header["source"]["sha256"] == hashlib.sha256(merl_file.read_bytes()).hexdigest()
    assert header["source"]["spec"] == str(merl_file)


def test_a_rejected_input_fails_before_the_fitting_stack_is_imported(merl_file, tmp_path):
    bad = tmp_path / "bad.binary"
    bad.write_bytes(merl_file.read_bytes()[:1000])  # truncated
    for argv in (["fit", str(bad), "--model", "tabulated"], ["info", str(bad)]):
        code, mods = _modules_after(_cli(argv))
        assert code == 1, argv
        assert "brdffit.fit.tabulated" not in mods and "brdffit.microfacet" not in mods
        assert not mods & set(HEAVY), mods & set(HEAVY)


def test_an_unknown_model_is_a_usage_error_without_importing_fitters():
    code, mods = _modules_after(_cli(["fit", "synthetic:gold-ggx", "--model", "nope"]))
    assert code == 2
    assert not any(m.startswith("brdffit.fit.") and m != "brdffit.fit.registry" for m in mods)


def test_options_are_checked_before_the_input_is_read(tmp_path, capsys):
    from brdffit.cli import main

    # the input does not exist: a bad option is still reported as a usage error (exit 2)
    assert main(["fit", str(tmp_path / "missing.binary"), "-m", "ggx", "-O", "bogus=1"]) == 2
    assert "bogus" in capsys.readouterr().err


def test_numpy_spline_slopes_match_scipy():
    from scipy.interpolate import CubicSpline

    from brdffit.microfacet.tabulated import _spline_slopes

    rng = np.random.default_rng(7)
    for n in (2, 3, 4, 5, 17, 90, 179):
        x = np.cumsum(rng.uniform(0.01, 1.0, n)) - 3.0
        for shape in ((n,), (n, 3)):
            y = rng.normal(size=shape)
            want = CubicSpline(x, y, axis=0).derivative()(x)
            assert np.allclose(_spline_slopes(x, y), want, rtol=1e-10, atol=1e-12), (n, shape)
    # the mirrored quadratic-u grid of the tabulated NDF
    u = (np.arange(90) / 90.0) ** 2
    u = np.concatenate([-u[1:][::-1], u])
    y = np.log1p(np.cos(3 * u)[:, None] * np.array([1.0, 2.0, 3.0]) + 2)
    assert np.allclose(_spline_slopes(u, y), CubicSpline(u, y, axis=0).derivative()(u),
                       rtol=1e-10, atol=1e-12)


def test_lazy_numba_compiles_once_the_work_pays_for_it():
    """Small jobs stay in NumPy (Numba's import and a cached kernel cost 0.4-0.9 s); the
    kernel is compiled once the work left to NumPy passes COMPILE_AFTER."""
    code, mods = _modules_after(
        "import sys\n"
        "import numpy as np\n"
        "from brdffit._jit import COMPILE_AFTER\n"
        "from brdffit.io import merl\n"
        "from brdffit.geometry import io_to_half_diff\n"
        "wi = np.array([[0.3, 0.1, np.sqrt(0.9)]]); wo = np.array([[-0.3, 0.2, np.sqrt(0.87)]])\n"
        "th, td, pd, above = merl.fast_half_diff(wi, wo)\n"
        "ref = io_to_half_diff(wi, wo)\n"
        "assert np.allclose(th, ref[0]) and np.allclose(td, ref[2])\n"
        "small = 'numba' in sys.modules\n"
        "n = COMPILE_AFTER // 2 + 1\n"
        "big = (np.repeat(wi, n, 0), np.repeat(wo, n, 0))\n"
        "merl.fast_half_diff(*big)\n"
        "half = 'numba' in sys.modules\n"
        "th, td, pd, above = merl.fast_half_diff(*big)\n"
        "assert np.allclose(th, ref[0][0]) and np.allclose(td, ref[2][0])\n"
        "code = int(small) + 2 * int(half)")
    assert code == 0  # neither a 1-pair call nor half the threshold imported numba
    assert "numba" in mods  # ... the call past the threshold did


def test_end_to_end_tests_run_in_the_mode_users_run():
    """tests/conftest.py: Dr.Jit's debug mode is for the render layer's tests only."""
    import os

    from tests.conftest import _DEBUG_FROM_ENV

    if _DEBUG_FROM_ENV is not None:
        pytest.skip("BRDFFIT_DRJIT_DEBUG is set in the environment: it applies to every test")
    assert os.environ["BRDFFIT_DRJIT_DEBUG"] == "0"
