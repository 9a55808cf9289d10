"""Settling a provisional effect (identification.loop.settle, issue 18): confirmed
only if, switched off in the final model with the rest refitted, the misfit
rises decisively."""
from __future__ import annotations

import dataclasses

import numpy as np

from identification.loop.attribution import Attribution
from identification.loop.loop_result import Round


def _round(number, outcome, *, confirmed=False, provisional=False, **kw):
    r = Round(number, 1.0, np.ones(7), Attribution(1.0, 1.0, [], []), f"round {number}: {outcome}",
              effect=f"effect{number}", confirmed=confirmed, provisional=provisional, outcome=outcome, **kw)
    r.verdict_if_confirmed = f"effect{number} confirmed"
    return r


def test_a_provisional_effect_not_needed_in_the_final_model_stays_unconfirmed():
    """A later round's model reaches the noise, but switched off there (the rest
    refitted) the provisional effect leaves the misfit where it was: a later
    effect explains what it had taken; it is not confirmed
    (identification.loop.settle)."""
    from identification.loop.settle import settle_provisional
    calls = []

    def not_needed(r, last):
        calls.append((r.number, last.number))
        return {"dS": 0.4, "dbic": -20.0, "p": 0.5, "needed": False, "text": "S rises by 0.4"}

    def needed(r, last):
        return {"dS": 900.0, "dbic": 850.0, "p": 0.0, "needed": True, "text": "S rises by 900"}

    rounds = [_round(1, "not in the catalogue", provisional=True), _round(2, "confirmed", confirmed=True)]
    settle_provisional(rounds, not_needed)
    assert calls == [(1, 2)]
    assert not rounds[0].confirmed and rounds[0].outcome == "not in the catalogue"
    assert "not needed" in rounds[0].verdict and rounds[0].refined["settled"]["dbic"] == -20.0
    assert rounds[1].confirmed
    rounds = [_round(1, "not in the catalogue", provisional=True), _round(2, "confirmed", confirmed=True)]
    settle_provisional(rounds, needed)
    assert rounds[0].confirmed and "still needed there" in rounds[0].verdict
    # no later model at the noise: never asked
    calls.clear()
    rounds = [_round(1, "not in the catalogue", provisional=True), _round(2, "not in the catalogue")]
    settle_provisional(rounds, not_needed)
    assert calls == [] and not rounds[0].confirmed


def test_switching_an_effect_off_removes_its_parameters_everywhere():
    """The final model with an effect switched off carries none of its
    parameters (free, fixed or start value): the FMU's defaults, the effect off."""
    from identification.objective.problem import DESIGN, IdentificationProblem
    from identification.loop.settle import switched_off_in
    cor, h, s = DESIGN[0], "effects.track_bump.height", "effects.track_bump.s"
    p = IdentificationProblem(np.zeros((3, 7)), np.arange(3.0), "layout7", "LW", {cor: (0.1, 1.0), h: (-1e-3, 1e-3)},
                              fixed={s: 4.0, "drive.k_p": 1.0}, free=(cor, h), x0={cor: 0.2, h: 1e-4})
    off, x = switched_off_in(p, np.array([0.3, 5e-4]), [h, s])
    assert tuple(off.free) == (cor,) and list(x) == [0.3]
    assert off.fixed == {"drive.k_p": 1.0} and h not in off.x0
    assert h not in off.values(x) and s not in off.values(x)
    assert tuple(p.free) == (cor, h) and s in p.fixed   # the final model itself untouched


def test_an_effect_is_needed_in_the_final_model_only_if_the_record_has_it(fmu_file):
    """Through the FMU: the record of a transducer cart 25 % heavier, the final
    model with that mass and a 20 um track bump the record does not have.
    Switched off (the CoRs and the other effect refitted), the mass raises
    the misfit far beyond the noise (needed), the bump does not."""
    from identification.objective.noise import noise_levels
    from identification.loop.settle import still_needed
    from identification.loop.synthetic import TRUTH, effect_case
    from lss_fmu.sensor import NOISE_STD
    mass, bump = "effects.mass.transducer_factor", "effects.track_bump.height"
    prob, _ = effect_case([], 7, params={mass: 1.25}, transducer=0)
    place = {"effects.track_bump.s": 10.0, "effects.track_bump.length": 0.2}
    final = dataclasses.replace(prob, free=(*prob.free, mass, bump),
                                bounds={**prob.bounds, mass: (0.5, 1.6), bump: (-1e-3, 1e-3)},
                                fixed={**prob.fixed, **place}, x0={**prob.x0, mass: 1.25, bump: 2e-5})
    x = np.array([TRUTH[n] for n in prob.free] + [1.25, 2e-5])
    noise = noise_levels(np.zeros((3, 7)), NOISE_STD)
    last = _round(2, "confirmed", confirmed=True, problem_extended=final, x_extended=x, noise=noise)
    real = still_needed(_round(1, "x", provisional=True, identified={mass: 1.25}), last)
    assert real is not None and real["needed"] and real["dbic"] > 100 and real["p"] < 1e-6, real
    spurious = still_needed(_round(1, "x", provisional=True, identified={bump: 2e-5, **place}), last)
    assert spurious is not None and not spurious["needed"], spurious
