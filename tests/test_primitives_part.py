"""The ``primitives`` main-job part (Williamson 1996 beyond Figure 4) at its ``--quick`` size: it runs,
writes valid artefacts, and its equilibria balance springs against gravity as C MuJoCo computes it."""

import csv

import mujoco
import numpy as np
import pytest
from _layout import checking_part_figures

import pmpjax as pj
from pmpjax._app import cli
from pmpjax._springy_arm.primitives import PRIMITIVES

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
#: Layout problems of each figure the part records (filled by the ``run`` fixture).
LAYOUT: dict[str, list[str]] = {}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("primitives")
    with checking_part_figures() as layout:
        res = cli.reproduce(out, quick=True, only=["primitives"], progress=False, cache=False)
    LAYOUT.update(layout)
    return out, res["primitives"]


def test_figures_keep_their_titles_and_legends_inside_and_off_the_data(run):
    """Blends, force field (its legend used to hide arrows), reflex traces: every title and
    legend inside the figure, none over what the figure draws."""
    assert "primitives_force_field.png" in LAYOUT and len(LAYOUT) >= 4
    assert {name: problems for name, problems in LAYOUT.items() if problems} == {}


def rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def test_part_writes_valid_artefacts_with_captions(run):
    out, entry = run
    assert entry["status"] == "ok", entry.get("error")
    names = {a["path"] for a in entry["artefacts"]}
    assert names == {"primitives_equilibria.csv", "primitives_blends.png", "primitives_force_field.png",
                     "primitives_grasp.png", "primitives_withdrawal.png", "primitives_lead.png",
                     "primitives_reflexes.csv"}
    for a in entry["artefacts"]:
        data = (out / a["path"]).read_bytes()
        assert len(data) > 1000 if a["kind"] == "figure" else len(data) > 0
        assert a["caption"] and "Williamson (1996)" in a["paper"]
        if a["kind"] == "figure":
            assert data[:8] == PNG_MAGIC
        else:
            assert len(rows(out / a["path"])) >= 2
    assert "primitives" in (out / "report.md").read_text()


def test_blended_equilibrium_balances_c_mujoco_gravity_and_springs(run):
    """Every equilibrium of the table: the set-point is Σ α_i P_i (the paper's primitives) or the
    winning primitive; at q_eq the spring torque −K (q − θ_set) cancels C MuJoCo's gravity torque
    (``qfrc_bias`` at rest, ``mj_forward``), the hand is at C MuJoCo's site position, and the
    stiffness K + ∂G/∂q (central differences of C MuJoCo) is positive definite (a stable posture)."""
    out, entry = run
    arm = pj.load_arm(contacts=False)
    m = arm.mj_model
    d = mujoco.MjData(m)
    P = np.array(PRIMITIVES)

    def gravity(q):
        d.qpos[:], d.qvel[:] = q, 0.0
        mujoco.mj_forward(m, d)
        return d.qfrc_bias.copy(), d.site_xpos[arm.layout.hand_site].copy()

    table = rows(out / "primitives_equilibria.csv")
    assert len(table) == 2 * 7 and all(r["status"] == pj.Status.SUCCESSFUL.message for r in table)
    mixed = 0
    for r in table:
        alpha = np.array([float(r[f"alpha_{nm}"]) for nm in ("rest", "down", "up", "side")])
        q_set = np.array([float(r[f"q_set_{j} [rad]"]) for j in range(1, 7)])
        q_eq = np.array([float(r[f"q_eq_{j} [rad]"]) for j in range(1, 7)])
        want = alpha @ P if r["rule"] == "blend" else P[int(np.argmax(alpha))]
        np.testing.assert_allclose(q_set, want, atol=1e-9)
        g, hand = gravity(q_eq)
        assert np.abs(-arm.K * (q_eq - q_set) - g).max() < 1e-8
        np.testing.assert_allclose([float(r[f"hand_eq_{c} [m]"]) for c in "xyz"], hand, atol=1e-10)
        assert np.linalg.norm(q_eq - q_set) > 0.02  # gravity really sags the arm
        if r["rule"] == "blend" and np.count_nonzero(alpha) > 1:
            mixed += 1
            h = 1e-6
            H = np.stack([(gravity(q_eq + h * e)[0] - gravity(q_eq - h * e)[0]) / (2 * h) for e in np.eye(6)], 1)
            assert np.linalg.eigvalsh(np.diag(arm.K) + 0.5 * (H + H.T)).min() > 0
        assert float(r["c_rollout_vs_equilibrium [rad]"]) < 1e-4
    assert mixed == 3  # the three pairwise blends of the front primitives at the --quick grid


def test_part_reports_the_papers_behaviours(run):
    _, entry = run
    r = entry["results"]
    assert r["winner_take_all_distinct_postures"] == 4  # winner-take-all reaches only the primitives
    assert min(r["blend_region_hand_span_m"]) > 0.05  # blends spread between them, in 3-D
    assert r["grasp_hold_error_rad"] < 1e-3 and r["grasp_set_point_gap_rad"] > 0.05  # stops; gravity gap
    assert r["withdrawal_set_point_vs_rest_rad"] < 1e-9  # back to rest; the later target suppressed
    assert r["lead_set_point_shift_rad"] > 0.1  # lifted hand: the set-point follows
