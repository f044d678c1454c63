"""The one JSON conversion (:func:`planeray.io.jsonable`) of every record, report and printed result."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from planeray.errors import StackError
from planeray.io import jsonable


def _strict(text: str):
    """Parse ``text`` as strict JSON: NaN and Infinity refused (what other languages' readers do)."""

    def refuse(token):
        raise ValueError(f"not strict JSON: {token}")

    return json.loads(text, parse_constant=refuse)


def test_reports_are_strict_json_with_nulls_for_non_finite_numbers():
    value = {"a": np.float32(0.25), 2: [np.int64(3), float("nan"), np.inf], "m": np.array([[1.0, np.nan]])}
    text = json.dumps(jsonable(value), indent=1)
    assert _strict(text) == {"a": 0.25, "2": [3, None, None], "m": [[1.0, None]]}
    assert type(jsonable(np.int64(3))) is int and type(jsonable(np.bool_(True))) is bool
    assert jsonable(Path("runs") / "a.zarr") == str(Path("runs") / "a.zarr")


def test_finite_false_keeps_non_finite_numbers_and_default_converts_the_rest():
    out = jsonable({"x": [np.float64(np.nan), -np.inf], "o": object()}, finite=False, default=lambda o: "obj")
    assert math.isnan(out["x"][0]) and out["x"][1] == -math.inf and out["o"] == "obj"


def test_strict_mode_names_where_the_unserializable_value_is():
    with pytest.raises(StackError, match=r"metadata\['a'\]\[1\] is not JSON-serializable \(type object\)"):
        jsonable({"a": [1, object()]}, finite=False, where="metadata", error=StackError)
    with pytest.raises(StackError, match="metadata key"):
        jsonable({(1, 2): 3}, where="metadata", error=StackError)
