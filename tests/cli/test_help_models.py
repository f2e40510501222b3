"""A CLI that explains itself (issue 16.1): every --help at 80 columns, the model list with
descriptions from the registry, defaults, `brdffit models`; the registry's declared models
match what the fitting modules register."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from brdffit.cli import main
from brdffit.fit import registry

COMMANDS = ["info", "convert", "fit", "models", "render", "compare", "batch", "export", "demo"]
WITH_MODELS = ["fit", "compare", "batch", "demo"]


def _help(argv, monkeypatch, capsys) -> list[str]:
    monkeypatch.setenv("COLUMNS", "80")
    assert main(argv + ["--help"]) == 0
    return capsys.readouterr().out.splitlines()


@pytest.mark.parametrize("command", [[]] + [[c] for c in COMMANDS])
def test_help_reads_well_at_80_columns(command, monkeypatch, capsys):
    lines = _help(command, monkeypatch, capsys)
    text = "\n".join(lines)
    assert lines and all(len(line) <= 80 for line in lines), \
        [ln for ln in lines if len(ln) > 80]
    for noise in ("<bool>", "<str>", "<int", "<path>", "<list", "<float>"):
        assert noise not in text, noise
    broken = [ln for ln in lines if ln.rstrip().endswith("-") and ln.rstrip()[-2:-1].isalpha()]
    assert not broken, broken  # names such as sphere-courtyard are not cut at the hyphen
    assert "..." not in "".join(ln for ln in lines if ln.startswith("  ") and
                                ln.strip().split(" ")[0] in COMMANDS)  # no cut summaries


@pytest.mark.parametrize("command", [[]] + [[c] for c in WITH_MODELS])
def test_help_lists_every_model_with_its_description(command, monkeypatch, capsys):
    text = "\n".join(_help(command, monkeypatch, capsys))
    for name in registry.known_names():
        info = registry.MODELS[name]
        assert f"  {name}" in text and info.description in text, name


def test_help_shows_defaults(monkeypatch, capsys):
    text = " ".join(" ".join(_help(["fit"], monkeypatch, capsys)).split())
    assert "[default: ggx-diffuse]" in text
    text = " ".join(" ".join(_help(["batch"], monkeypatch, capsys)).split())
    assert "[default: ggx-diffuse,tabulated,ggx,beckmann]" in text and "[default: 2; 1..256]" in text


def test_batch_help_does_not_send_to_fit_help(monkeypatch, capsys):
    text = "\n".join(_help(["batch"], monkeypatch, capsys))
    assert "fit --help" not in text and "summary.csv" in text


def test_models_table(monkeypatch, capsys):
    monkeypatch.setenv("COLUMNS", "80")
    assert main(["models"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert all(len(line) <= 80 for line in lines), [ln for ln in lines if len(ln) > 80]
    text = "\n".join(lines)
    for name, info in registry.MODELS.items():
        assert f"\n{name:<17}{'yes' if info.isotropic_only else 'no':<4}" in text, name
    assert "Dupuy 2015:" in text and "Bagher 2016:" in text  # references under the table
    assert registry.TYPICAL_SOURCE.split(":")[0] in " ".join(text.split())


def test_models_json_rows_come_from_the_registry(capsys):
    assert main(["models", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    rows = {r["name"]: r for r in data["models"]}
    assert list(rows) == registry.known_names()
    for name, r in rows.items():
        info = registry.MODELS[name]
        assert (r["isotropic_only"], r["fit_file_bytes"], r["fit_cpu_s"]) == (
            info.isotropic_only, info.typical_bytes, info.typical_time_s)
        assert r["references"] and r["figures"] == "declared"


def test_models_measure(capsys):
    assert main(["models", "--measure", "--models", "ggx,sgd", "--json"]) == 0
    rows = {r["name"]: r for r in json.loads(capsys.readouterr().out)["models"]}
    assert set(rows) == {"ggx", "sgd"}
    for r in rows.values():
        assert r["figures"] == "measured on synthetic:gold-ggx"
        assert r["fit_cpu_s"] > 0 and r["fit_file_bytes"] > r["table_bytes"] >= 0
        assert 0 <= r["cos_rel_error"] < 0.5
    assert rows["ggx"]["cos_rel_error"] < 0.01  # gold-ggx is a GGX material


def test_models_measure_says_when_a_model_does_not_apply(capsys):
    assert main(["models", "--measure", "-m", "sgd", "--on", "synthetic:aniso-ggx",
                 "--json"]) == 0
    (row,) = json.loads(capsys.readouterr().out)["models"]
    assert "isotropic inputs only" in row["error"] and row["fit_cpu_s"] is None


def test_models_with_an_unknown_name_is_a_usage_error(capsys):
    assert main(["models", "-m", "nope"]) == 2
    assert "nope" in capsys.readouterr().err


def test_every_declared_model_resolves_to_its_module():
    """Each "module:function" of MODELS names a function of that module, and its summary;
    resolving one imports the fitting stack only then."""
    import inspect

    for name, info in registry.MODELS.items():
        fitter = registry.get(name)
        assert inspect.unwrap(fitter.fit).__module__.startswith(f"brdffit.fit.{info.module}")
        assert fitter.isotropic_only == info.isotropic_only and callable(fitter.summary)
        assert inspect.unwrap(fitter.fit).__name__ == info.function.split(":")[1], name
    for info in registry.MODELS.values():
        assert len(info.description) <= 58 and "\n" not in info.description
        assert all(k.strip() in registry.PAPERS for k in info.paper.split(","))


def test_declared_typical_figures_are_the_bench_measurements():
    """The sizes and times `brdffit models` shows are those bench/bench_cli.py --models
    measured (bench/results/cli.json), not typed in."""
    path = Path(__file__).resolve().parents[2] / "bench" / "results" / "cli.json"
    if not path.is_file():
        pytest.skip("bench/results/cli.json not present")
    measured = json.loads(path.read_text())["models"]["figures"]
    for name, info in registry.MODELS.items():
        m = measured[name]
        assert (info.typical_bytes, info.typical_table_bytes) == (m["fit_file_bytes"],
                                                                  m["table_bytes"]), name
        assert info.typical_time_s == float(f"{m['fit_cpu_s']:.2g}"), name


def test_models_options_come_from_the_options_dataclasses(monkeypatch, capsys):
    """`brdffit models --options` lists each model's command-line options from its options
    dataclass, with its default and range, within 80 columns."""
    import dataclasses

    from brdffit.fit import options as fit_options

    monkeypatch.setenv("COLUMNS", "80")
    assert main(["models", "--options", "-m", "tabulated,npf"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert all(len(line) <= 80 for line in lines)
    text = "\n".join(lines)
    assert "-O n (int, default 90, in [8, 1024])" in text
    assert "-O seed (int, default 0, in [0, 4294967295])" in text
    assert "callback" not in text and "verbose" not in text      # Python-only options
    assert main(["models", "--json", "--options", "-m", "ggx-ct"]) == 0
    (row,) = json.loads(capsys.readouterr().out)["models"]
    assert [(o["name"], o["default"]) for o in row["options"]] == [
        (f.name, f.default) for f in dataclasses.fields(fit_options.CookTorranceOptions)]


def test_typical_figures_are_absent_without_the_bench_results(monkeypatch, tmp_path):
    """An installed package has no bench/: the typical figures are then None ("–")."""
    monkeypatch.setattr(registry, "TYPICAL_FILE", tmp_path / "missing.json")
    registry.typical_figures.cache_clear()
    try:
        assert registry.typical_figures() == {}
        assert registry.MODELS["ggx"].typical_time_s is None
    finally:
        monkeypatch.undo()
        registry.typical_figures.cache_clear()
    assert registry.MODELS["ggx"].typical_time_s is not None


def test_help_lists_every_environment_variable_the_package_reads(monkeypatch, capsys):
    """``brdffit --help`` lists each ``BRDFFIT_*`` variable that some module of the package
    reads (found in the source, so a new one cannot be left out) with what it does."""
    import re

    import brdffit
    from brdffit.cli import ENVIRONMENT

    src = Path(brdffit.__file__).parent
    read = {m for f in src.rglob("*.py")
            for m in re.findall(r"\bBRDFFIT_[A-Z_]+[A-Z]\b", f.read_text(encoding="utf-8"))}
    assert read and read == set(ENVIRONMENT), read ^ set(ENVIRONMENT)
    lines = _help([], monkeypatch, capsys)
    start = lines.index("Environment:")
    listed = [ln.split()[0] for ln in lines[start + 1:start + 1 + len(ENVIRONMENT)]]
    assert listed == list(ENVIRONMENT)
