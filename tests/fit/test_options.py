"""brdffit.fit.options: every fitter option typed and bounded, one check for every entry
(issue 32.3)."""

from __future__ import annotations

import pytest

import brdffit
from brdffit.cli import main
from brdffit.fit import registry
from brdffit.fit.options import RANGES, OptionError, fitter_parameters, option_kind
from brdffit.fit.registry import check_options


@pytest.mark.parametrize("model, options, message", [
    ("ggx-diffuse", {"starts": -5}, "starts: expected an integer in [1, 100], found -5"),
    ("ggx-diffuse", {"theta_d_stride": 0}, "theta_d_stride: expected an integer in [1, 90]"),
    ("ggx-diffuse", {"phi_d_stride": -3}, "phi_d_stride: expected an integer in [1, 180]"),
    ("ggx-diffuse", {"starts": 2.5}, "starts: expected an integer"),
    ("ggx-diffuse", {"starts": True}, "starts: expected an integer"),
    ("npf", {"seed": -1}, "seed: expected an integer in [0, 4294967295], found -1"),
    ("npf", {"max_iter": 0}, "max_iter: expected an integer in [1, 100000]"),
    ("npf", {"tol": 0}, "tol: expected a number in (0, 1]"),
    ("npf", {"tol": float("nan")}, "tol: expected a number in (0, 1], found nan"),
    ("npf", {"polish_bound": 0.5}, "polish_bound: expected 0 (no trust region) or a number"),
    ("npf", {"starts": 3}, "starts: expected a list of names"),
    ("tabulated", {"n": 10**9}, "n: expected an integer in [8, 1024]"),
    ("tabulated", {"anisotropic": "yes"}, "anisotropic: expected true or false"),
    ("sgd", {"grid": [0, 8]}, "grid: expected two integers in [1, 10000]"),
    ("ggx-diffuse", {"bogus": 1}, "model 'ggx-diffuse' has no option 'bogus'; accepted:"),
])
def test_bad_values_are_refused_naming_the_option(model, options, message):
    with pytest.raises(OptionError) as info:
        check_options(model, options)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_good_values_pass_and_command_line_numbers_are_converted():
    assert check_options("npf", {"polish_bound": 0, "starts": ["ones"], "tol": "1e-6",
                                 "max_iter": 5.0}) == {"polish_bound": 0, "starts": ("ones",),
                                                       "tol": 1e-6, "max_iter": 5}
    assert check_options("sgd", {"grid": [18, 8]}) == {"grid": (18, 8)}
    with pytest.raises(OptionError, match="has no option 'callback'"):
        check_options("npf", {"callback": print}, command_line=True)
    assert check_options("npf", {"callback": print})["callback"] is print  # the Python API


def test_every_numeric_option_of_every_model_has_a_range():
    """A new numeric option must be given a range here (or it is unbounded)."""
    missing = set()
    for name in registry.known_names():
        params, _ = fitter_parameters(registry.get(name).fit)
        for opt, param in params.items():
            if option_kind(param)[0] in ("int", "float") and opt not in RANGES \
                    and opt not in ("polish_bound",):
                missing.add(opt)
    assert not missing, sorted(missing)


def test_the_cli_the_python_api_and_compare_all_check(tmp_path, capsys):
    assert main(["fit", "synthetic:gold-ggx", "-m", "ggx-diffuse", "-O", "phi_d_stride=-3"]) == 2
    assert "phi_d_stride: expected an integer in [1, 180], found -3" in capsys.readouterr().err
    with pytest.raises(ValueError, match="phi_d_stride"):
        brdffit.fit("synthetic:gold-ggx", model="ggx-diffuse", phi_d_stride=-3)
    assert main(["compare", "synthetic:gold-ggx", "--models", "ggx-diffuse", "--fit-options",
                 '{"ggx-diffuse": {"starts": 0}}', "--out", str(tmp_path / "c")]) == 2
    assert "starts: expected an integer in [1, 100], found 0" in capsys.readouterr().err
    assert not (tmp_path / "c").exists()
