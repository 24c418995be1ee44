"""The Donders-fitted wrist-pointing model of Tommasino & Campolo (2017): the NIO fit, the prediction
with the paper's time constants and the time constants fitted through the simulator (the pipeline the
``analyze-pointing`` command and the main job's ``pointing`` part run)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

import pmpjax as pj

from .._donders import fit_donders
from .prediction import predict_pointing
from .time_constants import fit_time_constants


class PointingModels(NamedTuple):
    """The NIO fits (``donders``, in the Donders recording's order; ``order`` maps analysed subjects to them),
    the model's prediction with ``τ = τ0 = T/5`` (``heuristic``), the time constants fitted
    through the simulator (``time_constants``) and the prediction with them (``fitted``)."""

    donders: object
    order: list[int]
    heuristic: object
    time_constants: object
    fitted: object


def fit_pointing_models(analysis, donders: pj.DondersRecording, *, n_starts: int, seed: int = 0) -> PointingModels:
    """NIO ``KJ``, ``q_rest`` per subject of ``analysis`` from its Donders recording (matched by name),
    then the model's predictions with the paper's heuristic time constants and with time constants
    fitted through the simulator."""
    fit = fit_donders(pj.Wrist(d=float(donders.d)), donders.pointing, donders.joint_angles, mask=donders.mask,
                      n_starts=n_starts, seed=seed)
    order = [list(donders.subjects).index(s) for s in analysis.subjects]
    KJ, q_rest = np.asarray(fit.KJ)[order], np.asarray(fit.q_rest)[order]
    heuristic = predict_pointing(analysis, KJ, q_rest)
    tc = fit_time_constants(analysis, KJ, q_rest)
    fitted = predict_pointing(analysis, KJ, q_rest, tau0=tc.tau0, tau=tc.tau)
    return PointingModels(fit, order, heuristic, tc, fitted)
