"""The reflex network of Williamson (1996), Figure 7, as a jit-able, batchable controller.

Subsumption layers (higher ones suppress the lower):

- **reach** (bottom): the target generator issues joint-space targets; each new target adds a
  minimum-jerk move from the *previous target* to the new one (moves sum, Figure 4).
- **lead**: while the hand is held (input ``lead``), the joint torque is compared with a
  reference torque refreshed every ``lead_refresh`` s; where it deviates by more than
  ``lead_threshold`` the set-point is backed off (each joint independently) so the deviation is
  clipped at the threshold. Targets are suppressed; afterwards reaching resumes from the set-point.
- **grasp**: palm touch → a move from the current target to the posture where the arm was
  touched (superposition: it cancels the ongoing move smoothly; the arm then rests there up to
  its gravity sag, as in Figure 8), targets suppressed until ``release``.
- **withdrawal** (top): back-of-hand touch → winner-take-all: ongoing moves are dropped and a fast
  move returns the set-point to the rest primitive; targets suppressed until ``release``.

Everything is ``jnp.where`` on the state, so a batch of arms in different modes runs in lock-step.
Set-points integrate the summed move velocities exactly over each step (``_primitives._xi``).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from .._base.pytree import pytree_dataclass, static_field
from .._base.validate import as_array, check_positive
from .arm import ArmTrajectory, CogArm, run_controller
from .primitives import _xi

REACH, GRASP, WITHDRAW, LEAD = 0, 1, 2, 3
MODES = ("reach", "grasp", "withdraw", "lead")


@pytree_dataclass
class ReflexInputs:
    """Per-step inputs (…, T, ·): ``target`` (…, T, n) [rad] the target generator's current
    target, ``new_target`` (…, T) 1 where a new target is issued, ``lead`` (…, T) 1 while the
    hand is held, ``release`` (…, T) 1 to release grasp/withdrawal, ``touch`` (…, T, 2) [N]
    scripted palm/back touch (combined with the measured contact forces by ``max``)."""

    target: jax.Array
    new_target: jax.Array
    lead: jax.Array
    release: jax.Array
    touch: jax.Array


def script_inputs(arm: CogArm, duration: float, *, targets=(), lead=(), release=(), touch=(), q_start=None):
    """Build :class:`ReflexInputs` for ``duration`` [s] at the arm's ``dt``.

    ``targets``: sequence of ``(time, q_target (n,))``; ``lead``: ``(t_on, t_off)`` intervals;
    ``release``: times; ``touch``: ``(t_on, t_off, palm_N, back_N)`` scripted touches.
    """
    check_positive("duration", duration)
    T = int(round(duration / arm.dt))
    n = arm.n
    t = np.arange(T) * arm.dt
    target = np.broadcast_to(np.asarray(arm.q_rest if q_start is None else q_start, float), (T, n)).copy()
    new = np.zeros(T)
    for tk, q in sorted(targets, key=lambda e: e[0]):
        q = np.asarray(as_array("targets", q, tail=(n,)), float)
        k = int(round(tk / arm.dt))
        if not 0 <= k < T:
            raise ValueError(f"`targets` time {tk} s is outside [0, {duration}) s")
        target[k:] = q
        new[k] = 1.0
    lead_a = np.zeros(T)
    for t0, t1 in lead:
        lead_a[(t >= t0) & (t < t1)] = 1.0
    rel = np.zeros(T)
    for tk in release:
        rel[min(T - 1, int(round(tk / arm.dt)))] = 1.0
    touch_a = np.zeros((T, 2))
    for t0, t1, palm, back in touch:
        sel = (t >= t0) & (t < t1)
        touch_a[sel] = np.maximum(touch_a[sel], [palm, back])
    return ReflexInputs(*(jnp.asarray(a) for a in (target, new, lead_a, rel, touch_a)))


@pytree_dataclass
class ReflexState:
    """Network state: commanded set-point ``q_set`` (n,), latest target ``target_end`` (n,),
    move slots (``t0`` (S,), ``duration`` (S,), ``delta`` (S, n)), ``mode`` (int), lead
    reference torque ``tau_ref`` (n,) and its refresh time ``t_ref``."""

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
    """Parameters of the reflex network (all times [s]): ``rest`` (n,) rest primitive [rad];
    ``reach_duration``, ``grasp_duration``, ``withdraw_duration`` move durations;
    ``touch_threshold`` [N]; ``lead_threshold`` (n,) or scalar [Nm]; ``lead_refresh`` [s];
    ``dt`` (static) the control period = the arm's MuJoCo step; ``slots`` (static) concurrent moves.
    """

    rest: jax.Array
    reach_duration: float = 1.0
    grasp_duration: float = 0.25
    withdraw_duration: float = 0.4
    touch_threshold: float = 0.5
    lead_threshold: jax.Array = 0.5
    lead_refresh: float = 5.0
    dt: float = static_field(default=0.002)
    slots: int = static_field(default=4)

    def __post_init__(self):
        for name in (
            "reach_duration",
            "grasp_duration",
            "withdraw_duration",
            "touch_threshold",
            "lead_threshold",
            "lead_refresh",
            "dt",
        ):
            check_positive(name, getattr(self, name))
        object.__setattr__(self, "rest", jnp.asarray(as_array("rest", self.rest, tail=(None,)), float))

    def init(self, q_set0):
        S, n = self.slots, q_set0.shape[-1]
        z = jnp.zeros((), q_set0.dtype)
        return ReflexState(
            q_set=q_set0,
            target_end=q_set0,
            t0=jnp.zeros(S) + z,
            duration=jnp.ones(S) + z,
            delta=jnp.zeros((S, n)) + z,
            mode=jnp.asarray(REACH),
            tau_ref=jnp.zeros(n) + z,
            t_ref=z,
        )

    def step(self, s: ReflexState, obs, inp, K):
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

        q_set = s.q_set
        # Winner-take-all layers drop the ongoing moves and restart from the current set-point.
        clear = start_wd | start_lead
        delta = jnp.where(clear, 0.0, s.delta)
        target_end = jnp.where(clear, q_set, s.target_end)

        # One new move per step at most (the events are exclusive).
        add = start_wd | start_gr | new_tg
        goal = jnp.where(start_wd, self.rest, jnp.where(start_gr, obs.q, inp.target))
        dur = jnp.where(
            start_wd, self.withdraw_duration, jnp.where(start_gr, self.grasp_duration, self.reach_duration)
        )
        end = s.t0 + s.duration
        k = jnp.argmin(end)
        # A still-running move in the reused slot hands its remainder to the new move.
        remainder = delta[k] * (1.0 - _xi((t - s.t0[k]) / s.duration[k]))
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
        # Exact integral of the summed minimum-jerk velocities over [t, t + dt].
        inc = (_xi((t + self.dt - t0) / duration) - _xi((t - t0) / duration)) @ delta
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
        return state, q_set, {"mode": mode, "tau_ref": tau_ref}


def reflex_network(arm: CogArm, **params) -> ReflexNetwork:
    """A :class:`ReflexNetwork` for ``arm`` (rest primitive and ``dt`` from the arm)."""
    params.setdefault("rest", arm.q_rest)
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
) -> ArmTrajectory:
    """Closed-loop rollout of the reflex network on the MJX arm.

    ``inputs`` (:class:`ReflexInputs`, leaves (…, T, ·)) drive the target generator and the
    scripted sensors; ``probe`` (…, T, 3) moves the contact probe (touch from MuJoCo contacts);
    ``force`` (…, T, 3) [N] pushes the hand (for lead). Returns an :class:`ArmTrajectory` whose
    ``log`` holds ``mode`` (…, T) and ``tau_ref`` (…, T, n).
    """
    if not isinstance(network, ReflexNetwork):
        raise TypeError(f"`network` must be a ReflexNetwork, got {type(network).__name__}")
    if not math.isclose(network.dt, arm.dt):
        raise ValueError(f"`network.dt`={network.dt} must equal the arm's timestep {arm.dt}")
    n = arm.n
    if network.rest.shape != (n,):
        raise ValueError(f"`network.rest` must have shape ({n},), got {network.rest.shape}")
    target = as_array("inputs.target", inputs.target, tail=(None, n))
    T = target.shape[-2]
    batch = tuple(target.shape[:-2])
    for name in ("new_target", "lead", "release"):
        as_array(f"inputs.{name}", getattr(inputs, name), tail=(T,))
    as_array("inputs.touch", inputs.touch, tail=(T, 2))
    inputs = ReflexInputs(
        target=jnp.asarray(target, float),
        new_target=jnp.broadcast_to(jnp.asarray(inputs.new_target, float), batch + (T,)),
        lead=jnp.broadcast_to(jnp.asarray(inputs.lead, float), batch + (T,)),
        release=jnp.broadcast_to(jnp.asarray(inputs.release, float), batch + (T,)),
        touch=jnp.broadcast_to(jnp.asarray(inputs.touch, float), batch + (T, 2)),
    )
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
    )


def stack_inputs(inputs) -> ReflexInputs:
    """Stack a list of :class:`ReflexInputs` (same T) along a new leading batch axis."""
    return jax.tree_util.tree_map(lambda *a: jnp.stack(a), *inputs)
