"""`lss build` and `lss simulate`: the FMU itself."""
from __future__ import annotations

from pathlib import Path


def register(sub, common) -> None:
    b = sub.add_parser("build", parents=[common], help="build build/LSSChain.fmu")
    b.set_defaults(run=run_build)

    s = sub.add_parser("simulate", parents=[common],
                       help="simulate a layout and write the transducer signals as CSV")
    s.add_argument("--layout", default="demo", help="built-in layout name or layout file")
    s.add_argument("--stop-time", type=float, required=True)
    s.add_argument("--step", type=float, default=1.0 / 300.0, help="communication step, s")
    s.add_argument("--tolerance", type=float, default=None)
    s.add_argument("--out", required=True, help="CSV file to write")
    s.add_argument("--set", action="append", metavar="NAME=VALUE", help="set an FMU parameter")
    s.add_argument("--output", action="append", metavar="NAME", help="record another output")
    s.set_defaults(run=run_simulate)


def run_build(args) -> int:
    from lss_fmu import build
    build.build_fmu()
    return 0


def parse_set(items: list[str] | None) -> dict:
    params = {}
    for item in items or []:
        if "=" not in item:
            raise ValueError(f"--set {item!r}: expected NAME=VALUE")
        name, value = item.split("=", 1)
        params[name.strip()] = value.strip()
    return params


def typed(sim, params: dict) -> dict:
    """--set values converted to the FMU variables' types (a clear error for a wrong one)."""
    out = {}
    for name, value in params.items():
        var = sim.variables.get(name)
        if var is None:
            sim.vr(name)  # raises KeyError naming the variable
        try:
            out[name] = {"Real": float, "Integer": int, "Boolean": lambda v: v.lower() in ("1", "true"),
                         "String": str}[var.type](value)
        except ValueError:
            raise ValueError(f"--set {name}={value}: {name} takes a {var.type} value") from None
    return out


def run_simulate(args) -> int:
    from lss_fmu.atomic import write_atomic
    from lss_fmu.layouts import resolve_layout
    from lss_fmu.runner import DEFAULT_OUTPUTS, ChainSimulator
    layout = args.layout
    resolve_layout(layout)  # clear error for an unknown layout
    if layout.endswith(".layout") or "/" in layout:
        layout = str(Path(layout).resolve())
    with ChainSimulator() as sim:
        params = {"layout.name": layout, **typed(sim, parse_set(args.set))}
        outputs = list(DEFAULT_OUTPUTS) + [o for o in (args.output or []) if o not in DEFAULT_OUTPUTS]
        for o in outputs:
            sim.vr(o)
        df = sim.simulate(args.stop_time, args.step, params, outputs, tolerance=args.tolerance)
        info = sim.info()
    out = Path(args.out)
    write_atomic(out, df.to_csv(index=False))
    print(f"wrote {out}: {len(df)} rows, {df.shape[1] - 1} channels; "
          f"{info.n_steps} solver steps ({info.n_rejected} rejected)")
    return 0
