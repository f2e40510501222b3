"""Build the report's live viewer bundle (docs/design/report-viewer.md).

    python tools/build_viewer_bundle.py [--out PATH] [--npm-prefix .npm]

esbuild (``make npmdeps``: ``ESBUILD_VERSION`` of the Makefile) bundles
``src/brdffit/evaluation/engines/threejs_page/viewer.js`` with three (``THREE_VERSION``),
its ``OrbitControls`` and ``GLTFLoader`` into one minified classic script (an IIFE, no
``import``: Chromium runs it from ``file://``), three's MIT licence comment kept at the end
(``--legal-comments=eof``). The default output is the committed
``threejs_page/vendor/viewer.bundle.js``; the same versions give the same bytes, which
tests/evaluation/test_report_viewer.py checks when ``.npm`` holds them.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "src" / "brdffit" / "evaluation" / "engines" / "threejs_page"
ENTRY = PAGE / "viewer.js"
BUNDLE = PAGE / "vendor" / "viewer.bundle.js"
#: the bundle's header: what it holds, at which versions (checked against .npm)
HEADER = ("/* brdffit report viewer: viewer.js + three {three} (MIT, three.js authors) "
          "OrbitControls, GLTFLoader; bundled by esbuild {esbuild} "
          "(tools/build_viewer_bundle.py) */")


def versions(npm_prefix: Path) -> dict[str, str]:
    """Versions of the ``three`` and ``esbuild`` packages under ``npm_prefix/node_modules``."""
    mods = npm_prefix / "node_modules"
    return {name: json.loads((mods / name / "package.json").read_text())["version"]
            for name in ("three", "esbuild")}


def esbuild_args(npm_prefix: Path, out: Path) -> list[str]:
    """The esbuild command line (run from the source tree's root)."""
    v = versions(npm_prefix)
    return [str(npm_prefix / "node_modules" / ".bin" / "esbuild"),
            str(ENTRY.relative_to(ROOT)), "--bundle", "--format=iife", "--minify",
            "--target=es2020", "--legal-comments=eof", "--charset=utf8",
            "--banner:js=" + HEADER.format(three=v["three"], esbuild=v["esbuild"]),
            f"--outfile={out}", "--log-level=warning"]


def build(out: Path = BUNDLE, npm_prefix: Path = ROOT / ".npm") -> Path:
    """Write the bundle to ``out``; ``RuntimeError`` with esbuild's message when it fails."""
    npm_prefix = Path(npm_prefix).resolve()
    env = dict(os.environ, NODE_PATH=str(npm_prefix / "node_modules"))
    proc = subprocess.run(esbuild_args(npm_prefix, Path(out).resolve()), cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=120)
    if proc.returncode != 0:
        raise RuntimeError(f"esbuild failed ({proc.returncode}): {proc.stderr[-2000:]}")
    return Path(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=BUNDLE)
    ap.add_argument("--npm-prefix", type=Path, default=ROOT / ".npm")
    a = ap.parse_args(argv)
    path = build(a.out, a.npm_prefix)
    print(f"{path}: {path.stat().st_size} bytes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
