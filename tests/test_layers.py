"""The import contracts of pyproject.toml ([tool.importlinter]) hold: the layers of the package
import only downwards (imports inside functions included) and the product does not import its
test kit. A broken contract fails with import-linter's report: which module imports which,
by which chain and at which lines."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import brdffit

PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"


def test_import_contracts_hold():
    # the brdffit these tests import is the one analysed (a work tree may shadow the install)
    src = str(Path(brdffit.__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([src, os.environ.get("PYTHONPATH", "")])}
    res = subprocess.run([sys.executable, "-c", "from importlinter.cli import lint_imports_command;"
                          " lint_imports_command()", "--no-cache", "--no-logo", str(PYPROJECT)],
                         capture_output=True, text=True, env=env, timeout=300)
    assert res.returncode == 0, res.stdout + res.stderr
