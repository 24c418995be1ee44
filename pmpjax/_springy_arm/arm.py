"""The springy Cog-like arm (Williamson 1996) on MuJoCo MJX: loading and batched rollouts.

Joint torque (design §3.7, restoring form) ``τ = −K (θ − θ_set) − B θ̇`` is computed in JAX from
the state at the start of every step and written into ``qfrc_applied`` before ``mjx.step``.
So the set-points ``θ_set`` and the gains ``K``, ``B`` are ordinary array inputs: they can be
vmapped and differentiated without touching the compiled model, and the same formula drives the
C ``mujoco.mj_step`` loop used as the reference. (MuJoCo's own joint springs would put ``K``,
``θ_set`` into the model, and position actuators would couple ``K``/``B`` to ``actuator_gainprm``.)
The semi-implicit Euler integrator uses this force for the whole step, like Cog's 1 kHz joint
controllers hold their command between updates; damping is explicit, so ``dt·B/M_ii`` is checked.

Rollouts are one ``lax.scan`` over ``mjx.step`` per arm, vmapped over a flat batch and jitted at
module level with the MJX model as an argument (every arm loaded from the same MJCF shares the
compiled code). Reverse-mode gradients need the contact-free model (``contacts=False``): MJX's
constraint solver is a ``lax.while_loop``; forward mode (``jax.jacfwd``) works with contacts.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from importlib import resources
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from .._base.pytree import pytree_dataclass
from .._base.validate import as_array, is_concrete

JOINTS = ("sh_flex", "sh_abd", "sh_rot", "el_flex", "wr_flex", "wr_dev")
DEFAULT_K = (40.0, 40.0, 20.0, 20.0, 5.0, 5.0)  # Nm/rad: human-like, so gravity sags the arm
DEFAULT_B = (4.0, 4.0, 2.0, 2.0, 0.3, 0.3)  # Nm s/rad: damping ratios ≈ 0.6–1
REST = (0.0, 0.15, 0.0, 0.6, 0.0, 0.0)  # rad: arm down at the side, elbow bent
PROBE_PARK = (0.0, -1.0, -1.0)  # m: where the probe waits, out of reach of the hand


def arm_xml_path() -> str:
    """Path of the shipped MJCF ``pmpjax/data/cog_arm.xml``."""
    return str(resources.files("pmpjax") / "data" / "cog_arm.xml")


class _Layout(NamedTuple):
    """Static indices used inside the compiled step."""

    hand_body: int
    hand_site: int
    touch_adr: tuple[int, ...]  # sensordata addresses of the palm and back touch sensors
    probe_mocap: int


@dataclasses.dataclass(frozen=True, eq=False)
class CogArm:
    """A loaded arm: ``mj_model`` (C MuJoCo), ``mjx_model`` (MJX), static indices, defaults.

    ``n`` joints (6); ``dt`` [s] the MuJoCo timestep; ``K``, ``B`` (n,) default joint stiffness
    [Nm/rad] and damping [Nm s/rad]; ``q_rest`` (n,) the rest posture [rad]; ``contacts`` whether
    the probe–hand contacts (and touch forces) are simulated.
    """

    mj_model: mujoco.MjModel
    mjx_model: Any
    layout: _Layout
    contacts: bool
    inertia_diag: np.ndarray  # diag of the joint-space inertia at q_rest, for step-size checks
    K: np.ndarray = dataclasses.field(default_factory=lambda: np.array(DEFAULT_K))
    B: np.ndarray = dataclasses.field(default_factory=lambda: np.array(DEFAULT_B))
    q_rest: np.ndarray = dataclasses.field(default_factory=lambda: np.array(REST))
    n: int = 6

    @property
    def dt(self) -> float:
        return float(self.mj_model.opt.timestep)


def load_arm(xml_or_model=None, *, contacts: bool = True) -> CogArm:
    """Load the Cog-like arm (default: the shipped ``cog_arm.xml``) for MJX.

    ``xml_or_model``: path to an MJCF file, an MJCF string, or a ``mujoco.MjModel`` with the same
    joint/site/sensor names (6 hinges, sites ``hand``/``palm``/``back``, touch sensors ``palm``
    and ``back``, mocap body ``probe``). ``contacts=False`` disables contacts (needed for
    ``jax.grad`` through rollouts). The default model is cached.
    """
    if xml_or_model is None:
        return _load_default(bool(contacts))
    return _load(_as_mj_model(xml_or_model), bool(contacts))


@functools.lru_cache(maxsize=4)
def _load_default(contacts: bool) -> CogArm:
    return _load(mujoco.MjModel.from_xml_path(arm_xml_path()), contacts)


def _as_mj_model(xml_or_model) -> mujoco.MjModel:
    if isinstance(xml_or_model, mujoco.MjModel):
        return xml_or_model
    if not isinstance(xml_or_model, str):
        raise TypeError(
            f"`xml_or_model` must be a path, MJCF string or mujoco.MjModel, got {type(xml_or_model).__name__}"
        )
    try:
        if xml_or_model.lstrip().startswith("<"):
            return mujoco.MjModel.from_xml_string(xml_or_model)
        return mujoco.MjModel.from_xml_path(xml_or_model)
    except ValueError as e:
        raise ValueError(f"`xml_or_model` is not a loadable MJCF model: {e}") from e


def _load(m: mujoco.MjModel, contacts: bool) -> CogArm:
    m = _copy_model(m)
    names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(m.njnt)]
    if tuple(names) != JOINTS or m.nq != 6 or m.nv != 6:
        raise ValueError(f"`xml_or_model` must have the 6 hinge joints {JOINTS}, got {names}")

    def ident(kind, name):
        i = mujoco.mj_name2id(m, kind, name)
        if i < 0:
            raise ValueError(f"`xml_or_model` lacks the {kind.name[6:].lower()} '{name}'")
        return i

    hand_body = ident(mujoco.mjtObj.mjOBJ_BODY, "hand")
    hand_site = ident(mujoco.mjtObj.mjOBJ_SITE, "hand")
    touch = tuple(int(m.sensor_adr[ident(mujoco.mjtObj.mjOBJ_SENSOR, s)]) for s in ("palm", "back"))
    probe = int(m.body_mocapid[ident(mujoco.mjtObj.mjOBJ_BODY, "probe")])
    if probe < 0:
        raise ValueError("`xml_or_model`: body 'probe' must be a mocap body")
    m.body_pos[ident(mujoco.mjtObj.mjOBJ_BODY, "probe")] = PROBE_PARK
    if not contacts:
        m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    d = mujoco.MjData(m)
    d.qpos[:] = REST
    mujoco.mj_forward(m, d)
    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    with jax.numpy_rank_promotion("allow"):
        mx = mjx.put_model(m)
    return CogArm(m, mx, _Layout(hand_body, hand_site, touch, probe), contacts, np.diag(M).copy())


def _copy_model(m):
    import copy

    return copy.deepcopy(m)


# ----------------------------------------------------------------------------------------------
# Observations and trajectories


@pytree_dataclass
class ArmObs:
    """What a controller sees at step time ``t`` [s]: joint angles ``q`` (n,) [rad], velocities
    ``qdot`` (n,) [rad/s], spring torque ``tau`` (n,) [Nm] = −K (q − θ_set) with the set-point
    held so far, ``touch`` (2,) [N] palm and back-of-hand normal forces (measured one step
    earlier: a 1-step sensing delay), ``hand`` (3,) [m] hand site position (one step earlier)."""

    t: jax.Array
    q: jax.Array
    qdot: jax.Array
    tau: jax.Array
    touch: jax.Array
    hand: jax.Array


@pytree_dataclass
class ArmTrajectory:
    """Rollout record at step start times ``t`` (T,) [s] (``t = k·dt``): ``q``, ``qdot``,
    ``q_set`` (…, T, n) joint angles, velocities and the set-points commanded during the step;
    ``tau`` (…, T, n) spring torque −K (q − θ_set) [Nm]; ``touch`` (…, T, 2) palm/back touch
    [N]; ``hand`` (…, T, 3) hand site position [m]; ``q_final``, ``qdot_final`` (…, n) after
    the last step; ``log`` the controller's per-step log (pytree, leaves (…, T, ·))."""

    t: jax.Array
    q: jax.Array
    qdot: jax.Array
    q_set: jax.Array
    tau: jax.Array
    touch: jax.Array
    hand: jax.Array
    q_final: jax.Array
    qdot_final: jax.Array
    log: Any = None


@pytree_dataclass
class Scripted:
    """Open-loop controller: the set-point is the scripted input ``inp`` (n,)."""

    def init(self, q_set0):
        return ()

    def step(self, state, obs, inp, K):
        return state, inp, ()


# ----------------------------------------------------------------------------------------------
# The compiled core


def _scan_arm(mx, layout: _Layout, controller, K, B, q0, qdot0, q_set0, c0, inputs):
    """One arm: ``inputs`` = (ctrl (T, ...), probe (T, 3), force (T, 3)); returns the record."""
    with jax.numpy_rank_promotion("allow"):
        d0 = mjx.make_data(mx)
        d0 = d0.replace(qpos=q0, qvel=qdot0)
        ts = jnp.asarray(layout.touch_adr)

        def step(carry, inp):
            d, c, q_hold, touch, hand = carry
            ctrl, probe, force = inp
            obs = ArmObs(t=d.time, q=d.qpos, qdot=d.qvel, tau=-K * (d.qpos - q_hold), touch=touch, hand=hand)
            c, q_set, log = controller.step(c, obs, ctrl, K)
            tau_s = -K * (d.qpos - q_set)
            d = d.replace(
                qfrc_applied=tau_s - B * d.qvel,
                mocap_pos=d.mocap_pos.at[layout.probe_mocap].set(probe),
                xfrc_applied=d.xfrc_applied.at[layout.hand_body, :3].set(force),
            )
            d1 = mjx.step(mx, d)
            touch1 = d1.sensordata[ts]
            hand1 = d1.site_xpos[layout.hand_site]
            rec = (d.time, d.qpos, d.qvel, q_set, tau_s, touch1, hand1, log)
            return (d1, c, q_set, touch1, hand1), rec

        carry0 = (d0, c0, q_set0, jnp.zeros(2, q0.dtype), jnp.zeros(3, q0.dtype))
        (dT, *_), rec = jax.lax.scan(step, carry0, inputs)
    return rec, dT.qpos, dT.qvel


@functools.partial(jax.jit, static_argnames=("layout",))
def _rollout_batch(mx, layout, controller, K, B, q0, qdot0, q_set0, c0, inputs):
    """Flat batch: every array argument has a leading (Bt,) axis; the controller's leaves too."""
    fn = functools.partial(_scan_arm, mx, layout, controller)
    return jax.vmap(fn)(K, B, q0, qdot0, q_set0, c0, inputs)


def _broadcast_batch(batch, x, core):
    x = jnp.asarray(x)
    B = math.prod(batch)
    return jnp.broadcast_to(x, batch + x.shape[x.ndim - core :]).reshape((B,) + x.shape[x.ndim - core :])


def check_gains(arm: CogArm, K, B):
    """Validate ``K``, ``B`` (..., n): positive (``K``) / non-negative (``B``), and stable for
    the explicit step ``dt`` (``dt·B/M_ii < 1``, ``dt·sqrt(K/M_ii) < 0.5``). Returns arrays."""
    n = arm.n
    K = as_array("K", K, tail=(n,))
    B = as_array("B", B, tail=(n,))
    if is_concrete(K):
        if np.any(np.asarray(K) <= 0):
            raise ValueError(
                f"`K` (joint stiffness) must be positive, got min {np.min(np.asarray(K)):.3g} Nm/rad"
            )
        w = arm.dt * np.sqrt(np.max(np.asarray(K) / arm.inertia_diag))
        if w > 0.5:
            raise ValueError(f"`K` is too stiff for dt={arm.dt} s (dt·sqrt(K/M) = {w:.2f} > 0.5)")
    if is_concrete(B):
        if np.any(np.asarray(B) < 0):
            raise ValueError(f"`B` (joint damping) must be non-negative, got min {np.min(np.asarray(B)):.3g}")
        r = arm.dt * np.max(np.asarray(B) / arm.inertia_diag)
        if r > 1.0:
            raise ValueError(
                f"`B` is too large for the explicit damping step dt={arm.dt} s (dt·B/M = {r:.2f} > 1)"
            )
    return jnp.asarray(K, float), jnp.asarray(B, float)


def run_controller(
    arm: CogArm,
    controller,
    ctrl_inputs,
    *,
    n_steps: int,
    K=None,
    B=None,
    q0=None,
    qdot0=None,
    q_set0=None,
    probe=None,
    force=None,
    batch_shape: tuple[int, ...] = (),
) -> ArmTrajectory:
    """Closed-loop rollout of ``n_steps`` MuJoCo steps with ``controller`` in the loop.

    ``controller`` is a pytree with ``init(q_set0)`` -> state and
    ``step(state, obs: ArmObs, inp, K)`` -> (state, θ_set (n,), log pytree), shared by the whole batch
    (its array leaves are parameters, not batched). ``ctrl_inputs``: pytree of per-step inputs with leaves
    (*batch, n_steps, ...) (already broadcast to ``batch_shape``). ``probe`` (..., T, 3) [m]
    mocap positions of the probe (default: parked out of reach); ``force`` (..., T, 3) [N]
    external force on the hand's centre of mass. ``K``, ``B``, ``q0``, ``qdot0``, ``q_set0``
    (..., n) default to the arm's. Leading axes broadcast to ``batch_shape``.
    """
    n, T = arm.n, int(n_steps)
    if T < 1:
        raise ValueError(f"`n_steps` must be >= 1, got {n_steps}")
    K, B = check_gains(arm, arm.K if K is None else K, arm.B if B is None else B)
    q0 = jnp.asarray(as_array("q0", arm.q_rest if q0 is None else q0, tail=(n,)), float)
    qdot0 = jnp.asarray(as_array("qdot0", np.zeros(n) if qdot0 is None else qdot0, tail=(n,)), float)
    q_set0 = q0 if q_set0 is None else jnp.asarray(as_array("q_set0", q_set0, tail=(n,)), float)
    probe = np.broadcast_to(PROBE_PARK, (T, 3)) if probe is None else probe
    force = np.zeros((T, 3)) if force is None else force
    probe = jnp.asarray(as_array("probe", probe, tail=(T, 3)), float)
    force = jnp.asarray(as_array("force", force, tail=(T, 3)), float)
    batch = tuple(
        np.broadcast_shapes(
            batch_shape,
            K.shape[:-1],
            B.shape[:-1],
            q0.shape[:-1],
            qdot0.shape[:-1],
            q_set0.shape[:-1],
            probe.shape[:-2],
            force.shape[:-2],
        )
    )
    flat = lambda x, core: _broadcast_batch(batch, x, core)  # noqa: E731
    ctrl = jax.tree_util.tree_map(lambda x: flat(x, jnp.ndim(x) - len(batch_shape)), ctrl_inputs)
    qs0 = flat(q_set0, 1)
    c0 = jax.vmap(controller.init)(qs0)
    (t, q, qd, qs, tau, touch, hand, log), qT, qdT = _rollout_batch(
        arm.mjx_model,
        arm.layout,
        controller,
        flat(K, 1),
        flat(B, 1),
        flat(q0, 1),
        flat(qdot0, 1),
        qs0,
        c0,
        (ctrl, flat(probe, 2), flat(force, 2)),
    )
    shape = lambda a: a.reshape(batch + a.shape[1:])  # noqa: E731
    return ArmTrajectory(
        t=t[0],
        q=shape(q),
        qdot=shape(qd),
        q_set=shape(qs),
        tau=shape(tau),
        touch=shape(touch),
        hand=shape(hand),
        q_final=shape(qT),
        qdot_final=shape(qdT),
        log=jax.tree_util.tree_map(shape, log),
    )


def rollout(
    arm: CogArm, q_set, *, K=None, B=None, q0=None, qdot0=None, probe=None, force=None
) -> ArmTrajectory:
    """Open-loop rollout: set-points ``q_set`` (..., T, n) [rad], one per MuJoCo step.

    ``K``, ``B`` (..., n) joint stiffness/damping (default the arm's); ``q0``, ``qdot0`` (..., n)
    initial state (default: rest, at rest); ``probe``/``force`` (..., T, 3) as in
    :func:`run_controller`. Leading axes broadcast. Differentiable w.r.t. ``q_set``, ``K``,
    ``B``, ``q0`` (reverse mode on arms loaded with ``contacts=False``).
    """
    q_set = as_array("q_set", q_set, tail=(None, arm.n))
    q_set = jnp.asarray(q_set, float)
    if q0 is None:
        q0 = q_set[..., 0, :]
    return run_controller(
        arm,
        Scripted(),
        q_set,
        n_steps=q_set.shape[-2],
        K=K,
        B=B,
        q0=q0,
        qdot0=qdot0,
        q_set0=q_set[..., 0, :],
        probe=probe,
        force=force,
        batch_shape=q_set.shape[:-2],
    )
