import math

from ovon.reports.power import min_detectable_diff


def test_mde_hand_computation():
    assert abs(min_detectable_diff(500, sd_d=0.5) - 2.8016 * 0.5 / math.sqrt(500)) < 1e-4
    assert abs(min_detectable_diff(500, sd_d=0.5) - 0.0626) < 1e-3
    assert abs(min_detectable_diff(500) - 0.125) < 1e-3


def test_mde_shrinks_as_inverse_sqrt_n():
    assert abs(min_detectable_diff(100, sd_d=0.5) / min_detectable_diff(400, sd_d=0.5) - 2.0) < 1e-9
    assert min_detectable_diff(500, p_a=0.2, p_b=0.3) < min_detectable_diff(500)


def test_measured_mde_falls_back_when_differences_do_not_vary():
    from ovon.reports.power import measured_mde

    assert abs(measured_mde([1.0, -1.0] * 50, 0.5, 0.5) - min_detectable_diff(100, sd_d=1.005037815)) < 1e-6
    assert abs(measured_mde([0.0] * 100, 0.5, 0.5) - min_detectable_diff(100, p_a=0.5, p_b=0.5)) < 1e-12
    assert measured_mde([0.0] * 100, 1.0, 1.0) == min_detectable_diff(100)  # both always succeed: the bound


def test_bad_arguments_are_refused():
    import pytest

    from ovon.reports.power import measured_mde

    for kwargs in ({"n": 0}, {"n": 10, "alpha": 1.5}, {"n": 10, "power": 0.0}):
        with pytest.raises(ValueError):
            min_detectable_diff(**kwargs)
    with pytest.raises(ValueError):
        measured_mde([], 0.5, 0.5)


def test_the_sentence_names_the_bound_and_the_planning_value():
    from ovon.reports.power import mde_sentence

    assert "12.5 points at worst" in mde_sentence(500)
    assert "about 8.1 for two agents near 30% SR" in mde_sentence(500, 0.3)
    assert "near" not in mde_sentence(500, 0.0)
