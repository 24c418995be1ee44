"""Times and joint angles in the wrong unit, and movements that stop short of their target.

Each documented threshold is pinned by behaviour (just below and just above it), each refusal
names its argument or key and hints the unit, and ``NOT_REACHED`` is checked against the
closed-form minimum-jerk path (along the λ0-PMP, ``ẋ = γ(t)(x_d − x)`` puts the hand at
``x0 + (x_d − x0) ξ(t/T)``, ``ξ(s) = 10 s³ − 15 s⁴ + 6 s⁵``).
"""

import re
import warnings

import jax
import numpy as np
import pytest

import pmpjax as pj
from pmpjax._data.simulation_config import ConfigError, build_simulation, read_config

KJ = np.diag([0.5, 1.5, 2.0])
Q_REST = np.deg2rad([5.0, 0.0, 0.0])
WRIST = pj.Wrist(1.0)
MODEL = pj.Lambda0PMP(WRIST, KJ=KJ, q_rest=Q_REST, W=0.08 * KJ)
TARGET = np.array([np.pi / 12, 0.0])  # E
# the start: the hand on the centre in the rest posture's null space (the paper's start)
Q0 = Q_REST


def _xi(s):
    return 10 * s**3 - 15 * s**4 + 6 * s**5


@pytest.fixture
def no_warnings():
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        yield


# --- the API refuses milliseconds and degrees, naming the argument, before any tracing --------


@pytest.mark.parametrize("make, name", [
    (lambda: pj.ArimotoPlanner(k=22.5, tau=80), "tau"),
    (lambda: pj.ArimotoPlanner(k=None, tau=0.08, tau0=80), "tau0"),
    (lambda: pj.ArimotoPlanner(k=22.5, tau=0.08, delay=-40), "delay"),
    (lambda: pj.MinimumJerkPlanner(duration=400), "duration"),
    (lambda: pj.damping_from_stiffness(KJ, 80), "tau0"),
    (lambda: pj.simulate(MODEL, pj.ArimotoPlanner(k=22.5, tau=0.08), Q0, TARGET, duration=400), "duration"),
])
def test_milliseconds_are_refused_by_name_with_the_unit_hint(make, name):
    with pytest.raises(ValueError, match=rf"`{name}` = -?\d+ s: .*milliseconds\? .* is -?0\.\d+ s"):
        make()


@pytest.mark.parametrize("make, name", [
    (lambda: pj.Lambda0PMP(WRIST, KJ=KJ, q_rest=[5.0, 0, 0], W=0.08 * KJ), "q_rest"),
    (lambda: pj.PMP2(WRIST, KJ=KJ, q_rest=[0, 0, -5.0], W=0.08 * KJ), "q_rest"),
    (lambda: pj.simulate(MODEL, pj.ArimotoPlanner(k=22.5, tau=0.08), [5.0, 0, 0], TARGET, duration=0.4), "q0"),
])
def test_degrees_typed_as_radians_are_refused_by_name(make, name):
    with pytest.raises(ValueError, match=rf"`{name}` = -?5 .*rad \(-?286°\).*degrees\? -?5° is -?0\.08727 rad"):
        make()


def test_refusals_come_before_tracing_and_traced_values_pass(monkeypatch):
    import importlib

    sim = importlib.import_module("pmpjax._pmp.simulate")  # (the face binds simulate to the function)

    monkeypatch.setattr(sim, "_kernel", lambda **kw: pytest.fail("compiled before refusing"))
    with pytest.raises(ValueError, match="`q0`"):
        pj.simulate(MODEL, pj.ArimotoPlanner(k=22.5, tau=0.08), [5.0, 0, 0], TARGET, duration=0.4)
    monkeypatch.undo()
    # inside a caller's jit the values are unknown: nothing is raised (the status judges the result)
    gain = jax.jit(lambda tau: pj.ArimotoPlanner(k=22.5, tau=tau).gain(0.4))(80.0)
    s = 0.4 / 80.0
    assert float(gain) == pytest.approx(22.5 * (1 - (1 + s) * np.exp(-s)), rel=1e-12)


# --- the documented thresholds, by behaviour --------------------------------------------------


@pytest.mark.parametrize("make", [
    lambda v: pj.ArimotoPlanner(k=22.5, tau=v),
    lambda v: pj.ArimotoPlanner(k=None, tau=0.08, tau0=v),
    lambda v: pj.damping_from_stiffness(KJ, v),
])
def test_time_constants_warn_above_2_s_and_are_refused_above_10_s(make, no_warnings):
    make(1.99)  # no warning
    with pytest.warns(UserWarning, match=r"= 2\.01 s is longer than any human reach's time constant"):
        make(2.01)
    with pytest.warns(UserWarning):
        make(9.99)
    with pytest.raises(ValueError, match="under 10 s; milliseconds"):
        make(10.01)


def test_durations_warn_above_10_s_and_are_refused_above_60_s(no_warnings):
    planner = pj.ArimotoPlanner(k=22.5, tau=0.08)
    pj.MinimumJerkPlanner(duration=9.99)
    with pytest.warns(UserWarning, match=r"`duration` = 10\.01 s is longer than any human reach's duration"):
        pj.MinimumJerkPlanner(duration=10.01)
    with pytest.raises(ValueError, match="`duration` = 60.01 s: .*under 60 s"):
        pj.MinimumJerkPlanner(duration=60.01)
    with pytest.raises(ValueError, match="`duration` = 60.01 s"):
        pj.simulate(MODEL, planner, Q0, TARGET, duration=60.01)


@pytest.mark.parametrize("chain, warn_above, refuse_above", [
    (pj.Wrist(1.0), np.pi / 2, np.pi),
    (pj.ShoulderElbowArm(), np.pi, 2 * np.pi),
    (pj.PlanarArm((0.3, 0.3, 0.2)), None, 2 * np.pi),
])
def test_joint_angle_ranges_per_chain(chain, warn_above, refuse_above, no_warnings):
    n = chain.n
    K = np.eye(n)

    def model(q1):
        return pj.Lambda0PMP(chain, KJ=K, q_rest=np.r_[q1, np.zeros(n - 1)], W=0.08 * K)

    eps = 1e-3
    if warn_above is not None:
        model(warn_above - eps)
        with pytest.warns(UserWarning, match=r"`q_rest` = .*beyond the human range.*degrees\?"):
            model(-(warn_above + eps))
    else:
        model(refuse_above - eps)
    with pytest.raises(ValueError, match=r"`q_rest` = .*beyond any .* joint's range"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model(refuse_above + eps)


# --- configuration files and sweeps -----------------------------------------------------------

FIGURE3 = """
[chain]
type = "wrist"
[model]
KJ_diag = [0.5, 1.5, 2.0]
q_rest_deg = [5, 0, 0]
tau0 = 0.08
[planner]
type = "arimoto"
k = 22.5
tau = 0.08
[simulation]
q0_deg = [5, 0, 0]
duration = 0.4
"""


def _config(tmp_path, old, new, name="c.toml"):
    text = FIGURE3 if old is None else FIGURE3.replace(old, new)
    assert old is None or old in FIGURE3 or old.startswith("[")
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("old, new, key, unit", [
    ("tau0 = 0.08", "tau0 = 80", "model.tau0", "milliseconds"),
    ("tau = 0.08", "tau = 80", "planner.tau", "milliseconds"),
    ("duration = 0.4", "duration = 400", "simulation.duration", "milliseconds"),
    ('type = "arimoto"\nk = 22.5\ntau = 0.08', 'type = "minimum_jerk"\nduration = 400', "planner.duration",
     "milliseconds"),
    ("q0_deg = [5, 0, 0]", "q0 = [5, 0, 0]", "simulation.q0", "degrees"),
    ("q_rest_deg = [5, 0, 0]", "q_rest = [5, 0, 0]", "model.q_rest", "degrees"),
])
def test_configuration_values_in_the_wrong_unit_are_refused_by_key(tmp_path, old, new, key, unit):
    path = _config(tmp_path, old, new)
    with pytest.raises(ConfigError) as e:
        build_simulation(read_config(path), path)
    msg = str(e.value)
    assert msg.startswith(f"{path}: `{key}` = ") and f"{unit}?" in msg, msg


def test_configuration_warnings_name_the_key_once(tmp_path):
    path = _config(tmp_path, "tau0 = 0.08", "tau0 = 5")
    with pytest.warns(UserWarning) as rec:
        build_simulation(read_config(path), path)
    assert [str(w.message).split(" = ")[0] for w in rec] == ["`model.tau0`"]


def test_sweep_rows_in_milliseconds_are_refused_by_key_and_row(tmp_path):
    from fitting._app.sweep_command import build_sweep

    path = tmp_path / "s.toml"
    path.write_text(FIGURE3 + '[sweep]\n[sweep.grid]\n"planner.tau" = [0.06, 80.0, 0.1]\n')
    with pytest.raises(ConfigError, match=re.escape("`planner.tau (row 2 of the sweep)` = 80 s") + ".*milliseconds"):
        build_sweep(path)
    path.write_text(FIGURE3 + '[sweep]\n[sweep.grid]\n"model.tau0" = [0.08, 5.0]\n')
    with pytest.warns(UserWarning) as rec:
        build_sweep(path)
    assert [str(w.message).split(" = ")[0] for w in rec] == ["`model.tau0 (row 2 of the sweep)`"]  # (1-based)
    # Swept angles in degrees beyond the chain's range (the wrist's ±180°) are refused, as simulate
    # refuses them outside a sweep (inside the sweep's compiled kernel it cannot).
    path.write_text(FIGURE3 + '[sweep]\n[sweep.grid]\n"simulation.q0_deg[0]" = [5, 400]\n')
    with pytest.raises(ConfigError, match=re.escape("simulation.q0_deg[0] = 400° in row 2 of the sweep is beyond "
                                                    "any Wrist joint's range (±180°)")):
        build_sweep(path)


def test_reach_tol_key_is_checked(tmp_path):
    path = _config(tmp_path, "duration = 0.4", "duration = 0.4\nreach_tol = 2")
    with pytest.raises(ConfigError, match=r"simulation\.reach_tol must be a number in \[0, 1\]"):
        build_simulation(read_config(path), path)
    path = _config(tmp_path, "duration = 0.4", "duration = 0.4\nreach_tol = 0.25")
    assert build_simulation(read_config(path), path)[4]["reach_tol"] == 0.25


# --- a movement that stops short is not SUCCESSFUL --------------------------------------------


@pytest.fixture(scope="module")
def short_and_full():
    """Minimum-jerk movements of planner duration T_p simulated for 0.4 s: T_p = 0.4 s reaches,
    T_p = 0.4/0.7 s ends at s = 0.7 (1 − ξ = 0.163 of the way left), T_p = 4 s at s = 0.1."""
    Tp = np.array([0.4, 0.4 / 0.7, 4.0])
    planner = pj.MinimumJerkPlanner(duration=Tp)
    traj = pj.simulate(MODEL, planner, Q0, TARGET, duration=0.4, dt=1e-3, saveat=pj.SaveAt(every=10))
    return Tp, planner, traj


def test_a_hand_that_stops_short_is_not_reached_by_the_closed_form(short_and_full):
    Tp, planner, traj = short_and_full
    x0 = np.asarray(WRIST.fk(Q0))
    d0 = np.linalg.norm(x0 - TARGET)
    left = np.linalg.norm(np.asarray(traj.x[:, -1]) - TARGET, axis=-1) / d0
    closed = 1 - _xi(np.minimum(0.4 / Tp, 1.0))
    np.testing.assert_allclose(left[1:], closed[1:], rtol=1e-6)  # (the reaching one: a capped-gain tail)
    assert left[0] < 1e-3
    assert (np.asarray(traj.status) == pj.Status.SUCCESSFUL).all()  # integration alone: all accurate
    st = lambda tol: np.asarray(pj.simulate(MODEL, planner, Q0, TARGET, duration=0.4, dt=1e-3,  # noqa: E731
                                            saveat=pj.SaveAt(every=10), reach_tol=tol).status).tolist()
    NR, OK = int(pj.Status.NOT_REACHED), int(pj.Status.SUCCESSFUL)
    # the rule: ended farther than reach_tol × the start distance; 0.163 left at s = 0.7
    assert st(0.1) == [OK, NR, NR]
    assert st(closed[1] * 1.001) == [OK, OK, NR] and st(closed[1] * 0.999) == [OK, NR, NR]
    assert "did not reach the target within the duration" in pj.status_message(NR)


def test_time_constants_in_milliseconds_inside_jit_end_not_reached():
    """Where the values cannot be checked (a caller's jit), ``τ = 80`` leaves the hand where it
    started, and the status says so. Bound: the gain stays below k (t/τ)²/2, and the hand's rate
    below that times λ_max(J W⁻¹ Jᵀ) ≤ 3/(τ0 λ_min(KJ)) (wrist, d = 1: |J| ≤ √3), so at most
    1 − exp(−3 k T³ / (6 τ² τ0 λ_min)) of the distance is covered."""
    k, T, tau, tau0 = 22.5, 0.4, 80.0, 0.08

    @jax.jit
    def run(tau):
        tr = pj.simulate(MODEL, pj.ArimotoPlanner(k=k, tau=tau), Q0, TARGET, duration=T, dt=1e-3,
                         saveat=pj.SaveAt(final=True), reach_tol=0.1)
        return tr.status, tr.x[-1]

    status, x_end = run(tau)
    d0 = np.linalg.norm(np.asarray(WRIST.fk(Q0)) - TARGET)
    left = np.linalg.norm(np.asarray(x_end) - TARGET) / d0
    assert left >= np.exp(-3 * k * T**3 / (6 * tau**2 * tau0 * 0.5)) > 0.99
    assert int(status) == pj.Status.NOT_REACHED
    status, _ = run(0.08)
    assert int(status) == pj.Status.SUCCESSFUL


def test_reach_tol_needs_the_end_saved():
    with pytest.raises(ValueError, match="`reach_tol` judges the hand at the end"):
        pj.simulate(MODEL, pj.ArimotoPlanner(k=22.5, tau=0.08), Q0, TARGET, duration=0.4,
                    saveat=pj.SaveAt(ts=[0.0, 0.2]), reach_tol=0.1)
    with pytest.raises(ValueError, match="`reach_tol`"):
        pj.simulate(MODEL, pj.ArimotoPlanner(k=22.5, tau=0.08), Q0, TARGET, duration=0.4, reach_tol=-1)


def test_simulate_command_reports_movements_that_stop_short(tmp_path, capsys):
    """The command with a planner slower than the simulation (minimum jerk over 4 s, simulated
    0.4 s): every movement written, none SUCCESSFUL, exit status 1; the hand 1 − ξ(0.1) of the way
    from each target, against the closed form."""
    from pmpjax._app import cli

    path = _config(tmp_path, 'type = "arimoto"\nk = 22.5\ntau = 0.08', 'type = "minimum_jerk"\nduration = 4.0')
    assert cli.main(["simulate", str(path), "--out", str(tmp_path / "o")]) == 1
    import json

    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert s["status"] == [pj.Status.NOT_REACHED.message] * 8
    d0 = np.pi / 12  # centre-out: every target 15° from the start on the centre
    x0 = np.asarray(WRIST.fk(np.deg2rad([5.0, 0, 0])))
    assert np.linalg.norm(x0) < 1e-12
    np.testing.assert_allclose(np.array(s["final_task_error"]) / d0, 1 - _xi(0.1), rtol=1e-6)
    assert "8 not successful" in capsys.readouterr().out


def test_batches_built_from_fitted_values_are_not_stopped_by_one_item():
    """The library's own batches (pointing predictions and fits through ``normalised_movements``)
    skip the unit checks: a diverged fit's q_rest of −94 rad in one item does not stop the other
    (the user's values are checked where the user passes them)."""
    from pmpjax.internal import normalised_movements

    KJ2 = np.broadcast_to(KJ, (2, 3, 3))
    q_rest = np.array([Q_REST, [-94.5, 0.0, 0.0]])
    tr = normalised_movements(KJ2, q_rest, np.array([0.2, 0.2]), np.array([0.2, 0.2]), np.array([Q0, Q0]),
                              np.array([TARGET, TARGET]), span=2.5, dt=0.01)
    assert np.asarray(tr.q).shape[0] == 2 and np.isfinite(np.asarray(tr.q)[0]).all()
    with pytest.raises(ValueError, match="`q_rest`"):
        pj.Lambda0PMP(WRIST, KJ=KJ2, q_rest=q_rest, W=0.08 * KJ2)


def test_sweep_rows_whose_hand_stops_short_are_not_reached(tmp_path):
    """A sweep row with τ = 5 s (legal, warned) leaves the hand where it started within 0.4 s: its
    row is NOT_REACHED, the τ = 0.08 s row succeeds; the final error against the bound of
    ``test_time_constants_in_milliseconds_inside_jit_end_not_reached`` (at least exp(−3 k T³ /
    (6 τ² τ0 λ_min)) = 0.49 of the distance left)."""
    import json

    from fitting._app.sweep_command import run_sweep_config

    path = tmp_path / "s.toml"
    path.write_text(FIGURE3.replace("duration = 0.4", 'duration = 0.4\ntargets = [[0.2617993877991494, 0.0]]')
                    + '[sweep]\nmetrics = ["final_error"]\n[sweep.grid]\n"planner.tau" = [0.08, 5.0]\n')
    with pytest.warns(UserWarning, match="planner.tau"):
        s = run_sweep_config(path, tmp_path / "o")
    assert s["status"] == [0, int(pj.Status.NOT_REACHED)] and s["failed"] == 1
    assert "did not reach the target within the duration" in s["reasons"][1]
    k, T, tau, tau0 = 22.5, 0.4, 5.0, 0.08
    err = np.array(s["outputs"]["final_error"])[:, 0] / (np.pi / 12)
    assert err[0] < 1e-3 and err[1] >= np.exp(-3 * k * T**3 / (6 * tau**2 * tau0 * 0.5))
    assert json.loads((tmp_path / "o" / "sweep.json").read_text())["status"][1] == int(pj.Status.NOT_REACHED)
