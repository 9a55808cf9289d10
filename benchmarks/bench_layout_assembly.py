#!/usr/bin/env python3
"""How often the FMU cannot assemble a chain on a layout within the layout
rules, by curve radius in cart pitches (issue 20, docs/layouts.md).

Random closed layouts (ovals, rounded rectangles, loops with a level change,
loops with a helix) with a pitch of 0.5-5 m and the smallest radius 1-2.5
times max(1 m, 2 pitches), built with the FMU's chain_create (the core
library, default parameters):

    .venv/bin/python benchmarks/bench_layout_assembly.py --n 1500 --seed 2
"""
from __future__ import annotations

import argparse
import math
import random
import tempfile
from collections import Counter
from pathlib import Path

from lss_fmu import ccore
from lss_fmu.layout_format import LayoutError, parse_layout
from lss_fmu.track_geometry import Track


def chain_builds(ffi, lib, path: Path) -> bool:
    par = lib.lss_params_new()
    lib.lss_params_set_string(par, b"layout.name", str(path).encode())
    err = ffi.new("char[1024]")
    c = lib.lss_chain_new(par, ffi.NULL, err, 1024)
    lib.lss_params_free(par)
    if c != ffi.NULL:
        lib.lss_chain_free(c)
    return c != ffi.NULL


def random_layout(rng: random.Random):
    fam = rng.choice(["oval", "rect", "vert", "spiral"])
    p = math.exp(rng.uniform(math.log(0.5), math.log(5)))
    r_rule = max(1.0, 2 * p)
    R = r_rule * math.exp(rng.uniform(0, math.log(2.5)))
    R2 = r_rule * math.exp(rng.uniform(0, math.log(4)))
    S = rng.uniform(0.05, 20)
    if fam == "oval":
        els = [f"straight {S}", f"curve {R} 180 left"] * 2
    elif fam == "rect":
        S2 = rng.uniform(0.05, 20)
        els = [f"straight {S}", f"curve {R} 90 left", f"straight {S2}", f"curve {R2} 90 left"] * 2
    elif fam == "vert":
        a, t = rng.uniform(1, 30), rng.uniform(0.05, 5)
        horiz = 2 + 2 * R2 * math.sin(math.radians(a)) + t * math.cos(math.radians(a))
        els = ["straight 1", f"vcurve {R2} {a} up", f"straight {t}", f"vcurve {R2} {a} down", "straight 1",
               f"curve {R} 180 left", f"straight {horiz!r}", f"curve {R} 180 left"]
    else:
        a, t = rng.uniform(1, 8), rng.uniform(0.5, 5)
        rise = 2 * R2 * (1 - math.cos(math.radians(a))) + t * math.sin(math.radians(a))
        Rs = rise / (2 * math.pi * math.tan(math.radians(a)))
        if Rs < r_rule:
            return None
        horiz = 2 * R2 * math.sin(math.radians(a)) + t * math.cos(math.radians(a))
        els = [f"straight {S}", f"vcurve {R2} {a} up", f"straight {t}", f"vcurve {R2} {a} down",
               f"vcurve {R2} {a} down", f"spiral {Rs!r} 360 left", f"vcurve {R2} {a} up",
               f"straight {S + horiz!r}", f"curve {R} 180 left", f"straight {S + 2 * horiz!r}", f"curve {R} 180 left"]
    head = f"wheel {rng.choice('ABC')}\ncoupling {rng.choice('AB')}\nmotors 1\n"
    try:
        track = Track(parse_layout(head + "\n".join(els) + "\n"))
    except LayoutError:
        return None
    n = max(3, round(track.length / p))
    r_min = min(e.radius for e in track.spec.elements if e.kind != 1)
    return head + f"carts {n}\n" + "\n".join(els) + "\n", r_min / (track.length / n)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=1500)
    ap.add_argument("--seed", type=int, default=2)
    args = ap.parse_args()
    ffi, lib = ccore.load()
    rng = random.Random(args.seed)
    tried, failed = Counter(), Counter()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "sweep.layout"
        while sum(tried.values()) < args.n:
            made = random_layout(rng)
            if made is None:
                continue
            text, ratio = made
            path.write_text(text)
            b = math.floor(ratio * 4) / 4
            tried[b] += 1
            failed[b] += not chain_builds(ffi, lib, path)
    print("smallest radius / pitch   layouts   not assembled")
    for b in sorted(tried):
        print(f"  {b:4.2f} - {b + 0.25:4.2f}          {tried[b]:6d}   {failed[b]:5d} ({100 * failed[b] / tried[b]:.1f} %)")


if __name__ == "__main__":
    main()
