"""The `lss` command line: one parser, one sub-command per job.

    lss build | simulate | layouts | rig | identify | campaign | report | close-loop | figures | demo

Each sub-command lives in a cmd_*.py module of this package (`register(sub)`
adds its parser, `run(args)` does the job). A user error (a missing file, a
malformed input, an unknown layout or model, an impossible bound) is one line
on stderr naming what is wrong and exit code 2; `--traceback` (or
LSS_TRACEBACK=1) shows the full trace.
"""
from __future__ import annotations

import argparse
import os
import sys

from . import cmd_campaign, cmd_close_loop, cmd_figures, cmd_identify, cmd_layouts, cmd_rig, cmd_simulate, demo

COMMANDS = (cmd_simulate, cmd_layouts, cmd_rig, cmd_identify, cmd_campaign, cmd_close_loop, cmd_figures, demo)


class UserError(Exception):
    """An error in what the user asked for: reported as one line."""


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="lss", description="Loop-sorter chain FMU: build, simulate, measure, "
                                "identify contact parameters, close the loop.")
    p.add_argument("--traceback", action="store_true", help="show the full traceback on errors")
    # the same switch after the command name too (SUPPRESS: it must not reset a --traceback given before)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--traceback", action="store_true", default=argparse.SUPPRESS, help=argparse.SUPPRESS)
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in COMMANDS:
        module.register(sub, common)
    return p


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # usage error or --help: argparse has printed it
        return int(exc.code or 0)
    show = args.traceback or os.environ.get("LSS_TRACEBACK") == "1"
    try:
        return int(args.run(args) or 0)
    except KeyboardInterrupt:
        print("lss: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # one line for the user, the trace on request
        if show:
            raise
        from lss_fmu.runner import SimulationError
        known = (UserError, SimulationError, FileNotFoundError, KeyError, ValueError, PermissionError)
        msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else str(exc)
        kind = "" if isinstance(exc, known) else f"{type(exc).__name__}: "
        print(f"lss {args.command}: {kind}{msg}".splitlines()[0], file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
