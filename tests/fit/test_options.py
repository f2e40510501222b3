"""brdffit.fit.options: every fitter option typed and bounded, one check for every entry
(issue 32.3); one options dataclass per fitting function, whose defaults are the function's
(issue 33)."""

from __future__ import annotations

import pytest

import brdffit
from brdffit.cli import main
from brdffit.fit import registry
import dataclasses
import inspect
import typing

from brdffit.fit import options as fit_options
from brdffit.fit.options import RANGES, OptionError, option_table, signature_options
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
    # the string options: their choices, before any work
    ("tabulated", {"rule": "nope"}, "rule: expected 'auto', 'merl' or 'gauss', found 'nope'"),
    ("ggx", {"hotspot": "G3"}, "hotspot: expected 'G1' or 'G2', found 'G3'"),
    ("ggx-diffuse", {"fresnel": "schlik"}, "fresnel: expected 'auto', 'schlick', 'dielectric'"),
    ("beckmann-diffuse", {"f90": 1}, "f90: expected 'one' or 'free', found 1"),
    ("ggx-diffuse", {"coat": "yes"}, "coat: expected 'auto', 'off' or 'on', found 'yes'"),
    ("sgd", {"weighting": "uniform"}, "weighting: expected 'relative' or 'cosine'"),
    ("ggx-2s", {"selection": "all"}, "selection: expected 'full' or 'slice', found 'all'"),
    ("beckmann-2s", {"linear": ""}, "linear: expected 'full' or 'slice', found ''"),
    ("npf-g-from-d", {"init": "nope"}, "init: expected 'slices', 'ones' or 'random'"),
    ("npf", {"starts": ["ones", "best"]}, "starts: expected names among 'random', 'ones', "),
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


def test_string_options_with_choices_are_listed_and_their_fitters_check_the_same_choices():
    """A ``Literal`` option's choices are what ``brdffit models --options`` lists, and the
    fitting function refuses the same values when called directly (no second list)."""
    from brdffit.fit import npf, sgd, tabulated

    table = option_table(fit_options.NPFOptions)
    assert table["starts"].choices == npf.ALL_STARTS
    assert "one of 'slices', 'ones', 'random'" in fit_options.describe_option(table["init"])
    with pytest.raises(OptionError, match="hotspot: expected 'G1' or 'G2', found 'G9'"):
        tabulated.solve_slope_pdf([1.0, 0.5], hotspot="G9")
    with pytest.raises(OptionError, match="selection: expected 'full' or 'slice'"):
        sgd.fit_two_slice("synthetic:gold-ggx", selection="both")
    with pytest.raises(OptionError, match="starts: expected 'random', 'ones', 'sgd'"):
        npf.fit_npf("synthetic:gold-ggx", starts=["ones", "best"])


def test_every_numeric_option_of_every_model_has_a_range():
    """A new numeric option must be given a range here (or it is unbounded)."""
    missing = set()
    for name in registry.known_names():
        cls, _ = registry.options_class(name)
        for opt, option in option_table(cls).items():
            if option.kind in ("int", "float") and opt not in RANGES \
                    and opt not in ("polish_bound",):
                missing.add(opt)
    assert not missing, sorted(missing)


#: The function whose signature each options class declares, and the parameters before the
#: options (the BRDF, and the distribution or variant the model fixes).
_SIGNATURES = {"TabulatedOptions": ("tabulated", "fit_tabulated", 1),
               "DiffuseOptions": ("analytic", "fit_analytic_diffuse", 2),
               "TwoSliceOptions": ("sgd", "fit_two_slice", 2),
               "CookTorranceOptions": ("sgd", "fit_cook_torrance", 2),
               "NPFOptions": ("npf", "fit_npf", 2)}


@pytest.mark.parametrize("cls_name", sorted(_SIGNATURES))
def test_options_classes_are_the_fitting_functions_signatures(cls_name):
    """Names, order, defaults of each options dataclass are those of the function it
    declares (a default changed in one place only fails here)."""
    from importlib import import_module

    module, function, skip = _SIGNATURES[cls_name]
    fn = getattr(import_module(f"brdffit.fit.{module}"), function)
    params = list(inspect.signature(fn).parameters.values())[skip:]
    fields = dataclasses.fields(getattr(fit_options, cls_name))
    assert [p.name for p in params] == [f.name for f in fields]
    hints = typing.get_type_hints(fn)
    for p, f in zip(params, fields):
        assert p.default == f.default, (p.name, p.default, f.default)
        choices = option_table(getattr(fit_options, cls_name))[f.name].choices
        if choices:   # a string option's choices: the function is annotated with the same
            assert p.name in hints and choices[0] in str(hints[p.name]), p.name
    assert dataclasses.is_dataclass(getattr(fit_options, cls_name))
    with pytest.raises(dataclasses.FrozenInstanceError):
        getattr(fit_options, cls_name)().name = "x"


def test_every_model_declares_its_options_class_and_its_wrappers_forward_to_it():
    """The classes the registry declares are those of the function each model's fitting
    function calls (the SGD wrapper's own defaults included)."""
    from brdffit.fit import sgd

    for name, info in registry.MODELS.items():
        cls, open_ended = registry.options_class(name)
        assert info.options == f"options:{cls.__name__}" and not open_ended
    sig = inspect.signature(sgd.fit_sgd).parameters
    fields = {f.name: f.default for f in dataclasses.fields(fit_options.TwoSliceOptions)}
    for p in ("weighting", "starts", "g1_approximation"):
        assert sig[p].default == fields[p]


def test_a_plugin_without_a_class_gets_one_from_its_signature():
    def fit_mine(brdf, *, strength: float = 0.5, label="x", **kw):
        return brdf

    cls, open_ended = signature_options(fit_mine)
    table = option_table(cls)
    assert open_ended and list(table) == ["strength", "label"]
    assert (table["strength"].kind, table["label"].kind) == ("float", "str")
    assert fit_options.check_values(cls, {"strength": "0.25", "other": 1}, model="mine",
                                    open_ended=True) == {"strength": 0.25, "other": 1}
    with pytest.raises(OptionError, match="strength: expected a number, found 'x'"):
        fit_options.check_values(cls, {"strength": "x"}, model="mine")


def test_the_cli_the_python_api_and_compare_all_check(tmp_path, capsys):
    assert main(["fit", "synthetic:gold-ggx", "-m", "ggx-diffuse", "-O", "phi_d_stride=-3"]) == 2
    assert "phi_d_stride: expected an integer in [1, 180], found -3" in capsys.readouterr().err
    with pytest.raises(ValueError, match="phi_d_stride"):
        brdffit.fit("synthetic:gold-ggx", model="ggx-diffuse", phi_d_stride=-3)
    assert main(["compare", "synthetic:gold-ggx", "--models", "ggx-diffuse", "--fit-options",
                 '{"ggx-diffuse": {"starts": 0}}', "--out", str(tmp_path / "c")]) == 2
    assert "starts: expected an integer in [1, 100], found 0" in capsys.readouterr().err
    assert not (tmp_path / "c").exists()
    # a string option's value is checked before the input is read: the usage error, not
    # the missing file
    assert main(["fit", str(tmp_path / "missing.binary"), "-m", "npf-g-from-d", "-O",
                 "init=nope"]) == 2
    assert "init: expected 'slices', 'ones' or 'random', found 'nope'" in \
        capsys.readouterr().err
