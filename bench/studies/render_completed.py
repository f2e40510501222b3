"""Render stage of a running or finished ``brdffit batch`` folder, material by material, as
soon as a material's fits are complete (one process; the render tasks are the batch's own,
so a later ``brdffit batch --render`` on the same folder skips what this did).

Used to overlap the render stage with the tail of a long fit run on a small machine::

    .venv/bin/python bench/studies/render_completed.py runs/merl-full merl_nbrdf.zip \\
        --models tabulated,ggx,beckmann,sgd,npf-g-from-d,npf --extra npf-naive

``--extra`` models are fitted here (cheap ones) before rendering. Stops when every material
has a render record, or after ``--idle`` seconds without work.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "src"))

from brdffit.batch import (RenderSettings, _existing, enumerate_materials,  # noqa: E402
                           make_render_tasks, make_tasks, run_render_task, run_task)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out")
    ap.add_argument("source")
    ap.add_argument("--models", required=True)
    ap.add_argument("--extra", default="")
    ap.add_argument("--idle", type=float, default=900.0)
    ap.add_argument("--reverse", action="store_true",
                    help="walk the materials from the end (a second process next to a first)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    models = args.models.split(",")
    extra = [m for m in args.extra.split(",") if m]
    last_work = time.time()
    while True:
        pending = 0
        materials = enumerate_materials(args.source)
        for name, spec in (reversed(materials) if args.reverse else materials):
            tasks = make_tasks([(name, spec)], models + extra)
            main_recs = [_existing(t, out) for t in tasks[:len(models)]]
            render = make_render_tasks(tasks, RenderSettings())[0]
            if _existing(render, out) is not None:
                continue
            pending += 1
            if not all(r is not None for r in main_recs):
                continue
            for t in tasks[len(models):]:
                if _existing(t, out) is None:
                    rec = run_task(t, out)
                    print(f"{name}: {t.model} {rec['status']} {rec['wall_time_s']:.1f} s", flush=True)
            rec = run_render_task(render, out)
            print(f"{name}: render {rec['status']} {rec['wall_time_s']:.1f} s "
                  f"{rec.get('error') or ''}", flush=True)
            last_work = time.time()
        if pending == 0 or time.time() - last_work > args.idle:
            return 0
        time.sleep(20)


if __name__ == "__main__":
    sys.exit(main())
