"""identification.ladder: an extension that ended on its rung's edge is
identified again on the rung beyond, through the FMU."""
import numpy as np

from scipy.optimize import minimize_scalar

from identification.attribution import weights
from identification.catalogue import CATALOGUE
from identification.extension import extended_problem
from identification.ladder import walk_ladder
from identification.problem import weighted_residual
from identification.synthetic import make_problem

GAP = "effects.joint_clearance.gap"


def _on_rung(drawn: float, rung_gap: float, start: float, seed: int = 7):
    """The extension of a record with a play `drawn` on the rung of `rung_gap`,
    at the true CoRs with the gap at `start`."""
    problem, truth = make_problem({GAP: drawn}, seed, window=0.6)
    clr = CATALOGUE["joint_clearance"]
    hyp = next(h for h in clr.hypotheses(None) if abs(h.probes[0].params[GAP] - rung_gap) < 1e-3 * rung_gap)
    ext = extended_problem(problem, truth, clr.extension(hyp, np.array([start])))
    x = np.array([ext.x0[n] for n in ext.free])
    w = weights(problem)
    sim = ext.simulate(x)
    return ext, x, weighted_residual(ext, sim, w)[1], sim, w


def _local_fit(w, calls):
    """The gap alone, by Brent's bounded search (the CoRs are the truth here, and
    S is V-shaped about the drawn gap): the walk, not the optimiser, under test."""
    def fit(problem, x, i):
        calls.append((i, problem.bounds[GAP]))
        lo, hi = problem.bounds[GAP]
        out = np.array(x, float)

        def S(g):
            out[-1] = g
            return weighted_residual(problem, problem.simulate(out), w)[1]
        out[-1] = minimize_scalar(S, bounds=(lo, hi), method="bounded", options={"xatol": 1e-3 * lo}).x
        return out
    return fit


def test_a_play_stopped_on_the_rung_below_is_walked_up_to_it(fmu_file):
    """20 um drawn, the extension on the 7.7 um rung ended at its upper bound
    (joint_clearance_a5_r00 of the rates benchmark)."""
    ext, x, S, sim, w = _on_rung(20e-6, 7.69e-6, 20e-6)
    assert np.isclose(x[-1], ext.bounds[GAP][1])   # clipped to the rung: on its edge
    calls = []
    moved, xm, S_m, sim_m, walked = walk_ladder("joint_clearance", ext, x, S, sim, w, _local_fit(w, calls))
    assert walked and S_m < 0.2 * S, (S, S_m, walked)
    assert abs(xm[-1] / 20e-6 - 1.0) < 0.05, xm[-1]
    lo, hi = moved.bounds[GAP]
    assert lo <= xm[-1] <= hi and lo < ext.bounds[GAP][1] < hi, (lo, hi)   # the rung beyond the old edge
    assert calls[0][0] == 1 and len(calls) == len(walked)
    assert np.isclose(weighted_residual(moved, moved.simulate(xm), w)[1], S_m)


def test_a_play_inside_its_rung_is_not_walked(fmu_file):
    ext, x, S, sim, w = _on_rung(4e-6, 3.42e-6, 4e-6)
    calls = []
    moved, xm, S_m, _, walked = walk_ladder("joint_clearance", ext, x, S, sim, w, _local_fit(w, calls))
    assert moved is ext and xm is x and S_m == S and walked == [] and calls == []


def test_an_effect_without_a_ladder_is_left_alone():
    class Problem:
        free = ("contact.e_JA", "effects.mass.transducer_factor")
    p, x = Problem(), np.zeros(2)
    out = walk_ladder("mass", p, x, 1.0, None, np.ones(7), fit=None)
    assert out[0] is p and out[1] is x and out[2] == 1.0 and out[4] == []
