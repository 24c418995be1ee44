"""``pmpjax simulate CONFIG``: run the simulation a TOML or JSON file describes (the format:
``pmpjax._data.simulation_config``) and write its trajectories, paths and summary."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._base import output_dir, write_json
from .._data import CONFIG_HELP, ConfigError, build_simulation, read_config
from .text import example_help, plain, plural


def run_simulation_config(path, out) -> dict:
    """Run ``pmpjax simulate CONFIG``: writes ``trajectories.csv``, ``paths.png``, ``summary.json``."""
    import matplotlib.pyplot as plt

    import pmpjax as pj

    cfg = read_config(path)
    model, planner, q0, targets, opt = build_simulation(cfg, path)
    out = Path(out)
    out = output_dir("--out", out)
    try:
        traj = pj.simulate(model, planner, np.broadcast_to(q0, (len(targets), q0.shape[0])), targets,
                           duration=opt["duration"], dt=opt["dt"], saveat=pj.SaveAt(every=opt["every"]),
                           reach_tol=opt["reach_tol"])
    except ValueError as e:
        raise ConfigError(f"{path}: {e}") from None
    t, q, x = (np.asarray(a) for a in (traj.t, traj.q, traj.x))
    # Columns numbered from 1 with their units, as the configuration names them (targets [[x1, x2], ...] [m]).
    rows = [",".join(["target", "t [s]", *(f"q{i + 1} [rad]" for i in range(q.shape[-1])),
                      *(f"x{i + 1} [m]" for i in range(x.shape[-1]))])]
    for b, name in enumerate(opt["names"]):
        for s in range(t.shape[0]):
            rows.append(",".join([name, f"{t[s]:.6g}", *(f"{v + 0.0:.9g}" for v in q[b, s]),  # (+ 0.0: no "-0")
                                  *(f"{v + 0.0:.9g}" for v in x[b, s])]))
    (out / "trajectories.csv").write_text("\n".join(rows) + "\n")
    fig, ax = plt.subplots(figsize=(5, 5))
    for b, name in enumerate(opt["names"]):
        ax.plot(x[b, :, 0], x[b, :, 1], "-")
        ax.plot(*targets[b], "k+")
        ax.annotate(name, targets[b], fontsize=8)
    ax.set_aspect("equal")
    ax.set_xlabel("x1 [m]")
    ax.set_ylabel("x2 [m]")
    fig.savefig(out / "paths.png", dpi=110)
    plt.close(fig)
    summary = {
        "targets": opt["names"],
        "final_task_error": np.linalg.norm(x[:, -1] - targets, axis=-1).tolist(),
        "final_q": q[:, -1].tolist(),
        "status": [pj.status_message(int(s)) for s in np.asarray(traj.status).reshape(-1)],
    }
    write_json(out / "summary.json", summary, indent=2)
    return summary


def add_simulate_command(sub) -> None:
    p = sub.add_parser("simulate", help="simulate movements described in a TOML/JSON file",
                       description=plain(CONFIG_HELP), epilog=example_help("simulate_figure3.toml"),
                       formatter_class=__import__("argparse").RawDescriptionHelpFormatter)
    p.add_argument("config", help="TOML or JSON configuration file")
    p.add_argument("--out", default="out_simulate", help="output folder (default out_simulate)")

    def run(args) -> int:
        import jax

        from .._base import Status

        jax.config.update("jax_enable_x64", True)
        s = run_simulation_config(args.config, args.out)
        failed = sum(status != Status.SUCCESSFUL.message for status in s["status"])
        print(f"{plural(len(s['targets']), 'movement')}, max final task error {max(s['final_task_error']):.2e}"
              + (f", {failed} not successful (summary.json says why)" if failed else "")
              + f"; wrote {Path(args.out) / 'trajectories.csv'}, paths.png, summary.json")
        return 1 if failed else 0

    p.set_defaults(func=run)
