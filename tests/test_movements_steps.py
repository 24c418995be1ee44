"""``fit_movements``' step refinement, by its documented behaviour: a subject whose integration
error at the optimum exceeds ``INTEGRATION_TOL_DEG`` is fitted again at twice the steps, alone
(the others keep their fits), until it passes or the step limit is reached, where it is
``INACCURATE`` (not converged) with a warning. The two stages are replaced by stand-ins whose
integration error is a known function of the step count (no simulation: the fits themselves are
checked against SciPy references in tests/test_movements*.py)."""

import math

import numpy as np
import pytest

import pmpjax as pj
from fitting._movements import fit as fit_module
from fitting._movements import model as mdl
from fitting._movements.data import SAMPLES, SubjectReaches


def reaches(name, B=2):
    rng = np.random.default_rng(len(name))
    q = np.deg2rad(30.0) + 0.1 * rng.standard_normal((B, SAMPLES, 3))
    return SubjectReaches(name, ("r",) * B, np.arange(B), np.tile(np.linspace(0, 1, SAMPLES), (B, 1)), q,
                          np.ones(B), q[:, 0], q[:, -1])


def stand_ins(monkeypatch, error_at, p, calls):
    """Stage 1 and stage 2 replaced: stage 2 moves each subject by 1 in 5 iterations and reports
    ``error_at[name](steps)`` [deg] as its integration error; ``calls`` records (subjects, steps)."""

    def stage1(theta0, data, chain, max_steps, *, cfg):
        S = theta0.shape[0]
        return dict(x=theta0, converged=np.ones(S, bool), status=np.zeros(S, int), steps=np.full(S, 3),
                    cost=np.ones(S), start=np.zeros((S, p)), weight=np.asarray(data["weight"]),
                    jac=np.zeros((S, 1, theta0.shape[1])))

    def stage2(x, data, chain, max_steps, *, cfg, steps, solver, approximate=True):
        names = [n for n, q in zip(error_at, subjects_q)
                 if any(np.array_equal(q, d[: len(q)]) for d in np.asarray(data["q_obs"]))]
        calls.append((tuple(names), steps))
        S, P = x.shape
        N = data["q_obs"].shape[1] * SAMPLES * 3 + 4 + data["q_obs"].shape[1] * mdl.n_nuisance(cfg)
        return dict(x=x + 1.0, cost=np.ones(S), residual=np.zeros((S, N)), converged=np.ones(S, bool),
                    status=np.zeros(S, int), steps=np.full(S, 5), jac=np.zeros((S, N, P)),
                    singular_values=np.ones((S, p)), V0=np.zeros((S, p, p)),
                    integration_error=np.array([math.radians(error_at[n](steps)) for n in names]))

    subjects = [reaches(name * (i + 1)) for i, name in enumerate(error_at)]
    subjects_q = [s.q_obs for s in subjects]
    monkeypatch.setattr(fit_module, "_stage1", stage1)
    monkeypatch.setattr(fit_module, "_stage2", stage2)
    return subjects


def test_only_inaccurate_subjects_are_refitted_at_twice_the_steps(monkeypatch):
    chain = pj.PlanarArm([0.3, 0.25, 0.15])
    cfg = mdl.Config(3, "lambda0", "tau0_KJ", "seconds", m=2)
    p = mdl.n_params(cfg)
    # integration error [deg] of each subject at `steps` steps per sample: A passes at 1, B at 8, C never
    error_at = {"A": lambda s: 0.001, "B": lambda s: 0.08 * (2 / s) ** 2, "C": lambda s: 1.0}
    calls = []
    subjects = stand_ins(monkeypatch, error_at, p, calls)
    with pytest.warns(UserWarning, match="integration error at the optimum stays above"):
        out = fit_module._fit(chain, subjects, cfg, (10, 10))
    # RODAS4 from one step per sample
    assert calls == [(("A", "B", "C"), 1), (("B", "C"), 2), (("B", "C"), 4), (("B", "C"), 8), (("C",), 16),
                     (("C",), 32)]
    assert out["steps"] == fit_module.MAX_STEPS_PER_SAMPLE
    assert np.allclose(out["integration_error_deg"], [0.001, 0.005, 1.0])
    # each refit starts from the subject's last optimum; its LM steps add up
    assert np.allclose(out["x"][:, 0], [1.0, 4.0, 6.0]) and out["lm2"].tolist() == [5, 20, 30]
    fit = fit_module._assemble(chain, {s.subject: s for s in subjects}, {s.subject: s for s in subjects}, out, cfg,
                               ("q1", "q2", "q3"))
    assert fit.converged.tolist() == [True, True, False]
    assert fit.status[2] == int(pj.Status.INACCURATE)


def test_a_non_finite_error_at_the_first_step_count_is_refitted_once_then_reported(monkeypatch):
    # D's simulations fail at one step per sample and pass at two; E's fail at every count: it is
    # refitted once (not doubled to the limit) and reported INACCURATE, never converged
    chain = pj.PlanarArm([0.3, 0.25, 0.15])
    cfg = mdl.Config(3, "lambda0", "tau0_KJ", "seconds", m=2)
    p = mdl.n_params(cfg)
    error_at = {"D": lambda s: math.nan if s == 1 else 0.001, "E": lambda s: math.nan}
    calls = []
    subjects = stand_ins(monkeypatch, error_at, p, calls)
    out = fit_module._fit(chain, subjects, cfg, (10, 10))
    assert calls == [(("D", "E"), 1), (("D", "E"), 2)]
    assert out["integration_error_deg"][0] == 0.001 and np.isnan(out["integration_error_deg"][1])
    fit = fit_module._assemble(chain, {s.subject: s for s in subjects}, {s.subject: s for s in subjects}, out, cfg,
                               ("q1", "q2", "q3"))
    assert fit.converged.tolist() == [True, False]
    assert fit.status[1] == int(pj.Status.INACCURATE)
