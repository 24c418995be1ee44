"""Wrist-pointing analysis, statistics and Donders-fitted predictions (Tommasino & Campolo 2017,
Section 2 "Data Analysis", Section 3; design §3.5).

**Analysis** (:func:`analyze_pointing`), per trial of a :class:`pmpjax.PointingRecording`:

1. Screen path from the orientations (Eq 6) and joint angles (inverse of Eq 6).
2. Smoothing splines (``pmpjax.smooth_path``, cubic, penalised curvature) of the screen path and
   joint angles. The smoothing parameter is chosen by generalised cross-validation
   (``pmpjax.gcv_lambda``, the criterion of SciPy's ``make_smoothing_spline``) once per subject,
   jointly for both screen axes (a separate choice per axis over-smooths the axis that barely
   moves, and then biases the speed profile), on the first movement windows of the subject's
   first trial (median over windows), and used for all of that subject's trials: noise and
   sampling are the session's.
3. Movements are the changes of the ``target`` column: centre → X is ``out-X``, X → centre is
   ``in-X``. In the window from the cue to the next cue the tangential speed's peak is found;
   start = first sample before the peak below ``threshold`` × peak, end = first sample after it
   (``pmpjax.segment_by_speed``). Movements that never leave the start target (largest
   displacement < radius/2), are cut by the next cue, or end farther than radius/2 from the
   target are excluded with the reason.
4. Exclusion of movements whose path length or duration lies beyond ``iqr`` inter-quartile
   ranges from the subject's median (over all of the subject's movements).
5. Time normalised from start to end and the spline evaluated at ``n_samples`` equally spaced
   times: mean ± sd paths, joint angles and speeds per subject × movement; ``T`` the mean duration.
6. Curvature (Figure 4): areas between the path (start to end samples) and the line joining the
   movement's own start and end points, directed from the start to the end target, normalised
   by ``radius²`` (the paper: (π/12)²); ``A_sum = A_R + A_L``, ``A_net = A_R − A_L``.
7. The paper's four t-tests (``scipy.stats.ttest_1samp``, two-sided): ``A_sum ≠ 0``,
   ``A_net_out ≠ 0``, ``A_net_in ≠ 0`` per movement, and hysteresis ``A_net_out ≠ −A_net_in``,
   tested paired within trials as ``A_hyst = A_net_out + A_net_in ≠ 0`` (an outbound movement is
   always followed by its inbound one).

Trials with invalid data (NaN, non-monotonic time, non-unit quaternions, unknown targets) are
skipped with a warning naming file, subject and trial; every skipped trial or movement is listed
in ``PointingAnalysis.excluded`` with its reason, and the analysis goes on.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np

from pmpjax import (
    DIRECTIONS,
    MOVEMENT_LABELS,
    PointingRecording,
    center_out_targets,
    curvature_measures,
    gcv_lambda,
    joint_angles_from_quat,
    segment_by_speed,
    smooth_path,
)
from pmpjax.internal import (
    bucket,
    check_positive_int,
    drop_trials,
    fast_compile_jit,
    trial_problems,
)

_ALPHA = 0.05


@dataclasses.dataclass(frozen=True)
class PointingAnalysis:
    """Result of :func:`analyze_pointing` (numpy arrays; S subjects, L = 16 movements, K trials,
    n = ``n_samples``).

    ``subjects`` (S,); ``labels`` (16,) ``out-N, in-N, out-NE, in-NE, …``; ``trials`` (S, K)
    trial numbers (−1: none). Per subject × label × trial, NaN where excluded or absent:
    ``a_sum``, ``a_net`` (normalised areas), ``duration`` [s], ``path_length`` [m],
    ``peak_speed`` [m/s], ``start_q`` (…, 3) joint angles at movement start [rad], ``rest_q``
    (…, 3) the mean posture at rest before the movement [rad], ``start_x``/``end_x`` (…, 2)
    [m]; ``valid`` (S, L, K) bool. ``excluded``: ``(subject, trial, label, reason)`` for every
    skipped trial (label None) or movement, and subject × label cells with too few movements
    (trial None). Means over valid trials: ``mean_path``/``sd_path`` (S, L, n, 2) [m],
    ``mean_q``/``sd_q`` (S, L, n, 3) [rad], ``mean_speed``/``sd_speed`` (S, L, n) [m/s],
    ``T`` (S, L) mean duration [s], ``n_valid`` (S, L). ``targets`` (L, 2, 2) nominal start and
    end target of each movement. Statistics (two-sided one-sample t-tests, NaN with < 2
    movements): ``p_sum`` (S, L) of ``A_sum ≠ 0``, ``p_net`` (S, L) of ``A_net ≠ 0``,
    ``a_hyst`` (S, 8, K) ``A_net_out + A_net_in`` per trial (directions ``pmpjax.DIRECTIONS``)
    and ``p_hyst`` (S, 8). ``lam`` (S,) smoothing parameters; ``radius``, ``d`` [m], ``rate``
    [Hz], ``threshold``, ``source`` (the file).
    """

    subjects: tuple
    labels: tuple
    trials: np.ndarray
    a_sum: np.ndarray
    a_net: np.ndarray
    duration: np.ndarray
    path_length: np.ndarray
    peak_speed: np.ndarray
    start_q: np.ndarray
    rest_q: np.ndarray
    start_x: np.ndarray
    end_x: np.ndarray
    valid: np.ndarray
    excluded: tuple
    mean_path: np.ndarray
    sd_path: np.ndarray
    mean_q: np.ndarray
    sd_q: np.ndarray
    mean_speed: np.ndarray
    sd_speed: np.ndarray
    T: np.ndarray
    n_valid: np.ndarray
    targets: np.ndarray
    a_hyst: np.ndarray
    p_sum: np.ndarray
    p_net: np.ndarray
    p_hyst: np.ndarray
    lam: np.ndarray
    radius: float
    d: float
    rate: float
    threshold: float
    source: str

    def subject_index(self, subject) -> int:
        """The row of a subject.

        **Arguments:**

        - ``subject``: a subject name or an index.

        **Returns:**

        Its index (int).

        **Raises:**

        - ``ValueError`` naming ``subject`` when it is neither.
        """
        if isinstance(subject, int | np.integer) and not isinstance(subject, bool):
            if 0 <= subject < len(self.subjects):
                return int(subject)
        elif str(subject) in self.subjects:
            return self.subjects.index(str(subject))
        raise ValueError(f"`subject` {subject!r} is not one of {list(self.subjects)} (or an index below "
                         f"{len(self.subjects)})")

    def statistics_rows(self, predictions: dict | None = None) -> list[dict]:
        """The statistics as rows (one per subject × movement, floats; NaN where untested):
        ``n``, mean duration ``T_s`` [s], mean ``A_sum``, ``A_net`` (normalised by (π/12)²) with their
        t-test p-values and the SD of ``A_net``; for every prediction the model's
        ``A_net_model_<name>`` and the p-value ``p_model_<name>`` of the measured areas against it. The
        table behind the main job's and ``pmpjax analyze-pointing``'s ``pointing_statistics.csv``.

        **Arguments:**

        - ``predictions``: optional ``{name: PointingPrediction}``.

        **Returns:**

        A list of dicts.
        """
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            mean_net, sd_net = np.nanmean(self.a_net, axis=2), np.nanstd(self.a_net, axis=2, ddof=1)
            mean_sum = np.nanmean(self.a_sum, axis=2)
        rows = []
        for s, name in enumerate(self.subjects):
            for j, lab in enumerate(self.labels):
                row = {"subject": name, "movement": lab, "n": int(self.n_valid[s, j]), "T_s": float(self.T[s, j]),
                       "A_sum": float(mean_sum[s, j]), "p_sum": float(self.p_sum[s, j]),
                       "A_net": float(mean_net[s, j]), "A_net_sd": float(sd_net[s, j]),
                       "p_net": float(self.p_net[s, j])}
                for tag, pred in (predictions or {}).items():
                    row[f"A_net_model_{tag}"] = float(pred.a_net[s, j])
                    row[f"p_model_{tag}"] = float(pred.p_model[s, j])
                rows.append(row)
        return rows

    def table(self, subject=None, *, alpha: float = _ALPHA) -> str:
        """The statistics as text: per movement n, mean A_sum and A_net with their p-values, and
        hysteresis per direction (``*`` marks p < ``alpha``).

        **Arguments:**

        - ``subject``: a subject name or index (default every subject).
        - ``alpha``: the significance level marked.

        **Returns:**

        The table (str).
        """
        rows = []
        for s in [self.subject_index(subject)] if subject is not None else range(len(self.subjects)):
            rows.append(f"{self.subjects[s]}: movement   n   A_sum     p       A_net     p       hyst p")
            for j, lab in enumerate(self.labels):
                star = lambda p: "*" if np.isfinite(p) and p < alpha else " "  # noqa: E731
                h = ""
                if lab.startswith("in-"):
                    p = self.p_hyst[s, DIRECTIONS.index(lab[3:])]
                    h = f"{p:8.3g}{star(p)}"
                n = int(self.n_valid[s, j])
                m_sum = np.nanmean(self.a_sum[s, j]) if n else np.nan
                m_net = np.nanmean(self.a_net[s, j]) if n else np.nan
                rows.append(f"  {lab:>7} {n:3d} {m_sum:7.4f} {self.p_sum[s, j]:8.3g}{star(self.p_sum[s, j])}"
                            f" {m_net:+8.4f} {self.p_net[s, j]:8.3g}{star(self.p_net[s, j])} {h}")
        return "\n".join(rows)


def _ttest(a, popmean=0.0):
    """Two-sided one-sample t-test p-value of the finite values of ``a`` (NaN with < 2 values or
    no spread)."""
    a = np.asarray(a, float)
    a = a[np.isfinite(a)]
    if a.size < 2 or np.ptp(a) == 0:
        return np.nan
    import scipy.stats  # (imported here: 1 s at `import fitting`)

    return float(scipy.stats.ttest_1samp(a, popmean).pvalue)


def _label(prev: str, cur: str):
    if prev == "C" and cur != "C":
        return f"out-{cur}"
    if cur == "C" and prev != "C":
        return f"in-{prev}"
    return None


def _epochs(target):
    starts = np.concatenate([[0], np.flatnonzero(target[1:] != target[:-1]) + 1])
    ends = np.concatenate([starts[1:], [target.shape[0]]])
    return starts, ends


@fast_compile_jit
def _joint_angles_jit(quat):
    return joint_angles_from_quat(quat)


def _joint_angles(quat):
    N = quat.shape[0]
    pad = np.concatenate([quat, np.tile([[1.0, 0.0, 0.0, 0.0]], (bucket(N, minimum=1024) - N, 1))])
    return np.asarray(_joint_angles_jit(pad))[:N]


def _subject_lambda(rec, subject, trials, x_all):
    """GCV smoothing parameter of one subject: joint over both screen axes (one noise level), the
    median over the first four movement windows (cue to next cue, at most 200 samples) of the
    subject's first trial that has any."""
    for trial in trials:
        rows = rec.rows(subject, trial)
        t, x = rec.time[rows], x_all[rows]
        starts, ends = _epochs(rec.target[rows])
        lams = [gcv_lambda(t[a:min(b, a + 200)], x[a:min(b, a + 200)], joint=True)
                for a, b in zip(starts[1:5], ends[1:5]) if b - a >= 12]
        if lams:
            return float(np.median(lams))
    raise ValueError(f"{rec.source}: subject {subject!r} has no trial with a movement window of >= 12 samples")


@dataclasses.dataclass(frozen=True)
class _Movement:
    """One movement found in a trial (step 3): label index ``j``, its measures, its normalised
    samples and its cut screen path ``segment`` (n, 2)."""

    j: int
    duration: float
    path_length: float
    peak_speed: float
    start_q: np.ndarray
    rest_q: np.ndarray
    start_x: np.ndarray
    end_x: np.ndarray
    norm_x: np.ndarray
    norm_q: np.ndarray
    norm_v: np.ndarray
    segment: np.ndarray


def _movement_targets(radius):
    """Nominal start and end target (L, 2, 2) of every movement label, and the targets by name."""
    tg = center_out_targets(radius)
    targets = np.array([[tg["C"], tg[lab[4:]]] if lab.startswith("out") else [tg[lab[3:]], tg["C"]]
                        for lab in MOVEMENT_LABELS])
    return targets, tg


def _trial_movements(rec, rows, lam, x_all, q_all, targets, tg, *, threshold, n_samples):
    """Steps 2–3 for one trial (its ``rows`` of ``rec``): smoothing, then the movements between cues.
    Returns ``(movements, skips)``: the :class:`_Movement` s in the trial's order and
    ``(label or None, reason)`` for everything skipped, in the order met."""
    t = rec.time[rows]
    sm = smooth_path(t, np.concatenate([x_all[rows], q_all[rows]], axis=1), lam=lam)
    xs, qs = sm.x[:, :2], sm.x[:, 2:]
    speed = np.linalg.norm(sm.xdot[:, :2], axis=1)
    names = rec.target[rows]
    starts, ends = _epochs(names)
    movements, skips, seen = [], [], set()
    epochs = [(a, b, str(names[a - 1])) for a, b in zip(starts[1:], ends[1:])]
    first = str(names[starts[0]])
    if first != "C":  # a peripheral target already on screen: the hand starts where it rests
        rest = float(np.linalg.norm(xs[0] - tg["C"]))
        if rest <= 0.5 * rec.radius:
            epochs.insert(0, (starts[0], ends[0], "C"))
        else:
            skips.append((f"out-{first}", f"the trial starts with target {first} on screen and the hand "
                          f"{rest:.3g} m from the centre (> radius/2): no start target"))
            seen.add(f"out-{first}")
    for a, b, prev in epochs:
        cur = str(names[a])
        label = _label(prev, cur)
        if label is None:
            skips.append((None, f"unexpected target change {prev} -> {cur} at t = {t[a]:.3f} s "
                          f"({rec.where(rows[a], 'target')})"))
            continue
        if label in seen:
            skips.append((label, "repeated in the trial; only the first is analysed"))
            continue
        seen.add(label)
        j = MOVEMENT_LABELS.index(label)
        w = slice(a, b)
        disp = np.max(np.linalg.norm(xs[w] - xs[a], axis=1))
        if disp < 0.5 * rec.radius:
            skips.append((label, f"never left the start target {prev} (largest displacement "
                          f"{disp:.3g} m < radius/2 = {0.5 * rec.radius:.3g} m)"))
            continue
        if b - a < 3:
            skips.append((label, f"the target was shown for only {b - a} samples"))
            continue
        on, off = segment_by_speed(speed[w], threshold=threshold)
        if on is None or off is None:
            side = "before" if on is None else "after"
            skips.append((label, f"speed never fell below {threshold:.0%} of its peak {side} the peak "
                          "within the target's window (movement cut by the cue)"))
            continue
        i0, i1 = a + on, a + off
        seg = xs[i0:i1 + 1]
        miss = np.linalg.norm(seg[-1] - targets[j, 1])
        if miss > 0.5 * rec.radius:
            skips.append((label, f"ended {miss:.3g} m from target {cur} (> radius/2)"))
            continue
        if np.dot(seg[-1] - seg[0], targets[j, 1] - targets[j, 0]) <= 0:
            skips.append((label, "moved away from the target"))
            continue
        peak = np.max(speed[i0:i1 + 1])
        still = np.flatnonzero(speed[a:i0 + 1] < 0.05 * peak)
        tn = np.linspace(t[i0], t[i1], n_samples)
        ev, dv = sm(tn), sm(tn, nu=1)
        movements.append(_Movement(
            j=j, duration=t[i1] - t[i0], path_length=np.sum(np.linalg.norm(np.diff(seg, axis=0), axis=1)),
            peak_speed=peak, start_q=qs[i0], rest_q=qs[a + still].mean(0) if still.size else qs[a], start_x=seg[0],
            end_x=seg[-1], norm_x=ev[:, :2], norm_q=ev[:, 2:], norm_v=np.linalg.norm(dv[:, :2], axis=1), segment=seg,
        ))
    for label in MOVEMENT_LABELS:
        if label not in seen:
            skips.append((label, f"no such movement in the trial (target {label.split('-')[1]} never shown)"))
    return movements, skips


def _outliers(valid, path_length, duration, iqr):
    """Step 4: movements (s, j, k) whose path length or duration lies beyond ``iqr`` inter-quartile
    ranges from the subject's median. Returns the valid mask without them and ``(s, j, k, reason)``."""
    valid = valid.copy()
    dropped = []
    for s in range(valid.shape[0]):
        for name, v in (("path length", path_length[s]), ("duration", duration[s])):
            vals = v[valid[s]]
            if vals.size < 4:
                continue
            med = np.median(vals)
            spread = np.subtract(*np.percentile(vals, [75, 25]))
            out = valid[s] & (np.abs(v - med) > iqr * spread)
            unit = "m" if name == "path length" else "s"
            dropped += [(s, j, k, f"{name} {v[j, k]:.3g} {unit} beyond {iqr:g} IQR ({spread:.3g} {unit}) of the "
                         f"subject's median {med:.3g} {unit}") for j, k in zip(*np.nonzero(out))]
            valid[s] &= ~out
    return valid, dropped


def _curvatures(segments, valid, targets, radius):
    """Step 6: ``(a_sum, a_net)`` (S, L, K) of the valid movements' cut paths ``segments``
    {(s, j, k): (n, 2)} in one batched call (paths padded by repeating the last point, which adds
    no area); NaN elsewhere. The line joins the movement's own start and end; its direction is
    the targets'."""
    a_sum, a_net = np.full(valid.shape, np.nan), np.full(valid.shape, np.nan)
    keys = [key for key in segments if valid[key]]
    if not keys:
        return a_sum, a_net
    n_pad = bucket(max(segments[key].shape[0] for key in keys), minimum=16)
    P = np.stack([np.concatenate([segments[key], np.repeat(segments[key][-1:], n_pad - segments[key].shape[0], 0)])
                  for key in keys])
    P = np.concatenate([P, np.repeat(P[:1], bucket(len(keys), minimum=16) - len(keys), 0)])
    dirs = np.stack([targets[j, 1] - targets[j, 0] for _, j, _ in keys])
    sgn = np.sign(np.einsum("bi,bi->b", P[:len(keys), -1] - P[:len(keys), 0], dirs))
    s_, n_ = (np.asarray(v) for v in curvature_measures(P, P[:, 0], P[:, -1], scale=radius))
    for i, key in enumerate(keys):
        a_sum[key], a_net[key] = s_[i], sgn[i] * n_[i]
    return a_sum, a_net


def _too_few(subjects, n_valid, src):
    """Exclusion entries of subjects with fewer than 2 valid movements and of subject × label cells
    with fewer than 2 (no statistics)."""
    out = []
    for s, subj in enumerate(subjects):
        if n_valid[s].sum() < 2:
            out.append((subj, None, None, f"{src}: subject {subj!r}: only {int(n_valid[s].sum())} "
                        "valid movement(s); no means or statistics"))
            continue
        out += [(subj, None, MOVEMENT_LABELS[j], f"{src}: subject {subj!r}, {MOVEMENT_LABELS[j]}: "
                 f"{int(n_valid[s, j])} valid movement(s); no statistics") for j in np.flatnonzero(n_valid[s] < 2)]
    return out


def _cell_mean_sd(a, n_valid):
    """Mean (cells with >= 1 valid movement) and SD (>= 2) over the trial axis 2 of ``a`` (S, L, K, ...)."""
    cells = lambda m: (n_valid >= m).reshape(n_valid.shape + (1,) * (a.ndim - 3))  # noqa: E731
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN cells give NaN means
        return (np.where(cells(1), np.nanmean(a, axis=2), np.nan),
                np.where(cells(2), np.nanstd(a, axis=2, ddof=1), np.nan))


def _t_tests(a_sum, a_net):
    """Step 7: ``a_hyst`` (S, 8, K) and the p-values ``p_sum``, ``p_net`` (S, L), ``p_hyst`` (S, 8)."""
    S, L = a_sum.shape[:2]
    a_hyst = np.stack([a_net[:, MOVEMENT_LABELS.index(f"out-{d}")] + a_net[:, MOVEMENT_LABELS.index(f"in-{d}")]
                       for d in DIRECTIONS], axis=1)
    p_sum = np.array([[_ttest(a_sum[s, j]) for j in range(L)] for s in range(S)])
    p_net = np.array([[_ttest(a_net[s, j]) for j in range(L)] for s in range(S)])
    p_hyst = np.array([[_ttest(a_hyst[s, i]) for i in range(len(DIRECTIONS))] for s in range(S)])
    return a_hyst, p_sum, p_net, p_hyst


def analyze_pointing(recording: PointingRecording, *, n_samples: int = 20, threshold: float = 0.2,
                     iqr: float = 2.0) -> PointingAnalysis:
    """The paper's Section 2 "Data Analysis" of a pointing recording (module docstring).

    **Arguments:** ``recording`` (``pmpjax.read_pointing``); ``n_samples`` normalised samples per
    movement (paper: 20); ``threshold`` onset/offset level as a fraction of peak speed (paper:
    0.2); ``iqr`` exclusion distance from the subject's median in inter-quartile ranges (paper: 2;
    ``np.inf`` keeps every movement).

    Invalid trials and movements are skipped (warning) and listed in ``excluded``.

    **Returns:**

    A :class:`PointingAnalysis`.

    **Raises:**

    ``TypeError``/``ValueError`` naming the argument for a non-recording or bad options, and
    ``ValueError`` naming the file when no trial is valid.
    """
    if not isinstance(recording, PointingRecording):
        raise TypeError(f"`recording` must be a pmpjax.PointingRecording (pmpjax.read_pointing), got "
                        f"{type(recording).__name__}")
    n_samples = check_positive_int("n_samples", n_samples, minimum=2)
    if not (np.isfinite(threshold) and 0.0 < threshold < 1.0):
        raise ValueError(f"`threshold` must lie in (0, 1), got {threshold}")
    if not iqr > 0:  # np.inf switches the outlier rule off
        raise ValueError(f"`iqr` must be positive (inf: no outlier exclusion), got {iqr}")
    rec = drop_trials(recording, trial_problems(recording))
    src = rec.source
    excluded = [(s, t, None, reason) for s, t, reason in rec.skipped]
    x_all = rec.pointing
    q_all = _joint_angles(rec.quat)  # step 1
    subjects = rec.subjects
    S, L = len(subjects), len(MOVEMENT_LABELS)
    trials = [rec.trials(s) for s in subjects]
    K = max(len(t) for t in trials)
    targets, tg = _movement_targets(rec.radius)

    def skip(s, trial, label, reason):
        excluded.append((subjects[s], trial, label, f"{src}: subject {subjects[s]!r}, trial {trial}"
                         + (f", {label}" if label else "") + f": {reason}"))

    # steps 2–3: per subject and trial, the movements and their normalised samples
    scalars = ("duration", "path_length", "peak_speed")
    shapes = dict(start_q=(3,), rest_q=(3,), start_x=(2,), end_x=(2,), norm_x=(n_samples, 2), norm_q=(n_samples, 3),
                  norm_v=(n_samples,))
    per = {name: np.full((S, L, K) + shapes.get(name, ()), np.nan) for name in scalars + tuple(shapes)}
    segments = {}
    trial_ids = np.full((S, K), -1)
    lam = np.zeros(S)
    dts = []
    for s, subj in enumerate(subjects):
        lam[s] = _subject_lambda(rec, subj, trials[s], x_all)
        for k, trial in enumerate(trials[s]):
            trial_ids[s, k] = trial
            rows = rec.rows(subj, trial)
            dts.append(np.median(np.diff(rec.time[rows])))
            if rows.size < 8:
                skip(s, trial, None, f"only {rows.size} samples")
                continue
            movements, skips = _trial_movements(rec, rows, lam[s], x_all, q_all, targets, tg, threshold=threshold,
                                                n_samples=n_samples)
            for label, reason in skips:
                skip(s, trial, label, reason)
            for m in movements:
                for name, arr in per.items():
                    arr[s, m.j, k] = getattr(m, name)
                segments[(s, m.j, k)] = m.segment

    valid, dropped = _outliers(np.isfinite(per["duration"]), per["path_length"], per["duration"], iqr)  # step 4
    for s, j, k, reason in dropped:
        skip(s, int(trial_ids[s, k]), MOVEMENT_LABELS[j], reason)
    a_sum, a_net = _curvatures(segments, valid, targets, rec.radius)
    for arr in per.values():
        arr[~valid] = np.nan
    n_valid = valid.sum(-1)
    excluded += _too_few(subjects, n_valid, src)
    # step 5: means and SDs over the valid trials
    mean_path, sd_path = _cell_mean_sd(per["norm_x"], n_valid)
    mean_q, sd_q = _cell_mean_sd(per["norm_q"], n_valid)
    mean_speed, sd_speed = _cell_mean_sd(per["norm_v"], n_valid)
    T = _cell_mean_sd(per["duration"], n_valid)[0]
    a_hyst, p_sum, p_net, p_hyst = _t_tests(a_sum, a_net)
    return PointingAnalysis(
        subjects=subjects, labels=MOVEMENT_LABELS, trials=trial_ids, a_sum=a_sum, a_net=a_net,
        duration=per["duration"], path_length=per["path_length"], peak_speed=per["peak_speed"],
        start_q=per["start_q"], rest_q=per["rest_q"], start_x=per["start_x"], end_x=per["end_x"], valid=valid,
        excluded=tuple(excluded), mean_path=mean_path, sd_path=sd_path, mean_q=mean_q, sd_q=sd_q,
        mean_speed=mean_speed, sd_speed=sd_speed, T=T, n_valid=n_valid, targets=targets, a_hyst=a_hyst,
        p_sum=p_sum, p_net=p_net, p_hyst=p_hyst, lam=lam, radius=rec.radius, d=rec.d,
        rate=float(1.0 / np.median(dts)), threshold=float(threshold), source=src,
    )
