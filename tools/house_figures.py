"""The figures of the package's structure: lines per layer, the functions above a length,
and the in-function imports of the project's own modules (``tools/inner_imports.py``).

    python tools/house_figures.py [src/brdffit] [--longest 80] [--json]

Lines are physical lines of ``.py`` files; a layer is a top-level module or package of
``brdffit`` (the layers of ``[tool.importlinter]`` in pyproject.toml); a function's length is
``end_lineno - lineno + 1`` of its ``def`` (docstring included).
"""

from __future__ import annotations

import argparse
import ast
import collections
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from inner_imports import inner_imports  # noqa: E402


def lines_per_layer(root: Path) -> dict[str, int]:
    """Physical lines per top-level module or package of ``root``."""
    out: collections.Counter = collections.Counter()
    for path in root.rglob("*.py"):
        layer = path.relative_to(root).parts[0].removesuffix(".py")
        out[layer] += len(path.read_text(encoding="utf-8").splitlines())
    return dict(sorted(out.items(), key=lambda kv: -kv[1]))


def long_functions(root: Path, limit: int) -> list[tuple[int, str, str]]:
    """``(lines, file, name)`` of every function longer than ``limit`` lines, longest first."""
    rows = []
    for path in sorted(root.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > limit:
                    rows.append((n, str(path.relative_to(root.parent)), node.name))
    return sorted(rows, reverse=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("root", nargs="?", default=str(Path(__file__).resolve().parents[1]
                                                   / "src" / "brdffit"))
    ap.add_argument("--longest", type=int, default=80)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    root = Path(args.root)
    layers = lines_per_layer(root)
    longest = long_functions(root, args.longest)
    inner = inner_imports(root.resolve())
    figures = {"lines_total": sum(layers.values()), "lines_per_layer": layers,
               f"functions_above_{args.longest}_lines": [
                   {"lines": n, "file": f, "function": name} for n, f, name in longest],
               "in_function_imports": len(inner)}
    if args.json:
        print(json.dumps(figures, indent=1))
        return 0
    print(f"lines: {figures['lines_total']}  "
          + ", ".join(f"{k} {v}" for k, v in layers.items()))
    print(f"functions above {args.longest} lines: {len(longest)}")
    for n, f, name in longest:
        print(f"  {n:4d} {f} {name}")
    print(f"in-function imports of brdffit modules: {len(inner)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
