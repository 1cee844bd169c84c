"""The progress lines' time left: the estimate's stages scaled by the bake's own pace."""

import pytest

from relightable_textures.lt_addon.transport import estimate as est

SECONDS = {"other": 2.0, "direct": 60.0, "indirect": 6.0, "fit": 12.0}   # 80 s in all


def test_on_pace_the_time_left_is_the_estimates():
    assert est.estimated_elapsed(SECONDS, "direction 800/1600 (rays, about 9 s left)") == 32.0
    assert est.time_left(SECONDS, "direction 800/1600", 32.0) == pytest.approx(48.0)
    assert est.time_left(SECONDS, "indirect bake 3/6", 65.0) == pytest.approx(15.0)
    assert est.time_left(SECONDS, "models fitted", 80.0) == 0.0


def test_a_bake_twice_as_slow_as_estimated_says_so_at_once():
    """The statue and ground at 512^2: the calibration put the rays at 60 s and they took
    twice that; a quarter of the way through the directions the time left doubles too (the
    fixed figure said 41 s while 90 s were left)."""
    left = est.time_left(SECONDS, "direction 400/1600", 2.0 * 17.0)
    assert left == pytest.approx(2.0 * (80.0 - 17.0))
    # too early to judge the pace (under a tenth of the estimate): the plain remainder
    assert est.time_left(SECONDS, "direction 16/1600", 3.0) == pytest.approx(80.0 - 2.6)
    # a step the estimate does not place keeps the last figure
    assert est.time_left(SECONDS, "writing the files", 200.0, last=5.0) == 5.0
    assert est.time_left(SECONDS, "writing the files", 20.0) == 60.0
