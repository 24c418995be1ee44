"""The springy Cog-like arm (Williamson 1996): loading, and batched rollouts on MJX or C MuJoCo.

Joint torque (design §3.7, restoring form) ``τ = −K (θ − θ_set) − B θ̇`` is computed from the
state at the start of every step and held for the whole (semi-implicit Euler) step, like Cog's
1 kHz joint controllers hold their command between updates; damping is explicit, so
``dt·B/M_ii`` is checked.

Two engines run the same arm and give the same numbers (to rounding without contacts; with
contacts to the constraint solver's tolerance, ~1e-6 rad, because MJX's line search differs):

- ``backend="mjx"`` (default): the torque is computed in JAX and written into ``qfrc_applied``
  before ``mjx.step``, so ``θ_set``, ``K``, ``B``, ``q0`` are ordinary array inputs that can be
  jitted, vmapped and differentiated. One ``lax.scan`` over ``mjx.step`` per arm, vmapped over a
  flat batch, jitted at module level with the MJX model as an argument (arms loaded from the same
  MJCF share compiled code). Reverse-mode gradients need ``contacts=False`` (MJX's constraint
  solver is a ``lax.while_loop``); forward mode works with contacts.
- ``backend="mujoco"``: C MuJoCo, no JAX, no gradients, no compile time, 10–20× faster per step on
  a CPU. Open-loop :func:`rollout` goes through MuJoCo's multi-threaded batch rollout
  (``mujoco.rollout``, all cores by default). That takes open-loop control sequences only, but
  the spring torque feeds back the state at every step, so the C model (``CogArm.c_model``) adds
  one affine ``general`` actuator per joint, ``force = K·ctrl − K·θ − B·θ̇`` with ``ctrl = θ_set``:
  the same torque as ``qfrc_applied`` (Euler integrates actuator forces explicitly; only joint
  ``damping`` would be implicit, and the arm has none), with per-item models when ``K``/``B``
  differ in the batch. Probe positions and hand forces go in as ``mocap_pos`` /
  ``xfrc_applied`` control channels and the hand position comes back from a ``framepos`` sensor.
  Closed-loop :func:`run_controller` steps each arm with ``mj_step`` and the controller (jitted
  JAX, vmapped over the batch) in between.
"""

from __future__ import annotations

import dataclasses
import functools
import os
from importlib import resources
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._base import (
    as_array,
    check_positive_int,
    fast_compile_jit,
    flatten_batch,
    import_mjx,
    import_mujoco,
    is_concrete,
    load_spec,
    on_host,
    pytree_dataclass,
    to_jax,
)
from .._chains import gravity_from_kinematics, kinematics

JOINTS = ("sh_flex", "sh_abd", "sh_rot", "el_flex", "wr_flex", "wr_dev")
DEFAULT_K = (40.0, 40.0, 20.0, 20.0, 5.0, 5.0)  # Nm/rad: human-like, so gravity sags the arm
DEFAULT_B = (4.0, 4.0, 2.0, 2.0, 0.3, 0.3)  # Nm s/rad: damping ratios ≈ 0.6–1
REST = (0.0, 0.15, 0.0, 0.6, 0.0, 0.0)  # rad: arm down at the side, elbow bent
PROBE_PARK = (0.0, -1.0, -1.0)  # m: where the probe waits, out of reach of the hand
BACKENDS = ("mjx", "mujoco")


def arm_xml_path() -> str:
    """Path of the shipped MJCF model of the Cog-like arm.

    **Returns:**

    The path of ``pmpjax/data/cog_arm.xml`` (str).
    """
    return str(resources.files("pmpjax") / "data" / "cog_arm.xml")


class _Layout(NamedTuple):
    """Static indices used inside the compiled step."""

    hand_body: int
    hand_site: int
    touch_adr: tuple[int, ...]  # sensordata addresses of the palm and back touch sensors
    probe_mocap: int
    hand_sensor_adr: int  # sensordata address of the hand framepos sensor in ``c_model``


@dataclasses.dataclass(frozen=True, eq=False)
class CogArm:
    """A loaded springy arm (made by :func:`load_arm`, not by hand).

    **Fields:**

    - ``mj_model``: the C MuJoCo ``MjModel``, as loaded.
    - ``mjx_model``: the MJX model.
    - ``layout``: static indices of joints, sites, sensors and the probe.
    - ``contacts``: whether the probe–hand contacts (and touch forces) are simulated.
    - ``inertia_diag``: (n,) diagonal of the joint-space inertia at ``q_rest`` (for step-size checks).
    - ``c_model``: the C model with the springs as actuators, for ``backend="mujoco"``; ``None`` for
      arms loaded from a compiled ``MjModel``.
    - ``K``, ``B``: (n,) default joint stiffness [Nm/rad] and damping [Nm s/rad].
    - ``q_rest``: (n,) the rest posture [rad].
    - ``n``: number of joints (6).

    ``dt`` [s] is the MuJoCo timestep.
    """

    mj_model: Any
    mjx_model: Any
    layout: _Layout
    contacts: bool
    inertia_diag: np.ndarray  # diag of the joint-space inertia at q_rest, for step-size checks
    c_model: Any = None
    K: np.ndarray = dataclasses.field(default_factory=lambda: np.array(DEFAULT_K))
    B: np.ndarray = dataclasses.field(default_factory=lambda: np.array(DEFAULT_B))
    q_rest: np.ndarray = dataclasses.field(default_factory=lambda: np.array(REST))
    n: int = 6

    @property
    def dt(self) -> float:
        return float(self.mj_model.opt.timestep)


def load_arm(xml_or_model=None, *, contacts: bool = True) -> CogArm:
    """Load the Cog-like arm for MJX and C MuJoCo.

    **Arguments:**

    - ``xml_or_model``: path to an MJCF file, an MJCF string, or a ``mujoco.MjModel`` with the same
      joint/site/sensor names (6 hinges, sites ``hand``/``palm``/``back``, touch sensors ``palm``
      and ``back``, mocap body ``probe``); default the shipped ``cog_arm.xml`` (cached). A compiled
      ``MjModel`` cannot be given actuators, so such an arm runs on MJX only.
    - ``contacts``: ``False`` disables contacts (needed for ``jax.grad`` through rollouts).

    **Returns:**

    A :class:`CogArm`.

    **Raises:**

    - ``TypeError`` for a non-bool ``contacts``; ``ValueError`` naming ``xml_or_model`` for a model
      without the 6 hinge joints, the sites or sensors named above, a mocap ``probe``, or with
      actuators of its own.
    """
    if not isinstance(contacts, bool):
        raise TypeError(f"`contacts` must be a bool, got {type(contacts).__name__}")
    if xml_or_model is None:
        return _load_default(contacts)
    try:
        spec, m = load_spec(xml_or_model)
    except ValueError as e:  # (a file's error starts with its path: name the argument too)
        if str(e).startswith("`xml_or_model`"):
            raise
        raise type(e)(f"`xml_or_model`: {e}") from e
    return _load(spec, m if spec is not None else _copy_model(m), contacts)


@functools.lru_cache(maxsize=4)
def _load_default(contacts: bool) -> CogArm:
    spec, m = load_spec(arm_xml_path())
    return _load(spec, m, contacts)


def _load(spec, m, contacts: bool) -> CogArm:
    mujoco = import_mujoco()
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
    probe_body = ident(mujoco.mjtObj.mjOBJ_BODY, "probe")
    probe = int(m.body_mocapid[probe_body])
    if probe < 0:
        raise ValueError("`xml_or_model`: body 'probe' must be a mocap body")
    if m.nu != 0:
        raise ValueError(f"`xml_or_model` must have no actuators (the springs are added), got {m.nu}")
    c_model, hand_adr = (None, -1) if spec is None else _spring_model(spec)
    for model in (m, c_model):
        if model is None:
            continue
        model.body_pos[probe_body] = PROBE_PARK
        if not contacts:
            model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    d = mujoco.MjData(m)
    d.qpos[:] = REST
    mujoco.mj_forward(m, d)
    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    with jax.numpy_rank_promotion("allow"):
        mx = import_mjx().put_model(m)
    layout = _Layout(hand_body, hand_site, touch, probe, hand_adr)
    return CogArm(m, mx, layout, contacts, np.diag(M).copy(), c_model)


def _spring_model(spec):
    """The C model: the MJCF plus one affine actuator per joint (the spring-damper, gains set per
    rollout) and a ``framepos`` sensor at the hand site. Returns (model, hand sensor address)."""
    mujoco = import_mujoco()
    spec = spec.copy()
    for name in JOINTS:
        a = spec.add_actuator(name=f"_spring_{name}", target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        a.gaintype = mujoco.mjtGain.mjGAIN_FIXED
        a.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        a.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
        a.forcelimited = mujoco.mjtLimited.mjLIMITED_FALSE
    spec.add_sensor(
        name="_hand_pos", type=mujoco.mjtSensor.mjSENS_FRAMEPOS, objtype=mujoco.mjtObj.mjOBJ_SITE, objname="hand"
    )
    c = spec.compile()
    sid = mujoco.mj_name2id(c, mujoco.mjtObj.mjOBJ_SENSOR, "_hand_pos")
    return c, int(c.sensor_adr[sid])


def _copy_model(m):
    import copy

    return copy.deepcopy(m)


# ----------------------------------------------------------------------------------------------
# Observations and trajectories


@pytree_dataclass
class ArmObs:
    """What a controller sees at step time ``t`` [s]: joint angles ``q`` (n,) [rad], velocities
    ``qdot`` (n,) [rad/s], spring torque ``tau`` (n,) [Nm] = −K (q − θ_set) with the set-point
    held so far; sensed one step earlier (a 1-step sensing delay) at the posture ``q_sensed``
    (n,): ``touch`` (2,) [N] palm and back-of-hand normal forces, ``hand`` (3,) [m] hand site
    position and ``gravity`` (n,) [Nm] the gravity torque ``∇V(q_sensed)`` the springs must
    balance to hold that posture (``K (q − θ_set) + ∇V(q) = 0``)."""

    t: jax.Array
    q: jax.Array
    qdot: jax.Array
    tau: jax.Array
    touch: jax.Array
    hand: jax.Array
    gravity: jax.Array
    q_sensed: jax.Array


@pytree_dataclass
class ArmTrajectory:
    """Rollout record of :func:`rollout` and :func:`run_controller`.

    JAX arrays from ``backend="mjx"``, NumPy arrays from ``backend="mujoco"``.

    **Fields:**

    - ``t``: (T,) step start times ``k·dt`` [s].
    - ``q``, ``qdot``: (…, T, n) joint angles [rad] and velocities [rad/s] at the step starts.
    - ``q_set``: (…, T, n) the set-points commanded during each step [rad].
    - ``tau``: (…, T, n) spring torque ``−K (q − θ_set)`` [Nm].
    - ``touch``: (…, T, 2) palm and back touch [N].
    - ``hand``: (…, T, 3) hand site position [m].
    - ``q_final``, ``qdot_final``: (…, n) the state after the last step.
    - ``log``: the controller's per-step log (pytree, leaves (…, T, ·)).
    """

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
# MJX: the compiled core


def _scan_arm(mx, layout: _Layout, controller, K, B, q0, qdot0, q_set0, c0, inputs):
    """One arm: ``inputs`` = (ctrl (T, ...), probe (T, 3), force (T, 3)); returns the record."""
    mjx = import_mjx()
    with jax.numpy_rank_promotion("allow"):
        d0 = mjx.make_data(mx).replace(qpos=q0, qvel=qdot0)
        k0 = kinematics(mx, q0)
        ts = jnp.asarray(layout.touch_adr)

        def step(carry, inp):
            d, c, q_hold, touch, hand, grav, q_sensed = carry
            ctrl, probe, force = inp
            tau = -K * (d.qpos - q_hold)
            obs = ArmObs(
                t=d.time, q=d.qpos, qdot=d.qvel, tau=tau, touch=touch, hand=hand, gravity=grav, q_sensed=q_sensed
            )
            c, q_set, log = controller.step(c, obs, ctrl, K)
            tau_s = -K * (d.qpos - q_set)
            d = d.replace(
                qfrc_applied=tau_s - B * d.qvel,
                mocap_pos=d.mocap_pos.at[layout.probe_mocap].set(probe),
                xfrc_applied=d.xfrc_applied.at[layout.hand_body, :3].set(force),
            )
            d1 = mjx.step(mx, d)
            # d1's kinematics and sensors are those of the step's start posture d.qpos.
            touch1 = d1.sensordata[ts]
            hand1 = d1.site_xpos[layout.hand_site]
            rec = (d.time, d.qpos, d.qvel, q_set, tau_s, touch1, hand1, log)
            return (d1, c, q_set, touch1, hand1, gravity_from_kinematics(mx, d1), d.qpos), rec

        zero_touch = jnp.zeros(2, q0.dtype)
        carry0 = (d0, c0, q_set0, zero_touch, k0.site_xpos[layout.hand_site], gravity_from_kinematics(mx, k0), q0)
        (dT, *_), rec = jax.lax.scan(step, carry0, inputs)
    return rec, dT.qpos, dT.qvel


@functools.partial(fast_compile_jit, static_argnames=("layout",))
def _rollout_batch(mx, layout, controller, K, B, q0, qdot0, q_set0, c0, inputs):
    """Flat batch: every array argument has a leading (Bt,) axis; the controller's leaves too."""
    fn = functools.partial(_scan_arm, mx, layout, controller)
    return jax.vmap(fn)(K, B, q0, qdot0, q_set0, c0, inputs)


# ----------------------------------------------------------------------------------------------
# C MuJoCo


def _c_models(arm: CogArm, K: np.ndarray, B: np.ndarray):
    """The spring model with gains ``K``, ``B`` (Bt, n): one model when all items share them,
    else one per item (``mujoco.rollout`` takes a sequence of same-sized models)."""
    base = arm.c_model

    def with_gains(k, b):
        m = _copy_model(base)
        m.actuator_gainprm[:, 0] = k
        m.actuator_biasprm[:, :3] = np.stack([np.zeros_like(k), -k, -b], axis=-1)
        return m

    if np.all(K == K[:1]) and np.all(B == B[:1]):
        return [with_gains(K[0], B[0])]
    return [with_gains(k, b) for k, b in zip(K, B)]


def _check_c_backend(arm: CogArm, *arrays):
    if arm.c_model is None:
        raise ValueError(
            "`backend='mujoco'` needs an arm loaded from an MJCF path or string (a compiled MjModel "
            "cannot be given the spring actuators); use backend='mjx'"
        )
    if not is_concrete(*arrays):
        raise TypeError("`backend='mujoco'` runs C MuJoCo outside JAX (no jit/vmap/grad); use backend='mjx'")


@functools.cache
def _pool(nthread: int):
    from mujoco import rollout as mj_rollout

    return mj_rollout.Rollout(nthread=nthread)


def _rollout_c(arm: CogArm, q_set, K, B, q0, qdot0, probe, force, nthread):
    """Open-loop C rollouts of a flat batch (arrays (Bt, ...)) through ``mujoco.rollout``."""
    mujoco = import_mujoco()
    q_set, K, B, q0, qdot0, probe, force = (np.asarray(a, float) for a in (q_set, K, B, q0, qdot0, probe, force))
    Bt, T, n = q_set.shape
    models = _c_models(arm, K, B)
    m = models[0]
    full = mujoco.mjtState.mjSTATE_FULLPHYSICS
    d = mujoco.MjData(m)
    x0 = np.zeros(mujoco.mj_stateSize(m, full))
    mujoco.mj_getState(m, d, x0, full)
    i_q = mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_TIME)
    i_v = i_q + m.nq
    x0 = np.tile(x0, (Bt, 1))
    x0[:, i_q:i_v] = q0
    x0[:, i_v : i_v + m.nv] = qdot0
    spec = mujoco.mjtState.mjSTATE_CTRL | mujoco.mjtState.mjSTATE_XFRC_APPLIED | mujoco.mjtState.mjSTATE_MOCAP_POS
    ctrl = np.zeros((Bt, T, m.nu + 6 * m.nbody + 3 * m.nmocap))
    ctrl[..., :n] = q_set
    f0 = m.nu + 6 * arm.layout.hand_body
    ctrl[..., f0 : f0 + 3] = force
    p0 = m.nu + 6 * m.nbody + 3 * arm.layout.probe_mocap
    ctrl[..., p0 : p0 + 3] = probe
    nthread = min(os.cpu_count() or 1, Bt) if nthread is None else min(int(nthread), Bt)
    pool = _pool(nthread if nthread > 1 else 0)
    datas = [mujoco.MjData(m) for _ in range(max(nthread, 1))]
    state, sensordata = pool.rollout(
        models if len(models) > 1 else m,
        datas if nthread > 1 else datas[0],
        x0,
        ctrl,
        control_spec=int(spec),
        initial_warmstart=np.zeros((Bt, m.nv)),
    )
    q_after, qd_after = state[..., i_q:i_v], state[..., i_v : i_v + m.nv]
    q = np.concatenate([q0[:, None], q_after[:, :-1]], axis=1)
    qd = np.concatenate([qdot0[:, None], qd_after[:, :-1]], axis=1)
    touch = sensordata[..., list(arm.layout.touch_adr)]
    a = arm.layout.hand_sensor_adr
    hand = sensordata[..., a : a + 3]
    tau = -K[:, None] * (q - q_set)
    return (q, qd, q_set, tau, touch, hand, ()), q_after[:, -1], qd_after[:, -1]


@fast_compile_jit
def _controller_init(controller, q_set0):
    return jax.vmap(controller.init)(q_set0)


@fast_compile_jit
def _controller_step_c(controller, c, t, q, qdot, q_hold, touch, hand, grav, q_sensed, inp, K):
    """One closed-loop controller step for a flat batch (C backend)."""

    def one(c, q, qd, qh, to, ha, g, qs, inp, K):
        obs = ArmObs(t=t, q=q, qdot=qd, tau=-K * (q - qh), touch=to, hand=ha, gravity=g, q_sensed=qs)
        return controller.step(c, obs, inp, K)

    return jax.vmap(one)(c, q, qdot, q_hold, touch, hand, grav, q_sensed, inp, K)


def _gravity_c(mujoco, m, scratch, q):
    """``∇V(q)`` (nv,) from C MuJoCo: ``qfrc_bias`` at zero velocity."""
    scratch.qpos[:] = q
    scratch.qvel[:] = 0.0
    mujoco.mj_fwdPosition(m, scratch)
    mujoco.mj_fwdVelocity(m, scratch)
    return scratch.qfrc_bias.copy()


def _run_controller_c(arm: CogArm, controller, ctrl, K, B, q0, qdot0, q_set0, probe, force, T):
    """Closed-loop C run of a flat batch (NumPy arrays (Bt, ...)): ``mj_step`` per arm, the jitted
    controller in between; the gravity torque of the sensed posture from C MuJoCo's ``qfrc_bias``."""
    mujoco = import_mujoco()
    Bt, n = q0.shape
    models = _c_models(arm, K, B)
    models = models * Bt if len(models) == 1 else models
    datas = [mujoco.MjData(m) for m in models]
    scratch = mujoco.MjData(models[0])
    lay = arm.layout
    touch_adr, hand_adr = list(lay.touch_adr), lay.hand_sensor_adr
    hand = np.empty((Bt, 3))
    for i, (m, d) in enumerate(zip(models, datas)):
        d.qpos[:], d.qvel[:] = q0[i], qdot0[i]
        mujoco.mj_kinematics(m, d)
        hand[i] = d.site_xpos[lay.hand_site]
    grav = np.stack([_gravity_c(mujoco, models[0], scratch, qq) for qq in q0])
    touch = np.zeros((Bt, 2))
    c = _controller_init(controller, q_set0)
    q_hold, q_sensed = q_set0, q0
    recs = []
    for k in range(T):
        q = np.stack([d.qpos for d in datas])
        qd = np.stack([d.qvel for d in datas])
        inp = jax.tree_util.tree_map(lambda x: x[:, k], ctrl)
        obs = (q, qd, q_hold, touch, hand, grav, q_sensed)
        c, q_set, log = _controller_step_c(controller, c, k * arm.dt, *obs, inp, K)
        q_set = np.asarray(q_set)
        touch1, hand1 = np.empty((Bt, 2)), np.empty((Bt, 3))
        for i, (m, d) in enumerate(zip(models, datas)):
            d.ctrl[:] = q_set[i]
            d.mocap_pos[lay.probe_mocap] = probe[i, k]
            d.xfrc_applied[lay.hand_body, :3] = force[i, k]
            mujoco.mj_step(m, d)
            touch1[i] = d.sensordata[touch_adr]
            hand1[i] = d.sensordata[hand_adr : hand_adr + 3]
        recs.append((q, qd, q_set, -K * (q - q_set), touch1, hand1, log))
        q_hold, q_sensed, touch, hand = q_set, q, touch1, hand1
        grav = np.stack([_gravity_c(mujoco, models[0], scratch, qq) for qq in q])
    stacked = jax.tree_util.tree_map(lambda *a: np.stack([np.asarray(x) for x in a], axis=1), *recs)
    qT = np.stack([d.qpos for d in datas])
    qdT = np.stack([d.qvel for d in datas])
    return stacked, qT, qdT


# ----------------------------------------------------------------------------------------------
# Public entry points


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


def check_arm(arm) -> None:
    if not isinstance(arm, CogArm):
        raise TypeError(f"`arm` must be a CogArm (pmpjax.load_arm()), got {type(arm).__name__}")


def _check_backend(backend, nthread):
    if backend not in BACKENDS:
        raise ValueError(f"`backend` must be one of {BACKENDS}, got {backend!r}")
    if nthread is not None:
        check_positive_int("nthread", nthread)


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
    backend: str = "mjx",
) -> ArmTrajectory:
    """Closed-loop rollout of ``n_steps`` MuJoCo steps with ``controller`` in the loop.

    **Arguments:**

    - ``arm``: a :class:`CogArm`.
    - ``controller``: a pytree with ``init(q_set0)`` -> state and
      ``step(state, obs: ArmObs, inp, K)`` -> (state, θ_set (n,), log pytree), shared by the whole
      batch (its array leaves are parameters, not batched), e.g. :func:`reflex_network`.
    - ``ctrl_inputs``: pytree of per-step inputs with leaves (*batch, n_steps, ...), already
      broadcast to ``batch_shape``.
    - ``n_steps``: MuJoCo steps.
    - ``K``, ``B``: (..., n) joint stiffness [Nm/rad] and damping [Nm s/rad] (default the arm's).
    - ``q0``, ``qdot0``, ``q_set0``: (..., n) initial posture [rad], velocity [rad/s] and set-point
      [rad] (default the arm's rest, at rest).
    - ``probe``: (..., T, 3) mocap positions of the probe [m] (default: parked out of reach).
    - ``force``: (..., T, 3) external force on the hand's centre of mass [N].
    - ``batch_shape``: the leading axes every argument broadcasts to.
    - ``backend``: ``"mjx"`` (jit/vmap/grad) or ``"mujoco"`` (C ``mj_step`` per arm with the jitted
      controller between steps; NumPy results, no gradients).

    **Returns:**

    An :class:`ArmTrajectory` with leaves (*batch_shape, n_steps, ·).

    **Raises:**

    - ``TypeError`` for a non-arm, or traced inputs with ``backend="mujoco"``; ``ValueError`` naming
      the argument for wrong shapes, NaN/inf, gains too stiff for the timestep, negative damping,
      an unknown ``backend`` or leading axes that do not broadcast.
    """
    check_arm(arm)
    _check_backend(backend, None)
    n = arm.n
    T = check_positive_int("n_steps", n_steps)
    K, B = check_gains(arm, arm.K if K is None else K, arm.B if B is None else B)
    q0 = to_jax(as_array("q0", arm.q_rest if q0 is None else q0, tail=(n,)), float)
    qdot0 = to_jax(as_array("qdot0", np.zeros(n) if qdot0 is None else qdot0, tail=(n,)), float)
    q_set0 = q0 if q_set0 is None else to_jax(as_array("q_set0", q_set0, tail=(n,)), float)
    probe = np.broadcast_to(PROBE_PARK, (T, 3)) if probe is None else probe
    force = np.zeros((T, 3)) if force is None else force
    probe = to_jax(as_array("probe", probe, tail=(T, 3)), float)
    force = to_jax(as_array("force", force, tail=(T, 3)), float)
    try:
        batch = tuple(
            np.broadcast_shapes(
                tuple(batch_shape),
                K.shape[:-1],
                B.shape[:-1],
                q0.shape[:-1],
                qdot0.shape[:-1],
                q_set0.shape[:-1],
                probe.shape[:-2],
                force.shape[:-2],
            )
        )
    except ValueError as e:
        raise ValueError(f"leading (batch) axes of K, B, q0, qdot0, q_set0, probe, force do not broadcast: {e}") from e
    if backend == "mujoco":
        _check_c_backend(arm, K, B, q0, qdot0, q_set0, probe, force, ctrl_inputs)
        flat = lambda x, core: flatten_batch(x, batch, core, dtype=float, xp=np)  # noqa: E731
        ctrl = jax.tree_util.tree_map(lambda x: flat(x, np.ndim(x) - len(batch_shape)), ctrl_inputs)
        args = (flat(K, 1), flat(B, 1), flat(q0, 1), flat(qdot0, 1), flat(q_set0, 1))
        (q, qd, qs, tau, touch, hand, log), qT, qdT = _run_controller_c(
            arm, controller, ctrl, *args, flat(probe, 2), flat(force, 2), T
        )
        t = np.arange(T) * arm.dt
    else:
        flat = lambda x, core: flatten_batch(x, batch, core)  # noqa: E731
        ctrl = jax.tree_util.tree_map(lambda x: flat(x, jnp.ndim(x) - len(batch_shape)), ctrl_inputs)
        args = (flat(K, 1), flat(B, 1), flat(q0, 1), flat(qdot0, 1), flat(q_set0, 1))
        c0 = jax.vmap(controller.init)(args[4])
        (t, q, qd, qs, tau, touch, hand, log), qT, qdT = _rollout_batch(
            arm.mjx_model, arm.layout, controller, *args, c0, (ctrl, flat(probe, 2), flat(force, 2))
        )
        t = t[0]
    shape = lambda a: a.reshape(batch + a.shape[1:])  # noqa: E731
    return ArmTrajectory(
        t=t,
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
    arm: CogArm,
    q_set,
    *,
    K=None,
    B=None,
    q0=None,
    qdot0=None,
    probe=None,
    force=None,
    backend: str = "mjx",
    nthread: int | None = None,
) -> ArmTrajectory:
    """Open-loop rollout: one set-point per MuJoCo step.

    ``backend="mjx"`` (default): JAX arrays, differentiable with respect to ``q_set``, ``K``, ``B``,
    ``q0``, ``qdot0`` (reverse mode on arms loaded with ``contacts=False``); compiles once per batch
    size and ``T``. ``backend="mujoco"``: C MuJoCo's batch rollout on ``nthread`` threads, NumPy
    arrays, no gradients, no compile; equal to MJX to rounding (contacts: to the solver tolerance).

    **Arguments:**

    - ``arm``: a :class:`CogArm`.
    - ``q_set``: (..., T, n) set-points [rad], one per step.
    - ``K``, ``B``: (..., n) joint stiffness [Nm/rad] and damping [Nm s/rad] (default the arm's).
    - ``q0``, ``qdot0``: (..., n) initial state (default ``q_set[..., 0, :]``, at rest).
    - ``probe``, ``force``: (..., T, 3) as in :func:`run_controller`.
    - ``backend``: ``"mjx"`` or ``"mujoco"``.
    - ``nthread``: threads of the C backend (default: all cores).

    Leading axes broadcast.

    **Returns:**

    An :class:`ArmTrajectory`.

    **Raises:**

    - ``TypeError`` for a non-arm, or traced inputs with ``backend="mujoco"``; ``ValueError`` naming
      the argument for wrong shapes, no steps, NaN/inf, gains too stiff for the timestep, negative
      damping, an unknown ``backend``, a non-positive ``nthread`` or leading axes that do not
      broadcast.

    **Compile time** (``backend="mjx"``): ≈ 11 s for 4 × 200 steps of the 6-DoF arm on a 2-core CPU
    (``pj.fast_compile_jit``; benchmarks/compile_times.py); ``backend="mujoco"`` compiles nothing.
    """
    check_arm(arm)
    _check_backend(backend, nthread)
    q_set = as_array("q_set", q_set, tail=(None, arm.n))
    if q_set.shape[-2] < 1:
        raise ValueError(f"`q_set` must have at least one step, got shape {q_set.shape}")
    q_set = to_jax(q_set, float)
    if q0 is None:
        q0 = on_host(q_set, lambda a: a[..., 0, :])
    if backend == "mjx":
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
    n, T = arm.n, q_set.shape[-2]
    K, B = check_gains(arm, arm.K if K is None else K, arm.B if B is None else B)
    q0 = as_array("q0", q0, tail=(n,))
    qdot0 = as_array("qdot0", np.zeros(n) if qdot0 is None else qdot0, tail=(n,))
    probe = as_array("probe", np.broadcast_to(PROBE_PARK, (T, 3)) if probe is None else probe, tail=(T, 3))
    force = as_array("force", np.zeros((T, 3)) if force is None else force, tail=(T, 3))
    _check_c_backend(arm, q_set, K, B, q0, qdot0, probe, force)
    try:
        batch = tuple(
            np.broadcast_shapes(
                q_set.shape[:-2], K.shape[:-1], B.shape[:-1], np.shape(q0)[:-1], np.shape(qdot0)[:-1],
                np.shape(probe)[:-2], np.shape(force)[:-2],
            )
        )
    except ValueError as e:
        raise ValueError(f"leading (batch) axes of q_set, K, B, q0, qdot0, probe, force do not broadcast: {e}") from e
    flat = lambda x, core: flatten_batch(x, batch, core, dtype=float, xp=np)  # noqa: E731
    rec, qT, qdT = _rollout_c(
        arm, flat(q_set, 2), flat(K, 1), flat(B, 1), flat(q0, 1), flat(qdot0, 1), flat(probe, 2), flat(force, 2),
        nthread,
    )
    q, qd, qs, tau, touch, hand, log = rec
    shape = lambda a: a.reshape(batch + a.shape[1:])  # noqa: E731
    return ArmTrajectory(
        t=np.arange(T) * arm.dt,
        q=shape(q),
        qdot=shape(qd),
        q_set=shape(qs),
        tau=shape(tau),
        touch=shape(touch),
        hand=shape(hand),
        q_final=shape(qT),
        qdot_final=shape(qdT),
        log=log,
    )
