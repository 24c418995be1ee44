"""The main job's report: ``report.md`` and a self-contained ``report.html`` (figures embedded
as base64 PNG, tables inline) showing every figure and table a part recorded, each with what it
shows and the paper's corresponding figure or number, plus versions, seed and wall times."""

from __future__ import annotations

import base64
import csv
import html
from pathlib import Path

TITLE = "pmpjax — reproduced results"
INTRO = (
    "Results of the three papers that pmpjax reproduces, computed on the embedded defaults: "
    "λ0-PMP (Tommasino & Campolo 2017), IK weights (Khoramshahi et al. 2022) and postural "
    "primitives (Williamson 1996). Each figure and table says what it shows and, in italics, "
    "what the paper reports for comparison."
)


def _parts(results: dict):
    return [(k, v) for k, v in results.items() if not k.startswith("_")]


def _read_csv(path: Path, max_rows: int = 60):
    with path.open() as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1 : max_rows + 1], max(len(rows) - 1 - max_rows, 0)


def write_report(out: Path, results: dict) -> tuple[Path, Path]:
    """Write ``report.md`` and ``report.html`` into ``out`` from ``results`` (results.json)."""
    out = Path(out)
    meta = results.get("_meta", {})
    md = [f"# {TITLE}", "", INTRO, ""]
    body = [f"<h1>{html.escape(TITLE)}</h1>", f"<p>{html.escape(INTRO)}</p>"]
    # Summary table of parts.
    md += ["| part | status | wall time [s] | what it is |", "|---|---|---:|---|"]
    rows_html = []
    for name, entry in _parts(results):
        status = entry.get("status", "?")
        summary = " ".join(entry.get("doc", "").split())  # one table row, however the docstring wraps
        md.append(f"| [{name}](#{name}) | {status} | {entry.get('seconds', '')} | {summary} |")
        cls = "ok" if status == "ok" else "failed"
        rows_html.append(
            f"<tr><td><a href='#{name}'>{name}</a></td><td class='{cls}'>{status}</td>"
            f"<td>{entry.get('seconds', '')}</td><td>{html.escape(entry.get('doc', ''))}</td></tr>"
        )
    body.append("<table><tr><th>part</th><th>status</th><th>wall time [s]</th><th>what it is</th></tr>"
                + "".join(rows_html) + "</table>")
    for name, entry in _parts(results):
        md += ["", f"## {name}", "", entry.get("doc", "")]
        body.append(f"<h2 id='{name}'>{html.escape(name)}</h2><p>{html.escape(entry.get('doc', ''))}</p>")
        if entry.get("status") == "failed":
            md += ["", f"**Failed:** `{entry.get('error', '')}` (traceback in `{name}.error.txt`)"]
            body.append(f"<p class='failed'>Failed: {html.escape(entry.get('error', ''))}</p>")
        for a in entry.get("artefacts", []):
            path = out / a["path"]
            paper = f" *Paper: {a['paper']}*" if a.get("paper") else ""
            md += ["", f"**{a['path']}** — {a['caption']}{paper}", ""]
            paper_html = f" <em>Paper: {html.escape(a['paper'])}</em>" if a.get("paper") else ""
            cap = f"<p><b>{html.escape(a['path'])}</b> — {html.escape(a['caption'])}{paper_html}</p>"
            if a["kind"] == "figure":
                md.append(f"![{a['path']}]({a['path']})")
                data = base64.b64encode(path.read_bytes()).decode() if path.exists() else ""
                body.append(f"<figure>{cap}<img alt='{html.escape(a['path'])}' "
                            f"src='data:image/png;base64,{data}'></figure>")
            else:
                md.append(f"[{a['path']}]({a['path']})")
                table = ""
                if path.exists():
                    head, rows, more = _read_csv(path)
                    md += ["", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
                    md += ["| " + " | ".join(r) + " |" for r in rows]
                    if more:
                        md.append(f"| … {more} more rows in {a['path']} |")
                    table = ("<table><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in head) + "</tr>"
                             + "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>"
                                       for r in rows) + "</table>")
                    if more:
                        table += f"<p>… {more} more rows in <a href='{a['path']}'>{a['path']}</a></p>"
                body.append(f"<div class='table'>{cap}<p><a href='{html.escape(a['path'])}'>"
                            f"{html.escape(a['path'])}</a></p>{table}</div>")
    run = f"Seed {meta.get('seed')}, quick = {meta.get('quick')}"
    if "wall_seconds" in meta:
        run += f"; the last run took {meta['wall_seconds']} s wall time with {meta.get('jobs', 1)} worker process(es)"
    run += "."
    md += ["", "## Run", "", run, ""]
    md += [f"- {k}: {v}" for k, v in meta.get("versions", {}).items()]
    body.append("<h2>Run</h2><p>" + html.escape(run)
                + "</p><ul>" + "".join(f"<li>{html.escape(str(k))}: {html.escape(str(v))}</li>"
                                       for k, v in meta.get("versions", {}).items()) + "</ul>")
    md_path, html_path = out / "report.md", out / "report.html"
    md_path.write_text("\n".join(md) + "\n")
    html_path.write_text(
        "<!doctype html><html><head><meta charset='utf-8'><title>" + html.escape(TITLE) + "</title><style>"
        "body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;line-height:1.45}"
        "img{max-width:100%;border:1px solid #ddd}table{border-collapse:collapse;margin:.5em 0;font-size:.9em}"
        "td,th{border:1px solid #ccc;padding:2px 6px;text-align:right}th{background:#f3f3f3}"
        ".ok{color:#060}.failed{color:#b00}em{color:#555}figure{margin:1.5em 0}"
        "</style></head><body>" + "\n".join(body) + "</body></html>\n"
    )
    return md_path, html_path
