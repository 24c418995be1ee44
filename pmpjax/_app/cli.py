"""Command line: ``pmpjax reproduce`` (the main job) and subcommands for users' own files.

``pmpjax [reproduce] [--out DIR] [--quick] [--force] [--only PART ...] [--jobs N]``
(``python -m pmpjax`` does the same) runs every part of the main job on the embedded defaults and
writes PNG figures, CSV/JSON tables, ``results.json`` and a report (``report.html``,
self-contained, and ``report.md``). Results are written after every part, so an interruption
loses nothing; a re-run skips parts already finished (with the same ``--quick``) unless
``--force``; a failing part is reported and the others still run (exit status 1 when any part
failed). ``--jobs N`` (default: the usable cores) runs the parts in N spawned worker processes,
each on its share of the cores, longest first (the run is compile bound and XLA compiles on one
thread), a part that reuses another's compilations right after it on its worker;
``--jobs 1`` runs them in this process. Workers' own output (JAX, XLA, MuJoCo) goes to
``DIR/_logs/``, kept only if not empty; their log lines and progress bars appear in this
process's display.

Parts are registered by installed packages under the ``pmpjax.jobs`` entry-point group: pmpjax's
own (Figure 3, Figure 4, the postural primitives) and ``fitting``'s fits, so ``pmpjax`` never
imports ``fitting`` (the protocol: ``pmpjax._app.parts``). Subcommands for users' files
(``fit-donders``, ``analyze-pointing``, ...) are registered the same way under
``pmpjax.commands``: ``command(subparsers) -> None`` adds a parser whose ``func(args) -> int``
runs it. Bad input ends with a one-line message and exit status 2,
never a traceback.

JAX's persistent compilation cache is on for the command line (``$PMPJAX_CACHE_DIR``, default
``~/.cache/pmpjax/jax``; ``--no-cache`` turns it off), so a second run does not recompile.
"""

from __future__ import annotations

import argparse
import os
import sys

from .parts import as_part, available_parts
from .reproduce import default_jobs, reproduce


class UserError(Exception):
    """Bad input from the command line: printed as one line, exit status 2."""


def _commands() -> dict:
    """Subcommands registered by installed packages (``pmpjax.commands`` entry points)."""
    from importlib.metadata import entry_points

    return {ep.name: ep for ep in entry_points(group="pmpjax.commands")}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="pmpjax", description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    rep = sub.add_parser("reproduce", help="run every reproduced result of the three papers (the main job)",
                         description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    rep.add_argument("--out", default="out", help="output folder (created; default: out)")
    rep.add_argument("--quick", action="store_true",
                     help="small sizes: every part once, quickly (run times: README)")
    rep.add_argument("--force", action="store_true", help="re-run parts that finished before")
    rep.add_argument("--only", nargs="+", metavar="PART", help="run only these parts")
    rep.add_argument("--list", action="store_true", help="list the parts and exit")
    rep.add_argument("--seed", type=int, default=0, help="random seed of the synthetic data (default 0)")
    rep.add_argument("--no-progress", action="store_true", help="no progress display")
    rep.add_argument("--no-cache", action="store_true", help="no persistent JAX compilation cache")
    rep.add_argument("--jobs", "-j", type=_positive_int, default=None, metavar="N",
                     help=f"worker processes running parts at once (default: the usable cores, "
                          f"here {default_jobs()}; 1 runs in this process)")
    rep.set_defaults(func=_reproduce_cmd)
    from .simulate import add_simulate_command

    add_simulate_command(sub)
    for name, ep in _commands().items():
        ep.load()(sub)
    return parser


def _positive_int(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return n


def _reproduce_cmd(args) -> int:
    if args.list:
        for name, part in available_parts().items():
            print(f"{name:16s} {as_part(part).doc.splitlines()[0] if as_part(part).doc else ''}")
        return 0
    parts = available_parts()
    if args.only:
        unknown = [n for n in args.only if n not in parts]
        if unknown:
            raise UserError(f"--only: unknown part(s) {', '.join(unknown)}; available: {', '.join(parts)}")
    res = reproduce(args.out, quick=args.quick, force=args.force, only=args.only, seed=args.seed,
                    progress=not args.no_progress, cache=not args.no_cache, jobs=args.jobs)
    failed = [k for k, v in res.items() if not k.startswith("_") and v.get("status") == "failed"]
    return 1 if failed else 0


def main(argv=None) -> int:
    os.environ.setdefault("MPLBACKEND", "Agg")
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    commands = set(parser._subparsers._group_actions[0].choices)  # noqa: SLF001
    if not argv:  # a bare `pmpjax` says what it can do rather than start a long run in the current folder
        parser.print_help(sys.stderr)
        print("\npmpjax: give a command, or run the main job with `pmpjax --out DIR` (= pmpjax reproduce --out DIR)",
              file=sys.stderr)
        return 2
    if argv[0] not in commands and argv[0] not in ("-h", "--help"):
        argv = ["reproduce", *argv]  # `pmpjax --out out` is `pmpjax reproduce --out out`
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (UserError, ValueError, FileNotFoundError, TypeError) as e:
        print(f"pmpjax {args.command}: error: {e}", file=sys.stderr)
        return 2
