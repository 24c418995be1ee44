"""The independent multi-reach generator (tests/_movement_reference.py) is right: λ0-PMP reaches
end on their targets in the minimum-energy posture, it agrees with ``pj.simulate_sequence`` (the
only place pmpjax's simulator is used here), its MuJoCo kinematics agree with ``pj.MjcfChain``;
and ``MjcfChain.joint_names`` are the MJCF file's joint names."""

from pathlib import Path

import numpy as np
import pytest
from _movement_reference import (
    continuous_recording,
    mjcf_fk_jac_fn,
    null_space,
    planar_fk_jac,
    random_spd,
)

import pmpjax as pj

ARM5 = Path(pj.__file__).parent / "data" / "examples" / "arm5.xml"
TAU0 = TAU = 0.1
Q_REST = np.deg2rad([20.0, 10.0, 15.0, 60.0, 0.0])
Q_START = np.deg2rad([25.0, 10.0, 0.0, 85.0, 0.0])
STEPS = np.array([[0.10, 0.05, 0.05], [-0.05, -0.12, 0.10], [0.0, 0.10, -0.08]])  # [m], from the start's hand


@pytest.fixture(scope="module")
def arm5_trial():
    fk_jac, _ = mjcf_fk_jac_fn(ARM5)
    KJ = random_spd(np.random.default_rng(1), 5, cond=10.0, trace=5.0)
    targets = fk_jac(Q_START)[0] + STEPS
    hold = 20 * TAU0  # long: each reach settles (Arimoto ramp + ~15 τ0)
    t, q, info = continuous_recording(fk_jac, KJ, Q_REST, TAU0, TAU, Q_START, targets, hold, noise_deg=0.2, seed=3,
                                      t0=0.5, lead=0.3)
    return fk_jac, KJ, targets, hold, t, q, info


def test_random_spd_is_full_anisotropic_and_scaled():
    K = random_spd(np.random.default_rng(0), 5, cond=20.0, trace=5.0)
    ev = np.linalg.eigvalsh(K)
    np.testing.assert_allclose(K, K.T, atol=0)
    assert np.trace(K) == pytest.approx(5.0, rel=1e-12)
    assert ev[-1] / ev[0] == pytest.approx(20.0, rel=1e-9)
    assert np.min(np.abs(K[~np.eye(5, dtype=bool)])) > 1e-4  # full, not diagonal


def test_reaches_end_on_targets_in_the_equilibrium_posture(arm5_trial):
    fk_jac, KJ, targets, hold, t, q, info = arm5_trial
    # the clock: t0 + i/fs up to the end of the last reach; switches after the lead rest
    np.testing.assert_allclose(t, 0.5 + np.arange(t.size) / 100.0, rtol=0, atol=1e-12)
    assert t[-1] == pytest.approx(0.5 + 0.3 + 3 * hold, abs=1e-12)
    np.testing.assert_allclose(info["t_switch"], 0.8 + hold * np.arange(3), atol=1e-12)
    # (a) every reach ends on its target
    err = np.linalg.norm(info["x_final"] - targets, axis=1)
    assert np.all(err < 1e-4), err
    # the sampled path reaches each target just before the next one appears
    for k in range(3):
        i = np.searchsorted(t, info["t_switch"][k] + hold - 1e-9) - 1
        assert np.linalg.norm(info["x"][i] - targets[k]) < 2e-4
    # (b) λ0-PMP's final posture: the elastic torque has no null-space component (Nᵀ KJ (q − q_rest) = 0)
    for qf in info["q_final"]:
        N = null_space(fk_jac(qf)[1])
        assert N.shape == (5, 2)
        tau_el = KJ @ (qf - Q_REST)
        assert np.linalg.norm(N.T @ tau_el) < 1e-4 * np.linalg.norm(tau_el), N.T @ tau_el
    # Eq 10's gain at each reach's start, and the lead rest is the F = 0 field from Q_START
    assert np.all(np.isfinite(info["gains"])) and np.all(info["gains"] > 0)
    np.testing.assert_allclose(info["q"][0], Q_START, atol=1e-12)
    np.testing.assert_allclose(info["x"][t < 0.8], np.broadcast_to(fk_jac(Q_START)[0], (30, 3)), atol=1e-7)


def test_noise_is_seeded_gaussian_on_the_clean_path(arm5_trial):
    fk_jac, KJ, targets, hold, t, q, info = arm5_trial
    e = np.rad2deg(q - info["q"])
    assert e.shape == (t.size, 5)
    assert abs(np.std(e) - 0.2) < 0.02 and abs(np.mean(e)) < 0.02
    fk2, _ = mjcf_fk_jac_fn(ARM5)
    # same seed, same noise (a short trial: the noise is drawn after integration, in sample order)
    short = dict(noise_deg=0.2, seed=3, fs=100.0)
    _, qa, ia = continuous_recording(fk2, KJ, Q_REST, TAU0, TAU, Q_START, targets[:1], 0.2, **short)
    _, qb, _ = continuous_recording(fk2, KJ, Q_REST, TAU0, TAU, Q_START, targets[:1], 0.2, **short)
    np.testing.assert_array_equal(qa, qb)
    assert not np.allclose(qa, ia["q"])


def test_agrees_with_pmpjax_simulate_sequence_on_a_planar_arm():
    lengths = (0.30, 0.27, 0.08)
    KJ = random_spd(np.random.default_rng(7), 3, cond=6.0, trace=4.0)
    q_rest = np.deg2rad([30.0, 60.0, 10.0])
    q0 = np.deg2rad([20.0, 80.0, 5.0])
    tau0, tau, T = 0.08, 0.06, 0.5
    x0 = planar_fk_jac(q0, lengths)[0]
    targets = x0 + np.array([[0.08, 0.10], [-0.12, 0.02], [0.05, -0.10]])
    t, q, info = continuous_recording(lambda v: planar_fk_jac(v, lengths), KJ, q_rest, tau0, tau, q0, targets, T)
    model = pj.Lambda0PMP(pj.PlanarArm(lengths), KJ=KJ, q_rest=q_rest, W=tau0 * KJ)
    planner = pj.ArimotoPlanner(k=None, tau=tau, tau0=tau0)
    tr = pj.simulate_sequence(model, planner, q0, targets, duration=T, dt=1e-3, saveat=pj.SaveAt(every=10))
    assert np.all(np.asarray(tr.status) == pj.Status.SUCCESSFUL)
    qs = np.asarray(tr.q)  # (M, S + 1, n): t = 0, 0.01, ..., T of each movement
    S = qs.shape[1] - 1
    assert S == 50 and t.size == 3 * S + 1
    ref = np.concatenate([qs[0], qs[1, 1:], qs[2, 1:]])
    assert np.max(np.abs(np.rad2deg(q - ref))) < 0.01
    assert np.max(np.abs(np.rad2deg(info["q_final"] - qs[:, -1]))) < 0.01
    assert np.max(np.abs(np.rad2deg(q[-1] - q0))) > 5.0  # (the comparison is not vacuous)


def test_mjcf_kinematics_agree_with_mjcf_chain_and_joint_names():
    import xml.etree.ElementTree as ET

    chain = pj.MjcfChain(ARM5, "hand")
    names = tuple(j.get("name") for j in ET.parse(ARM5).find("worldbody").iter("joint"))
    assert chain.joint_names == names == ("shoulder_flexion", "shoulder_abduction", "shoulder_rotation",
                                          "elbow_flexion", "wrist_flexion")
    assert chain.n == 5 and chain.m == 3
    fk_jac, _ = mjcf_fk_jac_fn(ARM5)
    Q = np.random.default_rng(2).uniform(-1.5, 1.5, (6, 5))
    x_c, J_c = np.asarray(chain.fk(Q)), np.asarray(chain.jacobian(Q))
    for qq, x, J in zip(Q, x_c, J_c):
        x_r, J_r = fk_jac(qq)
        np.testing.assert_allclose(x, x_r, rtol=0, atol=1e-10)
        np.testing.assert_allclose(J, J_r, rtol=0, atol=1e-10)
    # hand redundancy: full row rank at a typical posture, 2-D null space
    assert np.linalg.svd(fk_jac(Q_START)[1], compute_uv=False)[-1] > 0.05
    # an unnamed joint: no names (the reader then matches columns by order)
    xml = ARM5.read_text().replace('name="wrist_flexion" ', "")
    assert pj.MjcfChain(xml, "hand").joint_names is None


def test_shipped_example_is_its_truth_plus_noise():
    """The shipped synthetic recordings (pmpjax/data/examples/reaching, made by pmpjax's simulator)
    are the independent generator's λ0-PMP with the README's truth, plus 0.2° white noise; the
    MjcfChain's joint names pick their columns; the .sto and .csv copies hold the same trial."""
    import csv
    import json
    import warnings

    here = ARM5.parent / "reaching"
    chain = pj.MjcfChain(ARM5, "hand")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rec = pj.read_joint_angles(here / "S2_trial1.mot", subject="S2", joints=chain)
        copies = [pj.read_joint_angles(here / f"S1_trial1.{ext}", joints=chain) for ext in ("mot", "sto", "csv")]
    assert rec.joint_names == chain.joint_names and rec.fs == pytest.approx(100.0)
    for c in copies:
        assert c.joint_names == chain.joint_names and c.q.shape == copies[0].q.shape
        np.testing.assert_allclose(c.q, copies[0].q, rtol=0, atol=1e-8)
    truth = json.loads((here / "truth.json").read_text())
    p = truth["subjects"]["S2"]
    with open(here / "targets.csv", newline="") as f:
        ev = [e for e in csv.DictReader(f) if (e["subject"], e["trial"]) == ("S2", "1")]
    targets = np.array([[float(e[c]) for c in "xyz"] for e in ev])
    t_on, t_off = (np.array([float(e[c]) for e in ev]) for c in ("t_on", "t_off"))
    np.testing.assert_allclose(t_on[1:], t_off[:-1], atol=1e-12)
    fk_jac, _ = mjcf_fk_jac_fn(ARM5)
    t, q, info = continuous_recording(fk_jac, np.asarray(p["KJ"]), np.deg2rad(p["q_rest_deg"]), p["tau0"], p["tau"],
                                      np.deg2rad(p["q_home_deg"]), targets, t_off - t_on, lead=t_on[0])
    np.testing.assert_allclose(rec.t, t, rtol=0, atol=1e-9)
    r = np.rad2deg(rec.q - q)  # noise alone: white, 0.2°
    assert abs(np.std(r) - 0.2) < 0.01
    c = np.cumsum(np.vstack([np.zeros((1, 5)), r]), axis=0)
    assert np.max(np.abs(c[50:] - c[:-50])) / 50 < 0.15  # 0.09 here; ≥ 0.34 with τ0 or τ 10 % off
    # the reaches move the arm and each reach ends near its target
    assert np.min(np.ptp(np.rad2deg(q), axis=0)) > 5.0
    assert np.max(np.linalg.norm(info["x_final"] - targets, axis=1)) < 2e-3
