"""The `lss` command line.

Every sub-command reports a user error (missing file, malformed input,
unknown layout or model, impossible bound) as one line on stderr with a
non-zero exit code; `--traceback` (or LSS_TRACEBACK=1) shows the full trace.
Sub-commands of other modules are imported lazily, so `lss build` works even
before the rest of the package's dependencies are needed.
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys
from pathlib import Path


class UserError(Exception):
    """An error in what the user asked for: reported as one line."""


def _parse_set(items: list[str]) -> dict:
    params = {}
    for item in items or []:
        if "=" not in item:
            raise UserError(f"--set {item!r}: expected NAME=VALUE")
        name, value = item.split("=", 1)
        params[name.strip()] = value.strip()
    return params


def _typed(sim, params: dict) -> dict:
    out = {}
    for name, value in params.items():
        var = sim.variables.get(name)
        if var is None:
            sim.vr(name)  # raises KeyError naming the variable
        try:
            out[name] = {"Real": float, "Integer": int, "Boolean": lambda v: v.lower() in ("1", "true"),
                         "String": str}[var.type](value)
        except ValueError:
            raise UserError(f"--set {name}={value}: {name} takes a {var.type} value") from None
    return out


def cmd_build(args) -> int:
    from . import build
    build.build_fmu()
    return 0


def cmd_simulate(args) -> int:
    from .layouts import resolve_layout
    from .runner import DEFAULT_OUTPUTS, ChainSimulator
    layout = args.layout
    resolve_layout(layout)  # clear error for an unknown layout
    if layout.endswith(".layout") or "/" in layout:
        layout = str(Path(layout).resolve())
    with ChainSimulator() as sim:
        params = {"layout.name": layout, **_typed(sim, _parse_set(args.set))}
        outputs = list(DEFAULT_OUTPUTS) + [o for o in (args.output or []) if o not in DEFAULT_OUTPUTS]
        for o in outputs:
            sim.vr(o)
        df = sim.simulate(args.stop_time, args.step, params, outputs, tolerance=args.tolerance)
        info = sim.info()
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    from .atomic import write_atomic
    write_atomic(out, df.to_csv(index=False))
    print(f"wrote {out}: {len(df)} rows, {df.shape[1] - 1} channels; "
          f"{info.n_steps} solver steps ({info.n_rejected} rejected)")
    return 0


def _delegate(module: str, func: str):
    def run(args) -> int:
        mod = importlib.import_module(f"lss_fmu.{module}" if not module.startswith("identification")
                                      else module)
        return getattr(mod, func)(args.rest)
    return run


# commands whose own parser takes everything after their name
DELEGATED = {
    "layouts": ("layouts_cli", "layouts_main", "list, check and draw track layouts"),
    "rig": ("rig_cli", "rig_main", "synthesise measurements with the virtual transducer cart"),
    "identify": ("identification.cli", "identify_main", "identify one measurement"),
    "campaign": ("identification.cli", "campaign_main", "identify all measurements x models"),
    "report": ("identification.cli", "report_main", "the paper's section 4 from a campaign"),
    "close-loop": ("identification.cli", "close_loop_main", "residual -> missing effect -> extended model"),
}


def _split_delegated(argv: list[str]):
    """`lss [--traceback] CMD ARGS...` for a delegated CMD -> (CMD, ARGS, traceback);
    argparse's REMAINDER would swallow nothing when ARGS starts with an option."""
    opts = []
    for i, a in enumerate(argv):
        if a == "--traceback":
            opts.append(a)
            continue
        if a in DELEGATED:
            return a, argv[i + 1:], bool(opts)
        return None
    return None


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="lss", description="Loop-sorter chain FMU: build, simulate, "
                                "measure, identify contact parameters, close the loop.")
    p.add_argument("--traceback", action="store_true", help="show the full traceback on errors")
    sub = p.add_subparsers(dest="command", required=True)

    b = sub.add_parser("build", help="build build/LSSChain.fmu")
    b.set_defaults(func=cmd_build)

    s = sub.add_parser("simulate", help="simulate a layout and write the transducer signals as CSV")
    s.add_argument("--layout", default="demo", help="built-in layout name or layout file")
    s.add_argument("--stop-time", type=float, required=True)
    s.add_argument("--step", type=float, default=1.0 / 300.0, help="communication step, s")
    s.add_argument("--tolerance", type=float, default=None)
    s.add_argument("--out", required=True, help="CSV file to write")
    s.add_argument("--set", action="append", metavar="NAME=VALUE", help="set an FMU parameter")
    s.add_argument("--output", action="append", metavar="NAME", help="record another output")
    s.set_defaults(func=cmd_simulate)

    for name, (module, func, help_) in DELEGATED.items():
        d = sub.add_parser(name, help=help_, add_help=False)
        d.add_argument("rest", nargs=argparse.REMAINDER)
        d.set_defaults(func=_delegate(module, func))
    return p


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    split = _split_delegated(argv)
    if split is not None:
        cmd, rest, tb = split
        args = argparse.Namespace(command=cmd, rest=rest, traceback=tb, func=_delegate(*DELEGATED[cmd][:2]))
    else:
        args = build_parser().parse_args(argv)
    show = args.traceback or os.environ.get("LSS_TRACEBACK") == "1"
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("lss: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # one line for the user, the trace on request
        if show:
            raise
        from .runner import SimulationError
        known = (UserError, SimulationError, FileNotFoundError, KeyError, ValueError, PermissionError)
        msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else str(exc)
        kind = "" if isinstance(exc, known) else f"{type(exc).__name__}: "
        print(f"lss {args.command}: {kind}{msg}".splitlines()[0], file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
