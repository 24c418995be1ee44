"""What every subcommand of fitting does the same way: float64 on, result tables written as CSV."""

from __future__ import annotations

import csv
from pathlib import Path


def enable_x64() -> None:
    """Compute in float64 (the commands' fits and their tolerances assume it)."""
    import jax

    jax.config.update("jax_enable_x64", True)


def write_csv(path: Path, rows: list[dict]) -> None:
    """``rows`` (dicts with the same keys) as a CSV file with a header."""
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
