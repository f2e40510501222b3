"""Whether two runs of ``fit_database.py`` (two source trees, same materials and models) wrote
the same fits: every array of every fit file bit-identical, and the header equal once the
fields that measure time are left out.

Used to show that a change of structure leaves the fits alone::

    git worktree add /tmp/base REV
    nice .venv/bin/python /tmp/base/bench/studies/fit_database.py --models M --out /tmp/id-base
    nice .venv/bin/python bench/studies/fit_database.py --models M --out /tmp/id-head
    .venv/bin/python bench/studies/fit_identity.py /tmp/id-base /tmp/id-head

Writes ``bench/results/fit_identity.json``: one row per (material, model) found in both runs,
with the arrays and header fields that differ (empty when identical), and the counts: files
identical, files whose arrays are identical, the models whose arrays differ and the header
fields that differ (with how many files each).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "bench" / "results" / "fit_identity.json"

#: header keys whose values are measurements of time, not of the fit
TIME_KEYS = {"time", "time_s", "fit_time_s", "seconds", "cpu_s", "wall_s", "elapsed_s",
             "start_time", "saved", "created"}


def _without_time(obj):
    """``obj`` with every mapping entry whose key names a time measurement removed."""
    if isinstance(obj, dict):
        return {k: _without_time(v) for k, v in obj.items()
                if k not in TIME_KEYS and not k.startswith("time_")
                and not k.endswith(("_time_s", "_seconds"))}
    if isinstance(obj, list):
        return [_without_time(v) for v in obj]
    return obj


def _header_diff(a, b, prefix="") -> list[str]:
    """Paths of the header fields that differ between ``a`` and ``b``."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for k in sorted(set(a) | set(b)):
            if k not in a or k not in b:
                out.append(f"{prefix}{k} (only in {'b' if k not in a else 'a'})")
            else:
                out += _header_diff(a[k], b[k], f"{prefix}{k}.")
        return out
    return [] if a == b else [prefix.rstrip(".")]


def compare_fit_files(a: Path, b: Path) -> dict:
    """The arrays and header fields of two fit files (``.npz``) that differ."""
    with np.load(a, allow_pickle=False) as fa, np.load(b, allow_pickle=False) as fb:
        names = sorted(set(fa.files) | set(fb.files))
        arrays = [n for n in names if n != "__header__" and (
            n not in fa.files or n not in fb.files or fa[n].dtype != fb[n].dtype
            or fa[n].shape != fb[n].shape or fa[n].tobytes() != fb[n].tobytes())]
        ha = json.loads(fa["__header__"].tobytes())
        hb = json.loads(fb["__header__"].tobytes())
    return {"arrays": arrays, "header": _header_diff(_without_time(ha), _without_time(hb))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("a", type=Path, help="the --out folder of the first run")
    ap.add_argument("b", type=Path, help="the --out folder of the second run")
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args(argv)
    rows, only = [], []
    for fa in sorted((args.a / "fits").glob("*/*.npz")):
        rel = fa.relative_to(args.a / "fits")
        fb = args.b / "fits" / rel
        if not fb.is_file():
            only.append(str(rel))
            continue
        diff = compare_fit_files(fa, fb)
        rows.append({"material": rel.parent.name, "model": rel.stem, **diff})
    different = [r for r in rows if r["arrays"] or r["header"]]
    summary = {"command": " ".join(sys.argv), "date": time.strftime("%Y-%m-%dT%H:%M:%S"),
               "a": str(args.a), "b": str(args.b), "compared": len(rows),
               "identical": len(rows) - len(different),
               "arrays_identical": sum(not r["arrays"] for r in rows),
               "arrays_differ_by_model": dict(Counter(r["model"] for r in rows if r["arrays"])),
               "header_fields_differ": dict(Counter(f for r in rows for f in r["header"])),
               "only_in_a": only, "different": different}
    head = json.dumps({k: v for k, v in summary.items() if k != "different"}, indent=1)
    rows_text = ",\n".join("  " + json.dumps(r, ensure_ascii=False) for r in different)
    args.out.write_text(head[:-2] + ',\n "different": [\n' + rows_text + "\n ]\n}\n")
    print(f"{summary['identical']} / {len(rows)} fit files identical, "
          f"{summary['arrays_identical']} with identical arrays "
          f"({len(only)} only in {args.a}); written {args.out}")
    for r in different:
        print(f"  {r['material']} {r['model']}: arrays {r['arrays']} header {r['header']}")
    return 0 if not different else 1


if __name__ == "__main__":
    sys.exit(main())
