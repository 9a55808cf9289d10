"""identification.variants: a wheel extension with the wrong order, above the
noise, is replaced by the order that fits, through the FMU."""
import numpy as np
from scipy.optimize import minimize

from identification.attribution import attribute, weights
from identification.catalogue import CATALOGUE
from identification.extension import extended_problem, extension_of
from identification.locate import context
from identification.problem import weighted_residual
from identification.synthetic import make_problem
from identification.variants import best_variant

WHEEL = {"effects.wheel_oor.amplitude": 80e-6, "effects.wheel_oor.order": 2,
         "effects.wheel_oor.phase_left": 1.0, "effects.wheel_oor.phase_right": 4.0}


def _fit(w, calls):
    """The effect's parameters alone by Nelder-Mead (the CoRs are the truth here):
    the choice, not the optimiser, under test."""
    def fit(problem, x, i):
        calls.append(i)
        k = [j for j, n in enumerate(problem.free) if n.startswith("effects.")]
        out = np.array(x, float)

        def S(v):
            out[k] = v
            return weighted_residual(problem, problem.simulate(out), w)[1]
        out[k] = minimize(S, out[k], method="Nelder-Mead", options={"maxfev": 60, "xatol": 1e-7}).x
        return out
    return fit


def test_the_order_that_fits_replaces_the_one_ranked_first(fmu_file):
    problem, truth = make_problem(WHEEL, 3, window=0.6)
    att = attribute(problem, truth, context(problem, truth), effects=["wheel_oor"])
    one = next(h for h in att.all_hypotheses if h.label == "1 lobe")
    ext = extension_of(one)
    prob = extended_problem(problem, truth, ext)
    w = weights(problem)
    calls = []
    x = _fit(w, [])(prob, np.array([prob.x0[n] for n in prob.free]), 0)
    sim = prob.simulate(x)
    S = weighted_residual(prob, sim, w)[1]
    h, ext2, prob2, x2, S2, sim2, tried = best_variant(one, att, problem, ext, prob, x, S, sim, w, _fit(w, calls))
    assert [t["hypothesis"] for t in tried] == ["2 lobes", "3 lobes"] and calls == [1, 2]
    assert h.label == "2 lobes" and ext2.fixed["effects.wheel_oor.order"] == 2, tried
    assert prob2.fixed["effects.wheel_oor.order"] == 2 and S2 < 0.5 * S, (S, S2)   # measured: 0.36
    assert np.isclose(weighted_residual(prob2, prob2.simulate(x2), w)[1], S2)


def test_an_effect_without_alternatives_is_left_alone():
    class Score:
        effect = "mass"
    sc = Score()
    out = best_variant(sc, None, None, "ext", "problem", "x", 1.0, None, None, fit=None)
    assert out == (sc, "ext", "problem", "x", 1.0, None, [])
