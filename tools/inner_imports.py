"""List the imports of brdffit's own modules made inside functions (docs/design/lazy-imports.md).

    python tools/inner_imports.py [src/brdffit] [-v]

Prints the total, the count per package and per file; ``-v`` lists each import
(file, line, importing module, imported module).
"""

from __future__ import annotations

import ast
import collections
import sys
from pathlib import Path


def _module(path: Path, root: Path) -> tuple[str, bool]:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    is_package = parts[-1] == "__init__"
    return ".".join(parts[:-1] if is_package else parts), is_package


def _imported(node: ast.Import | ast.ImportFrom, module: str, is_package: bool) -> list[str]:
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    if not node.level:
        return [node.module or ""]
    base = module.split(".") if is_package else module.split(".")[:-1]
    base = base[:len(base) - (node.level - 1)]
    if node.module:
        return [".".join(base + [node.module])]
    return [".".join(base + [alias.name]) for alias in node.names]  # from . import a, b


def inner_imports(root: Path) -> list[tuple[str, int, str, str]]:
    found = []
    for path in sorted(root.rglob("*.py")):
        module, is_package = _module(path, root)

        class Visitor(ast.NodeVisitor):
            depth = 0

            def visit_FunctionDef(self, node):
                self.depth += 1
                self.generic_visit(node)
                self.depth -= 1

            visit_AsyncFunctionDef = visit_FunctionDef

            def visit_Import(self, node):
                if self.depth:
                    found.extend((str(path), node.lineno, module, target)
                                 for target in _imported(node, module, is_package)
                                 if target.split(".")[0] == "brdffit")

            visit_ImportFrom = visit_Import

        Visitor().visit(ast.parse(path.read_text(encoding="utf-8")))
    return found


def main(argv: list[str]) -> None:
    args = [a for a in argv if not a.startswith("-")]
    root = Path(args[0] if args else Path(__file__).resolve().parents[1] / "src" / "brdffit")
    found = inner_imports(root.resolve())
    if "-v" in argv:
        for row in found:
            print(*row)
    packages = collections.Counter(m.split(".")[1] for _, _, m, _ in found)
    print("total", len(found))
    print("per package:", dict(packages.most_common()))
    for path, n in collections.Counter(p for p, *_ in found).most_common():
        print(n, path)


if __name__ == "__main__":
    main(sys.argv[1:])
