"""Benchmark of the command line as a user runs it: whole processes.

Prints and writes ``bench/results/cli.json``:

* the median (and min) **wall** and **CPU** time (user + system of the child, from
  ``wait4``) of ``--runs`` runs of each command, in fresh processes:
  ``python -c pass`` (the interpreter alone), ``import brdffit``, ``brdffit --help``,
  ``brdffit models``, ``brdffit fit GOLD --model tabulated -o f.npz`` with and without the
  error figure (``--no-error`` is the job of the C++ reference: read, fit, save), and a
  rejected (truncated) MERL file through ``fit`` and ``info``;
* where the time of the fit process goes (median over runs): interpreter start, importing
  the CLI, reading the input (NumPy included), importing the fitting module, the fit, the
  save, the error figure, the rest (parsing, printing, exit); the slowest imports
  (``python -X importtime``) and which heavy packages the process loaded;
* ``--reference CMD``: a reference program doing the same job, timed interleaved with the
  commands above (side by side, same load), e.g. the authors' C++ (jdupuy/dj_brdf, built
  outside the repository: ``djb::merl`` read, ``djb::tabular(merl, 90, true)`` fit, tables
  written): ``--reference "/tmp/cpp/djfit {input} {output}"``; the JSON keeps the command
  and the ratio of the fit process to it;
* ``--models [A,B]``: one fit of GOLD per model (fit time, CPU, fit-file and table bytes,
  quick error): the typical figures :data:`brdffit.fit.registry.MODELS` declares.

GOLD is the MERL file of the Neural-BRDF ``gold-metallic-paint`` (``brdffit convert
merl_nbrdf.zip:gold-metallic-paint``) when ``../shared/data`` is present, else
``synthetic:gold-ggx`` resampled on the MERL grid. The load average is recorded before and
after: on this shared 2-core machine wall times grow with the load, CPU times much less.

Run: ``.venv/bin/python bench/bench_cli.py [--runs 11] [--models] [--reference CMD]``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import random
import re
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent
REPO = ROOT.parent
SHARED = REPO.parent / "shared" / "data"
HEAVY = ("numpy", "scipy", "numba", "llvmlite", "pydantic", "rich", "click", "mitsuba",
         "drjit", "dask", "distributed", "matplotlib", "colour", "h5py", "PIL")
C_REFERENCE_S = 0.175  # jdupuy/dj_brdf (egsr_2015, g++ -O3) on this machine
REFERENCE = "reference program (--reference): read, fit, save"
FIT = "fit tabulated -o (read, fit, save)"

_WRAP = "import sys\nfrom brdffit.cli import main\nsys.exit(main(sys.argv[1:]))"


def _run(argv, env=None) -> tuple[float, float, int]:
    """``(wall s, CPU s, exit status)`` of one child process (output discarded)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env=env)
    _, status, ru = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    return wall, ru.ru_utime + ru.ru_stime, proc.returncode


def _stats(samples: list[float]) -> dict:
    return {"median": statistics.median(samples), "min": min(samples), "n": len(samples)}


_PYCACHE = Path(tempfile.mkdtemp(prefix="bench-cli-pycache-"))


def _env() -> dict:
    """The children's environment: as a user's -- bytecode cached (this machine's sessions
    set PYTHONDONTWRITEBYTECODE, which recompiles every brdffit module in every process,
    ~20 ms); the caches go to a temporary folder, not into the source tree."""
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env["PYTHONPYCACHEPREFIX"] = str(_PYCACHE / "current")
    return env


def _make_inputs(tmp: Path) -> tuple[Path, Path, str]:
    gold = tmp / "gold.binary"
    zip_ = SHARED / "nbrdf" / "merl_nbrdf.zip"
    if zip_.is_file():
        from brdffit.cli.convert import convert

        convert(f"{zip_}:gold-metallic-paint", gold)
        what = "MERL file of merl_nbrdf.zip:gold-metallic-paint"
    else:  # pragma: no cover - without the shared data
        from brdffit import synthetic
        from brdffit.io.merl import resample_to_merl

        resample_to_merl(synthetic("gold-ggx"), gold)
        what = "synthetic:gold-ggx resampled on the MERL grid"
    bad = tmp / "bad.binary"
    bad.write_bytes(gold.read_bytes()[:1000])
    return gold, bad, what


def _commands(py: str, gold: Path, bad: Path, out: Path,
              reference: str | None = None) -> dict[str, list]:
    cli = [py, "-m", "brdffit"]  # the tree's own entry point, as the console script runs it
    fit = cli + ["fit", str(gold), "--model", "tabulated", "-o", str(out)]
    cmds = {
        "python -c pass": [py, "-c", "pass"],
        "import brdffit": [py, "-c", "import brdffit"],
        "brdffit --help": cli + ["--help"],
        # the C++ reference's job: read the MERL file, fit, save
        FIT: fit + ["--no-error"],
        "fit rejected input": cli + ["fit", str(bad), "--model", "tabulated", "-o", str(out)],
        "info rejected input": cli + ["info", str(bad)],
        "brdffit models": cli + ["models"],
        "fit tabulated -o, with error figure": fit,
    }
    if reference:
        cmds[REFERENCE] = shlex.split(reference.format(input=gold,
                                                       output=out.with_suffix(".ref")))
    return cmds


def time_commands(py, gold, bad, runs, reference=None) -> dict:
    """Median (and min) wall and CPU of each command over ``runs`` rounds; every round runs
    each command once, in an order shuffled per round (a fixed order moved medians by up to
    10 %: the command after a heavy one pays for it)."""
    env = _env()
    rng = random.Random(0)
    with tempfile.TemporaryDirectory() as tmp:
        cmds = {k: (argv, env) for k, argv in
                _commands(py, gold, bad, Path(tmp) / "f.npz", reference).items()}
        res = {k: {"wall": [], "cpu": [], "status": None} for k in cmds}
        for argv, cmd_env in cmds.values():  # warm-up: bytecode caches, page cache
            _run(argv, cmd_env)
        for _ in range(runs):  # interleaved: the load drifts, every command sees it
            order = list(cmds.items())
            rng.shuffle(order)
            for name, (argv, cmd_env) in order:
                wall, cpu, status = _run(argv, cmd_env)
                res[name]["wall"].append(wall)
                res[name]["cpu"].append(cpu)
                res[name]["status"] = status
    out = {k: {"wall_s": _stats(v["wall"]), "cpu_s": _stats(v["cpu"]), "exit": v["status"]}
           for k, v in res.items()}
    out[FIT]["no_error"] = True
    if REFERENCE in out:
        out[REFERENCE]["command"] = reference
        out[REFERENCE]["fit_over_reference"] = {
            k: out[FIT][k]["median"] / out[REFERENCE][k]["median"] for k in ("wall_s", "cpu_s")}
        # the ratio within each interleaved round (same moment of the machine), then the median
        for name in (FIT, "fit tabulated -o, with error figure"):
            if name in res:
                out[REFERENCE].setdefault("per_round_ratio_median", {})[name] = {
                    k: statistics.median(a / b for a, b in zip(res[name][k.split("_")[0]],
                                                               res[REFERENCE][k.split("_")[0]]))
                    for k in ("wall_s", "cpu_s")}
    return out


_BREAKDOWN = r"""
import json, resource, sys, time, io, contextlib
def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF); return r.ru_utime + r.ru_stime
t0, c0 = time.perf_counter(), cpu()
from brdffit.cli import main
t1, c1 = time.perf_counter(), cpu()
from brdffit._blas import single_thread_env
single_thread_env()  # as main() does before NumPy loads (else the fit goes through threadpoolctl)
import numpy  # timed apart: reading the input would import it first
tn = time.perf_counter() - t1
t1, c1 = time.perf_counter(), cpu()
buf = io.StringIO()
with contextlib.redirect_stdout(buf):
    code = main(sys.argv[1:] + ["--json"])
t2, c2 = time.perf_counter(), cpu()
s = json.loads(buf.getvalue())
print(json.dumps({"import_cli": t1 - t0 - tn, "import_numpy": tn,
                  "import_cli_cpu": c1 - c0, "main": t2 - t1,
                  "main_cpu": c2 - c1, "timings": s["timings_s"], "code": code,
                  "n_modules": len(sys.modules)}))
"""


def breakdown(py, gold, runs) -> dict:
    """Where the time of ``brdffit fit GOLD -m tabulated -o f.npz`` goes (medians)."""
    env = _env()
    floor = [_run([py, "-c", "pass"], env)[0] for _ in range(runs)]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        argv = ["fit", str(gold), "--model", "tabulated", "-o", str(Path(tmp) / "f.npz")]
        for _ in range(runs):
            t0 = time.perf_counter()
            proc = subprocess.run([py, "-c", _BREAKDOWN, *argv], capture_output=True,
                                  text=True, check=True, env=env)
            rows.append(dict(json.loads(proc.stdout), wall=time.perf_counter() - t0))
        # -X importtime of one run: the slowest modules (cumulative, top level)
        proc = subprocess.run([py, "-X", "importtime", "-c", _WRAP, *argv], text=True,
                              capture_output=True, env=env)
    med = statistics.median
    t = {k: med(r["timings"].get(k, 0.0) for r in rows)
         for k in ("load", "import", "fit", "save", "error")}
    main_ = med(r["main"] for r in rows)
    phases = {"interpreter start (python -c pass)": med(floor),
              "import brdffit.cli (argparse, command modules)": med(r["import_cli"] for r in rows),
              "import NumPy": med(r["import_numpy"] for r in rows),
              "read + validate the MERL file": t["load"],
              "import the fitting module (brdffit.fit.tabulated)": t["import"],
              "fit (power iteration)": t["fit"], "save the fit file": t["save"],
              "error figure (quick_error)": t["error"],
              "rest of main (parse, figures, print)": main_ - sum(t.values())}
    # what the child cannot time itself: start-up beyond `python -c pass`, and shutdown
    phases["interpreter shutdown and the rest"] = med(
        r["wall"] - r["import_cli"] - r["import_numpy"] - r["main"] for r in rows) - phases[
        "interpreter start (python -c pass)"]
    imports = []
    for line in proc.stderr.splitlines():
        m = re.match(r"import time:\s+(\d+) \|\s+(\d+) \|( *)(\S+)", line)
        if m and len(m.group(3)) <= 1:  # top-level imports of the process
            imports.append((m.group(4), int(m.group(2)) / 1e6))
    imports.sort(key=lambda x: -x[1])
    return {"phases_s": phases, "sum_s": sum(phases.values()),
            "process_wall_s": med(r["wall"] for r in rows),
            "import_cli_and_numpy_cpu_s": med(r["import_cli_cpu"] for r in rows),
            "main_cpu_s": med(r["main_cpu"] for r in rows),
            "n_modules": rows[0]["n_modules"],
            "heavy_loaded": json.loads(_loaded(py, ["fit", str(gold), "--model", "tabulated",
                                                    "--no-error"])),
            "slowest_top_level_imports_s": imports[:12], "runs": runs}


def _loaded(py, argv) -> str:
    code = ("import sys, json\nfrom brdffit.cli import main\nimport io, contextlib\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n    main(sys.argv[1:])\n"
            f"print(json.dumps(sorted({{m.split('.')[0] for m in sys.modules}} & set({HEAVY!r}))))")
    return subprocess.run([py, "-c", code, *argv], capture_output=True, text=True,
                          check=True, env=_env()).stdout


def model_figures(spec: Path, names: list[str]) -> dict:
    """One fit of ``spec`` per model, in this process: fit wall/CPU time, file and table
    bytes, quick error (what registry.MODELS declares as typical)."""
    from brdffit.cli.fit import quick_error
    from brdffit.fit import registry
    from brdffit.io import load
    from brdffit.io.fitfile import save_fit

    ref = load(str(spec))
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            print(f"  fitting {name} ...", flush=True)
            entry = registry.get(name)
            t0, c0 = time.perf_counter(), time.process_time()
            try:
                fitted = entry.fit(ref)
            except Exception as exc:  # noqa: BLE001
                out[name] = {"error": f"{type(exc).__name__}: {exc}"}
                continue
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            path = Path(tmp) / f"{name}.npz"
            save_fit(fitted, path, source=str(spec), options={"model": name})
            out[name] = {"fit_time_s": wall, "fit_cpu_s": cpu,
                         "fit_file_bytes": path.stat().st_size,
                         "table_bytes": registry.table_bytes(fitted),
                         "cos_rel_error": quick_error(ref, fitted)["cos_rel_error"],
                         "converged": (getattr(fitted, "fit_info", None) or {}).get("converged")}
            print(f"    {out[name]}", flush=True)
    return out


def _git(*args) -> str:
    return subprocess.run(["git", *args], cwd=REPO, capture_output=True, text=True,
                          check=True).stdout.strip()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=11)
    ap.add_argument("--models", nargs="?", const="all", default=None,
                    help="also fit GOLD with these models (comma-separated; default all)")
    ap.add_argument("--no-commands", action="store_true", help="only --models")
    ap.add_argument("--reference", default=None,
                    help="reference program timed side by side: a command with {input} and "
                         "{output}, e.g. '/tmp/cpp/djfit {input} {output}'")
    ap.add_argument("--out", default=str(ROOT / "results" / "cli.json"))
    args = ap.parse_args()
    py = sys.executable
    previous = {}
    if Path(args.out).is_file():
        previous = json.loads(Path(args.out).read_text())
    result = {"benchmark": "whole-process CLI",
              "machine": {"platform": platform.platform(), "python": platform.python_version(),
                          "cpus": os.cpu_count()},
              "revision": _git("rev-parse", "--short", "HEAD"),
              "load_average_before": os.getloadavg(), "c_reference_s": C_REFERENCE_S}
    with tempfile.TemporaryDirectory(prefix="bench-cli-") as tmp:
        tmp = Path(tmp)
        gold, bad, what = _make_inputs(tmp)
        result["input"] = what
        if not args.no_commands:
            print(f"timing {args.runs} runs of each command ...", flush=True)
            result["commands"] = time_commands(py, gold, bad, args.runs,
                                               reference=args.reference)
            print("breakdown of the fit process ...", flush=True)
            result["fit_breakdown"] = breakdown(py, gold, args.runs)
        else:   # keep the command timings with the revision and load they were measured at
            for key in ("commands", "fit_breakdown", "revision",
                        "load_average_before", "load_average_after"):
                if key in previous:
                    result[key] = previous[key]
        if args.models:
            from brdffit.fit import registry

            names = (registry.known_names() if args.models == "all"
                     else [m for m in args.models.split(",") if m])
            print(f"fitting {what} with {', '.join(names)} ...", flush=True)
            figs = dict(previous.get("models", {}).get("figures", {}))
            rev = _git("rev-parse", "--short", "HEAD")
            for name, fig in model_figures(gold, names).items():
                figs[name] = dict(fig, revision=rev, load_average=list(os.getloadavg()))
            result["models"] = {"input": what, "figures": figs,
                                "measured_at_revision": rev + " (the last --models run; each "
                                "figure carries its own revision when measured since)",
                                "load_average": os.getloadavg()}
        elif "models" in previous:
            result["models"] = previous["models"]
    if not args.no_commands:
        result["load_average_after"] = os.getloadavg()
    result["note"] = ("children run with bytecode caching (PYTHONPYCACHEPREFIX in a temporary "
                      "folder; this machine's sessions set PYTHONDONTWRITEBYTECODE=1), after one "
                      "warm-up run of each command; medians over the runs, interleaved")
    import shutil

    shutil.rmtree(_PYCACHE, ignore_errors=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=1) + "\n")

    if "commands" in result:
        print(f"\n{'command':<40}{'wall med':>9}{'CPU med':>9}")
        for name, r in result["commands"].items():
            status = "" if r["exit"] in (0, None) else f"  (exit {r['exit']})"
            if "fit_over_reference" in r:
                status += "  fit / reference: {wall_s:.2f} wall, {cpu_s:.2f} CPU".format(
                    **r["fit_over_reference"])
            print(f"{name:<40}{r['wall_s']['median']:>9.3f}{r['cpu_s']['median']:>9.3f}"
                  f"{status}")
            for fit_name, ratio in r.get("per_round_ratio_median", {}).items():
                print(f"    {fit_name} / reference, median of the per-round ratios: "
                      f"{ratio['wall_s']:.3f} wall, {ratio['cpu_s']:.3f} CPU")
        print("\nfit process, where the time goes (median wall s):")
        for k, v in result["fit_breakdown"]["phases_s"].items():
            print(f"  {k:<58}{v:8.3f}")
        print(f"  heavy packages loaded: {result['fit_breakdown']['heavy_loaded']}")
    print(f"load average before {result['load_average_before']}, "
          f"after {result['load_average_after']}; wrote {args.out}")


if __name__ == "__main__":
    main()
