"""One answer whatever the CPU: a short identification and a short closed loop
on two forced right-hand-side paths give the same result within tolerances.

The paths (scalar, AVX2, AVX-512) round differently in the last bits, as
another CPU's linear algebra does; an optimiser's route through the points it
asks for diverges after the first differing bit. What must not diverge is
the answer: the identified CoRs agree within a small part of their interval,
the fit reaches the same objective, the loop gives the same verdict. The
same comparison over every path and two other BLAS kernels, on longer
records: benchmarks/bench_cross_path.py (docs/robustness.md).
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from identification.close_loop import close_loop
from identification.identify import identify
from identification.synthetic import effect_case, release_problem
from lss_fmu.design import CORS

from conftest import path_available
from test_close_loop import _evidence_reported

SHIFT = 0.5       # of a half-interval: CoRs of two paths agree within this
F_RATIO = 1.05    # and their objectives within this factor


@pytest.fixture(scope="module")
def two_paths(fmu_file, best_vector_path):
    """The two widest paths this CPU runs (the scalar one costs twice as much;
    benchmarks/bench_cross_path.py runs every path)."""
    if best_vector_path == 1 or not path_available(fmu_file, best_vector_path - 1):
        pytest.skip("this CPU runs one right-hand-side path only")
    return best_vector_path - 1, best_vector_path


def _on_path(problem, path: int):
    return dataclasses.replace(problem, fixed={**problem.fixed, "solver.vector_path": path})


def test_identification_agrees_across_paths(two_paths):
    """Complex-RF from the middle of the box, refined by Levenberg-Marquardt,
    with intervals, on the first 0.4 s of the release transient: the CoRs the
    noise lets through (e_JA, e_SW, e_RW; e_JR is below it) agree within
    SHIFT of their interval, the claims agree, both fits reach the same
    objective. (Whether that point is the truth: tests/test_identification.py.)"""
    base = release_problem(window=0.4)
    results = [identify(_on_path(base, p), max_evals=150, seed=0, progress=False, refine_evals=200,
                        uncertainty=True) for p in two_paths]
    a, b = results
    iv = {i.name: i for i in a.intervals}
    for n in ("contact.e_JA", "contact.e_SW", "contact.e_RW"):
        half = 0.5 * (iv[n].upper - iv[n].lower)
        assert abs(a.x[CORS.index(n)] - b.x[CORS.index(n)]) <= SHIFT * half, (n, a.x, b.x, half)
    assert [i.identifiable for i in a.intervals] == [i.identifiable for i in b.intervals]
    assert max(a.f, b.f) <= F_RATIO * min(a.f, b.f), (a.f, b.f)


def test_loop_verdict_agrees_across_paths(two_paths):
    """The closed loop on a release transient with the transducer cart a
    quarter heavier (an effect the CoRs absorb: catalogue.ABSORBED, fitted
    with them): on both paths the mass is confirmed with its evidence, the
    extended model at the noise, the factor right within 0.02."""
    problem, _ = effect_case([], 146954997, params={"effects.mass.transducer_factor": 1.25}, transducer=7)
    out = []
    for p in two_paths:
        res = close_loop(_on_path(problem, p), rounds=1, seed=0, base_evals=80, max_evals=100, refine_evals=40,
                         fit_evals=20, base_refine_evals=60, test_max=4)
        out.append(res)
    assert [r.found for r in out] == [["mass"], ["mass"]], [r.verdict for r in out]
    for r in out:
        _evidence_reported(r.rounds[0])
        assert next(t for t in r.rounds[0].tests if t.effect == "mass").adequate
    amps = [r.rounds[0].amplitude for r in out]
    assert abs(amps[0] - amps[1]) <= 0.02 and all(abs(a - 0.25) <= 0.02 for a in amps), amps
