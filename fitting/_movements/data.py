"""A subject's reaches on normalised time, cut out of continuous joint-angle recordings, or taken
whole from recordings of one motion each.

**Continuous recordings** (:func:`subject_reaches`). Each reach found by
:func:`pmpjax.find_movements` is cut out from ``ONSET_LEAD`` before its onset (the hand at rest;
the model's target-onset ``delay`` absorbs the fixed lead) to the next reach's window start (the
hold on the target), in the recording's own clock, and resampled at ``SAMPLES`` equally spaced
times by linear interpolation of the recorded joint angles. Reaches cut short by the next one (the
hand still moving when the next target appeared) are left out with their reason: their target is
unknown.

**Segmented recordings** (:func:`segmented_reaches`; the HuG-MP protocol, ``fitting.fit_reaching``).
Each recording is one motion, idle time removed: the window is the whole recording, its first
sample the start posture and its last the final posture (the target is the hand there). The
movement duration ``T`` is the time between the onset and the offset at ``onset`` (20 %) of the
peak hand speed of the hand path smoothed by ``pmpjax.smooth_path`` (paper Section 2), with the
fixed smoothing parameter ``SEGMENTED_SMOOTHING`` (the median of the GCV choices over 48 HuG-MP
motions, for hand paths in metres against seconds); time constants given as fractions are
fractions of ``T`` (``t_ratio = T / window``), as in the paper.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

import pmpjax as pj
from pmpjax.internal import fast_compile_jit

#: Samples per reach on normalised time (as the HuG-MP fits).
SAMPLES = 50
SAMPLE_TIMES = tuple(float(v) for v in np.linspace(0.0, 1.0, SAMPLES))
#: The last reach of a recording runs on after its found end by this fraction of its window (the
#: others run on to the next reach's start): the model's reach ends at rest on its target.
HOLD_EXTENSION = 0.5
#: A reach's window starts this long before its onset (20 % of peak speed) [s]: one fixed lead for
#: every reach (anchored at the rest threshold instead, τ came out 7 % further off on noise-free data).
ONSET_LEAD = 0.25
#: The start and end postures are the mean recorded posture over this long before them [s].
REST_AVERAGE = 0.05
#: Segmented recordings: ``pmpjax.smooth_path``'s λ for the hand path [m against s], and the
#: onset/offset level as a fraction of the peak speed (options ``smoothing``, ``onset``).
SEGMENTED_SMOOTHING = 5e-6
SEGMENTED_ONSET = 0.2
#: A segmented recording whose smoothed hand speed never exceeds this [task units/s: m/s on the
#: arms] is skipped (nothing moves; the smoothing spline's rounding, ~1e-13, is no movement).
SEGMENTED_MIN_PEAK_SPEED = 1e-3


@dataclasses.dataclass(frozen=True)
class SubjectReaches:
    """One subject's usable reaches (B of them): ``recording`` (B,) names, ``index`` (B,) the
    reach's row in its recording's :class:`pmpjax.Reaches`, ``t`` (B, S) [s] the sample times in
    the recording's clock, ``q_obs`` (B, S, n) [rad], ``duration`` (B,) [s]; ``q_start``, ``q_end``
    (B, n) [rad] the start and end postures, averaged at rest (the model's initial posture and,
    through the chain, its target);
    ``skipped`` a list of ``(recording, t_from, t_to, reason)``; ``t_ratio`` (B,) the duration
    that time constants given as fractions refer to, as a fraction of the window (ones for
    continuous recordings; ``T / window`` for segmented ones)."""

    subject: str
    recording: tuple[str, ...]
    index: np.ndarray
    t: np.ndarray
    q_obs: np.ndarray
    duration: np.ndarray
    q_start: np.ndarray
    q_end: np.ndarray
    skipped: tuple = ()
    t_ratio: np.ndarray | None = None

    def __post_init__(self):
        if self.t_ratio is None:
            object.__setattr__(self, "t_ratio", np.ones_like(self.duration))

    def __len__(self):
        return int(self.duration.shape[0])


def check_recordings(recordings, chain) -> list:
    """``recordings`` as a list of :class:`pmpjax.JointRecording` with ``chain.n`` joints."""
    if isinstance(recordings, pj.JointRecording):
        recordings = [recordings]
    try:
        recordings = list(recordings)
    except TypeError as e:
        raise TypeError("`recordings` must be a list of pmpjax.JointRecording (pmpjax.read_joint_angles)") from e
    if not recordings:
        raise ValueError("`recordings` is empty")
    for r in recordings:
        if not isinstance(r, pj.JointRecording):
            raise TypeError(f"`recordings` must hold pmpjax.JointRecording objects (pmpjax.read_joint_angles), "
                            f"got {type(r).__name__}")
        if r.q.shape[1] != chain.n:
            raise ValueError(f"recording '{r.name}' has {r.q.shape[1]} joints ({', '.join(r.joint_names)}) but the "
                             f"chain has {chain.n}")
    names = [r.name for r in recordings]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValueError(f"`recordings` holds recordings with the same name twice: {dup}")
    return recordings


def subject_reaches(subject: str, recordings: Sequence, chain, find_options: dict) -> SubjectReaches:
    """The usable reaches of ``recordings`` (all of one subject), resampled on normalised time."""
    rows, skipped = [], []
    for rec in recordings:
        found = pj.find_movements(rec, chain, **find_options)
        skipped += [(rec.name, float(a), float(b), why) for a, b, why in found.skipped]
        K = len(found.start)
        starts = np.maximum(float(rec.t[0]), np.asarray(found.t_onset, float) - ONSET_LEAD)
        for k in range(K):
            t0, t1 = float(starts[k]), float(found.t_end[k])
            # The model's reach ends at rest on its target: the window runs on to the next reach's
            # window start (the hold), or for the last reach as long again as the found window allows.
            if k + 1 < K:
                t1 = max(t1, float(starts[k + 1]))
            else:
                t1 = min(float(rec.t[-1]), t1 + (t1 - t0) * HOLD_EXTENSION)
            if bool(found.cut_short[k]):
                skipped.append((rec.name, t0, t1, "cut short by the next reach (its target is unknown)"))
                continue
            ts = np.linspace(t0, t1, SAMPLES)
            q = np.stack([np.interp(ts, rec.t, rec.q[:, j]) for j in range(chain.n)], -1)
            ends = np.stack([_rest_mean(rec, t0), _rest_mean(rec, t1)])
            rows.append((rec.name, k, ts, q, t1 - t0, ends[0], ends[1]))
    n = chain.n
    if not rows:
        return SubjectReaches(subject, (), np.zeros(0, int), np.zeros((0, SAMPLES)), np.zeros((0, SAMPLES, n)),
                              np.zeros(0), np.zeros((0, n)), np.zeros((0, n)), tuple(skipped))
    return SubjectReaches(subject, tuple(r[0] for r in rows), np.array([r[1] for r in rows]),
                          np.stack([r[2] for r in rows]), np.stack([r[3] for r in rows]),
                          np.array([r[4] for r in rows]), np.stack([r[5] for r in rows]),
                          np.stack([r[6] for r in rows]), tuple(skipped))


def segmented_reaches(subject: str, recordings: Sequence, chain, options: dict) -> SubjectReaches:
    """The reaches of ``recordings`` of one motion each (module docstring), resampled on normalised
    time. ``options``: ``onset`` (fraction of the peak speed, default ``SEGMENTED_ONSET``) and
    ``smoothing`` (``pmpjax.smooth_path``'s λ; None: GCV per motion; default
    ``SEGMENTED_SMOOTHING``). Recordings whose speed never falls below the level on one side
    (cut by the recording) or never exceeds ``SEGMENTED_MIN_PEAK_SPEED``, or with fewer than 5
    samples, are skipped with the reason."""
    options = check_find_options(options, True)
    level = float(options.get("onset", SEGMENTED_ONSET))
    lam = options.get("smoothing", SEGMENTED_SMOOTHING)
    if not 0.0 < level < 1.0:
        raise ValueError(f"`find_options['onset']` must lie in (0, 1), got {level!r}")
    if lam is not None and not (np.isfinite(float(lam)) and float(lam) > 0.0):
        raise ValueError(f"`find_options['smoothing']` must be a positive number or None, got {lam!r}")
    rows, skipped = [], []
    for rec in recordings:
        t, q = np.asarray(rec.t, float), np.asarray(rec.q, float)
        if t.shape[0] < 5:
            skipped.append((rec.name, float(t[0]), float(t[-1]), f"too short: {t.shape[0]} samples (< 5)"))
            continue
        x = np.asarray(hand_positions(chain, q))
        path = pj.smooth_path(t, x, lam=None if lam is None else float(lam))
        if not float(np.max(path.speed)) > SEGMENTED_MIN_PEAK_SPEED:
            skipped.append((rec.name, float(t[0]), float(t[-1]),
                            f"hand speed never exceeds {SEGMENTED_MIN_PEAK_SPEED:g} (nothing moves)"))
            continue
        a, b = pj.segment_by_speed(path.speed, threshold=level)
        if a is None or b is None:
            side = "onset" if a is None else "offset"
            skipped.append((rec.name, float(t[0]), float(t[-1]), f"hand speed never falls below {level:.0%} of "
                                                                 f"its peak before the {side} (cut by the recording)"))
            continue
        ts = np.linspace(t[0], t[-1], SAMPLES)
        q_obs = np.stack([np.interp(ts, t, q[:, j]) for j in range(chain.n)], -1)
        window = float(t[-1] - t[0])
        rows.append((rec.name, ts, q_obs, window, float(t[b] - t[a]) / window))
    n = chain.n
    if not rows:
        return SubjectReaches(subject, (), np.zeros(0, int), np.zeros((0, SAMPLES)), np.zeros((0, SAMPLES, n)),
                              np.zeros(0), np.zeros((0, n)), np.zeros((0, n)), tuple(skipped), np.zeros(0))
    q_obs = np.stack([r[2] for r in rows])
    return SubjectReaches(subject, tuple(r[0] for r in rows), np.zeros(len(rows), int), np.stack([r[1] for r in rows]),
                          q_obs, np.array([r[3] for r in rows]), q_obs[:, 0], q_obs[:, -1], tuple(skipped),
                          np.array([r[4] for r in rows]))


@fast_compile_jit
def hand_positions(chain, q):
    """``chain.fk(q)``, compiled once per chain and shape."""
    return chain.fk(q)


def check_find_options(find_options, segmented: bool) -> dict:
    """``find_options`` as a dict of ``pmpjax.find_movements``' keyword options (segmented
    recordings: ``onset``, ``smoothing``); an unknown key is refused by name with the valid ones."""
    import inspect

    if find_options is None:
        return {}
    if not isinstance(find_options, dict):
        raise TypeError(f"`find_options` must be a dict of options, got {type(find_options).__name__}")
    valid = ("onset", "smoothing") if segmented else tuple(
        k for k, v in inspect.signature(pj.find_movements).parameters.items() if v.kind is v.KEYWORD_ONLY)
    unknown = sorted(set(find_options) - set(valid))
    if unknown:
        what = "segmented recordings" if segmented else "pmpjax.find_movements"
        raise ValueError(f"`find_options` has unknown {'key' if len(unknown) == 1 else 'keys'} "
                         f"{', '.join(map(repr, unknown))}; the options of {what} are {', '.join(valid)}")
    return dict(find_options)


def skipped_summary(skipped) -> str:
    """``(recording, t_from, t_to, reason)`` rows as one line per recording: each stretch's window
    [s] and reason."""
    by: dict = {}
    for rec, a, b, why in skipped:
        by.setdefault(rec, []).append(f"{a:.2f}–{b:.2f} s: {why}")
    return "; ".join(f"{rec}: " + ", ".join(v) for rec, v in by.items()) or "no movement found"


def _rest_mean(rec, t: float):
    """The mean recorded posture (n,) over the ``REST_AVERAGE`` seconds up to ``t`` (the hand at rest
    there): one noisy sample as the model's start or target would bias the fit, and a low-pass
    filter would mix in the movement next to it."""
    sel = (rec.t <= t + 1e-9) & (rec.t >= t - REST_AVERAGE - 1e-9)
    if not sel.any():
        sel = np.argmin(np.abs(rec.t - t)) == np.arange(rec.t.shape[0])
    return np.asarray(rec.q, float)[sel].mean(0)


def group_by_subject(recordings) -> dict:
    """``{subject: [recordings]}`` in order of first appearance."""
    out: dict = {}
    for r in recordings:
        out.setdefault(r.subject, []).append(r)
    return out
