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
    assert split == {"direct": 20.0, "horizons": 30.0, "indirect": 10.0, "indirect_pca": 0.0,
                     "fit": 8.0, "fit_choose": 0.0, "fit_blocks": 0.0, "other": 2.0}
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


def test_the_gathered_term_splits_into_the_grids_rays_and_the_textures_pca():
    """The gathered indirect term: its points and rays scale with the indirect grid, which the
    calibration bakes keep at the bake's own (the same units in both: a stage proportional to
    the grid's texels), and its PCA, which reads T's rows, with the texture's texels. The
    draft bumps at 256^2 with a 64^2 grid: calibrated with the grid at the texture's side,
    the estimate put the term at 2.9 s; it took 0.33 s."""
    split = est.stage_seconds({"direct_total": 5.0, "indirect_total": 1.5, "indirect_pca": 1.0,
                               "fit": 1.0, "bake_total": 8.0})
    assert split["indirect"] == 0.5 and split["indirect_pca"] == 1.0 and split["other"] == 0.5
    samples = []
    for R, pca in ((64, 0.1), (128, 0.25)):          # grid 64^2 in both; the PCA grows with R^2
        u = {st: est.units(st, R, 64, 1, 0) for st in est.STAGES}
        samples.append((u, {"indirect": 0.2 if R == 64 else 0.24, "indirect_pca": pca}))
    costs = est.fit_costs(samples)
    at = est.predict(costs, 256, 64, 1, 0)
    assert at["indirect"] == pytest.approx(0.22)      # the grid's own cost: the mean
    assert at["indirect_pca"] == pytest.approx(0.05 + 0.15 / (3 * 64 ** 2) * 256 ** 2)
    assert est.predict(costs, 256, 128, 1, 0)["indirect"] == pytest.approx(4 * 0.22)
    assert "indirect_pca" not in est.predict(costs, 256, 0, 1, 0)
    # the time left counts the PCA with the indirect term, before the models
    sec = {"other": 0.0, "direct": 10.0, "indirect": 1.0, "indirect_pca": 3.0, "fit": 2.0}
    assert est.estimated_elapsed(sec, "models fitted") == pytest.approx(16.0)
    assert est.estimated_elapsed(sec, "indirect bake 1/2") == pytest.approx(12.0)


def test_the_block_choice_is_a_stage_that_stops_growing_at_128():
    """The block viewport's choice fits sampled regions of at most 64^2 texels with at most
    four candidate blocks: the same work at every side from 128^2 up. Measured on the statue
    demo's calibration bakes (2026-12-04): 0.31 s at 64^2, 2.45 s at 128^2; as part of the fit,
    linear in texels, it made the 2048^2 estimate's fit 16.3 min."""
    split = est.stage_seconds({"fit": 5.0, "fit_choose": 2.0, "bake_total": 5.0})
    assert (split["fit"], split["fit_choose"]) == (3.0, 2.0)
    samples = [({st: est.units(st, R, 0, 2, 0) for st in est.STAGES},
                {"fit_choose": c}) for R, c in ((64, 0.31), (128, 2.45))]
    costs = est.fit_costs(samples)
    assert est.predict(costs, 2048, 0, 2, 0)["fit_choose"] == pytest.approx(2.45)
    assert est.predict(costs, 128, 0, 2, 0)["fit_choose"] == pytest.approx(2.45)


def test_the_time_left_places_the_horizon_trial_and_the_gathered_terms_steps():
    """Steps the ETA once did not place (it then froze on the last figure): the trial on
    sampled tiles ("horizon trial k/A azimuths, object i/n", an eighth of an object's
    horizons), and the gathered indirect term's steps (points and rays, then its PCA)."""
    from relightable_textures.lt_addon.transport.horizon_trial import FRACTION

    sec = {"other": 0.0, "direct": 10.0, "horizons": 16.0, "indirect": 1.0,
           "indirect_pca": 3.0, "fit": 2.0}
    at = est.estimated_elapsed
    assert at(sec, "horizon trial 64/128 azimuths, object 1/2") == pytest.approx(
        10.0 + 16.0 * 0.5 * FRACTION / 2)
    assert at(sec, "horizon trial 128/128 azimuths") == pytest.approx(10.0 + 16.0 * FRACTION)
    assert at(sec, "horizons 128/128 azimuths, object 2/2") == pytest.approx(26.0)
    assert at(sec, "indirect light: gather points") == pytest.approx(26.0)
    assert at(sec, "indirect light: 64 rays from 16,384 points") == pytest.approx(26.0)
    assert at(sec, "indirect light: 2 bounce(s), PCA 16") == pytest.approx(27.0)
    assert at(sec, "indirect light gathered") == pytest.approx(30.0)
    # the figure moves on those steps instead of staying at the last one
    assert est.time_left(sec, "indirect light: 2 bounce(s), PCA 16", 27.0, last=99.0) == \
        pytest.approx(5.0)


def test_the_block_viewports_fit_is_a_stage_of_its_own():
    """The block viewport's choice and fit come out of the fit stage (the estimate says them
    apart where auto may show the horizons instead: made only for an object whose horizons it
    does not show), and the time left counts them in the fit."""
    split = est.stage_seconds({"direct_total": 10.0, "indirect_total": 2.0, "fit": 9.0,
                               "fit_choose": 2.0, "fit_blocks": 5.0, "bake_total": 21.0})
    assert (split["fit"], split["fit_choose"], split["fit_blocks"]) == (2.0, 2.0, 5.0)
    # a bake's figures that overlap are clipped to the fit they came from
    assert est.stage_seconds({"fit": 3.0, "fit_choose": 2.0, "fit_blocks": 5.0})["fit_blocks"] \
        == 1.0
    sec = {"other": 0.0, "direct": 10.0, "fit": 2.0, "fit_choose": 2.0, "fit_blocks": 5.0}
    assert est.estimated_elapsed(sec, "models fitted") == pytest.approx(19.0)
