"""The command line's runner: artefacts, report, skipping, failures, interruption, bad input."""

import contextlib
import csv
import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from pmpjax._app import cli, figures
from pmpjax._app import reproduce as main_job
from pmpjax._app.display import Display
from pmpjax._app.parts import Part

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce")
    res = cli.reproduce(out, quick=True, only=["figure3", "figure4"], progress=False, cache=False, jobs=1)
    return out, res


def test_reproduce_writes_artefacts_and_a_report_linking_them(run_dir):
    out, res = run_dir
    for part in ("figure3", "figure4"):
        entry = res[part]
        assert entry["status"] == "ok" and entry["artefacts"], part
        for a in entry["artefacts"]:
            path = out / a["path"]
            assert path.stat().st_size > 0
            if a["kind"] == "figure":
                assert path.read_bytes()[:8] == PNG_MAGIC
            assert a["caption"]
    html = (out / "report.html").read_text()
    md = (out / "report.md").read_text()
    for entry in (res["figure3"], res["figure4"]):
        for a in entry["artefacts"]:
            assert a["path"] in md and a["path"] in html
    assert html.count("data:image/png;base64,iVBOR") == 2  # figures embedded: self-contained
    saved = json.loads((out / "results.json").read_text())
    fig3 = saved["figure3"]["results"]
    assert fig3["all_ok"] and fig3["max_final_task_error_m"] < 1e-6
    # Point symmetry of the Figure 3 model (diagonal KJ, rest posture pure PS): opposite targets
    # have equal curvature magnitudes; diagonal paths curve more than cardinal ones (Figure 3A).
    a = fig3["A_net_out"]
    assert abs(a["NE"] - a["SW"]) < 1e-4 and abs(a["NW"] - a["SE"]) < 1e-4
    assert min(abs(a["NE"]), abs(a["NW"])) > 3 * max(abs(a["N"]), abs(a["E"]))
    assert "jax" in saved["_meta"]["versions"]


def test_rerun_skips_finished_parts_unless_forced(run_dir):
    out, _ = run_dir
    png = out / "figure4_summed_moves.png"
    before = png.stat().st_mtime_ns
    cli.reproduce(out, quick=True, only=["figure4"], progress=False, cache=False)
    assert png.stat().st_mtime_ns == before
    cli.reproduce(out, quick=True, only=["figure4"], force=True, progress=False, cache=False)
    assert png.stat().st_mtime_ns > before


def test_a_failing_part_is_reported_and_the_others_run(tmp_path, monkeypatch):
    def broken(ctx):
        """A part that fails."""
        raise RuntimeError("boom")

    parts = {"broken": broken, "figure4": figures.figure4}
    monkeypatch.setattr(main_job, "available_parts", lambda: parts)
    res = cli.reproduce(tmp_path, quick=True, progress=False, cache=False, jobs=1)
    assert res["broken"]["status"] == "failed" and "boom" in res["broken"]["error"]
    assert "RuntimeError" in (tmp_path / "broken.error.txt").read_text()
    assert res["figure4"]["status"] == "ok"
    assert "Failed" in (tmp_path / "report.html").read_text()


def test_ctrl_c_ends_with_one_line_and_keeps_the_finished_parts(tmp_path, monkeypatch, capsys):
    """Ctrl-C: one line saying what is kept (exit 130, no traceback); the re-run runs the rest,
    and the report links no traceback of a part's earlier failure."""
    state = {"second": "fails"}

    def first(ctx):
        """Writes a table."""
        ctx.table([{"a": 1}], "first.csv", "**Verdict:** fine.")
        return {}

    def second(ctx):
        """Fails, is interrupted, then works."""
        if state["second"] == "fails":
            raise RuntimeError("boom")
        if state["second"] == "interrupted":
            raise KeyboardInterrupt
        return {}

    for host in (main_job, cli):
        monkeypatch.setattr(host, "available_parts", lambda: {"first": first, "second": second})
    assert cli.main([*RUN, str(tmp_path)]) == 1
    assert "RuntimeError" in (tmp_path / "second.error.txt").read_text()
    capsys.readouterr()
    state["second"] = "interrupted"
    assert cli.main([*RUN, str(tmp_path)]) == 130
    err = capsys.readouterr().err
    assert err.splitlines()[-1] == ("pmpjax reproduce: interrupted; the finished parts are in "
                                    f"{tmp_path}/results.json; run the same command again to run the others"), err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    assert _strict_json((tmp_path / "results.json").read_text())["first"]["status"] == "ok"
    state["second"] = "works"
    assert cli.main([*RUN, str(tmp_path)]) == 0
    assert "first: finished earlier, skipped" in capsys.readouterr().err
    html = (tmp_path / "report.html").read_text()
    assert not (tmp_path / "second.error.txt").exists() and "second.error.txt" not in html
    assert "<b>Verdict:</b> fine." in html and "**" not in html  # a caption's Markdown bold, rendered


def _unconverged_part(ctx):
    """Fits of which none converged."""
    import numpy as np

    return {"converged": [0, 3], "rms": float("nan"), "per_fit": np.array([np.nan, 1.5, -np.inf])}


def _converged_part(ctx):
    """Fits that all converged (one flag per fit)."""
    return {"converged": [[True], [True]]}


def _strict_json(text):
    """JSON as the standard defines it: NaN and Infinity are not JSON."""
    def refuse(constant):
        raise ValueError(f"{constant} is not JSON")

    return json.loads(text, parse_constant=refuse)


RUN = ["reproduce", "--quick", "--no-progress", "--no-cache", "--jobs", "1", "--out"]


def test_a_part_whose_fits_did_not_all_converge_says_so(tmp_path, monkeypatch, capsys):
    parts = {"partial": _unconverged_part, "whole": _converged_part}
    for host in (main_job, cli):
        monkeypatch.setattr(host, "available_parts", lambda: parts)
    assert cli.main([*RUN, str(tmp_path)]) == 1  # ran, but not every fit converged
    saved = _strict_json((tmp_path / "results.json").read_text())
    assert saved["partial"]["results"]["rms"] is None and saved["partial"]["results"]["per_fit"] == [None, 1.5, None]
    assert saved["partial"]["status"] == "ok" and saved["partial"]["converged"] == [0, 3]
    assert saved["partial"]["all_converged"] is False
    assert saved["whole"]["converged"] == [2, 2] and saved["whole"]["all_converged"] is True
    html = (tmp_path / "report.html").read_text()
    # none of its fits converged: not "ok" (red)
    assert "<td class='failed'>none of 3 fits converged</td>" in html and "<td class='ok'>ok</td>" in html
    assert ".failed{color:#b00}" in html and ".ok{color:#060}" in html  # red, green
    assert "| [partial](#partial) | none of 3 fits converged |" in (tmp_path / "report.md").read_text()
    err = capsys.readouterr().err
    assert "partial: none of 3 fits converged" in err and "whole: ok in" in err
    assert "(1/2 parts)" in err and "(2/2 parts)" in err
    assert cli.main([*RUN, str(tmp_path), "--only", "whole"]) == 0  # every fit of the parts run converged


def test_the_progress_display_counts_the_parts_done():
    ui = Display(True)
    try:
        ui.begin(3)
        ui.part_done("a", {"status": "ok", "seconds": 1.0})
        ui.part_done("b", {"status": "ok", "converged": [1, 2], "seconds": 1.0})
        overall = ui._prog.tasks[0]
        assert (overall.completed, overall.total) == (2, 3) and "parts done" in overall.description
    finally:
        ui.close()


def _shown(ui, task):
    """The text of a progress row as the display draws it (its text columns)."""
    from rich.text import Text

    return " ".join(str(r) for c in ui._prog.columns if isinstance(r := c.render(task), Text))


def test_a_running_part_shows_its_loops_items_done_of_the_total():
    """A running part's row has no count ("0/?" for the whole run said nothing); the loops inside
    it (ctx.progress) show their items done out of the total."""
    ui = Display(True)
    try:
        ui.begin(1)
        ui.started("fits")
        row = next(t for t in ui._prog.tasks if "fits" in t.description)
        assert "running" in _shown(ui, row) and not re.search(r"\d+/(\d+|\?)", _shown(ui, row))
        assert list(ui.factory(range(5), description="fits: subjects")) == [0, 1, 2, 3, 4]
        inner = next(t for t in ui._prog.tasks if "subjects" in t.description)
        assert "fits: subjects 5/5" in _shown(ui, inner)
    finally:
        ui.close()


def test_a_library_calls_progress_callback_shows_its_items_done_of_the_total(tmp_path):
    """``ctx.counter()``: a callback ``advance(done, total)`` for a loop the part does not drive
    (``fitting.sweep``'s ``progress``), shown as the part's own loops are: here through a worker's
    queue, each count as it is reached, and the row ended at the total."""
    import types

    from pmpjax._app.parts import PartContext
    from pmpjax._app.workers import _queue_progress

    sent = []
    queue = types.SimpleNamespace(put=sent.append)
    ctx = PartContext("sweeps", tmp_path, quick=True, seed=0, console=None,
                      progress_factory=_queue_progress(queue, "sweeps"))
    advance = ctx.counter(description="curvature map rows")
    counts = lambda: [m[4:6] for m in sent if m[0] == "progress"]  # noqa: E731
    advance(0, 24)
    assert counts()[-1] == (0, 24) and "curvature map rows" in sent[0][3]
    advance(10, 24)
    assert counts()[-1] == (10, 24)
    advance(20, 24)
    assert counts()[-1] == (20, 24) and sent[-1][0] == "progress"
    advance(24, 24)
    assert counts()[-1] == (24, 24) and sent[-1][0] == "progress_end"


def test_log_lines_are_not_wrapped_when_the_output_is_not_a_terminal(capsys):
    """Written to a file or a pipe (a job's log), a long message stays one line."""
    ui = Display(False)
    message = "part: " + " ".join(f"word{k}" for k in range(60))
    ui.console.print(message)
    ui.close()
    assert capsys.readouterr().err.splitlines() == [message]


# Parts for the worker-process tests: module-level, so that spawned workers can import them. They
# wait for each other by files in the output folder (events that hold under any load), not by sleeping.
def _wait_for(*paths, timeout=120.0):
    """Wait until every file of ``paths`` exists (or fail after ``timeout`` seconds)."""
    deadline = time.monotonic() + timeout
    while not all(Path(p).exists() for p in paths):
        if time.monotonic() > deadline:
            raise TimeoutError(f"waited {timeout} s for {paths}")
        time.sleep(0.02)


def _raising_part(ctx):
    """Raises."""
    raise RuntimeError("boom in a worker")


def _crashing_part(ctx):
    """Kills its worker process (as a segfault in XLA or MuJoCo would), once the other worker's
    part has failed."""
    _wait_for(ctx.out / "raising.error.txt")
    print("the crashing part's last words", file=sys.stderr, flush=True)
    os._exit(3)


def _tiny_part(ctx):
    """Writes one table."""
    assert list(ctx.progress(range(3), description="steps")) == [0, 1, 2]
    ctx.table([{"pid": os.getpid(), "quick": ctx.quick}], "tiny.csv", "One row.")
    ctx.log("tiny done")
    return {"value": 1.5}


def _affinity_part(ctx):
    """Reports the cores its worker may run on, once both parts run (one on each worker)."""
    (ctx.out / f"{ctx.name}.running").touch()
    _wait_for(ctx.out / "a.running", ctx.out / "b.running")
    return {"pid": os.getpid(), "cores": sorted(os.sched_getaffinity(0))}


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2,
                    reason="needs two usable cores (Linux)")
def test_two_workers_run_on_disjoint_cores(tmp_path, monkeypatch):
    """Each of two workers is pinned to its half of the cores (unpinned, XLA gives each worker a
    thread per core and the two compete for both)."""
    monkeypatch.setattr(main_job, "available_parts", lambda: {"a": _affinity_part, "b": _affinity_part})
    res = cli.reproduce(tmp_path, quick=True, progress=False, cache=False, jobs=2)
    a, b = res["a"]["results"], res["b"]["results"]
    assert a["pid"] != b["pid"]
    usable = sorted(os.sched_getaffinity(0))
    assert not set(a["cores"]) & set(b["cores"]) and sorted(a["cores"] + b["cores"]) == usable
    assert abs(len(a["cores"]) - len(b["cores"])) <= 1


def _timed_part(ctx):
    """Reports its worker and when it ran; "lead" ends only after o1, o2 and o3 have ended."""
    t0 = time.time()
    if ctx.name == "lead":
        _wait_for(*(ctx.out / f"o{i}.done" for i in (1, 2, 3)))
    (ctx.out / f"{ctx.name}.done").touch()
    return {"pid": os.getpid(), "start": t0, "end": time.time()}


def test_a_follower_part_runs_after_its_leader_on_the_leaders_worker(tmp_path, monkeypatch):
    """A part that ``follows`` another (donders_nio after pointing, whose NIO compilation it
    reuses): submitted second, it would start at once on the other worker; it waits and runs
    where its leader ran. The leader holds its worker until the other parts have run on the
    other worker."""
    names = ["lead", "follower", "o1", "o2", "o3"]
    parts = {**dict.fromkeys(names, _timed_part), "follower": Part(_timed_part, follows="lead")}
    monkeypatch.setattr(main_job, "available_parts", lambda: parts)
    res = cli.reproduce(tmp_path, quick=True, progress=False, cache=False, jobs=2)
    r = {n: res[n]["results"] for n in names}
    assert all(res[n]["status"] == "ok" for n in names)
    assert r["follower"]["pid"] == r["lead"]["pid"] and r["follower"]["start"] >= r["lead"]["end"]
    assert all(r[n]["pid"] != r["lead"]["pid"] for n in ("o1", "o2", "o3"))  # the other worker meanwhile


def test_parts_in_workers_a_raising_and_a_crashing_part_fail_alone(tmp_path, monkeypatch):
    from importlib.metadata import EntryPoint

    # "tiny" as an installed package registers it (pmpjax.jobs entry point): the worker loads it.
    tiny = EntryPoint(name="tiny", value=f"{__name__}:_tiny_part", group="pmpjax.jobs")
    parts = {"raising": _raising_part, "crashing": _crashing_part, "tiny": tiny}
    monkeypatch.setattr(main_job, "available_parts", lambda: parts)
    # An earlier run's traceback and messages of a part that runs again, and of an earlier worker
    (tmp_path / "_logs").mkdir()
    for stale in ("tiny.error.txt", "_logs/tiny.log", "_logs/worker-1.log"):
        (tmp_path / stale).write_text("stale\n")
    res = cli.reproduce(tmp_path, quick=True, progress=False, cache=False, jobs=2)
    assert res["_meta"]["jobs"] == 2
    assert res["raising"]["status"] == "failed" and "boom in a worker" in res["raising"]["error"]
    assert "RuntimeError" in (tmp_path / "raising.error.txt").read_text()
    assert res["crashing"]["status"] == "failed" and "crashed" in res["crashing"]["error"]
    crash_log = tmp_path / "_logs" / "crashing.log"  # its messages, named in its entry
    assert str(crash_log) in res["crashing"]["error"]
    assert "the crashing part's last words" in crash_log.read_text()
    assert res["tiny"]["status"] == "ok" and res["tiny"]["results"] == {"value": 1.5}
    row = (tmp_path / "tiny.csv").read_text().splitlines()[1]
    assert int(row.split(",")[0]) != os.getpid()  # it ran in a worker
    assert list(res) == ["_meta", "raising", "crashing", "tiny"]  # report order, not finishing order
    html = (tmp_path / "report.html").read_text()
    assert html.count("Failed") >= 2 and "tiny.csv" in html
    assert not (tmp_path / "tiny.error.txt").exists() and not (tmp_path / "_logs" / "worker-1.log").exists()
    tiny_log = tmp_path / "_logs" / "tiny.log"
    assert not tiny_log.exists() or "stale" not in tiny_log.read_text()
    assert "tiny.error.txt" not in html and "worker-1.log" not in html and "_logs/crashing.log" in html


def test_two_workers_give_the_numbers_of_one_process(run_dir, tmp_path, monkeypatch):
    import jax

    out, res1 = run_dir
    # Workers load what the in-process fixture compiled from the suite's cache (conftest): a worker
    # without float64 would miss the cache and differ in the last bits.
    monkeypatch.setenv("PMPJAX_CACHE_DIR", jax.config.jax_compilation_cache_dir)
    min_time = jax.config.jax_persistent_cache_min_compile_time_secs
    try:
        res2 = cli.reproduce(tmp_path, quick=True, only=["figure3", "figure4"], progress=False, jobs=2)
    finally:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", min_time)
    assert res2["_meta"]["jobs"] == 2
    for part in ("figure3", "figure4"):
        assert res2[part]["status"] == "ok"
        assert res2[part]["results"] == json.loads(json.dumps(res1[part]["results"])), part


def test_an_interrupted_run_keeps_the_parts_already_written(tmp_path):
    script = textwrap.dedent(f"""
        import time
        from pmpjax._app import figures, reproduce as main_job
        def hang(ctx):
            '''Never ends.'''
            time.sleep(600)
        main_job.available_parts = lambda: {{"figure4": figures.figure4, "hang": hang}}
        main_job.reproduce({str(tmp_path)!r}, quick=True, progress=False, cache=False)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], env={**os.environ, "MPLBACKEND": "Agg"})
    results = tmp_path / "results.json"
    try:
        deadline = time.monotonic() + 600  # (generous: matters only when something is wrong)
        while time.monotonic() < deadline:
            if results.exists() and "figure4" in json.loads(results.read_text()):
                break
            assert proc.poll() is None, "the run ended before it could be interrupted"
            time.sleep(0.2)
        else:
            pytest.fail("figure4 never finished")
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    saved = json.loads(results.read_text())
    assert saved["figure4"]["status"] == "ok" and "hang" not in saved
    assert (tmp_path / "figure4_summed_moves.png").read_bytes()[:8] == PNG_MAGIC


def _alive(pid):
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state not in ("Z", "X")  # a zombie has exited


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc and prctl: Linux")
@pytest.mark.parametrize("stop", ["SIGTERM", "Ctrl-C"])
def test_stopping_the_command_stops_its_worker_processes(tmp_path, stop):
    """SIGTERM to ``reproduce`` (a job scheduler's timeout, ``kill``) or Ctrl-C (SIGINT to the
    terminal's process group: the command and its workers) must not leave its spawned workers
    computing: they stop with it; Ctrl-C ends with one line and exit status 130, no traceback."""
    # Each part announces it runs by a file, then waits for one that never comes: the test stops
    # the command once both run, whatever the load (no race with a sleep).
    (tmp_path / "sleepers.py").write_text(textwrap.dedent(f"""
        import os, time
        def sleeper(ctx):
            here = {str(tmp_path)!r}
            tmp = os.path.join(here, f"{{os.getpid()}}.tmp")
            open(tmp, "w").close()
            os.replace(tmp, os.path.join(here, f"worker-{{os.getpid()}}.pid"))
            while not os.path.exists(os.path.join(here, "never")):
                time.sleep(0.05)
    """))
    # Ctrl-C as from a terminal: a test run started in the background (`&`, nohup) hands its
    # children SIGINT ignored, and Python then raises no KeyboardInterrupt (the command waited out
    # the 300 s limit and failed); the command restores the default handler first.
    script = textwrap.dedent(f"""
        import signal, sys
        signal.signal(signal.SIGINT, signal.default_int_handler)
        sys.path.insert(0, {str(tmp_path)!r})
        import sleepers
        from pmpjax._app import cli, reproduce as main_job
        main_job.available_parts = cli.available_parts = lambda: {{"a": sleepers.sleeper, "b": sleepers.sleeper}}
        sys.exit(cli.main(["reproduce", "--out", {str(tmp_path / "out")!r}, "--quick", "--no-progress",
                           "--no-cache", "--jobs", "2"]))
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], env={**os.environ, "MPLBACKEND": "Agg"},
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    pids = []
    # Generous limits: they only matter when something is wrong (spawning two workers that import
    # JAX on two loaded cores can take minutes; stopping takes seconds).
    try:
        deadline = time.monotonic() + 600
        while len(pids) < 2:
            assert time.monotonic() < deadline, "the workers never started"
            assert proc.poll() is None, "the run ended before it could be stopped"
            time.sleep(0.1)
            pids = [int(f.stem.split("-")[1]) for f in tmp_path.glob("worker-*.pid")]
        if stop == "SIGTERM":
            proc.send_signal(signal.SIGTERM)
        else:
            os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=300)
        deadline = time.monotonic() + 120
        while any(_alive(p) for p in pids) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not any(_alive(p) for p in pids), "worker processes outlived the stopped command"
        if stop == "Ctrl-C":
            assert proc.returncode == 130, err
            # (no part finished: the message points to no results.json, which does not exist)
            assert not (tmp_path / "out" / "results.json").exists()
            assert err.strip().splitlines() == ["pmpjax reproduce: interrupted; no part had finished; run the same "
                                                "command again to run them"], err
    finally:
        for p in pids:
            with contextlib.suppress(ProcessLookupError):
                os.kill(p, signal.SIGKILL)
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_command_line_bad_input_is_one_line_and_exit_2(capsys, tmp_path, monkeypatch):
    assert cli.main(["reproduce", "--only", "no_such_part", "--no-cache"]) == 2
    err = capsys.readouterr().err
    assert "no_such_part" in err and "Traceback" not in err
    # a bare `pmpjax` prints its usage and starts nothing (no `out/` in the current folder)
    monkeypatch.chdir(tmp_path)
    assert cli.main([]) == 2
    err = capsys.readouterr().err
    assert "usage:" in err and "--out DIR" in err and not any(tmp_path.iterdir())


def _example(name):
    from importlib import resources

    return str(resources.files("pmpjax") / "data" / "examples" / name)


def test_simulate_command_runs_the_shipped_figure3_config(tmp_path, capsys, monkeypatch):
    import numpy as np

    import pmpjax as pj
    from pmpjax.internal import replace

    assert cli.main(["simulate", _example("simulate_figure3.toml"), "--out", str(tmp_path)]) == 0
    s = json.loads((tmp_path / "summary.json").read_text())
    assert len(s["targets"]) == 8 and max(s["final_task_error"]) < 1e-6
    lines = (tmp_path / "trajectories.csv").read_text().splitlines()
    # columns as the configuration names them, numbered from 1, with units; x1, x2 the target's coordinates
    assert lines[0] == "target,t [s],q1 [rad],q2 [rad],q3 [rad],x1 [m],x2 [m]" and len(lines) == 1 + 8 * 41
    last = {r["target"]: r for r in csv.DictReader(lines)}  # (each target's final sample)
    for name, (x1, x2) in pj.center_out_targets().items():
        if name in last:
            assert float(last[name]["x1 [m]"]) == pytest.approx(x1, abs=1e-6)
            assert float(last[name]["x2 [m]"]) == pytest.approx(x2, abs=1e-6)
    assert float(last["NE"]["t [s]"]) == pytest.approx(0.4)
    assert (tmp_path / "paths.png").read_bytes()[:8] == PNG_MAGIC
    assert capsys.readouterr().out.startswith("8 movements, ")
    # The exit-status policy: a movement that did not end successfully is written, and exits 1.
    simulate = pj.simulate

    def one_inaccurate(*args, **kwargs):
        traj = simulate(*args, **kwargs)
        status = np.asarray(traj.status).copy()
        status.reshape(-1)[3] = int(pj.Status.INACCURATE)
        return replace(traj, status=status)

    monkeypatch.setattr(pj, "simulate", one_inaccurate)
    assert cli.main(["simulate", _example("simulate_figure3.toml"), "--out", str(tmp_path)]) == 1
    s = _strict_json((tmp_path / "summary.json").read_text())
    assert [m == pj.Status.SUCCESSFUL.message for m in s["status"]] == [k != 3 for k in range(8)]
    assert ", 1 not successful (summary.json says why)" in capsys.readouterr().out


def test_python_m_pmpjax_in_the_folder_holding_a_clone_says_what_to_do(tmp_path):
    """A clone named pmpjax, `python -m pmpjax` run beside it: Python imports the clone's folder (no
    __init__.py) as an empty package; the command says so instead of an ImportError."""
    (tmp_path / "pmpjax" / "pmpjax").mkdir(parents=True)  # (a clone: the package is one level down)
    run = {"cwd": tmp_path, "capture_output": True, "text": True, "env": {**os.environ, "PYTHONPATH": ""}}
    probe = subprocess.run([sys.executable, "-c", "import pmpjax; print(getattr(pmpjax, '__file__', None))"], **run)
    if probe.stdout.strip() != "None":
        pytest.skip("this installation of pmpjax takes precedence over a folder in the current one")
    proc = subprocess.run([sys.executable, "-m", "pmpjax", "--version"], **run)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert f"imported the folder {tmp_path / 'pmpjax'} instead of the installed pmpjax" in proc.stderr
    assert "Run the command from any other folder" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1


def test_the_application_writes_json_only_as_strict_json():
    """Every JSON file of the commands and the main job is strict JSON: written by the writer that
    turns NaN and inf into null, or by json.dump(s) with allow_nan=False (by default json.dumps
    writes bare NaN, which is not JSON)."""
    import ast

    import fitting

    modules = [*Path(cli.__file__).parent.glob("*.py"), *(Path(fitting.__file__).parent / "_app").glob("*.py")]
    assert len(modules) > 8
    for module in modules:
        for node in ast.walk(ast.parse(module.read_text())):
            f = node.func if isinstance(node, ast.Call) else None
            if not (isinstance(f, ast.Attribute) and f.attr in ("dump", "dumps")
                    and getattr(f.value, "id", "") == "json"):
                continue
            if not any(k.arg == "allow_nan" and getattr(k.value, "value", True) is False for k in node.keywords):
                pytest.fail(f"{module.name}:{node.lineno}: json.{f.attr} may write NaN; use pmpjax.internal.write_json")
    from pmpjax.internal import json_text

    text = json_text({"a": float("nan"), "b": [1.0, float("inf")], "c": __import__("numpy").array([-float("inf")])})
    assert _strict_json(text) == {"a": None, "b": [1.0, None], "c": [None]}


def test_simulate_command_ends_in_the_donders_posture(tmp_path):
    """A long movement ends where ½ (q − q_rest)ᵀ KJ (q − q_rest) is least on the target
    (SciPy SLSQP on the paper's Eq 6, written out here)."""
    import numpy as np
    from scipy.optimize import minimize

    KJ, q_rest, target = np.diag([0.5, 1.5, 2.0]), np.deg2rad([5.0, 0, 0]), np.array([0.15, 0.1])
    cfg = tmp_path / "long.json"
    cfg.write_text(json.dumps({
        "model": {"KJ": KJ.tolist(), "q_rest": q_rest.tolist(), "tau0": 0.08},
        "planner": {"type": "arimoto", "k": 22.5, "tau": 0.08},
        # 8 targets, 400 steps saved every 10: the shapes of the shipped Figure 3 config, whose
        # compilation this reuses.
        "simulation": {"q0_deg": [0, 10, -5], "targets": [target.tolist()] * 8, "duration": 1.6, "dt": 0.004,
                       "save_every": 10},
    }))
    assert cli.main(["simulate", str(cfg), "--out", str(tmp_path / "o")]) == 0
    q_end = np.asarray(json.loads((tmp_path / "o" / "summary.json").read_text())["final_q"][0])

    def fk(q):  # R = Rx(−q_PS) Rz(q_FE) Ry(q_RUD); x = [[0, −1, 0], [0, 0, 1]] R e_x (d = 1)
        cx, sx = np.cos(-q[0]), np.sin(-q[0])
        cz, sz = np.cos(q[1]), np.sin(q[1])
        cy, sy = np.cos(q[2]), np.sin(q[2])
        Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
        Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
        Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
        v = Rx @ Rz @ Ry @ np.array([1.0, 0, 0])
        return np.array([-v[1], v[2]])

    ref = minimize(lambda q: 0.5 * (q - q_rest) @ KJ @ (q - q_rest), q_rest, method="SLSQP",
                   constraints=[{"type": "eq", "fun": lambda q: fk(q) - target}],
                   options={"ftol": 1e-15, "maxiter": 1000}).x
    assert np.linalg.norm(fk(ref) - target) < 1e-10
    np.testing.assert_allclose(q_end, ref, atol=2e-6)


@pytest.mark.parametrize("text, key", [
    ("[model]\nKJ = [[1, 2], [3\n", "bad.toml"),
    ("[model]\nKJ_diag = [1, 2]\n", "model.KJ_diag"),
    ("[model]\nKJ_diag = [1, 1, 1]\n[simulation]\nduration = -1\n", "simulation.duration"),
    ("[model]\nKJ = [[1, 2, 0], [0, 1, 0], [0, 0, 1]]\n", "KJ"),
    ("[chain]\ntype = 'hand'\n", "chain.type"),
])
@pytest.mark.bad_input("pj.read_simulation_config")
def test_simulate_command_bad_config_names_file_and_key(tmp_path, capsys, text, key):
    import pmpjax as pj

    path = tmp_path / "bad.toml"
    path.write_text(text)
    assert cli.main(["simulate", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "bad.toml" in err and key in err and "Traceback" not in err
    with pytest.raises(ValueError, match=key):
        pj.read_simulation_config(path)


def test_every_registered_part_carries_its_metadata_and_the_host_names_none():
    """Parts are found by entry point and schedule by their own metadata: every registered part
    is a Part with positive expected seconds, a human title and a ``follows`` naming another registered part;
    the host modules hold no part's name (adding a part never edits them)."""
    import ast

    from pmpjax._app.parts import as_part, available_parts

    parts = {name: as_part(p) for name, p in available_parts().items()}
    assert {"figure3", "figure4", "primitives", "pointing", "reaching", "donders_nio"} <= set(parts)
    for name, part in parts.items():
        assert isinstance(part, Part) and part.seconds > 0 and part.seconds_full > 0 and part.doc, name
        # a title for the report's section, in words (not the part's identifier)
        assert len(part.title.split()) >= 3 and "_" not in part.title, name
        assert part.follows is None or (part.follows in parts and part.follows != name), name
    assert [p.order for p in parts.values()] == sorted(p.order for p in parts.values())
    host = Path(cli.__file__).parent
    for module in ("cli.py", "reproduce.py", "workers.py", "display.py", "parts.py", "report.py"):
        strings = {n.value for n in ast.walk(ast.parse((host / module).read_text()))
                   if isinstance(n, ast.Constant) and isinstance(n.value, str)}
        assert not strings & set(parts), (module, strings & set(parts))
