"""granflow.analysis.compare: the one "agrees within 2 SEs" rule."""

import math

import pytest
from granflow.analysis.compare import AGREE_SIGMA, agrees, difference_z, interval_z


def test_interval_z_is_zero_inside_and_the_gap_in_ses_outside() -> None:
    assert interval_z(1.38, 0.01, 1.37, 1.40) == 0.0
    assert interval_z(1.34, 0.01, 1.37, 1.40) == pytest.approx(3.0)
    assert interval_z(1.43, 0.01, 1.37, 1.40) == pytest.approx(3.0)
    # a point reference: the plain |x - x0| / se
    assert interval_z(0.52, 0.01, 0.5) == pytest.approx(2.0)


@pytest.mark.parametrize("value,se", [(math.nan, 0.1), (1.0, math.nan), (1.0, 0.0),
                                      (1.0, -0.1), (math.inf, 0.1)])
def test_interval_z_without_a_usable_se_is_nan(value: float, se: float) -> None:
    assert math.isnan(interval_z(value, se, 0.0, 1.0))


def test_difference_z_combines_the_ses_in_quadrature() -> None:
    diff, se, z = difference_z(1.0, 0.3, 0.5, 0.4)
    assert (diff, se, z) == pytest.approx((0.5, 0.5, 1.0))
    assert math.isnan(difference_z(1.0, 0.0, 0.5, 0.0)[2])


def test_agrees_is_within_two_ses_and_false_without_an_se() -> None:
    assert AGREE_SIGMA == 2.0
    assert agrees(2.0) and agrees(-2.0) and not agrees(2.01) and not agrees(-3.0)
    assert not agrees(math.nan)
    assert agrees(2.5, sigma=3.0)
