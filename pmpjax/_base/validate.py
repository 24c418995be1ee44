"""Python-side input checks, run before tracing. Value checks are skipped for tracers."""

from __future__ import annotations

import contextlib
import contextvars
import os
from pathlib import Path
from typing import Any

import jax
import numpy as np


def is_concrete(*xs: Any) -> bool:
    """True when no leaf is a JAX tracer (so values can be inspected in Python)."""
    return not any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(xs))


_X64_WARNED = []


def warn_without_x64() -> None:
    """Warn once per process when JAX computes in float32 (``jax_enable_x64`` off): the science
    here needs double precision, and without it results come back silently as float32."""
    if not jax.config.jax_enable_x64 and not _X64_WARNED:
        _X64_WARNED.append(True)
        import warnings

        warnings.warn("pmpjax: JAX runs in float32 (jax_enable_x64 is off): results lose precision. Turn it on "
                      "before creating arrays: jax.config.update('jax_enable_x64', True) or JAX_ENABLE_X64=1",
                      UserWarning, stacklevel=3)


def to_jax(x: Any, dtype=None):
    """``jnp.asarray(x, dtype)``; a NumPy array goes through ``jax.device_put`` (``jnp.asarray``
    compiles a copy per shape: 30-100 ms for each new shape of an eager call)."""
    if isinstance(x, np.ndarray | np.generic):
        return jax.device_put(x if dtype is None else np.asarray(x, dtype))
    return jax.numpy.asarray(x, dtype)


def as_array(name: str, x: Any, *, tail: tuple[int | None, ...] = (), finite: bool = True):
    """Convert ``x`` to a float array with trailing shape ``tail`` (``None`` = any size).

    Raises ``ValueError`` naming ``name`` on wrong rank/shape or NaN/inf (when concrete).
    """
    if x is None:
        raise ValueError(f"`{name}` is required, got None")
    if not isinstance(x, jax.Array | np.ndarray):
        try:
            x = np.asarray(x, dtype=float)
        except (TypeError, ValueError) as e:
            raise ValueError(f"`{name}` must be numeric, got {type(x).__name__}") from e
    shape = tuple(x.shape)
    if len(shape) < len(tail):
        raise ValueError(f"`{name}` must have trailing shape {_fmt(tail)}, got shape {shape}")
    for got, want in zip(shape[len(shape) - len(tail):], tail):
        if want is not None and got != want:
            raise ValueError(f"`{name}` must have trailing shape {_fmt(tail)}, got shape {shape}")
    if finite and is_concrete(x) and not np.all(np.isfinite(np.asarray(x))):
        raise ValueError(f"`{name}` contains NaN or inf")
    return x


def check_spd(name: str, M: Any, *, rtol: float = 1e-8) -> None:
    """Require ``M`` (..., n, n) symmetric positive definite (only when concrete)."""
    if not is_concrete(M):
        return
    a = np.asarray(M, dtype=float)
    if a.ndim < 2 or a.shape[-1] != a.shape[-2]:
        raise ValueError(f"`{name}` must be a square (..., n, n) matrix, got shape {a.shape}")
    scale = np.max(np.abs(a), axis=(-1, -2), keepdims=True) + 1e-300
    if np.any(np.abs(a - np.swapaxes(a, -1, -2)) > rtol * scale):
        raise ValueError(f"`{name}` must be symmetric")
    eig = np.linalg.eigvalsh(a)
    if np.any(eig <= 0):
        raise ValueError(
            f"`{name}` must be positive definite; smallest eigenvalue {eig.min():.3g}"
        )


def check_positive(name: str, x: Any) -> None:
    """Require every entry of ``x`` strictly positive and finite (only when concrete)."""
    if x is None or not is_concrete(x):
        return
    a = np.asarray(x, dtype=float)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"`{name}` contains NaN or inf")
    if np.any(a <= 0):
        raise ValueError(f"`{name}` must be positive, got {a.min() if a.size else a}")


def positive_float(name: str, v: Any) -> float:
    """A concrete, positive, finite scalar (durations and steps that set a step count) as ``float``;
    ``ValueError`` naming ``name`` when it is traced, NaN/inf or not positive."""
    if not is_concrete(v):
        raise ValueError(f"`{name}` must be a concrete Python float (it sets the step count)")
    if np.ndim(v) != 0:
        raise ValueError(f"`{name}` must be a scalar, got shape {np.shape(v)}")
    check_positive(name, v)
    return float(v)


def check_positive_int(name: str, v: Any, minimum: int = 1) -> int:
    """Require ``v`` to be an integer >= ``minimum`` (counts, step limits); returns ``int(v)``."""
    if int(v) != v or v < 1:
        raise ValueError(f"`{name}` must be a positive integer, got {v}")
    if v < minimum:
        raise ValueError(f"`{name}` must be >= {minimum}, got {v}")
    return int(v)


def check_prng_key(name: str, key: Any) -> None:
    """``key`` must be one JAX PRNG key: a typed key (``jax.random.key``) or a raw uint32 (2,)
    (``jax.random.PRNGKey``)."""
    dtype = getattr(key, "dtype", None)
    if dtype is not None and jax.numpy.issubdtype(dtype, jax.dtypes.prng_key) and np.shape(key) == ():
        return
    if dtype == np.uint32 and np.shape(key) == (2,):
        return
    raise TypeError(f"`{name}` must be one JAX PRNG key (jax.random.PRNGKey(seed)), got {key!r}")


def as_prng_key(name: str, seed: Any):
    """The JAX PRNG key of ``seed``: an integer gives ``jax.random.PRNGKey(seed)``, one key is passed
    through; ``TypeError`` naming ``name`` for anything else."""
    if isinstance(seed, int | np.integer) and not isinstance(seed, bool):
        return jax.random.PRNGKey(int(seed))
    try:
        check_prng_key(name, seed)
    except TypeError:
        raise TypeError(f"`{name}` must be an integer or one JAX PRNG key (jax.random.PRNGKey(seed)), "
                        f"got {seed!r}") from None
    return seed


def _fmt(tail: tuple[int | None, ...]) -> str:
    return "(..., " + ", ".join("?" if t is None else str(t) for t in tail) + ")"


def check_finite_masked(name: str, a, mask, *, labels=None, where: str = "") -> None:
    """Require ``a`` (S, N, k) finite wherever ``mask`` (S, N) is True; the error names ``name``,
    the count and the first offending (subject, sample). ``labels`` name subjects (default index)."""
    bad = np.asarray(mask) & ~np.all(np.isfinite(np.asarray(a)), axis=-1)
    if bad.any():
        s, i = np.argwhere(bad)[0]
        subject = repr(labels[s]) if labels is not None else int(s)
        prefix = f"{where}: " if where else ""
        raise ValueError(
            f"{prefix}`{name}` contains NaN or inf at {int(bad.sum())} valid sample(s); first: "
            f"subject {subject}, sample {int(i)} (mask them out or drop them)"
        )


def csv_floats(path, line: int, row, columns: dict, names) -> list[float]:
    """Finite floats of ``row``'s fields ``names`` (``columns`` maps a name to its 0-based index);
    a ``ValueError`` names the file, line, column and field of the first bad one."""
    out = []
    for name in names:
        i = columns[name]
        try:
            v = float(row[i])
        except ValueError:
            raise ValueError(f"{path}: line {line}, column {i + 1} ({name}): not a number: {row[i]!r}") from None
        if not np.isfinite(v):
            raise ValueError(f"{path}: line {line}, column {i + 1} ({name}): NaN or inf")
        out.append(v)
    return out


def as_path(name: str, path) -> Path:
    """``path`` as a ``Path``; ``TypeError`` naming ``name`` for anything but a str or os.PathLike."""
    if not isinstance(path, str | os.PathLike):
        raise TypeError(f"`{name}` must be a path (str or os.PathLike), got {type(path).__name__}")
    return Path(path)


class MissingFileError(FileNotFoundError, ValueError):
    """A file that is not there: both a ``FileNotFoundError`` and a ``ValueError`` (bad input)."""


def input_file(name: str, path) -> Path:
    """``path`` of an existing, non-empty regular file, else a ``ValueError`` naming the file
    (no such file, a directory, empty); ``TypeError`` naming ``name`` for a non-path."""
    path = as_path(name, path)
    if path.is_dir():
        raise ValueError(f"{path}: is a directory, not a file")
    if not path.is_file():
        raise MissingFileError(f"{path}: no such file")
    if path.stat().st_size == 0:
        raise ValueError(f"{path}: empty file")
    return path


def read_text_file(path: Path) -> str:
    """The UTF-8 text of ``path``; ``ValueError`` naming the file otherwise: a binary file (a NUL
    byte) as binary, UTF-16 or text in another encoding by its encoding or first non-UTF-8 byte."""
    data = path.read_bytes()
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise ValueError(f"{path}: UTF-16 text, not UTF-8; save it as UTF-8")
    if (i := data.find(b"\x00")) >= 0:
        line = data[:i].count(b"\n") + 1
        raise ValueError(f"{path}: a binary file (NUL byte at byte {i}, line {line}), not a text file")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = data[: e.start].count(b"\n") + 1
        raise ValueError(f"{path}: not a UTF-8 text file (line {line}, byte {e.start}: {data[e.start:e.start + 1]!r}): "
                         "text in another encoding (Latin-1, Windows-1252)? save it as UTF-8") from None


def open_npz(path):
    """The arrays of the NPZ archive ``path`` (``np.load``, no pickles), to use in a ``with``;
    ``ValueError`` naming the file when it is not one (a zip of ``.npy`` arrays, as ``numpy.savez``
    writes)."""
    import zipfile

    with open(path, "rb") as f:
        magic = f.read(6)
    if not magic.startswith((b"PK\x03\x04", b"PK\x05\x06")):
        what = "a single .npy array" if magic == b"\x93NUMPY" else "not a zip archive"
        raise ValueError(f"{path}: not an NPZ archive ({what}; expected the zip of .npy arrays that numpy.savez "
                         "writes)")
    try:
        return np.load(path, allow_pickle=False)
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as e:
        raise ValueError(f"{path}: not a readable NPZ archive ({e})") from None


def output_dir(name: str, path) -> Path:
    """The folder ``path``, created if missing and checked writable (a probe file is created and
    removed), so that a command fails before its work rather than after it; ``ValueError`` naming
    ``name`` when it is a file or cannot be created or written to."""
    import tempfile

    path = as_path(name, path)
    try:
        if path.exists() and not path.is_dir():
            raise ValueError(f"`{name}`: {path} is a file, not a folder")
        path.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ValueError(f"`{name}`: cannot create the folder {path} ({e.strerror})") from None
    try:
        fd, probe = tempfile.mkstemp(dir=path, prefix=".write-check-")
    except OSError as e:
        raise ValueError(f"`{name}`: cannot write to the folder {path} ({e.strerror})") from None
    os.close(fd)
    os.unlink(probe)
    return path


# --- units and ranges of times and joint angles -----------------------------------------------

#: Time constants (τ, τ0) [s] above which a value is refused: no human arm or wrist movement has a
#: time constant of 10 s (the paper's are 0.06–0.12 s for 0.3–0.6 s movements), so such a value is
#: almost surely milliseconds (``tau=80`` for 80 ms).
MAX_TIME_CONSTANT = 10.0
#: Time constants [s] above which a value runs with a warning: a reach of a few seconds at most
#: has time constants well under a second.
PLAUSIBLE_TIME_CONSTANT = 2.0
#: Movement durations [s] above which a value is refused (one movement of a minute; ``duration=400``
#: is 400 ms typed as seconds).
MAX_DURATION = 60.0
#: Movement durations [s] above which a value runs with a warning (human reaches last 0.2–3 s).
PLAUSIBLE_DURATION = 10.0
#: Joint angles [rad] beyond a full turn are refused on every chain: degrees typed as radians.
MAX_JOINT_ANGLE = 2 * np.pi


_UNIT_CHECKS = contextvars.ContextVar("pmpjax_unit_checks", default=True)


@contextlib.contextmanager
def without_unit_checks():
    """Within: :func:`check_seconds` and :func:`check_joint_angles` check nothing. For batches the
    library builds from fitted or generated values (e.g. ``normalised_movements``), whose items
    report a failure by their status instead of stopping the batch; a user's values are checked
    at the public functions they pass them to."""
    token = _UNIT_CHECKS.set(False)
    try:
        yield
    finally:
        _UNIT_CHECKS.reset(token)


def _largest(a: np.ndarray) -> tuple[float, str]:
    """The largest ``|a|`` and where it is (``" (item i, j)"`` for arrays of more than one value)."""
    flat = np.abs(a).reshape(-1)
    i = int(np.argmax(flat))
    where = "" if a.size == 1 else f" (index {', '.join(map(str, np.unravel_index(i, a.shape)))})"
    return float(a.reshape(-1)[i]), where


def check_seconds(name: str, v: Any, *, kind: str = "time constant") -> None:
    """Refuse (``ValueError``) or warn about a time [s] that no human arm or wrist movement has.

    ``kind`` "time constant" (τ, τ0): refused above :data:`MAX_TIME_CONSTANT` (10 s), a warning
    above :data:`PLAUSIBLE_TIME_CONSTANT` (2 s); "duration" (of one movement): refused above
    :data:`MAX_DURATION` (60 s), a warning above :data:`PLAUSIBLE_DURATION` (10 s). The message
    names ``name``, the value and the unit it probably is in. Only concrete values are checked
    (inside a caller's ``jit`` nothing is raised)."""
    if v is None or not is_concrete(v) or not _UNIT_CHECKS.get():
        return
    a = np.asarray(v, dtype=float)
    if a.size == 0 or not np.all(np.isfinite(a)):
        return
    hi, warn = (MAX_DURATION, PLAUSIBLE_DURATION) if kind == "duration" else (MAX_TIME_CONSTANT,
                                                                              PLAUSIBLE_TIME_CONSTANT)
    top, where = _largest(a)
    if abs(top) > hi:
        raise ValueError(f"`{name}` = {top:g}{where} s: a human arm or wrist movement's {kind} is under "
                         f"{hi:g} s; milliseconds? {top:g} ms is {top / 1000:g} s")
    if abs(top) > warn:
        import warnings

        warnings.warn(f"`{name}` = {top:g}{where} s is longer than any human reach's {kind} (under {warn:g} s); "
                      f"milliseconds? {top:g} ms is {top / 1000:g} s", UserWarning, stacklevel=3)


def check_joint_angles(name: str, q: Any, chain=None) -> None:
    """Refuse (``ValueError``) or warn about joint angles [rad] that look like degrees.

    An angle beyond ``chain.angle_error`` [rad] is refused (default :data:`MAX_JOINT_ANGLE`, a
    full turn, on every chain; the wrist's π: no wrist joint turns 180° from neutral), and one
    beyond ``chain.angle_limit`` [rad] runs with a warning (a chain with a human range: the wrist's
    π/2, the shoulder–elbow arm's π). The message names ``name``, the value and its size in
    degrees. Only concrete values are checked (inside a caller's ``jit`` nothing is raised)."""
    if q is None or not is_concrete(q) or not _UNIT_CHECKS.get():
        return
    a = np.asarray(q, dtype=float)
    if a.size == 0 or not np.all(np.isfinite(a)):
        return
    top, where = _largest(a)
    limit = getattr(chain, "angle_limit", None)
    refuse = getattr(chain, "angle_error", None) or MAX_JOINT_ANGLE
    what = f"{type(chain).__name__} joint" if chain is not None else "joint"
    if abs(top) > refuse:
        raise ValueError(f"`{name}` = {top:g}{where} rad ({np.rad2deg(top):.0f}°) is beyond any {what}'s range "
                         f"(±{refuse:.3g} rad); degrees? {top:g}° is {np.deg2rad(top):.4g} rad (np.deg2rad)")
    if limit is not None and abs(top) > limit:
        import warnings

        warnings.warn(f"`{name}` = {top:g}{where} rad ({np.rad2deg(top):.0f}°) is beyond the human range of a "
                      f"{what} (±{np.rad2deg(limit):.0f}°); degrees? {top:g}° is {np.deg2rad(top):.4g} rad",
                      UserWarning, stacklevel=3)
