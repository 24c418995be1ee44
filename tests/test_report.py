"""The main job's report rendered from hand-made artefacts: inline code, paper references, wide
tables, numbers and status codes in tables, links to every file of the output folder."""

import csv
import json
import re

import pytest

import pmpjax as pj
from pmpjax._app.report import convergence, part_status, write_report

PNG = b"\x89PNG\r\n\x1a\n" + bytes(16)


@pytest.fixture
def report(tmp_path):
    out = tmp_path
    (out / "paths.png").write_bytes(PNG)
    head = ["subject", "status", "n", "value", "big", "tiny", "note"] + [f"extra_{k}" for k in range(30)]
    rows = [["S01", 0, 42, 0.123456789, 123456.7, 3e-7, "n/a"] + [1.5] * 30,
            ["S02", int(pj.Status.STALLED), 7, 1234.5678, -2.0, 0.5, "x"] + [2.25] * 30]
    with (out / "fits.csv").open("w", newline="") as f:
        csv.writer(f).writerows([head] + rows)
    (out / "results.json").write_text("{}")
    (out / "reaching_hugmp_summary.json").write_text("[]")
    (out / "reaching_hugmp_motions.csv").write_text("a\n1\n")
    (out / "pointing_data").mkdir()
    (out / "pointing_data" / "subj1.csv").write_text("t\n0\n")
    results = {
        "_meta": {"seed": 0, "quick": True, "versions": {"pmpjax": "0"}},
        "demo": {"status": "ok", "seconds": 1.0, "doc": "Curvature ``A_net`` per target and `KJ`.", "artefacts": [
            {"kind": "figure", "path": "paths.png", "caption": "Paths of ``simulate`` runs.",
             "paper": "Paper Figure 3: curved diagonal paths."},
            {"kind": "table", "path": "fits.csv", "caption": "Fits (`status` per subject).",
             "paper": "Williamson (1996) Figure 4."},
        ]},
        "unfinished": {"status": "ok", "converged": [1, 4], "seconds": 2.0, "doc": "Some fits.", "artefacts": [],
                       "results": {"converged": [1, 4]}},
    }
    write_report(out, results)
    return (out / "report.html").read_text(), (out / "report.md").read_text()


def test_inline_code_renders_as_code(report):
    html, md = report
    for name in ("A_net", "KJ", "simulate", "status"):
        assert f"<code>{name}</code>" in html
    assert "`" not in html
    assert "``A_net``" in md  # (Markdown renders it as code)


def test_paper_references_are_labelled_once(report):
    html, md = report
    for text in (html, md):
        assert "Paper: Paper" not in text and "Paper Figure 3: curved diagonal paths." in text
        assert "Paper: Williamson (1996) Figure 4." in text


def test_tables_scroll_inside_their_box(report):
    html, _ = report
    assert ".scroll{overflow-x:auto" in html
    assert html.count("<table") == html.count("<div class='scroll'><table") == 2


def test_table_numbers_and_status_codes(report):
    html, md = report
    cells = re.findall(r"<td(?: class='num')?>([^<]*)</td>", html)
    for shown in ("0.1235", "1235", "123457", "3e-07", "42", "-2", "0.5", "2.25", "SUCCESSFUL", "STALLED", "n/a"):
        assert shown in cells, shown
    assert "0.123456789" not in html and "1234.5678" not in html
    assert "| S02 | STALLED | 7 | 1235 | -2 | 0.5 | x |" in md


def test_every_file_of_the_output_folder_is_linked(report):
    html, md = report
    for path in ("paths.png", "fits.csv", "results.json", "report.md", "reaching_hugmp_summary.json",
                 "reaching_hugmp_motions.csv", "pointing_data/subj1.csv"):
        assert f"href='{path}'" in html, path
        assert f"]({path})" in md, path
    others = html.split("Other files in the output folder", 1)[1].split("</ul>", 1)[0]
    assert "reaching_hugmp_summary.json" in others and "fits.csv" not in others and "paths.png" not in others


def test_status_of_parts_whose_fits_did_not_all_converge(report):
    html, md = report
    assert "<td class='partial'>ok, 1/4 converged</td>" in html and "<td class='ok'>ok</td>" in html
    assert "| [unfinished](#unfinished) | ok, 1/4 converged |" in md
    assert part_status({"status": "ok", "results": {"converged": [True, False, True]}}) == \
        ("ok, 2/3 converged", "partial")
    assert part_status({"status": "ok", "converged": [3, 3]}) == ("ok", "ok")
    # a part whose every fit failed to converge is not "ok" (and the job exits 1 for it)
    assert part_status({"status": "ok", "converged": [0, 24]}) == ("none of 24 fits converged", "failed")
    assert part_status({"status": "ok", "results": {"converged": [False, False]}})[1] == "failed"
    assert part_status({"status": "failed"}) == ("failed", "failed")
    assert convergence({"converged": [[True, True], [False, True]]}) == (3, 4)
    assert convergence({"converged": [0.5, 1.0]}) is None and convergence({"converged": 3}) is None
    assert convergence(json.loads(json.dumps({"converged": [True, False]}))) == (1, 2)


def test_readable_tables_titles_and_numbers(tmp_path):
    """Prose columns left-aligned and numbers right-aligned on one line; NaN shown as "—"; a unit
    suffix shown as the unit in brackets; the part's human title as its section title (its name
    in small print); long tables folded; numbers in captions not broken across lines."""
    rows = [["subject", "note", "tau0_s", "p", "A_net [1]"]]
    rows += [[f"S{k:02d}", "a long sentence of prose in a table cell", 0.1 + k, "nan", 1e-5] for k in range(20)]
    with (tmp_path / "long.csv").open("w", newline="") as f:
        csv.writer(f).writerows(rows)
    results = {"_meta": {}, "ik_hugmp": {
        "status": "ok", "seconds": 1.0, "doc": "Weights.", "title": "IK weights of the HuG-MP recordings",
        "artefacts": [{"kind": "table", "path": "long.csv", "caption": "Hotelling T² = 225.3, p = 3.1e-05."}]}}
    write_report(tmp_path, results)
    html = (tmp_path / "report.html").read_text()
    md = (tmp_path / "report.md").read_text()
    assert "text-align:left" in html and ".num{text-align:right;white-space:nowrap}" in html
    assert "<th class='num'>tau0 [s]</th>" in html and "<th>note</th>" in html and "A_net [1]" in html
    assert "<td>a long sentence of prose in a table cell</td>" in html and "<td class='num'>0.1</td>" in html
    assert html.count("<td class='num'>—</td>") == 20 and ">nan<" not in html and "| — |" in md
    assert "<span class='nw'>p = 3.1e-05</span>" in html and ".nw{white-space:nowrap}" in html
    assert re.search(r"<h2 id='ik_hugmp'>IK weights of the HuG-MP recordings <small>\(part <code>ik_hugmp</code>"
                     r"\)</small></h2>", html)
    assert "## IK weights of the HuG-MP recordings (`ik_hugmp`)" in md
    assert "<a href='#ik_hugmp'>IK weights of the HuG-MP recordings</a>" in html
    assert "<details><summary>20 rows (click to show)</summary>" in html
    short = {"_meta": {}, "p": {"status": "ok", "doc": "", "artefacts": [
        {"kind": "table", "path": "short.csv", "caption": "Few rows."}]}}
    (tmp_path / "short.csv").write_text("a,b\n1,2\n")
    write_report(tmp_path, short)
    html = (tmp_path / "report.html").read_text()
    assert "<details>" not in html and "<h2 id='p'>p</h2>" in html
