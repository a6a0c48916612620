import math

from ovon.reports.paired import min_detectable_diff


def test_mde_hand_computation():
    assert abs(min_detectable_diff(500, sd_d=0.5) - 2.8016 * 0.5 / math.sqrt(500)) < 1e-4
    assert abs(min_detectable_diff(500, sd_d=0.5) - 0.0626) < 1e-3
    assert abs(min_detectable_diff(500) - 0.125) < 1e-3


def test_mde_shrinks_as_inverse_sqrt_n():
    assert abs(min_detectable_diff(100, sd_d=0.5) / min_detectable_diff(400, sd_d=0.5) - 2.0) < 1e-9
    assert min_detectable_diff(500, p_a=0.2, p_b=0.3) < min_detectable_diff(500)
