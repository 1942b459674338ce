"""JetCalibration: validation names the field; interpolation is monotone and clamped."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.valve import JetCalibration

CAL = JetCalibration.from_points([(0.0, 0), (0.01, 150), (0.05, 600), (0.1, 1000)])


def test_interpolates_between_points() -> None:
    assert CAL.duty_for_force(0.0) == 0
    assert CAL.duty_for_force(0.01) == 150
    assert CAL.duty_for_force(0.03) == 375  # halfway 150..600
    assert CAL.duty_for_force(0.075) == 800
    assert CAL.max_force_n == 0.1


def test_clamps_outside_the_table() -> None:
    assert CAL.duty_for_force(-1.0) == 0
    assert CAL.duty_for_force(5.0) == 1000
    assert CAL.duty_for_force(math.inf) == 1000
    offset = JetCalibration((0.02, 0.2), (120, 900))
    assert offset.duty_for_force(0.0) == 120


def test_nan_force_is_rejected() -> None:
    with pytest.raises(ValueError, match="NaN"):
        CAL.duty_for_force(math.nan)


@pytest.mark.parametrize(
    ("force_n", "duty_permille", "field"),
    [
        ((0.0,), (0,), "force_n"),
        ((0.0, 0.1), (0,), "duty_permille"),
        ((0.0, 0.0), (0, 10), "force_n"),
        ((0.1, 0.0), (0, 10), "force_n"),
        ((-0.1, 0.1), (0, 10), "force_n"),
        ((0.0, math.nan), (0, 10), "force_n"),
        ((0.0, 0.1), (0, 1001), "duty_permille"),
        ((0.0, 0.1), (500, 400), "duty_permille"),
        ((0.0, 0.1), (0, 10.5), "duty_permille"),
    ],
)
def test_invalid_tables_name_the_field(force_n, duty_permille, field: str) -> None:
    with pytest.raises(ValueError, match=f"JetCalibration.{field}"):
        JetCalibration(force_n, duty_permille)


def test_is_frozen() -> None:
    with pytest.raises(AttributeError):
        CAL.force_n = (0.0, 1.0)  # type: ignore[misc]


@st.composite
def tables(draw):
    n = draw(st.integers(2, 6))
    forces = sorted(draw(st.sets(st.floats(0, 1, allow_nan=False), min_size=n, max_size=n)))
    duties = sorted(draw(st.lists(st.integers(0, 1000), min_size=n, max_size=n)))
    return JetCalibration(tuple(forces), tuple(duties))


@settings(max_examples=200, deadline=None)
@given(tables(), st.floats(-1, 2, allow_nan=False), st.floats(-1, 2, allow_nan=False))
def test_monotone_and_within_table_limits(cal: JetCalibration, a: float, b: float) -> None:
    lo, hi = sorted((a, b))
    d_lo, d_hi = cal.duty_for_force(lo), cal.duty_for_force(hi)
    assert d_lo <= d_hi
    assert cal.duty_permille[0] <= d_lo and d_hi <= cal.duty_permille[-1]
