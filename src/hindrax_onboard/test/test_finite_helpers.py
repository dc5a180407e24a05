"""The control tick's NaN helpers (hindrax_onboard/vehicle/state.py) against numpy's own:
``finite_or_zeros`` and ``finite_or_zero`` give what ``np.nan_to_num`` gives for finite and NaN
entries and 0 for an infinity (an unknown value, not the largest float); ``all_finite`` what
``np.all(np.isfinite(.))`` gives."""
from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from hindrax_onboard.vehicle.state import all_finite, finite_or_zero, finite_or_zeros

ANY_FLOAT = st.floats(allow_nan=True, allow_infinity=True, width=64)


@given(arrays(np.float64, st.integers(0, 8), elements=ANY_FLOAT))
def test_finite_or_zeros_is_nan_to_num_with_infinities_at_zero(a):
    got = finite_or_zeros(a)
    want = np.nan_to_num(a)
    want[np.isinf(a)] = 0.0
    assert got.shape == a.shape and got.dtype == np.float64
    np.testing.assert_array_equal(got, want)
    finite = np.isfinite(a)
    np.testing.assert_array_equal(a[finite], got[finite])  # the input is not changed in place


@given(st.lists(ANY_FLOAT, max_size=6))
def test_finite_or_zeros_takes_sequences_and_all_finite_agrees_with_numpy(values):
    as_array = np.array(values, dtype=float)
    np.testing.assert_array_equal(finite_or_zeros(values), finite_or_zeros(as_array))
    assert all_finite(values) == bool(np.all(np.isfinite(as_array)))
    assert all_finite(as_array) == all_finite(values)


@given(ANY_FLOAT)
def test_finite_or_zero_of_python_and_numpy_scalars(x):
    want = 0.0 if not math.isfinite(x) else x
    for value in (x, np.float64(x), np.array([x])[0]):
        got = finite_or_zero(value)
        assert type(got) is float and got == want
