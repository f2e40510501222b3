"""The top-level Python API: brdffit.fit(brdf, model=...), one naming scheme, FitResult."""

from __future__ import annotations

import doctest
import subprocess
import sys

import numpy as np
import pytest

import brdffit
from brdffit.fit import registry

FAST = {"npf-g-from-d": {"max_iter": 4, "polish": 0}, "npf-naive": {"max_iter": 4}}


def test_fit_is_callable_and_stays_a_package():
    assert callable(brdffit.fit)
    import brdffit.fit.registry as reg        # the submodules are still there

    assert reg is registry and brdffit.fit.registry is registry
    assert callable(brdffit.fit)              # importing a submodule does not undo it


@pytest.mark.parametrize("model", ["tabulated", "ggx", "ggx-diffuse", "sgd", "npf-g-from-d",
                                   "npf-naive", "npf-bivariate"])
def test_fit_by_name_equals_the_registry_fitter_and_reports(model):
    ref = brdffit.synthetic("gold-ggx")
    fitted = brdffit.fit(ref, model=model, **FAST.get(model, {}))
    direct, _ = registry.fit_model(model, ref, FAST.get(model, {}))
    wi = np.array([[0.3, 0.1, 0.95]]) / np.linalg.norm([0.3, 0.1, 0.95])
    wo = np.array([[-0.2, 0.3, 0.93]]) / np.linalg.norm([-0.2, 0.3, 0.93])
    np.testing.assert_allclose(fitted.eval(wi, wo), direct.eval(wi, wo), rtol=1e-12)
    res = brdffit.fit_result(fitted)
    info = fitted.fit_info
    assert res.model is fitted and res.fit_info is info
    assert res.time is not None and res.time > 0
    if "converged" in info:
        assert res.converged == info["converged"] and res.nit == info["nit"]
    if model.startswith("npf-") and model != "npf-bivariate":
        polished = info.get("polish", {}).get("iterations", 0)     # G-from-D's LM polish
        assert res.nit == info["iterations"] + polished
        assert res.fun == pytest.approx(info["objective"])
        assert res.converged == info["stop_reason"].startswith(("relative", "damping limit",
                                                                "exact fit"))
        assert res.success == res.converged
    if model == "npf-bivariate":
        # one linear solve: exact by construction, reported converged by fit_npf's fit_info
        assert res.success and res.converged is not False and "closed form" in res.message
    if model == "ggx-diffuse":
        assert res.fun == pytest.approx(info["objective"]) and res.converged is None
    assert isinstance(res.message, str) and res.message
    assert "success" in repr(res)
    # the fitter recorded its result in one shape; the method's own keys give the same
    from brdffit.fit.result import RESULT_FIELDS, _legacy_fields

    assert list(info["result"]) == list(RESULT_FIELDS) and res.info is info
    assert {k: getattr(res, k) for k in RESULT_FIELDS} == _legacy_fields(info)
    assert "time_s" not in info and res.time == info["time"]


def test_the_recorded_result_is_read_and_saved_and_old_fit_files_still_give_one(tmp_path):
    """fit_result reads the fitter's record (not the method's keys); the record is saved
    in the fit file; a file written before fits recorded it (NPF: ``time_s``) still gives
    its result from the method's keys."""
    import json
    import zipfile

    from brdffit.io.fitfile import load_fit, save_fit

    m = brdffit.fit("synthetic:gold-ggx", model="npf-naive", max_iter=3)
    m.fit_info["nit"] = 10**6                     # the method's key; the record stands
    assert brdffit.fit_result(m).nit == m.fit_info["result"]["nit"] != 10**6
    path = save_fit(m, tmp_path / "new.npz")
    loaded = brdffit.fit_result(load_fit(path))
    assert loaded.nit == m.fit_info["result"]["nit"] and loaded.time == m.fit_info["time"]
    # the same file as written before: no record, NPF's time under "time_s"
    with zipfile.ZipFile(path) as z:
        members = {n: z.read(n) for n in z.namelist()}
    header = json.loads(np.load(path)["__header__"].tobytes())
    info = header["fit_info"]
    del info["result"]
    info["time_s"] = info.pop("time")
    info["nit"] = 7
    blob = json.dumps(header, sort_keys=True).encode()
    import io as _io

    buf = _io.BytesIO()
    np.save(buf, np.frombuffer(blob, dtype=np.uint8))
    members["__header__.npy"] = buf.getvalue()
    with zipfile.ZipFile(tmp_path / "old.npz", "w") as z:
        for n, data in members.items():
            z.writestr(n, data)
    old = brdffit.fit_result(load_fit(tmp_path / "old.npz"))
    assert old.nit == 7 and old.time == info["time_s"] and old.message == info["message"]
    # a record that is not one (a hand-edited file) falls back to the method's keys
    m.fit_info["result"] = {"success": "yes"}
    assert brdffit.fit_result(m).nit == 10**6


def test_capped_fit_is_reported_not_converged():
    m = brdffit.fit("synthetic:gold-ggx", model="tabulated", max_iterations=1, tol=1e-12)
    res = brdffit.fit_result(m)
    assert res.converged is False and res.success is False and "NOT converged" in res.message


def test_load_spec_and_unknown_model():
    m = brdffit.fit("synthetic:gold-ggx", model="ggx")
    assert m.distribution.alpha_x == pytest.approx(0.12, rel=1e-3)
    with pytest.raises(ValueError, match="unknown model 'nope'.*tabulated"):
        brdffit.fit("synthetic:gold-ggx", model="nope")
    with pytest.raises(ValueError, match="no fit_info"):
        brdffit.fit_result(brdffit.synthetic("gold-ggx"))


def test_npf_variants_accept_the_model_names():
    from brdffit.fit import fit_npf

    ref = brdffit.synthetic("gold-ggx")
    a = fit_npf(ref, variant="npf-naive", max_iter=3)
    b = fit_npf(ref, variant="naive", max_iter=3)
    assert a.fit_info["variant"] == b.fit_info["variant"] == "naive"
    assert a.fit_info["objective"] == b.fit_info["objective"]
    with pytest.raises(ValueError, match="npf-g-from-d"):
        fit_npf(ref, variant="g_from_d")


def test_docstring_examples_run():
    import importlib

    import brdffit.fit as fit_pkg
    from brdffit.fit import analytic, result, sgd, tabulated

    others = [importlib.import_module(f"brdffit.{m}") and sys.modules[f"brdffit.{m}"]
              for m in ("synthetic", "microfacet.fresnel", "evaluation.metrics")]
    for mod in (fit_pkg, result, tabulated, analytic, sgd, *others):
        failed, tried = doctest.testmod(mod, optionflags=doctest.ELLIPSIS)
        assert tried > 0 and failed == 0, mod.__name__


def test_import_brdffit_and_fit_attribute_do_not_import_numpy():
    code = ("import sys, brdffit; f = brdffit.fit; assert callable(f); "
            "print('numpy' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
