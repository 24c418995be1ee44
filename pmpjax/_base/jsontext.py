"""JSON as pmpjax writes it: strict JSON (NaN and ±inf as ``null``, which every JSON reader
accepts), NumPy and JAX arrays and scalars as lists and numbers."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path


def json_safe(obj):
    """``obj`` as plain JSON data: NaN and ±inf as None, arrays and NumPy/JAX scalars as lists and
    numbers, tuples as lists, paths and anything else as their string."""
    if obj is None or type(obj) in (bool, int, str):
        return obj
    if isinstance(obj, float):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, str):
        return str(obj)
    if isinstance(obj, int):  # (an IntEnum)
        return int(obj)
    if isinstance(obj, dict):
        return {k if isinstance(k, str | int | float | bool) or k is None else str(k): json_safe(v)
                for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_safe(v) for v in obj]
    if hasattr(obj, "tolist"):  # NumPy and JAX arrays and scalars
        return json_safe(obj.tolist())
    return str(obj)


def json_text(obj, **kwargs) -> str:
    """``json.dumps`` of :func:`json_safe` ``(obj)``, refusing anything that is not strict JSON."""
    return json.dumps(json_safe(obj), allow_nan=False, **kwargs)


def write_json(path: str | os.PathLike, obj, *, indent: int | None = 1) -> Path:
    """Write ``obj`` as strict JSON (:func:`json_text`) to ``path``."""
    path = Path(path)
    path.write_text(json_text(obj, indent=indent) + "\n")
    return path
