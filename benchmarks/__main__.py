"""Run every benchmark: ``python -m benchmarks [--quick] [--only NAME ...]``.

Each script ``benchmarks/<name>.py`` runs in its own process (so compile caches and thread pools
do not leak between them) and writes ``<results>/<name>.json`` (``benchmarks/results/`` for full
runs, ``benchmarks/results/quick/`` with ``--quick``). The JSON holds ``ratios`` (name → value,
pmpjax against the baseline run in the same process), optionally ``targets`` (name → the ratio
the project aims for) and ``scaling`` (rows ``{"series", "B", "seconds"}``: cost per call at batch
size B). This runner prints one table of every ratio, writes ``summary.json`` and draws the
cost-versus-batch-size plot ``scaling.png``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def scripts() -> list[str]:
    return sorted(p.stem for p in HERE.glob("*.py") if not p.stem.startswith("_"))


def run(names, *, quick: bool, results: Path) -> dict:
    results.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "PMPJAX_BENCH_RESULTS": str(results), "MPLBACKEND": "Agg"}
    summary = {}
    for name in names:
        t0 = time.perf_counter()
        cmd = [sys.executable, str(HERE / f"{name}.py")] + (["--quick"] if quick else [])
        print(f"== {name}: {' '.join(cmd[1:])}", flush=True)
        proc = subprocess.run(cmd, env=env, cwd=HERE.parent)
        entry = {"returncode": proc.returncode, "seconds": round(time.perf_counter() - t0, 1)}
        path = results / f"{name}.json"
        if proc.returncode == 0 and path.exists():
            data = json.loads(path.read_text())
            entry.update(ratios=data.get("ratios", {}), targets=data.get("targets", {}),
                         scaling=data.get("scaling", []))
        summary[name] = entry
    return summary


def table(summary: dict) -> str:
    lines = ["| benchmark | ratio (pmpjax vs in-run baseline) | value | target | met |", "|---|---|---:|---:|---|"]
    for name, e in summary.items():
        if e["returncode"] != 0:
            lines.append(f"| {name} | FAILED (exit {e['returncode']}) | | | |")
            continue
        for k, v in e.get("ratios", {}).items():
            tgt = e.get("targets", {}).get(k)
            met = "" if tgt is None or v is None else ("yes" if v >= tgt else "no")
            val = "n/a" if v is None else f"{v:.3g}"
            lines.append(f"| {name} | {k} | {val} | {'' if tgt is None else f'{tgt:g}'} | {met} |")
    return "\n".join(lines)


def plot(summary: dict, path: Path) -> None:
    import matplotlib.pyplot as plt

    series = [(n, s) for n, e in summary.items() for s in _series(e.get("scaling", []))]
    if not series:
        return
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for name, (label, B, sec) in series:
        ax.loglog(B, sec, "o-", label=f"{name}: {label}")
    ax.set_xlabel("batch size B")
    ax.set_ylabel("seconds per call")
    ax.set_title("Cost versus batch size (this machine)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _series(rows):
    by = {}
    for r in rows:
        by.setdefault(r["series"], []).append((r["B"], r["seconds"]))
    for label, pts in by.items():
        pts.sort()
        yield label, [p[0] for p in pts], [p[1] for p in pts]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="small smoke sizes (a few minutes in all)")
    ap.add_argument("--only", nargs="+", choices=scripts(), metavar="NAME", help="run only these benchmarks")
    args = ap.parse_args(argv)
    results = HERE / "results" / ("quick" if args.quick else "")
    summary = run(args.only or scripts(), quick=args.quick, results=results)
    print("\n" + table(summary))
    (results / "summary.json").write_text(json.dumps(summary, indent=1))
    plot(summary, results / "scaling.png")
    print(f"\nwrote {results / 'summary.json'} and {results / 'scaling.png'}")
    return 0 if all(e["returncode"] == 0 for e in summary.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
