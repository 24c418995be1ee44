"""Command line: ``pmpjax reproduce`` (the main job) and subcommands for users' own files.

``pmpjax [reproduce] [--out DIR] [--quick] [--force] [--only PART ...] [--jobs N]``
(``python -m pmpjax`` does the same) runs every part of the main job on the embedded defaults:
:data:`REPRODUCE_HELP` says what it does for users; the parts run in this process or in spawned
workers (``reproduce.py``, ``workers.py``).

Parts are registered by installed packages under the ``pmpjax.jobs`` entry-point group: pmpjax's
own (Figure 3, Figure 4, the postural primitives) and ``fitting``'s fits, so ``pmpjax`` never
imports ``fitting`` (the protocol: ``pmpjax._app.parts``). Subcommands for users' files
(``fit-donders``, ``analyze-pointing``, ...) are registered the same way under
``pmpjax.commands``: ``command(subparsers) -> None`` adds a parser whose ``func(args) -> int``
runs it; ``set_defaults(resume=fn)`` (``fn(args) -> str``) says, when it is interrupted, what is
kept and how to go on.

Every command follows :data:`EXIT_STATUS`. Bad input, an output folder that cannot be written
and an interruption end with a one-line message, never a traceback; warnings print as one line
each.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import textwrap
import warnings

from .parts import as_part, available_parts
from .reproduce import default_jobs, reproduce
from .text import plain, positive_int
from .workers import pools_interrupted

EXIT_STATUS = """\
exit status (every command):
  0    done: every fit converged, every movement and sweep row ended successfully
  1    done and written, but not everything succeeded: a fit did not converge, a movement or
       sweep row did not end successfully, or a part of the main job failed (the output and
       its report say which)
  2    bad input or an output folder that cannot be written: nothing was run
  130  interrupted (Ctrl-C): what was finished is kept; run the command again to go on"""

REPRODUCE_HELP = """\
Run every reproduced result of the three papers that pmpjax reproduces (λ0-PMP, IK weights,
postural primitives) on the embedded defaults, and write PNG figures, CSV/JSON tables,
results.json and a report (report.html, self-contained, and report.md) into the output folder.

Results are written after every part, so an interruption loses nothing: run the same command
again and it skips the parts already finished (with the same --quick) unless --force. A part
that fails is reported (its traceback in PART.error.txt) and the others still run; a part whose
fits did not all converge says so. --jobs N runs the parts in N worker processes, each on its
share of the cores, longest first; their own messages (JAX, XLA, MuJoCo) go to
OUT/_logs/PART.log, kept only if not empty. JAX's compilation cache ($PMPJAX_CACHE_DIR, default
~/.cache/pmpjax/jax; --no-cache turns it off) lets a second run skip compiling."""


class _KeepBlocks(argparse.HelpFormatter):
    """Help text wrapped to the terminal, except paragraphs laid out by hand (with line breaks,
    such as :data:`EXIT_STATUS`), which are kept as written."""

    def _fill_text(self, text, width, indent):
        return "\n\n".join(p if "\n" in p else super(_KeepBlocks, self)._fill_text(p, width, indent)
                           for p in text.split("\n\n"))


class UserError(Exception):
    """Bad input from the command line: printed as one line, exit status 2."""


def _commands() -> dict:
    """Subcommands registered by installed packages (``pmpjax.commands`` entry points)."""
    from importlib.metadata import entry_points

    return {ep.name: ep for ep in entry_points(group="pmpjax.commands")}


def _version() -> str:
    import pmpjax

    return pmpjax.__version__


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="pmpjax", description="pmpjax: λ0-PMP, IK weights and postural primitives on the command line.\n"
        "pmpjax --out DIR (= pmpjax reproduce --out DIR) runs the main job; the other commands work on\n"
        "your own files. Each command has --help.", epilog=EXIT_STATUS,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"pmpjax {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    rep = sub.add_parser("reproduce", help="run every reproduced result of the three papers (the main job)",
                         description=REPRODUCE_HELP, epilog=EXIT_STATUS,
                         formatter_class=argparse.RawDescriptionHelpFormatter)
    rep.add_argument("--out", default="out", help="output folder (created; default: out)")
    rep.add_argument("--quick", action="store_true",
                     help="small sizes: every part once, quickly (run times: README)")
    rep.add_argument("--force", action="store_true", help="re-run parts that finished before")
    rep.add_argument("--only", nargs="+", metavar="PART", help="run only these parts (--list names them)")
    rep.add_argument("--list", action="store_true", help="list the parts and exit")
    rep.add_argument("--seed", type=int, default=0, help="random seed of the synthetic data (default 0)")
    rep.add_argument("--no-progress", action="store_true", help="no progress display")
    rep.add_argument("--no-cache", action="store_true", help="no persistent JAX compilation cache")
    rep.add_argument("--jobs", "-j", type=positive_int, default=None, metavar="N",
                     help=f"worker processes running parts at once (default: the usable cores, "
                          f"here {default_jobs()}; 1 runs in this process)")
    rep.set_defaults(func=_reproduce_cmd, resume=_reproduce_resume)
    from .simulate import add_simulate_command

    add_simulate_command(sub)
    for name, ep in _commands().items():
        ep.load()(sub)
    for p in sub.choices.values():  # one exit-status policy, in every command's --help
        if EXIT_STATUS not in (p.epilog or ""):
            p.epilog = f"{p.epilog}\n\n{EXIT_STATUS}" if p.epilog else EXIT_STATUS
            if p.formatter_class is argparse.HelpFormatter:
                p.formatter_class = _KeepBlocks
    return parser


def _reproduce_resume(args) -> str:
    """What an interrupted main job kept and how to go on."""
    from pathlib import Path

    if (Path(args.out) / "results.json").is_file():
        return f"the finished parts are in {args.out}/results.json; run the same command again to run the others"
    return "no part had finished; run the same command again to run them"


def _reproduce_cmd(args) -> int:
    if args.list:
        width = max(60, min(120, _columns()))
        for name, part in available_parts().items():
            doc = " ".join(plain(as_part(part).doc).split())
            print(textwrap.fill(doc, width, initial_indent=f"{name:16s} ", subsequent_indent=" " * 17,
                                break_on_hyphens=False))
        return 0
    parts = available_parts()
    if args.only:
        unknown = [n for n in args.only if n not in parts]
        if unknown:
            raise UserError(f"--only: unknown part(s) {', '.join(unknown)}; available: {', '.join(parts)}")
    res = reproduce(args.out, quick=args.quick, force=args.force, only=args.only, seed=args.seed,
                    progress=not args.no_progress, cache=not args.no_cache, jobs=args.jobs)
    from .report import part_status

    return 0 if all(part_status(res[name])[1] == "ok" for name in args.only or parts if name in res) else 1


def _columns() -> int:
    import shutil

    return shutil.get_terminal_size().columns


def _print_warning(command: str):
    """``warnings.showwarning`` for the command line: one line, no source line."""

    def show(message, category, filename, lineno, file=None, line=None):
        print(f"pmpjax {command}: warning: {message}", file=sys.stderr if file is None else file)

    return show


def main(argv=None) -> int:
    os.environ.setdefault("MPLBACKEND", "Agg")
    whole_process = argv is None  # (the `pmpjax` command, not a call from Python)
    argv = list(sys.argv[1:] if argv is None else argv)
    command, args = "reproduce", None
    try:
        parser = build_parser()
        commands = set(parser._subparsers._group_actions[0].choices)  # noqa: SLF001
        if not argv:  # a bare `pmpjax` says what it can do rather than start a long run in the current folder
            parser.print_help(sys.stderr)
            print("\npmpjax: give a command, or run the main job with pmpjax --out DIR (= pmpjax reproduce "
                  "--out DIR)", file=sys.stderr)
            return 2
        if argv[0] not in commands and argv[0] not in ("-h", "--help", "--version"):
            argv = ["reproduce", *argv]  # `pmpjax --out out` is `pmpjax reproduce --out out`
        args = parser.parse_args(argv)
        command = args.command
        with warnings.catch_warnings():
            warnings.showwarning = _print_warning(command)
            return int(args.func(args) or 0)
    except (UserError, ValueError, FileNotFoundError, TypeError) as e:
        print(f"pmpjax {command}: error: {e}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # (output piped into a command that stopped reading it, e.g. `| head`)
        with contextlib.suppress(OSError, ValueError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except OSError as e:  # (a file that cannot be read or written)
        where = f"{e.filename}: " if e.filename else ""
        print(f"pmpjax {command}: error: {where}{e.strerror or e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        resume = getattr(args, "resume", None)
        print(f"pmpjax {command}: interrupted" + (f"; {resume(args)}" if resume else ""), file=sys.stderr)
        # The interpreter's exit could wait forever on the ended workers' pools, or crash while the
        # interrupted work's threads (XLA's) still run (a segmentation fault, exit status 139):
        # the command ends its process at once.
        if pools_interrupted() or whole_process:
            with contextlib.suppress(OSError, ValueError):
                sys.stdout.flush()
                sys.stderr.flush()
            os._exit(130)
        return 130
