"""fitting.sweep: chunked = unchunked, any device count, resumable after SIGKILL, corrupt shards
recomputed, Dask = local, failures marked per row, samplers, CSV tables, clear bad-input errors.

The reference for every output is the closed form of the tiny test function (NumPy), and the
unchunked ``jax.vmap(fn)`` over all rows. Budget: a few seconds of compute; the Dask cluster is
started once per module; subprocesses are only where the test needs a fresh process (2 devices,
SIGKILL).
"""

import hashlib
import itertools
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import fitting
import pmpjax as pj

ROOT = Path(__file__).parent.parent
TESTS = Path(__file__).parent


def tiny(p):
    """Closed form per row; NaN where a < 0 (log), status STALLED where b > 25."""
    y = jnp.sin(p["a"]) * p["b"] + jnp.arange(3.0)
    return {"y": y, "s": jnp.log(p["a"] + 1.0), "status": jnp.where(p["b"] > 25, int(pj.Status.STALLED), 0)}


def tiny_numpy(a, b):
    with np.errstate(invalid="ignore", divide="ignore"):
        return {"y": np.sin(a)[:, None] * b[:, None] + np.arange(3.0), "s": np.log(a + 1.0),
                "status": np.where(b > 25, int(pj.Status.STALLED), 0)}


def slow(p):
    """tiny + a pause per chunk (a host callback; $SWEEP_TEST_PAUSE seconds, read when it runs, so
    only the process to be killed pauses), so that a run can be killed between chunks."""
    def wait(a):
        time.sleep(float(os.environ.get("SWEEP_TEST_PAUSE", "0")))
        return a

    a = jax.pure_callback(wait, jax.ShapeDtypeStruct(p["a"].shape, p["a"].dtype), p["a"], vmap_method="expand_dims")
    return tiny({"a": a, "b": p["b"]})


PARAMS = fitting.grid(a=np.linspace(-1.5, 2.0, 8), b=[10.0, 20.0, 30.0])  # 24 rows


def _equal(res, ref):
    for k in ref:
        np.testing.assert_array_equal(np.asarray(res[k]), np.asarray(ref[k]), err_msg=k)


@pytest.fixture(scope="module")
def reference():
    return jax.vmap(tiny)(PARAMS)


def test_reference_is_the_closed_form(reference):
    want = tiny_numpy(PARAMS["a"], PARAMS["b"])
    for k in want:
        np.testing.assert_allclose(np.asarray(reference[k]), want[k], rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize("chunk_size", [1, 5, 24, 100])
def test_chunked_equals_unchunked_vmap(chunk_size, reference, tmp_path):
    res = fitting.sweep(tiny, PARAMS, chunk_size=chunk_size, out=tmp_path / "s", progress=False, devices=1)
    _equal(res.outputs, reference)
    assert res.chunks_computed == -(-24 // min(chunk_size, 24)) and res.chunks_reused == 0
    mem = fitting.sweep(tiny, PARAMS, chunk_size=chunk_size, progress=False)  # no store
    _equal(mem.outputs, reference)


def test_one_compilation_whatever_the_chunk_count():
    traces = []

    def counted(p):
        traces.append(1)
        return p["a"] * 2.0

    res = fitting.sweep(counted, PARAMS, chunk_size=5, progress=False, devices=1)  # 5 chunks, last padded
    np.testing.assert_array_equal(res.outputs, PARAMS["a"] * 2.0)
    assert len(traces) == 1  # one trace: the fingerprint's jaxpr is the one compilation's


def _shards(out):
    return {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in (Path(out) / "chunks").glob("*.npz")}


@pytest.fixture(scope="module")
def killed_run(tmp_path_factory):
    """One fresh process with 2 local CPU devices (XLA_FLAGS): it checks sweeps on 2 devices
    against vmap, then starts a slow sweep into a store and is SIGKILLed once >= 2 chunks are on
    disk. (One process for both, to keep process start-ups within the test budget.)"""
    out = tmp_path_factory.mktemp("sweep") / "killed"
    script = f"""
    import sys; sys.path.insert(0, {str(TESTS)!r})
    import jax, numpy as np
    jax.config.update("jax_enable_x64", True)
    import fitting
    from test_sweep import PARAMS, slow, tiny
    assert len(jax.local_devices()) == 2
    ref = jax.vmap(tiny)(PARAMS)
    for cs in (1, 7, 24):
        res = fitting.sweep(tiny, PARAMS, chunk_size=cs, devices=2, progress=False)
        for k in ref:
            np.testing.assert_array_equal(np.asarray(res.outputs[k]), np.asarray(ref[k]))
    print("2 devices OK", flush=True)
    fitting.sweep(slow, PARAMS, chunk_size=2, out={str(out)!r}, devices=2, progress=False)
    """
    env = {**os.environ, "XLA_FLAGS": "--xla_force_host_platform_device_count=2", "SWEEP_TEST_PAUSE": "0.4"}
    proc = subprocess.Popen([sys.executable, "-c", textwrap.dedent(script)], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 900  # only a guard: a loaded machine can take minutes to start and compile
    while len(_shards(out) if (out / "chunks").exists() else {}) < 2:
        if proc.poll() is not None:
            pytest.fail(f"the sweep process ended before it was killed: {proc.stderr.read()[-3000:]}")
        assert time.time() < deadline, "no chunk written in time"
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    stdout, stderr = proc.communicate()
    return out, _shards(out), stdout, stderr


def test_two_local_devices_equal_vmap(killed_run):
    _, _, stdout, stderr = killed_run
    assert "2 devices OK" in stdout, stderr[-3000:]


def test_sigkill_midway_then_restart_is_complete_and_keeps_finished_chunks(killed_run, reference):
    out, before, _, _ = killed_run
    assert 2 <= len(before) < 12, f"the kill came too late to test a restart ({len(before)} of 12 chunks)"
    # restarted on 1 device: the store does not depend on the device count
    res = fitting.sweep(slow, PARAMS, chunk_size=2, out=out, devices=1, progress=False)
    _equal(res.outputs, reference)
    assert res.chunks_reused == len(before) and res.chunks_computed == 12 - len(before)
    after = _shards(out)
    assert len(after) == 12
    for name, stat in before.items():
        assert after[name] == stat, f"{name} was rewritten"
    assert not [p for p in (out / "chunks").iterdir() if p.suffix != ".npz"]  # no temporary left


def test_truncated_corrupted_or_wrong_shards_are_recomputed(tmp_path, reference):
    out = tmp_path / "s"
    fitting.sweep(tiny, PARAMS, chunk_size=4, out=out, progress=False, devices=1)  # 6 chunks
    files = sorted((out / "chunks").glob("*.npz"))
    keep = _shards(out)
    data = files[0].read_bytes()
    files[0].write_bytes(data[: len(data) // 2])  # truncated
    data = bytearray(files[1].read_bytes())
    data[-40] ^= 0xFF  # one flipped byte
    files[1].write_bytes(bytes(data))
    # a shard that is whole and honestly named, but of the wrong shape (a stale or foreign file)
    buf = __import__("io").BytesIO()
    np.savez(buf, o0=np.zeros(3), o1=np.zeros(3, np.int64), o2=np.zeros((3, 3)))
    blob = buf.getvalue()
    files[2].unlink()
    (out / "chunks" / f"000002-{hashlib.blake2b(blob, digest_size=16).hexdigest()}.npz").write_bytes(blob)
    (out / "chunks" / ".000003-x.npz.tmp-1").write_bytes(b"partial")  # a killed write
    res = fitting.sweep(tiny, PARAMS, chunk_size=4, out=out, progress=False, devices=1)
    _equal(res.outputs, reference)
    assert res.chunks_computed == 3 and res.chunks_reused == 3
    after = _shards(out)
    assert len(after) == 6 and not (out / "chunks" / ".000003-x.npz.tmp-1").exists()
    for f in files[3:]:
        assert after[f.name] == keep[f.name]


@pytest.fixture(scope="module")
def dask_client():
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1, host="127.0.0.1",
                                       dashboard_address=None, worker_dashboard_address=None)
    client = distributed.Client(cluster)
    yield client
    client.close()
    cluster.close()


def test_dask_cluster_equals_local_run(dask_client, tmp_path, reference):
    local = fitting.sweep(tiny, PARAMS, chunk_size=5, progress=False, devices=1)
    res = fitting.sweep(tiny, PARAMS, chunk_size=5, client=dask_client, out=tmp_path / "d", progress=False)
    _equal(res.outputs, local.outputs)
    _equal(res.outputs, reference)
    assert len(dask_client.nthreads()) == 2
    # the same store resumes from a local run: the engines write the same shards
    again = fitting.sweep(tiny, PARAMS, chunk_size=5, out=tmp_path / "d", progress=False)
    assert again.chunks_reused == 5 and again.chunks_computed == 0


def test_failed_rows_are_marked_with_reasons_and_the_rest_complete(reference):
    res = fitting.sweep(tiny, PARAMS, chunk_size=7, progress=False)
    a, b = PARAMS["a"], PARAMS["b"]
    nan = a + 1.0 < 0  # log of a negative number
    inf = a + 1.0 == 0
    stalled = b > 25
    np.testing.assert_array_equal(res.failed, nan | inf | stalled)
    np.testing.assert_array_equal(res.status, np.where(stalled, int(pj.Status.STALLED),
                                                       np.where(nan | inf, int(pj.Status.NONFINITE), 0)))
    reasons = res.reasons
    for i in range(len(a)):
        assert ("STALLED" in reasons[i]) == stalled[i]
        assert ("non-finite values (NaN or inf) in output s" in reasons[i]) == (nan[i] or inf[i])
        assert (reasons[i] == "") == (not res.failed[i])
    ok = ~res.failed
    np.testing.assert_array_equal(res.outputs["y"][ok], np.asarray(reference["y"])[ok])


def test_table_joins_outputs_to_parameters():
    P = {**PARAMS, "label": np.array([f"row{i}" for i in range(24)])}
    res = fitting.sweep(tiny, P, chunk_size=10, progress=False)
    t = res.table()
    assert list(t) == ["a", "b", "label", "s", "status", "y[0]", "y[1]", "y[2]", "failed", "reason"]
    want = tiny_numpy(PARAMS["a"], PARAMS["b"])
    np.testing.assert_allclose(t["y[2]"], want["y"][:, 2], rtol=1e-14)
    np.testing.assert_array_equal(t["label"], P["label"])
    np.testing.assert_array_equal(t["a"], PARAMS["a"])
    assert t["reason"][23] == res.reason(23) != ""
    pd = pytest.importorskip("pandas")
    df = res.table(pandas=True)
    assert isinstance(df, pd.DataFrame) and df.shape == (24, 10)


def test_progress_bar_honours_progress_flag(capsys):
    fitting.sweep(tiny, PARAMS, chunk_size=8, progress=False)
    assert capsys.readouterr().err == ""
    fitting.sweep(tiny, PARAMS, chunk_size=8, progress=True)
    assert "24/24" in capsys.readouterr().err


def test_progress_as_a_function_gets_the_rows_done_of_all(capsys, tmp_path):
    """``progress=f``: ``f(done, total)`` before the first chunk and after each (24 rows in chunks
    of 10: 0, 10, 20, 24); a restart counts the chunks already stored as done. No bar is drawn."""
    calls = []
    record = lambda done, total: calls.append((done, total))  # noqa: E731
    fitting.sweep(tiny, PARAMS, chunk_size=10, out=tmp_path / "s", progress=record)
    assert calls == [(0, 24), (10, 24), (20, 24), (24, 24)] and capsys.readouterr().err == ""
    (shard,) = (tmp_path / "s" / "chunks").glob("000002-*.npz")  # the last chunk, to compute again
    shard.unlink()
    calls.clear()
    fitting.sweep(tiny, PARAMS, chunk_size=10, out=tmp_path / "s", progress=record)
    assert calls == [(20, 24), (24, 24)]
    with pytest.raises(TypeError, match="`progress`"):
        fitting.sweep(tiny, PARAMS, chunk_size=10, progress="yes")


def test_grid_is_the_cartesian_product():
    g = fitting.grid(x=[1.0, 2.0], y=[10.0, 20.0, 30.0], z=[0.5])
    rows = list(itertools.product([1.0, 2.0], [10.0, 20.0, 30.0], [0.5]))
    np.testing.assert_array_equal(np.stack([g["x"], g["y"], g["z"]], 1), np.array(rows))


def test_latin_hypercube_has_one_sample_per_stratum():
    n = 50
    s = fitting.latin_hypercube({"k": (0.5, 4.0), "tau": (0.05, 0.2)}, n, seed=3)
    for name, (lo, hi) in {"k": (0.5, 4.0), "tau": (0.05, 0.2)}.items():
        strata = np.floor((s[name] - lo) / (hi - lo) * n).astype(int)
        np.testing.assert_array_equal(np.sort(strata), np.arange(n))
    again = fitting.latin_hypercube({"k": (0.5, 4.0), "tau": (0.05, 0.2)}, n, seed=3)
    np.testing.assert_array_equal(s["k"], again["k"])
    assert not np.array_equal(s["k"], fitting.latin_hypercube({"k": (0.5, 4.0), "tau": (0, 1)}, n, seed=4)["k"])


def test_sobol_points_are_a_binary_net():
    n = 64
    s = fitting.sobol({"a": (-1.0, 1.0), "b": (0.0, 8.0)}, n, seed=1)
    # (0, m, 2)-net in base 2: every elementary box of area 1/n (2^i x 2^(m-i)) holds exactly one point
    u = np.stack([(s["a"] + 1.0) / 2.0, s["b"] / 8.0], 1)
    for i in range(7):
        cells = np.floor(u[:, 0] * 2**i).astype(int) * 2 ** (6 - i) + np.floor(u[:, 1] * 2 ** (6 - i)).astype(int)
        np.testing.assert_array_equal(np.sort(cells), np.arange(n))


def test_params_from_csv(tmp_path):
    f = tmp_path / "subjects.csv"
    f.write_text("# per-subject parameters\nsubject,K_PS,K_FE,q_ps\nS1,0.5,1.5,0.08\nS2, 0.7 ,1.2,-0.01\n")
    p = fitting.params_from_csv(f, labels=("subject",))
    np.testing.assert_array_equal(p["subject"], ["S1", "S2"])
    np.testing.assert_array_equal(p["K_FE"], [1.5, 1.2])
    np.testing.assert_array_equal(p["K_PS"], [0.5, 0.7])
    res = fitting.sweep(lambda r: r["K_PS"] + r["K_FE"], p, chunk_size=2, progress=False)
    np.testing.assert_allclose(res.outputs, [2.0, 1.9], rtol=1e-15)
    assert list(res.table()) [:2] == ["subject", "K_PS"]


@pytest.mark.bad_input("fitting.params_from_csv")
def test_params_from_csv_bad_files(tmp_path):
    cases = {
        "": "empty",
        "a,b\n": "no data rows",
        "a,a\n1,2\n": "line 1",
        "a,b\n1,2\n3\n": "line 3: 1 fields",
        "a,b\n1,2\n3,x\n": r"line 3, column 2 \('b'\): 'x' is not a finite number",
        "a,b\n1,nan\n": r"line 2, column 2 \('b'\)",
        "a,b\n1,\n": "empty field",
    }
    for i, (text, msg) in enumerate(cases.items()):
        f = tmp_path / f"bad{i}.csv"
        f.write_text(text)
        with pytest.raises(ValueError, match=msg) as e:
            fitting.params_from_csv(f)
        assert str(f) in str(e.value)
    f = tmp_path / "ok.csv"
    f.write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match="label column"):
        fitting.params_from_csv(f, labels=("subject",))


@pytest.mark.bad_input("fitting.grid", "fitting.latin_hypercube", "fitting.sobol")
def test_samplers_bad_input():
    with pytest.raises(ValueError, match="grid axis `b`"):
        fitting.grid(a=[1, 2], b=[])
    with pytest.raises(ValueError, match="grid axis `a`"):
        fitting.grid(a=[[1, 2]])
    with pytest.raises(ValueError, match=r"bounds\['k'\]"):
        fitting.latin_hypercube({"k": (2.0, 1.0)}, 10)
    with pytest.raises(ValueError, match="`n`"):
        fitting.latin_hypercube({"k": (0.0, 1.0)}, 0)
    with pytest.raises(ValueError, match="power of two"):
        fitting.sobol({"k": (0.0, 1.0)}, 100)
    with pytest.raises(TypeError, match="bounds"):
        fitting.sobol([(0.0, 1.0)], 8)


@pytest.mark.bad_input("fitting.sweep")
def test_sweep_bad_input_raises_before_any_work(tmp_path):
    out = tmp_path / "never"
    with pytest.raises(ValueError, match=r"same number of rows.*'b': 3"):
        fitting.sweep(tiny, {"a": np.ones(4), "b": np.ones(3)}, chunk_size=2, out=out)

    def not_jittable(p):
        return p["a"] if float(p["a"]) > 0 else -p["a"]

    with pytest.raises(TypeError, match="`fn` is not jit-able"):
        fitting.sweep(not_jittable, PARAMS, chunk_size=2, out=out)

    def branches(p):
        if p["a"] > 0:
            return p["a"]
        return -p["a"]

    with pytest.raises(TypeError, match="`fn` is not jit-able"):
        fitting.sweep(branches, PARAMS, chunk_size=2, out=out)
    with pytest.raises(ValueError, match=r"KeyError\('c'\).*\['a', 'b'\]"):
        fitting.sweep(lambda p: p["c"], {**PARAMS, "name": np.array(["x"] * 24)}, chunk_size=2, out=out)
    with pytest.raises(TypeError, match="`fn` must be callable"):
        fitting.sweep("tiny", PARAMS, chunk_size=2, out=out)
    with pytest.raises(ValueError, match="`chunk_size`"):
        fitting.sweep(tiny, PARAMS, chunk_size=0, out=out)
    with pytest.raises(ValueError, match=r"params\['a'\]` contains NaN"):
        fitting.sweep(tiny, {"a": np.array([1.0, np.nan]), "b": np.ones(2)}, chunk_size=2, out=out)
    with pytest.raises(TypeError, match="`params` must be a non-empty dict"):
        fitting.sweep(tiny, [PARAMS["a"]], chunk_size=2, out=out)
    with pytest.raises(ValueError, match="`devices`"):
        fitting.sweep(tiny, PARAMS, chunk_size=2, out=out, devices=len(jax.local_devices()) + 1)
    with pytest.raises(TypeError, match="`client`"):
        fitting.sweep(tiny, PARAMS, chunk_size=2, out=out, client=object())
    with pytest.raises(TypeError, match="`progress`"):
        fitting.sweep(tiny, PARAMS, chunk_size=2, out=out, progress="no")
    assert not out.exists()

    # an `out` that holds another sweep's store: refused, its shards untouched
    other = tmp_path / "other"
    fitting.sweep(tiny, PARAMS, chunk_size=6, out=other, progress=False)
    before = _shards(other)
    with pytest.raises(ValueError, match="another sweep's store.*params"):
        fitting.sweep(tiny, {**PARAMS, "b": PARAMS["b"] + 1.0}, chunk_size=6, out=other, progress=False)
    with pytest.raises(ValueError, match="another sweep's store.*chunk_size"):
        fitting.sweep(tiny, PARAMS, chunk_size=4, out=other, progress=False)
    with pytest.raises(ValueError, match="another sweep's store.*fn"):
        fitting.sweep(lambda p: tiny(p), PARAMS, chunk_size=6, out=other, progress=False)
    assert _shards(other) == before
    junk = tmp_path / "junk"
    junk.mkdir()
    (junk / "notes.txt").write_text("mine")
    with pytest.raises(ValueError, match="non-empty directory without a sweep manifest"):
        fitting.sweep(tiny, PARAMS, chunk_size=6, out=junk, progress=False)


def test_donders_power_rows_report_the_fits_status_codes():
    # The power-analysis rows carry fitting's Status codes as the fit returns them: one LM step
    # cannot have converged (MAX_STEPS), 3 postures cannot determine 8 parameters (TOO_FEW_DATA).
    from functools import partial

    from fitting._sweep import donders_power_row

    rows = dict(logK=jnp.zeros((2, 5)), q_rest=jnp.zeros((2, 3)), n_postures=jnp.array([40, 3]),
                noise_deg=jnp.array([0.5, 0.5]), seed=jnp.array([0, 1]))
    out = jax.jit(jax.vmap(partial(donders_power_row, n_max=40, n_starts=1, max_steps=1)))(rows)
    assert [int(s) for s in out["status"]] == [int(pj.Status.MAX_STEPS), int(pj.Status.TOO_FEW_DATA)]


def test_a_stalled_chunk_raises_and_keeps_the_finished_chunks(tmp_path, monkeypatch, reference):
    # A chunk whose computation does not finish while the process uses no CPU (an XLA:CPU
    # deadlock; here the last chunk's outputs never become ready) fails with an explanation
    # instead of hanging; the chunks finished before stay in the store and a new run resumes.
    from fitting._sweep import engines

    release = threading.Event()

    class Never:
        def is_ready(self):
            return False

        def block_until_ready(self):
            release.wait()

    init = engines._LocalEngine.__init__

    def stalling_init(self, *args, **kwargs):
        init(self, *args, **kwargs)
        kernel, calls = self.kernel, []

        def run(args):
            calls.append(None)
            out = kernel(args)
            return out if len(calls) < 3 else jax.tree_util.tree_map(lambda _: Never(), out)

        self.kernel = run

    monkeypatch.setattr(engines._LocalEngine, "__init__", stalling_init)
    monkeypatch.setattr(engines, "STALL_SECONDS", 0.3)
    t0 = time.perf_counter()
    try:
        with pytest.raises(RuntimeError, match=r"sweep chunk 2 stalled: .*XLA:CPU deadlocks"):
            fitting.sweep(tiny, PARAMS, chunk_size=9, out=tmp_path / "s", progress=False)
    finally:
        release.set()
    assert time.perf_counter() - t0 < 5.0
    monkeypatch.undo()
    again = fitting.sweep(tiny, PARAMS, chunk_size=9, out=tmp_path / "s", progress=False)
    assert (again.chunks_reused, again.chunks_computed) == (2, 1)
    _equal(again.outputs, reference)


def test_a_slow_chunk_that_computes_is_not_stalled():
    # Progress is CPU time: a chunk that takes longer than the stall window while the process
    # computes is waited for.
    from fitting._sweep.engines import _wait_computed

    start = time.monotonic()

    class Busy:
        def is_ready(self):
            return time.monotonic() - start > 1.0

        def block_until_ready(self):
            time.sleep(max(0.0, 1.0 - (time.monotonic() - start)))

    def burn():
        while time.monotonic() - start < 1.1:
            sum(range(1000))

    t = threading.Thread(target=burn)
    t.start()
    try:
        _wait_computed([Busy()], "sweep chunk 0", stall_seconds=0.2)
    finally:
        t.join()
