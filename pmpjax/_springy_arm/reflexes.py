"""The reflex network of Williamson (1996), Figure 7, as a jit-able, batchable controller.

Subsumption layers (higher ones suppress the lower):

- **reach** (bottom): the target generator issues joint-space targets; each new target adds a
  minimum-jerk move from the *previous target* to the new one. Overlapping moves sum (their
  velocities add, Figure 4) whatever their issue times: each move takes a free slot (idle, or
  finished); only when all ``slots`` are busy does the earliest-ending move hand its remainder
  over to the new one (the set-point still ends at the new target).
- **lead**: while the hand is held (input ``lead``), the joint torque is compared with a
  reference torque refreshed every ``lead_refresh`` s; where it deviates by more than
  ``lead_threshold`` the set-point is backed off (each joint independently) so the deviation is
  clipped at the threshold. Targets are suppressed; afterwards reaching resumes from the set-point.
- **grasp**: palm touch → the arm "quickly stops, and holds itself in the stopped position"
  (Figure 8): the ongoing moves are dropped and the set-point jumps to the one that holds the
  *touched* posture ``q_s`` against gravity, ``θ_hold = q_s + K⁻¹ ∇V(q_s)`` (so the arm rests
  where it was touched, not a sag below it), minus a braking term ``grasp_damping ⊙ θ̇ / K``
  while grasping (extra joint damping, so the arm stops without swinging back past the touched
  posture). Targets are suppressed until ``release``; reaching then resumes from ``θ_hold``.
  (Adding a move on top of the running reach instead, as before, swung a one-joint reach 0 → 1
  touched at 0.4 s down to −0.29 rad: the two moves' velocity profiles do not cancel.)
- **withdrawal** (top): back-of-hand touch → winner-take-all: ongoing moves are dropped and a fast
  move returns the set-point to the rest primitive; targets suppressed until ``release``.

Everything is ``jnp.where`` on the state, so a batch of arms in different modes runs in lock-step.
Set-points integrate the summed move velocities exactly over each step (``minimum_jerk`` of ``pmpjax._base.profiles``).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from .._base import (
    as_array,
    check_positive,
    check_positive_int,
    is_concrete,
    minimum_jerk,
    pytree_dataclass,
    static_field,
    to_jax,
)
from .arm import ArmTrajectory, CogArm, check_arm, run_controller

REACH, GRASP, WITHDRAW, LEAD = 0, 1, 2, 3
IDLE_T0 = -2.0  # start of an idle slot's (empty, duration 1 s) move: it ended before t = 0


@pytree_dataclass
class ReflexInputs:
    """Per-step inputs of the reflex network (made by :func:`script_inputs`).

    **Fields:**

    - ``target``: (…, T, n) the target generator's current target [rad].
    - ``new_target``: (…, T) 1 where a new target is issued.
    - ``lead``: (…, T) 1 while the hand is held.
    - ``release``: (…, T) 1 to release grasp or withdrawal.
    - ``touch``: (…, T, 2) scripted palm and back touch [N] (combined with the measured contact
      forces by ``max``).
    """

    target: jax.Array
    new_target: jax.Array
    lead: jax.Array
    release: jax.Array
    touch: jax.Array

    def __post_init__(self):
        target = as_array("target", self.target, tail=(None, None))
        T = target.shape[-2]
        for name in ("new_target", "lead", "release"):
            object.__setattr__(self, name, to_jax(as_array(name, getattr(self, name), tail=(T,)), float))
        object.__setattr__(self, "touch", to_jax(as_array("touch", self.touch, tail=(T, 2)), float))
        object.__setattr__(self, "target", jnp.asarray(target, float))


def script_inputs(arm: CogArm, duration: float, *, targets=(), lead=(), release=(), touch=(), q_start=None):
    """Build the :class:`ReflexInputs` of a scripted run at the arm's timestep.

    **Arguments:**

    - ``arm``: a :class:`CogArm`.
    - ``duration``: length of the run [s] (at least one step).
    - ``targets``: sequence of ``(time [s], q_target (n,) [rad])``.
    - ``lead``: ``(t_on, t_off)`` intervals [s] during which the hand is held.
    - ``release``: times [s] of releases.
    - ``touch``: ``(t_on, t_off, palm_N, back_N)`` scripted touches (times [s], forces [N] ≥ 0).
    - ``q_start``: (n,) the target before the first one [rad] (default the arm's rest posture).

    **Returns:**

    The :class:`ReflexInputs` with leaves (T, ·), ``T = duration / dt`` steps.

    **Raises:**

    - ``TypeError`` for a non-arm; ``ValueError`` naming the argument for a non-positive or too
      short ``duration``, wrong shapes, times outside ``[0, duration)``, intervals with
      ``t_off <= t_on`` or negative forces.
    """
    check_arm(arm)
    check_positive("duration", duration)
    T = int(round(duration / arm.dt))
    if T < 1:
        raise ValueError(f"`duration` must be at least one step ({arm.dt} s), got {duration}")
    n = arm.n
    t = np.arange(T) * arm.dt
    start = np.asarray(as_array("q_start", arm.q_rest if q_start is None else q_start, tail=(n,)), float)
    if start.shape != (n,):
        raise ValueError(f"`q_start` must have shape ({n},), got {start.shape}")
    target = np.broadcast_to(start, (T, n)).copy()
    new = np.zeros(T)

    def entries(name, xs, width):
        for e in xs:
            if len(e) != width:
                raise ValueError(f"`{name}` entries must have {width} items, got {e!r}")
            yield e

    def step_of(name, tk):
        k = int(round(float(as_array(name, tk)) / arm.dt))
        if not 0 <= k < T:
            raise ValueError(f"`{name}` time {tk} s is outside [0, {duration}) s")
        return k

    for tk, q in sorted(entries("targets", targets, 2), key=lambda e: e[0]):
        q = np.asarray(as_array("targets", q, tail=(n,)), float)
        if q.shape != (n,):
            raise ValueError(f"`targets` postures must have shape ({n},), got {q.shape}")
        k = step_of("targets", tk)
        target[k:] = q
        new[k] = 1.0
    lead_a = np.zeros(T)
    for t0, t1 in entries("lead", lead, 2):
        if not t1 > t0:
            raise ValueError(f"`lead` intervals must have t_off > t_on, got ({t0}, {t1})")
        lead_a[(t >= t0) & (t < t1)] = 1.0
    rel = np.zeros(T)
    for tk in release:
        rel[step_of("release", tk)] = 1.0
    touch_a = np.zeros((T, 2))
    for t0, t1, palm, back in entries("touch", touch, 4):
        if not t1 > t0:
            raise ValueError(f"`touch` intervals must have t_off > t_on, got ({t0}, {t1})")
        force = np.asarray(as_array("touch", [palm, back]))
        if np.any(force < 0):
            raise ValueError(f"`touch` forces must be non-negative [N], got {force}")
        sel = (t >= t0) & (t < t1)
        touch_a[sel] = np.maximum(touch_a[sel], force)
    return ReflexInputs(*(to_jax(np.asarray(a)) for a in (target, new, lead_a, rel, touch_a)))


@pytree_dataclass
class ReflexState:
    """Network state: set-point ``q_set`` (n,) without the grasp's braking term, latest target
    ``target_end`` (n,), move slots (``t0`` (S,), ``duration`` (S,), ``delta`` (S, n)), ``mode``
    (int), lead reference torque ``tau_ref`` (n,) and its refresh time ``t_ref``."""

    q_set: jax.Array
    target_end: jax.Array
    t0: jax.Array
    duration: jax.Array
    delta: jax.Array
    mode: jax.Array
    tau_ref: jax.Array
    t_ref: jax.Array


@pytree_dataclass
class ReflexNetwork:
    """Parameters of the reflex network (Williamson 1996, Figures 8–10), all times in seconds.

    Made by :func:`reflex_network`; construction checks every field and raises ``ValueError`` naming
    it for non-positive durations or thresholds, negative ``grasp_damping`` or a bad ``slots``.

    **Fields:**

    - ``rest``: (n,) rest primitive [rad].
    - ``reach_duration``, ``withdraw_duration``: move durations [s].
    - ``touch_threshold``: touch that triggers grasp or withdrawal [N].
    - ``lead_threshold``: (n,) or scalar joint torque that triggers lead [Nm].
    - ``lead_refresh``: period of the lead reflex's new targets [s].
    - ``grasp_damping``: (n,) or scalar extra joint damping while grasping [Nm s/rad] (0 = none;
      :func:`reflex_network` uses the arm's ``B``, doubling it).
    - ``dt``: (static) the control period, the arm's MuJoCo step [s].
    - ``slots``: (static) concurrent moves.
    """

    rest: jax.Array
    reach_duration: float = 1.0
    withdraw_duration: float = 0.4
    touch_threshold: float = 0.5
    lead_threshold: jax.Array = 0.5
    lead_refresh: float = 5.0
    grasp_damping: jax.Array = 0.0
    dt: float = static_field(default=0.002)
    slots: int = static_field(default=4)

    def __post_init__(self):
        for name in (
            "reach_duration",
            "withdraw_duration",
            "touch_threshold",
            "lead_threshold",
            "lead_refresh",
            "dt",
        ):
            as_array(name, getattr(self, name))
            check_positive(name, getattr(self, name))
        gd = as_array("grasp_damping", self.grasp_damping)
        if np.any(np.asarray(gd) < 0):
            raise ValueError(f"`grasp_damping` must be non-negative, got {np.asarray(gd)}")
        check_positive_int("slots", self.slots)
        object.__setattr__(self, "rest", to_jax(as_array("rest", self.rest, tail=(None,)), float))

    def init(self, q_set0):
        """The controller's state at the start of a run (the controller protocol of
        :func:`pmpjax.run_controller`).

        **Arguments:**

        - ``q_set0``: (n,) the first set-point [rad].

        **Returns:**

        The ``ReflexState`` (set-point, target, concurrent moves in ``slots``, mode, lead reference).
        """
        S, n = self.slots, q_set0.shape[-1]
        z = jnp.zeros((), q_set0.dtype)
        return ReflexState(
            q_set=q_set0,
            target_end=q_set0,
            # Idle slots hold empty moves that ended before t = 0, so any new move is "later".
            t0=jnp.full(S, IDLE_T0) + z,
            duration=jnp.ones(S) + z,
            delta=jnp.zeros((S, n)) + z,
            mode=jnp.asarray(REACH),
            tau_ref=jnp.zeros(n) + z,
            t_ref=z,
        )

    def step(self, s: ReflexState, obs, inp, K):
        """One control period: touch, lead and new targets switch the mode (reach, grasp, withdraw,
        lead) and start moves; the summed moves give the set-point (the controller protocol of
        :func:`pmpjax.run_controller`).

        **Arguments:**

        - ``s``: the ``ReflexState``.
        - ``obs``: the arm's ``ArmObs`` (``t``, ``q``, ``qdot``, spring torque ``tau``, ``touch``,
          ``hand``, ``gravity``).
        - ``inp``: this step's :class:`ReflexInputs` entries.
        - ``K``: (n,) joint stiffness [Nm/rad].

        **Returns:**

        ``(state, θ_set (n,) [rad], log)``; the log holds ``mode`` and ``tau_ref``.
        """
        t = obs.t
        touch = jnp.maximum(obs.touch, inp.touch)
        palm, back = touch[0] > self.touch_threshold, touch[1] > self.touch_threshold
        mode = jnp.where((inp.release > 0.5) & ((s.mode == GRASP) | (s.mode == WITHDRAW)), REACH, s.mode)
        lead_on = inp.lead > 0.5
        start_wd = back & (mode != WITHDRAW)
        start_gr = palm & (mode == REACH) & ~start_wd
        start_lead = lead_on & ((mode == REACH) | (mode == GRASP)) & ~start_wd & ~start_gr
        end_lead = ~lead_on & (mode == LEAD)
        new_tg = (inp.new_target > 0.5) & (mode == REACH) & ~start_wd & ~start_gr & ~start_lead

        # Grasp: hold the touched posture q_s against gravity, K (q_s − θ_hold) + ∇V(q_s) = 0.
        q_hold = obs.q_sensed + obs.gravity / K
        q_set = jnp.where(start_gr, q_hold, s.q_set)
        # Winner-take-all layers drop the ongoing moves and restart from the current set-point.
        clear = start_wd | start_lead | start_gr
        delta = jnp.where(clear, 0.0, s.delta)
        target_end = jnp.where(clear, q_set, s.target_end)

        # One new move per step at most (the events are exclusive).
        add = start_wd | new_tg
        goal = jnp.where(start_wd, self.rest, inp.target)
        dur = jnp.where(start_wd, self.withdraw_duration, self.reach_duration)
        end = s.t0 + s.duration
        k = jnp.argmin(end)  # a free (idle or finished) slot if there is one: those end <= t
        # Only when every slot is busy: the earliest-ending move hands its remainder to the new one.
        remainder = delta[k] * (1.0 - minimum_jerk((t - s.t0[k]) / s.duration[k])[0])
        new_delta = goal - target_end + remainder
        delta = jnp.where(add, delta.at[k].set(new_delta), delta)
        t0 = jnp.where(add, s.t0.at[k].set(t), s.t0)
        duration = jnp.where(add, s.duration.at[k].set(dur), s.duration)
        target_end = jnp.where(add, goal, target_end)

        # Lead: refresh the reference torque slowly; clip the deviation by moving the set-point.
        leading = start_lead | ((mode == LEAD) & ~end_lead & ~start_wd)
        refresh = start_lead | (leading & (t - s.t_ref >= self.lead_refresh))
        tau_ref = jnp.where(refresh, obs.tau, s.tau_ref)
        t_ref = jnp.where(refresh, t, s.t_ref)
        dev = obs.tau - tau_ref
        q_lead = obs.q + (tau_ref + jnp.clip(dev, -self.lead_threshold, self.lead_threshold)) / K
        q_set = jnp.where(leading, q_lead, q_set)
        target_end = jnp.where(leading, q_set, target_end)

        mode = jnp.where(
            start_wd,
            WITHDRAW,
            jnp.where(start_gr, GRASP, jnp.where(start_lead, LEAD, jnp.where(end_lead, REACH, mode))),
        )
        # While grasping, extra damping through the set-point brakes the arm and keeps it still.
        command = jnp.where(mode == GRASP, q_set - self.grasp_damping * obs.qdot / K, q_set)
        # Exact integral of the summed minimum-jerk velocities over [t, t + dt].
        inc = (minimum_jerk((t + self.dt - t0) / duration)[0] - minimum_jerk((t - t0) / duration)[0]) @ delta
        state = ReflexState(
            q_set=q_set + inc,
            target_end=target_end,
            t0=t0,
            duration=duration,
            delta=delta,
            mode=mode,
            tau_ref=tau_ref,
            t_ref=t_ref,
        )
        return state, command, {"mode": mode, "tau_ref": tau_ref}


def reflex_network(arm: CogArm, **params) -> ReflexNetwork:
    """The reflex network of an arm, with its defaults.

    **Arguments:**

    - ``arm``: a :class:`CogArm`; the rest primitive, ``grasp_damping`` (= the arm's joint damping
      ``B``, doubling it while grasping) and ``dt`` come from it.
    - ``params``: fields of :class:`ReflexNetwork` to override (not ``dt``).

    **Returns:**

    A :class:`ReflexNetwork`.

    **Raises:**

    - ``TypeError`` for a non-arm; ``ValueError`` for ``dt`` among ``params`` or a bad field value.
    """
    check_arm(arm)
    if "dt" in params:
        raise ValueError("`dt` comes from the arm (its MuJoCo timestep); do not pass it")
    params.setdefault("rest", arm.q_rest)
    params.setdefault("grasp_damping", arm.B)
    return ReflexNetwork(dt=arm.dt, **params)


def run_reflexes(
    arm: CogArm,
    network: ReflexNetwork,
    inputs: ReflexInputs,
    *,
    probe=None,
    force=None,
    K=None,
    B=None,
    q0=None,
    backend: str = "mjx",
) -> ArmTrajectory:
    """Closed-loop rollout of the reflex network on the arm (Williamson 1996, Figures 8–10).

    **Arguments:**

    - ``arm``: a :class:`CogArm`.
    - ``network``: the :class:`ReflexNetwork` (:func:`reflex_network`).
    - ``inputs``: :class:`ReflexInputs` with leaves (…, T, ·): they drive the target generator and
      the scripted sensors.
    - ``probe``: (…, T, 3) positions of the contact probe [m] (touch from MuJoCo contacts).
    - ``force``: (…, T, 3) force pushing the hand [N] (for lead).
    - ``K``, ``B``: (…, n) joint stiffness [Nm/rad] and damping [Nm s/rad] (default the arm's).
    - ``q0``: (…, n) initial posture [rad] (default the arm's rest).
    - ``backend``: ``"mjx"`` or ``"mujoco"`` (C MuJoCo, see :func:`pmpjax.run_controller`).

    **Returns:**

    An :class:`ArmTrajectory` whose ``log`` holds ``mode`` (…, T) and ``tau_ref`` (…, T, n).

    **Raises:**

    - ``TypeError`` for a non-arm, non-network or non-inputs; ``ValueError`` naming the argument for
      a network made for another timestep, wrong shapes, leading axes that do not broadcast, or
      grasp damping too large for the explicit damping step.
    """
    check_arm(arm)
    if not isinstance(network, ReflexNetwork):
        raise TypeError(f"`network` must be a ReflexNetwork, got {type(network).__name__}")
    if not isinstance(inputs, ReflexInputs):
        raise TypeError(f"`inputs` must be ReflexInputs (pmpjax.script_inputs), got {type(inputs).__name__}")
    if not math.isclose(network.dt, arm.dt):
        raise ValueError(f"`network.dt`={network.dt} must equal the arm's timestep {arm.dt}")
    n = arm.n
    if network.rest.shape != (n,):
        raise ValueError(f"`network.rest` must have shape ({n},), got {network.rest.shape}")
    for name in ("lead_threshold", "grasp_damping"):
        if np.ndim(getattr(network, name)) > 0 and np.shape(getattr(network, name)) != (n,):
            raise ValueError(f"`network.{name}` must be a scalar or ({n},), got {np.shape(getattr(network, name))}")
    target = as_array("inputs.target", inputs.target, tail=(None, n))
    T = target.shape[-2]
    batch = tuple(target.shape[:-2])
    for name in ("new_target", "lead", "release"):
        as_array(f"inputs.{name}", getattr(inputs, name), tail=(T,))
    as_array("inputs.touch", inputs.touch, tail=(T, 2))
    try:
        inputs = ReflexInputs(
            target=jnp.asarray(target, float),
            new_target=jnp.broadcast_to(jnp.asarray(inputs.new_target, float), batch + (T,)),
            lead=jnp.broadcast_to(jnp.asarray(inputs.lead, float), batch + (T,)),
            release=jnp.broadcast_to(jnp.asarray(inputs.release, float), batch + (T,)),
            touch=jnp.broadcast_to(jnp.asarray(inputs.touch, float), batch + (T, 2)),
        )
    except ValueError as e:
        raise ValueError(f"`inputs` leading (batch) axes must match `inputs.target`'s {batch}: {e}") from e
    # The grasp's braking adds to the joint damping: keep the explicit step stable.
    B_total = (arm.B if B is None else B) + network.grasp_damping
    if is_concrete(B_total) and np.max(arm.dt * np.asarray(B_total) / arm.inertia_diag) > 1.0:
        raise ValueError("`network.grasp_damping` + `B` is too large for the explicit damping step (dt·B/M > 1)")
    q0 = arm.q_rest if q0 is None else q0
    return run_controller(
        arm,
        network,
        inputs,
        n_steps=T,
        K=K,
        B=B,
        q0=q0,
        q_set0=q0,
        probe=probe,
        force=force,
        batch_shape=batch,
        backend=backend,
    )


def stack_inputs(inputs) -> ReflexInputs:
    """Stack :class:`ReflexInputs` of the same length along a new leading batch axis.

    **Arguments:**

    - ``inputs``: a non-empty sequence of :class:`ReflexInputs` (same T and n).

    **Returns:**

    The :class:`ReflexInputs` with leaves (B, T, ·).

    **Raises:**

    - ``TypeError`` for an empty or non-``ReflexInputs`` sequence; ``ValueError`` for unequal shapes.
    """
    inputs = list(inputs)
    if not inputs or not all(isinstance(i, ReflexInputs) for i in inputs):
        raise TypeError("`inputs` must be a non-empty sequence of ReflexInputs")
    shapes = {tuple(np.shape(i.target)) for i in inputs}
    if len(shapes) != 1:
        raise ValueError(f"`inputs` must all have the same shape (same T and n), got {sorted(shapes)}")
    return jax.tree_util.tree_map(lambda *a: to_jax(np.stack([np.asarray(x) for x in a])) if is_concrete(a)
                                  else jnp.stack(a), *inputs)
