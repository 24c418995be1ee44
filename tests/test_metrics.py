import numpy as np
import pytest

import pmpjax as pj


def test_curvature_areas_closed_forms():
    # Half circle of radius 1 below the directed line (0,0) -> (2,0): on its right, area π/2.
    th = np.linspace(np.pi, 0, 4001)
    path = np.stack([1 + np.cos(th), -np.sin(th)], -1)
    a_r, a_l = pj.curvature_areas(path, np.zeros(2), np.array([2.0, 0.0]))
    assert abs(float(a_r) - np.pi / 2) < 1e-6 and float(a_l) == 0.0
    # Reversing the direction of travel puts the same lobe on the left.
    a_r2, a_l2 = pj.curvature_areas(path[::-1], np.array([2.0, 0.0]), np.zeros(2))
    assert abs(float(a_l2) - np.pi / 2) < 1e-6 and float(a_r2) == 0.0
    # One sine period of amplitude a over length L: a L / π on each side; rotated frame.
    s = np.linspace(0, 1, 4001)
    c, sn = np.cos(0.7), np.sin(0.7)
    local = np.stack([s, 0.1 * np.sin(2 * np.pi * s)], -1)
    path = local @ np.array([[c, sn], [-sn, c]]) + np.array([0.3, -0.2])
    end = np.array([c, sn]) + np.array([0.3, -0.2])
    a_r, a_l = pj.curvature_areas(path, np.array([0.3, -0.2]), end)
    np.testing.assert_allclose([a_r, a_l], [0.1 / np.pi] * 2, rtol=1e-6)


def test_curvature_measures_batch_and_errors():
    s = np.linspace(0, 1, 101)
    paths = np.stack([np.stack([s, k * s * (1 - s)], -1) for k in (-0.4, 0.0, 0.4)])
    a_sum, a_net = pj.curvature_measures(paths, np.zeros((3, 2)), np.tile([1.0, 0.0], (3, 1)), scale=1.0)
    exact = 0.4 / 6  # ∫ k s(1−s) ds with linear interpolation error O(h²)
    np.testing.assert_allclose(a_net, [exact, 0.0, -exact], rtol=1e-3)
    np.testing.assert_allclose(a_sum, [exact, 0.0, exact], rtol=1e-3)
    with pytest.raises(ValueError, match="path"):
        pj.curvature_areas(np.zeros((5, 3)), np.zeros(2), np.ones(2))


def test_figure3_and_main_job(tmp_path):
    from pmpjax._cli import main

    assert main(["--out", str(tmp_path), "--jobs", "figure3"]) == 0
    import json

    res = json.loads((tmp_path / "results.json").read_text())["figure3"]
    assert res["all_ok"] and res["max_final_task_error_m"] < 1e-6
    assert (tmp_path / "figure3.png").stat().st_size > 10_000
    # Point symmetry of the Figure 3 model (diagonal KJ, rest posture pure PS): opposite targets
    # have equal curvature magnitudes; diagonal paths curve more than cardinal ones (Figure 3A).
    a = res["A_net_out"]
    assert abs(a["NE"] - a["SW"]) < 1e-4 and abs(a["NW"] - a["SE"]) < 1e-4
    assert min(abs(a["NE"]), abs(a["NW"])) > 3 * max(abs(a["N"]), abs(a["E"]))
