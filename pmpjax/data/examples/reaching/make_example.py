"""Regenerate the synthetic reaching example in this folder (see README.md).

    python pmpjax/data/examples/reaching/make_example.py

Two subjects × two continuous trials of six reaches (out to a target and back home, three times)
of the 5-joint arm ``../arm5.xml``, simulated by pmpjax's λ0-PMP (``pj.simulate``, RK4,
``dt`` = 0.5 ms) with the Arimoto planner and Eq 10's gain at each reach's start, ``W = τ0 KJ``
(Eq 7), sampled at 100 Hz, with 0.2° Gaussian noise on the joints. Seeded: a rerun rewrites the
same bytes. Writes ``S<s>_trial<t>.mot`` (degrees), ``S1_trial1.sto`` (radians) and
``S1_trial1.csv`` (degrees, ``_deg`` columns) copies of one trial, ``targets.csv`` (when each
target appears, and where) and ``truth.json`` (the parameters).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import pmpjax as pj  # noqa: E402

HERE = Path(__file__).resolve().parent
ARM = HERE.parent / "arm5.xml"
FS = 100.0  # [Hz]
DT = 5e-4  # [s] RK4 step
NOISE_DEG = 0.2  # [deg] per joint and sample
LEAD = 0.5  # [s] at rest at home before the first target appears
SEED = 2027
N_TRIALS, N_OUT = 2, 3  # trials per subject; out-and-back pairs per trial
HOLD = (1.0, 1.4)  # [s] range of each reach's duration (the next target appears after it)
X_HOME = (0.35, 0.0, -0.15)  # [m] home (start) position of the hand, shoulder at the origin
REACH = (0.10, 0.15)  # [m] range of target distances from home

# The truth: full, anisotropic stiffness (trace 5 Nm/rad), rest posture, time constants.
SUBJECTS = {
    "S1": {
        "KJ": [[0.689, -0.218, -0.014, -0.136, 0.052],
               [-0.218, 1.344, 0.415, 0.285, 0.242],
               [-0.014, 0.415, 0.529, 0.052, 0.236],
               [-0.136, 0.285, 0.052, 1.564, 0.603],
               [0.052, 0.242, 0.236, 0.603, 0.874]],
        "q_rest_deg": [20.0, 15.0, 20.0, 75.0, 0.0],
        "tau0": 0.10,
        "tau": 0.10,
    },
    "S2": {
        "KJ": [[0.759, 0.305, -0.228, 0.053, 0.416],
               [0.305, 1.642, -0.332, 0.898, 0.206],
               [-0.228, -0.332, 0.769, -0.202, -0.046],
               [0.053, 0.898, -0.202, 0.862, -0.143],
               [0.416, 0.206, -0.046, -0.143, 0.968]],
        "q_rest_deg": [30.0, 10.0, 30.0, 60.0, 10.0],
        "tau0": 0.12,
        "tau": 0.09,
    },
}


def targets_and_holds(rng):
    """Targets (2 N_OUT, 3) (out, home, out, home, ...) and reach durations (2 N_OUT,) [s] on the
    sampling clock."""
    home = np.asarray(X_HOME)
    out = []
    while len(out) < N_OUT:
        u = rng.standard_normal(3)
        u /= np.linalg.norm(u)
        x = home + rng.uniform(*REACH) * u
        if x[0] >= 0.28 and np.linalg.norm(x) <= 0.52:  # in front of the shoulder, elbow bent
            out.append(x)
    targets = np.stack([p for x in out for p in (x, home)])
    holds = rng.integers(round(HOLD[0] * FS), round(HOLD[1] * FS) + 1, size=2 * N_OUT) / FS
    return targets, holds


def simulate_trial(chain, p, q_home, targets, holds):
    """Noise-free (T, n) joint angles [rad] at 1/FS: LEAD at rest at ``q_home``, then one
    λ0-PMP reach per target, each from where the last one ended (planner time reset, Eq 10)."""
    KJ, q_rest = np.asarray(p["KJ"]), np.deg2rad(p["q_rest_deg"])
    model = pj.Lambda0PMP(chain, KJ=KJ, q_rest=q_rest, W=pj.damping_from_stiffness(KJ, p["tau0"]))
    planner = pj.ArimotoPlanner(k=None, tau=p["tau"], tau0=p["tau0"])
    every = round(1.0 / (FS * DT))
    parts, q = [np.tile(q_home, (round(LEAD * FS), 1))], np.asarray(q_home)
    for target, hold in zip(targets, holds):
        tr = pj.simulate(model, planner, q, target, duration=HOLD[1], dt=DT, saveat=pj.SaveAt(every=every))
        if not bool(tr.ok):
            raise RuntimeError(f"simulation failed: {pj.Status(int(tr.status)).name}")
        qs = np.asarray(tr.q)[: round(hold * FS) + 1]
        parts.append(qs[:-1])
        q = qs[-1]
    parts.append(q[None])
    return np.concatenate(parts)


def _rows(t, q, fmt, sep):
    return "".join(sep.join([f"{a:.2f}", *(fmt % v for v in row)]) + "\n" for a, row in zip(t, q))


def write_opensim(path, name, t, q, names, degrees):
    vals, fmt = (np.rad2deg(q), "%.6f") if degrees else (q, "%.10f")
    header = (f"{name}\nversion=1\nnRows={t.size}\nnColumns={q.shape[1] + 1}\n"
              f"inDegrees={'yes' if degrees else 'no'}\nendheader\n")
    path.write_text(header + "\t".join(["time", *names]) + "\n" + _rows(t, vals, fmt, "\t"), encoding="utf-8")


def write_csv(path, t, q, names):
    head = ",".join(["time", *(f"{s}_deg" for s in names)]) + "\n"
    path.write_text(head + _rows(t, np.rad2deg(q), "%.6f", ","), encoding="utf-8")


def main():
    chain = pj.MjcfChain(ARM, "hand")
    names = chain.joint_names
    truth = {"chain": "../arm5.xml, site 'hand'", "joint_names": list(names), "fs": FS, "noise_deg": NOISE_DEG,
             "lead": LEAD, "x_home": list(X_HOME), "dt": DT, "solver": "rk4", "subjects": {}}
    events = ["subject,trial,reach,t_on,t_off,x,y,z"]
    for s, (subject, p) in enumerate(SUBJECTS.items()):
        eq = pj.equilibrium_posture(chain, np.asarray(p["KJ"]), np.deg2rad(p["q_rest_deg"]), np.asarray(X_HOME))
        if not bool(eq.converged):
            raise RuntimeError(f"{subject}: no equilibrium posture at home")
        q_home = np.asarray(eq.q)
        truth["subjects"][subject] = {**p, "W": "tau0 * KJ", "q_home_deg": np.rad2deg(q_home).round(6).tolist()}
        for trial in range(1, N_TRIALS + 1):
            rng = np.random.default_rng([SEED, s, trial])
            targets, holds = targets_and_holds(rng)
            q = simulate_trial(chain, p, q_home, targets, holds)
            q = q + np.deg2rad(NOISE_DEG) * rng.standard_normal(q.shape)
            t = np.arange(q.shape[0]) / FS
            name = f"{subject}_trial{trial}"
            label = f"{name} (synthetic: pmpjax lambda0-PMP simulation, see README.md)"
            write_opensim(HERE / f"{name}.mot", label, t, q, names, degrees=True)
            if (subject, trial) == ("S1", 1):
                write_opensim(HERE / f"{name}.sto", label, t, q, names, degrees=False)
                write_csv(HERE / f"{name}.csv", t, q, names)
            t_on = LEAD + np.concatenate([[0.0], np.cumsum(holds)[:-1]])
            for k, (a, h, x) in enumerate(zip(t_on, holds, targets), 1):
                events.append(f"{subject},{trial},{k},{a:.2f},{a + h:.2f},{x[0]:.6f},{x[1]:.6f},{x[2]:.6f}")
    (HERE / "targets.csv").write_text("\n".join(events) + "\n", encoding="utf-8")
    text = json.dumps(truth, indent=1)  # (then each innermost list on one line)
    text = re.sub(r"\[([^\[\]{}]*)\]", lambda m: "[" + ", ".join(v.strip() for v in m.group(1).split(",")) + "]", text)
    (HERE / "truth.json").write_text(text + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
