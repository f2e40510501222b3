"""Names from files never reach a terminal, a log, CSV or HTML with their control
characters (issue 32.4): ESC sequences, newlines, NUL-free but bidi-overriding names."""

from __future__ import annotations

import csv
import json

import pytest

from brdffit.cli import main
from brdffit.errors import csv_cell, printable

HOSTILE = "evil\x1b[2J\u202ename\x07"
RAW = ("\x1b", "\u202e", "\x07")


@pytest.fixture(scope="module")
def hostile_file(tmp_path_factory):
    folder = tmp_path_factory.mktemp("hostile")
    path = folder / f"{HOSTILE}.binary"
    assert main(["convert", "synthetic:gold-ggx", str(path)]) == 0
    return path


def _clean(text: str) -> None:
    assert not any(c in text for c in RAW), repr(text)


def test_printable_and_csv_cell():
    assert printable("a\x1b[2Jb\nc\u202e") == "a\\x1b[2Jb\\nc\\u202e"
    assert csv_cell("=HYPERLINK(\"x\")") == "'=HYPERLINK(\"x\")"
    assert csv_cell("-0.5") == "-0.5" and csv_cell(0.25) == 0.25 and csv_cell(None) is None


def test_info_fit_and_errors_print_escaped_names(hostile_file, capsys):
    assert main(["info", str(hostile_file), "--albedo-samples", "256"]) == 0
    out = capsys.readouterr().out
    _clean(out)
    assert "evil\\x1b[2J\\u202ename\\x07" in out
    assert main(["fit", str(hostile_file), "-m", "ggx", "--no-error"]) == 0
    _clean(capsys.readouterr().out)
    missing = hostile_file.with_name(f"missing{HOSTILE}.binary")
    assert main(["info", str(missing)]) == 1
    err = capsys.readouterr().err
    _clean(err)
    assert len(err.strip().splitlines()) == 1


@pytest.mark.slow
def test_batch_log_summary_csv_and_report_hold_no_control_characters(hostile_file, tmp_path,
                                                                      capsys):
    out = tmp_path / "runs"
    assert main(["batch", str(hostile_file.parent), "--models", "ggx", "--workers", "1",
                 "--quiet", "--out", str(out)]) == 0
    _clean((out / "batch.log").read_text(encoding="utf-8"))
    rows = list(csv.DictReader((out / "summary.csv").open(encoding="utf-8")))
    assert rows and all(not any(c in v for c in RAW) for r in rows for v in r.values() if v)
    assert any("\\x1b" in r["material"] for r in rows)
    assert main(["compare", str(hostile_file), "--models", "ggx", "--spp", "2", "--resolution",
                 "16", "--scenes", "sphere-studio", "--out", str(tmp_path / "cmp")]) == 0
    captured = capsys.readouterr()
    _clean(captured.out + captured.err)
    for page in (tmp_path / "cmp").rglob("*.html"):
        _clean(page.read_text(encoding="utf-8"))
    for res in (tmp_path / "cmp").rglob("result.json"):  # the data keeps the exact name
        assert json.loads(res.read_text())["material"].startswith("evil\x1b")
