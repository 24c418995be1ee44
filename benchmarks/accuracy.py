"""Benchmark: ``simulate``'s error estimate against the true error, adaptive steps against fixed
steps, and what the estimate costs on the fixed-step path.

``Trajectory.error_estimate`` [rad] is the sum over steps of the largest component of the embedded
local error estimate (RK4: its first-same-as-last third-order companion; RODAS4: its last stage);
``status`` is ``INACCURATE`` where it exceeds ``atol + rtol·max|q|`` (defaults 5e-4 rad, 1e-4:
0.029–0.038° here).

**1. Estimate against the true error** (``estimate``). Batches of movements, each run through the
public ``simulate`` (float64); the true error of a movement is its largest joint error over the
saved samples against SciPy ``solve_ivp(method="Radau", rtol=1e-10, atol=1e-12)`` on an independent
NumPy field (``tests/_reference.py``: ``pmp_field`` with ``wrist_fk``/``wrist_jac`` or
``arm4_fk``/``arm4_jac``, ``arimoto``; Eq 10's gain from ``eigvalsh``; the minimum-jerk gain from
its definition ξ̇/(1 − ξ), the integration restarted where it reaches the cap). The reference's own
error is ≤ 1.4e-9° on every problem (against Radau at rtol 1e-12 and DOP853 at 1e-13), so true
errors below 1e-8° are not resolved (two wrist-edge movements at 10 RODAS4 steps per sample:
their ratio is shown as a lower bound and left out of the summary). Problems: **Figure 3**
(``FIGURE3``, ``Wrist()``, ``ArimotoPlanner(k=22.5, tau=0.08)``, W = τ0 KJ, 8 targets on the π/12
circle, every step saved; a step longer than the movement is cut to one 0.4 s step, final state;
adaptive rows save 50 samples); **wrist edge** (Eq 10's
gain, ``ArimotoPlanner(k=None, tau=τ0, tau0=τ0)``, random SPD KJ of trace 4 with cond 1e2, 1e3, 1e4,
4 movements each, start, target and rest postures pointing 45–60° off the screen's normal, 50
samples over 0.4 s); **arm** (``ShoulderElbowArm``, benchmarks/stiff.py's movements: its first 12 and
the six of its B = 64 batch beyond them that fixed RODAS4 ×5 flags and whose reference finishes, 50
samples); **k = 1e9** (Figure 3 with Arimoto k = 1e9); **min-jerk** (``MinimumJerkPlanner(0.4,
gain_cap=200)`` on Figure 3's wrist); **stiffening path** (Eq 10's gain with KJ = diag(0.01, 1.5, 2)
from near the screen's centre, where Eq 10's rate is 15/s and RK4's start check accepts dt up to
0.17 s, to targets 0.6 d out, where the rate reaches ~900/s). "Catastrophic": non-finite or a true
error above 10°.

**2. Adaptive against fixed steps** (``adaptive``). benchmarks/stiff.py's arm batch (B = 64, 256;
50 samples over normalised time) at its fixed RODAS4 steps (×2, ×5 per sample) against ``dt=None``
with ``solver="rodas4"`` (also with ``max_steps=1024``) and ``"rk4"``; benchmarks/simulate.py's
Figure 3 batch (B = 1 000, final state) at RK4 1 ms against ``dt=None`` with either solver. Public
calls: the first call (compile + run) apart, then 7 rounds interleaved across the rows, median.
Steps per movement of ``dt=None``: counted by tracing its kernel again with
``integrate_adaptive`` wrapped to report its step counts (``jax.debug.callback``); the batch runs in
lockstep, so its loop runs the largest count. Accuracy against Radau on the first 8 (arm) or 12
(wrist) movements ("first n") and on those plus the 8 movements with the largest estimates that
some row flags, skipping references that take over 30 s ("checked": 2 arm movements pass so close
to a singular posture that Radau does not finish). ``× first row``: run time over the workload's
first (fixed-step) row.

**3. Overhead of the estimate on the fixed-step path** (``overhead --base DIR``, DIR a work tree of
the code without the error estimate, made with ``git worktree add``). One worker process
per tree (PYTHONPATH puts the tree first; the worker reports ``pmpjax.__file__`` and the run stops if
it is not that tree's) runs benchmarks/simulate.py's foundation rows — Figure 3 wrist, RK4 1 ms,
the public ``simulate`` call and the AOT-compiled kernel alone (its ``bench_jax``), final state at
B = 1 000 and 10 000 and every step at B = 10 000 (its ``--saves`` row) — one call at a time on
request, alternating which tree goes first, so both see the same background load. Per row: the
median time per tree and the median (interquartile range) of the per-round ratios new / base, wall
and process CPU time.

Run: ``python benchmarks/accuracy.py estimate`` (≈ 6 min; ``--only figure3 k1e9``, ``wrist_edge``,
``arm``, ``minjerk stiffening`` run 1.5–3 min each and keep the other problems' rows in the JSON),
``adaptive`` (≈ 6 min; ``--only arm64``, ``arm256``, ``figure3``), ``overhead --base DIR [--rounds
12]`` (≈ 4 min); no part: estimate and adaptive; ``--quick``: a smoke run that writes nothing.
Writes ``results/accuracy.json`` (one section per part).

Latest figures: 2026-12-05 22:09–23:40 UTC, 2-core AMD EPYC (Zen 4, KVM), no GPU, jax 0.10.2,
SciPy 1.17.1, float64. Other work shared the machine throughout (load average 2.5–9 during
``estimate``, 2.5–3.2 during ``adaptive``, 2.7–6.2 during ``overhead``).

Estimate against the true error (per case: largest true error and estimate over its B movements,
the range of estimate / true over them, the statuses)::

    | case | solver | step | B | true error [deg] | estimate [deg] | estimate / true | status |
    |---|---|---|---:|---:|---:|---:|---|
    | Figure 3 | rk4 | 1 ms | 8 | 1.3e-07 | 1.7e-05 | 1.3e+02 – 1.5e+02 | 8 OK |
    | Figure 3 | rk4 | 2 ms | 8 | 2.2e-06 | 1.4e-04 | 63 – 74 | 8 OK |
    | Figure 3 | rk4 | 5 ms | 8 | 9.8e-05 | 2.5e-03 | 25 – 29 | 8 OK |
    | Figure 3 | rodas4 | 5 ms | 8 | 1.2e-05 | 2.5e-03 | 2.1e+02 – 2.6e+02 | 8 OK |
    | Figure 3 | rodas4 | 20 ms | 8 | 7.9e-03 | 1.7e-01 | 21 – 25 | 8 INACC |
    | Figure 3 | rodas4 | 50 ms | 8 | 1.3e+00 | 6.1e+00 | 4.4 – 5.4 | 8 INACC |
    | Figure 3 | rodas4 | 100 ms | 8 | 1.2e+11 | 1.9e+11 | 0.23 – 2.6 | 8 INACC |
    | Figure 3 | rodas4 | 200 ms | 8 | 7.1e+02 | 5.5e+02 | 0.35 – 1.1 | 8 INACC |
    | Figure 3 | rodas4 | 400 ms | 8 | 1.1e+03 | 2.2e+03 | 0.21 – 1.9 | 8 INACC |
    | Figure 3 | rodas4 | 1000 ms (> T) | 8 | 1.1e+03 | 2.2e+03 | 0.21 – 1.9 | 8 INACC |
    | Figure 3 | rk4 | adaptive | 8 | 1.5e-04 | 2.4e-03 | 16 – 18 | 8 OK |
    | Figure 3 | rodas4 | adaptive | 8 | 3.8e-06 | 1.5e-03 | 3.5e+02 – 4.2e+02 | 8 OK |
    | wrist edge, Eq 10 | rodas4 | 2/sample (4.08 ms) | 12 | 1.1e-01 | 2.3e+00 | 16 – 3.5e+02 | 6 INACC, 6 OK |
    | wrist edge, Eq 10 | rodas4 | 5/sample (1.63 ms) | 12 | 6.3e-03 | 1.8e-01 | 28 – 1.1e+03 | 10 OK, 2 INACC |
    | wrist edge, Eq 10 | rodas4 | 10/sample (0.816 ms) | 12 | 8.4e-05 | 2.9e-02 | 1.4e+02 – 1.1e+03 | 12 OK |
    | wrist edge, Eq 10 | rodas4 | adaptive | 12 | 6.4e-04 | 3.6e-03 | 5.7 – 1.4e+03 | 12 OK |
    | arm, Eq 10 | rodas4 | 2/sample (10.2 ms) | 18 | inf | inf | 3.5 – 1.8e+02 | 13 INACC, 4 OK, 1 NONFIN |
    | arm, Eq 10 | rodas4 | 5/sample (4.08 ms) | 18 | 5.6e+13 | 1.6e+14 | 2.9 – 5.6e+02 | 10 OK, 8 INACC |
    | arm, Eq 10 | rodas4 | 10/sample (2.04 ms) | 18 | 1.2e+00 | 5.4e+01 | 4.5 – 1.3e+03 | 14 OK, 4 INACC |
    | arm, Eq 10 | rodas4 | adaptive | 18 | 2.8e-04 | 4.4e-03 | 16 – 1.3e+03 | 18 OK |
    | Arimoto k = 1e9 | rk4 | 1 ms | 4 | – | – | – | refused: `dt`=0.001 s is too large for RK4 |
    | Arimoto k = 1e9 | rodas4 | 1 ms | 4 | 4.1e+09 | 5.0e+09 | 0.29 – 1.2 | 4 INACC |
    | Arimoto k = 1e9 | rodas4 | 5 ms | 4 | 1.1e+16 | 1.1e+16 | 0.035 – 0.99 | 4 INACC |
    | Arimoto k = 1e9 | rodas4 | 20 ms | 4 | 3.9e+07 | 8.8e+07 | 0.96 – 6.6 | 4 INACC |
    | Arimoto k = 1e9 | rodas4 | 100 ms | 4 | 2.7e+09 | 2.8e+09 | 0.73 – 1.4 | 4 INACC |
    | Arimoto k = 1e9 | rodas4 | adaptive | 4 | 8.7e-06 | 4.5e-05 | 5.2 – 12 | 4 OK |
    | min-jerk generator | rk4 | 1 ms | 4 | 6.6e-07 | 4.5e-06 | 6.9 | 4 OK |
    | min-jerk generator | rk4 | 5 ms | 4 | 8.5e-05 | 8.1e-04 | 9.5 | 4 OK |
    | min-jerk generator | rk4 | 10 ms | 4 | 1.8e-03 | 1.1e-02 | 6.1 | 4 OK |
    | min-jerk generator | rodas4 | 5 ms | 4 | 6.6e-06 | 5.4e-04 | 81 | 4 OK |
    | min-jerk generator | rodas4 | 20 ms | 4 | 4.2e-04 | 6.8e-03 | 16 | 4 OK |
    | min-jerk generator | rodas4 | 50 ms | 4 | 7.7e-02 | 2.1e-01 | 2.7 | 4 INACC |
    | min-jerk generator | rk4 | adaptive | 4 | 2.7e-04 | 2.6e-03 | 9.8 | 4 OK |
    | min-jerk generator | rodas4 | adaptive | 4 | 1.4e-05 | 5.8e-04 | 42 | 4 OK |
    | stiffening path, Eq 10 | rk4 | 1 ms | 4 | 2.0e-06 | 8.3e-04 | 3.5e+02 – 4.4e+02 | 4 OK |
    | stiffening path, Eq 10 | rk4 | 2 ms | 4 | 3.7e-05 | 7.9e-03 | 1.9e+02 – 2.2e+02 | 4 OK |
    | stiffening path, Eq 10 | rk4 | 3 ms | 4 | 2.2e-04 | 3.2e-02 | 1.4e+02 – 1.5e+02 | 4 OK |
    | stiffening path, Eq 10 | rk4 | 5 ms | 4 | 6.3e-02 | 7.5e-01 | 8.9 – 13 | 4 INACC |
    | stiffening path, Eq 10 | rk4 | 10 ms | 4 | 7.1e+01 | 6.1e+02 | 7.2 – 9 | 4 INACC |
    | stiffening path, Eq 10 | rk4 | adaptive | 4 | 2.5e-04 | 6.9e-03 | 24 – 27 | 4 OK |

    estimate / true over the 235 non-catastrophic movements (true error 1e-8° to 10°): 2.7 to
    1.4e3, median 73, 5th–95th percentile 5.0–600; none below 1. By solver (min, median, max):
    rk4 fixed 6.1, 65, 440 (52 movements); rk4 adaptive 9.8, 17, 27 (16); rodas4 fixed 2.7, 72,
    1.3e3 (121); rodas4 adaptive 5.2, 300, 1.4e3 (46).
    True error > 0.05°: 79 movements (24 of them non-catastrophic), SUCCESSFUL among them: none.
    Every SUCCESSFUL movement is within 0.0018° (estimates ≤ 0.038°).
    Accurate (true < 0.01°): 204 movements, 22 flagged INACCURATE (true 0.0007–0.008°, estimates
    0.038–0.27°): Figure 3 RODAS4 at 20 ms (all 8), wrist edge RODAS4 ×2 (1 of 12) and ×5 (2),
    arm RODAS4 ×2 (5 of 18), ×5 (4), ×10 (2). All 9 movements between 0.01° and 0.05° are flagged.

Adaptive against fixed steps::

    | workload | B | solver | steps/movement (median, max) | max err, first n [deg] | max err, checked [deg] | > 0.05° of checked | status | compile [s] | run [s] | per movement [ms] | × first row |
    |---|---:|---|---:|---:|---:|---:|---|---:|---:|---:|---:|
    | arm (stiff.py), 50 samples | 64 | rodas4 ×2 (fixed) | 98 | 1.3e-01 | 9.0e+11 | 8/15 | 37 INACC, 26 OK, 1 NONFIN | 9.1 | 0.016 | 0.246 | 1.00 |
    | arm (stiff.py), 50 samples | 64 | rodas4 ×5 (fixed) | 245 | 1.0e-03 | 1.3e+11 | 2/16 | 50 OK, 14 INACC | 7.4 | 0.033 | 0.510 | 2.07 |
    | arm (stiff.py), 50 samples | 64 | rodas4 adaptive | 130, 4096 | 1.3e-05 | 2.8e-04 | 0/16 | 62 OK, 2 MAXST | 10.4 | 0.666 | 10.406 | 42.22 |
    | arm (stiff.py), 50 samples | 64 | rodas4 adaptive, max_steps 1024 | 130, 1024 | 1.3e-05 | 2.8e-04 | 0/16 | 62 OK, 2 MAXST | 11.6 | 0.166 | 2.593 | 10.52 |
    | arm (stiff.py), 50 samples | 64 | rk4 adaptive | 448, 4096 | 3.7e-04 | 5.0e-04 | 0/9 | 54 OK, 10 MAXST | 8.2 | 0.255 | 3.981 | 16.15 |
    | arm (stiff.py), 50 samples | 256 | rodas4 ×2 (fixed) | 98 | 1.3e-01 | 9.0e+11 | 8/15 | 155 INACC, 100 OK, 1 NONFIN | 7.6 | 0.077 | 0.300 | 1.00 |
    | arm (stiff.py), 50 samples | 256 | rodas4 ×5 (fixed) | 245 | 1.0e-03 | 1.3e+11 | 3/16 | 198 OK, 58 INACC | 6.9 | 0.184 | 0.717 | 2.39 |
    | arm (stiff.py), 50 samples | 256 | rodas4 adaptive | 134, 4096 | 1.3e-05 | 2.8e-04 | 0/16 | 254 OK, 2 MAXST | 9.9 | 5.238 | 20.461 | 68.29 |
    | arm (stiff.py), 50 samples | 256 | rodas4 adaptive, max_steps 1024 | 134, 1024 | 1.3e-05 | 2.8e-04 | 0/16 | 254 OK, 2 MAXST | 11.3 | 1.335 | 5.214 | 17.40 |
    | arm (stiff.py), 50 samples | 256 | rk4 adaptive | 544, 4096 | 3.7e-04 | 1.6e-03 | 0/10 | 212 OK, 44 MAXST | 6.3 | 1.883 | 7.355 | 24.55 |
    | Figure 3 wrist (simulate.py), final | 1000 | rk4 1 ms (fixed) | 400 | 3.9e-11 | 3.9e-11 | 0/12 | 1000 OK | 1.8 | 0.172 | 0.172 | 1.00 |
    | Figure 3 wrist (simulate.py), final | 1000 | rk4 adaptive | 43, 45 | 1.8e-04 | 1.8e-04 | 0/12 | 1000 OK | 4.7 | 0.024 | 0.024 | 0.14 |
    | Figure 3 wrist (simulate.py), final | 1000 | rodas4 adaptive | 30, 31 | 6.8e-06 | 6.8e-06 | 0/12 | 1000 OK | 6.3 | 0.038 | 0.038 | 0.22 |

Overhead of the estimate (new: the work tree with the estimate; base: a work tree without it; 14
rounds, 23:36–23:40 UTC, load 2.9–4.4)::

    | row (Figure 3 wrist, RK4 1 ms) | base [ms] | new [ms] | new / base, wall | new / base, CPU |
    |---|---:|---:|---:|---:|
    | final, public call, B = 1000 | 175 | 174 | 1.004 (0.87–1.06) | 0.958 (0.92–1.03) |
    | final, kernel alone, B = 1000 | 156 | 156 | 0.983 (0.95–1.09) | 0.980 (0.97–1.08) |
    | final, public call, B = 10000 | 1318 | 1444 | 1.105 (1.00–1.15) | 1.078 (1.02–1.14) |
    | final, kernel alone, B = 10000 | 1304 | 1356 | 1.061 (1.02–1.13) | 1.055 (1.02–1.13) |
    | every step, public call, B = 10000 | 1699 | 1790 | 1.083 (1.04–1.11) | 1.066 (1.02–1.09) |
    | every step, kernel alone, B = 10000 | 1711 | 1833 | 1.052 (1.02–1.08) | 1.054 (1.04–1.08) |

What the figures say:

- **The estimate is an upper bound in practice.** On every non-catastrophic movement it exceeds
  the true error, by 2.7× to 1 400× (median 73×). It is loosest where the error is small, since
  the embedded solution is of lower order than the one returned (RK4's third-order companion:
  O(h⁴) against RK4's O(h⁵) per step, 130–150× at 1 ms on Figure 3, 25–29× at 5 ms; RODAS4's
  order-3 companion: median 72× fixed, 300× adaptive): 5–1 400×, median 150×, below 0.001°; and
  tightest where it is large: 2.7–43× from 0.05° up (24 movements).
  Where the integration has diverged (catastrophic: RODAS4 at 100–400 ms on Figure 3, fixed
  RODAS4 at any step for k = 1e9, RK4 at 10 ms on the stiffening path, arm movement 53) the
  estimate is 0.03–9× the (astronomical) true error, always far above the tolerance: every such
  trajectory is INACCURATE or NONFINITE.
- **No inaccurate trajectory passes.** Every movement with a true error above 0.05° (79, from
  0.053° to 1e16°) is non-SUCCESSFUL, including RK4 on the path that stiffens after RK4's start
  check passed (5 ms: 0.063°, 10 ms: 71°) and fixed RODAS4 on the arm movements beyond the 12
  that benchmarks/stiff.py checks (×5: 5.1° on movement 23, a divergence on 53, 0.02–0.04° on 20
  and 59; ×10: 1.2° on 53; ×2: 7.9°, a divergence and a NONFINITE). Every SUCCESSFUL one is within
  0.0018°.
- **The price is false alarms near the tolerance.** 22 of 204 movements within 0.01° are flagged
  (estimates 0.04–0.27° against true 0.0007–0.008°): fixed steps whose estimate sits a few times
  above the 0.03° tolerance (Figure 3 RODAS4 at 20 ms; the stiff cases at 2–10 steps per sample).
  With the default tolerances a fixed-step user asking for 0.01° is never told SUCCESSFUL wrongly,
  but may be told INACCURATE when the true error is 4–40× below the tolerance.
- **L-stable is not accurate.** Fixed RODAS4 is within 0.01° on Figure 3 up to 20 ms (0.008°),
  1.3° off at 50 ms and diverges from 100 ms on; for k = 1e9 it diverges at every step tried
  (1–100 ms: the hand reaches its target, 15° away, within the first millisecond, far beyond one
  linearisation). Adaptive RODAS4 does both to 1e-5°.
- **Adaptive steps: cheapest where every movement is easy, slowest where one is hard.** On Figure 3
  (B = 1 000, final state) ``dt=None`` takes 43 RK4 or 30 RODAS4 steps instead of 400 and runs in
  0.14× (RK4) or 0.22× (RODAS4) the time of RK4 at 1 ms, at 1.8e-4° / 6.8e-6° (the 1 ms steps give
  4e-11°). On the stiff arm batch adaptive RODAS4 needs a median 130 steps per movement (×5 fixed:
  245) and is accurate to 3e-4° on every finished movement, where fixed ×5 has 2 of 16 checked
  movements above 0.05° (5.1° and a divergence; 3 of 16 at B = 256) and ×2 8 of 15, all of them
  flagged. But the batch runs in lockstep, and 2 movements (of 64, and of 256) that pass near a
  singular posture exhaust ``max_steps`` (MAX_STEPS): the loop runs 4 096 iterations for everyone,
  42× (B = 64) and 68× (B = 256) the time of fixed ×2, 20× and 29× that of ×5; ``max_steps=1024``
  cuts it to 10× and 17× that of ×2 with the same statuses. Adaptive RK4 on the stiff arm is
  stability-limited (median 450–540 steps; 10 and 44 movements MAX_STEPS).
- **Which default.** The numbers support keeping fixed steps as the default (RK4, dt = 1 ms):
  ``dt=None`` cannot be reverse-differentiated (``jax.grad`` through its ``while_loop`` raises;
  forward mode works), its cost on a batch is set by the slowest movement, and on non-stiff batches
  the fixed 1 ms steps cost 7× more for an accuracy (4e-11°) far beyond the tolerance. They
  support ``dt=None`` as the recommended setting for forward simulation of non-stiff batches
  (Figure 3: 7× faster at the default tolerance) and as the retry for trajectories that a fixed
  step flags INACCURATE, rather than as the default for stiff batches; and a smaller
  ``MAX_ADAPTIVE_STEPS`` (1 024 instead of 4 096: 4× faster on the arm batch with the same
  statuses).
- **Overhead.** With final saves at B = 10 000 the estimate costs +5–11 % (public call; median of
  five runs +8 %) and +2–10 % (kernel alone; median +6 %); at B = 1 000 it is within the noise
  (0.96–1.09); saving every step, +5–8 % in the kernel and +8–19 % for the public call (median
  +9 %). The 10 % target holds for the medians, not for every run. Of this, measured apart in
  one process (kernel variants compiled side by side, interleaved): judging the status on the
  host (max|q| over the saved samples with NumPy) 23 ms per every-step call (≈ 1 %; 2 ms
  with final saves); computing and carrying RK4's fifth-stage observation (x, q̇, ẋ,
  manipulability) through every step when only the end state is saved ≈ 2.5–4 % (a variant that
  carries only k5 and observes the end state once after the loop gives bit-identical results at
  0.96–0.975× the time, B = 1 000 and 10 000); with every step saved, leaving out the error sum or
  the observation carry each moved the time by less than the noise (0.96–0.99×, ±5 %).
"""

# ruff: noqa: E501  (the pasted result tables above)
from __future__ import annotations

import argparse
import inspect
import json
import os
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(ROOT, "tests"))
import _baselines as bl  # noqa: E402
import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

from _reference import arimoto, arm4_fk, arm4_jac, pmp_field, wrist_fk, wrist_jac  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402
from scipy.optimize import brentq  # noqa: E402

import pmpjax as pj  # noqa: E402

F3 = pj.FIGURE3
TAU0_W = F3["tau0"]  # the wrist's intrinsic time constant [s]
DUR_W = F3["duration"]  # 0.4 s
#: Sample times of the stiff cases: 50 over the movement, as benchmarks/stiff.py (wrist: 0.4 s, arm: 1).
TS_W = tuple(float(v) for v in np.linspace(0.0, DUR_W, 50))
REF_RTOL, REF_ATOL = 1e-10, 1e-12
#: The reference's own error, ≤ 1.4e-9° on every problem (against Radau at rtol 1e-12 and DOP853 at
#: rtol 1e-13): true errors below REF_FLOOR_DEG are not resolved (their ratio is a lower bound).
REF_FLOOR_DEG = 1e-8
#: A trajectory "fails" above this true error [deg] (the tests' bound on successful ones) and is
#: "accurate" below ACCURATE_DEG; "catastrophic": non-finite or above CATASTROPHIC_DEG.
FAIL_DEG, ACCURATE_DEG, CATASTROPHIC_DEG = 0.05, 0.01, 10.0
STATUS = {int(s): s.name for s in pj.Status}
SHORT = {"SUCCESSFUL": "OK", "INACCURATE": "INACC", "NONFINITE": "NONFIN", "MAX_STEPS": "MAXST",
         "SINGULAR": "SING"}


# --- independent reference: SciPy Radau on tests/_reference.py's NumPy field ---------------------


def _fk_jac(chain):
    if chain == "wrist":
        return lambda q: (wrist_fk(q), wrist_jac(q))
    return lambda q: (arm4_fk(q), arm4_jac(q))


def minjerk_gain(T, cap):
    """The time-base generator's gain γ(t) [1/s] (Morasso et al. 2010): ξ̇/(1 − ξ) of the
    minimum-jerk ξ(s) = 10 s³ − 15 s⁴ + 6 s⁵, s = t/T, capped at ``cap``; and the time of the cap."""
    def raw(t):
        s = t / T
        xi = s**3 * (10 - 15 * s + 6 * s * s)
        dxi = 30 * s * s * (1 - s) ** 2 / T
        return dxi / (1 - xi)

    t_cap = brentq(lambda t: raw(t) - cap, 1e-6 * T, T * (1 - 1e-4), xtol=1e-15)
    return (lambda t: min(raw(t), cap) if t < t_cap else cap), t_cap


def reference(p, i, ts):
    """q (len(ts), n) of movement ``i`` of problem ``p`` at times ``ts`` (increasing, from 0):
    Radau at rtol 1e-10, atol 1e-12, restarted at the gain's kinks."""
    fk_jac = _fk_jac(p["chain"])
    KJ, q_rest, W, q0, target = (np.asarray(p[k][i], float) for k in ("KJ", "q_rest", "W", "q0", "target"))
    A = np.linalg.inv(W)
    breaks = []
    if p["planner"] == "minjerk":
        gamma, t_cap = minjerk_gain(p["T"], p["cap"])
        breaks = [t_cap]

        def force(t, x, J):
            return gamma(t) * np.linalg.solve(J @ A @ J.T, target - x)
    else:
        k = p["k"]
        if k is None:  # Eq 10: k = b_max(B(q0)) / τ0 = 1 / (λ_min(J W⁻¹ Jᵀ) τ0)
            J0 = fk_jac(q0)[1]
            k = 1.0 / (np.linalg.eigvalsh(J0 @ A @ J0.T)[0] * p["tau0"])
        gain = arimoto(k, p["tau"])

        def force(t, x, J):
            return gain(t) * (target - x)

    def rhs(t, q):
        x, J = fk_jac(q)
        return pmp_field(q, force(t, x, J), fk_jac, KJ, q_rest, W, "lambda0")

    ts = np.asarray(ts, float)
    edges = [0.0] + [b for b in breaks if 0 < b < ts[-1]] + [ts[-1]]
    out, q = [], q0
    for a, b in zip(edges[:-1], edges[1:]):
        sel = ts[(ts >= a) & ((ts <= b) if b == edges[-1] else (ts < b))]
        te = np.unique(np.append(sel, b))
        sol = solve_ivp(rhs, (a, b), q, method="Radau", rtol=REF_RTOL, atol=REF_ATOL, t_eval=te)
        if not sol.success:
            raise RuntimeError(f"reference failed: {sol.message}")
        out.append(sol.y.T[np.searchsorted(te, sel)])
        q = sol.y[:, -1]
    return np.concatenate(out)[: ts.size]


# --- the problems (batches of movements) and the cases run on them --------------------------------


def spd_with_cond(rng, n, cond, trace=4.0):
    """A random SPD matrix (n, n) with condition number ``cond`` and the given trace."""
    Q, _ = np.linalg.qr(rng.normal(size=(n, n)))
    ev = np.geomspace(1.0, cond, n)
    return Q @ np.diag(trace * ev / ev.sum()) @ Q.T


def _wrist(B, KJ, q_rest, q0, target, tau0=TAU0_W, **planner):
    KJ = np.broadcast_to(KJ, (B, 3, 3)).copy()
    return dict(chain="wrist", KJ=KJ, W=tau0 * KJ, q_rest=np.broadcast_to(q_rest, (B, 3)).copy(),
                q0=np.broadcast_to(q0, (B, 3)).copy(), target=np.asarray(target, float), duration=DUR_W,
                tau0=tau0, **planner)


def _circle(B, radius, phase=0.0):
    ang = phase + np.linspace(0.0, 2 * np.pi, B, endpoint=False)
    return radius * np.stack([np.cos(ang), np.sin(ang)], axis=-1)


def figure3_problem(B=8, k=F3["k"]):
    """Figure 3: from q_rest to B targets on the π/12 circle, Arimoto k, τ = 0.08 s, W = τ0 KJ."""
    return _wrist(B, F3["KJ"], F3["q_rest"], F3["q_rest"], _circle(B, F3["radius"]), planner="arimoto", k=k,
                  tau=F3["tau"])


def wrist_edge_problem(per=4, seed=1):
    """Eq 10's gain on the wrist near the rim of its workspace (pointing 45–60° off the screen's
    normal, |x| ≈ 0.7–0.87 d; the rim is 80°): random SPD KJ (trace 4) with cond(KJ) = 1e2, 1e3,
    1e4, ``per`` movements each, random start, target and rest postures in that band."""
    rng = np.random.default_rng(seed)

    def postures(k):
        sign = rng.choice([-1.0, 1.0], k)
        return np.deg2rad(np.stack([rng.uniform(-30, 30, k), sign * rng.uniform(45, 60, k),
                                    rng.uniform(-15, 15, k)], axis=-1))

    conds = np.repeat([1e2, 1e3, 1e4], per)
    B = conds.size
    KJ = np.stack([spd_with_cond(rng, 3, c) for c in conds])
    q0, q_rest = postures(B), postures(B)
    target = np.stack([wrist_fk(q) for q in postures(B)])
    p = _wrist(B, KJ, q_rest, q0, target, planner="arimoto", k=None, tau=TAU0_W)
    p["cond"] = conds
    return p


#: Movements of benchmarks/stiff.py's B = 64 batch beyond its first 12 that fixed RODAS4 at 5 steps
#: per sample flags INACCURATE and whose Radau reference finishes within REF_TIMEOUT (17 and 50 pass
#: so close to a singular posture that it does not).
ARM_HARD = (20, 23, 26, 37, 53, 59)


def arm_problem(n=12, hard=ARM_HARD):
    """benchmarks/stiff.py's movements (the first ``n`` of its B = 256 problem, and ``hard``):
    ShoulderElbowArm, Eq 10's gain, τ = τ0 = 0.2 on normalised time [0, 1], cond(KJ) = 1e2, 1e3,
    1e4 in turn."""
    import stiff

    idx = np.array(list(range(n)) + list(hard))
    prob = {k: v[idx] for k, v in stiff.problem(256).items()}
    return dict(chain="arm", KJ=prob["KJ"], W=stiff.TAU0 * prob["KJ"], q_rest=prob["q_rest"], q0=prob["q0"],
                target=prob["target"], duration=1.0, tau0=stiff.TAU0, planner="arimoto", k=None, tau=stiff.TAU,
                cond=np.asarray([stiff.CONDS[i % 3] for i in idx]), index=idx)


def minjerk_problem(B=4, cap=200.0):
    """The time-base generator (MinimumJerkPlanner, T = 0.4 s, gain cap 200/s) on Figure 3's wrist."""
    return _wrist(B, F3["KJ"], F3["q_rest"], F3["q_rest"], _circle(B, F3["radius"], 0.3), planner="minjerk",
                  T=DUR_W, cap=cap)


def stiffening_problem(B=4):
    """A field that stiffens along the path: Eq 10's gain with a compliant pronation–supination
    joint (KJ = diag(0.01, 1.5, 2)) from near the screen's centre, where that joint hardly moves the
    hand and Eq 10's rate cond(M)/τ0 is 15/s (RK4's start check accepts dt up to 0.17 s), to
    targets 0.6 d out, where its rate k λ_max(M) reaches ~900/s (RK4 needs dt < 3 ms there)."""
    q0 = np.deg2rad([0.0, 3.0, 0.0])
    return _wrist(B, np.diag([0.01, 1.5, 2.0]), q0, q0, _circle(B, 0.6, 0.2), planner="arimoto", k=None,
                  tau=TAU0_W)


def problems(quick=False):
    return {"figure3": figure3_problem(), "wrist_edge": wrist_edge_problem(1 if quick else 4),
            "arm": arm_problem(3, ()) if quick else arm_problem(), "k1e9": figure3_problem(4, k=1e9),
            "minjerk": minjerk_problem(), "stiffening": stiffening_problem()}


def model_planner(p):
    chain = pj.Wrist() if p["chain"] == "wrist" else pj.ShoulderElbowArm()
    model = pj.Lambda0PMP(chain, KJ=p["KJ"], q_rest=p["q_rest"], W=p["W"])
    if p["planner"] == "minjerk":
        return model, pj.MinimumJerkPlanner(duration=p["T"], gain_cap=p["cap"])
    return model, pj.ArimotoPlanner(k=p["k"], tau=p["tau"], tau0=p["tau0"] if p["k"] is None else None)


def sample_times(p):
    return TS_W if p["chain"] == "wrist" else tuple(float(v) for v in np.linspace(0.0, 1.0, 50))


def estimate_cases(quick=False):
    """(problem, label, solver, dt, save): ``save`` "every" (every step), "final" or "ts" (50 samples);
    ``dt`` [s] or ("per sample", k) for k steps per sample interval, or None (adaptive)."""
    ms = 1e-3
    if quick:
        return [("figure3", "Figure 3", "rk4", 2 * ms, "every"), ("figure3", "Figure 3", "rodas4", 50 * ms, "every"),
                ("wrist_edge", "wrist edge, Eq 10", "rodas4", ("per sample", 5), "ts"),
                ("arm", "arm, Eq 10", "rodas4", ("per sample", 5), "ts"),
                ("stiffening", "stiffening path, Eq 10", "rk4", 5 * ms, "every")]
    cases = [("figure3", "Figure 3", "rk4", dt * ms, "every") for dt in (1, 2, 5)]
    cases += [("figure3", "Figure 3", "rodas4", dt * ms, "every") for dt in (5, 20, 50, 100, 200, 400)]
    cases += [("figure3", "Figure 3", "rodas4", 1.0, "final")]
    cases += [("figure3", "Figure 3", s, None, "ts") for s in ("rk4", "rodas4")]
    for key, label in (("wrist_edge", "wrist edge, Eq 10"), ("arm", "arm, Eq 10")):
        cases += [(key, label, "rodas4", ("per sample", k), "ts") for k in (2, 5, 10)]
        cases += [(key, label, "rodas4", None, "ts")]
    cases += [("k1e9", "Arimoto k = 1e9", "rk4", 1 * ms, "every")]
    cases += [("k1e9", "Arimoto k = 1e9", "rodas4", dt * ms, "every") for dt in (1, 5, 20, 100)]
    cases += [("k1e9", "Arimoto k = 1e9", "rodas4", None, "ts")]
    cases += [("minjerk", "min-jerk generator", "rk4", dt * ms, "every") for dt in (1, 5, 10)]
    cases += [("minjerk", "min-jerk generator", "rodas4", dt * ms, "every") for dt in (5, 20, 50)]
    cases += [("minjerk", "min-jerk generator", s, None, "ts") for s in ("rk4", "rodas4")]
    cases += [("stiffening", "stiffening path, Eq 10", "rk4", dt * ms, "every") for dt in (1, 2, 3, 5, 10)]
    cases += [("stiffening", "stiffening path, Eq 10", "rk4", None, "ts")]
    return cases


def _dt(p, dt):
    if isinstance(dt, tuple):
        ts = sample_times(p)
        return (ts[1] - ts[0]) / dt[1]
    return dt


def _saveat(p, save):
    return {"every": pj.SaveAt(), "final": pj.SaveAt(final=True), "ts": pj.SaveAt(ts=sample_times(p))}[save]


def run_case(p, solver, dt, save):
    """``simulate`` on problem ``p``: (t (S,), q (B, S, n), estimate (B,) [rad], status (B,), seconds),
    or the message of the ValueError it raised."""
    model, planner = model_planner(p)
    t0 = time.perf_counter()
    try:
        tr = pj.simulate(model, planner, p["q0"], p["target"], duration=p["duration"], dt=_dt(p, dt),
                         saveat=_saveat(p, save), solver=solver)
    except ValueError as e:
        return str(e)
    jax.block_until_ready(tr)
    return (np.asarray(tr.t), np.asarray(tr.q), np.asarray(tr.error_estimate), np.asarray(tr.status),
            time.perf_counter() - t0)


def references(p, times):
    """Reference q (B, len(times), n) at the sorted ``times``."""
    return np.stack([reference(p, i, times) for i in range(len(p["q0"]))])


def step_label(p, dt):
    if dt is None:
        return "adaptive"
    if isinstance(dt, tuple):
        return f"{dt[1]}/sample ({_dt(p, dt) * 1e3:.3g} ms)"
    return f"{dt * 1e3:g} ms" + (" (> T)" if dt > p["duration"] else "")


def _status_text(status):
    names, counts = np.unique([SHORT.get(STATUS[int(s)], STATUS[int(s)]) for s in status], return_counts=True)
    return ", ".join(f"{c} {n}" for n, c in sorted(zip(names, counts), key=lambda nc: -nc[1]))


def part_estimate(quick=False, only=None):
    """Every case of :func:`estimate_cases` (of the problems in ``only``, default all): per movement
    the true error (largest joint error over the saved samples against Radau) and the estimate [deg]."""
    probs = problems(quick)
    cases = [c for c in estimate_cases(quick) if not only or c[0] in only]
    runs = []
    for key, label, solver, dt, save in cases:
        out = run_case(probs[key], solver, dt, save)
        runs.append(out)
        print(f"  {label} {solver} {step_label(probs[key], dt)}: "
              + (f"refused: {out[:80]}" if isinstance(out, str) else f"{out[4]:.1f} s"), flush=True)
    refs = {}
    for key in {c[0] for c in cases}:
        ts = np.unique(np.round(np.concatenate([r[0] for c, r in zip(cases, runs) if c[0] == key
                                                and not isinstance(r, str)]), 12))
        t0 = time.perf_counter()
        refs[key] = (ts, references(probs[key], ts))
        print(f"  reference {key}: {len(probs[key]['q0'])} movements × {ts.size} times, "
              f"{time.perf_counter() - t0:.1f} s", flush=True)
    rows = []
    for (key, label, solver, dt, save), out in zip(cases, runs):
        p = probs[key]
        row = dict(problem=key, case=label, solver=solver, step=step_label(p, dt), save=save,
                   dt_s=None if dt is None else _dt(p, dt), B=len(p["q0"]))
        if isinstance(out, str):
            row.update(refused=out)
            rows.append(row)
            continue
        t, q, est, status, _ = out
        ts, ref = refs[key]
        idx = np.searchsorted(ts, np.round(t, 12))
        err = np.abs(q - ref[:, idx])
        true = np.rad2deg(np.where(np.all(np.isfinite(q), axis=(1, 2)), np.max(err, axis=(1, 2)), np.inf))
        row.update(true_deg=true.tolist(), est_deg=np.rad2deg(est).tolist(),
                   status=[STATUS[int(s)] for s in status])
        for k in ("cond", "index"):
            if k in p:
                row[k] = np.asarray(p[k]).tolist()
        rows.append(row)
    return rows


def _ratio_range(true, est):
    """min – max of estimate / true over a case's movements (``> x``: true errors below the
    reference's resolution, where the ratio is a lower bound)."""
    true, est = np.asarray(true), np.asarray(est)
    floor = true < REF_FLOOR_DEG
    r = np.where(floor, est / REF_FLOOR_DEG, est / true)
    ok = np.isfinite(r)
    if not ok.any():
        return "–"
    lo, hi = np.min(r[ok]), np.max(r[ok])
    text = f"{lo:.2g}" if np.isclose(lo, hi, rtol=0.05) else f"{lo:.2g} – {hi:.2g}"
    return ("> " + text) if floor[ok].all() else text


def _fmt(v):
    return "inf" if not np.isfinite(v) else f"{v:.1e}"


def estimate_table(rows):
    L = ["| case | solver | step | B | true error [deg] | estimate [deg] | estimate / true | status |",
         "|---|---|---|---:|---:|---:|---:|---|"]
    for r in rows:
        if "refused" in r:
            L.append(f"| {r['case']} | {r['solver']} | {r['step']} | {r['B']} | – | – | – | refused: "
                     f"{r['refused'].split(':')[0]} |")
            continue
        true, est = np.asarray(r["true_deg"]), np.asarray(r["est_deg"])
        L.append(f"| {r['case']} | {r['solver']} | {r['step']} | {r['B']} | {_fmt(np.max(true))} | "
                 f"{_fmt(np.max(est))} | {_ratio_range(true, est)} | "
                 f"{_status_text([{v: k for k, v in STATUS.items()}[s] for s in r['status']])} |")
    return "\n".join(L)


def estimate_summary(rows):
    """Per movement over every case: the range of estimate/true where neither is catastrophic,
    whether every movement with true error > FAIL_DEG is flagged (non-SUCCESSFUL), and the
    accurate (< ACCURATE_DEG) movements that are flagged."""
    ratios, missed, false_alarms, n_fail, n_acc, n, by_kind = [], [], [], 0, 0, 0, {}
    for r in rows:
        if "refused" in r:
            continue
        for i, (t, e, s) in enumerate(zip(r["true_deg"], r["est_deg"], r["status"])):
            n += 1
            where = f"{r['case']} {r['solver']} {r['step']} #{r['index'][i] if 'index' in r else i}"
            if np.isfinite(t) and REF_FLOOR_DEG <= t <= CATASTROPHIC_DEG and np.isfinite(e):
                ratios.append((e / t, where))
                kind = f"{r['solver']} {'adaptive' if r['step'] == 'adaptive' else 'fixed'}"
                by_kind.setdefault(kind, []).append(e / t)
            if t > FAIL_DEG:
                n_fail += 1
                if s == "SUCCESSFUL":
                    missed.append((where, t, e))
            if t < ACCURATE_DEG:
                n_acc += 1
                if s != "SUCCESSFUL":
                    false_alarms.append((where, t, e, s))
    rs = np.array([v for v, _ in ratios])
    lo, hi = min(ratios), max(ratios)
    return dict(movements=n, ratio_min=lo[0], ratio_min_at=lo[1], ratio_max=hi[0], ratio_max_at=hi[1],
                ratio_median=float(np.median(rs)), ratio_below_1=int(np.sum(rs < 1)), n_ratios=len(rs),
                failing=n_fail, failing_not_flagged=missed, accurate=n_acc, accurate_flagged=false_alarms,
                by_solver={k: [float(np.min(v)), float(np.median(v)), float(np.max(v)), len(v)]
                           for k, v in sorted(by_kind.items())})


def summary_text(s):
    L = [f"estimate / true over {s['n_ratios']} non-catastrophic movements (true error {REF_FLOOR_DEG:g}° to "
         f"{CATASTROPHIC_DEG:g}°): {s['ratio_min']:.2g} "
         f"({s['ratio_min_at']}) to {s['ratio_max']:.2g} ({s['ratio_max_at']}), median {s['ratio_median']:.2g}; "
         f"below 1 (underestimates): {s['ratio_below_1']}. By solver (min, median, max; movements): "
         + "; ".join(f"{k} {a:.2g}, {m:.2g}, {b:.2g} ({c})" for k, (a, m, b, c) in s["by_solver"].items()) + ".",
         f"true error > {FAIL_DEG}°: {s['failing']} movements, SUCCESSFUL among them: {len(s['failing_not_flagged'])}"
         + "".join(f"\n  missed: {w} true {t:.2g}° est {e:.2g}°" for w, t, e in s["failing_not_flagged"]),
         f"accurate (true < {ACCURATE_DEG}°): {s['accurate']} movements, flagged: {len(s['accurate_flagged'])}"
         + "".join(f"\n  flagged: {w} true {t:.2g}° est {e:.2g}° {st}" for w, t, e, st in s["accurate_flagged"])]
    return "\n".join(L)


# --- adaptive against fixed steps on the benchmark workloads --------------------------------------


def adaptive_steps(model, planner, q0, target, **kw):
    """Steps tried per movement (B,) by ``simulate(..., dt=None)``: its kernel traced again with
    ``integrate_adaptive`` wrapped to report its step counts (a ``jax.debug.callback``), the
    library untouched."""
    from pmpjax.internal import simulate_module as S

    box = []
    orig_int, orig_run = S.integrate_adaptive, S._run_adaptive

    def counted(*a, **k):
        out = orig_int(*a, **k)
        jax.debug.callback(lambda s: box.append(np.asarray(s)), out[3])
        return out

    sig = inspect.signature(S._movements_adaptive).parameters.values()
    static = [prm.name for prm in sig if prm.kind is prm.KEYWORD_ONLY]

    def movements(*a, **k):  # a new function: JAX's trace cache holds the unwrapped one
        return S._movements_adaptive(*a, **k)

    S.integrate_adaptive, S._run_adaptive = counted, jax.jit(movements, static_argnames=static)
    try:
        jax.block_until_ready(pj.simulate(model, planner, q0, target, **{**kw, "dt": None}))
    finally:
        S.integrate_adaptive, S._run_adaptive = orig_int, orig_run
    return np.concatenate(box)


def workloads(quick=False):
    """(key, name, problem, B, save, rows, n_check): benchmarks/stiff.py's arm movements (50 samples
    over normalised time [0, 1]) and benchmarks/simulate.py's Figure 3 batch (final state); rows
    (label, solver, dt, max_steps) with the fixed-step rows first."""
    import stiff

    out = []
    for B in ((16,) if quick else (64, 256)):
        prob = {k: v[:B] for k, v in stiff.problem(256).items()}
        p = dict(chain="arm", KJ=prob["KJ"], W=stiff.TAU0 * prob["KJ"], q_rest=prob["q_rest"], q0=prob["q0"],
                 target=prob["target"], duration=1.0, tau0=stiff.TAU0, planner="arimoto", k=None, tau=stiff.TAU)
        h = 1.0 / (stiff.SAMPLES - 1)
        rows = [("rodas4 ×2 (fixed)", "rodas4", h / 2, None), ("rodas4 ×5 (fixed)", "rodas4", h / 5, None),
                ("rodas4 adaptive", "rodas4", None, None), ("rodas4 adaptive, max_steps 1024", "rodas4", None, 1024),
                ("rk4 adaptive", "rk4", None, None)]
        out.append((f"arm{B}", "arm (stiff.py), 50 samples", p, B, "ts", rows, 3 if quick else 8))
    B = 100 if quick else 1000
    p = _wrist(B, F3["KJ"], F3["q_rest"], F3["q_rest"], bl.targets(B), planner="arimoto", k=F3["k"], tau=F3["tau"])
    rows = [("rk4 1 ms (fixed)", "rk4", bl.DT, None), ("rk4 adaptive", "rk4", None, None),
            ("rodas4 adaptive", "rodas4", None, None)]
    out.append(("figure3", "Figure 3 wrist (simulate.py), final", p, B, "final", rows, 3 if quick else 12))
    return out


#: Longest a reference movement may take [s] (near-singular paths take Radau minutes): skipped beyond.
REF_TIMEOUT = 30
#: Most movements added to the checked ones because some row flags them.
MAX_FLAGGED_CHECKS = 8


def _reference_or_none(p, i, ts):
    import signal

    def alarm(*_):
        raise TimeoutError

    old = signal.signal(signal.SIGALRM, alarm)
    signal.alarm(REF_TIMEOUT)
    try:
        return reference(p, i, ts)
    except TimeoutError:
        return None
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def part_adaptive(quick=False, only=None):
    """Per workload: the rows' public ``simulate`` calls, first call (compile + run) apart, then
    ``rounds`` rounds interleaved across the rows (same background load), median per row; steps per
    movement; accuracy against Radau on the first ``n_check`` movements and on the movements some
    row flags (non-SUCCESSFUL; the MAX_FLAGGED_CHECKS with the largest estimates whose reference
    finishes within REF_TIMEOUT)."""
    rounds = 2 if quick else 7
    res = []
    for key, name, p, B, save, rows, n_check in workloads(quick):
        if only and key not in only:
            continue
        model, planner = model_planner(p)
        calls, outs, first = {}, {}, {}
        for label, solver, dt, max_steps in rows:
            kw = dict(duration=p["duration"], dt=dt, saveat=_saveat(p, save), solver=solver)
            kw.update({} if max_steps is None else dict(max_steps=max_steps))

            def call(kw=kw):
                return jax.block_until_ready(pj.simulate(model, planner, p["q0"], p["target"], **kw))

            t0 = time.perf_counter()
            outs[label] = call()
            first[label] = time.perf_counter() - t0
            calls[label] = (call, kw)
            print(f"  {name} B={B} {label}: first call {first[label]:.1f} s", flush=True)
        times = {k: [] for k in calls}
        for _ in range(rounds):
            for k, (c, _) in calls.items():
                t0 = time.perf_counter()
                c()
                times[k].append(time.perf_counter() - t0)
        ts = np.asarray(outs[rows[0][0]].t)
        # Flagged movements, largest estimate (over the rows) first.
        flagged = {int(i) for o in outs.values() for i in np.flatnonzero(np.asarray(o.status) != 0) if i >= n_check}
        worst = np.nanmax(np.stack([np.nan_to_num(np.asarray(o.error_estimate), nan=np.inf) for o in outs.values()]), 0)
        flagged = sorted(flagged, key=lambda i: -worst[i])
        refs, skipped = {}, []
        for i in list(range(n_check)) + flagged:
            if len(refs) >= n_check + MAX_FLAGGED_CHECKS:
                break
            r = _reference_or_none(p, i, ts)
            if r is None:
                skipped.append(i)
            else:
                refs[i] = r
        print(f"  references: {sorted(refs)}; over {REF_TIMEOUT} s (skipped): {skipped}", flush=True)
        base = None
        for label, solver, dt, max_steps in rows:
            tr = outs[label]
            q = np.asarray(tr.q)
            errs = {i: float(np.rad2deg(np.max(np.abs(q[i] - r)))) for i, r in refs.items()
                    if np.all(np.isfinite(q[i]))}
            if dt is None:
                tried = adaptive_steps(model, planner, p["q0"], p["target"], **calls[label][1])
                steps_mean, steps_med, steps_max = float(np.mean(tried)), float(np.median(tried)), int(np.max(tried))
            else:
                steps_mean = steps_med = steps_max = round(p["duration"] / dt)
            run = float(np.median(times[label]))
            row = dict(key=key, workload=name, B=B, row=label, solver=solver, dt_s=dt, max_steps=max_steps,
                       steps_mean=steps_mean, steps_median=steps_med, steps_max=steps_max,
                       err_first_deg=max((e for i, e in errs.items() if i < n_check), default=float("nan")),
                       err_checked_deg=max(errs.values(), default=float("nan")),
                       n_checked=len(refs), n_unfinished=len(refs) - len(errs),
                       n_over_fail=sum(e > FAIL_DEG for e in errs.values()), errs_deg=errs,
                       est_max_deg=float(np.rad2deg(np.nanmax(tr.error_estimate))),
                       status=_status_text(np.asarray(tr.status)), compile_s=first[label] - run, run_s=run,
                       run_min_s=float(np.min(times[label])), per_movement_ms=1e3 * run / B)
            base = base or row
            row["vs_first"] = run / base["run_s"]
            res.append(row)
            print(f"    {label}: {run:.3f} s, steps {steps_mean:.0f}/{steps_max}, err first {row['err_first_deg']:.2g}, "
                  f"checked {row['err_checked_deg']:.2g}, {row['status']}", flush=True)
    return res


def adaptive_table(rows):
    L = ["| workload | B | solver | steps/movement (median, max) | max err, first n [deg] | max err, checked [deg] "
         "| > 0.05° of checked | status | compile [s] | run [s] | per movement [ms] | × first row |",
         "|---|---:|---|---:|---:|---:|---:|---|---:|---:|---:|---:|"]
    for r in rows:
        st = f"{r['steps_max']}" if r["dt_s"] else f"{r['steps_median']:.0f}, {r['steps_max']}"
        L.append(f"| {r['workload']} | {r['B']} | {r['row']} | {st} | {_fmt(r['err_first_deg'])} | "
                 f"{_fmt(r['err_checked_deg'])} | {r['n_over_fail']}/{r['n_checked'] - r['n_unfinished']} | "
                 f"{r['status']} | {r['compile_s']:.1f} | {r['run_s']:.3f} | {r['per_movement_ms']:.3f} | "
                 f"{r['vs_first']:.2f} |")
    return "\n".join(L)


def main_adaptive(quick, only):
    load0, t0 = _load(), time.perf_counter()
    rows = part_adaptive(quick, only)
    date = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    for r in rows:
        r.update(date=date, load=load0)
    if only and not quick:
        keep = [r for r in _previous("adaptive").get("rows", []) if r["key"] not in only and "err_first_deg" in r]
        rows = sorted(keep + rows, key=lambda r: (not r["workload"].startswith("arm"), r["B"]))
    table = adaptive_table(rows)
    load1 = _load()
    print("\n" + table)
    print(f"load {load0} -> {load1}; {bl.machine()}; jax {jax.__version__}; {time.perf_counter() - t0:.0f} s")
    if not quick:
        ratios = {f"adaptive {r['row']} / fixed, {r['workload'].split(' (')[0]} B = {r['B']}": r["vs_first"]
                  for r in rows if "adaptive" in r["row"]}
        data = dict(rows=rows, table=table, machine=bl.machine(), jax=jax.__version__, date=date,
                    dates=sorted({r["date"] for r in rows}), load=[load0, load1], ratios=ratios)
        print("wrote", _merge_json("adaptive", data))


# --- overhead of the estimate on the fixed-step path: A/B against the committed code ----------------

OVERHEAD_ROWS = (("final", 1000, "call"), ("final", 1000, "kernel"), ("final", 10_000, "call"),
                 ("final", 10_000, "kernel"), ("every step", 10_000, "call"), ("every step", 10_000, "kernel"))


def _row_key(save, B, what):
    return f"{save}, {'public call' if what == 'call' else 'kernel alone'}, B = {B}"


def overhead_server():
    """A worker on whichever pmpjax PYTHONPATH selects: prepares benchmarks/simulate.py's
    foundation rows (the public ``simulate`` call, Figure 3 wrist, RK4 1 ms, and the AOT-compiled
    kernel alone, as its ``bench_jax``; every-step saves as its ``--saves`` row), runs
    each once to compile, then runs one row per line read from stdin and answers its wall and
    process CPU time (every thread) as JSON."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("bench_simulate", os.path.join(HERE, "simulate.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.SAVES["every step"] = pj.SaveAt()  # (its bench_jax knows "final" and "every10")
    model, planner = bl.jax_problem()
    calls = {}
    for save, B, what in OVERHEAD_ROWS:
        q0, xd = bl.start_postures(B), bl.targets(B)
        if what == "kernel":
            _, compiled, args = mod.compile_run(q0, xd, save)
            calls[_row_key(save, B, what)] = lambda c=compiled, a=args: jax.block_until_ready(c(*a))
        else:
            sv = pj.SaveAt(final=True) if save == "final" else pj.SaveAt()
            calls[_row_key(save, B, what)] = lambda q0=q0, xd=xd, sv=sv: jax.block_until_ready(
                pj.simulate(model, planner, q0, xd, duration=bl.DURATION, dt=bl.DT, saveat=sv))
    first = {}
    for k, c in calls.items():
        t0 = time.perf_counter()
        c()
        first[k] = time.perf_counter() - t0
    print(json.dumps({"pmpjax": os.path.dirname(pj.__file__), "first_call_s": first}), flush=True)
    for line in sys.stdin:
        k = line.strip()
        if not k:
            break
        w0, c0 = time.perf_counter(), time.process_time()
        calls[k]()
        w1, c1 = time.perf_counter(), time.process_time()
        print(json.dumps({"wall": w1 - w0, "cpu": c1 - c0}), flush=True)


def part_overhead(base, rounds):
    """One worker process per tree (PYTHONPATH puts the tree first; the import is checked), then
    ``rounds`` rounds in which every row runs once on each side, the side going first alternating
    by round and row: both sides see the same background load, one call at a time."""
    trees = {"base": os.path.abspath(base), "new": ROOT}
    procs, info = {}, {}
    for side, tree in trees.items():
        env = {**os.environ, "PYTHONPATH": tree}
        procs[side] = subprocess.Popen([sys.executable, os.path.abspath(__file__), "--overhead-server"], env=env,
                                       cwd="/", stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        line = procs[side].stdout.readline()
        if not line:
            raise RuntimeError(f"{side} worker failed")
        info[side] = json.loads(line)
        if os.path.realpath(info[side]["pmpjax"]) != os.path.realpath(os.path.join(tree, "pmpjax")):
            raise RuntimeError(f"{side} worker imported {info[side]['pmpjax']}, not {tree}")
        print(f"  {side}: {info[side]['pmpjax']}, first calls "
              + ", ".join(f"{v:.1f}" for v in info[side]["first_call_s"].values()) + " s", flush=True)
    times = {k: {"base": [], "new": []} for k in (_row_key(*r) for r in OVERHEAD_ROWS)}
    loads = [_load()]
    try:
        for i in range(rounds):
            for j, k in enumerate(times):
                for side in (("base", "new") if (i + j) % 2 == 0 else ("new", "base")):
                    procs[side].stdin.write(k + "\n")
                    procs[side].stdin.flush()
                    times[k][side].append(json.loads(procs[side].stdout.readline()))
            loads.append(_load())
            print(f"  round {i}: load {loads[-1]}", flush=True)
    finally:
        for p in procs.values():
            p.stdin.close()
            p.wait()
    return dict(times=times, info=info, loads=loads)


def overhead_table(res):
    L = ["| row (Figure 3 wrist, RK4 1 ms) | base [ms] | new [ms] | new / base, wall | new / base, CPU |",
         "|---|---:|---:|---:|---:|"]
    ratios = {}
    for k, t in res["times"].items():
        b, n = ({c: np.array([x[c] for x in t[side]]) for c in ("wall", "cpu")} for side in ("base", "new"))
        rw, rc = n["wall"] / b["wall"], n["cpu"] / b["cpu"]
        ratios[f"estimate overhead (new / base wall), {k}"] = float(np.median(rw))
        L.append(f"| {k} | {np.median(b['wall']) * 1e3:.0f} | {np.median(n['wall']) * 1e3:.0f} | "
                 f"{np.median(rw):.3f} ({np.percentile(rw, 25):.2f}–{np.percentile(rw, 75):.2f}) | "
                 f"{np.median(rc):.3f} ({np.percentile(rc, 25):.2f}–{np.percentile(rc, 75):.2f}) |")
    return "\n".join(L), ratios


def main_overhead(base, rounds, quick=False):
    t0 = time.perf_counter()
    res = part_overhead(base, rounds)
    table, ratios = overhead_table(res)
    n = len(next(iter(res["times"].values()))["base"])
    print("\n" + table + f"\n{n} rounds; load {min(res['loads'])}–{max(res['loads'])}; {bl.machine()}; "
          f"jax {jax.__version__}; {time.perf_counter() - t0:.0f} s")
    if not quick:
        data = dict(res, table=table, ratios=ratios, machine=bl.machine(), jax=jax.__version__, base=base,
                    date=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()))
        print("wrote", _merge_json("overhead", data))

# --- main ---------------------------------------------------------------------------------------


def _load():
    return round(os.getloadavg()[0], 2)


def _merge_json(section, data):
    """Write ``data`` as ``section`` of results/accuracy.json, keeping the other sections."""
    default = os.path.join(HERE, "results")
    path = os.path.join(os.environ.get("PMPJAX_BENCH_RESULTS") or default, "accuracy.json")
    res = {}
    if os.path.exists(path):
        with open(path) as f:
            res = json.load(f)
    res[section] = data
    res["ratios"] = {k: v for sec in ("estimate", "adaptive", "overhead") for k, v in res.get(sec, {}).get("ratios", {}).items()}
    return bl.write_results("accuracy", res)


def _previous(section):
    path = os.path.join(os.environ.get("PMPJAX_BENCH_RESULTS") or os.path.join(HERE, "results"), "accuracy.json")
    if not os.path.exists(path):
        return {}
    with open(path) as f:
        return json.load(f).get(section, {})


def main_estimate(quick, only):
    load0, t0 = _load(), time.perf_counter()
    rows = part_estimate(quick, only)
    date = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    for r in rows:
        r.update(date=date, load=load0)
    if only and not quick:  # keep the other problems' rows of an earlier run
        order = [c[0] for c in estimate_cases()]
        keep = [r for r in _previous("estimate").get("rows", []) if r["problem"] not in only]
        rows = sorted(keep + rows, key=lambda r: order.index(r["problem"]))
    table = estimate_table(rows)
    summ = estimate_summary(rows)
    text = summary_text(summ)
    load1 = _load()
    print("\n" + table + "\n\n" + text)
    print(f"load {load0} -> {load1}; {bl.machine()}; jax {jax.__version__}; {time.perf_counter() - t0:.0f} s")
    if not quick:
        data = dict(rows=rows, summary=summ, table=table, text=text, machine=bl.machine(), jax=jax.__version__,
                    date=date, load=[load0, load1], dates=sorted({r["date"] for r in rows}),
                    ratios={"estimate_over_true_min": summ["ratio_min"], "estimate_over_true_max": summ["ratio_max"]})
        print("wrote", _merge_json("estimate", data))


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("parts", nargs="*", help="of estimate, adaptive, overhead (default: estimate and adaptive; "
                    "overhead needs --base)")
    ap.add_argument("--quick", action="store_true", help="smoke run; writes nothing")
    ap.add_argument("--only", nargs="+", choices=["figure3", "wrist_edge", "arm", "k1e9", "minjerk", "stiffening",
                                                  "arm64", "arm256"],
                    help="run these problems (estimate: figure3 ... stiffening; adaptive: arm64, arm256, figure3) "
                    "only; the others' rows are kept from the JSON")
    ap.add_argument("--base", help="overhead: a work tree of the code to compare with (e.g. `git worktree add "
                    "/tmp/pmpjax-base <commit>` of a commit without the error estimate)")
    ap.add_argument("--rounds", type=int, default=12, help="overhead: interleaved rounds (default 12)")
    ap.add_argument("--overhead-server", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.overhead_server:
        overhead_server()
        sys.exit(0)
    parts = a.parts or ["estimate", "adaptive"]
    if set(parts) - {"estimate", "adaptive", "overhead"}:
        ap.error(f"unknown part(s) {sorted(set(parts) - {'estimate', 'adaptive', 'overhead'})}")
    if "estimate" in parts:
        main_estimate(a.quick, a.only)
    if "adaptive" in parts:
        main_adaptive(a.quick, a.only)
    if "overhead" in parts:
        if not a.base:
            ap.error("overhead needs --base (a work tree of the code to compare with)")
        main_overhead(a.base, 2 if a.quick else a.rounds, a.quick)
