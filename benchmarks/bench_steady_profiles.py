#!/usr/bin/env python3
"""Does a statistical objective make the CoRs identifiable in steady running?
(issue 17, item 2)

On steady-running recovery records (a whole lap after the photocell, LW truth)
each CoR is moved along a grid around its true value, every other design
variable at the truth, and the record's objective is evaluated both ways from
the same simulation: the paper's pointwise Eq. 10-12 and the statistics of
identification.objective.features (spectra and amplitude distributions per channel).
Beside each profile, the objective's own scatter: the same objective at tiny
perturbations of the truth (1e-4 of each CoR's range), which a chaotic
record turns into a different trajectory every time. A CoR is identifiable
by an objective when its profile rises well above that scatter.

    .venv/bin/python benchmarks/bench_steady_profiles.py --measurements 20,13 \\
        --json benchmarks/results/steady_profiles.json --figures docs/figures
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from identification.objective.features import stat_errors  # noqa: E402
from identification.objective.problem import from_measurement, nrmsd  # noqa: E402
from lss_fmu.atomic import write_json_atomic  # noqa: E402
from lss_fmu.design import CORS, SYMBOL  # noqa: E402
from lss_fmu.measurement import load_measurement  # noqa: E402
from lss_fmu.rig import generate_set, load_truth, parse_numbers, true_design_values  # noqa: E402


def evaluate(p, x) -> tuple:
    sim = p.simulate(x)
    return (float(np.sum(nrmsd(p.samples, sim, p.tare) ** 2)),
            float(np.sum(stat_errors(p.samples, sim, p.rate, p.tare) ** 2)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default="build/bench_steady_profiles")
    ap.add_argument("--measurements", default="20,13")
    ap.add_argument("--half-width", type=float, default=0.15)
    ap.add_argument("--points", type=int, default=7)
    ap.add_argument("--scatter", type=int, default=6)
    ap.add_argument("--json", default=None)
    ap.add_argument("--figures", default=None)
    args = ap.parse_args(argv)
    numbers = parse_numbers(args.measurements)
    data = Path(args.work) / "data"
    generate_set("recovery", data, numbers, workers=2, log=lambda m: print(m, file=sys.stderr))
    out = {"command": " ".join(sys.argv), "measurements": {}}
    for n in numbers:
        m = load_measurement(data / f"m{n:02d}")
        truth = load_truth(m)
        p = from_measurement(m, "LW", tare=True)
        vals = true_design_values(truth)
        xt = np.array([vals[d] for d in p.free])
        c0 = time.process_time()
        f_pt, f_st = evaluate(p, xt)
        rng = np.random.default_rng(0)
        scatter = []
        for _ in range(args.scatter):
            x = xt.copy()
            for k, d in enumerate(p.free):
                if d in CORS:
                    x[k] += 1e-4 * 0.7 * rng.uniform(-1, 1)
            scatter.append(evaluate(p, x))
        profiles = {}
        for d in CORS:
            k = p.free.index(d)
            lo, hi = p.bounds[d]
            grid = np.clip(xt[k] + np.linspace(-args.half_width, args.half_width, args.points), lo, hi)
            rows = []
            for g in grid:
                x = xt.copy()
                x[k] = g
                rows.append(evaluate(p, x))
            profiles[SYMBOL[d]] = {"grid": grid.tolist(), "pointwise": [r[0] for r in rows],
                                   "statistics": [r[1] for r in rows], "truth": float(xt[k])}
        sc = np.array(scatter)
        entry = {"layout": m.layout, "duration_s": float(m.duration), "f_truth": {"pointwise": f_pt, "statistics": f_st},
                 "scatter": {"pointwise": sc[:, 0].tolist(), "statistics": sc[:, 1].tolist()},
                 "profiles": profiles, "cpu_s": time.process_time() - c0}
        out["measurements"][m.id] = entry
        print(f"{m.id} ({m.layout}, {m.duration:.0f} s): f(truth) pointwise {f_pt:.4g}, statistics {f_st:.4g}; "
              f"scatter pointwise {sc[:, 0].min():.4g}-{sc[:, 0].max():.4g}, statistics "
              f"{sc[:, 1].min():.4g}-{sc[:, 1].max():.4g}")
        for s, pr in profiles.items():
            print(f"  {s}: pointwise " + " ".join(f"{v:.4g}" for v in pr["pointwise"]))
            print(f"  {s}: statistics " + " ".join(f"{v:.4g}" for v in pr["statistics"]))
        if args.json:
            write_json_atomic(args.json, out)
        if args.figures:
            draw(entry, Path(args.figures) / f"steady_profiles_{m.layout}", m.id)
        p.sim.close()
    return 0


def draw(entry: dict, path: Path, title: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(2, 4, figsize=(14, 6), sharey="row")
    for row, obj in enumerate(("pointwise", "statistics")):
        band = entry["scatter"][obj]
        for ax, (s, pr) in zip(axes[row], entry["profiles"].items()):
            ax.axhspan(min(band), max(band), color="0.85", label="scatter at the truth")
            ax.plot(pr["grid"], pr[obj], "o-", ms=3, label=obj)
            ax.axvline(pr["truth"], color="k", ls=":", lw=1, label="truth")
            ax.set_xlabel(s)
            ax.grid(alpha=0.3)
        axes[row][0].set_ylabel(f"f, {obj}")
    axes[0][0].legend(fontsize=7)
    fig.suptitle(f"{title}: objective along each CoR, steady running, the rest at the truth")
    fig.tight_layout()
    from lss_app.figures.save import save_figure
    save_figure(fig, path)


if __name__ == "__main__":
    sys.exit(main())
