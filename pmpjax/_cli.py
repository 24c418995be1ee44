"""Command line: ``python -m pmpjax [--out DIR] [--jobs ...]`` runs the main job on the embedded
defaults: Figure 3 (λ0-PMP), Figure 4 (summed set-point moves), and every job registered by
installed packages under the ``pmpjax.jobs`` entry-point group (``fitting`` registers the
Donders/NIO fits and the IK weights of the bundled HuG-MP recordings). Plugins keep ``pmpjax``
free of imports of ``fitting``. Each job is ``job(out: Path, log) -> dict`` (JSON-able).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path


def _figure3(out: Path, log) -> dict:
    from ._wrist.figure3 import figure3_data, plot_figure3

    t0 = time.perf_counter()
    data = figure3_data()
    fig = plot_figure3(data)
    fig.savefig(out / "figure3.png", dpi=120)
    final_err = float(abs(data["x"][:, :, -1] - _ends(data)).max())
    res = {
        "parameters": {k: (v.tolist() if hasattr(v, "tolist") else v) for k, v in data["params"].items()},
        "max_final_task_error_m": final_err,
        "peak_speed_m_per_s": {d: float(data["speed"][i].max()) for i, d in enumerate(data["directions"])},
        "A_net_out": dict(zip(data["directions"], data["A_net"][:, 0].round(5).tolist())),
        "A_net_in": dict(zip(data["directions"], data["A_net"][:, 1].round(5).tolist())),
        "A_hyst": dict(zip(data["directions"], data["A_hyst"].round(5).tolist())),
        "all_ok": bool((data["status"] == 0).all()),
        "seconds": round(time.perf_counter() - t0, 2),
    }
    log(f"figure3: final task error {final_err:.2e} m, figure -> {out / 'figure3.png'}")
    return res


def _ends(data):
    import numpy as np

    return np.stack([data["targets"], np.zeros_like(data["targets"])], axis=1)


def _figure4(out: Path, log) -> dict:
    import numpy as np

    from ._springy_arm.plots import plot_summed_moves
    from ._springy_arm.primitives import moves_from_targets, summed_moves

    # Williamson's Figure 4: a move 0 → 1 (1 s) with a second move to 1.5 issued half-way.
    moves = moves_from_targets(np.zeros(1), np.array([[1.0], [1.5]]), np.array([0.0, 0.5]), 1.0)
    t = np.linspace(0.0, 2.0, 401)
    p, v = (np.asarray(a) for a in summed_moves(moves, np.zeros(1), t))
    plot_summed_moves(moves, np.zeros(1), t).savefig(out / "figure4_summed_moves.png", dpi=120)
    log(f"figure4: final set-point {p[-1, 0]:.6f}, figure -> {out / 'figure4_summed_moves.png'}")
    return {"final_set_point": float(p[-1, 0]), "peak_velocity": float(v[:, 0].max()),
            "velocity_jump_max": float(np.abs(np.diff(v[:, 0])).max())}


def _jobs() -> dict:
    """Built-in jobs, then entry points of the ``pmpjax.jobs`` group, in registration order."""
    from importlib.metadata import entry_points

    jobs = {"figure3": _figure3, "figure4": _figure4}
    for ep in sorted(entry_points(group="pmpjax.jobs"), key=lambda e: e.name):
        jobs.setdefault(ep.name, ep)
    return jobs


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="pmpjax", description=__doc__)
    parser.add_argument("--out", default="out", help="output folder (created)")
    jobs = _jobs()
    parser.add_argument("--jobs", nargs="*", default=list(jobs), choices=list(jobs),
                        help="which parts of the main job to run (default: all)")
    args = parser.parse_args(argv)
    os.environ.setdefault("MPLBACKEND", "Agg")
    import jax

    jax.config.update("jax_enable_x64", True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results_path = out / "results.json"
    results = json.loads(results_path.read_text()) if results_path.exists() else {}
    for name in args.jobs:
        job = jobs[name]
        job = job.load() if hasattr(job, "load") else job
        t0 = time.perf_counter()
        results[name] = job(out, print)
        results[name].setdefault("seconds", round(time.perf_counter() - t0, 2))
        # Written after every part so an interruption loses nothing already computed.
        results_path.write_text(json.dumps(results, indent=2))
    print(f"results -> {results_path}")
    return 0
