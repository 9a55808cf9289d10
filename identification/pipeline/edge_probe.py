"""A CoR found near its box edge, refined again from the edge (issue 17).

The Complex-RF reflects a point that leaves the box back inside it, so the
region along an edge is the one its points visit least, and the
Levenberg-Marquardt refinement after it goes down the valley it starts in.
Where the truth lies close to an edge the two together can stop in a
neighbouring local minimum a few hundredths further in: on one layout-5
record (three start-stops, e_RW true 0.200 on its lower bound) the pipeline
ended at e_RW 0.241, f 20.9275, with an interval of +-0.016 that missed the
truth; the same refinement started from the point with e_RW moved onto the
edge ends at e_RW 0.203, f 20.918, below it (110 CPU-s).

`edge_probes` does that for each identifiable CoR whose estimate lies within
EDGE_SHARE of its range from an edge: the refinement from the point with
that CoR on the edge, kept only where it ends at a lower f, then the
intervals again at the point kept. A CoR reported not identifiable is left
alone (its profile is flat: the edge says nothing), and so are the other
design variables (their boxes come from meta.json's nominal values, not from
what the chain can be).
"""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Optional

import numpy as np

from lss_fmu.design import CORS

from .identify import local_stage

log = logging.getLogger(__name__)

EDGE_SHARE = 0.075   # of the CoR's range (0.7): within 0.0525 of an edge
AT_EDGE = 1e-6       # of the range: already on the edge, nothing to probe


def near_edges(problem, x, intervals) -> list:
    """[(name, index, edge)] of the identifiable CoRs within EDGE_SHARE of an edge."""
    if not intervals:
        return []
    ok = {iv.name for iv in intervals if iv.identifiable}
    out = []
    for j, (name, (lo, hi)) in enumerate(zip(problem.free, problem.bounds_array)):
        if name not in CORS or name not in ok or not hi > lo:
            continue
        span = hi - lo
        edge = lo if x[j] - lo <= hi - x[j] else hi
        if AT_EDGE * span < abs(x[j] - edge) <= EDGE_SHARE * span:
            out.append((name, j, float(edge)))
    return out


def edge_probes(problem, x, f: float, intervals, refine_evals: int, journal: Optional[Path]) -> tuple:
    """(x, f, intervals, probes): the point after the probes (module
    docstring) and one entry per probe (the CoR, its edge, f from there,
    simulations, whether it was kept). Each probe's refinement is kept in a
    journal of its own (identify.local_stage), so a resumed run does not pay again."""
    x = np.asarray(x, float)
    probes = []
    if refine_evals <= 0:
        return x, f, intervals, probes
    best = None
    for name, j, edge in near_edges(problem, x, intervals):
        xs = x.copy()
        xs[j] = edge
        jr = None if journal is None else \
            Path(journal).with_name(Path(journal).stem + f".edge.{name.split('.')[-1]}.jsonl")
        try:
            f_start = float(problem(xs))
            local = local_stage(problem, xs, f_start, int(refine_evals), False, jr)
        except Exception as exc:   # a probe that fails leaves the result as it was
            log.warning("%s: probe from the edge of %s failed: %s", problem.name, name, exc)
            continue
        fe = float(local.get("f", f_start))
        xe = np.asarray(local.get("x", xs), float)
        probes.append({"name": name, "edge": edge, "from": float(x[j]), "f": fe, "to": float(xe[j]),
                       "nfev": 1 + int((local.get("refined") or {}).get("nfev", 0)), "kept": False})
        if fe < f and (best is None or fe < best[1]):
            best = (xe, fe, len(probes) - 1)
    if best is None:
        return x, f, intervals, probes
    x, f = best[0], best[1]
    probes[best[2]]["kept"] = True
    jr = None if journal is None else Path(journal).with_name(Path(journal).stem + ".edge.jsonl")
    again = local_stage(problem, x, f, 0, True, jr).get("intervals")
    log.info("%s: from the edge of %s f = %.6g is kept", problem.name, probes[best[2]]["name"], f)
    return x, f, again if again is not None else intervals, probes


__all__ = ["edge_probes", "near_edges", "EDGE_SHARE"]
