"""`make demo`: the main job on an embedded default, end to end.

1. simulate the built-in layout 7 (52 carts) with the virtual transducer cart
   and write one start-stop measurement (samples + metadata; the truth goes to
   a separate answer file);
2. identify the ten design variables as `lss identify` does by default;
3. close the loop on a start-stop of the same sorter with an undeclared effect:
   analyse the residual, trace it to a missing effect, extend the model and
   report the error before and after.

The output folder gets a README.md that links the figures and tables of
every stage. `lss demo --out DIR`; `make demo` runs it into demo_out/.
"""
from __future__ import annotations

import time
from pathlib import Path


def simulate_and_plot(out: Path) -> list[str]:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lss_fmu.runner import ChainSimulator
    from lss_fmu.variables import FORCE_CHANNELS

    with ChainSimulator() as sim:
        t0 = time.process_time()
        df = sim.simulate(12.0, 1.0 / 300.0, {"layout.name": "layout7", "drive.v_ref": 2.0})
        cpu = time.process_time() - t0
        n = sim.get("chain.n_carts")
    df.to_csv(out / "simulation_layout7.csv", index=False)
    fig, axes = plt.subplots(len(FORCE_CHANNELS), 1, figsize=(10, 12), sharex=True)
    for ax, ch in zip(axes, FORCE_CHANNELS):
        ax.plot(df["time"], df[ch], lw=0.7)
        ax.set_ylabel(ch.replace("transducer.", ""), fontsize=8)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time, s")
    fig.suptitle("Layout 7, transducer cart: the seven forces (N)")
    fig.tight_layout()
    fig.savefig(out / "simulation_layout7.png", dpi=110)
    plt.close(fig)
    return [f"## Simulation\n\nLayout 7, {n} carts, 12 s simulated in {cpu:.1f} CPU-s "
            f"({n * 12 / cpu:.0f} cart-s per CPU-s).\n\n![forces](simulation_layout7.png)\n"]


def register(sub, common) -> None:
    ap = sub.add_parser("demo", parents=[common], help="the main job end to end on a built-in layout",
                        description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="demo_out", help="output folder (default demo_out)")
    ap.set_defaults(run=run)


def run(args) -> int:
    from .demo_identify import run_stages
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sections = ["# LSS demo\n"]
    print("[1] simulating layout 7 ...", flush=True)
    sections += simulate_and_plot(out)
    sections += run_stages(out)
    (out / "README.md").write_text("\n".join(sections))
    print(f"demo written to {out}/README.md")
    return 0
