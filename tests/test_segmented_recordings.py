"""Recordings of one motion each (``fitting.fit_movements(segmented=True)``, the HuG-MP protocol):
the window, the start and final postures, and the movement duration T that fractions refer to,
against closed forms; the tied time constants against their documented values."""

import math

import jax.numpy as jnp
import numpy as np
import pytest

import pmpjax as pj
from fitting._movements import model as mdl
from fitting._movements.data import SAMPLES, segmented_reaches

L1, L2 = 0.3, 0.33
FS = 100.0


def _ik(x):
    """Closed-form elbow-down inverse kinematics of the two-link planar arm, x (N, 2) [m]."""
    r2 = np.sum(x**2, axis=-1)
    c2 = (r2 - L1**2 - L2**2) / (2 * L1 * L2)
    q2 = np.arccos(np.clip(c2, -1.0, 1.0))
    q1 = np.arctan2(x[:, 1], x[:, 0]) - np.arctan2(L2 * np.sin(q2), L1 + L2 * np.cos(q2))
    return np.stack([q1, q2], -1)


def _motion(D=0.8, rest=(0.3, 0.4), name="m1", cut_end=False):
    """A straight hand reach of 0.2 m with minimum-jerk timing over ``D`` s, at rest for ``rest``
    seconds before and after; joint angles by closed-form IK; ``cut_end``: the recording stops at
    the speed peak."""
    t = np.arange(0.0, rest[0] + D + rest[1] + 1e-9, 1.0 / FS)
    s = np.clip((t - rest[0]) / D, 0.0, 1.0)
    xi = 10 * s**3 - 15 * s**4 + 6 * s**5
    a, b = np.array([0.35, 0.10]), np.array([0.25, 0.27])
    q = _ik(a + xi[:, None] * (b - a))
    if cut_end:
        keep = t <= rest[0] + D / 2
        t, q = t[keep], q[keep]
    return pj.JointRecording("A", name, t, q, ("q1", "q2"), fs=FS)


def test_window_postures_and_movement_duration():
    chain = pj.PlanarArm([L1, L2])
    D = 0.8
    rec = _motion(D)
    sr = segmented_reaches("A", [rec, _motion(name="cut", cut_end=True)], chain, {})
    assert len(sr) == 1 and sr.recording == ("m1",)
    # the whole recording is the window; its first and last samples are the postures
    assert sr.duration[0] == pytest.approx(rec.t[-1] - rec.t[0])
    np.testing.assert_allclose(sr.q_start[0], rec.q[0], atol=1e-15)
    np.testing.assert_allclose(sr.q_end[0], rec.q[-1], atol=1e-15)
    np.testing.assert_allclose(sr.t[0], np.linspace(rec.t[0], rec.t[-1], SAMPLES))
    np.testing.assert_allclose(sr.q_obs[0], np.stack([np.interp(sr.t[0], rec.t, rec.q[:, j]) for j in range(2)], -1))
    # T between the crossings of 20 % of the peak of the minimum-jerk speed 30 s²(1 − s)²/D:
    # 16 s²(1 − s)² = 0.2, so s(1 − s) = √0.0125 and T = D √(1 − 4 √0.0125); within 2 samples
    T = D * math.sqrt(1.0 - 4.0 * math.sqrt(0.0125))
    assert abs(sr.t_ratio[0] * sr.duration[0] - T) <= 2.0 / FS, (sr.t_ratio[0] * sr.duration[0], T)
    # a lower level widens T: at 5 %, s(1 − s) = √(0.05/16)
    T5 = D * math.sqrt(1.0 - 4.0 * math.sqrt(0.05 / 16))
    sr5 = segmented_reaches("A", [rec], chain, {"onset": 0.05})
    assert abs(sr5.t_ratio[0] * sr5.duration[0] - T5) <= 2.0 / FS
    # the recording cut at the speed peak is skipped with its reason
    assert [why for r, *_, why in sr.skipped if r == "cut"] == [
        "hand speed never falls below 20% of its peak before the offset (cut by the recording)"]


def test_bad_segmentation_options_are_named():
    chain = pj.PlanarArm([L1, L2])
    with pytest.raises(ValueError, match=r"'smoothing_hz'"):
        segmented_reaches("A", [_motion()], chain, {"smoothing_hz": 6.0})
    with pytest.raises(ValueError, match=r"onset.*\(0, 1\)"):
        segmented_reaches("A", [_motion()], chain, {"onset": 1.5})


@pytest.mark.parametrize("model", mdl.MODELS)
def test_tied_time_constants_are_a_fifth_of_the_movement(model):
    # "tied": τ = τ0 = T/5 (the time-base generator: its duration the whole window), i.e. the
    # fractions' model at those values, with no timing parameter and no delay in segmented fits
    tied = mdl.Config(3, model, "tau0_KJ", "tied", delay=False)
    frac = mdl.Config(3, model, "tau0_KJ", "fractions", delay=False)
    assert mdl.n_params(tied) == mdl.n_params(frac) - 2 == 5 + 3
    assert not any(n.startswith("log(") or n.startswith("delay") for n in mdl.param_names(tied, ("a", "b", "c")))
    th = jnp.asarray(np.random.default_rng(0).normal(size=mdl.n_params(tied)))
    first = 0.0 if model == "lambda0_minjerk" else math.log(0.2)
    p, q = mdl.unpack(th, tied), mdl.unpack(jnp.concatenate([th, jnp.array([first, math.log(0.2)])]), frac)
    for k in ("KJ", "q_rest", "W", "a", "a0", "delay"):
        np.testing.assert_allclose(p[k], q[k], rtol=1e-15, err_msg=k)
    assert float(p["a0"]) == 0.2 and float(p["delay"]) == 0.0
    # fractions of T: τ0 on normalised time is 0.2 T / window
    ratio = jnp.array([0.5, 0.8])
    _, planner = mdl.model_and_planner(pj.PlanarArm([0.3, 0.3, 0.2]), p, jnp.array([1.0, 2.0]), tied, t_ratio=ratio)
    if model == "lambda0":
        np.testing.assert_allclose(planner.tau0, 0.2 * np.asarray(ratio))
        np.testing.assert_allclose(planner.tau, 0.2 * np.asarray(ratio))
    else:
        np.testing.assert_allclose(planner.duration, 1.0)


def test_refusals_before_any_fit_name_the_option_and_each_recording():
    import fitting

    chain = pj.PlanarArm([L1, L2])
    with pytest.raises(ValueError, match=r"unknown key 'nope'.*options of pmpjax.find_movements are .*min_peak_speed"):
        fitting.fit_movements(chain, [_motion()], find_options={"nope": 1})
    with pytest.raises(ValueError, match=r"unknown key 'smoothing_hz'.*segmented recordings are onset, smoothing"):
        fitting.fit_movements(chain, [_motion()], segmented=True, find_options={"smoothing_hz": 6.0})
    # nothing moves in "still": the refusal names the recording, its stretch and why
    still = pj.JointRecording("A", "still", np.arange(0.0, 2.0, 0.01), np.full((200, 2), 0.5), ("q1", "q2"), fs=FS)
    with pytest.raises(ValueError, match=r"no subject has a usable reach: A: still: .*0\.00–1\.99 s: hand speed never "
                                         r"exceeds 0\.001 \(nothing moves\)"):
        fitting.fit_movements(chain, [still], segmented=True)
