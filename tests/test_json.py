"""brdffit._json: standard JSON of NumPy values and non-finite floats, numbers read back."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from brdffit._json import float_or_none, json_default, standard_json, strict_json_default


def test_standard_json_is_accepted_by_strict_json():
    obj = {1: (np.float32(0.5), float("inf"), -np.inf, np.nan), "n": np.int64(3),
           "a": [np.float64(np.nan), {"b": None, "s": "x"}]}
    out = standard_json(obj)
    assert out == {"1": [0.5, "inf", "-inf", "nan"], "n": 3,
                   "a": ["nan", {"b": None, "s": "x"}]}
    assert type(out["n"]) is int
    json.dumps(out, allow_nan=False)


def test_float_or_none_reads_back_standard_json():
    assert float_or_none(None) is None
    assert float_or_none("x") is None and float_or_none([1.0]) is None
    assert float_or_none("2.5") == 2.5 and float_or_none(np.int32(4)) == 4.0
    assert float_or_none("inf") == math.inf and float_or_none("-inf") == -math.inf
    assert math.isnan(float_or_none("nan"))
    assert float_or_none("nan", keep_nan=False) is None
    assert float_or_none(float("inf"), keep_nan=False) == math.inf


def test_defaults():
    assert json.dumps([np.float32(1.5), np.arange(2), Path("a/b")],
                      default=strict_json_default) == '[1.5, [0, 1], "a/b"]'
    with pytest.raises(TypeError):
        json.dumps(object(), default=strict_json_default)
    assert json.dumps({1, }, default=json_default) == '"{1}"'
