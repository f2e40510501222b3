"""Fit files (issue 12 "Trust", issue 13 item 5): every kind declares a state schema, real
fits round-trip through it, invalid states are neither written nor loaded, and
``brdffit.io.fitfile`` sits below the model packages (no import circle)."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import brdffit
from brdffit.errors import BRDFFormatError
from brdffit.io.fitfile import load_fit, read_fit_header, save_fit
from tests.support import malformed_fits as mf
from tests.support.hostile import run_limited


def _raw(path):
    """Header and arrays of a fit file we wrote ourselves (trusted: np.load is fine here)."""
    with np.load(path, allow_pickle=False) as z:
        data = {k: z[k] for k in z.files}
    header = json.loads(data.pop("__header__").tobytes().decode())
    return header, data


def _dirs(rng, n):
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2]) + 0.05
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


# ------------------------------------------------------------------------------------------
# every kind has a schema
# ------------------------------------------------------------------------------------------
def test_every_builtin_kind_and_component_has_a_schema():
    from brdffit.schema import schema_of
    from brdffit.serialization import PLUGINS, builtin_kinds, model_registry

    reg = model_registry()
    ours = {k for k, c in reg.items() if c.__module__.startswith("brdffit.")}
    assert set(builtin_kinds()) <= ours
    # every kind brdffit registers is in the plugin table, so a fresh process can load it
    assert ours <= set(PLUGINS), sorted(ours - set(PLUGINS))
    for kind in sorted(ours):
        assert schema_of(reg[kind]) is not None, kind
        assert reg[kind].has_schema()

    import brdffit.microfacet.sgd  # noqa: F401  (registers sgd, sgd_eq9)
    import brdffit.microfacet.tabulated  # noqa: F401  (tabulated, tabulated_aniso, tabulated_merl)
    from brdffit.microfacet import model as mm

    comps = {**{f"distribution:{k}": c for k, c in mm._DISTRIBUTIONS.items()},
             **{f"fresnel:{k}": c for k, c in mm._FRESNELS.items()}}
    builtin = {k: c for k, c in comps.items() if c.__module__.startswith("brdffit.")}
    assert len(builtin) >= 12
    for name, cls in sorted(builtin.items()):
        assert schema_of(cls) is not None, name


# ------------------------------------------------------------------------------------------
# real instances of every kind round-trip through the schema
# ------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def real_models():
    """One real instance (synthetic materials and quick fits of them) per kind and layout."""
    from brdffit.fit.npf import fit_npf
    from brdffit.fit.sgd import fit_sgd
    from brdffit.fit.tabulated import fit_ggx, fit_tabulated
    from brdffit.grid import tabulate_merl_grid

    s = brdffit.synthetic
    models = {name: s(name) for name in brdffit.list_synthetic()}
    models["fit-tabulated"] = fit_tabulated(s("gold-ggx"), n=32)
    models["fit-tabulated-per-channel"] = fit_tabulated(s("gold-ggx"), n=32, per_channel=True)
    models["fit-tabulated-aniso"] = fit_tabulated(s("aniso-ggx"), n=16, n_phi=16)
    models["fit-ggx"] = fit_ggx(s("plastic-beckmann"), n=32)
    models["fit-sgd"] = fit_sgd(s("sgd-paint"), starts=1)
    data = tabulate_merl_grid(s("plastic-beckmann"))
    models["fit-npf-bivariate"] = fit_npf(data=data, variant="bivariate")
    models["fit-npf-naive"] = fit_npf(data=data, variant="naive", max_iter=3)
    models["fit-npf-g-from-d"] = fit_npf(data=data, variant="g-from-d", max_iter=3, polish=0)
    models["fit-npf-independent-g"] = fit_npf(data=data, variant="independent-g",
                                              starts=("ones",), max_iter=3, start_max_iter=3,
                                              polish=0)
    return models


def test_real_fits_round_trip_through_validation(real_models, tmp_path):
    from brdffit.serialization import builtin_kinds

    assert {m.fit_kind for m in real_models.values()} == set(builtin_kinds())
    rng = np.random.default_rng(0)
    wi, wo = _dirs(rng, 300), _dirs(rng, 300)
    for name, model in real_models.items():
        path = save_fit(model, tmp_path / f"{name}.npz")
        header, arrays = _raw(path)
        cls = type(model)
        # the file's own state passes its schema, on headers only and on the values
        from brdffit.schema import ArrayHeader

        cls.validate_state(header["params"], {k: ArrayHeader(v.shape, v.dtype)
                                              for k, v in arrays.items()})
        cls.validate_state(header["params"], arrays)
        back = load_fit(path)
        assert back.fit_kind == model.fit_kind, name
        np.testing.assert_allclose(back.eval(wi, wo), model.eval(wi, wo), rtol=2e-6, atol=1e-9,
                                   err_msg=name)
        _, a2 = back.to_state()
        for k, v in arrays.items():
            np.testing.assert_array_equal(np.asarray(a2[k]), v, err_msg=f"{name}: {k}")


def test_minimal_version_1_header_still_loads(tmp_path):
    """A version-1 file with only the keys the format requires (no name, source, options,
    fit_info, brdffit_version, created) loads, and its schema accepts it."""
    from brdffit.microfacet import GGX, MicrofacetBRDF, SchlickFresnel

    model = MicrofacetBRDF(GGX(0.2), SchlickFresnel(0.05))
    params, arrays = model.to_state()
    header = {"format": "brdffit-fit", "version": 1, "model": "microfacet", "params": params}
    path = mf.write_npz(tmp_path / "minimal.npz", header, arrays)
    MicrofacetBRDF.validate_state(json.loads(json.dumps(header))["params"], arrays)
    back = load_fit(path)
    assert back.distribution.alpha_x == 0.2
    assert read_fit_header(path)["version"] == 1


# ------------------------------------------------------------------------------------------
# invalid states are not written
# ------------------------------------------------------------------------------------------
def test_save_fit_refuses_a_state_that_would_not_load(tmp_path):
    from brdffit.microfacet import GGX, MicrofacetBRDF, TabulatedFresnel

    t = np.linspace(0, np.pi / 2, 8)
    bad = [MicrofacetBRDF(GGX(1e300)),                                   # α out of range
           MicrofacetBRDF(GGX(0.2), TabulatedFresnel(t, -1.9 * np.ones((8, 3))))]
    for k, model in enumerate(bad):
        path = tmp_path / f"bad{k}.npz"
        with pytest.raises(BRDFFormatError, match="would not load") as info:
            save_fit(model, path)
        assert "\n" not in str(info.value)
        assert not path.exists()
        assert list(tmp_path.iterdir()) == []


def test_parameter_json_states_are_checked_by_the_same_schema(tmp_path):
    """``brdffit export`` also reads parameter JSON (``state`` = params + arrays): the same
    schema applies."""
    from brdffit.export.json_params import from_json_dict, to_json_dict
    from brdffit.microfacet import GGX, MicrofacetBRDF, SchlickFresnel

    doc = to_json_dict(MicrofacetBRDF(GGX(0.2), SchlickFresnel(0.05)))
    assert from_json_dict(json.loads(json.dumps(doc))).distribution.alpha_x == 0.2
    doc["state"]["params"]["distribution"]["params"]["alpha_x"] = 1e300
    with pytest.raises(BRDFFormatError, match=r"params\.distribution\.params\.alpha_x"):
        from_json_dict(doc, path=tmp_path / "p.json")


# ------------------------------------------------------------------------------------------
# exporting a lying file fails like loading it
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["fresnel-negative", "alpha-1e300", "version-true"])
def test_export_of_an_invalid_fit_fails_cleanly(name, tmp_path):
    case = {c.name: c for c in mf.cases()}[name]
    bad = case.write(tmp_path)
    work = tmp_path / "work"
    work.mkdir()
    out = run_limited(["export", str(bad), "--to", "json", "-o", "out.json"], cwd=work)
    assert out.problems(names=bad.name, out_dir=work) == []
    for phrase in case.mentions:
        assert phrase in out.stderr


# ------------------------------------------------------------------------------------------
# layering: io is below the model packages
# ------------------------------------------------------------------------------------------
def _fresh(code: str) -> str:
    res = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True,
                         text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    return res.stdout


def test_layering_is_one_way_and_every_kind_still_loads(real_models, tmp_path):
    """``brdffit.io.fitfile`` imports neither ``brdffit.microfacet`` nor ``brdffit.fit``, the
    model packages do not import ``brdffit.io``, the fitting modules import no reader (only
    the package, for ``brdffit.fit("spec")`` through ``brdffit.loading``), and in a fresh
    process every kind loads (the loader imports the kind's module by name from the plugin
    table)."""
    out = _fresh("""
        import sys
        import brdffit.io.fitfile
        print(sorted(m for m in sys.modules
                     if m.startswith(("brdffit.microfacet", "brdffit.fit"))))
    """)
    assert out.strip() == "[]"
    out = _fresh("""
        import sys
        import brdffit.microfacet, brdffit.microfacet.model, brdffit.microfacet.npf_model
        import brdffit.microfacet.sgd, brdffit.microfacet.tabulated
        print(sorted(m for m in sys.modules if m.startswith("brdffit.io")))
        import brdffit.fit.tabulated, brdffit.fit.sgd
        print(sorted(m for m in sys.modules if m.startswith("brdffit.io.")))
    """)
    assert out.strip().splitlines() == ["[]", "[]"]
    paths = {name: str(save_fit(model, tmp_path / f"{name}.npz"))
             for name, model in real_models.items()}
    out = _fresh(f"""
        from brdffit.io.fitfile import load_fit
        for name, p in {paths!r}.items():
            print(name, load_fit(p).fit_kind)
    """)
    got = dict(line.split() for line in out.strip().splitlines())
    assert got == {n: m.fit_kind for n, m in real_models.items()}
