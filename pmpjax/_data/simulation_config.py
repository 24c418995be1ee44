"""Simulation configuration files: a λ0-PMP (or PMP1/PMP2) simulation described in a TOML or JSON file,
the format of ``pmpjax simulate CONFIG`` and ``pmpjax sweep CONFIG``.

Example (TOML; the same keys in JSON)::

    [chain]                 # "wrist" (Eq 6; d [m]) or "planar" (lengths [m])
    type = "wrist"
    d = 1.0

    [model]                 # "lambda0" (default), "pmp1", "pmp2"
    type = "lambda0"
    KJ = [[0.5, 0, 0], [0, 1.5, 0], [0, 0, 2.0]]     # [Nm/rad], SPD; or KJ_diag = [...]
    q_rest_deg = [5, 0, 0]                           # or q_rest = [...] [rad]
    tau0 = 0.08                                      # W = τ0 KJ (Eq 7); or W = [[...]]

    [planner]               # "arimoto" (Eq 8), "constant", "minimum_jerk"
    type = "arimoto"
    k = 22.5                # [N/m]; omit for Eq 10 (k = b_max / τ0)
    tau = 0.08              # [s]

    [simulation]
    q0_deg = [5, 0, 0]      # or q0 = [...] [rad]
    targets = "center_out"  # or [[x1, x2], ...] [m]; "center_out" = the 8 targets of §3.2
    duration = 0.4          # [s]
    dt = 0.001              # [s]
    save_every = 10         # RK4 steps between saved samples
    reach_tol = 0.1         # a movement ending farther from its target than 0.1 × its start
                            # distance did not reach it (status NOT_REACHED)

Errors name the file and the key (and line and column for syntax errors). Times are in seconds and
angles in radians unless the key ends in ``_deg``: a time constant (``model.tau0``,
``planner.tau``) above 10 s or a duration above 60 s is refused as milliseconds, one above 2 s or
10 s runs with a warning; a joint angle beyond the chain's range (the wrist: ±180°, any chain: a
full turn) is refused as degrees (use ``q0_deg``, ``q_rest_deg``).
"""

from __future__ import annotations

import json
import tomllib
import warnings

import numpy as np

from .._base import check_seconds, check_spd, input_file, read_text_file
from .._chains import PlanarArm, Wrist
from .._pmp import PMP1, PMP2, ArimotoPlanner, ConstantPlanner, Lambda0PMP, MinimumJerkPlanner, damping_from_stiffness
from .._wrist import center_out_targets

#: The format of a simulation file, as ``pmpjax simulate --help`` shows it (this module's docstring).
CONFIG_HELP = __doc__


class ConfigError(ValueError):
    """A configuration file that cannot be used; the message names the file and the key."""


def read_config(path) -> dict:
    """Parse a TOML (``.toml``) or JSON (``.json``) file; syntax errors name line and column."""
    path = input_file("config", path)
    text = read_text_file(path)
    try:
        if path.suffix.lower() == ".json":
            return json.loads(text)
        return tomllib.loads(text)
    except json.JSONDecodeError as e:
        raise ConfigError(f"{path}: line {e.lineno}, column {e.colno}: {e.msg}") from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{path}: {e}") from None


def _get(cfg, path, section, key, default=...):
    sec = cfg.get(section, {})
    if not isinstance(sec, dict):
        raise ConfigError(f"{path}: [{section}] must be a table")
    if key not in sec:
        if default is ...:
            raise ConfigError(f"{path}: missing key {section}.{key}")
        return default
    return sec[key]


def _checked(path, check, *args, **kwargs):
    """``check(*args, **kwargs)`` with a ``ValueError`` as a ``ConfigError`` naming the file."""
    try:
        check(*args, **kwargs)
    except ValueError as e:
        raise ConfigError(f"{path}: {e}") from None


def _degrees(path, chain, name, deg):
    """``deg`` [°] in radians, refused beyond the chain's joint range (as ``simulate`` refuses
    radians, but without its hint that the values may be degrees: they are)."""
    limit = np.rad2deg(getattr(chain, "angle_error", None) or 2 * np.pi)
    beyond = np.abs(deg) > limit * (1 + 1e-12)
    if np.any(beyond):
        i = int(np.argmax(beyond))
        raise ConfigError(f"{path}: {name} = {deg[i]:g}° (index {i}) is beyond any {type(chain).__name__} joint's "
                          f"range (±{limit:.0f}°)")
    return np.deg2rad(deg)


def _array(path, name, value, shape=None):
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(f"{path}: {name} must be numeric, got {value!r}") from None
    if shape is not None and a.shape != shape:
        raise ConfigError(f"{path}: {name} must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ConfigError(f"{path}: {name} contains NaN or inf")
    if name in ("model.q_rest", "simulation.q0") and np.any(np.abs(a) > 2 * np.pi):
        raise ConfigError(f"{path}: {name} has angles above 2π rad (degrees? use {name}_deg)")
    if name.endswith("_deg") and np.any(np.abs(a) > 360):
        raise ConfigError(f"{path}: {name} has angles above 360°")
    return a


#: Default ``simulation.reach_tol``: a movement that ends farther from its target than this share of
#: its start distance did not reach it (``pmpjax.simulate``'s ``reach_tol``; status NOT_REACHED).
REACH_TOL = 0.1


#: The keys each table of a simulation configuration may hold (``[sweep]`` is the sweep command's).
KNOWN_KEYS = {
    "chain": {"type", "d", "lengths"},
    "model": {"type", "KJ", "KJ_diag", "q_rest", "q_rest_deg", "W", "tau0"},
    "planner": {"type", "k", "tau", "duration"},
    "simulation": {"duration", "dt", "q0", "q0_deg", "targets", "save_every", "reach_tol"},
}


def check_keys(cfg: dict, path, extra_tables=()) -> None:
    """``ConfigError`` naming the file and the key for an unknown table or key (a typo would
    otherwise fall back silently to a default)."""
    import difflib

    for table, sec in cfg.items():
        if table in extra_tables:
            continue
        if table not in KNOWN_KEYS:
            raise ConfigError(f"{path}: unknown table [{table}]; expected "
                              f"{', '.join(f'[{t}]' for t in [*KNOWN_KEYS, *extra_tables])}")
        if not isinstance(sec, dict):
            raise ConfigError(f"{path}: [{table}] must be a table")
        for key in sec:
            if key not in KNOWN_KEYS[table]:
                near = difflib.get_close_matches(key, KNOWN_KEYS[table], n=1)
                hint = f" (did you mean {table}.{near[0]}?)" if near else ""
                raise ConfigError(f"{path}: unknown key {table}.{key}{hint}; [{table}] takes "
                                  f"{', '.join(sorted(KNOWN_KEYS[table]))}")


def read_simulation_config(path):
    """Read a simulation file (TOML or JSON, the format of ``pmpjax simulate``) into the arguments
    of :func:`simulate`.

    The file has tables ``[chain]`` (``"wrist"``, Eq 6, with ``d`` [m], or ``"planar"`` with
    ``lengths`` [m]), ``[model]`` (``"lambda0"``, ``"pmp1"``, ``"pmp2"``), ``[planner]``
    (``"arimoto"``, Eq 8, ``"constant"``, ``"minimum_jerk"``) and ``[simulation]``; see
    ``pmpjax/data/examples/simulate_figure3.toml``.

    **Arguments:**

    - ``path``: the ``.toml`` or ``.json`` file.

    **Returns:**

    ``(model, planner, q0, targets, options)``: the model, the planner, the start posture (n,) [rad],
    the targets (P, m) and ``options`` with ``duration``, ``dt``, ``every``, ``names`` and
    ``reach_tol``.

    **Raises:**

    - ``ValueError`` (``ConfigError``) naming the file and the key, unknown keys too.
    """
    return build_simulation(read_config(path), path)


def build_simulation(cfg: dict, path="<config>", extra_tables=()):
    """``(model, planner, q0, targets, options)`` from a parsed configuration."""
    check_keys(cfg, path, extra_tables)

    ctype = _get(cfg, path, "chain", "type", "wrist")
    if ctype == "wrist":
        chain = Wrist(d=float(_get(cfg, path, "chain", "d", 1.0)))
    elif ctype == "planar":
        chain = PlanarArm(tuple(_array(path, "chain.lengths", _get(cfg, path, "chain", "lengths")).tolist()))
    else:
        raise ConfigError(f"{path}: chain.type must be 'wrist' or 'planar', got {ctype!r}")
    n = chain.n
    mtype = _get(cfg, path, "model", "type", "lambda0")
    if "KJ" in cfg.get("model", {}):
        KJ = _array(path, "model.KJ", cfg["model"]["KJ"], (n, n))
    elif "KJ_diag" in cfg.get("model", {}):
        KJ = np.diag(_array(path, "model.KJ_diag", cfg["model"]["KJ_diag"], (n,)))
    elif mtype == "pmp1":
        KJ = np.eye(n)
    else:
        raise ConfigError(f"{path}: missing key model.KJ (or model.KJ_diag)")
    if "q_rest_deg" in cfg.get("model", {}):
        q_rest = _degrees(path, chain, "model.q_rest_deg", _array(path, "model.q_rest_deg", cfg["model"]["q_rest_deg"],
                                                                   (n,)))
    else:
        q_rest = _array(path, "model.q_rest", _get(cfg, path, "model", "q_rest", np.zeros(n)), (n,))
        _checked(path, chain.check_angles, "model.q_rest", q_rest)
    if "W" in cfg.get("model", {}):
        W = _array(path, "model.W", cfg["model"]["W"], (n, n))
        tau0 = None
    else:
        tau0 = float(_get(cfg, path, "model", "tau0", 0.08))
        _checked(path, check_seconds, "model.tau0", tau0)
        W = None
    with warnings.catch_warnings():  # the API's own unit warnings: given by the file's key names instead
        warnings.filterwarnings("ignore", r"`(tau|tau0|duration|q_rest|q0)` = ")
        return _build(cfg, path, chain, mtype, KJ, q_rest, W, tau0)


def _build(cfg, path, chain, mtype, KJ, q_rest, W, tau0):
    n = chain.n
    try:
        if mtype != "pmp1":
            check_spd("model.KJ", KJ)
        if W is None:
            W = damping_from_stiffness(KJ, tau0)
        if mtype == "lambda0":
            model = Lambda0PMP(chain, KJ=KJ, q_rest=q_rest, W=W)
        elif mtype == "pmp2":
            model = PMP2(chain, KJ=KJ, q_rest=q_rest, W=W)
        elif mtype == "pmp1":
            model = PMP1(chain, W=W)
        else:
            raise ConfigError(f"{path}: model.type must be 'lambda0', 'pmp1' or 'pmp2', got {mtype!r}")
    except ConfigError:
        raise
    except ValueError as e:
        raise ConfigError(f"{path}: [model]: {e}") from None

    ptype = _get(cfg, path, "planner", "type", "arimoto")
    duration = float(_get(cfg, path, "simulation", "duration", 0.4))
    if not duration > 0:
        raise ConfigError(f"{path}: simulation.duration must be positive [s], got {duration}")
    _checked(path, check_seconds, "simulation.duration", duration, kind="duration")
    try:
        if ptype == "arimoto":
            k = _get(cfg, path, "planner", "k", None)
            tau = float(_get(cfg, path, "planner", "tau", 0.08))
            _checked(path, check_seconds, "planner.tau", tau)
            planner = (ArimotoPlanner(k=float(k), tau=tau) if k is not None
                       else ArimotoPlanner(k=None, tau=tau, tau0=tau0 if tau0 is not None else tau))
        elif ptype == "constant":
            planner = ConstantPlanner(k=float(_get(cfg, path, "planner", "k")))
        elif ptype == "minimum_jerk":
            T = float(_get(cfg, path, "planner", "duration", duration))
            _checked(path, check_seconds, "planner.duration", T, kind="duration")
            planner = MinimumJerkPlanner(duration=T)
        else:
            raise ConfigError(f"{path}: planner.type must be 'arimoto', 'constant' or 'minimum_jerk', got {ptype!r}")
    except ConfigError:
        raise
    except (ValueError, TypeError) as e:
        raise ConfigError(f"{path}: [planner]: {e}") from None

    sim = cfg.get("simulation", {})
    if "q0_deg" in sim:
        q0 = _degrees(path, chain, "simulation.q0_deg", _array(path, "simulation.q0_deg", sim["q0_deg"], (n,)))
    else:
        q0 = _array(path, "simulation.q0", sim.get("q0", q_rest), (n,))
        _checked(path, chain.check_angles, "simulation.q0", q0)
    targets = sim.get("targets", "center_out")
    if isinstance(targets, str):
        if targets != "center_out":
            raise ConfigError(f"{path}: simulation.targets must be 'center_out' or a list of points")
        named = center_out_targets()
        names = [k for k in named if k != "C"]
        targets = np.stack([np.asarray(named[k]) for k in names])
    else:
        targets = _array(path, "simulation.targets", targets)
        if targets.ndim != 2 or targets.shape[1] != chain.m:
            raise ConfigError(f"{path}: simulation.targets must be a list of {chain.m}-vectors, got shape "
                              f"{targets.shape}")
        names = [f"T{i}" for i in range(len(targets))]
    dt = float(sim.get("dt", 1e-3))
    if not 0 < dt <= duration:
        raise ConfigError(f"{path}: simulation.dt must be in (0, duration] s, got {dt}")
    every = sim.get("save_every", 10)
    if not (isinstance(every, int) and every >= 1):
        raise ConfigError(f"{path}: simulation.save_every must be a positive integer, got {every!r}")
    reach = sim.get("reach_tol", REACH_TOL)
    if isinstance(reach, bool) or not isinstance(reach, int | float) or not 0 <= reach <= 1:
        raise ConfigError(f"{path}: simulation.reach_tol must be a number in [0, 1] (the share of the start "
                          f"distance to the target the hand may still be from it at the end), got {reach!r}")
    return model, planner, q0, targets, {"duration": duration, "dt": dt, "every": every, "names": names,
                                         "reach_tol": float(reach)}
