"""The one check of a time argument and of a count argument: what they accept, what they refuse."""

from __future__ import annotations

import numpy as np
import pytest

from qpbench.exceptions import ParamError, positive_count, positive_seconds


@pytest.mark.parametrize("value", [1, 7, np.int64(3)])
def test_a_count_is_an_integer_of_at_least_one(value):
    assert positive_count(value, "jobs") == int(value)
    assert type(positive_count(value, "jobs")) is int


@pytest.mark.parametrize("value", [0, -2, 1.0, 2.5, "3", True, None])
def test_anything_else_is_refused_naming_the_key(value):
    with pytest.raises(ParamError, match=r"must be an integer >= 1, got") as err:
        positive_count(value, "--jobs")
    assert err.value.key == "--jobs"


@pytest.mark.parametrize("value", [1e-3, 2, "0.5"])
def test_a_duration_is_a_positive_finite_number(value):
    assert positive_seconds(value, "deadline") == float(value)


@pytest.mark.parametrize("value", [0, -1.0, float("inf"), float("nan"), "x", True, None])
def test_a_bad_duration_is_refused_naming_the_key(value):
    with pytest.raises(ParamError, match="must be a positive number of seconds") as err:
        positive_seconds(value, "deadline")
    assert err.value.key == "deadline"
