"""Material names → folders: one slug function, no two materials in one folder (issue 12 §2)."""

from __future__ import annotations

import csv
import hashlib
import json
import re
from pathlib import Path

import pytest

from brdffit.batch import enumerate_materials, make_tasks, run_batch
from brdffit.errors import BRDFError

HOSTILE = ["mat a", "mat_a", "金", "銀", "..", ".", "", "Gold", "gold", "con", "nul.txt",
           "a" * 300, "a" * 299 + "b", "x--0123456789ab", "mat/a", "mat\\a", "../../etc",
           "-rf", "é", "e\u0301", "a.", "a\x00b", "tab\there", "nan.bin", "nan.binary"]


def test_slug_is_safe_stable_and_injective():
    from brdffit.paths import slug

    slugs = [slug(n) for n in HOSTILE]
    assert len(set(slugs)) == len(HOSTILE)                       # no two names share a folder
    assert len({s.casefold() for s in slugs}) == len(HOSTILE)   # not on macOS/Windows either
    for name, s in zip(HOSTILE, slugs):
        assert re.fullmatch(r"[A-Za-z0-9._-]+", s) and s not in (".", "..")
        assert not s.startswith((".", "-")) and len(s) <= 80
        assert slug(name) == s                                   # stable
        if s != name:  # the hashed form names the exact name
            assert s.endswith(hashlib.sha256(name.encode("utf-8", "surrogatepass"))
                              .hexdigest()[:12])
    # plain names are their own slug: existing run folders stay valid
    for name in ("alum-bronze", "gold-ggx", "acrylic_felt_green_rgb", "nan.bin", "npf-g-from-d"):
        assert slug(name) == name


def test_report_folders_of_non_ascii_names_differ():
    from brdffit.evaluation.report import slugify
    from brdffit.paths import slug

    assert slugify("金") != slugify("銀")
    assert slugify("alum-bronze") == "alum-bronze" and slugify("金") == slug("金")


def test_batch_paths_are_distinct_and_inside_out(tmp_path):
    names = ["mat a", "mat_a", "金", "銀", "..", "../../escape"]
    tasks = make_tasks([(n, "synthetic:gold-ggx") for n in names], ["ggx"])
    out = tmp_path / "out"
    for kind in ("fit_path", "record_path"):
        paths = [getattr(t, kind)(out) for t in tasks]
        assert len(set(paths)) == len(names)
        root = out / ("fits" if kind == "fit_path" else "records")
        assert all(p.resolve().parent.parent == root.resolve() for p in paths)


def test_folder_with_colliding_stems_keeps_extensions(tmp_path):
    for f in ("nan.bin", "nan.binary", "gold.binary"):
        (tmp_path / f).write_bytes(b"")
    pairs = enumerate_materials(tmp_path)
    assert [n for n, _ in pairs] == ["gold", "nan.bin", "nan.binary"]
    assert all(Path(spec).is_absolute() for _, spec in pairs)


def test_list_file_names_are_unique_and_specs_absolute(tmp_path, monkeypatch):
    for d in ("a", "b"):
        (tmp_path / d).mkdir()
        (tmp_path / d / "x.binary").write_bytes(b"")
    lst = tmp_path / "list.txt"
    lst.write_text("a/x.binary\nb/x.binary\nsynthetic:gold-ggx\nsynthetic:gold-ggx\n")
    monkeypatch.chdir(tmp_path)
    pairs = enumerate_materials("list.txt")
    names = [n for n, _ in pairs]
    assert len(pairs) == 3 and len(set(names)) == 3 and "gold-ggx" in names
    assert {s for _, s in pairs} == {str(tmp_path / "a/x.binary"), str(tmp_path / "b/x.binary"),
                                     "synthetic:gold-ggx"}


def test_synthetic_list_with_brackets():
    assert enumerate_materials("synthetic:[gold-ggx, plastic-beckmann]") == [
        ("gold-ggx", "synthetic:gold-ggx"), ("plastic-beckmann", "synthetic:plastic-beckmann")]
    with pytest.raises(BRDFError, match="unknown synthetic material.*gold-ggx"):
        enumerate_materials("synthetic:gold,plastic-beckmann")


def test_two_specs_with_one_name_are_refused(tmp_path):
    tasks = make_tasks([("m", "synthetic:gold-ggx"), ("m", "synthetic:plastic-beckmann")], ["ggx"])
    with pytest.raises(BRDFError, match="'m'.*synthetic:gold-ggx.*synthetic:plastic-beckmann"):
        run_batch(tasks, tmp_path / "out", progress=False)
    assert not (tmp_path / "out" / "records").exists()


def test_batch_keeps_every_material_and_its_readable_name(tmp_path, dask_client):
    names = ["mat a", "mat_a", "金", "銀", ".."]
    tasks = make_tasks([(n, "synthetic:gold-ggx") for n in names], ["test-copy"])
    res = run_batch(tasks, tmp_path / "out", client=dask_client, metrics=False, progress=False)
    assert res["ran"] == 5 and res["failed"] == 0
    assert sorted(r["material"] for r in res["records"]) == sorted(names)
    rows = list(csv.DictReader((tmp_path / "out" / "summary.csv").open(encoding="utf-8")))
    assert sorted(r["material"] for r in rows) == sorted(names)
    assert len(list((tmp_path / "out" / "fits").glob("*/test-copy.npz"))) == 5
    for t in tasks:
        assert json.loads(t.record_path(tmp_path / "out").read_text())["material"] == t.material
    again = run_batch(tasks, tmp_path / "out", client=dask_client, metrics=False, progress=False)
    assert again["ran"] == 0 and again["skipped"] == 5  # a resume redoes none of them
