"""The report's panel of the predicted optimal t: its y range spans at least +-25 % of the values'
middle (a wobble of a few per cent looks small), with a margin, never beyond the config's t range."""

import math

import pytest

from noisebo.view.report import t_range_shown


@pytest.mark.parametrize(
    ("values", "expected"),
    [
        ([2.40, 2.51], (2.455 * 0.75, 2.455 * 1.25)),  # a 4 % wobble: widened to +-25 % of 2.455 s
        ([1.0, 5.0], (1.0 - 0.2, 5.0 + 0.2)),  # already wide: the values and a 5 % margin
        ([0.2, 0.21], (0.2, 0.205 * 1.25)),  # widened, but not below t_min
        ([9.0, 9.5], (9.25 * 0.75, 10.0)),  # nor above t_max
        ([math.nan, 2.0], (1.5, 2.5)),  # a step without a value is left out
        ([math.nan], (0.2, 10.0)),  # nothing to show: the whole t range
    ],
)
def test_the_t_axis_is_wide_enough_and_inside_the_t_range(values, expected):
    assert t_range_shown(values, 0.2, 10.0) == pytest.approx(expected)
