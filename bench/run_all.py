"""Run every benchmark of bench/ (``make bench``) and collect bench/results/*.json.

Each ``bench/bench_<name>.py`` writes ``bench/results/<name>.json``; this script runs them one
after the other (real-data modes included when ``../shared/data`` exists), then writes
``bench/results/all.json`` (not kept in git) with the machine description and every result.
The studies of ``bench/studies/`` (hours over the whole database) are not run: see
bench/README.md. Pass benchmark names to run a subset:
``.venv/bin/python bench/run_all.py tabulated sgd``.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
SHARED = HERE.parents[1] / "shared" / "data"

# script → extra arguments for the real-data mode (used when ../shared/data exists)
REAL_ARGS = {"tabulated": ["--real"], "sgd": ["--real"], "export": ["--real"]}


def main(argv: list[str]) -> int:
    if {"-h", "--help"} & set(argv):
        print(__doc__)
        return 0
    scripts = sorted(HERE.glob("bench_*.py"))
    if argv:
        scripts = [s for s in scripts if s.stem.removeprefix("bench_") in argv]
    status = {}
    for script in scripts:
        name = script.stem.removeprefix("bench_")
        args = REAL_ARGS.get(name, []) if SHARED.exists() else []
        print(f"== {script.name} {' '.join(args)}", flush=True)
        t0 = time.perf_counter()
        rc = subprocess.run([sys.executable, str(script), *args], cwd=HERE.parent).returncode
        status[name] = {"returncode": rc, "seconds": time.perf_counter() - t0}
    results = {}
    for path in sorted((HERE / "results").glob("*.json")):
        if path.name != "all.json":
            try:
                results[path.stem] = json.loads(path.read_text())
            except json.JSONDecodeError:
                results[path.stem] = {"error": "unreadable"}
    summary = {"machine": {"platform": platform.platform(), "python": platform.python_version(),
                           "cpus": os.cpu_count()},
               "status": status, "results": results}
    (HERE / "results" / "all.json").write_text(json.dumps(summary, indent=1))
    print(f"wrote {HERE / 'results' / 'all.json'}")
    return 0 if all(s["returncode"] == 0 for s in status.values()) else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
