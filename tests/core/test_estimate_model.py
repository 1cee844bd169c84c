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


def test_the_horizons_are_a_stage_of_their_own_at_their_own_side():
    """The horizons' seconds come out of the direct stage and scale with the horizon map's
    texels (a 2048^2 texture's horizons at 1024^2: a quarter); the time left places the
    "horizons k/A azimuths, object i/n" steps after the directions."""
    split = est.stage_seconds({"direct_total": 50.0, "horizons": 30.0, "indirect_total": 10.0,
                               "fit": 8.0, "bake_total": 70.0})
    assert split == {"direct": 20.0, "horizons": 30.0, "indirect": 10.0, "fit": 8.0,
                     "other": 2.0}
    costs = {"direct": est.StageCost(1.0, 1e-5), "horizons": est.StageCost(0.5, 2e-5)}
    at = est.predict(costs, 2048, 0, 1, 0, horizon_resolution=1024)
    assert at["horizons"] == pytest.approx(0.5 + 2e-5 * 1024 ** 2)
    assert at["direct"] == pytest.approx(1.0 + 1e-5 * 2048 ** 2)
    assert at["bake"] == pytest.approx(at["direct"] + at["horizons"])
    assert est.predict(costs, 512, 0, 1, 0)["horizons"] == pytest.approx(0.5 + 2e-5 * 512 ** 2)
    sec = {**SECONDS, "horizons": 20.0}                              # 100 s in all
    assert est.estimated_elapsed(sec, "horizons 64/128 azimuths") == pytest.approx(72.0)
    assert est.estimated_elapsed(sec, "horizons 64/128 azimuths, object 2/2") == \
        pytest.approx(62.0 + 20.0 * 0.75)
    assert est.estimated_elapsed(sec, "indirect bake 3/6") == pytest.approx(85.0)
    assert est.time_left(sec, "models fitted", 100.0) == 0.0
