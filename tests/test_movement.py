"""Movement analysis (paper Section 2): segmentation at 20 % of peak speed, smoothing splines."""

import numpy as np
import pytest

import pmpjax as pj


def test_segmentation_finds_the_known_threshold_crossings():
    # Minimum-jerk bell 0.3..0.9 s inside rests, sampled at 120 Hz: speed ∝ s²(1-s)², s = (t-0.3)/0.6.
    t = np.arange(0.0, 1.2, 1 / 120)
    s = np.clip((t - 0.3) / 0.6, 0, 1)
    speed = 30 * s**2 * (1 - s) ** 2
    # Closed form: 30 s²(1-s)² = 0.2 · 30/16  ⇔  s(1-s) = sqrt(0.2)/4.
    r = np.sqrt(0.2) / 4
    s_lo, s_hi = (1 - np.sqrt(1 - 4 * r)) / 2, (1 + np.sqrt(1 - 4 * r)) / 2
    t_lo, t_hi = 0.3 + 0.6 * s_lo, 0.3 + 0.6 * s_hi
    start, end = pj.segment_by_speed(speed, threshold=0.2)
    # start: the last sample before the peak that is below the level; end: the first after it.
    assert start == int(np.floor(t_lo * 120 - 1e-9)) and t[start] < t_lo <= t[start + 1]
    assert end == int(np.ceil(t_hi * 120 + 1e-9)) and t[end - 1] <= t_hi < t[end]
    assert pj.segment_by_speed(speed) == (start, end)  # the default level is the paper's 20 %


def test_segmentation_reports_a_cut_movement():
    speed = np.linspace(0.0, 1.0, 50)  # still accelerating when the recording ends
    start, end = pj.segment_by_speed(speed)
    assert start is not None and end is None


def test_smoothing_spline_recovers_derivatives_of_a_noisy_path():
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 1.0, 1 / 120)
    x = np.stack([0.2 * np.sin(2 * np.pi * t), 0.1 * t**2], -1)
    noisy = x + 1e-3 * rng.normal(size=x.shape)  # 1 mm IMU-like noise
    p = pj.smooth_path(t, noisy)
    xdot = np.stack([0.4 * np.pi * np.cos(2 * np.pi * t), 0.2 * t], -1)
    inner = slice(6, -6)  # spline end effects
    assert np.max(np.abs(p.x - x)) < 1.5e-3
    assert np.sqrt(np.mean((p.xdot[inner] - xdot[inner]) ** 2)) < 0.03  # vs 1.26 m/s peak speed
    assert np.allclose(p.speed, np.linalg.norm(p.xdot, axis=-1))


@pytest.mark.bad_input("pj.smooth_path", "pj.segment_by_speed")
def test_movement_analysis_rejects_bad_input():
    t = np.arange(10.0)
    with pytest.raises(ValueError, match="`t`"):
        pj.smooth_path(t[::-1], np.zeros((10, 2)))
    with pytest.raises(ValueError, match="`x`"):
        pj.smooth_path(t, np.zeros((9, 2)))
    with pytest.raises(ValueError, match="NaN"):
        pj.smooth_path(t, np.full((10, 2), np.nan))
    with pytest.raises(ValueError, match="`speed`"):
        pj.segment_by_speed(np.array([0.0, np.nan, 1.0, 0.0]))
    with pytest.raises(ValueError, match="`threshold`"):
        pj.segment_by_speed(np.ones(5), threshold=1.5)


@pytest.mark.bad_input("pj.status_message")
def test_status_vocabulary():
    assert pj.Status.SUCCESSFUL == 0 and pj.status_message(0).startswith("successful")
    assert pj.status_message(np.array([0, 2]))[1] == pj.Status.MAX_STEPS.message
    with pytest.raises(ValueError):
        pj.status_message(99)


@pytest.mark.bad_input("pj.gcv_lambda")
def test_gcv_lambda_matches_scipys_generalised_cross_validation():
    from scipy.interpolate import make_smoothing_spline

    rng = np.random.default_rng(7)
    t = np.sort(rng.uniform(0.0, 1.5, 150))  # uneven sampling
    clean = np.stack([0.2 * np.tanh(6 * (t - 0.7)), 0.05 * np.sin(4 * t)], -1)
    y = clean + 1.5e-3 * rng.normal(size=clean.shape)
    lam = pj.gcv_lambda(t, y)
    assert lam.shape == (2,)
    for c in range(2):
        ref = make_smoothing_spline(t, y[:, c])(t)  # SciPy's own GCV choice
        ours = make_smoothing_spline(t, y[:, c], lam=lam[c])(t)
        # Same criterion, same minimiser: the fits agree far below the noise (1.5 mm).
        assert np.max(np.abs(ours - ref)) < 5e-5
    # The 1-D call is the first column's λ (the two differ tenfold). Not to the last bit: BLAS takes
    # other paths for one column and two, and the GCV score is flat enough near its minimum that
    # an ulp moves the golden-section minimiser by ~1e-7 relative (seen with NumPy 2.4's OpenBLAS).
    assert float(pj.gcv_lambda(t, y[:, 0])) == pytest.approx(lam[0], rel=1e-5)
    with pytest.raises(ValueError, match="`t` must be strictly"):
        pj.gcv_lambda(t[::-1], y)
    with pytest.raises(ValueError, match="must agree"):
        pj.gcv_lambda(t, y[:-1])
    with pytest.raises(ValueError, match="`y` contains NaN"):
        pj.gcv_lambda(t, np.full_like(y, np.nan))
    with pytest.raises(ValueError, match="at least 5"):
        pj.gcv_lambda(t[:4], y[:4])
