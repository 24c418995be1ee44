"""Command line: ``python -m pmpjax [--out DIR]`` runs the main job on the embedded defaults."""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path


def _figure3(out: Path, log) -> dict:
    from ._figure3 import figure3_data, plot_figure3

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


JOBS = {"figure3": _figure3}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="pmpjax", description=__doc__)
    parser.add_argument("--out", default="out", help="output folder (created)")
    parser.add_argument("--jobs", nargs="*", default=list(JOBS), choices=list(JOBS),
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
        results[name] = JOBS[name](out, print)
        # Written after every part so an interruption loses nothing already computed.
        results_path.write_text(json.dumps(results, indent=2))
    print(f"results -> {results_path}")
    return 0
