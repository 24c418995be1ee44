"""Built-in main-job parts: Figure 3 of Tommasino & Campolo (2017) and Figure 4 of Williamson (1996)."""

from __future__ import annotations

from .parts import Part, PartContext


def _figure3(ctx: PartContext) -> dict:
    """Figure 3 of Tommasino & Campolo (2017): λ0-PMP center-out paths, speeds and curvature."""
    import numpy as np

    from .._wrist import figure3_data, plot_figure3

    data = figure3_data()
    ends = np.stack([data["targets"], np.zeros_like(data["targets"])], axis=1)
    final_err = float(abs(data["x"][:, :, -1] - ends).max())
    ctx.figure(plot_figure3(data), "figure3.png",
               "λ0-PMP center-out movements of the Figure 3 model (KJ = diag(0.5, 1.5, 2), τ = τ0 = 80 ms, "
               "k = 22.5): screen paths out and back, speed profiles and joint trajectories.",
               "Paper Figure 3: curved paths for diagonal targets, straight cardinal ones, bell-shaped speeds.")
    rows = [{"target": d, "A_net_out": float(data["A_net"][i, 0]), "A_net_in": float(data["A_net"][i, 1]),
             "A_hyst": float(data["A_hyst"][i]), "peak_speed_m_per_s": float(data["speed"][i].max())}
            for i, d in enumerate(data["directions"])]
    ctx.table(rows, "figure3_curvature.csv",
              "Curvature (A_net, normalised by (π/12)²) and hysteresis of the Figure 3 movements per target.",
              "Paper Figure 3A: diagonal paths curve, cardinal ones do not.")
    ctx.log(f"final task error {final_err:.2e} m")
    return {
        "parameters": {k: (v.tolist() if hasattr(v, "tolist") else v) for k, v in data["params"].items()},
        "max_final_task_error_m": final_err,
        "peak_speed_m_per_s": {d: float(data["speed"][i].max()) for i, d in enumerate(data["directions"])},
        "A_net_out": dict(zip(data["directions"], data["A_net"][:, 0].round(5).tolist())),
        "A_net_in": dict(zip(data["directions"], data["A_net"][:, 1].round(5).tolist())),
        "A_hyst": dict(zip(data["directions"], data["A_hyst"].round(5).tolist())),
        "all_ok": bool((data["status"] == 0).all()),
    }


def _figure4(ctx: PartContext) -> dict:
    """Williamson (1996) Figure 4: two overlapping minimum-jerk set-point moves are summed."""
    import numpy as np

    from .._springy_arm import moves_from_targets, plot_summed_moves, summed_moves

    # A move 0 → 1 (1 s) with a second move to 1.5 issued half-way.
    moves = moves_from_targets(np.zeros(1), np.array([[1.0], [1.5]]), np.array([0.0, 0.5]), 1.0)
    t = np.linspace(0.0, 2.0, 401)
    p, v = (np.asarray(a) for a in summed_moves(moves, np.zeros(1), t))
    ctx.figure(plot_summed_moves(moves, np.zeros(1), t), "figure4_summed_moves.png",
               "Set-point position and velocity of a move 0 → 1 (1 s) with a second move to 1.5 issued "
               "at 0.5 s: the velocities add, the set-point ends at 1.5 without a jump.",
               "Williamson (1996) Figure 4: summed minimum-jerk moves.")
    ctx.log(f"final set-point {p[-1, 0]:.6f}")
    return {"final_set_point": float(p[-1, 0]), "peak_velocity": float(v[:, 0].max()),
            "velocity_jump_max": float(np.abs(np.diff(v[:, 0])).max())}


figure3 = Part(_figure3, seconds=2, seconds_full=2, order=0,
               title="λ0-PMP center-out movements (Tommasino & Campolo Figure 3)")
figure4 = Part(_figure4, seconds=1, seconds_full=1, order=80,
               title="Summed minimum-jerk set-point moves (Williamson Figure 4)")
