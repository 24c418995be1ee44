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

**Prediction** (:func:`predict_pointing`, Section 3): every movement of every subject simulated
from the subject's mean rest posture before that movement to the target with the λ0-PMP
(``W = τ0 KJ``, Eq 7; Arimoto ``K(t)``, Eq 8, with ``k = b_max/τ0``, Eq 10), by default
``τ = τ0 = T_sj/5``, all in one batched ``pmpjax.simulate`` call; the model paths are observed through the
analysis' smoothing spline (its equivalent kernel), cut at the same speed threshold, and their
``A_net`` is compared with the measured one by a one-sample t-test.
"""

from __future__ import annotations

import dataclasses
import warnings

import jax
import jax.numpy as jnp
import numpy as np

from pmpjax import (
    DIRECTIONS,
    MOVEMENT_LABELS,
    PointingRecording,
    Status,
    Wrist,
    center_out_targets,
    curvature_measures,
    gcv_lambda,
    joint_angles_from_quat,
    segment_by_speed,
    smooth_path,
    task_damping,
)
from pmpjax.internal import (
    as_array,
    bucket,
    check_positive_int,
    check_spd,
    drop_trials,
    fast_compile_jit,
    model_grid,
    normalised_movements,
    trial_problems,
)

_ALPHA = 0.05


# --- analysis ----------------------------------------------------------------------------------


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
        """Index of ``subject`` (a name or an index); ``ValueError`` naming it otherwise."""
        if isinstance(subject, int | np.integer) and not isinstance(subject, bool):
            if 0 <= subject < len(self.subjects):
                return int(subject)
        elif str(subject) in self.subjects:
            return self.subjects.index(str(subject))
        raise ValueError(f"`subject` {subject!r} is not one of {list(self.subjects)} (or an index below "
                         f"{len(self.subjects)})")

    def statistics_rows(self, predictions: dict | None = None) -> list[dict]:
        """The statistics as rows (one per subject × movement, floats; NaN where untested):
        ``n``, mean duration ``T_s`` [s], mean ``A_sum``, ``A_net`` (normalised by (π/12)²) with
        their t-test p-values and the SD of ``A_net``; for every ``name: PointingPrediction`` in
        ``predictions`` the model's ``A_net_model_<name>`` and the p-value ``p_model_<name>`` of the
        measured areas against it. The table behind the main job's and ``pmpjax analyze-pointing``'s
        ``pointing_statistics.csv``."""
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
        hysteresis per direction (``*`` marks p < ``alpha``)."""
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


def analyze_pointing(recording: PointingRecording, *, n_samples: int = 20, threshold: float = 0.2,
                     iqr: float = 2.0) -> PointingAnalysis:
    """The paper's Section 2 "Data Analysis" of a pointing recording (module docstring).

    **Arguments:** ``recording`` (``pmpjax.read_pointing``); ``n_samples`` normalised samples per
    movement (paper: 20); ``threshold`` onset/offset level as a fraction of peak speed (paper:
    0.2); ``iqr`` exclusion distance from the subject's median in inter-quartile ranges (paper: 2;
    ``np.inf`` keeps every movement).

    Returns a :class:`PointingAnalysis`. Raises ``TypeError``/``ValueError`` naming the argument
    for a non-recording or bad options, and ``ValueError`` naming the file when no trial is valid;
    invalid trials and movements are skipped (warning) and listed in ``excluded``.
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
    q_all = _joint_angles(rec.quat)
    subjects = rec.subjects
    S, L = len(subjects), len(MOVEMENT_LABELS)
    trials = [rec.trials(s) for s in subjects]
    K = max(len(t) for t in trials)
    lab_idx = {lab: j for j, lab in enumerate(MOVEMENT_LABELS)}
    tg = center_out_targets(rec.radius)
    targets = np.array([[tg["C"], tg[lab[4:]]] if lab.startswith("out") else [tg[lab[3:]], tg["C"]]
                        for lab in MOVEMENT_LABELS])

    nan = lambda *shape: np.full(shape, np.nan)  # noqa: E731
    duration, path_length, peak = nan(S, L, K), nan(S, L, K), nan(S, L, K)
    start_q, rest_q = nan(S, L, K, 3), nan(S, L, K, 3)
    start_x, end_x = nan(S, L, K, 2), nan(S, L, K, 2)
    norm_x, norm_q, norm_v = nan(S, L, K, n_samples, 2), nan(S, L, K, n_samples, 3), nan(S, L, K, n_samples)
    segments = {}
    trial_ids = np.full((S, K), -1)
    lam = np.zeros(S)
    dts = []

    def skip(s, trial, label, reason):
        excluded.append((subjects[s], trial, label, f"{src}: subject {subjects[s]!r}, trial {trial}"
                         + (f", {label}" if label else "") + f": {reason}"))

    for s, subj in enumerate(subjects):
        lam[s] = _subject_lambda(rec, subj, trials[s], x_all)
        for k, trial in enumerate(trials[s]):
            trial_ids[s, k] = trial
            rows = rec.rows(subj, trial)
            t = rec.time[rows]
            dts.append(np.median(np.diff(t)))
            if t.size < 8:
                skip(s, trial, None, f"only {t.size} samples")
                continue
            sm = smooth_path(t, np.concatenate([x_all[rows], q_all[rows]], axis=1), lam=lam[s])
            xs, qs = sm.x[:, :2], sm.x[:, 2:]
            speed = np.linalg.norm(sm.xdot[:, :2], axis=1)
            names = rec.target[rows]
            starts, ends = _epochs(names)
            seen = set()
            epochs = [(a, b, str(names[a - 1])) for a, b in zip(starts[1:], ends[1:])]
            first = str(names[starts[0]])
            if first != "C":  # a peripheral target already on screen: the hand starts where it rests
                rest = float(np.linalg.norm(xs[0] - tg["C"]))
                if rest <= 0.5 * rec.radius:
                    epochs.insert(0, (starts[0], ends[0], "C"))
                else:
                    skip(s, trial, f"out-{first}", f"the trial starts with target {first} on screen and the hand "
                         f"{rest:.3g} m from the centre (> radius/2): no start target")
                    seen.add(f"out-{first}")
            for a, b, prev in epochs:
                cur = str(names[a])
                label = _label(prev, cur)
                if label is None:
                    skip(s, trial, None, f"unexpected target change {prev} -> {cur} at t = {t[a]:.3f} s "
                         f"({rec.where(rows[a], 'target')})")
                    continue
                if label in seen:
                    skip(s, trial, label, "repeated in the trial; only the first is analysed")
                    continue
                seen.add(label)
                j = lab_idx[label]
                w = slice(a, b)
                disp = np.max(np.linalg.norm(xs[w] - xs[a], axis=1))
                if disp < 0.5 * rec.radius:
                    skip(s, trial, label, f"never left the start target {prev} (largest displacement "
                         f"{disp:.3g} m < radius/2 = {0.5 * rec.radius:.3g} m)")
                    continue
                if b - a < 3:
                    skip(s, trial, label, f"the target was shown for only {b - a} samples")
                    continue
                on, off = segment_by_speed(speed[w], threshold=threshold)
                if on is None or off is None:
                    side = "before" if on is None else "after"
                    skip(s, trial, label, f"speed never fell below {threshold:.0%} of its peak {side} the peak "
                         "within the target's window (movement cut by the cue)")
                    continue
                i0, i1 = a + on, a + off
                seg = xs[i0:i1 + 1]
                miss = np.linalg.norm(seg[-1] - targets[j, 1])
                if miss > 0.5 * rec.radius:
                    skip(s, trial, label, f"ended {miss:.3g} m from target {cur} (> radius/2)")
                    continue
                if np.dot(seg[-1] - seg[0], targets[j, 1] - targets[j, 0]) <= 0:
                    skip(s, trial, label, "moved away from the target")
                    continue
                duration[s, j, k] = t[i1] - t[i0]
                path_length[s, j, k] = np.sum(np.linalg.norm(np.diff(seg, axis=0), axis=1))
                peak[s, j, k] = np.max(speed[i0:i1 + 1])
                start_q[s, j, k], start_x[s, j, k], end_x[s, j, k] = qs[i0], seg[0], seg[-1]
                still = np.flatnonzero(speed[a:i0 + 1] < 0.05 * peak[s, j, k])
                rest_q[s, j, k] = qs[a + still].mean(0) if still.size else qs[a]
                tn = np.linspace(t[i0], t[i1], n_samples)
                ev, dv = sm(tn), sm(tn, nu=1)
                norm_x[s, j, k], norm_q[s, j, k] = ev[:, :2], ev[:, 2:]
                norm_v[s, j, k] = np.linalg.norm(dv[:, :2], axis=1)
                segments[(s, j, k)] = seg
            for label in MOVEMENT_LABELS:
                if label not in seen:
                    skip(s, trial, label, f"no such movement in the trial (target {label.split('-')[1]} never shown)")

    valid = np.isfinite(duration)
    # Subject-specific outliers of path length and duration (paper: beyond 2 IQR from the median).
    for s in range(S):
        for name, v in (("path length", path_length[s]), ("duration", duration[s])):
            vals = v[valid[s]]
            if vals.size < 4:
                continue
            med = np.median(vals)
            spread = np.subtract(*np.percentile(vals, [75, 25]))
            out = valid[s] & (np.abs(v - med) > iqr * spread)
            for j, k in zip(*np.nonzero(out)):
                unit = "m" if name == "path length" else "s"
                skip(s, int(trial_ids[s, k]), MOVEMENT_LABELS[j], f"{name} {v[j, k]:.3g} {unit} beyond {iqr:g} IQR "
                     f"({spread:.3g} {unit}) of the subject's median {med:.3g} {unit}")
            valid[s] &= ~out

    # Curvature of all valid movements in one batched call (segments padded by repeating the last
    # point, which adds no area).
    keys = [key for key in segments if valid[key]]
    a_sum, a_net = nan(S, L, K), nan(S, L, K)
    if keys:
        n_max = max(segments[key].shape[0] for key in keys)
        n_pad = bucket(n_max, minimum=16)
        P = np.stack([np.concatenate([segments[key], np.repeat(segments[key][-1:], n_pad - segments[key].shape[0], 0)])
                      for key in keys])
        P = np.concatenate([P, np.repeat(P[:1], bucket(len(keys), minimum=16) - len(keys), 0)])
        dirs = np.stack([targets[j, 1] - targets[j, 0] for _, j, _ in keys])
        # The line joins the movement's own start and end; its direction is the targets'.
        sgn = np.sign(np.einsum("bi,bi->b", P[:len(keys), -1] - P[:len(keys), 0], dirs))
        s_, n_ = (np.asarray(v) for v in curvature_measures(P, P[:, 0], P[:, -1], scale=rec.radius))
        for i, key in enumerate(keys):
            a_sum[key], a_net[key] = s_[i], sgn[i] * n_[i]

    for arr in (duration, path_length, peak):
        arr[~valid] = np.nan
    for arr in (start_q, rest_q, start_x, end_x, norm_x, norm_q):
        arr[~valid] = np.nan
    norm_v[~valid] = np.nan
    n_valid = valid.sum(-1)
    for s in range(S):
        if n_valid[s].sum() < 2:
            excluded.append((subjects[s], None, None, f"{src}: subject {subjects[s]!r}: only {int(n_valid[s].sum())} "
                             "valid movement(s); no means or statistics"))
            continue
        for j in np.flatnonzero(n_valid[s] < 2):
            excluded.append((subjects[s], None, MOVEMENT_LABELS[j], f"{src}: subject {subjects[s]!r}, "
                             f"{MOVEMENT_LABELS[j]}: {int(n_valid[s, j])} valid movement(s); no statistics"))

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN cells give NaN means
        mean = lambda a: np.where((n_valid >= 1).reshape(n_valid.shape + (1,) * (a.ndim - 3)),  # noqa: E731
                                  np.nanmean(a, axis=2), np.nan)
        sd = lambda a: np.where((n_valid >= 2).reshape(n_valid.shape + (1,) * (a.ndim - 3)),  # noqa: E731
                                np.nanstd(a, axis=2, ddof=1), np.nan)
        mean_path, sd_path, mean_q, sd_q = mean(norm_x), sd(norm_x), mean(norm_q), sd(norm_q)
        mean_speed, sd_speed = mean(norm_v), sd(norm_v)
        T = mean(duration)
    a_hyst = np.stack([a_net[:, lab_idx[f"out-{d}"]] + a_net[:, lab_idx[f"in-{d}"]] for d in DIRECTIONS], axis=1)
    p_sum = np.array([[_ttest(a_sum[s, j]) for j in range(L)] for s in range(S)])
    p_net = np.array([[_ttest(a_net[s, j]) for j in range(L)] for s in range(S)])
    p_hyst = np.array([[_ttest(a_hyst[s, i]) for i in range(len(DIRECTIONS))] for s in range(S)])
    return PointingAnalysis(
        subjects=subjects, labels=MOVEMENT_LABELS, trials=trial_ids, a_sum=a_sum, a_net=a_net, duration=duration,
        path_length=path_length, peak_speed=peak, start_q=start_q, rest_q=rest_q, start_x=start_x, end_x=end_x,
        valid=valid, excluded=tuple(excluded), mean_path=mean_path, sd_path=sd_path, mean_q=mean_q, sd_q=sd_q,
        mean_speed=mean_speed, sd_speed=sd_speed, T=T, n_valid=n_valid, targets=targets, a_hyst=a_hyst,
        p_sum=p_sum, p_net=p_net, p_hyst=p_hyst, lam=lam, radius=rec.radius, d=rec.d,
        rate=float(1.0 / np.median(dts)), threshold=float(threshold), source=src,
    )


# --- model movements analysed like the data (JAX; shared with the time-constant fit) -------------


def _hermite_uniform(h, y, dy, sq):
    """Cubic Hermite interpolation of ``y`` (B, n, k) with derivatives ``dy`` on the grid ``i·h``."""
    n = y.shape[1]
    i = jnp.clip(jnp.floor(sq / h).astype(int), 0, n - 2)
    u = (sq / h - i)[..., None]
    take = lambda a, idx: jnp.take_along_axis(a, idx[..., None], axis=1)  # noqa: E731
    h00, h10, h01, h11 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u, -2 * u**3 + 3 * u**2, u**3 - u**2
    return h00 * take(y, i) + h10 * h * take(dy, i) + h01 * take(y, i + 1) + h11 * h * take(dy, i + 1)


def _slopes(h, y):
    """Derivatives of ``y`` (B, n) on the grid ``i·h`` by central differences (one-sided at the
    ends): the slopes of the Catmull–Rom (C¹ cubic Hermite) interpolant."""
    return jnp.concatenate([y[:, 1:2] - y[:, :1], (y[:, 2:] - y[:, :-2]) / 2, y[:, -1:] - y[:, -2:-1]], 1) / h


def _hermite_pieces(h, y, m, j):
    """Values and slopes (×h) at both ends of interval ``j`` (B,) of the interpolant of ``y``."""
    take = lambda a, k: jnp.take_along_axis(a, k[:, None], axis=1)[:, 0]  # noqa: E731
    return take(y, j), h * take(m, j), take(y, j + 1), h * take(m, j + 1)


def _hermite_at(y0, d0, y1, d1, u):
    """The cubic Hermite piece at ``u`` ∈ [0, 1] and its derivative d/du."""
    p = (2 * u**3 - 3 * u**2 + 1) * y0 + (u**3 - 2 * u**2 + u) * d0 + (-2 * u**3 + 3 * u**2) * y1 + (u**3 - u**2) * d1
    dp = (6 * u**2 - 6 * u) * (y0 - y1) + (3 * u**2 - 4 * u + 1) * d0 + (3 * u**2 - 2 * u) * d1
    return p, dp


def _crossings(h, v, threshold):
    """Onset and offset (B,) [grid units × h] where the speed ``v`` (B, n) crosses ``threshold`` of
    its peak, before and after the peak, on its C¹ (Catmull–Rom) interpolant; the peak is the
    interpolant's maximum next to the largest sample. Both are continuously differentiable in ``v``
    (linear interpolation and a discrete maximum made the fits' residual piecewise smooth, and
    Levenberg–Marquardt crawled along its kinks)."""
    n = v.shape[1]
    idx = jnp.arange(n)
    m = _slopes(h, v)
    i = jnp.clip(jnp.argmax(v, axis=1), 1, n - 2)
    peak = jnp.take_along_axis(v, i[:, None], axis=1)[:, 0]
    for j in (i - 1, i):  # p'(u) = a u² + b u + c on the intervals either side of the largest sample
        y0, d0, y1, d1 = _hermite_pieces(h, v, m, j)
        a, b, c = 6 * y0 + 3 * d0 - 6 * y1 + 3 * d1, -6 * y0 - 4 * d0 + 6 * y1 - 2 * d1, d0
        disc = jnp.maximum(b * b - 4 * a * c, 0.0)
        safe_a = jnp.where(jnp.abs(a) > 1e-300, a, 1.0)
        for sgn in (1.0, -1.0):
            quad = jnp.abs(a) > 1e-12 * (jnp.abs(b) + jnp.abs(c))
            u = jnp.where(quad, (-b + sgn * jnp.sqrt(disc)) / (2 * safe_a), -c / jnp.where(b != 0, b, 1.0))
            val = _hermite_at(y0, d0, y1, d1, jnp.clip(u, 0.0, 1.0))[0]
            peak = jnp.maximum(peak, jnp.where((u >= 0) & (u <= 1), val, peak))
    level = threshold * peak
    below = v < level[:, None]
    i_on = jnp.max(jnp.where(below & (idx[None] < i[:, None]), idx[None], 0), axis=1)
    i_off = jnp.min(jnp.where(below & (idx[None] > i[:, None]), idx[None], n - 1), axis=1) - 1

    def root(j):
        """The crossing of ``level`` inside interval ``j``: Newton from the linear estimate."""
        y0, d0, y1, d1 = _hermite_pieces(h, v, m, j)
        u = jnp.clip((level - y0) / jnp.where(y1 != y0, y1 - y0, 1.0), 0.0, 1.0)
        for _ in range(4):
            f, df = _hermite_at(y0, d0, y1, d1, u)
            u = jnp.clip(u - (f - level) / jnp.where(df != 0, df, 1.0), 0.0, 1.0)
        return h * (j + u)

    return root(i_on), root(i_off), peak


def _silverman_weights(bandwidth, h, J):
    """Discrete equivalent kernel of a cubic smoothing spline (Silverman 1984):
    ``K(u) = ½ e^{−|u|/√2} sin(|u|/√2 + π/4)`` at offsets ``j·h``, ``|j| ≤ J``, for bandwidths
    (B,) in the grid's units; normalised to sum 1. (B, 2J + 1)."""
    u = jnp.abs(jnp.arange(-J, J + 1, dtype=float) * h)[None, :] / bandwidth[:, None]
    w = 0.5 * jnp.exp(-u / np.sqrt(2)) * jnp.sin(u / np.sqrt(2) + np.pi / 4)
    return w / jnp.sum(w, axis=1, keepdims=True)


def _smooth(y, w, *, edge):
    """``y`` (B, n, k) convolved with per-item symmetric weights ``w`` (B, 2J + 1); outside the
    grid ``y`` continues as its end values (``edge``) or as zeros. By FFT: a handful of
    operations in the compiled graph whatever ``J`` (shifted sums would add 2J + 1 per call)."""
    J = (w.shape[1] - 1) // 2
    if J == 0:
        return y
    n = y.shape[1]
    lo = jnp.repeat(y[:, :1], J, axis=1) if edge else jnp.zeros_like(y[:, :J])
    hi = jnp.repeat(y[:, -1:], J, axis=1) if edge else jnp.zeros_like(y[:, :J])
    yp = jnp.concatenate([lo, y, hi], axis=1)
    L = 1 << (n + 4 * J).bit_length()
    conv = jnp.fft.irfft(jnp.fft.rfft(yp, n=L, axis=1) * jnp.fft.rfft(w, n=L, axis=1)[:, :, None], n=L, axis=1)
    return conv[:, 2 * J:2 * J + n]  # symmetric kernel: the convolution is the centred moving sum


def spline_bandwidth(lam, rate):
    """Bandwidth [s] of the equivalent kernel of a cubic smoothing spline with parameter ``lam``
    (SciPy's ``make_smoothing_spline`` scale) on samples at ``rate`` [Hz]: ``(λ / rate)^{1/4}``
    (Silverman 1984)."""
    return (np.asarray(lam) / rate) ** 0.25


def _profiles(tr, T, half, bandwidth, *, h, J, threshold, n_samples, radius, joints=True):
    """A batch of normalised-time model movements (``pmpjax._wrist.pointing.normalised_movements``)
    analysed like the data: observed through the smoothing spline of the analysis (its equivalent
    kernel, ``bandwidth`` (B,) in units of T; ``J`` grid steps each side), cut at ``threshold``
    of its peak speed widened by ``half`` (B,) (half a data sample, in units of T: the data's
    sample-level cut lies on average half a sample outside the crossing), then the path, joint
    angles and speed at ``n_samples`` normalised times, the duration [s] and the curvature of the
    cut path (line through its own ends); ``joints``: also the joint angles (``q_path``).

    ``T`` (B,) [s] the time unit of each movement. Differentiable in every array input.
    """
    w = _silverman_weights(bandwidth, h, J)
    x, xdot = _smooth(tr.x, w, edge=True), _smooth(tr.xdot, w, edge=False)
    v = jnp.linalg.norm(xdot, axis=-1) / T[:, None]  # m/s
    s_on, s_off, peak = _crossings(h, v, threshold)
    span = h * (v.shape[1] - 1)
    s_on = jnp.clip(s_on - half, 0.0, span)
    s_off = jnp.clip(s_off + half, 0.0, span)
    u = jnp.linspace(0.0, 1.0, n_samples)
    sq = s_on[:, None] + u[None] * (s_off - s_on)[:, None]
    dense = s_on[:, None] + jnp.linspace(0.0, 1.0, 96)[None] * (s_off - s_on)[:, None]
    xd = _hermite_uniform(h, x, xdot, dense)
    a_sum, a_net = curvature_measures(xd, xd[:, 0], xd[:, -1], scale=radius)
    speed = _hermite_uniform(h, v[..., None], _slopes(h, v)[..., None], sq)[..., 0]
    out = dict(path=_hermite_uniform(h, x, xdot, sq), speed=speed, onset=s_on * T,
               offset=s_off * T, duration=(s_off - s_on) * T, peak=peak, a_sum=a_sum, a_net=a_net)
    if joints:
        out["q_path"] = _hermite_uniform(h, _smooth(tr.q, w, edge=True), _smooth(tr.qdot, w, edge=False), sq)
    return out


def _kernel_halfwidth(bandwidth, h):
    """Static half-width (grid steps) of the kernel: 6 bandwidths (the kernel is < 1e-3 there)."""
    return int(np.ceil(6.0 * float(np.max(bandwidth)) / h))


_profiles_jit = fast_compile_jit(_profiles, static_argnames=("h", "J", "threshold", "n_samples", "radius"))


def _check_params(analysis, KJ, q_rest):
    """``KJ`` (S, 3, 3) and ``q_rest`` (S, 3) (one (3, 3) / (3,) serves all subjects), validated."""
    if not isinstance(analysis, PointingAnalysis):
        raise TypeError(f"`analysis` must be a PointingAnalysis (fitting.analyze_pointing), got "
                        f"{type(analysis).__name__}")
    S = len(analysis.subjects)
    KJ = np.asarray(as_array("KJ", KJ, tail=(3, 3)), dtype=float)
    q_rest = np.asarray(as_array("q_rest", q_rest, tail=(3,)), dtype=float)
    if KJ.ndim == 2:
        KJ = np.broadcast_to(KJ, (S, 3, 3))
    if q_rest.ndim == 1:
        q_rest = np.broadcast_to(q_rest, (S, 3))
    if KJ.shape != (S, 3, 3):
        raise ValueError(f"`KJ` must be (3, 3) or (S, 3, 3) with S = {S} subjects of the analysis, got {KJ.shape}")
    if q_rest.shape != (S, 3):
        raise ValueError(f"`q_rest` must be (3,) or (S, 3) with S = {S} subjects of the analysis, got "
                         f"{q_rest.shape}")
    check_spd("KJ", KJ)
    return KJ, q_rest


def _time_constant(name, v, T):
    """``v`` (scalar, (S,) or (S, L) [s]) broadcast to ``T``'s (S, L); None: the paper's T/5."""
    if v is None:
        return T / 5.0
    a = np.asarray(as_array(name, v), dtype=float)
    if a.ndim == 1 and a.shape[0] == T.shape[0]:
        a = a[:, None]
    try:
        a = np.broadcast_to(a, T.shape)
    except ValueError as e:
        raise ValueError(f"`{name}` must be a scalar, (S,) or (S, L) = {T.shape} [s], got shape {np.shape(v)}") from e
    if np.any(a <= 0):
        raise ValueError(f"`{name}` must be positive [s], got {a.min()}")
    return a


def _movement_inputs(analysis):
    """Per subject × label: mean rest posture (S, L, 3), end target (S, L, 2), T (S, L) and the
    cells with data (S, L). Cells without data get placeholder values (masked by the callers)."""
    S, L = analysis.T.shape
    has = analysis.n_valid >= 1
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        q0 = np.nanmean(analysis.rest_q, axis=2)
    fallback = np.nanmean(q0[has], axis=0) if has.any() else np.zeros(3)
    q0 = np.where(has[..., None], q0, fallback)
    T = np.where(has, analysis.T, np.nanmean(analysis.T) if has.any() else 0.5)
    target = np.broadcast_to(analysis.targets[:, 1], (S, L, 2))
    return q0, target, T, has


@dataclasses.dataclass(frozen=True)
class PointingPrediction:
    """Donders-fitted λ0-PMP predictions of every movement (:func:`predict_pointing`), numpy arrays.

    ``subjects``, ``labels``; ``tau0``, ``tau``, ``k`` (S, L) the time constants [s] and Eq 10
    gain used (at the mean rest posture); ``t`` (S, L, N) [s], ``x`` (S, L, N, 2) [m], ``q``
    (S, L, N, 3) [rad], ``speed`` (S, L, N) [m/s] the simulated movements (mean over the trials,
    each from its measured rest posture); ``onset``, ``offset``, ``duration`` (S, L) [s] their cut
    at the analysis threshold; ``path`` (S, L, n, 2), ``q_path`` (S, L, n, 3), ``speed_path``
    (S, L, n) at the normalised samples; ``a_sum``, ``a_net`` (S, L) (means over the trials);
    the comparison with the data: ``p_model`` (S, L) p-value of the one-sample t-test of the
    measured ``A_net`` against the model's, ``captured`` (S, L) (tested and p ≥ ``alpha``),
    ``n_tested``, ``n_captured`` (S,) and ``share_captured`` (S,) = captured / 16 (the paper's
    "6 of 16 (37 %)"); ``status`` (S, L) (``pmpjax.Status``: 0 ok, TOO_FEW_DATA without data,
    NONFINITE / SINGULAR from the simulation); ``alpha``.
    """

    subjects: tuple
    labels: tuple
    tau0: np.ndarray
    tau: np.ndarray
    k: np.ndarray
    t: np.ndarray
    x: np.ndarray
    q: np.ndarray
    speed: np.ndarray
    onset: np.ndarray
    offset: np.ndarray
    duration: np.ndarray
    path: np.ndarray
    q_path: np.ndarray
    speed_path: np.ndarray
    a_sum: np.ndarray
    a_net: np.ndarray
    p_model: np.ndarray
    captured: np.ndarray
    n_tested: np.ndarray
    n_captured: np.ndarray
    share_captured: np.ndarray
    status: np.ndarray
    alpha: float

    def table(self) -> str:
        """Per subject: the movements whose ``A_net`` the model captures (paper Results)."""
        out = []
        for s, name in enumerate(self.subjects):
            caught = [lab for lab, c in zip(self.labels, self.captured[s]) if c]
            out.append(f"{name}: model captures A_net of {int(self.n_captured[s])} of {len(self.labels)} movements "
                       f"({100 * self.share_captured[s]:.0f} %; {int(self.n_tested[s])} tested): {', '.join(caught)}")
        return "\n".join(out)


def compare_curvature(a_net, model_a_net, *, alpha: float = _ALPHA):
    """One-sample t-tests of measured ``a_net`` (S, L, K) (NaN = excluded) against the model's
    ``model_a_net`` (S, L): ``(p (S, L), captured (S, L), n_tested (S,), n_captured (S,))``."""
    S, L = model_a_net.shape
    p = np.array([[_ttest(a_net[s, j], model_a_net[s, j]) if np.isfinite(model_a_net[s, j]) else np.nan
                   for j in range(L)] for s in range(S)])
    tested = np.isfinite(p)
    captured = tested & (p >= alpha)
    return p, captured, tested.sum(1), captured.sum(1)


def predict_pointing(analysis: PointingAnalysis, KJ, q_rest, *, tau0=None, tau=None) -> PointingPrediction:
    """The Donders-fitted λ0-PMP's prediction of every movement (paper Section 3).

    **Arguments:** ``analysis`` (:func:`analyze_pointing`); ``KJ`` (S, 3, 3) SPD [Nm/rad] and
    ``q_rest`` (S, 3) [rad] in the order of ``analysis.subjects`` (one (3, 3) / (3,) serves all),
    e.g. from ``fitting.fit_donders`` on the subjects' Donders sessions; ``tau0``, ``tau`` [s]:
    scalar, (S,) or (S, L); default the paper's ``τ = τ0 = T_sj/5`` with ``T_sj`` the measured
    mean duration.

    Every measured movement is simulated from its measured rest posture before the movement to
    the target: ``W = τ0 KJ`` (Eq 7), Arimoto ``K(t)`` (Eq 8) with ``k = b_max(B(q0))/τ0``
    (Eq 10). All subjects × movements × trials run in one batched ``pmpjax.simulate`` call (in
    time normalised by ``T_sj``, see ``normalised_movements``). The model movements are observed
    through the analysis' smoothing spline (its equivalent kernel) and cut at its speed
    threshold like the data; the model's values per subject × movement are the means over the
    trials. Its ``A_net`` is compared with the measured ones by a one-sample t-test per subject ×
    movement (α = 0.05). Returns a :class:`PointingPrediction`.

    **Compile time:** ≈ 3 s on first use, together with :func:`analyze_pointing`
    (benchmarks/compile_times.py).
    """
    KJ, q_rest = _check_params(analysis, KJ, q_rest)
    q_mean, target, T, has = _movement_inputs(analysis)
    S, L, K = analysis.valid.shape
    tau0_ = _time_constant("tau0", tau0, T)
    tau_ = _time_constant("tau", tau, T)
    r0, r = tau0_ / T, tau_ / T
    span, dt = model_grid(np.concatenate([r0[has], r[has]]) if has.any() else np.array([0.2]))
    valid = analysis.valid
    q0 = np.where(valid[..., None], np.nan_to_num(analysis.rest_q), q_mean[:, :, None])
    B = S * L * K
    flat = lambda a, tail=(): np.broadcast_to(  # noqa: E731
        np.reshape(a, (S, L, 1) + tail) if np.ndim(a) == 2 + len(tail) else a, (S, L, K) + tail).reshape((B,) + tail)
    tr = normalised_movements(flat(KJ[:, None, None], (3, 3)), flat(q_rest[:, None, None], (3,)), flat(r0), flat(r),
                              flat(q0, (3,)), flat(target, (2,)), span=span, dt=dt, d=analysis.d)
    bw = flat(spline_bandwidth(analysis.lam, analysis.rate)[:, None] / T)
    prof = jax.device_get(_profiles_jit(tr, jnp.asarray(flat(T)), jnp.asarray(0.5 / analysis.rate / flat(T)),
                                        jnp.asarray(bw), h=float(dt), J=_kernel_halfwidth(bw, dt),
                                        threshold=analysis.threshold, n_samples=analysis.mean_path.shape[2],
                                        radius=analysis.radius))
    rs = lambda a: np.asarray(a).reshape((S, L, K) + np.shape(a)[1:])  # noqa: E731
    sim_status = rs(tr.status)
    bad = np.where(valid, sim_status, 0)
    status = np.where(~has, int(Status.TOO_FEW_DATA), np.max(bad, axis=2))
    use = valid & (sim_status == 0)

    def mean(a):  # over the valid trials of each subject × movement; NaN where none
        m = use.reshape(use.shape + (1,) * (a.ndim - 3))
        n = np.maximum(use.sum(2), 1).reshape((S, L) + (1,) * (a.ndim - 3))
        out = np.where(m, a, 0.0).sum(2) / n
        return np.where((use.sum(2) > 0).reshape((S, L) + (1,) * (a.ndim - 3)), out, np.nan)

    a_net = mean(rs(prof["a_net"]))
    p, captured, n_tested, n_captured = compare_curvature(analysis.a_net, a_net)
    W = tau0_[..., None, None] * KJ[:, None]
    J = np.asarray(Wrist(analysis.d).jacobian(q_mean))
    k = np.linalg.eigvalsh(np.asarray(task_damping(J, W)))[..., -1] / tau0_
    ok = status == 0
    t = np.asarray(tr.t)[None, None] * T[..., None]
    return PointingPrediction(
        subjects=analysis.subjects, labels=analysis.labels, tau0=tau0_, tau=tau_, k=np.where(ok, k, np.nan), t=t,
        x=mean(rs(tr.x)), q=mean(rs(tr.q)), speed=mean(np.linalg.norm(rs(tr.xdot), axis=-1) / flat(T).reshape(
            S, L, K, 1)), onset=mean(rs(prof["onset"])), offset=mean(rs(prof["offset"])),
        duration=mean(rs(prof["duration"])), path=mean(rs(prof["path"])), q_path=mean(rs(prof["q_path"])),
        speed_path=mean(rs(prof["speed"])), a_sum=mean(rs(prof["a_sum"])), a_net=a_net, p_model=p,
        captured=captured, n_tested=n_tested, n_captured=n_captured, share_captured=n_captured / L, status=status,
        alpha=_ALPHA,
    )
