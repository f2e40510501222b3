"""Robustness figures: every bad input and fault scenario, clean or not.

Three parts, each run for real on this machine (nothing is counted that did not run):

* **bad inputs through the CLI**: every malformed measured file of
  :mod:`tests.support.malformed_readers` (``brdffit fit SPEC --model ggx -o OUT/x.npz``) and
  every malformed fit file of :mod:`tests.support.malformed_fits` (``brdffit export FIT
  --to json -o OUT/x.json``), each in a fresh process under a 1 GiB address-space limit
  (:func:`tests.support.hostile.run_limited`). Clean = exit 1, one line on stderr naming
  the file, no traceback, nothing left in OUT, under 5 s and 1 GiB;
* **hostile names**: exports to every target with output names carrying code/markup payloads;
  clean = the export succeeds, the generated file parses (Python ``compile``, XML, JSON) and
  the payload never runs (no ``INJECTED`` file after executing the Python script's code
  objects is checked by the test suite; here: parse + the payload only inside literals);
* **output targets**: ``-o`` naming a device, a FIFO, a socket, a folder, a
  missing or unwritable place, another format's extension, a protected file: the documented
  exit status, one line, the destination unchanged, the check before any work;
* **parameter files**: hand-written parameter JSON (out-of-range, denormal, NaN, huge tables,
  deep nesting, wrong version or dtype, 70 MB, invalid UTF-8) through ``export``: as bad inputs;
* **option values**: values no command can honour: exit 2 naming the option, before any work;
* **printing paths**: a file name with ESC, BEL and a bidirectional override through
  ``info``, ``fit``, errors, ``compare``, ``batch`` and into ``batch.log``, ``summary.csv``
  and the report: no raw control character anywhere;
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
sys.path.insert(0, str(ROOT))  # tests.support: the test kit

from tests.support import malformed_fits, malformed_readers  # noqa: E402
from tests.support.hostile import MAX_SECONDS, MEMORY_LIMIT, run_limited  # noqa: E402

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
            out.mkdir()  # -o never creates folders
            o = run_limited(["fit", spec, "--model", "ggx", "-o", out / "x.npz"], cwd=folder)
            rows.append(_row("reader", case.name, o,
                             o.problems(names=case.file_name, out_dir=out)))
    fits = malformed_fits.cli_subset() if quick else malformed_fits.cases()
    for case in fits:
        with tempfile.TemporaryDirectory() as tmp:
            folder = Path(tmp)
            path = Path(case.write(folder))
            out = folder / "out"
            out.mkdir()
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


# -- outputs, parameter files, option values, names on printing paths ---------------
def _plain(kind, name, o, problems) -> dict:
    return _row(kind, name, o, problems)


def output_targets() -> list[dict]:
    """``-o`` naming devices, FIFOs, sockets, folders, missing or unwritable places, other
    formats' extensions, protected files: the documented outcome, one line, nothing replaced."""
    import socket
    import stat
    import threading

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        fit = folder / "g.npz"
        assert run_limited(["fit", "synthetic:gold-ggx", "-m", "ggx", "-o", fit],
                           cwd=folder).returncode == 0
        (folder / "a-file").write_text("x")
        kept = folder / "kept.gltf"
        kept.write_text("old")
        kept.chmod(0o600)
        # a null device of the bench's own when it runs as root: code that replaces devices
        # (as brdffit did before) must not destroy the machine's /dev/null
        null = "/dev/null"
        if os.geteuid() == 0:
            try:
                os.mknod(folder / "null", stat.S_IFCHR | 0o666, os.makedev(1, 3))
                null = str(folder / "null")
            except OSError:
                pass
        link = folder / "null.gltf"
        link.symlink_to(null)
        fifo = folder / "pipe"
        os.mkfifo(fifo)
        sock_path = folder / "s.sock"
        sock = socket.socket(socket.AF_UNIX)
        sock.bind(str(sock_path))
        export = ["export", fit, "--to", "gltf", "-o"]
        cases = [  # name, argv, expected exit, check after
            ("/dev/null", export + [null], 0, lambda: stat.S_ISCHR(os.stat(null).st_mode)),
            ("link to /dev/null", export + [link], 0,
             lambda: link.is_symlink() and stat.S_ISCHR(os.stat(null).st_mode)),
            ("FIFO", export + [fifo], 0, lambda: stat.S_ISFIFO(fifo.lstat().st_mode)),
            ("socket", export + [sock_path], 1, lambda: stat.S_ISSOCK(sock_path.lstat().st_mode)),
            ("directory", ["fit", "synthetic:gold-ggx", "-m", "ggx", "-o", folder], 1, None),
            ("missing folder", export + [folder / "missing" / "x.gltf"], 1,
             lambda: not (folder / "missing").exists()),
            ("parent is a file", export + [folder / "a-file" / "x.gltf"], 1, None),
            ("/proc", ["fit", "synthetic:gold-ggx", "-m", "npf", "-o", "/proc/x.npz"], 1, None),
            ("fit -o x.gltf", ["fit", "synthetic:gold-ggx", "-o", folder / "x.gltf"], 2,
             lambda: not (folder / "x.gltf").exists()),
            ("--to gltf -o x.npz", export[:-1] + ["-o", folder / "y.npz"], 2, None),
            ("--to json -o x.gltf", ["export", fit, "--to", "json", "-o", folder / "y.gltf"], 2,
             None),
            ("glsl (2 files) -o /dev/null", ["export", fit, "--to", "glsl", "-o", null],
             1, lambda: stat.S_ISCHR(os.stat(null).st_mode)),
            ("mode 0600 kept", export + [kept], 0,
             lambda: stat.S_IMODE(kept.stat().st_mode) == 0o600),
        ]
        for name, argv, code, after in cases:
            reader = None
            if name == "FIFO":
                reader = threading.Thread(target=lambda: fifo.read_bytes(), daemon=True)
                reader.start()
            o = run_limited(argv, cwd=folder)
            if reader is not None:
                reader.join(10)
            problems = []
            if o.returncode != code:
                problems.append(f"exit {o.returncode}, expected {code}: {o.stderr[-200:]!r}")
            if code == 1 and len(o.error_lines) != 1:
                problems.append(f"{len(o.error_lines)} lines on stderr")
            if "Traceback" in o.stderr or ".tmp" in o.stderr:
                problems.append("traceback or temporary name on stderr")
            if o.seconds > MAX_SECONDS:
                problems.append(f"took {o.seconds:.1f} s: the check did not come first")
            if after is not None and not after():
                problems.append("destination changed")
            rows.append(_plain("output-target", name, o, problems))
        sock.close()
    return rows


def parameter_files() -> list[dict]:
    """Hand-written parameter JSON files through ``brdffit export``: exit 1, one line naming
    the file, nothing written, within the time and memory limits."""
    base = {"format": "brdffit-params", "version": 1, "model": "microfacet",
            "parameters": {"distribution": {"kind": "ggx", "alpha_x": 0.2}, "rho_d": 0.1}}

    def doc(**dist):
        d = json.loads(json.dumps(base))
        d["parameters"]["distribution"].update(dist)
        return json.dumps(d)

    fresnel = json.loads(json.dumps(base))
    fresnel["parameters"]["fresnel"] = {"kind": "conductor", "eta": 1e300, "k": 1e300}
    table = json.loads(json.dumps(base))
    table["parameters"]["fresnel"] = {"kind": "table", "theta_d": [i * 1.0 for i in range(
        3_000_000)], "values": [[0.5, 0.5, 0.5]] * 3_000_000}
    cases = {
        "alpha 1e300": doc(alpha_x=1e300), "alpha denormal 5e-324": doc(alpha_x=5e-324),
        "alpha NaN": doc(alpha_x=float("nan")), "conductor 1e300": json.dumps(fresnel),
        "Fresnel table of 3e6 nodes to 3e6 rad": json.dumps(table),
        "version '2'": json.dumps(dict(base, version="2")),
        "version 99": json.dumps(dict(base, version=99)),
        "nested 100000 deep": "[" * 100_000 + "]" * 100_000,
        "not JSON": "{format: brdffit", "a JSON list": "[1, 2]",
        "object dtype": json.dumps(dict(base, state={"params": {}, "arrays": {"x": {
            "dtype": "object", "shape": [1], "data": [1]}}})),
        "70 MB of spaces": json.dumps(base) + " " * (70 << 20),
        "invalid UTF-8": b"\xff\xfe{}",
    }
    rows = []
    for name, text in cases.items():
        with tempfile.TemporaryDirectory() as tmp:
            folder = Path(tmp)
            path = folder / "params.json"
            (path.write_bytes if isinstance(text, bytes) else path.write_text)(text)
            out = folder / "out"
            out.mkdir()
            for to, ext in (("glsl", ".glsl"), ("gltf", ".gltf")):
                o = run_limited(["export", path, "--to", to, "-o", out / f"x{ext}"], cwd=folder)
                rows.append(_row("parameter-file", f"{name} --to {to}", o,
                                 o.problems(names=path.name, out_dir=out)))
    return rows


def option_values() -> list[dict]:
    """Values no command can honour: exit 2, the option named, before any work."""
    cases = [
        ["fit", "synthetic:gold-ggx", "-m", "ggx-diffuse", "-O", "starts=-5"],
        ["fit", "synthetic:gold-ggx", "-m", "ggx-diffuse", "-O", "theta_d_stride=0"],
        ["fit", "synthetic:gold-ggx", "-m", "ggx-diffuse", "-O", "phi_d_stride=-3"],
        ["fit", "synthetic:gold-ggx", "-m", "npf", "-O", "seed=-1"],
        ["fit", "synthetic:gold-ggx", "-m", "npf", "-O", "max_iter=0"],
        ["fit", "synthetic:gold-ggx", "-m", "npf", "-O", "tol=nan"],
        ["fit", "synthetic:gold-ggx", "-m", "npf", "-O", "polish_bound=0.5"],
        ["fit", "synthetic:gold-ggx", "-m", "tabulated", "-O", "n=1000000000"],
        ["fit", "synthetic:gold-ggx", "-m", "npf", "-O", "callback=1"],
        ["render", "synthetic:gold-ggx", "-o", "x.png", "--resolution", "1000000"],
        ["render", "synthetic:gold-ggx", "-o", "x.png", "--spp", "1000000000"],
        ["render", "synthetic:gold-ggx", "-o", "x.png", "--resolution", "4096", "--spp", "65536"],
        ["render", "synthetic:gold-ggx", "-o", "x.png", "--seed", "-1"],
        ["render", "synthetic:gold-ggx", "-o", "x.png", "--gamma", "0"],
        ["render", "synthetic:gold-ggx", "-o", "x.png", "--exposure", "nan"],
        ["compare", "synthetic:gold-ggx", "--spp", "4", "--batches", "3"],
        ["compare", "synthetic:gold-ggx", "--fit-options", '{"ggx": {"n": 0}}', "-m", "ggx"],
        ["compare", "synthetic:gold-ggx", "--exposure", "-1"],
        ["demo", "--spp", "12"],
        ["demo", "--jobs", "1000"],
        ["batch", "synthetic:", "--out", "runs", "--render", "--spp", "10"],
        ["info", "synthetic:gold-ggx", "--albedo-samples", "0"],
    ]
    rows = []
    for argv in cases:
        with tempfile.TemporaryDirectory() as tmp:
            o = run_limited(argv, cwd=tmp)
            problems = []
            if o.returncode != 2:
                problems.append(f"exit {o.returncode}, expected 2: {o.stderr[-200:]!r}")
            if "Traceback" in o.stderr or "error:" not in o.stderr:
                problems.append("no one-line error")
            if o.seconds > MAX_SECONDS:
                problems.append(f"took {o.seconds:.1f} s: work started before the check")
            if any(Path(tmp).iterdir()):
                problems.append("something was written")
            rows.append(_plain("option-value", " ".join(map(str, argv)), o, problems))
    return rows


def printing_paths() -> list[dict]:
    """A file name with ESC, bell, a bidirectional override and a newline through every
    command that prints it, and the logs and tables it reaches: no raw control character."""
    raw = ("\x1b", "\x07", "\u202e", "\x00")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        name = "evil\x1b[2J\u202ename\x07"
        data = folder / "in"
        data.mkdir()
        src = data / f"{name}.binary"
        assert run_limited(["convert", "synthetic:gold-ggx", src], cwd=folder).returncode == 0
        runs = {
            "info": ["info", src, "--albedo-samples", "256"],
            "fit": ["fit", src, "-m", "ggx", "--no-error"],
            "fit (missing file)": ["fit", data / f"gone{name}.binary"],
            "export (bad output)": ["export", "synthetic:gold-ggx", "--to", "json", "-o",
                                    folder / f"no{name}" / "x.json"],
            "compare": ["compare", src, "-m", "ggx", "--spp", "2", "--resolution", "16",
                        "--scenes", "sphere-studio", "--out", folder / "cmp"],
            "batch": ["batch", data, "-m", "ggx", "--workers", "1", "-q", "--out",
                      folder / "runs"],
        }
        for label, argv in runs.items():
            o = run_limited(argv, cwd=folder, max_bytes=4 << 30, timeout=300)
            problems = [f"raw {c!r} on {stream}" for c in raw
                        for stream, text in (("stdout", o.stdout), ("stderr", o.stderr))
                        if c in text]
            if "Traceback" in o.stderr:
                problems.append("traceback")
            rows.append(_plain("printing-path", label, o, problems))
        for label, path in (("batch.log", folder / "runs" / "batch.log"),
                            ("summary.csv", folder / "runs" / "summary.csv"),
                            ("report HTML", folder / "cmp" / "index.html")):
            text = path.read_text(encoding="utf-8") if path.is_file() else ""
            problems = [] if text else ["not written"]
            problems += [f"raw {c!r}" for c in raw if c in text]
            rows.append({"kind": "printing-path", "case": label, "clean": not problems,
                         "problems": problems, "seconds": 0.0, "peak_mib": 0.0})
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
    rows = (bad_inputs(args.quick) + hostile_names(args.quick) + output_targets()
            + parameter_files() + option_values() + printing_paths() + fault_scenarios())
    rejected = [r for r in rows if r["kind"] in ("reader", "fit-file", "parameter-file")]
    summary = {"load_average_start": load0, "load_average_end": os.getloadavg(),
               "memory_limit_bytes": MEMORY_LIMIT, "time_limit_s": MAX_SECONDS,
               "quick": args.quick, "by_kind": {}}
    for kind in ("reader", "fit-file", "hostile-name", "output-target", "parameter-file",
                 "option-value", "printing-path", "fault"):
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
