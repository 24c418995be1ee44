"""The library's figures on small synthetic inputs: every title and legend lies inside its figure
(what ``savefig`` keeps), and no legend lies over bars, arrows, lines or labels, measured with
matplotlib's renderer (``tests/_layout.py``). The main job's figures are checked the same way
where their parts run (test_main_job_parts.py, test_primitives_part.py, test_cli.py)."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from _layout import covering_problems, layout_problems, outside_problems  # noqa: E402

import fitting  # noqa: E402
import pmpjax as pj  # noqa: E402
from fitting._sweep.examples import plot_curvature_map  # noqa: E402


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def test_a_clipped_title_and_a_legend_over_the_data_are_found():
    """The checks themselves: a title wider than its figure, a legend hanging off the right edge
    and a legend drawn over a line are found; the same figure laid out properly passes."""
    fig, ax = plt.subplots(figsize=(3, 2))
    ax.plot([0, 1], [0, 1], lw=4, label="a thick diagonal line")
    ax.set_title("a title far too long to fit into a figure three inches wide")
    ax.legend(loc="center")
    problems = layout_problems(fig)
    assert any("title" in p and "beyond" in p for p in problems), problems
    assert any("legend" in p and "drawn pixels" in p for p in problems), problems
    ax.set_title("short")
    ax.legend(loc="upper left", bbox_to_anchor=(0.9, 1.0))
    assert any("legend" in p and "beyond" in p for p in outside_problems(fig))
    ax.legend(loc="lower center", bbox_to_anchor=(0.5, 1.0), frameon=False)
    assert any("legend" in p and "drawn pixels" in p for p in covering_problems(fig))  # over the title
    ax.set_title("")
    fig.suptitle("short")
    fig.set_layout_engine("constrained")
    assert layout_problems(fig) == []


def test_ik_weights_of_two_conditions_with_a_title():
    """The ik_synthetic part's figure: one panel, two conditions, weights up to 1 (the top of the
    axes, where the legend used to sit), a long title."""
    w = np.array([[[0.15, 0.55, 1.0, 0.3], [0.3, 1.0, 0.7, 0.25]]])
    fig = fitting.plot_ik_weights(w, 0.9 * w, np.minimum(1.1 * w, 1.0), groups=["Natural", "Viscous"],
                                  panels=["6 synthetic participants"],
                                  title="Synthetic Experiment 1: IK weights per condition (mean, 95 % range)")
    assert layout_problems(fig) == []


def test_ik_weights_of_four_subjects_and_tasks():
    """The ik_hugmp part's figure: four panels (subjects) × four tasks with intervals."""
    rng = np.random.default_rng(0)
    w = rng.uniform(0.1, 1.0, (4, 4, 4))
    w[..., 3] = 1.0
    fig = fitting.plot_ik_weights(w, w - 0.1, np.minimum(w + 0.1, 1.0), panels=["S01", "S02", "S03", "S04"],
                                  groups=[f"task {k + 1}" for k in range(4)])
    assert layout_problems(fig) == []


def test_curvature_map():
    a = np.linspace(-0.2, 0.3, 3 * 4 * 8).reshape(3, 4, 8)
    fig = plot_curvature_map(np.array([0.5, 1.0, 2.0]), np.linspace(-15, 15, 4), a)
    assert layout_problems(fig) == []
    assert fig.axes[0].get_ylabel() == "K_RUD / K_FE"


def test_force_field_legend_hides_no_arrow(free_arm, P):
    chain = pj.MjcfChain(free_arm, "hand")
    fig = pj.plot_force_field(chain, P[1], free_arm.K, n=5)
    assert covering_problems(fig) == [] and outside_problems(fig) == []


def test_summed_moves_and_reflex_traces():
    mv = pj.moves_from_targets([0.0], [[1.0], [0.4]], t0=[0.0, 0.5], duration=1.0)
    t = np.linspace(0.0, 2.0, 81)
    assert layout_problems(pj.plot_summed_moves(mv, [0.0], t)) == []
    T, n = 50, 6
    tt = np.linspace(0.0, 1.0, T)
    ramp = np.outer(np.clip(2 * tt - 0.5, 0, 1), np.ones(n))
    traj = pj.ArmTrajectory(t=tt, q=0.9 * ramp, qdot=np.gradient(ramp, tt, axis=0), q_set=ramp, tau=ramp - 0.9 * ramp,
                            touch=np.stack([np.sin(3 * tt) ** 2, 0 * tt], 1), hand=np.zeros((T, 3)),
                            q_final=ramp[-1], qdot_final=0 * ramp[-1], log={"tau_ref": 0.05 * ramp})
    for sensor in ("palm", "torque"):
        fig = pj.plot_reflex(traj, sensor=sensor, title="grasp reflex: the hand closes on touch")
        assert layout_problems(fig) == [], sensor


def test_figure3_panels():
    """Figure 3's three panels on paths shaped like the model's (curved out, back in)."""
    d = list(pj.DIRECTIONS)
    targets = np.stack([pj.center_out_targets()[k] for k in d])
    s = np.linspace(0.0, 1.0, 21)
    bend = 0.1 * np.sin(np.pi * s)[None, :, None] * targets[:, None, ::-1] * [1, -1]
    out = s[None, :, None] * targets[:, None] + bend  # (8, S, 2)
    x = np.stack([out, out[:, ::-1]], 1)  # (8, 2, S, 2)
    q = np.repeat(x[..., :1], 3, -1) * [1.0, 0.5, 0.2]
    speed = np.linalg.norm(np.gradient(x, axis=2), axis=-1) * 50
    data = dict(t=s * 0.4, x=x, q=q, speed=speed, targets=targets, directions=d, params={"duration": 0.4})
    assert layout_problems(pj.plot_figure3(data)) == []


def test_donders_plot():
    """The 3-D Donders plot: its legend and labels inside the figure (the panes are not a white
    background, so only the outside check applies)."""
    rng = np.random.default_rng(1)
    r = rng.normal(0.0, 0.1, (60, 3)) * [0.1, 1, 1]
    ax = pj.plot_donders(r, [np.array([0.0, 0.0, 0.0, 0.1, 0.0, -0.1])], labels=["fitted surface"])
    assert outside_problems(ax.figure) == []


def test_movement_parameter_table():
    """``plot_movement_parameters`` of a one-subject fit (the --quick movements part's): its
    two-line title inside the figure (one line ran off both sides)."""
    import dataclasses

    names = ("KJ_chol_00", "KJ_chol_10", "KJ_chol_11", "q_rest[shoulder_abduction]", "q_rest[elbow_flexion]",
             "log_tau", "log_tau0", "delay")  # (long row labels push the table right)
    values = dict.fromkeys(f.name for f in dataclasses.fields(fitting.MovementFit))
    values.update(subjects=("S1",), param_names=names, params=np.linspace(-1.0, 1.0, 8)[None],
                  stderr=np.full((1, 8), 0.01), unidentified=((names[3:5],),), model="lambda0",
                  damping="tau0_KJ", time_constants="seconds")
    assert layout_problems(fitting.plot_movement_parameters(fitting.MovementFit(**values))) == []
