"""Shared input checks (planeray._validate): NaN, infinities, bounds and integers."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from planeray._validate import check_finite_array, check_integer, check_nonnegative, check_number, check_positive
from planeray.camera import CameraModel
from planeray.errors import InputError


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, "600", None, True, 0.0, -1.0])
def test_positive_refuses_and_names_the_parameter(bad):
    with pytest.raises(InputError, match=r"^exposure_us must be a positive number, got "):
        check_positive(bad, "exposure_us")


@given(st.floats(min_value=1e-300, max_value=1e300))
def test_positive_accepts_every_finite_positive_float(x):
    assert check_positive(x, "x") == x


def test_bounds_and_strictness():
    assert check_number(0.0, "g", minimum=-1, maximum=1) == 0.0
    with pytest.raises(InputError, match=r"g must be a finite number > -1 and < 1, got 1"):
        check_number(1, "g", minimum=-1, maximum=1, min_inclusive=False, max_inclusive=False)
    assert check_nonnegative(np.float32(0.0), "ambient_e_per_us") == 0.0
    with pytest.raises(InputError, match=">= 0"):
        check_nonnegative(-1e-9, "ambient_e_per_us")


def test_integers():
    assert check_integer(np.int64(4), "n", minimum=1) == 4
    assert check_integer(4.0, "n") == 4
    for bad in (4.5, math.nan, "4", 0):
        with pytest.raises(InputError, match="n must be an integer >= 1"):
            check_integer(bad, "n", minimum=1)


def test_arrays():
    assert check_finite_array([1, 2], "p").shape == (2,)
    with pytest.raises(InputError, match="NaN"):
        check_finite_array([1.0, math.nan], "p")
    with pytest.raises(InputError, match="2-D"):
        check_finite_array([1.0], "p", ndim=2)
    with pytest.raises(InputError, match="real-valued"):
        check_finite_array(["a"], "p")


@pytest.mark.parametrize("field", ["ambient_e_per_us", "read_noise_e", "jitter_us", "full_well_e", "laser_electrons"])
def test_camera_model_refuses_nan(field):
    # ``simulate --ambient nan`` used to record NaN in the stack's metadata.
    with pytest.raises(InputError, match=field):
        CameraModel(**{field: math.nan})
