"""Mahajan et al. 2007 reproduced on synthetic canonical transport (no Blender)."""

import json
from math import comb

import numpy as np
import pytest
import scipy.linalg

from relightable_textures.lt_addon.transport import cpca as CP
from relightable_textures.lt_addon.transport import dimensionality as DM
from relightable_textures.lt_addon.checks import mahajan2007 as PM


@pytest.fixture(scope="module")
def report():
    return PM.mahajan2007_report()


def test_report_is_json_and_all_ok(report):
    json.dumps(report)
    for name, e in report.items():
        assert set(e) == {"value", "paper", "tolerance", "ok", "note"}, name
    bad = {k: v["value"] for k, v in report.items() if not v["ok"]}
    assert PM.all_ok(report), bad


def test_slopes(report):
    assert report["slope_convex_phong"]["value"]["slope"] >= 0.8
    assert 0.4 <= report["slope_step_shadow"]["value"]["slope"] <= 0.6


def test_resolution_scaling_is_sublinear(report):
    v = report["resolution_cost_ratio"]["value"]
    assert 1.0 < v["measured"] < 4.0
    assert v["measured"] == pytest.approx(v["predicted_4mu4"], rel=0.15)


def test_flatland_g_against_closed_form():
    # g(0) = int_{-pi/2}^{pi/2} cos^{2s} u du = pi C(2s, s) / 4^s
    s = 50
    g = PM.flatland_g(s)
    assert g(0.0) == pytest.approx(np.pi * comb(2 * s, s) / 4 ** s, rel=1e-6)
    assert g(0.3) == pytest.approx(g(-0.3), rel=1e-9)          # symmetric
    assert g(0.3) < g(0.0)


def test_toeplitz_dft_small_case_independent():
    # the symbol at r = 0 is sum_k g_k, an upper bound of the largest eigenvalue (Gershgorin)
    t = PM.toeplitz_vs_dft(50, np.pi / 2, 200)
    g = PM.flatland_g(50)
    a = np.linspace(-np.pi / 2, np.pi / 2, 200)
    k = np.arange(-199, 200) * (a[1] - a[0])
    lam = scipy.linalg.eigvalsh(scipy.linalg.toeplitz(g(np.arange(200) * (a[1] - a[0]))))
    assert t["eig_top5"][0] == pytest.approx(lam.max())
    assert lam.max() <= g(k).sum() + 1e-9
    assert t["rel_l2_sorted"] < 0.2


def test_step_transport_depends_on_x_only():
    L = PM.fibonacci_directions(500)
    T = PM.step_shadow_transport(16, L).reshape(16, 16, -1)
    assert np.all(T == T[:1])                                   # same in every row (y)
    assert T.min() == 0.0 and T.max() == 1.0
    # farther from the wall: fewer blocked directions
    assert np.all(np.diff(T[0].sum(axis=1)) >= 0)


def test_cpca_on_sphere_matches_theory_direction():
    # adaptive CPCA on a small Phong sphere image beats a single global PCA in cost
    L = PM.fibonacci_directions(600)
    T, inside = PM.phong_sphere_transport(24, 20, L)
    T = T[inside]
    N = CP.global_dimension(T, 0.999, subset=None)
    one = CP.fit_cpca(T, 1, tol=1e-3, N=N)
    ad = CP.adaptive_cpca(T, start_clusters=4, tol=1e-3, N=N, n_iter=3)
    assert ad.cost() <= CP.fit_cpca(T, 4, tol=1e-3, N=N, n_iter=3).cost()
    assert ad.cost() < one.cost()
    rep = DM.analyse(T, [0], edges=np.zeros((0, 2), int), sizes=[1], N=N)
    assert rep["N"] == N


def test_cluster_count_and_adaptive(report):
    v = report["cpca_cluster_count"]["value"]
    c = v["cost_per_vertex"]
    assert min(c) < c[0] and min(c) < c[-1]                      # interior minimum (Fig. 9b)
    a = report["adaptive_vs_fixed"]["value"]
    assert a["adaptive_cost_per_vertex"] <= a["fixed_same_count"]
    assert a["adaptive_cost_per_vertex"] < a["N"]                 # beats global PCA alone
