"""MuJoCo on demand: lazy, quiet imports of ``mujoco`` / ``mujoco.mjx`` and MJCF loading.

``import pmpjax`` does not import MuJoCo (≈0.6 s, more for MJX): the springy arm and
``MjcfChain`` call :func:`import_mujoco` / :func:`import_mjx` when they first need them.

MJX 3.17 probes its optional Warp backend on import and *prints* (``print``, not ``warnings``)
``Failed to import warp: ...`` and ``Failed to import mujoco_warp: ...`` when Warp is not
installed. Warp is optional and unused here, so :func:`import_mjx` captures stdout during that
one import and writes back every other line; exceptions propagate unchanged.

MJCF loading (:func:`load_mj_model`) is shared by ``MjcfChain`` (``_chains``) and the springy
arm (``_springy_arm``), so neither imports the other.
"""

from __future__ import annotations

import contextlib
import functools
import io
import os
import sys
from typing import Any

from .validate import MissingFileError

_WARP_PROBE_LINES = ("Failed to import warp:", "Failed to import mujoco_warp:")


@functools.cache
def import_mujoco():
    """The ``mujoco`` module (imported on first use)."""
    import mujoco

    return mujoco


@functools.cache
def import_mjx():
    """The ``mujoco.mjx`` module, imported on first use without MJX's Warp-probe messages."""
    if "mujoco.mjx" in sys.modules:
        return sys.modules["mujoco.mjx"]
    buf = io.StringIO()
    try:
        with contextlib.redirect_stdout(buf):
            from mujoco import mjx
    finally:
        kept = [ln for ln in buf.getvalue().splitlines(keepends=True) if not ln.startswith(_WARP_PROBE_LINES)]
        if kept:
            sys.stdout.write("".join(kept))
    return mjx


def is_mj_model(x: Any) -> bool:
    """True for a ``mujoco.MjModel`` (without importing MuJoCo when it is not loaded yet)."""
    mujoco = sys.modules.get("mujoco")
    return mujoco is not None and isinstance(x, mujoco.MjModel)


def load_spec(xml_or_model, *, name: str = "xml_or_model"):
    """``(spec, model)`` for an MJCF path or string (``spec`` a ``mujoco.MjSpec``), or
    ``(None, model)`` for a ``mujoco.MjModel`` (a compiled model has no editable spec).

    Raises ``TypeError`` for other types and a one-line ``ValueError`` for files or strings
    MuJoCo cannot load: a file's error starts with its path (a folder, a missing file and a file
    MuJoCo cannot read say so), a string's with ``name``; MuJoCo's message (line, element) follows.
    """
    mujoco = import_mujoco()
    if isinstance(xml_or_model, mujoco.MjModel):
        return None, xml_or_model
    if not isinstance(xml_or_model, str):
        raise TypeError(f"`{name}` must be a path, MJCF string or mujoco.MjModel, got {type(xml_or_model).__name__}")
    is_text = xml_or_model.lstrip().startswith("<")
    where = f"`{name}`" if is_text else xml_or_model
    if not is_text:
        if os.path.isdir(xml_or_model):
            raise ValueError(f"{where}: is a folder, not an MJCF file")
        if not os.path.isfile(xml_or_model):
            raise MissingFileError(f"{where}: no such file")
    try:
        spec = mujoco.MjSpec.from_string(xml_or_model) if is_text else mujoco.MjSpec.from_file(xml_or_model)
        return spec, spec.compile()
    except ValueError as e:
        why = " ".join(str(e).split())  # (MuJoCo's messages span several lines)
        if "could not find decoder" in why:
            why = "MuJoCo reads MJCF from .xml files"
        raise ValueError(f"{where}: not a loadable MJCF model: {why}") from e


def load_mj_model(xml_or_model, *, name: str = "xml_or_model"):
    """A ``mujoco.MjModel`` from an MJCF path, an MJCF string or a model (returned as is)."""
    return load_spec(xml_or_model, name=name)[1]
