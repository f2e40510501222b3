"""Exit codes of the CLI (issue 12 §3): 0 all done, 1 error, 2 usage, 3 some tasks failed."""

from __future__ import annotations

import pytest

from brdffit.cli import main


def test_help_documents_the_exit_codes(capsys):
    assert main(["--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    for item in ("0 all done", "1 error", "2 usage", "3 some tasks failed"):
        assert item in text


def test_batch_with_an_unknown_model_is_a_usage_error(tmp_path, capsys):
    out = tmp_path / "out"
    rc = main(["batch", "synthetic:gold-ggx", "--models", "ggx,nope", "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 2 and "nope" in err and "tabulated" in err  # lists the known models
    assert not out.exists()  # refused before doing anything


def test_compare_with_an_unknown_model_is_a_usage_error(tmp_path, capsys):
    rc = main(["compare", "synthetic:gold-ggx", "--models", "nope", "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert rc == 2 and "nope" in err and "tabulated" in err
    assert not (tmp_path / "r").exists()


def test_demo_with_an_unknown_model_is_a_usage_error(tmp_path, capsys):
    rc = main(["demo", "--models", "nope", "--out", str(tmp_path / "d")])
    assert rc == 2 and "nope" in capsys.readouterr().err


@pytest.mark.parametrize("option", ["bogus=1", "n_phi=8", "bogus"])
def test_fit_with_an_unknown_option_names_it_and_the_accepted_ones(option, capsys):
    rc = main(["fit", "synthetic:gold-ggx", "--model", "ggx", "--option", option])
    err = capsys.readouterr().err
    if option == "n_phi=8":  # a real option of the GGX fit (forwarded to fit_tabulated)
        assert rc == 0, err
        return
    assert rc == 2 and "Traceback" not in err and "bogus" in err
    if "=" in option:
        assert "iterations" in err and "n_phi" in err  # the accepted options


def test_bad_values_are_usage_errors(tmp_path, capsys):
    assert main(["batch", "synthetic:gold-ggx", "--models", "ggx", "--out", str(tmp_path / "o"),
                 "--workers", "0"]) == 2
    assert main(["batch", "synthetic:gold-ggx", "--models", "ggx", "--out", str(tmp_path / "o"),
                 "--memory-limit", "lots"]) == 2
    assert main(["batch", "synthetic:gold-ggx", "--models", "ggx", "--out", str(tmp_path / "o"),
                 "--render", "--scenes", "nope"]) == 2
    assert main(["render", "synthetic:gold-ggx", "-o", str(tmp_path / "x.jpg")]) == 2
    assert main(["convert", "synthetic:gold-ggx", str(tmp_path / "x.png")]) == 2
    assert not any(tmp_path.iterdir())
    assert "Traceback" not in capsys.readouterr().err


def test_batch_with_a_failed_task_exits_3(tmp_path, capsys):
    lst = tmp_path / "list.txt"
    lst.write_text("synthetic:gold-ggx\n" + str(tmp_path / "missing.binary") + "\n")
    argv = ["batch", str(lst), "--models", "ggx", "--out", str(tmp_path / "out"), "-q",
            "--workers", "1", "--no-metrics"]
    assert main(argv) == 3
    assert "1 failed" in capsys.readouterr().out
    assert main(argv) == 3  # the resume still says the output is incomplete
    assert main(argv + ["--only", "gold-ggx"]) == 0


def test_unexpected_exceptions_are_one_line(monkeypatch, capsys):
    from brdffit.cli import info

    def boom(*a, **k):
        raise RuntimeError("kaboom")

    monkeypatch.setattr(info, "summarize", boom)
    assert main(["info", "synthetic:gold-ggx"]) == 1
    err = capsys.readouterr().err
    assert "kaboom" in err and "Traceback" not in err and err.count("\n") <= 2
