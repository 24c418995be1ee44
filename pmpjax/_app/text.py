"""Text the command line prints: help from docstrings without their markup, counts with their
nouns, and option values checked as they are parsed."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

_CODE = re.compile(r"``(.+?)``")


def plain(text: str) -> str:
    """``text`` (a docstring) as it reads on a terminal: RST inline code ````x```` as ``x``, a
    literal block's ``::`` as ``:``, Markdown ``**bold**`` as its words."""
    text = _CODE.sub(r"\1", text)
    text = re.sub(r"\*\*(.+?)\*\*", r"\1", text)
    return re.sub(r"::(?=\s*$)", ":", text, flags=re.MULTILINE)


def plural(n: int, noun: str, nouns: str | None = None) -> str:
    """``n`` and the noun in its number: ``1 subject``, ``2 subjects``, ``0 subjects``."""
    return f"{n} {noun if n == 1 else nouns or noun + 's'}"


def positive_int(text: str) -> int:
    """An ``argparse`` type: a positive integer, else a usage error naming the option."""
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return n


def example_help(name: str) -> str:
    """The ``--help`` line pointing to a shipped example file (``pmpjax/data/examples/name``)."""
    path = Path(__file__).parents[1] / "data" / "examples" / name
    return f"Example: {path} (copy it to start from your own: cp {path} .)"
