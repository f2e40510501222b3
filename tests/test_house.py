"""The house rules that a tool can check, besides the layers (tests/test_layers.py): no
function of ``src/brdffit`` above 80 lines, and at most 30 in-function imports of the
project's own modules, each listed in docs/design/lazy-imports.md."""

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "brdffit"


def _tool(name):
    sys.path.insert(0, str(ROOT / "tools"))
    try:
        spec = importlib.util.spec_from_file_location(name, ROOT / "tools" / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module
    finally:
        sys.path.remove(str(ROOT / "tools"))


def test_no_function_above_80_lines():
    longest = _tool("house_figures").long_functions(SRC, 80)
    assert longest == [], f"functions above 80 lines: {longest}"


def test_in_function_imports_are_few_and_listed():
    found = _tool("inner_imports").inner_imports(SRC.resolve())
    assert len(found) <= 30, f"{len(found)} in-function imports of brdffit modules (≤ 30)"
    doc = (ROOT / "docs" / "design" / "lazy-imports.md").read_text()
    files = {Path(path).relative_to(SRC.parent).as_posix() for path, *_ in found}
    unlisted = sorted(f for f in files if f.removeprefix("brdffit/") not in doc
                      and f not in doc)
    assert not unlisted, f"files with lazy imports not in docs/design/lazy-imports.md: {unlisted}"
