"""pj.find_movements: reaches of a continuous recording against closed-form minimum-jerk reaches.

The recordings are built here, not by the code under test: a 3-link planar arm whose joint angles
follow minimum-jerk profiles ``10s³ − 15s⁴ + 6s⁵`` between known postures, at 100 Hz, with 0.2° of
seeded white noise on the joints. The true hand speed comes from the closed-form derivative of the
profile and the arm's own kinematics written out below (never from ``chain.fk``), and its 20 % /
5 %-of-peak crossings are located on a 10 kHz grid.
"""

import numpy as np
import pytest

import pmpjax as pj

FS = 100.0
LENGTHS = np.array([0.3, 0.25, 0.15])
NOISE = np.deg2rad(0.2)
ARM = pj.PlanarArm(LENGTHS)
POSTURES = np.deg2rad([[20.0, 60.0, 30.0], [50.0, 30.0, 10.0], [10.0, 80.0, 40.0], [40.0, 50.0, 0.0]])
#: (start [s], duration [s]) of three reaches from POSTURES[k] to POSTURES[k + 1], rests between.
THREE = ((1.0, 0.8), (2.8, 0.6), (4.5, 1.0))


def min_jerk(tau):
    tau = np.clip(tau, 0.0, 1.0)
    return 10 * tau**3 - 15 * tau**4 + 6 * tau**5


def min_jerk_rate(tau):
    """d/dτ of min_jerk: 30τ²(1 − τ)² inside (0, 1), 0 outside."""
    inside = (tau > 0) & (tau < 1)
    return np.where(inside, 30 * tau**2 * (1 - tau) ** 2, 0.0)


def joint_path(t, moves, postures):
    """Superposed minimum-jerk moves: ``q`` (T, 3), ``q̇`` (T, 3) of moves ``(t0, D)`` between
    successive postures (each move adds ``postures[k+1] − postures[k]``, Flash & Henis 1991)."""
    q = np.tile(postures[0], (t.size, 1))
    qd = np.zeros_like(q)
    for k, (t0, D) in enumerate(moves):
        dq = postures[k + 1] - postures[k]
        q = q + dq * min_jerk((t - t0) / D)[:, None]
        qd = qd + dq * (min_jerk_rate((t - t0) / D) / D)[:, None]
    return q, qd


def hand(q, qd=None):
    """Planar arm, relative joint angles: hand position (T, 2) and speed (T,) in closed form."""
    phi = np.cumsum(q, axis=1)
    x = np.stack([(LENGTHS * np.cos(phi)).sum(1), (LENGTHS * np.sin(phi)).sum(1)], axis=1)
    if qd is None:
        return x
    w = np.cumsum(qd, axis=1)
    v = np.stack([(-LENGTHS * np.sin(phi) * w).sum(1), (LENGTHS * np.cos(phi) * w).sum(1)], axis=1)
    return x, np.linalg.norm(v, axis=1)


def truth(moves, postures, windows):
    """True peak, 20 % and 5 % crossings [s] of the noise-free speed inside each (a, b) window."""
    tf = np.arange(windows[0][0], windows[-1][1], 1e-4)
    _, speed = hand(*joint_path(tf, moves, postures))
    out = []
    for a, b in windows:
        m = (tf >= a) & (tf <= b)
        tt, ss = tf[m], speed[m]
        i = int(np.argmax(ss))
        P = ss[i]
        row = dict(peak=P, t_peak=tt[i])
        for name, frac in (("onset", 0.2), ("rest", 0.05)):  # None: no crossing in the window
            before, after = tt[:i][ss[:i] < frac * P], tt[i:][ss[i:] < frac * P]
            row[f"t_{name}"] = before[-1] if before.size else None
            row[f"t_{name}_off"] = after[0] if after.size else None
        out.append(row)
    return out, tf, speed


def recording(t, moves, postures=POSTURES, *, noise=NOISE, seed=0, name="trial"):
    q, _ = joint_path(t, moves, postures)
    q = q + np.random.default_rng(seed).normal(0.0, noise, q.shape)
    return pj.JointRecording("S1", name, t, q, ("shoulder", "elbow", "wrist"))


def true_speed_at(t_query, moves, postures=POSTURES):
    _, s = hand(*joint_path(np.atleast_1d(np.asarray(t_query, float)), moves, postures))
    return s


T7 = np.arange(0.0, 7.0, 1 / FS)
WINDOWS3 = [(t0 - 0.3, t0 + D + 0.3) for t0, D in THREE]


@pytest.mark.parametrize("noise, tol", [(0.0, 0.5), (NOISE, 5.0)])  # tol [samples] around the expected ∓0.5
def test_onsets_and_offsets_are_the_closed_form_20_percent_crossings(noise, tol):
    rec = recording(T7, THREE, noise=noise)
    found = pj.find_movements(rec, ARM)
    true, _, _ = truth(THREE, POSTURES, WINDOWS3)
    assert len(found) == 3 and found.skipped == ()
    # The onset is the last sample below 20 % of the peak: up to one step before the crossing (noise-
    # free: within that step; the offset, the first sample below, within the step after it).
    err_on = (found.t_onset - [r["t_onset"] for r in true]) * FS
    err_off = (found.t_offset - [r["t_onset_off"] for r in true]) * FS
    assert np.all(np.abs(err_on + 0.5) <= tol), err_on
    assert np.all(np.abs(err_off - 0.5) <= tol), err_off
    assert np.allclose(found.peak_speed, [r["peak"] for r in true], rtol=0.1)
    assert np.all(np.abs(found.t_peak - [r["t_peak"] for r in true]) <= 0.1)  # flat top: the peak time wanders
    assert not found.cut_short.any()
    # Amplitudes: the straight hand displacement between the postures, within 4 mm.
    x = hand(POSTURES)
    assert np.allclose(found.amplitude, np.linalg.norm(np.diff(x, axis=0), axis=1), atol=4e-3)


@pytest.mark.parametrize("seed", range(10))
def test_windows_start_and_end_at_rest_around_the_onset_and_offset(seed):
    # Several noise draws: 5 % of the slower reaches' peaks (0.017 m/s) is at the speed noise, and a
    # window edge one sample inside the reach shows up in a few draws out of ten, not in every one.
    rec = recording(T7, THREE, seed=seed)
    found = pj.find_movements(rec, ARM)
    true, _, _ = truth(THREE, POSTURES, WINDOWS3)
    assert np.all(found.start <= found.onset) and np.all(found.end >= found.offset)
    assert np.all(found.onset < found.peak) and np.all(found.peak < found.offset)
    P = np.array([r["peak"] for r in true])
    # At rest in the noise-free profile (below 5 % of the true peak) ...
    assert np.all(true_speed_at(found.t_start, THREE) < 0.05 * P)
    assert np.all(true_speed_at(found.t_end, THREE) < 0.05 * P)
    # ... and near the true 5 % crossing, not somewhere in the pause before it.
    assert np.all(np.abs(found.t_start - [r["t_rest"] for r in true]) <= 0.12), found.t_start
    assert np.all(np.abs(found.t_end - [r["t_rest_off"] for r in true]) <= 0.12), found.t_end
    # The windows cut the recording's own arrays.
    assert [rec.t[w][[0, -1]].tolist() for w in found.windows] == np.stack([found.t_start, found.t_end], 1).tolist()
    assert found.recording == "trial" and found.subject == "S1" and found.speed.shape == rec.t.shape


@pytest.mark.parametrize("third", [[10.0, 80.0, 40.0], [0.0, 70.0, 40.0]])
def test_a_reach_cut_short_by_the_next_ends_at_the_speed_minimum_between_them(third):
    # Reach 1 (0.8 s); the next target appears when it has covered 60 % of its path, s(τ) = 0.6,
    # and the next reach is superposed on it (the hand turns: a dip of 25 % / 17 % of peak 1).
    tau = 0.5 + np.arange(0, 0.5, 1e-6)
    tau_cut = tau[np.argmin(np.abs(min_jerk(tau) - 0.6))]
    postures = np.stack([POSTURES[0], POSTURES[1], np.deg2rad(third), POSTURES[3]])
    moves = ((1.0, 0.8), (1.0 + 0.8 * tau_cut, 0.7), (3.6, 0.8))
    t = np.arange(0.0, 5.5, 1 / FS)
    (p1, p2), tf, speed = truth(moves, postures, [(0.7, 1.0 + 0.8 * tau_cut), (1.9, 2.8)])
    between = (tf > p1["t_peak"]) & (tf < p2["t_peak"])
    t_dip, dip = tf[between][np.argmin(speed[between])], speed[between].min()
    true, _, _ = truth(moves, postures, [(0.7, t_dip), (t_dip, 2.8), (3.3, 4.7)])
    # The designed profile: two peaks separated by a dip well above rest and well below either peak.
    assert 0.15 * true[0]["peak"] < dip < 0.3 * min(true[0]["peak"], true[1]["peak"])

    found = pj.find_movements(recording(t, moves, postures), ARM)
    assert len(found) == 3
    assert found.cut_short.tolist() == [True, False, False]
    assert found.end[0] == found.start[1]  # the shared sample: the speed minimum between the peaks
    assert found.end[0] == found.peak[0] + np.argmin(found.speed[found.peak[0]:found.peak[1] + 1])
    assert abs(found.t_end[0] - t_dip) <= 0.05, (found.t_end[0], t_dip)
    # Its offset is its own 20 % crossing when the smoothed dip goes below it, else the dip.
    P0 = found.peak_speed[0]
    assert np.all(found.speed[found.peak[0]:found.offset[0]] >= 0.2 * P0)
    assert found.offset[0] == found.end[0] or found.speed[found.offset[0]] < 0.2 * P0
    assert abs(found.t_onset[0] - true[0]["t_onset"]) <= 0.04
    # The next onset: its own 20 % crossing, or the dip when smoothing fills the dip above that level.
    assert abs(found.t_onset[1] - true[1]["t_onset"]) <= 0.04 or found.onset[1] == found.start[1]
    assert abs(found.t_start[0] - true[0]["t_rest"]) <= 0.12 and abs(found.t_end[2] - true[2]["t_rest_off"]) <= 0.12


#: Three postures in a line in joint space: two reaches in one direction whose speeds add up.
LINE = np.deg2rad([20.0, 60.0, 30.0]) + np.outer([0.0, 1.0, 2.0], np.deg2rad([35.0, -25.0, -15.0]))


def _dip_of(t1, D=0.8):
    """The closed-form hand speed's dip between the two peaks of reaches (1.0, D) and (t1, D) along
    LINE, as a fraction of the lower peak (its prominence), and the peaks' times."""
    tf = np.arange(0.5, t1 + D + 0.5, 1e-3)
    _, speed = hand(*joint_path(tf, ((1.0, D), (t1, D)), LINE))
    inner = np.flatnonzero((speed[1:-1] > speed[:-2]) & (speed[1:-1] >= speed[2:])) + 1
    if len(inner) < 2:
        return 0.0, tf[inner]
    a, b = inner[0], inner[-1]
    low = min(speed[a], speed[b])
    return (low - speed[a:b + 1].min()) / low, tf[[a, b]]


@pytest.mark.parametrize(("dip", "reaches"), [(0.1, 1), (0.3, 2)])
def test_two_reaches_are_separate_when_the_speed_between_them_dips_by_a_fifth(dip, reaches):
    """The documented default ``min_dip = 0.2`` by its behaviour: two reaches in one direction
    (equal peaks, about 0.5 m/s), started so that the closed-form speed between the peaks dips
    by 10 % of the lower peak, are one reach; by 30 %, two, each at its own peak."""
    starts = np.arange(1.3, 1.8, 0.005)
    t1 = starts[np.argmin([abs(_dip_of(t1)[0] - dip) for t1 in starts])]
    depth, t_peaks = _dip_of(t1)
    assert abs(depth - dip) < 0.02
    t = np.arange(0.0, t1 + 2.5, 1 / FS)
    found = pj.find_movements(recording(t, ((1.0, 0.8), (t1, 0.8)), LINE, seed=1), ARM)
    assert len(found) == reaches and not found.skipped
    if reaches == 2:
        np.testing.assert_allclose(found.t_peak, t_peaks, atol=0.1)  # (peaks 0.5 s apart; smoothing moves them)
    else:
        assert found.t_onset[0] < t_peaks[0] and found.t_offset[0] > t_peaks[1]


def test_a_twitch_below_min_peak_speed_is_skipped_with_its_reason():
    # A 12° flick of the wrist joint alone (0.3 s) in the pause between reaches 1 and 2.
    postures = np.concatenate([POSTURES[:2], POSTURES[1:2] + np.deg2rad([0.0, 0.0, 12.0]), POSTURES[2:]])
    moves = (THREE[0], (2.0, 0.3), *THREE[1:])
    (flick,), _, _ = truth(moves, postures, [(1.9, 2.4)])
    # Designed: 12x the rms speed noise (0.016 m/s), below the other reaches' peaks (0.34, 0.71, 0.35 m/s).
    assert 0.18 < flick["peak"] < 0.21
    rec = recording(T7, moves, postures)
    found = pj.find_movements(rec, ARM, min_peak_speed=0.3, min_peak_fraction=0.0)
    assert len(found) == 3 and len(found.skipped) == 1
    t_from, t_to, reason = found.skipped[0]
    assert flick["t_rest"] - 0.05 <= t_from < flick["t_peak"] < t_to <= flick["t_rest_off"] + 0.05
    assert "below min_peak_speed=0.3 m/s" in reason and "min_peak_fraction" not in reason
    # Relative to the largest peak instead.
    rel = pj.find_movements(rec, ARM, min_peak_speed=0.0, min_peak_fraction=0.4)
    assert len(rel) == 3 and [s[:2] for s in rel.skipped] == [(t_from, t_to)]
    assert "below min_peak_fraction=0.4 of the largest peak" in rel.skipped[0][2]
    assert "min_peak_speed" not in rel.skipped[0][2]
    # Above both default thresholds it is a reach of its own (its 20 % level, 0.04 m/s, is only 2.5x the
    # speed noise: its onset and offset are uncertain by ~0.05 s, so only the peak is checked) ...
    default = pj.find_movements(rec, ARM)
    assert len(default) == 4 and default.skipped == () and abs(default.t_peak[1] - flick["t_peak"]) <= 0.08
    # ... unless it is shorter than min_duration (0.22 s from onset to offset, noise-free).
    short = pj.find_movements(rec, ARM, min_duration=0.4)
    assert len(short) == 3 and len(short.skipped) == 1 and "shorter than min_duration=0.4 s" in short.skipped[0][2]
    assert short.skipped[0][0] <= flick["t_onset"] + 0.03 and short.skipped[0][1] >= flick["t_onset_off"] - 0.03


def test_the_default_min_duration_keeps_a_reach_of_0_2_s_and_skips_shorter_ones():
    # Documented: a 0.2 s minimum-jerk reach lasts 0.15 s between its 20 % crossings, the default
    # min_duration. Noise-free reaches of 0.18, 0.23 and 0.26 s, filtered at 20 Hz (their crossings
    # within a sample of the closed form): the first (0.133 s on this arm) is skipped, the others kept.
    moves = ((0.8, 0.18), (1.6, 0.23), (2.4, 0.26))
    true, _, _ = truth(moves, POSTURES, [(0.7, 1.5), (1.5, 2.3), (2.3, 3.2)])
    width = np.array([r["t_onset_off"] - r["t_onset"] for r in true])
    assert width[0] < 0.14 and np.all(width[1:] > 0.16), width
    t = np.arange(0.0, 3.6, 1 / FS)
    found = pj.find_movements(recording(t, moves, noise=0.0), ARM, smoothing_hz=20.0)
    assert len(found) == 2 and np.all(np.abs(found.t_peak - [true[1]["t_peak"], true[2]["t_peak"]]) <= 0.02)
    assert len(found.skipped) == 1 and "shorter than min_duration=0.15 s" in found.skipped[0][2]
    assert found.skipped[0][0] < true[0]["t_peak"] < found.skipped[0][1]


@pytest.mark.parametrize(("deg", "lo", "hi", "explicit"), [(4.5, 0.06, 0.09, dict(min_peak_fraction=0.0)),
                                                         (7.0, 0.105, 0.135, {})])
def test_the_default_peak_thresholds_are_0_1_m_per_s_and_a_fifth_of_the_largest(deg, lo, hi, explicit):
    # A noise-free wrist flick between reaches 1 and 2 (largest peak 0.7 m/s): at 0.06-0.09 m/s it is
    # no reach under the default min_peak_speed (0.1 m/s), at 0.105-0.135 m/s none under the default
    # min_peak_fraction (0.2 of the largest peak: 0.14 m/s); halving either threshold makes it one.
    postures = np.concatenate([POSTURES[:2], POSTURES[1:2] + np.deg2rad([0.0, 0.0, deg]), POSTURES[2:]])
    moves = (THREE[0], (2.0, 0.3), *THREE[1:])
    true, _, _ = truth(moves, postures, [(0.9, 1.9), (1.9, 2.4), (2.7, 3.5), (4.4, 5.6)])
    assert lo < true[1]["peak"] < hi < 0.2 * max(r["peak"] for r in true)
    rec = recording(T7, moves, postures, noise=0.0)
    assert len(pj.find_movements(rec, ARM, **explicit)) == 3
    half = dict(min_peak_speed=0.05) if explicit else dict(min_peak_fraction=0.1)
    assert len(pj.find_movements(rec, ARM, **explicit, **half)) == 4


def test_reaches_running_off_either_end_of_the_recording_are_skipped():
    t = np.arange(1.3, 5.0, 1 / FS)  # starts inside reach 1 (1.0..1.8 s), ends inside reach 3 (4.5..5.5 s)
    found = pj.find_movements(recording(t, THREE), ARM)
    true, _, _ = truth(THREE, POSTURES, WINDOWS3)
    assert len(found) == 1 and abs(found.t_onset[0] - true[1]["t_onset"]) <= 0.04
    assert len(found.skipped) == 2
    (a0, b0, r0), (a1, b1, r1) = found.skipped
    assert a0 == t[0] and "runs off the start of the recording" in r0 and b0 < found.t_start[0]
    assert b1 == t[-1] and "runs off the end of the recording" in r1 and a1 > found.t_end[0]
    assert 4.4 <= a1 <= 4.7


def test_times_are_in_the_recordings_own_clock():
    t = 12.5 + T7
    moves = tuple((t0 + 12.5, D) for t0, D in THREE)
    found = pj.find_movements(recording(t, moves), ARM)
    at_zero = pj.find_movements(recording(T7, THREE), ARM)
    assert np.array_equal(found.onset, at_zero.onset) and np.array_equal(found.end, at_zero.end)
    for name in ("t_start", "t_onset", "t_peak", "t_offset", "t_end"):
        idx = getattr(found, name[2:])
        assert np.array_equal(getattr(found, name), t[idx])
        assert np.allclose(getattr(found, name), getattr(at_zero, name) + 12.5)
    true, _, _ = truth(THREE, POSTURES, WINDOWS3)
    assert np.all(np.abs(found.t_onset - 12.5 - [r["t_onset"] for r in true]) <= 0.04)


def test_a_recording_without_movement_has_no_reaches_and_nothing_skipped():
    found = pj.find_movements(recording(T7[:300], ()), ARM)
    assert len(found) == 0 and found.skipped == () and found.windows == ()
    assert found.start.shape == (0,) and found.amplitude.shape == (0,)
    # The noise estimate: white joint noise of 0.2° -> ~0.01 m/s rms hand speed after 6 Hz.
    assert 0.004 < found.noise_speed < 0.03


@pytest.mark.bad_input("pj.find_movements", "pj.Reaches")
def test_find_movements_rejects_bad_input():
    rec = recording(T7[:300], THREE[:1])
    with pytest.raises(TypeError, match="`recording`"):
        pj.find_movements(rec.q, ARM)
    with pytest.raises(TypeError, match="`chain`"):
        pj.find_movements(rec, LENGTHS)
    with pytest.raises(ValueError, match="`chain` has 2 joints but `recording.q` has 3"):
        pj.find_movements(rec, pj.PlanarArm([0.3, 0.25]))
    for kw, match in [
        (dict(smoothing_hz=50.0), "`smoothing_hz`.*Nyquist"), (dict(smoothing_hz=0), "`smoothing_hz`"),
        (dict(onset=1.0), "`onset`"), (dict(onset=0.0), "`onset`"),
        (dict(rest=0.2), "`rest`.*below `onset`"), (dict(rest=-0.01), "`rest`"),
        (dict(min_peak_speed=-1.0), "`min_peak_speed`"), (dict(min_peak_fraction=1.0), "`min_peak_fraction`"),
        (dict(min_dip=0.0), "`min_dip`"), (dict(min_duration=np.nan), "`min_duration`"),
        (dict(noise_factor=True), "`noise_factor`"), (dict(onset="0.2"), "`onset`"),
    ]:
        with pytest.raises(ValueError, match=match):
            pj.find_movements(rec, ARM, **kw)
    short = pj.JointRecording("S1", "short", T7[:30], rec.q[:30], rec.joint_names)
    with pytest.raises(ValueError, match="`recording` is too short to smooth"):
        pj.find_movements(short, ARM)
    uneven = pj.JointRecording("S1", "uneven", np.r_[T7[:150], T7[151:301]], rec.q[:300], rec.joint_names)
    with pytest.raises(ValueError, match="`recording.t` must be evenly sampled"):
        pj.find_movements(uneven, ARM)
    # Reaches built by hand (e.g. labelled windows) are checked.
    good = pj.find_movements(rec, ARM)
    fields = {f: getattr(good, f) for f in ("recording", "subject", "start", "onset", "peak", "offset", "end",
                                            "t_start", "t_onset", "t_peak", "t_offset", "t_end", "peak_speed",
                                            "cut_short", "amplitude")}
    assert len(pj.Reaches(**fields)) == 1
    with pytest.raises(ValueError, match="`onset` must have shape"):
        pj.Reaches(**{**fields, "onset": np.r_[good.onset, good.onset]})
    with pytest.raises(ValueError, match="`start` <= `onset`"):
        pj.Reaches(**{**fields, "start": good.onset + 1})
    with pytest.raises(ValueError, match="`peak` must hold integer"):
        pj.Reaches(**{**fields, "peak": good.peak + 0.5})
    with pytest.raises(TypeError, match="`subject`"):
        pj.Reaches(**{**fields, "subject": None})
