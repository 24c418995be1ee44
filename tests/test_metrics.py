import numpy as np
import pytest
from _reference import polygon_areas, shoelace

import pmpjax as pj


def test_curvature_areas_closed_forms():
    # Half circle of radius 1 below the directed line (0,0) -> (2,0): on its right, area π/2.
    th = np.linspace(np.pi, 0, 4001)
    path = np.stack([1 + np.cos(th), -np.sin(th)], -1)
    a_r, a_l = pj.curvature_areas(path, np.zeros(2), np.array([2.0, 0.0]))
    assert abs(float(a_r) - np.pi / 2) < 1e-6 and float(a_l) == 0.0
    # Reversing the direction of travel puts the same lobe on the left.
    a_r2, a_l2 = pj.curvature_areas(path[::-1], np.array([2.0, 0.0]), np.zeros(2))
    assert abs(float(a_l2) - np.pi / 2) < 1e-6 and float(a_r2) == 0.0
    # One sine period of amplitude a over length L: a L / π on each side; rotated frame.
    s = np.linspace(0, 1, 4001)
    c, sn = np.cos(0.7), np.sin(0.7)
    local = np.stack([s, 0.1 * np.sin(2 * np.pi * s)], -1)
    path = local @ np.array([[c, sn], [-sn, c]]) + np.array([0.3, -0.2])
    end = np.array([c, sn]) + np.array([0.3, -0.2])
    a_r, a_l = pj.curvature_areas(path, np.array([0.3, -0.2]), end)
    np.testing.assert_allclose([a_r, a_l], [0.1 / np.pi] * 2, rtol=1e-6)


@pytest.mark.bad_input("pj.curvature_areas", "pj.curvature_measures")
def test_curvature_measures_batch_and_errors():
    s = np.linspace(0, 1, 101)
    paths = np.stack([np.stack([s, k * s * (1 - s)], -1) for k in (-0.4, 0.0, 0.4)])
    a_sum, a_net = pj.curvature_measures(paths, np.zeros((3, 2)), np.tile([1.0, 0.0], (3, 1)), scale=1.0)
    exact = 0.4 / 6  # ∫ k s(1−s) ds with linear interpolation error O(h²)
    np.testing.assert_allclose(a_net, [exact, 0.0, -exact], rtol=1e-3)
    np.testing.assert_allclose(a_sum, [exact, 0.0, exact], rtol=1e-3)
    with pytest.raises(ValueError, match="path"):
        pj.curvature_areas(np.zeros((5, 3)), np.zeros(2), np.ones(2))
    with pytest.raises(ValueError, match="`path` needs at least 2"):
        pj.curvature_measures(np.zeros((1, 2)), np.zeros(2), np.ones(2))
    with pytest.raises(ValueError, match="`start`"):
        pj.curvature_measures(paths[0], np.array([np.nan, 0.0]), np.ones(2))
    with pytest.raises(ValueError, match="`end`"):
        pj.curvature_areas(paths[0], np.zeros(2), np.ones(3))


def test_curvature_areas_close_open_paths_like_a_polygon():
    # Measured paths cut at 20 % of peak speed start and end off the line that joins the targets:
    # the closing segments (start target → first sample, last sample → end target) enclose area.
    rng = np.random.default_rng(5)
    start, end = np.array([0.1, -0.05]), np.array([0.3, 0.2])
    u = (end - start) / np.linalg.norm(end - start)
    nrm = np.array([-u[1], u[0]])
    L = np.linalg.norm(end - start)
    for k in range(6):
        s = np.linspace(0.05, 0.93, 40) * L  # never reaches the targets along the line
        off = 0.03 * np.sin(np.pi * s / L * (1 + k % 3)) + 0.01 * rng.normal() + 0.004 * rng.normal(size=40)
        path = start + s[:, None] * u + off[:, None] * nrm
        a_r, a_l = (float(v) for v in pj.curvature_areas(path, start, end))
        ref_r, ref_l = polygon_areas(path, start, end)
        np.testing.assert_allclose([a_r, a_l], [ref_r, ref_l], rtol=1e-10, atol=1e-14)
    # One-sided open path: the area is the whole polygon's shoelace area.
    s = np.linspace(0.1, 0.8, 30) * L
    path = start + s[:, None] * u + (0.02 + 0.05 * np.sin(np.pi * s / L))[:, None] * nrm
    a_r, a_l = pj.curvature_areas(path, start, end)
    assert float(a_r) == 0.0
    np.testing.assert_allclose(float(a_l), abs(shoelace(np.vstack([start, path, end]))), rtol=1e-12)


def test_curvature_areas_gradient_matches_central_differences():
    import jax

    rng = np.random.default_rng(2)
    s = np.linspace(0.05, 0.95, 25)
    path = np.stack([s, 0.05 * np.sin(2 * np.pi * s) + 0.01], -1) + 0.002 * rng.normal(size=(25, 2))
    start, end = np.array([0.0, 0.0]), np.array([1.0, 0.1])
    w = rng.normal(size=2)

    def f(p):
        a_r, a_l = pj.curvature_areas(p, start, end)
        return w[0] * a_r + w[1] * a_l

    f = jax.jit(f)
    g = np.asarray(jax.grad(f)(path))
    h = np.sqrt(np.finfo(float).eps) * 0.1
    for i, j in [(0, 1), (3, 0), (12, 1), (24, 1), (24, 0)]:
        e = np.zeros_like(path)
        e[i, j] = h
        fd = (float(f(path + e)) - float(f(path - e))) / (2 * h)
        np.testing.assert_allclose(g[i, j], fd, rtol=1e-6, atol=1e-9)


@pytest.mark.bad_input("pj.center_out_targets", "pj.center_out_trials", "pj.target_radius")
def test_target_radius_nominal_or_visual_angle():
    from _reference import wrist_fk

    # Default: the paper's nominal π/12 m (which also normalises the curvature areas).
    tg = pj.center_out_targets()
    assert pj.TARGET_RADIUS == np.pi / 12 and pj.FIGURE3["radius"] == np.pi / 12
    np.testing.assert_allclose([np.linalg.norm(tg[k]) for k in pj.DIRECTIONS], np.pi / 12, rtol=1e-15)
    # A true 15° visual angle through Eq 6 (independent FK): pure FE of +15° points West, pure
    # RUD of +15° points South, at d·sin 15° (not π/12) from the centre, for any screen distance.
    for d in (1.0, 0.7):
        tg = pj.center_out_targets(angle_deg=15.0, d=d)
        np.testing.assert_allclose(tg["W"], wrist_fk(np.deg2rad([0.0, 15.0, 0.0]), d), atol=1e-15)
        np.testing.assert_allclose(tg["S"], wrist_fk(np.deg2rad([0.0, 0.0, 15.0]), d), atol=1e-15)
        assert abs(pj.target_radius(angle_deg=15.0, d=d) - d * 0.25881904510252074) < 1e-15
    # User-set radius flows through the protocol.
    _, seq = pj.center_out_trials(2, seed=1, radius=0.2)
    np.testing.assert_allclose(np.linalg.norm(seq[:, 0::2], axis=-1), 0.2)
    _, seq = pj.center_out_trials(2, seed=1, angle_deg=10.0)
    np.testing.assert_allclose(np.linalg.norm(seq[:, 0::2], axis=-1), np.sin(np.deg2rad(10.0)))
    with pytest.raises(ValueError, match="at most one of `radius`"):
        pj.center_out_targets(0.2, angle_deg=15.0)
    with pytest.raises(ValueError, match="`angle_deg`"):
        pj.center_out_trials(2, angle_deg=95.0)
    with pytest.raises(ValueError, match="`radius`"):
        pj.center_out_targets(-0.1)
    with pytest.raises(ValueError, match="`d`"):
        pj.target_radius(angle_deg=15.0, d=0.0)
    with pytest.raises(ValueError, match="`n_trials`"):
        pj.center_out_trials(0)
