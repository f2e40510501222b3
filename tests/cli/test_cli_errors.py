"""The CLI's error contract: one line on stderr, non-zero status, no traceback (unless --debug)."""

import pytest

from brdffit.cli import main


@pytest.mark.parametrize("argv, code", [
    (["info", "--bogus"], 2),                         # usage error (Typer's vendored Click)
    (["fit", "synthetic:gold-ggx", "--model", "nope"], 2),
    (["info", "/nonexistent/file.binary"], 1),          # library error
])
def test_errors_are_short_and_have_a_status(argv, code, capsys):
    assert main(argv) == code
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.strip()


def test_debug_shows_the_traceback():
    with pytest.raises(Exception, match="no such file"):
        main(["--debug", "info", "/nonexistent/file.binary"])


def test_an_unknown_option_is_reported_under_its_command(capsys):
    assert main(["fit", "synthetic:gold-ggx", "--mod", "ggx"]) == 2  # no abbreviations
    err = capsys.readouterr().err
    assert "usage: brdffit fit" in err and "unrecognized arguments: --mod ggx" in err


def test_version(capsys):
    from brdffit import __version__

    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"brdffit {__version__}"
