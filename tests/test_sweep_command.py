"""``pmpjax sweep CONFIG``: the shipped example against SciPy, resuming, and malformed configs."""

import csv
import json
import shutil
from importlib import resources

import numpy as np
import pytest
import scipy.integrate
from _reference import arimoto, pmp_qdot, polygon_areas, wrist_fk, wrist_jac

from fitting._app.sweep_command import sweep_parameters
from pmpjax._app import cli

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
EXAMPLE = str(resources.files("pmpjax") / "data" / "examples" / "sweep_figure3.toml")


def read_rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """The shipped example, run once through the command line (one compilation for the module)."""
    out = tmp_path_factory.mktemp("sweep") / "out"
    assert cli.main(["sweep", EXAMPLE, "--out", str(out), "--no-progress"]) == 0
    return out


def _reference_movement(KJ, q_rest, tau0, k, tau, q0, target, t):
    """The λ0-PMP movement by solve_ivp (DOP853) of the NumPy field of _reference: x (S, 2), speed (S,)."""
    W = tau0 * KJ
    gain = arimoto(k, tau)
    sol = scipy.integrate.solve_ivp(lambda s, q: pmp_qdot(q, s, target, KJ, q_rest, W, gain), (0.0, t[-1]), q0,
                                    method="DOP853", t_eval=t, rtol=1e-11, atol=1e-13)
    assert sol.success
    q = sol.y.T
    x = np.stack([wrist_fk(qi) for qi in q])
    speed = np.array([np.linalg.norm(wrist_jac(qi) @ pmp_qdot(qi, s, target, KJ, q_rest, W, gain))
                      for qi, s in zip(q, t)])
    return x, speed


def test_example_rows_equal_an_independent_scipy_computation(run):
    rows = read_rows(run / "sweep.csv")
    assert len(rows) == 6 and all(r["status"] == "0" and r["reason"] == "" for r in rows)
    # Grid in C order: KJ[2,2] slowest, τ fastest.
    assert [(float(r["model.KJ[2,2]"]), float(r["planner.tau"])) for r in rows] == [
        (a, b) for a in (1.0, 2.0, 3.0) for b in (0.06, 0.1)]
    r = rows[5]  # KJ = diag(0.5, 1.5, 3), τ = 0.1
    t = np.linspace(0.0, 0.4, 401)  # the command saves every RK4 step (dt = 1 ms)
    radius = np.pi / 12
    for name, ang in (("NE", 45.0), ("E", 0.0), ("SE", -45.0)):
        target = radius * np.array([np.cos(np.deg2rad(ang)), np.sin(np.deg2rad(ang))])
        x, speed = _reference_movement(np.diag([0.5, 1.5, 3.0]), np.deg2rad([5.0, 0, 0]), 0.08, 22.5, 0.1,
                                       np.deg2rad([5.0, 0, 0]), target, t)
        a_r, a_l = polygon_areas(x[1:], x[0], target)
        assert float(r[f"A_net_{name}"]) == pytest.approx((a_r - a_l) / radius**2, abs=2e-6)
        assert float(r[f"A_sum_{name}"]) == pytest.approx((a_r + a_l) / radius**2, abs=2e-6)
        assert float(r[f"final_error_{name}"]) == pytest.approx(np.linalg.norm(x[-1] - target), abs=1e-8)
        assert float(r[f"peak_speed_{name}"]) == pytest.approx(speed.max(), rel=1e-5)
    assert abs(float(r["A_net_NE"])) > 0.02  # anisotropic stiffness curves the diagonal movement
    # Paths barely depend on the planner's τ (a scalar gain re-times the same path; RK4 samples differ).
    a = np.array([[float(rw[f"A_net_{d}"]) for d in ("NE", "E", "SE")] for rw in rows]).reshape(3, 2, 3)
    np.testing.assert_allclose(a[:, 0], a[:, 1], atol=1e-4)  # sampled at other path points
    s = json.loads((run / "sweep.json").read_text())
    assert s["rows"] == 6 and s["chunks_computed"] == 2 and s["failed"] == 0
    np.testing.assert_allclose(np.asarray(s["outputs"]["A_net"])[5, 1], float(r["A_net_NE"]), rtol=1e-9)
    assert (run / "sweep.png").read_bytes()[:8] == PNG_MAGIC


def test_a_rerun_resumes_and_a_changed_config_is_refused(run, tmp_path, capsys):
    out = tmp_path / "out"
    shutil.copytree(run, out)
    shards = sorted((out / "store" / "chunks").iterdir())
    assert len(shards) == 2
    stamps = [p.stat().st_mtime_ns for p in shards]
    before = (out / "sweep.csv").read_text()
    assert cli.main(["sweep", EXAMPLE, "--out", str(out), "--no-progress"]) == 0
    s = json.loads((out / "sweep.json").read_text())
    assert (s["chunks_computed"], s["chunks_reused"]) == (0, 2)
    assert [p.stat().st_mtime_ns for p in shards] == stamps  # verified chunks are read, never rewritten
    shards[1].unlink()  # an interrupted run: the second chunk is missing
    assert cli.main(["sweep", EXAMPLE, "--out", str(out), "--no-progress"]) == 0
    s = json.loads((out / "sweep.json").read_text())
    assert (s["chunks_computed"], s["chunks_reused"]) == (1, 1)
    assert (out / "sweep.csv").read_text() == before
    # A different configuration in the same folder is another sweep: refused, the store kept.
    changed = tmp_path / "changed.toml"
    changed.write_text(open(EXAMPLE).read().replace("k = 22.5", "k = 20.0"))
    capsys.readouterr()
    assert cli.main(["sweep", str(changed), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "another sweep" in err and "Traceback" not in err
    assert len(list((out / "store" / "chunks").iterdir())) == 2


BASE = '[model]\nKJ_diag = [0.5, 1.5, 2.0]\n[planner]\nk = 22.5\ntau = 0.08\n'


@pytest.mark.parametrize("text, expect", [
    (BASE + "[sweep]\nchunk_size = 4\n[sweep.grid]\n'planner.tau' = [0.1, 0.2]]\n", "line 9, column"),
    (BASE, "[sweep]"),
    (BASE + "[sweep.grid]\n'model.stiffness' = [1, 2]\n", "unknown sweep parameter 'model.stiffness'"),
    (BASE + "[sweep.grid]\n'model.KJ[3,3]' = [1, 2]\n", "model.KJ[3,3]: index out of range"),
    (BASE + "[sweep.grid]\n'model.KJ[0,1]' = [0.0, 1.0]\n", "not positive definite in row 2"),
    (BASE + "[sweep.grid]\n'planner.tau' = [0.1, -0.1]\n", "planner.tau must be positive; row 2"),
    (BASE + "[sweep.grid]\n'planner.tau' = []\n", "sweep.grid.planner.tau"),
    (BASE + "[sweep]\nmetrics = ['A_net', 'wobble']\n[sweep.grid]\n'planner.tau' = [0.1]\n", "sweep.metrics"),
    (BASE + "[sweep]\nchunk_size = 0\n[sweep.grid]\n'planner.tau' = [0.1]\n", "sweep.chunk_size"),
    (BASE + "[sweep.sample]\nn = 6\nbounds = {'model.tau0' = [0.05, 0.1]}\n", "power of two"),
    (BASE + "[sweep.sample]\nmethod = 'random'\nn = 4\n", "sweep.sample.method"),
    (BASE + "[sweep.sample]\nn = 4\nbounds = {'model.tau0' = [0.1, 0.05]}\n", "low < high"),
    (BASE + "[sweep.grid]\n'model.tau0' = [0.08, 0.0005]\n", "simulation.dt: in some row of the sweep, `dt`=0.001"),
    ('[model]\nKJ_diag = [1, 1, 1]\nW = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n[sweep.grid]\n"model.tau0" = [0.1]\n',
     "cannot sweep"),
])
def test_malformed_configs_give_one_line_errors_naming_file_and_key(tmp_path, capsys, text, expect):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    assert cli.main(["sweep", str(path), "--out", str(tmp_path / "o"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "bad.toml" in err and expect in err and "Traceback" not in err
    assert err.count("\n") == 1 and not (tmp_path / "o").exists()  # nothing written before the checks


def test_json_syntax_errors_name_line_and_column(tmp_path, capsys):
    path = tmp_path / "bad.json"
    path.write_text('{"sweep": {"grid": {"planner.tau": [0.1,]}}}')
    assert cli.main(["sweep", str(path), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "bad.json: line 1, column" in err and "Traceback" not in err


def test_grid_crossed_with_sobol_points_and_dotted_keys():
    cfg = {"sweep": {"grid": {"model": {"tau0": [0.05, 0.1]}, "planner.k": [10.0, 20.0, 30.0]},
                     "sample": {"method": "sobol", "n": 4, "seed": 3, "bounds": {"model.q_rest_deg[0]": [-10, 10]}}},
           "planner": {"k": 22.5}}
    params, axes, parsed = sweep_parameters(cfg, "c.toml", 3, "arimoto")
    assert axes == [] and set(parsed) == {"model.tau0", "planner.k", "model.q_rest_deg[0]"}
    assert all(len(v) == 2 * 3 * 4 for v in params.values())
    # Every grid row meets the same 4 Sobol' points, each once.
    combos = {(a, b) for a, b in zip(params["model.tau0"], params["planner.k"])}
    assert combos == {(a, b) for a in (0.05, 0.1) for b in (10.0, 20.0, 30.0)}
    pts = params["model.q_rest_deg[0]"].reshape(6, 4)
    assert np.all(pts == pts[0]) and len(set(pts[0])) == 4 and np.all(np.abs(pts) <= 10)


def test_sweep_has_help(capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["sweep", "--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    assert "sweep" in out and "model.KJ[i,j]" in out and "resum" in out
