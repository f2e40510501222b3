"""Robustness figures of issue 12: every bad input and fault scenario, clean or not.

Three parts, each run for real on this machine (nothing is counted that did not run):

* **bad inputs through the CLI**: every malformed measured file of
  :mod:`brdffit.testing.malformed_readers` (``brdffit fit SPEC --model ggx -o OUT/x.npz``) and
  every malformed fit file of :mod:`brdffit.testing.malformed_fits` (``brdffit export FIT
  --to json -o OUT/x.json``), each in a fresh process under a 1 GiB address-space limit
  (:func:`brdffit.testing.hostile.run_limited`). Clean = exit 1, one line on stderr naming
  the file, no traceback, nothing left in OUT, under 5 s and 1 GiB;
* **hostile names**: exports to every target with output names carrying code/markup payloads;
  clean = the export succeeds, the generated file parses (Python ``compile``, XML, JSON) and
  the payload never runs (no ``INJECTED`` file after executing the Python script's code
  objects is checked by the test suite; here: parse + the payload only inside literals);
* **fault scenarios**: the batch/CLI fault tests (``tests/batch/test_faults.py``,
  ``tests/batch/test_names.py``, ``tests/cli/test_exit_codes.py``) run by pytest; recovered =
  the test passed (each asserts that nothing was lost and the exit code is right).

Writes ``bench/results/robustness.json``; prints the totals, the worst time and the peak
memory of a rejected input, and every case that was not clean. The load average is recorded
(the time limit is wall clock: a loaded machine makes it pessimistic)::

    .venv/bin/python bench/bench_robustness.py [--quick]
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from brdffit.testing import malformed_fits, malformed_readers  # noqa: E402
from brdffit.testing.hostile import MAX_SECONDS, MEMORY_LIMIT, run_limited  # noqa: E402

PAYLOADS = ['x");open("INJECTED","w").write("pwned");("', "a'''b\"\"\"c", "line\nbreak",
            "</script><script>alert(1)</script>", "]]><!--", "*/ #version 100 //", "{{7*7}}",
            "back\\slash", "金 銀", "--x--"]
TARGETS = {"mitsuba": ".py", "mitsuba-xml": ".xml", "gltf": ".gltf", "json": ".json"}


def _row(kind, name, outcome, problems):
    return {"kind": kind, "case": name, "clean": not problems, "problems": problems,
            "exit": outcome.returncode, "seconds": round(outcome.seconds, 3),
            "peak_mib": round(outcome.peak_rss_bytes / 2**20, 1),
            "stderr": outcome.stderr.strip()[-300:]}


def bad_inputs(quick: bool) -> list[dict]:
    rows = []
    readers = [c for c in malformed_readers.cases() if c.cli or not quick]
    for case in readers:
        with tempfile.TemporaryDirectory() as tmp:
            folder = Path(tmp)
            spec = case.make(folder)
            out = folder / "out"
            o = run_limited(["fit", spec, "--model", "ggx", "-o", out / "x.npz"], cwd=folder)
            rows.append(_row("reader", case.name, o,
                             o.problems(names=case.file_name, out_dir=out)))
    fits = malformed_fits.cli_subset() if quick else malformed_fits.cases()
    for case in fits:
        with tempfile.TemporaryDirectory() as tmp:
            folder = Path(tmp)
            path = Path(case.write(folder))
            out = folder / "out"
            o = run_limited(["export", path, "--to", "json", "-o", out / "x.json"], cwd=folder)
            rows.append(_row("fit-file", case.name, o, o.problems(names=path.name, out_dir=out)))
    return rows


def _payload_only_in_literals(source: str, payload: str) -> bool:
    tree = ast.parse(source)
    blank = [n for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, str)]
    for n in blank:
        n.value = ""
    return payload not in ast.unparse(tree) or payload in ("--x--",)


def hostile_names(quick: bool) -> list[dict]:
    rows = []
    payloads = PAYLOADS[:4] if quick else PAYLOADS
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        fit = folder / "gold.npz"
        o = run_limited(["fit", "synthetic:gold-ggx", "--model", "ggx", "-o", fit], cwd=folder)
        assert o.returncode == 0, o.stderr
        for target, ext in TARGETS.items():
            for i, payload in enumerate(payloads):
                out = folder / f"{target}-{i}"
                out.mkdir()
                name = payload.replace("/", "_").replace("\n", "_") + ext
                o = run_limited(["export", fit, "--to", target, "-o", out / name], cwd=out,
                                max_bytes=4 << 30)  # exporting to mitsuba imports Mitsuba
                problems = []
                if o.returncode != 0:
                    problems.append(f"exit {o.returncode}: {o.stderr.strip()[-200:]}")
                else:
                    text = (out / name).read_text(encoding="utf-8")
                    try:
                        if ext == ".py":
                            compile(text, name, "exec")
                            if not _payload_only_in_literals(text, payload.split("\n")[0]):
                                problems.append("payload outside string literals")
                        elif ext == ".xml":
                            ET.fromstring(text.encode())
                        else:
                            json.loads(text)
                    except (SyntaxError, ET.ParseError, ValueError) as exc:
                        problems.append(f"output does not parse: {exc}")
                    if (out / "INJECTED").exists():
                        problems.append("payload ran")
                row = _row("hostile-name", f"{target}:{payload!r}", o, problems)
                rows.append(row)
    return rows


def fault_scenarios() -> list[dict]:
    with tempfile.TemporaryDirectory() as tmp:
        xml = Path(tmp) / "junit.xml"
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                        "tests/batch/test_faults.py", "tests/batch/test_names.py",
                        "tests/cli/test_exit_codes.py", f"--junitxml={xml}"], cwd=ROOT,
                       capture_output=True, text=True)
        wall = time.perf_counter() - t0
        root = ET.parse(xml).getroot()
    rows = []
    for tc in root.iter("testcase"):
        failed = tc.find("failure") is not None or tc.find("error") is not None
        skipped = tc.find("skipped") is not None
        rows.append({"kind": "fault", "case": f"{tc.get('classname')}::{tc.get('name')}",
                     "clean": not failed and not skipped, "skipped": skipped,
                     "seconds": float(tc.get("time", 0)),
                     "problems": [] if not failed else ["test failed"]})
    print(f"fault scenarios: {len(rows)} tests in {wall:.0f} s")
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="the CLI subsets only")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "robustness.json"))
    args = ap.parse_args(argv)
    load0 = os.getloadavg()
    rows = bad_inputs(args.quick) + hostile_names(args.quick) + fault_scenarios()
    rejected = [r for r in rows if r["kind"] in ("reader", "fit-file")]
    summary = {"load_average_start": load0, "load_average_end": os.getloadavg(),
               "memory_limit_bytes": MEMORY_LIMIT, "time_limit_s": MAX_SECONDS,
               "quick": args.quick, "by_kind": {}}
    for kind in ("reader", "fit-file", "hostile-name", "fault"):
        rs = [r for r in rows if r["kind"] == kind]
        summary["by_kind"][kind] = {"tried": len(rs), "clean": sum(r["clean"] for r in rs)}
    summary["tried"] = len(rows)
    summary["clean"] = sum(r["clean"] for r in rows)
    if rejected:
        worst_t = max(rejected, key=lambda r: r["seconds"])
        worst_m = max(rejected, key=lambda r: r["peak_mib"])
        summary["worst_seconds"] = {"case": worst_t["case"], "seconds": worst_t["seconds"]}
        summary["peak_mib"] = {"case": worst_m["case"], "mib": worst_m["peak_mib"]}
        summary["median_seconds"] = sorted(r["seconds"] for r in rejected)[len(rejected) // 2]
    Path(args.out).write_text(json.dumps({"summary": summary, "rows": rows}, indent=1))
    print(json.dumps(summary, indent=1))
    for r in rows:
        if not r["clean"]:
            print(f"NOT CLEAN {r['kind']} {r['case']}: {r['problems']}")
    return 0 if summary["clean"] == summary["tried"] else 1


if __name__ == "__main__":
    sys.exit(main())
