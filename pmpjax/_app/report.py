"""The main job's report: ``report.md`` and a self-contained ``report.html`` (figures embedded
as base64 PNG, tables inline) showing every figure and table a part recorded, each with what it
shows and the paper's corresponding figure or number, links to every other file in the output
folder, plus versions, seed and wall times."""

from __future__ import annotations

import base64
import csv
import html
import re
from pathlib import Path
from urllib.parse import quote

TITLE = "pmpjax — reproduced results"
INTRO = (
    "Results of the three papers that pmpjax reproduces, computed on the embedded defaults: "
    "λ0-PMP (Tommasino & Campolo 2017), IK weights (Khoramshahi et al. 2022) and postural "
    "primitives (Williamson 1996). Each figure and table says what it shows and, in italics, "
    "what the paper reports for comparison."
)
#: Files listed under "Other files" at most (an output folder may hold much else).
MAX_OTHER_FILES = 300

_MARKUP = re.compile(r"``(.+?)``|`([^`\n]+)`|\*\*(.+?)\*\*")
_INT = re.compile(r"[+-]?\d+")
_FLOAT = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")
#: A number in prose after a comparison ("p = 3.1e-05", "< 0.001"), or with an exponent: kept on one line.
_PROSE_NUMBER = re.compile(r"(?:\b[pF]\s?(?:=|&lt;|&gt;|≤|≥)\s?|(?:&lt;|&gt;|≤|≥|≈)\s?)"
                           r"[-+−]?\d+(?:\.\d+)?(?:[eE][-+−]?\d+)?|[-+−]?\d+(?:\.\d+)?[eE][-+−]?\d+")
#: Unit suffixes of column names shown as units in brackets ("tau0_s" as "tau0 [s]").
_UNIT_SUFFIXES = {"_m_per_s": "m/s", "_rad_s": "rad/s", "_deg": "deg", "_rad": "rad", "_ms": "ms", "_s": "s",
                  "_Nm": "Nm", "_m": "m", "_N": "N"}
#: Tables longer than this are folded (a summary line opens them).
FOLD_ROWS = 12
#: Shown for a number that is not one (NaN: no data, no test).
MISSING = "—"


def convergence(results) -> tuple[int, int] | None:
    """``(n_converged, n_total)`` of a part's results: their ``converged`` as ``[n, total]`` (two
    integers) or as one boolean per fit (nested lists); None without such an entry."""
    c = results.get("converged") if isinstance(results, dict) else None
    if not isinstance(c, list | tuple):
        return None
    if len(c) == 2 and all(isinstance(v, int) and not isinstance(v, bool) for v in c):
        return int(c[0]), int(c[1])
    flat, stack = [], [c]
    while stack:
        for v in stack.pop():
            (stack.append if isinstance(v, list | tuple) else flat.append)(v)
    if flat and all(isinstance(v, bool) for v in flat):
        return sum(flat), len(flat)
    return None


def part_status(entry: dict) -> tuple[str, str]:
    """The status of a part's ``results.json`` entry as shown, e.g. ``ok, 3/12 converged``, and
    its class: "ok", "partial" (not every fit converged) or "failed" (the part failed, or it ran
    but none of its fits converged: ``none of 12 fits converged``)."""
    status = entry.get("status", "?")
    if status != "ok":
        return status, "failed"
    c = entry.get("converged") or convergence(entry.get("results"))
    if c and c[0] == 0 and c[1] > 0:
        return f"none of {c[1]} fits converged", "failed"
    if c and c[0] < c[1]:
        return f"ok, {c[0]}/{c[1]} converged", "partial"
    return "ok", "ok"


def _inline(text: str) -> str:
    """``text`` as HTML: its RST or Markdown inline code (double or single backticks) as ``<code>``,
    Markdown ``**bold**`` as ``<b>``."""
    out, pos = [], 0
    for m in _MARKUP.finditer(text):
        tag = "b" if m[3] else "code"
        out += [_nowrap_numbers(html.escape(text[pos:m.start()])),
                f"<{tag}>{html.escape(m[1] or m[2] or m[3])}</{tag}>"]
        pos = m.end()
    return "".join(out) + _nowrap_numbers(html.escape(text[pos:]))


def _nowrap_numbers(escaped: str) -> str:
    """HTML-escaped prose with each number (and the comparison before it) on one line."""
    return _PROSE_NUMBER.sub(lambda m: f"<span class='nw'>{m[0]}</span>", escaped)


def _paper(text: str) -> str:
    """The paper reference, labelled "Paper:" unless it names the paper itself."""
    return text if re.search(r"\bpapers?\b", text, re.IGNORECASE) else f"Paper: {text}"


def header(column: str) -> str:
    """A CSV column name as shown: a unit suffix in brackets (``tau0_s`` as ``tau0 [s]``)."""
    if "[" not in column:
        for suffix, unit in _UNIT_SUFFIXES.items():
            if column.endswith(suffix) and len(column) > len(suffix):
                return f"{column[:-len(suffix)]} [{unit}]"
    return column


def is_number(shown: str) -> bool:
    """A shown cell that is a number (right-aligned, never wrapped) or the mark of a missing one."""
    return shown == MISSING or bool(_FLOAT.fullmatch(shown)) or shown.lower() in ("inf", "-inf", "+inf")


def _cell(value: str, column: str) -> str:
    """A CSV cell as shown: status codes by name, numbers to about four significant digits, NaN
    as "—"."""
    if value.strip().lower() in ("nan", "+nan", "-nan"):
        return MISSING
    if column.strip().lower() == "status" and _INT.fullmatch(value):
        from .._base import Status

        try:
            return Status(int(value)).name
        except ValueError:
            return value
    if _INT.fullmatch(value) or not _FLOAT.fullmatch(value):
        return value
    x = float(value)
    return f"{x:.0f}" if 1e4 <= abs(x) < 1e15 else f"{x:.4g}"


def _numeric_column(rows, i: int) -> bool:
    """Every shown cell of column ``i`` a number (or missing)."""
    cells = [r[i] for r in rows if i < len(r) and r[i] != ""]
    return bool(cells) and all(is_number(c) for c in cells)


def _num(numeric: bool) -> str:
    return " class='num'" if numeric else ""


def section_title(name: str, entry: dict) -> str:
    """A part's section title: its ``title`` (a human one), else its name."""
    return entry.get("title") or name


def _href(path: str) -> str:
    return html.escape(quote(path), quote=True)


def _link(path: str) -> str:
    return f"<a href='{_href(path)}'>{html.escape(path)}</a>"


def _parts(results: dict):
    return [(k, v) for k, v in results.items() if not k.startswith("_")]


def _read_csv(path: Path, max_rows: int = 60):
    with path.open() as f:
        rows = list(csv.reader(f))
    head = rows[0] if rows else []
    body = [[_cell(c, head[i] if i < len(head) else "") for i, c in enumerate(r)] for r in rows[1 : max_rows + 1]]
    return head, body, max(len(rows) - 1 - max_rows, 0)


def _other_files(out: Path, linked: set[str]) -> list[str]:
    """Files under ``out`` (relative POSIX paths) that the report does not link otherwise."""
    found = []
    for p in sorted(out.rglob("*")):
        rel = p.relative_to(out).as_posix()
        if p.is_file() and rel not in linked and not rel.endswith(".tmp"):
            found.append(rel)
    return found


def write_report(out: Path, results: dict) -> tuple[Path, Path]:
    """Write ``report.md`` and ``report.html`` into ``out`` from ``results`` (results.json)."""
    out = Path(out)
    meta = results.get("_meta", {})
    linked = {"report.html", "report.md", "results.json"}
    everything = "Every number of the run: [results.json](results.json); this report also as [report.md](report.md)."
    md = [f"# {TITLE}", "", INTRO, "", everything, ""]
    body = [f"<h1>{html.escape(TITLE)}</h1>", f"<p>{html.escape(INTRO)}</p>",
            f"<p>Every number of the run: {_link('results.json')}; this report also as {_link('report.md')}.</p>"]
    md += ["| part | status | wall time [s] | what it is |", "|---|---|---:|---|"]
    rows_html = []
    for name, entry in _parts(results):
        label, cls = part_status(entry)
        doc = " ".join(entry.get("doc", "").split())  # one table row, however the docstring wraps
        title = section_title(name, entry)
        md.append(f"| [{title}](#{name}) | {label} | {entry.get('seconds', '')} | {doc} |")
        rows_html.append(
            f"<tr><td><a href='#{name}'>{html.escape(title)}</a></td><td class='{cls}'>{html.escape(label)}</td>"
            f"<td class='num'>{entry.get('seconds', '')}</td><td>{_inline(doc)}</td></tr>"
        )
    body.append("<div class='scroll'><table><tr><th>part</th><th>status</th><th class='num'>wall time [s]</th>"
                "<th>what it is</th></tr>" + "".join(rows_html) + "</table></div>")
    for name, entry in _parts(results):
        title = section_title(name, entry)
        md += ["", f"## {title}" + (f" (`{name}`)" if title != name else ""), "", entry.get("doc", "")]
        body.append(f"<h2 id='{name}'>{html.escape(title)}"
                    + (f" <small>(part <code>{html.escape(name)}</code>)</small>" if title != name else "")
                    + f"</h2><p>{_inline(entry.get('doc', ''))}</p>")
        label, cls = part_status(entry)
        if cls == "partial":
            md += ["", f"**Status: {label}** (the fits' status in results.json)"]
            body.append(f"<p class='partial'>Status: {html.escape(label)} (the fits' status in results.json)</p>")
        if entry.get("status") == "failed":
            md += ["", f"**Failed:** `{entry.get('error', '')}`"]
            body.append(f"<p class='failed'>Failed: {html.escape(entry.get('error', ''))}")
            if (out / f"{name}.error.txt").exists():
                linked.add(f"{name}.error.txt")
                md[-1] += f" (traceback in [{name}.error.txt]({quote(name)}.error.txt))"
                body[-1] += f" (traceback in {_link(name + '.error.txt')})"
            body[-1] += "</p>"
        for a in entry.get("artefacts", []):
            path = out / a["path"]
            linked.add(a["path"])
            paper = _paper(a["paper"]) if a.get("paper") else ""
            md += ["", f"**[{a['path']}]({quote(a['path'])})** — {a['caption']}" + (f" *{paper}*" if paper else ""), ""]
            paper_html = f" <em>{_inline(paper)}</em>" if paper else ""
            cap = f"<p><b>{_link(a['path'])}</b> — {_inline(a['caption'])}{paper_html}</p>"
            if a["kind"] == "figure":
                md.append(f"![{a['path']}]({quote(a['path'])})")
                data = base64.b64encode(path.read_bytes()).decode() if path.exists() else ""
                body.append(f"<figure>{cap}<img alt='{html.escape(a['path'])}' "
                            f"src='data:image/png;base64,{data}'></figure>")
            else:
                table = ""
                if path.exists():
                    head, rows, more = _read_csv(path)
                    head = [header(h) for h in head]
                    md += ["| " + " | ".join(head) + " |",
                           "|" + "".join("---:|" if _numeric_column(rows, i) else "---|" for i in range(len(head)))]
                    md += ["| " + " | ".join(r) + " |" for r in rows]
                    if more:
                        md.append(f"| … {more} more rows in {a['path']} |")
                    num = [_numeric_column(rows, i) for i in range(len(head))]
                    table = ("<div class='scroll'><table><tr>"
                             + "".join(f"<th{_num(num[i])}>{html.escape(h)}</th>" for i, h in enumerate(head))
                             + "</tr>" + "".join("<tr>" + "".join(f"<td{_num(is_number(c))}>{html.escape(c)}</td>"
                                                                  for c in r) + "</tr>"
                                                 for r in rows) + "</table></div>")
                    if more:
                        table += f"<p>… {more} more rows in {_link(a['path'])}</p>"
                    if len(rows) > FOLD_ROWS:
                        table = (f"<details><summary>{len(rows) + more} rows (click to show)</summary>{table}"
                                 "</details>")
                body.append(f"<div class='table'>{cap}{table}</div>")
    others = _other_files(out, linked)
    if others:
        shown, more = others[:MAX_OTHER_FILES], len(others) - MAX_OTHER_FILES
        md += ["", "## Other files in the output folder", ""] + [f"- [{f}]({quote(f)})" for f in shown]
        body.append("<h2 id='other-files'>Other files in the output folder</h2><ul>"
                    + "".join(f"<li>{_link(f)}</li>" for f in shown) + "</ul>")
        if more > 0:
            md.append(f"- … and {more} more")
            body.append(f"<p>… and {more} more</p>")
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
        "td,th{border:1px solid #ccc;padding:2px 6px;text-align:left;vertical-align:top}th{background:#f3f3f3}"
        ".num{text-align:right;white-space:nowrap}.nw{white-space:nowrap}summary{cursor:pointer;color:#333}"
        ".scroll{overflow-x:auto;max-width:100%}code{background:#f3f3f3;padding:0 .2em;border-radius:3px}"
        ".ok{color:#060}.partial{color:#b36b00}.failed{color:#b00}em{color:#555}figure{margin:1.5em 0}"
        "</style></head><body>" + "\n".join(body) + "</body></html>\n"
    )
    return md_path, html_path
