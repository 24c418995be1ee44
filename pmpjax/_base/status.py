"""One status vocabulary for every result type (trajectories, equilibria, fits, primitives).

Results carry an integer array ``status`` with one of the codes below (so it can live inside
``jit``/``vmap``); ``converged`` / ``ok`` are derived from it (``status == SUCCESSFUL``) and
``status_message(code)`` says what a code means. Modelled on optimistix ``RESULTS``.
"""

from __future__ import annotations

import enum

import numpy as np


class Status(enum.IntEnum):
    """Outcome of one item (one trajectory, equilibrium, subject's fit, ...)."""

    SUCCESSFUL = 0
    NONFINITE = 1
    MAX_STEPS = 2
    SINGULAR = 3
    STALLED = 4
    SCHEDULE_END = 5
    INVALID_INPUT = 6
    TOO_FEW_DATA = 7
    NOT_MINIMUM = 8
    INACCURATE = 9
    NOT_REACHED = 10

    @property
    def message(self) -> str:
        return _MESSAGES[self]


_MESSAGES = {
    Status.SUCCESSFUL: "successful: converged to tolerance (or completed without problems)",
    Status.NONFINITE: "non-finite values (NaN or inf) appeared",
    Status.MAX_STEPS: "reached the maximum number of steps without meeting the tolerance",
    Status.SINGULAR: "came within the tolerance of a singular posture (rank-deficient Jacobian)",
    Status.STALLED: "stalled: the iterates stopped moving (a fixed point) before the tolerance was met",
    Status.SCHEDULE_END: "the schedule ended (e.g. the null-space ratio γ reached 1) before the tolerance was met",
    Status.INVALID_INPUT: "input rejected (NaN/inf samples, rank-deficient Jacobians or out of range)",
    Status.TOO_FEW_DATA: "too few valid samples to fit",
    Status.NOT_MINIMUM: "a stationary point that is not a strict local minimum (a saddle or maximum)",
    Status.INACCURATE: ("the estimated integration error exceeds the tolerance (atol + rtol·max|q|): use a "
                        "smaller `dt`, solver='rodas4' or adaptive steps (dt=None)"),
    Status.NOT_REACHED: ("did not reach the target within the duration: the hand ended farther from it than "
                         "the reach tolerance (a longer duration, or time constants in seconds, not milliseconds?)"),
}


def status_message(code) -> str | list:
    """What a status code means.

    **Arguments:**

    - ``code``: a :class:`Status` code (int), or an array of them.

    **Returns:**

    The message (str) of a scalar code, or a nested list of messages shaped like the array.

    **Raises:**

    - ``ValueError`` for an integer that is not a status code.
    """
    arr = np.asarray(code)
    if arr.ndim == 0:
        return Status(int(arr)).message
    return [status_message(c) for c in arr]
