"""Reaches in a continuous recording: hand speed, one movement per speed peak, and the window a model
fit needs around each (Tommasino & Campolo 2017, Section 2 "Data Analysis", for several reaches).

:func:`find_movements` takes a :class:`~pmpjax.JointRecording` (one trial, several reaches, each
starting where the last ended) and a chain, and returns :class:`Reaches`, one row per reach, in
the recording's own clock. Host-side NumPy/SciPy, like :mod:`pmpjax._analysis.movement`: the
only JAX call is the chain's forward kinematics, once on the whole recording.

**Smoothing.** Hand positions are low-passed by a second-order Butterworth filter run forwards
and backwards (zero phase; SciPy ``butter`` + ``sosfiltfilt``) at ``smoothing_hz`` and
differentiated by central differences. Each end is extended by the recording reflected through a
straight line fitted to its first (last) ``2·fs/smoothing_hz`` samples: ``filtfilt``'s own
reflection through the end sample carries that sample's noise into the slope (hand-speed spikes of
3x the interior noise at the ends). Chosen by a check at 0.2° of white joint noise on a
0.3/0.25/0.15 m planar arm at 100 Hz (minimum-jerk reaches of 0.35-1 s, 100 noise draws): at 6 Hz
the 20 %-of-peak crossings are within 0.6 ± 1.4 samples of the noise-free ones (worst 5); 8 Hz
has 1.5x the speed noise at rest, 4 Hz moves the crossings of 0.35 s reaches by 2-3 samples; a
cubic Savitzky-Golay derivative (31 samples) equals the 5 Hz filter inside the recording but has
no cut-off in Hz to state and 3x the noise in its end samples.

**Rest** (``start``, ``end``) is looked for in the speed low-passed at ``rest_smoothing_hz`` (half
the cut-off by default): 5 % of a slow reach's peak is as low as the speed noise, and the first
sample below it in the 6 Hz speed is as often inside the reach as not; the smoother speed is 3x
quieter, and its wider bell crosses 5 % 2-4 samples early, on the side of rest.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .._chains import Chain
from .._data import JointRecording

_MAD = 1.4826  # median absolute deviation -> standard deviation of a normal sample


@dataclasses.dataclass(frozen=True, eq=False)
class Reaches:
    """The reaches found in one recording, one row per reach (K rows), in its own clock.

    - ``recording``, ``subject``: the recording's ``name`` and ``subject``.
    - ``start``, ``onset``, ``peak``, ``offset``, ``end``: (K,) sample indices into the recording,
      ``start ≤ onset ≤ peak ≤ offset ≤ end``. ``onset``/``offset``: the paper's 20 %-of-peak
      crossings; ``start``/``end``: the window for a model, at rest (see :func:`find_movements`).
    - ``t_start``, ``t_onset``, ``t_peak``, ``t_offset``, ``t_end``: (K,) the same as times from the
      recording's ``t`` [s].
    - ``peak_speed``: (K,) peak hand speed [m/s] (task units per second for a chain whose task
      space is not in metres).
    - ``cut_short``: (K,) bool, the next reach began before this one came to rest; its ``end`` is
      the speed minimum between the two peaks.
    - ``amplitude``: (K,) ``|x(end) − x(start)|`` of the smoothed hand path [m].
    - ``skipped``: ``(t_from, t_to, reason)`` [s] for every stretch outside the reaches in which
      the hand moved, time-ordered.
    - ``speed``: (T,) the smoothed hand speed [m/s] the reaches were found in (None if not given).
    - ``noise_speed``: rms hand speed [m/s] that the measurement noise alone leaves after smoothing
      (estimated from the smoothing residual; NaN if not given).

    ``len(reaches)`` is K; ``reaches.windows`` the K slices ``start:end + 1``. Construct by hand
    (e.g. from labelled windows) with equal-length arrays in this order; checked on construction.
    """

    recording: str
    subject: str
    start: np.ndarray
    onset: np.ndarray
    peak: np.ndarray
    offset: np.ndarray
    end: np.ndarray
    t_start: np.ndarray
    t_onset: np.ndarray
    t_peak: np.ndarray
    t_offset: np.ndarray
    t_end: np.ndarray
    peak_speed: np.ndarray
    cut_short: np.ndarray
    amplitude: np.ndarray
    skipped: tuple[tuple[float, float, str], ...] = ()
    speed: np.ndarray | None = None
    noise_speed: float = math.nan

    def __post_init__(self):
        set_ = object.__setattr__
        for name in ("recording", "subject"):
            if not isinstance(getattr(self, name), str):
                raise TypeError(f"Reaches: `{name}` must be a str, got {getattr(self, name)!r}")
        k = None
        for name in ("start", "onset", "peak", "offset", "end", "t_start", "t_onset", "t_peak", "t_offset",
                     "t_end", "peak_speed", "cut_short", "amplitude"):
            a = np.asarray(getattr(self, name))
            if a.ndim != 1 or (k is not None and a.shape[0] != k):
                raise ValueError(f"Reaches: `{name}` must have shape (K,) = ({k if k is not None else 'K'},) like "
                                 f"`start`, got shape {a.shape}")
            k = a.shape[0]
            if name == "cut_short":
                a = a.astype(bool)
            elif not name.startswith(("t_", "peak_speed", "amplitude")):
                if a.size and not np.all(np.asarray(a) == np.round(a)):
                    raise ValueError(f"Reaches: `{name}` must hold integer sample indices, got {a}")
                a = a.astype(np.int64)
            else:
                a = a.astype(np.float64)
            set_(self, name, a)
        order = np.stack([self.start, self.onset, self.peak, self.offset, self.end])
        if order.size and (np.any(order[0] < 0) or np.any(np.diff(order, axis=0) < 0)):
            raise ValueError("Reaches: every row needs 0 <= `start` <= `onset` <= `peak` <= `offset` <= `end`")
        skipped = tuple((float(a), float(b), str(r)) for a, b, r in self.skipped)
        set_(self, "skipped", skipped)
        if self.speed is not None:
            set_(self, "speed", np.asarray(self.speed, dtype=np.float64))
        set_(self, "noise_speed", float(self.noise_speed))

    def __len__(self) -> int:
        return int(self.start.shape[0])

    @property
    def windows(self) -> tuple[slice, ...]:
        """The K model windows as slices ``start:end + 1`` (``recording.q[w]``, ``recording.t[w]``)."""
        return tuple(slice(int(a), int(b) + 1) for a, b in zip(self.start, self.end))


def find_movements(recording: JointRecording, chain: Chain, *, smoothing_hz: float = 6.0, onset: float = 0.2,
                   rest: float = 0.05, min_peak_speed: float = 0.1, min_peak_fraction: float = 0.2,
                   min_dip: float = 0.2, min_duration: float = 0.15, noise_factor: float = 5.0,
                   rest_smoothing_hz: float | None = None) -> Reaches:
    """Find the reaches of a continuous recording from its hand speed.

    The hand path ``x = chain.fk(recording.q)`` is smoothed (zero-phase Butterworth low-pass at
    ``smoothing_hz``; see the module docstring) and its tangential speed ``|ẋ|`` taken. Every speed
    peak that is high enough (``min_peak_speed``, ``min_peak_fraction``) and separated from its
    neighbours by a dip (``min_dip``) is one reach. Around its peak ``P``, searching back and
    forward but never past the speed minimum between it and a neighbouring reach's peak:

    - ``onset``/``offset``: the last sample before / first after the peak with speed below
      ``onset·P`` (the paper's rule, as :func:`pmpjax.segment_by_speed` for one movement), or
      the minimum between the peaks when the speed does not fall that low;
    - ``start``/``end`` (the window for a model, which must start at rest, not at 20 % of the
      peak): the last sample at or before the onset / first at or after the offset with speed
      below ``rest·P`` (in the smoother speed, see the module docstring), or the minimum between
      the peaks when the speed does not fall that low.
      A reach that does not come to rest before the next one begins is ``cut_short``.

    Reported in ``skipped`` instead: a reach running off the start or end of the recording (no
    such sample before / after it), one shorter than ``min_duration``, and every other stretch
    whose speed rises above ``max(noise_factor·noise_speed, rest·largest peak)`` (a twitch,
    drift, a peak too low to be a reach).

    **Arguments:**

    - ``recording``: a :class:`~pmpjax.JointRecording`, ``q`` (T, n) [rad], evenly sampled.
    - ``chain``: a pmpjax chain with ``chain.n == n`` (``PlanarArm``, ``ShoulderElbowArm``,
      ``MjcfChain``, ``Wrist``, ``FunctionChain``); its ``fk`` gives the hand position [m].
    - ``smoothing_hz``: low-pass cut-off [Hz], in (0, fs/2). Default 6 Hz: minimum-jerk reaches
      of 0.35 s and longer keep their 20 % crossings within 1 sample on average (module docstring).
    - ``onset``: onset/offset level, a fraction of the reach's peak speed, in (0, 1). Default 0.2,
      the paper's 20 %. Reliable when ``onset·P`` is several times ``noise_speed``.
    - ``rest``: level of rest for the window, a fraction of the reach's peak speed, in
      (0, ``onset``). Default 0.05 (5 %).
    - ``min_peak_speed``: lowest peak speed of a reach [m/s], >= 0. Default 0.1 m/s (a slow reach
      peaks at 0.2-0.3 m/s; 0.2° of joint noise leaves ~0.016 m/s rms on an arm at 6 Hz).
    - ``min_peak_fraction``: lowest peak speed of a reach as a fraction of the recording's largest
      peak, in [0, 1). Default 0.2. A reach must pass both peak thresholds.
    - ``min_dip``: two peaks are separate reaches only when the speed between them falls by at
      least this fraction of the lower one (its prominence), in (0, 1). Default 0.2.
    - ``min_duration``: shortest reach from onset to offset [s], >= 0. Default 0.15 s (a 0.2 s
      minimum-jerk reach lasts 0.15 s between its 20 % crossings).
    - ``noise_factor``: a stretch outside the reaches counts as movement (``skipped``) where its
      speed exceeds this many ``noise_speed`` (and ``rest`` of the largest peak), >= 0. Default 5
      (with 0.2° of joint noise, 2-3 % of recordings report a noise peak at 4, under 0.5 % at 5).
    - ``rest_smoothing_hz``: cut-off [Hz] of the speed in which rest is looked for, in (0, fs/2).
      Default ``smoothing_hz / 2``.

    **Returns:**

    The :class:`Reaches`.

    **Raises:**

    ``TypeError`` for a ``recording`` or ``chain`` of the wrong type; ``ValueError``
    naming the argument for a chain whose size differs from ``recording.q``'s columns, thresholds
    out of range, a cut-off at or above the Nyquist rate, uneven sampling, or a recording of
    ``2/rest_smoothing_hz`` seconds or less (too short to smooth; 0.67 s by default).
    """
    if not isinstance(recording, JointRecording):
        raise TypeError(f"`recording` must be a pmpjax.JointRecording (pj.read_joint_angles), got "
                        f"{type(recording).__name__}")
    if not isinstance(chain, Chain):
        raise TypeError(f"`chain` must be a pmpjax chain (e.g. pj.PlanarArm), got {type(chain).__name__}")
    if chain.n != recording.n:
        raise ValueError(f"`chain` has {chain.n} joints but `recording.q` has {recording.n} columns "
                         f"({list(recording.joint_names)})")
    fs = recording.fs
    smoothing_hz = _number("smoothing_hz", smoothing_hz, lo=0.0, hi=fs / 2, lo_open=True, hi_open=True,
                           unit=f"Hz, below the Nyquist rate fs/2 = {fs / 2:g} Hz")
    onset = _number("onset", onset, lo=0.0, hi=1.0, lo_open=True, hi_open=True, unit="fraction of the peak")
    rest = _number("rest", rest, lo=0.0, hi=onset, lo_open=True, hi_open=True,
                   unit=f"fraction of the peak, below `onset` = {onset:g}")
    min_peak_speed = _number("min_peak_speed", min_peak_speed, lo=0.0, unit="m/s")
    min_peak_fraction = _number("min_peak_fraction", min_peak_fraction, lo=0.0, hi=1.0, hi_open=True,
                                unit="fraction of the largest peak")
    min_dip = _number("min_dip", min_dip, lo=0.0, hi=1.0, lo_open=True, hi_open=True,
                      unit="fraction of the lower peak")
    min_duration = _number("min_duration", min_duration, lo=0.0, unit="s")
    noise_factor = _number("noise_factor", noise_factor, lo=0.0, unit="multiple of the noise speed")
    rest_hz = smoothing_hz / 2 if rest_smoothing_hz is None else \
        _number("rest_smoothing_hz", rest_smoothing_hz, lo=0.0, hi=fs / 2, lo_open=True, hi_open=True,
                unit=f"Hz, below the Nyquist rate fs/2 = {fs / 2:g} Hz")
    t = recording.t
    T = t.shape[0]
    dt = 1.0 / fs
    if np.max(np.abs(np.diff(t) - dt)) > 0.05 * dt:
        raise ValueError(f"`recording.t` must be evenly sampled at fs = {fs:g} Hz to be filtered; steps range "
                         f"{np.diff(t).min():.4g}..{np.diff(t).max():.4g} s")
    low = min(smoothing_hz, rest_hz)
    if T <= _edge(fs, low):
        raise ValueError(f"`recording` is too short to smooth at {low:g} Hz (`smoothing_hz`, `rest_smoothing_hz`): "
                         f"{T} samples ({T * dt:.3g} s), needs more than {_edge(fs, low)} (2/{low:g} Hz)")

    x = np.asarray(chain.fk(recording.q), dtype=np.float64).reshape(T, -1)
    if not np.all(np.isfinite(x)):
        raise ValueError("`chain.fk(recording.q)` is not finite")
    xs, v, noise_speed = _smooth(x, fs, smoothing_hz)
    speed = np.linalg.norm(v, axis=1)
    # Rest in a quieter speed: 5 % of a slow reach's peak is down in the noise (module docstring).
    slow = np.linalg.norm(_smooth(x, fs, rest_hz)[1], axis=1)

    largest = float(speed.max())
    floor = max(min_peak_speed, min_peak_fraction * largest)
    peaks = _separate_peaks(speed, min_dip)
    # Prominence is measured against every higher peak, so two neighbouring peaks kept here are
    # separated by a dip of at least `min_dip` of the lower one.
    peaks = peaks[speed[peaks] >= floor] if floor > 0 else peaks[speed[peaks] > 0]

    rows, skipped = [], []
    covered = np.zeros(T, dtype=bool)
    dips = [int(a + np.argmin(speed[a:b + 1])) for a, b in zip(peaks[:-1], peaks[1:])]
    for k, p in enumerate(peaks):
        P = float(speed[p])
        lo = dips[k - 1] if k > 0 else None
        hi = dips[k] if k < len(dips) else None
        lo_i, hi_i = (0 if lo is None else lo), (T - 1 if hi is None else hi)
        i_on = _last_below(speed, lo_i, p - 1, onset * P)
        i_off = _first_below(speed, p + 1, hi_i, onset * P)
        i_on = lo if i_on is None else i_on
        i_off = hi if i_off is None else i_off
        i_start = _last_below(slow, lo_i, i_on, rest * P) if i_on is not None else None
        i_end = _first_below(slow, i_off, hi_i, rest * P) if i_off is not None else None
        cut = i_end is None and hi is not None
        i_start = lo if i_start is None else i_start
        i_end = hi if i_end is None else i_end
        tp = float(t[p])
        if i_start is None:
            covered[: (i_end if i_end is not None else T - 1) + 1] = True
            what = f"onset={onset:g}" if i_on is None else f"rest={rest:g}"
            skipped.append((float(t[0]), float(t[i_end if i_end is not None else T - 1]),
                            f"reach with peak {P:.3g} m/s at t={tp:.3f} s runs off the start of the recording (its "
                            f"speed is not below {what} of the peak before it; {speed[0]:.3g} m/s at the first "
                            "sample)"))
            continue
        if i_end is None:
            covered[i_start:] = True
            what = f"onset={onset:g}" if i_off is None else f"rest={rest:g}"
            skipped.append((float(t[i_start]), float(t[-1]),
                            f"reach with peak {P:.3g} m/s at t={tp:.3f} s runs off the end of the recording (its "
                            f"speed is not below {what} of the peak after it; {speed[-1]:.3g} m/s at the last "
                            "sample)"))
            continue
        covered[i_start:i_end + 1] = True
        duration = float(t[i_off] - t[i_on])
        if duration < min_duration:
            skipped.append((float(t[i_start]), float(t[i_end]),
                            f"movement with peak {P:.3g} m/s at t={tp:.3f} s lasts {duration:.3g} s from onset to "
                            f"offset, shorter than min_duration={min_duration:g} s"))
            continue
        rows.append((i_start, i_on, p, i_off, i_end, P, cut))

    moving = (speed > max(noise_factor * noise_speed, rest * largest)) & ~covered
    for a, b in _runs(moving):
        m = a + int(np.argmax(speed[a:b + 1]))
        below = [f"min_peak_speed={min_peak_speed:g} m/s"] if speed[m] < min_peak_speed else []
        if speed[m] < min_peak_fraction * largest:
            below.append(f"min_peak_fraction={min_peak_fraction:g} of the largest peak ({largest:.3g} m/s)")
        why = ("below " + " and ".join(below)) if below else \
            f"not separated from the neighbouring reach by a dip of min_dip={min_dip:g}"
        skipped.append((float(t[a]), float(t[b]), f"movement with peak {speed[m]:.3g} m/s at t={t[m]:.3f} s, {why}"))
    skipped.sort(key=lambda s: (s[0], s[1]))

    idx = np.array([r[:5] for r in rows], dtype=np.int64).reshape(-1, 5)
    st, on, pk, off, en = idx.T
    return Reaches(
        recording=recording.name, subject=recording.subject, start=st, onset=on, peak=pk, offset=off, end=en,
        t_start=t[st], t_onset=t[on], t_peak=t[pk], t_offset=t[off], t_end=t[en],
        peak_speed=np.array([r[5] for r in rows], dtype=np.float64),
        cut_short=np.array([r[6] for r in rows], dtype=bool),
        amplitude=np.linalg.norm(xs[en] - xs[st], axis=-1).reshape(-1),
        skipped=tuple(skipped), speed=speed, noise_speed=noise_speed)


# ---------------------------------------------------------------------------------------------


def _number(name, v, *, lo=None, hi=None, lo_open=False, hi_open=False, unit=""):
    if isinstance(v, bool) or not isinstance(v, int | float | np.integer | np.floating) or not np.isfinite(v):
        raise ValueError(f"`{name}` must be a finite number [{unit}], got {v!r}")
    v = float(v)
    if (lo is not None and (v < lo or (lo_open and v == lo))) or (hi is not None and (v > hi or (hi_open and v == hi))):
        rng = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}" if hi is not None else \
            f"{'>' if lo_open else '>='} {lo:g}"
        raise ValueError(f"`{name}` must be {'in ' if hi is not None else ''}{rng} [{unit}], got {v:g}")
    return v


def _edge(fs, fc):
    """Samples of each end's line fit and reflection: 2/fc seconds, many time constants of the filter."""
    return max(int(math.ceil(2 * fs / fc)), 5)


def _smooth(x, fs, fc):
    """Zero-phase low-pass of ``x`` (T, m), velocity by central differences, and the rms speed of
    white measurement noise after this smoothing (from the residual's robust spread)."""
    from scipy.signal import butter, sosfiltfilt  # (imported here: keeps `import pmpjax` fast)

    n_edge = _edge(fs, fc)
    sos = butter(2, fc, fs=fs, output="sos")
    T = x.shape[0]
    xp = np.concatenate([_line_reflection(x, n_edge), x, _line_reflection(x[::-1], n_edge)[::-1]])
    xs = sosfiltfilt(sos, xp, axis=0, padtype=None)
    v = np.gradient(xs, 1.0 / fs, axis=0)[n_edge:n_edge + T]
    xs = xs[n_edge:n_edge + T]
    # The pipeline is linear and shift-invariant away from the ends: its impulse responses give the
    # noise gains of the residual x - xs and of the velocity for white noise of unit variance.
    L = 2 * int(math.ceil(20 * fs / fc)) + 1
    impulse = np.zeros(L)
    impulse[L // 2] = 1.0
    h = sosfiltfilt(sos, impulse, padtype=None)
    g_res = float(np.sum((impulse - h) ** 2))
    g_vel = float(np.sum(np.gradient(h, 1.0 / fs) ** 2))
    r = x - xs
    sigma = _MAD * np.median(np.abs(r - np.median(r, axis=0)), axis=0) / math.sqrt(g_res)
    return xs, v, float(math.sqrt(g_vel * np.sum(sigma**2)))


def _line_reflection(x, n):
    """The ``n`` samples before ``x[0]``: ``x[1..n]`` reflected through the straight line fitted to
    ``x[0..n-1]`` at ``x[0]``'s time (keeps the end's slope without anchoring on one noisy sample)."""
    k = np.arange(n, dtype=np.float64)
    A = np.stack([np.ones(n), k], axis=1)
    coef = np.linalg.lstsq(A, x[:n], rcond=None)[0]
    return 2 * coef[0] - x[n:0:-1]


def _separate_peaks(speed, min_dip):
    """Local maxima (ends included) whose prominence is at least ``min_dip`` of their height."""
    from scipy.signal import find_peaks

    padded = np.concatenate([[0.0], speed, [0.0]])  # a maximum at either end counts (a reach cut off there)
    peaks, props = find_peaks(padded, prominence=0.0)
    keep = props["prominences"] >= min_dip * padded[peaks]
    return peaks[keep] - 1


def _last_below(speed, lo, hi, level):
    """Last index in [lo, hi] with speed < level, or None."""
    if hi < lo:
        return None
    i = np.nonzero(speed[lo:hi + 1] < level)[0]
    return int(lo + i[-1]) if i.size else None


def _first_below(speed, lo, hi, level):
    """First index in [lo, hi] with speed < level, or None."""
    if hi < lo:
        return None
    i = np.nonzero(speed[lo:hi + 1] < level)[0]
    return int(lo + i[0]) if i.size else None


def _runs(mask):
    """(first, last) index of every run of True in ``mask``."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.nonzero(d == 1)[0], np.nonzero(d == -1)[0] - 1))
