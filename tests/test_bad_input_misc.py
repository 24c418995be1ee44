"""Bad input of public names whose other tests live elsewhere: errors name the argument."""

import numpy as np
import pytest

import fitting
import pmpjax as pj

KJ = np.diag([0.5, 1.5, 2.0])
MODEL = pj.Lambda0PMP(pj.Wrist(), KJ=KJ, q_rest=np.deg2rad([5.0, 0, 0]), W=pj.damping_from_stiffness(KJ, 0.08))
PLANNER = pj.ArimotoPlanner(k=22.5, tau=0.08)
Q0 = np.deg2rad([5.0, 0, 0])


@pytest.mark.bad_input("pj.simulate", "pj.simulate_sequence", "pj.SaveAt")
def test_simulate_rejects_bad_input():
    with pytest.raises(ValueError, match="target"):
        pj.simulate(MODEL, PLANNER, Q0, np.array([0.1, np.nan]), duration=0.1)
    with pytest.raises(ValueError, match="target"):
        pj.simulate(MODEL, PLANNER, Q0, np.array([0.1, 0.0, 0.2]), duration=0.1)
    with pytest.raises(ValueError, match="q0"):
        pj.simulate(MODEL, PLANNER, np.zeros(2), np.array([0.1, 0.0]), duration=0.1)
    with pytest.raises(ValueError, match="duration"):
        pj.simulate(MODEL, PLANNER, Q0, np.array([0.1, 0.0]), duration=-0.1)
    with pytest.raises(ValueError, match="dt"):
        pj.simulate(MODEL, PLANNER, Q0, np.array([0.1, 0.0]), duration=0.1, dt=0.05)
    with pytest.raises(TypeError, match="model"):
        pj.simulate("wrist", PLANNER, Q0, np.array([0.1, 0.0]), duration=0.1)
    with pytest.raises(ValueError, match="targets"):
        pj.simulate_sequence(MODEL, PLANNER, Q0, np.array([0.1, 0.0]), duration=0.1)
    with pytest.raises(ValueError, match="one of"):
        pj.SaveAt(every=2, final=True)
    with pytest.raises(ValueError, match="every"):
        pj.SaveAt(every=0)
    with pytest.raises(ValueError, match="ts"):
        pj.SaveAt(ts=(0.2, 0.1))


@pytest.mark.bad_input("pj.figure3_data", "pj.plot_figure3")
def test_figure3_rejects_bad_input():
    with pytest.raises((ValueError, TypeError), match="dt"):
        pj.figure3_data(dt=-1e-3)
    with pytest.raises((ValueError, TypeError), match="no_such_parameter"):
        pj.figure3_data(no_such_parameter=1.0)
    with pytest.raises((ValueError, TypeError, KeyError), match="data"):
        pj.plot_figure3({"x": np.zeros(3)})


@pytest.mark.bad_input("pj.ShoulderElbowArm")
def test_shoulder_elbow_arm_rejects_bad_lengths():
    with pytest.raises(ValueError, match="L1"):
        pj.ShoulderElbowArm(L1=-0.3)
    with pytest.raises(ValueError, match="L2"):
        pj.ShoulderElbowArm(L2=np.nan)


@pytest.mark.bad_input("fitting.predict_pointing", "fitting.fit_time_constants")
def test_pointing_fits_reject_bad_analysis_and_parameters():
    for f in (fitting.predict_pointing, fitting.fit_time_constants):
        with pytest.raises((TypeError, ValueError), match="analysis"):
            f({"not": "an analysis"}, KJ, Q0)


def test_joint_angles_in_degrees_are_refused_as_radians(tmp_path):
    """A JointRecording built from degrees (fit_movements then fitted reaches of '108 rad') and a
    file whose degrees go beyond a full turn are refused, naming the joint, time or line and column."""
    t = np.arange(6) * 0.01
    q = np.zeros((6, 2))
    q[3, 1] = 108.1
    with pytest.raises(ValueError, match=r"^JointRecording\(<memory>\): `q` \[rad\] of joint 'elbow' is 108\.1 at "
                       r"t = 0\.03 s, beyond a full turn \(±2π\): degrees\? 108\.1° is 1\.887 rad"):
        pj.JointRecording("S1", "trial1", t, q, ("shoulder", "elbow"))
    path = tmp_path / "S1_trial1.csv"
    path.write_text("time,shoulder_deg,elbow_deg\n" + "".join(f"{k / 100},10,{400 if k == 3 else 90}\n"
                                                               for k in range(6)))
    with pytest.raises(ValueError, match=r"S1_trial1\.csv: line 5, column 3 \('elbow_deg'\): 400° is beyond a full "
                       r"turn \(±360°\), no joint angle$"):
        pj.read_joint_angles(path)
