"""bench/README.md is what ``bench/readme.py`` writes from the result files, and the generator
knows every benchmark, study and result file."""

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench"


def _readme_module():
    spec = importlib.util.spec_from_file_location("bench_readme", BENCH / "readme.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def test_readme_is_generated_from_the_results():
    readme = _readme_module()
    assert (BENCH / "README.md").read_text() == readme.render(), \
        "bench/README.md is out of date: run .venv/bin/python bench/readme.py"


def test_every_script_and_result_file_has_an_entry():
    readme = _readme_module()
    entries = readme.BENCHMARKS + readme.STUDIES
    names = {e.name for e in entries}
    scripts = {p.stem.removeprefix("bench_") for p in BENCH.glob("bench_*.py")}
    studies = {p.stem for p in (BENCH / "studies").glob("*.py")} - {"fit_database",
                                                                     "render_completed"}
    assert scripts <= names, f"benchmarks without an entry: {sorted(scripts - names)}"
    assert studies <= names, f"studies without an entry: {sorted(studies - names)}"
    listed = {f for e in entries for f in e.results}
    files = {p.name for p in (BENCH / "results").iterdir() if p.name != "all.json"}
    assert files <= listed, f"result files no entry lists: {sorted(files - listed)}"


def test_a_headline_that_no_longer_reads_its_file_is_an_error(tmp_path):
    readme = _readme_module()
    (tmp_path / "io.json").write_text('{"renamed": 1}')
    entry = next(e for e in readme.BENCHMARKS if e.name == "io")
    try:
        readme.headline(entry, tmp_path)
    except ValueError as exc:
        assert "io.json" in str(exc)
    else:
        raise AssertionError("a headline without its fields must fail")
