"""Write bench/README.md from the benchmarks' result files: each benchmark and study, what it
measures, how to run it, and its latest figure read from ``bench/results/``.

``make bench`` runs it after the benchmarks; ``.venv/bin/python bench/readme.py`` rewrites the
README by hand, ``--check`` exits 1 when the README is not what the results give
(``tests/test_bench_readme.py``).
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
README = HERE / "README.md"


@dataclass(frozen=True)
class Entry:
    """One benchmark or study: its name, what it measures, its command, its result files (the
    first holds the headline) and the headline read from that file."""

    name: str
    measures: str
    run: str
    results: tuple[str, ...]
    headline: Callable[[dict], str]


def _mean_min(summary: dict, unit: str = " dB") -> str:
    return f"{summary['psnr_mean']:.1f}{unit} mean, {summary['psnr_min']:.1f}{unit} lowest"


def _furnace(r: dict) -> str:
    d, p = r["summary"]["drjit"], r["summary"]["python"]
    return (f"{d['failed']} / {d['cases']} Dr.Jit and {p['failed']} / {p['cases']} Python cases "
            f"fail; max rel. error {max(d['max_rel_error'], p['max_rel_error']):.2%}")


def _tabulated(r: dict) -> str:
    s = r["validity"]["summary"]["default"]
    return (f"real materials: {s['invalid_fits']} invalid fits, cos-rel error mean "
            f"{s['mean_error']:.1%} / median {s['median_error']:.1%}; isotropic MERL-grid fit "
            f"{r['speed']['isotropic_merl_grid_N90']['median_s'] * 1e3:.0f} ms")


def _sgd(r: dict) -> str:
    s = r["speed"]["network"]
    cold = sorted(m["cpu_s_new_cold"] for m in s["materials"])
    return f"CPU per fit (cold): median {cold[len(cold) // 2]:.2f} s, max {cold[-1]:.2f} s"


def _npf(r: dict) -> str:
    v = r["per_variant"]
    return "mean time per material: " + ", ".join(
        f"{k} {v[k]['time_s']['avg']:.1f} s" for k in ("indep1", "gfromd", "naive", "bivariate")
        if k in v)


def _analytic(r: dict) -> str:
    s = r["summary"]["ggx-diffuse"]["cos_rel_error"]
    return f"ggx-diffuse cos-rel error median {s['median']:.1%} (mean {s['mean']:.1%})"


def _export(r: dict) -> str:
    return f"{len(r['results'])} materials × every target (per-material rows)"


def _cli(r: dict) -> str:
    c = r["commands"]
    return (f"`--help` {c['brdffit --help']['wall_s']['median'] * 1e3:.0f} ms, fit tabulated "
            f"{c['fit tabulated -o (read, fit, save)']['wall_s']['median']:.2f} s (median wall)")


def _robustness(r: dict) -> str:
    kinds = r["summary"]["by_kind"].values()
    return (f"{sum(k['clean'] for k in kinds)} / {sum(k['tried'] for k in kinds)} hostile "
            f"cases handled cleanly")


def _render_safety(r: dict) -> str:
    crashes = sum(c["crashes"] + c["failures"] for c in r["compare"] + r["demo"])
    oob = sum(v["out_of_bounds"] for v in r["out_of_bounds"].values())
    return f"{crashes} crashed or failed runs, {oob} out-of-bounds reads"


def _threejs(r: dict) -> str:
    s = r["summary"]
    d, p = s["scenes"]["sphere-distant"], s["paper_suite"]
    est = []
    for engine, label in (("three", "three.js"), ("materialx", "MaterialX")):
        e = [(sc.get(engine) or {}).get("estimate_error_db") for sc in s["scenes"].values()]
        e = [(x["within_2db"], x["of"]) for x in e if x]
        dist = s.get("sphere-distant", {})
        dist = dist if engine == "three" else dist.get(engine) or {}
        if "estimate_within_2db_vs_converged" in dist:      # against the converged fit
            e.append((dist["estimate_within_2db_vs_converged"], d["three"]["materials"]))
        if e:
            est.append(f"{label} {sum(x for x, _ in e)}/{sum(n for _, n in e)}")
    return (f"sphere-distant: three.js {_mean_min(d['three'])}, MaterialX "
            f"{_mean_min(d['materialx'])}; paper suite's spheres (per-material mean): three.js "
            f"{p['three']['mean']:.1f} dB mean, {p['three']['lowest_material_mean']:.1f} dB "
            f"lowest, MaterialX {p['materialx']['mean']:.1f} dB mean ({s['materials']} materials)"
            + (f"; cheap estimate within 2 dB of the engine: {', '.join(est)} (material × scene)"
               if est else ""))


BENCHMARKS = (
    Entry("io", "MERL `.binary` read; 10⁶ evaluations of a MERL table and of a Neural-BRDF "
          "network; UTIA read and evaluation", "bench/bench_io.py", ("io.json",),
          lambda r: f"MERL read {r['merl_read_s']:.2f} s; 10⁶ evaluations "
                    f"{r['merl_eval_trilinear_s']:.2f} s (table), {r['nbrdf_eval_s']:.2f} s "
                    f"(network)"),
    Entry("rgl", "10⁶ evaluations of each RGL `.bsdf`; agreement with Mitsuba 3's `measured`",
          "bench/bench_rgl.py", ("rgl.json",),
          lambda r: f"10⁶ evaluations ≤ {r['eval_1e6_s_max']:.2f} s; max rel. difference to "
                    f"Mitsuba {r['mitsuba_max_rel_all']:.1e}"),
    Entry("microfacet", "analytic models' evaluation speed; χ² tests of every sampler; G1 "
          "closed form vs quadrature", "bench/bench_microfacet.py", ("microfacet.json",),
          lambda r: f"χ² all passed: {r['chi2_all_passed']}; G1 max rel. error "
                    f"{r['g1_max_rel_error_overall']:.1e}"),
    Entry("furnace", "importance-sampled albedo vs quadrature, every evaluator and sampler "
          "(≈ 15 min; `--quick`)", "bench/bench_furnace.py", ("furnace.json",), _furnace),
    Entry("tabulated", "Dupuy et al. 2015: Table 1 recovery, round trips, speed; `--sections "
          "validity`: every real material, the paper's lobe vs the default",
          "bench/bench_tabulated.py [--real]", ("tabulated.json",), _tabulated),
    Entry("sgd", "Bagher et al. 2012: synthetic recovery; `--real` vs two-slice Beckmann; "
          "`--modes`, `--speed N` CPU time", "bench/bench_sgd.py [--real] [--speed 10]",
          ("sgd.json",), _sgd),
    Entry("npf", "Bagher et al. 2016, every variant over MERL: time, objective, failures; "
          "`--from-batch DIR` from a batch run", "bench/bench_npf.py [--limit 10]",
          ("npf.json", "npf_materials.csv", "npf_batch.json", "npf_batch_materials.csv"), _npf),
    Entry("analytic", "ggx-diffuse / beckmann-diffuse vs the moment GGX, synthetic and 10 MERL; "
          "validity of the glTF and MaterialX exports", "bench/bench_analytic.py",
          ("analytic.json",), _analytic),
    Entry("export", "export fidelity and times per target (`--real`, `--render`)",
          "bench/bench_export.py [--real]", ("export.json",), _export),
    Entry("engines", "glTF (and USD) exports rendered by Blender's importers and Cycles in "
          "`sphere-distant` and the paper suite's spheres vs our render of the fit: PSNR ± se, "
          "ratios, FLIP, our Cycles model's prediction (≈ 30 min; `make blender`)", "bench/bench_engines.py [--label NAME]",
          ("engines_blender.json",),
          lambda r: "Blender, sphere-distant: "
                    + _mean_min(r["current"]["summary"]["sphere-distant"]["blender"])
                    + "; paper suite's spheres (per-material mean): "
                    + f"{r['current']['summary']['paper_suite_spheres']['blender_psnr_mean']:.1f}"
                    + " dB mean, "
                    + f"{r['current']['summary']['paper_suite_spheres']['blender_psnr_min']:.1f}"
                    + " dB lowest"),
    Entry("engines_params", "the glTF parameters of the rules and of `optimize=\"engines\"` "
          "through the specification's BRDF and our models of Blender and three.js "
          "(no engine, noise-free)", "bench/bench_engines_params.py", ("engines_params.json",),
          lambda r: "rules: " + ", ".join(f"{k} {_mean_min(v)}"
                                          for k, v in r["summary"]["rule"].items())),
    Entry("engines_threejs", "glTF in three.js (WebGL 2, headless Chromium) and MaterialX's "
          "ESSL shaders vs our render of the fit", "bench/bench_engines_threejs.py",
          ("engines_threejs.json", "engines_threejs.csv"),
          _threejs),
    Entry("render", "Mitsuba 3 render time per model; `--crn`: CRN PSNR ± se of "
          "`synthetic:gold-ggx`", "bench/bench_render.py [--quick]; --crn",
          ("render.json", "render_crn.json"),
          lambda r: f"render CPU median {r['summary']['render_cpu_s_median']:.1f} s, max "
                    f"{r['summary']['render_cpu_s_max']:.1f} s"),
    Entry("report", "a one-material report end to end; `--crn-speed`: the four-scene "
          "comparison of 8 models", "bench/bench_report.py; --crn-speed",
          ("report.json", "report_crn.json"),
          lambda r: f"{r['total_seconds']:.0f} s (target {r['target_seconds']:.0f} s)"),
    Entry("render_safety", "repeated user commands on a chosen LLVM target; out-of-bounds "
          "reads in Dr.Jit's debug mode", "bench/bench_render_safety.py",
          ("render_safety.json",), _render_safety),
    Entry("cli", "whole `brdffit` processes: `--help`, `models`, `fit`, rejected inputs; "
          "`--models`: one fit per model (what `brdffit models` shows)",
          "bench/bench_cli.py [--runs 11] [--models]", ("cli.json",), _cli),
    Entry("robustness", "every malformed file, hostile name and fault under 1 GiB / 5 s",
          "bench/bench_robustness.py [--quick]", ("robustness.json",), _robustness),
    Entry("batch", "batch throughput with 1 and 2 Dask workers; `--full`: a whole-database "
          "run's records", "bench/bench_batch.py [--limit 8]", ("batch.json", "batch_full.json"),
          lambda r: f"2 workers / 1: × {r['speedup_2_over_1']:.2f}"),
    Entry("batch_cli", "one `brdffit batch` invocation, every model, every N-th MERL material;"
          " `--render`: with the four-scene renders (`batch_cli_render.json`)",
          "bench/bench_batch_cli.py --every 5 --out runs/db20 [--render]",
          ("batch_cli.json", "batch_cli_render.json"),
          lambda r: f"{len(r['materials'])} materials in {r['wall_s'] / 60:.1f} min; 100 "
                    f"projected {r['projected_all_materials_wall_h'] * 60:.0f} min"),
)

def _best_known(r: dict) -> str:
    return "; ".join(f"{m} default within 1 % of the best on {v['default_within_1pc']} / "
                     f"{v['materials']}" for m, v in r["per_model"].items())


BENCHMARKS += (
    Entry("best_known", "per MERL material, NPF variants and SGD: the defaults' objective "
          "against the best over many starts and longer runs; their CPU time",
          "nice bench/bench_best_known.py [--materials all]",
          ("best_known.json", "best_known.csv"), _best_known),
)

STUDIES = (
    Entry("threejs_ibl_terms", "which term of three.js's image-based lighting brightens a "
          "diffuse material under the paper suite's maps (the NumPy model of three with one "
          "term replaced at a time, vs Mitsuba's render of the fit)",
          "bench/studies/threejs_ibl_terms.py", ("threejs_ibl_terms.json",),
          lambda r: "courtyard: three " + f"{r['maps']['courtyard']['three']['psnr']:.1f} dB, "
                    "with the punctual BRDF's diffuse factor "
                    f"{r['maps']['courtyard']['punctual diffuse']['psnr']:.1f} dB"),
    Entry("engines_default", "the glTF default across renderers: rules vs the optimiser for "
          "Blender + three.js vs for the specification + Blender + three.js (their models, "
          "sphere-distant, 15 materials)", "bench/studies/engines_default.py",
          ("engines_default.json",),
          lambda r: "; ".join(f"{k}: " + ", ".join(f"{e} {v['psnr_mean'][e]:.1f}"
                                                    for e in ("specification", "blender",
                                                              "threejs"))
                              + f" dB mean, {v['cpu_seconds_mean']:.1f} s"
                              for k, v in r["summary"].items() if k in ("rule", "engines48",
                                                                        "all3_32"))),
    Entry("npf_defaults", "NPF with the product's defaults over MERL: convergence, time, "
          "objective vs the AWLS point and a reference run",
          "bench/studies/npf_defaults.py --reference runs/db20",
          ("npf_defaults.json", "npf_defaults_materials.csv"),
          lambda r: f"{len(r['converged'])} / {r['materials']} converged"
          if isinstance(r["converged"], list) else f"converged: {r['converged']}"),
    Entry("gfd_starts", "G-from-D from the data slices and from all ones: after how many "
          "polish iterations the start that ends lower can be told (G_FROM_D_SCREEN_POLISH)",
          "bench/studies/gfd_starts.py --part 0/2 & --part 1/2, then --summarise",
          ("gfd_starts.json", "gfd_starts_materials.jsonl"),
          lambda r: "after {k} iterations: {w} / {n} within 1 % of the best-known".format(
              k=4, w=r["per_screen"]["4"]["within_1pc_of_best_known"],
              n=r["per_screen"]["4"]["with_best_known"])),
    Entry("npf_polish", "the NPF polish per configuration, from stored AWLS fits",
          "bench/studies/npf_polish.py --start runs/db100v4",
          ("npf_polish.json", "npf_polish_materials.csv"),
          lambda r: f"{len(r['per_config'])} configurations"),
    Entry("npf_convergence", "independent-G objective against CPU time per solver "
          "configuration", "bench/studies/npf_convergence.py --configs default,omega1",
          ("npf_convergence.json", "npf_convergence.csv", "npf_convergence.png"),
          lambda r: f"{len(r['configs'])} configurations × {len(r['materials'])} materials"),
    Entry("coat_margin", "ggx-diffuse with and without the coat, rendered: the evidence for "
          "`COAT_MARGIN`", "bench/studies/coat_margin.py", ("coat_margin.json",
          "coat_margin.csv"), lambda r: f"{r['n']} materials"),
    Entry("coat_exports", "whether the coat helps the exported glTF and MaterialX materials",
          "bench/studies/coat_exports.py", ("coat_exports.json", "coat_exports.csv"),
          lambda r: f"{r['n']} materials"),
    Entry("export_fidelity", "per export target, the exported material vs the fit: error, "
          "PSNR, dE2000", "bench/studies/export_fidelity.py [--resume]",
          ("export_fidelity.json", "export_fidelity.csv"),
          lambda r: f"{r['n_materials']} materials × {len(r['per_target'])} targets"),
    Entry("database", "every model rendered on the paper suite with CRN over MERL + RGL: PSNR, "
          "wins, the papers' claims (fits by `fit_database.py`)",
          "bench/studies/fit_database.py --models …; bench/studies/database.py",
          ("database.json",), lambda r: f"{r['n_materials']} materials"),
    Entry("fit_identity", "whether two source trees write bit-identical fits (two "
          "`fit_database.py` runs)", "bench/studies/fit_identity.py A B",
          ("fit_identity.json",),
          lambda r: f"{r['arrays_identical']} / {r['compared']} fit files with identical "
                    f"arrays ({r['identical']} identical headers too)"),
)

INTRO = """\
# Benchmarks

Generated by `bench/readme.py` from `bench/results/` (`make bench` rewrites it): do not edit
the tables by hand.

* **Benchmarks** (`bench/bench_<name>.py`): speed and accuracy of the product, seconds to
  minutes each. `make bench` (`bench/run_all.py`) runs them all, in their real-data modes when
  `../shared/data` exists.
* **Studies** (`bench/studies/<name>.py`): per-material comparisons over the 100 Neural-BRDF
  MERL materials (and the 7 RGL ones) that chose or justify a default; hours each, resumable,
  run by hand; they need `../shared/data`.

Each writes `bench/results/<name>.json` (per-material rows in a `.csv` beside it), overwritten
by every run, with its command, date or revision and the load average; earlier runs are in git
history. The machine has 2 cores, often shared: compare CPU times across runs, wall times only
within one run. Every script takes `--help`; run them from the repository root with
`.venv/bin/python` (studies with `nice`).
"""

OUTRO = """\
`bench/repro/` holds minimal reproductions of third-party bugs
(`docs/design/render-crash-avx2.md`).

## Papers

Dupuy et al. 2015 §5.4 report < 1 s (isotropic) and < 20 s (anisotropic) per tabulated fit on
2015 hardware; Bagher et al. 2012 §6.4 report 2.5 min per SGD fit; Bagher et al. 2016 Table I
reports, single core, independent-G 59 / 2838 / 16421 s and G-from-D 135 / 765 / 7222 s
(min / avg / max) per material.
"""


def headline(entry: Entry, results: Path = RESULTS) -> str:
    """The latest figure of ``entry`` from its first result file, or why there is none."""
    path = results / entry.results[0]
    if not path.is_file():
        return "not run yet"
    try:
        return entry.headline(json.loads(path.read_text()))
    except (KeyError, IndexError, TypeError, ValueError) as exc:
        raise ValueError(f"{path}: no headline ({type(exc).__name__}: {exc})") from exc


def _table(entries, results: Path) -> str:
    rows = ["| name | measures | run | results | latest figure |", "|---|---|---|---|---|"]
    for e in entries:
        files = " ".join(f"`{f}`" for f in e.results)
        rows.append(f"| {e.name} | {e.measures} | `{e.run}` | {files} | "
                    f"{headline(e, results)} |")
    return "\n".join(rows) + "\n"


def render(results: Path = RESULTS) -> str:
    """The README text for the result files under ``results``."""
    return (INTRO + "\n## Benchmarks (`make bench`)\n\n" + _table(BENCHMARKS, results)
            + "\n## Studies (`bench/studies/`, by hand)\n\n" + _table(STUDIES, results)
            + "\n" + OUTRO)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="store_true",
                    help="exit 1 when bench/README.md differs from what the results give")
    args = ap.parse_args(argv)
    text = render()
    if args.check:
        same = README.is_file() and README.read_text() == text
        if not same:
            print(f"{README} is out of date: run .venv/bin/python bench/readme.py")
        return 0 if same else 1
    README.write_text(text)
    print(f"wrote {README}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
