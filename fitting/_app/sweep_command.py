"""``pmpjax sweep CONFIG``: a parameter sweep of λ0-PMP (or PMP1/PMP2) movements from a TOML/JSON file.

The model, chain, planner and movements are given as for ``pmpjax simulate`` (same keys); a
``[sweep]`` table says what varies, what is measured and where it goes. Example (TOML)::

    [sweep]
    metrics = ["A_net", "A_sum", "final_error", "peak_speed"]   # per target
    chunk_size = 4          # parameter rows per compiled call (memory)
    out = "out_sweep"       # output folder (--out overrides)

    [sweep.grid]            # full factorial grid (C order: the first key varies slowest)
    "model.KJ[2,2]" = [1.0, 2.0, 3.0]
    "planner.tau" = [0.06, 0.1]

    [sweep.sample]          # and/or quasi-random points in a box (crossed with the grid)
    method = "sobol"        # or "latin_hypercube"
    n = 8                   # a power of two for Sobol'
    seed = 0
    bounds = { "model.tau0" = [0.05, 0.12] }

Sweepable parameters: ``model.tau0`` [s] (``W = τ0 KJ``, Eq 7), ``model.KJ[i,j]`` [Nm/rad]
(0-based, symmetric: sets both entries), ``model.q_rest_deg[i]`` [deg], ``simulation.q0_deg[i]``
[deg], ``planner.k`` [N/m] and ``planner.tau`` [s] (Arimoto), ``planner.k`` (constant).

Metrics, one value per target: ``A_net``, ``A_sum`` (curvature areas between the path and the
line from its start to the target, normalised by ``sweep.area_scale``², default π/12),
``final_error`` [task units] (distance from the target at the end), ``peak_speed`` [task
units/s]. Each movement is saved at every RK4 step (``simulation.save_every`` is not used). A
row whose hand ends short of a target (farther than ``simulation.reach_tol``, default 0.1, times
its start distance) has status NOT_REACHED. Swept time constants are checked like the file's:
above 10 s refused as milliseconds, above 2 s a warning.

Writes ``sweep.csv`` (one row per parameter set: parameters, ``<metric>_<target>``, status,
reason), ``sweep.json`` (the same arrays and a summary) and, for a 1-D or 2-D grid without
sampling, ``sweep.png``. The rows are computed by ``fitting.sweep`` into the resumable store
``<out>/store``: a re-run computes only the chunks not yet finished (a changed configuration is
a different sweep and is refused: use a new ``--out``). Errors name the file and the key.
"""

from __future__ import annotations

import argparse
import csv
import itertools
import math
import re
import warnings
from pathlib import Path

import numpy as np

from pmpjax._app import ConfigError, build_simulation, example_help, plain, plural, read_config
from pmpjax.internal import check_rk4_stability, check_seconds, output_dir, write_json

from .output import enable_x64

METRICS = ("A_net", "A_sum", "final_error", "peak_speed")
_INDEXED = re.compile(r"^(model\.KJ|model\.q_rest_deg|simulation\.q0_deg)\[(\d+)(?:,\s*(\d+))?\]$")
_SCALARS = ("model.tau0", "planner.k", "planner.tau")


def _flatten(d, prefix=""):
    """Nested tables to dotted keys (TOML's bare ``model.tau0 = ...`` is a nested table)."""
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(_flatten(v, key + "."))
        else:
            out[key] = v
    return out


def _parse_name(path, where, name, n, cfg, ptype):
    """``(kind, i, j)`` of a sweepable parameter, or ConfigError naming the key."""
    model = cfg.get("model", {})
    if name in _SCALARS:
        if name == "model.tau0" and "W" in model:
            raise ConfigError(f"{path}: {where}.{name}: cannot sweep τ0 when model.W is given (W = τ0 KJ needs τ0)")
        if name.startswith("planner.") and (ptype, name) not in (("arimoto", "planner.k"), ("arimoto", "planner.tau"),
                                                                ("constant", "planner.k")):
            raise ConfigError(f"{path}: {where}.{name}: not a parameter of the {ptype!r} planner")
        if name == "planner.k" and ptype == "arimoto" and cfg.get("planner", {}).get("k") is None:
            raise ConfigError(f"{path}: {where}.{name}: the planner sets k by Eq 10 (no planner.k); give planner.k "
                              "to sweep it")
        return name, None, None
    m = _INDEXED.match(name.replace(" ", ""))
    if m is None:
        raise ConfigError(f"{path}: {where}: unknown sweep parameter {name!r}; sweepable: "
                          f"{', '.join(_SCALARS)}, model.KJ[i,j], model.q_rest_deg[i], simulation.q0_deg[i]")
    base, i, j = m.group(1), int(m.group(2)), m.group(3)
    if (base == "model.KJ") != (j is not None):
        idx = "two indices [i,j]" if base == "model.KJ" else "one index [i]"
        raise ConfigError(f"{path}: {where}.{name}: {base} takes {idx}")
    j = None if j is None else int(j)
    if i >= n or (j is not None and j >= n):
        raise ConfigError(f"{path}: {where}.{name}: index out of range for a chain of {n} joints (0-based)")
    if base == "model.KJ" and model.get("type", "lambda0") == "pmp1":
        raise ConfigError(f"{path}: {where}.{name}: a PMP1 model has no joint stiffness")
    return base, i, j


def sweep_parameters(cfg: dict, path, n: int, ptype: str) -> tuple[dict[str, np.ndarray], list[str], dict]:
    """The parameter table ``{name: (N,)}`` of ``[sweep]``, the grid axis names (for figures),
    and the parsed names ``{name: (kind, i, j)}``. Grid rows × sample points, grid in C order."""
    sw = cfg.get("sweep")
    if not isinstance(sw, dict):
        raise ConfigError(f"{path}: missing table [sweep] (with [sweep.grid] and/or [sweep.sample])")
    from .._sweep import grid, latin_hypercube, sobol

    parsed: dict = {}
    tables = []
    axes: list[str] = []
    if "grid" in sw:
        if not isinstance(sw["grid"], dict) or not sw["grid"]:
            raise ConfigError(f"{path}: sweep.grid must be a non-empty table {{parameter = [values]}}")
        g = _flatten(sw["grid"])
        for name, vals in g.items():
            parsed[name] = _parse_name(path, "sweep.grid", name, n, cfg, ptype)
            try:
                a = np.asarray(vals, dtype=float)
            except (TypeError, ValueError):
                raise ConfigError(f"{path}: sweep.grid.{name} must be a list of numbers, got {vals!r}") from None
            if a.ndim != 1 or a.size == 0 or not np.all(np.isfinite(a)):
                raise ConfigError(f"{path}: sweep.grid.{name} must be a non-empty list of finite numbers, got {vals!r}")
        tables.append(grid(**{k: np.asarray(v, float) for k, v in g.items()}))
        axes = list(g)
    if "sample" in sw:
        s = sw["sample"]
        if not isinstance(s, dict):
            raise ConfigError(f"{path}: sweep.sample must be a table (method, n, seed, bounds)")
        method = s.get("method", "sobol")
        if method not in ("sobol", "latin_hypercube"):
            raise ConfigError(f"{path}: sweep.sample.method must be 'sobol' or 'latin_hypercube', got {method!r}")
        n_pts, seed = s.get("n"), s.get("seed", 0)
        if not (isinstance(n_pts, int) and not isinstance(n_pts, bool) and n_pts >= 1):
            raise ConfigError(f"{path}: sweep.sample.n must be a positive integer, got {n_pts!r}")
        if not isinstance(seed, int) or isinstance(seed, bool):
            raise ConfigError(f"{path}: sweep.sample.seed must be an integer, got {seed!r}")
        bounds = _flatten(s.get("bounds", {})) if isinstance(s.get("bounds", {}), dict) else None
        if not bounds:
            raise ConfigError(f"{path}: sweep.sample.bounds must be a non-empty table {{parameter = [low, high]}}")
        for name in bounds:
            if name in parsed:
                raise ConfigError(f"{path}: sweep.sample.bounds.{name}: already swept in sweep.grid")
            parsed[name] = _parse_name(path, "sweep.sample.bounds", name, n, cfg, ptype)
        try:
            tables.append((sobol if method == "sobol" else latin_hypercube)(bounds, n_pts, seed=seed))
        except (TypeError, ValueError) as e:
            raise ConfigError(f"{path}: sweep.sample: {e}") from None
    if not tables:
        raise ConfigError(f"{path}: [sweep] needs [sweep.grid] and/or [sweep.sample]")
    if len(tables) == 2:
        ng, ns = len(next(iter(tables[0].values()))), len(next(iter(tables[1].values())))
        params = {k: np.repeat(v, ns) for k, v in tables[0].items()}
        params.update({k: np.tile(v, ng) for k, v in tables[1].items()})
        axes = []  # no grid figure for a crossed design
    else:
        params = tables[0]
    return params, axes, parsed


def _row_values(base: dict, parsed: dict, params: dict, xp):
    """Per-row KJ, q_rest, q0, tau0, k, tau from the base values with the swept ones put in.
    ``xp`` is numpy (all rows at once, for checks) or jax.numpy (one row, inside the kernel)."""
    KJ, q_rest, q0 = base["KJ"], base["q_rest"], base["q0"]
    vals = {"model.tau0": base["tau0"], "planner.k": base["k"], "planner.tau": base["tau"]}
    if xp is np:
        N = len(next(iter(params.values())))
        KJ, q_rest, q0 = (np.broadcast_to(a, (N,) + a.shape).copy() for a in (KJ, q_rest, q0))
    for name, (kind, i, j) in parsed.items():
        v = params[name]
        if kind in vals:
            vals[kind] = v
        elif kind == "model.KJ":
            if xp is np:
                KJ[:, i, j] = v
                KJ[:, j, i] = v
            else:
                KJ = KJ.at[i, j].set(v).at[j, i].set(v)
        else:
            v = xp.deg2rad(v)
            if xp is np:
                (q_rest if kind == "model.q_rest_deg" else q0)[:, i] = v
            elif kind == "model.q_rest_deg":
                q_rest = q_rest.at[i].set(v)
            else:
                q0 = q0.at[i].set(v)
    return KJ, q_rest, q0, vals["model.tau0"], vals["planner.k"], vals["planner.tau"]


def build_sweep(path):
    """Everything ``pmpjax sweep`` runs, checked before any tracing:
    ``(row_fn, params, axes, options)`` (``options``: chunk_size, out, metrics, names, targets)."""
    import jax.numpy as jnp

    import pmpjax as pj

    cfg = read_config(path)
    model, planner, q0, targets, opt = build_simulation(cfg, path, extra_tables=("sweep",))
    chain, n = model.chain, model.chain.n
    mtype = cfg.get("model", {}).get("type", "lambda0")
    ptype = cfg.get("planner", {}).get("type", "arimoto")
    sw = cfg.get("sweep", {})
    if not isinstance(sw, dict):
        raise ConfigError(f"{path}: [sweep] must be a table")
    metrics = sw.get("metrics", ["A_net", "A_sum", "final_error"])
    if (not isinstance(metrics, list) or not metrics or any(m not in METRICS for m in metrics)
            or len(set(metrics)) != len(metrics)):
        raise ConfigError(f"{path}: sweep.metrics must be a list of distinct names from {list(METRICS)}, "
                          f"got {metrics!r}")
    chunk = sw.get("chunk_size", 64)
    if not (isinstance(chunk, int) and not isinstance(chunk, bool) and chunk >= 1):
        raise ConfigError(f"{path}: sweep.chunk_size must be a positive integer, got {chunk!r}")
    out = sw.get("out")
    if out is not None and not isinstance(out, str):
        raise ConfigError(f"{path}: sweep.out must be a folder name (string), got {out!r}")
    scale = sw.get("area_scale", float(np.pi / 12))
    if isinstance(scale, bool) or not isinstance(scale, int | float) or not (math.isfinite(scale) and scale > 0):
        raise ConfigError(f"{path}: sweep.area_scale must be a positive number, got {scale!r}")
    params, axes, parsed = sweep_parameters(cfg, path, n, ptype)

    KJ0 = np.asarray(model.KJ) if mtype != "pmp1" else np.eye(n)
    tau0 = None if "W" in cfg.get("model", {}) else float(cfg.get("model", {}).get("tau0", 0.08))
    base = {"KJ": KJ0, "q_rest": np.asarray(getattr(model, "q_rest", np.zeros(n))), "q0": np.asarray(q0, float),
            "tau0": tau0, "W": np.asarray(model.W) if tau0 is None else None,
            "k": None if getattr(planner, "k", None) is None else float(planner.k),
            "tau": float(planner.tau) if hasattr(planner, "tau") else None}
    # Concrete checks of every row (NumPy) before tracing: positive constants, SPD stiffness.
    KJ, q_rest, q0s, t0, k, tau = _row_values(base, parsed, params, np)
    for name, v in (("model.tau0", t0), ("planner.k", k), ("planner.tau", tau)):
        if name in parsed and np.any(np.asarray(v) <= 0):
            row = int(np.argmax(np.asarray(v) <= 0))
            raise ConfigError(f"{path}: {name} must be positive; row {row + 1} of the sweep has {float(v[row])}")
        if name in parsed and name != "planner.k":  # seconds: milliseconds refused, implausible values warned
            row = int(np.argmax(np.asarray(v)))
            try:
                check_seconds(f"{name} (row {row + 1} of the sweep)", float(v[row]))
            except ValueError as e:
                raise ConfigError(f"{path}: {e}") from None
    if any(p[0] == "model.KJ" for p in parsed.values()):
        lam = np.linalg.eigvalsh(KJ)[:, 0]
        if np.any(lam <= 0):
            row = int(np.argmax(lam <= 0))
            names = [nm for nm, p in parsed.items() if p[0] == "model.KJ"]
            raise ConfigError(f"{path}: model.KJ is not positive definite in row {row + 1} of the sweep "
                              f"({', '.join(f'{nm} = {params[nm][row]:g}' for nm in names)})")
    limit = np.rad2deg(getattr(chain, "angle_error", None) or 2 * np.pi)  # (the chain's joint range, as simulate's)
    for name, (kind, _, _) in parsed.items():
        v = np.asarray(params[name], float)
        if kind in ("model.q_rest_deg", "simulation.q0_deg") and np.any(np.abs(v) > limit * (1 + 1e-12)):
            row = int(np.argmax(np.abs(v) > limit * (1 + 1e-12)))
            raise ConfigError(f"{path}: {name} = {v[row]:g}° in row {row + 1} of the sweep is beyond any "
                              f"{type(chain).__name__} joint's range (±{limit:.0f}°)")

    dur, dt, reach_tol = opt["duration"], opt["dt"], opt["reach_tol"]
    tg = jnp.asarray(targets)
    T = len(targets)

    def make(KJ, q_rest, tau0, k, tau):
        """Model and planner of one row (JAX values) or of all rows at once (NumPy, leading N)."""
        if base["W"] is not None:
            W = jnp.asarray(base["W"])
        else:
            W = pj.damping_from_stiffness(KJ, jnp.broadcast_to(tau0, jnp.shape(KJ)[:-2]))
        if mtype == "lambda0":
            mdl = pj.Lambda0PMP(chain, KJ=KJ, q_rest=q_rest, W=W)
        elif mtype == "pmp2":
            mdl = pj.PMP2(chain, KJ=KJ, q_rest=q_rest, W=W)
        else:
            mdl = pj.PMP1(chain, W=W)
        if ptype == "arimoto":
            pl = pj.ArimotoPlanner(k=k, tau=tau) if k is not None else pj.ArimotoPlanner(k=None, tau=tau, tau0=tau0)
        elif ptype == "constant":
            pl = pj.ConstantPlanner(k=k)
        else:
            pl = planner
        return mdl, pl

    # simulate's RK4 step check on every row at once (it is skipped inside the traced kernel).
    N = len(next(iter(params.values())))
    try:
        with warnings.catch_warnings():  # (the units of swept time constants are warned about above)
            warnings.filterwarnings("ignore", r"`(tau|tau0)` = ")
            mdl_all, pl_all = make(KJ, q_rest, t0, k, tau)
    except ValueError as e:
        raise ConfigError(f"{path}: in some row of the sweep, {e}") from None
    try:
        check_rk4_stability(mdl_all, pl_all, q0s, (N,), dur / max(1, math.ceil(dur / dt - 1e-9)))
    except ValueError as e:
        raise ConfigError(f"{path}: simulation.dt: in some row of the sweep, {e}") from None

    def row_fn(p):
        row_base = {**base, **{key: jnp.asarray(base[key]) for key in ("KJ", "q_rest", "q0")}}
        KJ, q_rest, q0, tau0, k, tau = _row_values(row_base, parsed, p, jnp)
        mdl, pl = make(KJ, q_rest, tau0, k, tau)
        tr = pj.simulate(mdl, pl, jnp.broadcast_to(q0, (T, n)), tg, duration=dur, dt=dt, reach_tol=reach_tol)
        res = {}
        if "A_net" in metrics or "A_sum" in metrics:
            a_sum, a_net = pj.curvature_measures(tr.x, tr.x[:, 0], tg, scale=scale)
            res.update(A_net=a_net, A_sum=a_sum)
        res["final_error"] = jnp.linalg.norm(tr.x[:, -1] - tg, axis=-1)
        res["peak_speed"] = jnp.max(tr.speed, axis=-1)
        out = {m: res[m] for m in metrics}
        out["status"] = tr.status
        return out

    row_fn.__qualname__ = "sweep_config_row"
    return row_fn, params, axes, {"chunk_size": chunk, "out": out, "metrics": list(metrics), "names": opt["names"],
                                  "targets": np.asarray(targets)}


def run_sweep_config(path, out=None, *, progress: bool = False) -> dict:
    """Run ``pmpjax sweep CONFIG`` into ``out`` (default ``sweep.out`` of the file, else
    ``out_sweep``); returns the ``sweep.json`` content."""
    from .._sweep import sweep

    row_fn, params, axes, opt = build_sweep(path)
    name = "sweep.out" if out is None and opt["out"] else "--out"  # (how errors name the folder's source)
    out = output_dir(name, Path(out or opt["out"] or "out_sweep"))
    output_dir(name, out / "store")  # (the resumable store too, before any work)
    res = sweep(row_fn, params, chunk_size=opt["chunk_size"], out=out / "store", progress=progress)
    names, metrics = opt["names"], opt["metrics"]
    N = len(res.status)
    header = [*params, *(f"{m}_{t}" for m in metrics for t in names), "status", "reason"]
    with (out / "sweep.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        for r in range(N):
            w.writerow([*(f"{params[p][r]:.10g}" for p in params),
                        *(f"{res.outputs[m][r, j]:.10g}" for m in metrics for j in range(len(names))),
                        int(res.status[r]), res.reason(r)])
    summary = {
        "config": str(path), "out": str(out), "rows": N, "chunk_size": opt["chunk_size"],
        "chunks_computed": res.chunks_computed, "chunks_reused": res.chunks_reused, "failed": res.n_failed,
        "targets": list(names), "metrics": metrics,
        "parameters": {p: np.asarray(v).tolist() for p, v in params.items()},
        "outputs": {m: np.asarray(res.outputs[m]).tolist() for m in metrics},
        "status": res.status.tolist(), "reasons": [res.reason(r) for r in range(N)],
    }
    if 1 <= len(axes) <= 2:
        _plot(out / "sweep.png", params, axes, res.outputs[metrics[0]], metrics[0], names)
        summary["figure"] = "sweep.png"
    write_json(out / "sweep.json", summary)
    return summary


def _plot(path, params, axes, values, metric, names):
    """1-D grid: ``metric`` against the parameter, one line per target. 2-D: one heat map per target."""
    import matplotlib.pyplot as plt

    T = len(names)
    if len(axes) == 1:
        fig, ax = plt.subplots(figsize=(6, 4))
        x = params[axes[0]]
        for j in range(T):
            ax.plot(x, values[:, j], "o-", label=names[j])
        ax.set_xlabel(axes[0])
        ax.set_ylabel(metric)
        ax.legend(fontsize=7, ncol=2)
    else:
        a0, a1 = (np.unique(params[a]) for a in axes)
        v = values.reshape(len(a0), len(a1), T)
        cols = min(4, T)
        rows = math.ceil(T / cols)
        fig, axs = plt.subplots(rows, cols, figsize=(3 * cols, 2.6 * rows), squeeze=False)
        lim = float(np.nanmax(np.abs(v))) or 1.0
        signed = bool(np.nanmin(v) < 0)
        for j, ax in itertools.zip_longest(range(T), axs.ravel()):
            if j is None:
                ax.axis("off")
                continue
            im = ax.pcolormesh(a1, a0, v[:, :, j], shading="nearest", cmap="RdBu_r" if signed else "viridis",
                               vmin=-lim if signed else None, vmax=lim if signed else None)
            ax.set_title(names[j], fontsize=9)
            ax.set_xlabel(axes[1], fontsize=8)
            ax.set_ylabel(axes[0], fontsize=8)
            ax.tick_params(labelsize=7)
            fig.colorbar(im, ax=ax)
        fig.suptitle(f"{metric} per target")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def add_sweep(sub) -> None:
    p = sub.add_parser("sweep", help="sweep model/planner parameters of movements described in a TOML/JSON "
                       "file (chunked, resumable)", description=plain(__doc__),
                       epilog=example_help("sweep_figure3.toml"),
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("config", help="TOML or JSON file ([chain], [model], [planner], [simulation], [sweep])")
    p.add_argument("--out", help="output folder (default: sweep.out of the file, else out_sweep)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")

    def run(args) -> int:
        enable_x64()
        s = run_sweep_config(args.config, args.out, progress=not args.no_progress)
        print(f"{plural(s['rows'], 'parameter row')} ({plural(s['chunks_computed'], 'chunk')} computed, "
              f"{s['chunks_reused']} reused), {s['failed']} failed; wrote {Path(s['out']) / 'sweep.csv'}, sweep.json"
              + (", sweep.png" if "figure" in s else ""))
        return 0 if s["failed"] == 0 else 1

    p.set_defaults(func=run, resume=lambda args: "the finished chunks are kept in the output folder's store; run "
                   "the same command again to compute the others")
