"""The command line's runner: artefacts, report, skipping, failures, interruption, bad input."""

import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from pmpjax import _cli

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce")
    res = _cli.reproduce(out, quick=True, only=["figure3", "figure4"], progress=False, cache=False)
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
    assert saved["figure3"]["results"]["max_final_task_error_m"] < 1e-6
    assert "jax" in saved["_meta"]["versions"]


def test_rerun_skips_finished_parts_unless_forced(run_dir):
    out, _ = run_dir
    png = out / "figure4_summed_moves.png"
    before = png.stat().st_mtime_ns
    _cli.reproduce(out, quick=True, only=["figure4"], progress=False, cache=False)
    assert png.stat().st_mtime_ns == before
    _cli.reproduce(out, quick=True, only=["figure4"], force=True, progress=False, cache=False)
    assert png.stat().st_mtime_ns > before


def test_a_failing_part_is_reported_and_the_others_run(tmp_path, monkeypatch):
    def broken(ctx):
        """A part that fails."""
        raise RuntimeError("boom")

    parts = {"broken": broken, "figure4": _cli.figure4_part}
    monkeypatch.setattr(_cli, "available_parts", lambda: parts)
    res = _cli.reproduce(tmp_path, quick=True, progress=False, cache=False)
    assert res["broken"]["status"] == "failed" and "boom" in res["broken"]["error"]
    assert "RuntimeError" in (tmp_path / "broken.error.txt").read_text()
    assert res["figure4"]["status"] == "ok"
    assert "Failed" in (tmp_path / "report.html").read_text()


def test_an_interrupted_run_keeps_the_parts_already_written(tmp_path):
    script = textwrap.dedent(f"""
        import time
        from pmpjax import _cli
        def hang(ctx):
            '''Never ends.'''
            time.sleep(600)
        _cli.available_parts = lambda: {{"figure4": _cli.figure4_part, "hang": hang}}
        _cli.reproduce({str(tmp_path)!r}, quick=True, progress=False, cache=False)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], env={**os.environ, "MPLBACKEND": "Agg"})
    results = tmp_path / "results.json"
    try:
        deadline = time.time() + 240
        while time.time() < deadline:
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


def test_command_line_bad_input_is_one_line_and_exit_2(capsys):
    assert _cli.main(["reproduce", "--only", "no_such_part", "--no-cache"]) == 2
    err = capsys.readouterr().err
    assert "no_such_part" in err and "Traceback" not in err
