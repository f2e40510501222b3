"""Malformed fit files (issue 12): each generated case is refused with one
``BRDFFormatError`` naming the file and the field; a subset through ``brdffit info`` under a
1 GiB memory limit (exit 1, one line, < 5 s); random byte flips and truncations of valid files
load or raise ``BRDFFormatError``, nothing else."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from brdffit.errors import BRDFFormatError
from brdffit.io.fitfile import load_fit
from tests.support import malformed_fits as mf
from tests.support.hostile import run_limited

CASES = mf.cases()


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_malformed_fit_is_one_clear_error(case, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)                 # where an unpickled payload would write
    path = case.write(tmp_path)
    with pytest.raises(BRDFFormatError) as info:
        load_fit(path)
    msg = str(info.value)
    assert "\n" not in msg
    assert path.name in msg, msg
    for phrase in case.mentions:
        assert phrase in msg, f"{phrase!r} not in {msg!r}"
    assert not (tmp_path / "PICKLE_EXECUTED").exists()


@pytest.mark.parametrize("case", mf.cli_subset(), ids=[c.name for c in mf.cli_subset()])
def test_malformed_fit_through_the_cli(case, tmp_path):
    work = tmp_path / "work"
    work.mkdir()
    path = case.write(tmp_path)
    out = run_limited(["info", str(path)], cwd=work, timeout=30)
    assert out.problems(names=path.name, out_dir=work) == []
    for phrase in case.mentions:
        assert phrase in out.stderr


# ------------------------------------------------------------------------------------------
# fuzzing: byte flips and truncations of valid files (stored and deflated)
# ------------------------------------------------------------------------------------------
def _valid_files() -> dict[str, bytes]:
    with tempfile.TemporaryDirectory() as d:
        out = {}
        for base in ("tab-fresnel", "npf", "sum"):
            p = mf.valid_fit(d, base)
            out[base] = p.read_bytes()
            header, arrays = mf._state(base)
            q = mf.write_npz(Path(d) / f"{base}-deflated.npz", header, arrays, deflate=True)
            out[f"{base}-deflated"] = q.read_bytes()
        return out


VALID = _valid_files()


def _mutation():
    return st.tuples(
        st.sampled_from(sorted(VALID)),
        st.lists(st.tuples(st.one_of(st.integers(0, 700), st.integers(0, 1 << 20),
                                     st.integers(-300, -1)),
                           st.integers(1, 255)), min_size=0, max_size=6),
        st.one_of(st.none(), st.integers(0, 1 << 20), st.integers(-400, -1)),
    )


@settings(max_examples=40, deadline=None, suppress_health_check=list(HealthCheck))
@given(_mutation())
def test_flipped_or_truncated_fit_loads_or_is_a_format_error(mutation):
    base, flips, cut = mutation
    data = bytearray(VALID[base])
    for pos, xor in flips:
        data[pos % len(data)] ^= xor
    if cut is not None:
        data = data[:cut % (len(data) + 1)]
    with tempfile.TemporaryDirectory() as d:
        cwd = os.getcwd()
        os.chdir(d)
        try:
            path = Path(d) / "fuzzed.npz"
            path.write_bytes(bytes(data))
            try:
                model = load_fit(path)
            except BRDFFormatError as exc:
                assert "\n" not in str(exc) and "fuzzed.npz" in str(exc)
            else:
                wi = np.array([[0.0, 0.0, 1.0]])
                assert model.eval(wi, wi).shape == (1, 3)
            assert not Path("PICKLE_EXECUTED").exists()
        finally:
            os.chdir(cwd)
