"""HuG-MP motions as tasks: loading, screening and resampling on normalised time.

**Movements as tasks.** Every recorded HuG-MP motion (``pmpjax.load_hugmp``: one motion from one
posture to the next, idle time already removed, 100 Hz) becomes a task: start posture
``q_obs[0]``, target = the recorded final hand position ``fk(q_obs[-1])`` on the 4-DoF chain
(``pmpjax.ShoulderElbowArm``), and two durations: the recording's ``T_rec`` and the movement
duration ``T`` between onset and offset at 20 % of the peak hand speed (``pmpjax.smooth_path``,
``pmpjax.segment_by_speed``; paper Section 2). The recorded joint angles are resampled at 50
equally spaced samples of normalised time ``s = t / T_rec`` (``q_obs`` is the recording itself;
its last sample is the recorded final posture). Skipped, with the reason: motions whose speed
never falls below 20 % of its peak on one side (cut by the recording), shorter than 0.25 s or a
3 cm hand path, touching a mechanical stop (q3 ≥ 27°, q4 ≥ 124.5°: within 1° of the stops the
data README reports; the stop, not the postural energy, then sets the posture), or ending/starting
at the edge of the workspace (elbow nearly straight: singular Jacobian).
"""

from __future__ import annotations

import dataclasses
import functools

import jax.numpy as jnp
import numpy as np

import pmpjax as pj
from pmpjax.internal import fast_compile_jit, hugmp_directory, row_chunks

SAMPLES = 50
#: smoothing parameter λ of ``pmpjax.smooth_path`` for hand paths [m] against time [s]: the
#: median of the GCV choices over 48 motions of the four subjects (range 3.4e-6 … 6.7e-6); a
#: fixed value because SciPy's GCV search costs ~0.1 s per component, ~6 min for the data set.
SMOOTHING = 5e-6
THRESHOLD = 0.2
FS = 100.0
MIN_DURATION = 0.25  # s, between 20 %-of-peak onset and offset
MIN_PATH = 0.03  # m
STOPS_DEG = {2: 27.0, 3: 124.5}  # q3, q4: 1° inside the mechanical stops of the data README
MIN_MANIPULABILITY = 2e-3  # m³: sqrt det J Jᵀ; ≈ 4° from a straight elbow at nominal lengths
JOINTS = ("q1", "q2", "q3", "q4")
_SAMPLE_TIMES = tuple(float(v) for v in np.linspace(0.0, 1.0, SAMPLES))


def _chain():
    return pj.ShoulderElbowArm()


@dataclasses.dataclass(frozen=True)
class _Motions:
    """One subject's usable motions (N of them) on normalised time (``SAMPLES`` samples)."""

    subject: str
    task: np.ndarray  # (N,) int, 1..6
    rep: np.ndarray  # (N,) int
    index: np.ndarray  # (N,) int, 1-based position inside its cell
    q_obs: np.ndarray  # (N, S, 4) [rad]
    x_obs: np.ndarray  # (N, S, 3) [m]
    duration: np.ndarray  # (N,) T [s], 20 %-of-peak onset to offset
    recording: np.ndarray  # (N,) T_rec [s]
    skipped: tuple = ()  # (task, rep, index or None, reason)

    def __len__(self):
        return int(self.task.shape[0])

    @property
    def target(self):
        return self.x_obs[:, -1]

    @property
    def t_ratio(self):
        """``T / T_rec`` (N,): the movement duration in normalised time."""
        return self.duration / self.recording


@fast_compile_jit
def _fk_jac_rows(chain, q):
    x, J = chain.fk_jac_soa(q.T)
    return x.T, jnp.moveaxis(J, -1, 0)


def _fk_jac(chain, q):
    """Hand positions (K, 3) and Jacobians (K, 3, 4) of postures (K, 4), K >= 1, in chunks of 1024
    of one compiled call (every K shares one compilation)."""
    return row_chunks(lambda r: _fk_jac_rows(chain, r), np.asarray(q, float).reshape(-1, 4), small=1024, chunk=1024)


def _fk(chain, q):
    return _fk_jac(chain, q)[0]


def _subject_name(subject) -> str:
    if isinstance(subject, bool) or not isinstance(subject, int | np.integer | str):
        raise TypeError(f"`subjects` must hold HuG-MP subject numbers (1, 2, ...) or names ('S01'); "
                        f"got {subject!r}")
    name = f"S{int(subject):02d}" if isinstance(subject, int | np.integer) else str(subject)
    if isinstance(subject, int | np.integer) and int(subject) < 1:
        raise ValueError(f"`subjects`: subject numbers start at 1, got {subject}")
    return name


def _file_key(name, directory):
    path = hugmp_directory(directory) / f"{name}_trajs.mat"
    try:
        st = path.stat()
        return str(path.resolve()), st.st_mtime_ns, st.st_size
    except OSError:
        return str(path), None, None


def _motions(subject, directory, reps, tasks, *, smoothing=SMOOTHING) -> _Motions:
    """Load one subject and turn its motions of repetitions ``reps`` and ``tasks`` into tasks
    (cached on the file's path, modification time and size). Raises ``FileNotFoundError`` /
    ``ValueError`` (from ``pmpjax.load_hugmp``) for a missing or malformed file."""
    name = _subject_name(subject)
    return _motions_cached(name, directory, _file_key(name, directory), tuple(reps), tuple(tasks), smoothing)


@functools.lru_cache(maxsize=64)
def _motions_cached(name, directory, _key, reps, tasks, smoothing) -> _Motions:
    sub = pj.load_hugmp(name, directory)
    chain = _chain()
    skipped = [(t, r, None, reason) for r, t, reason in sub.skipped if r in reps and t in tasks]
    items = [(t, r, i, q) for t in tasks for r, i, q in sub.motions.get(t, []) if r in reps]
    keep, durations = [], []
    if items:
        X = np.split(_fk(chain, np.concatenate([q for *_, q in items])), np.cumsum([len(q) for *_, q in items])[:-1])
        for (t, r, i, q), x in zip(items, X):
            reason, T = _analyse(q, x, smoothing)
            if reason is None:
                keep.append((t, r, i, q))
                durations.append(T)
            else:
                skipped.append((t, r, i, reason))
    if keep:
        s = np.linspace(0.0, 1.0, SAMPLES)
        q_obs = np.stack([np.stack([np.interp(s, np.linspace(0.0, 1.0, len(q)), q[:, j]) for j in range(4)], -1)
                          for *_, q in keep])
        x_obs, J = _fk_jac(chain, q_obs)
        x_obs = x_obs.reshape(len(keep), SAMPLES, 3)
        J = J.reshape(len(keep), SAMPLES, 3, 4)[:, [0, -1]]
        w = np.sqrt(np.maximum(np.linalg.det(J @ np.swapaxes(J, -1, -2)), 0.0)).min(-1)
        edge = (w < MIN_MANIPULABILITY) | ~chain.reachable(x_obs[:, -1])
        for k in np.nonzero(edge)[0]:
            t, r, i, _ = keep[k]
            skipped.append((t, r, i, "starts or ends at the edge of the workspace (elbow nearly straight: "
                                      f"sqrt det JJᵀ = {w[k]:.2g} m³ < {MIN_MANIPULABILITY:g})"))
    else:
        q_obs, x_obs, edge = np.zeros((0, SAMPLES, 4)), np.zeros((0, SAMPLES, 3)), np.zeros(0, bool)
    use = ~edge
    col = lambda j: np.array([kk[j] for kk in keep], int).reshape(-1)[use]  # noqa: E731
    return _Motions(
        subject=name, task=col(0), rep=col(1), index=col(2), q_obs=q_obs[use], x_obs=x_obs[use],
        duration=np.array(durations, float).reshape(-1)[use],
        recording=np.array([(len(q) - 1) / FS for *_, q in keep], float).reshape(-1)[use],
        skipped=tuple(sorted(skipped, key=lambda v: (v[1], v[0], v[2] or 0))),
    )


def _analyse(q, x, smoothing):
    """``(reason, T)``: why a motion (raw q (N, 4) [rad], hand path x (N, 3) [m]) is unusable
    (None if usable) and its duration T [s] between the 20 %-of-peak onset and offset."""
    t = np.arange(x.shape[0]) / FS
    path = pj.smooth_path(t, x, lam=smoothing)
    a, b = pj.segment_by_speed(path.speed, threshold=THRESHOLD)
    if a is None or b is None:
        side = "onset" if a is None else "offset"
        why = f"hand speed never falls below {THRESHOLD:.0%} of its peak before the {side} (cut by the recording)"
        return why, None
    T = (b - a) / FS
    length = float(np.linalg.norm(np.diff(path.x, axis=0), axis=-1).sum())
    if T < MIN_DURATION:
        return f"too short: {T:.2f} s between {THRESHOLD:.0%}-of-peak onset and offset (< {MIN_DURATION} s)", T
    if length < MIN_PATH:
        return f"too short: hand path {100 * length:.1f} cm (< {100 * MIN_PATH:.0f} cm)", T
    for j, stop in STOPS_DEG.items():
        top = float(np.rad2deg(np.max(q[:, j])))
        if top >= stop:
            return f"at the mechanical stop of {JOINTS[j]} (reaches {top:.1f}°, threshold {stop:.1f}°)", T
    return None, T


def _check_reps(name, reps):
    if isinstance(reps, int | np.integer):
        reps = (reps,)
    try:
        out = tuple(int(r) for r in reps)
    except (TypeError, ValueError) as e:
        raise TypeError(f"`{name}` must be an iterable of repetition numbers (1-based), got {reps!r}") from e
    if not out:
        raise ValueError(f"`{name}` must name at least one repetition")
    if any(r < 1 for r in out) or any(int(r) != r for r in reps):
        raise ValueError(f"`{name}` must hold positive integers (1-based repetitions), got {reps!r}")
    if len(set(out)) != len(out):
        raise ValueError(f"`{name}` has repeated entries: {reps!r}")
    return tuple(sorted(out))


def _reason_counts(skipped) -> str:
    counts = {}
    for *_, reason in skipped:
        key = reason.split(":")[0].split("(")[0].strip()
        counts[key] = counts.get(key, 0) + 1
    return ", ".join(f"{v}× {k}" for k, v in counts.items()) or "no motions recorded"
