"""Closing the loop on data with undeclared effects (issues 7 and 18).

Each case: the release transient of layout 7 measured with effects switched on
(drawn by the virtual transducer cart's draw from a seed, or given), the loop
told nothing about them. The loop identifies the base model, refits it to
its own optimum, ranks the catalogue, tests the leading candidates against
the noise (likelihood ratio, BIC, held-out validation, disturbances outside
the catalogue) and extends the model with a confirmed one. What must hold:
the right effect confirmed with its evidence, the extended objective at most
half of the base one, the identified amplitude within 25 % of the truth; on
a clean record nothing confirmed; a gain-only sensor error confirmed as a
sensor fault; two effects found in turn; disturbances outside the catalogue
reported as such and located; a degenerate candidate dropped with its
reason while the loop goes on.
"""
from __future__ import annotations

import numpy as np
import pytest

from identification.loop import catalogue
from identification.loop.close_loop import close_loop
from identification.loop.settings import LoopSettings
from identification.objective.noise import ALPHA
from identification.loop.synthetic import effect_case

BASE_EVALS = 120
EXT_EVALS = 200   # the extended design has 5 to 8 variables: 120 evaluations stop short
QUICK = dict(base_evals=80, max_evals=100, refine_evals=40)   # where no amplitude is checked
LEAN = dict(QUICK, profile_points=0)   # and where the disturbance, not the base's last digits, decides
# cases that repeat what a faster case here already checks (make test skips them; make test-slow runs them)
SLOW = pytest.mark.slow


def _loop(problem, rounds=1, effects=None, **budget):
    settings = LoopSettings(**{"base_evals": BASE_EVALS, "max_evals": EXT_EVALS, **budget})
    return close_loop(problem, effects=effects, rounds=rounds, seed=0, settings=settings)


def _record(name: str, res, **extra) -> None:
    """The case's figures for docs/close_loop.md, one file per case (xdist-safe)."""
    from lss_fmu.atomic import write_json_atomic
    from lss_fmu.build import BUILD
    write_json_atomic(BUILD / "close_loop_cases" / f"{name}.json",
                      {"case": name, "found": res.found, "verdict": res.verdict, "outcome": res.outcome,
                       "rounds": [r.to_dict() | {"attribution": None} for r in res.rounds], **extra})


def _true_amplitude(effect: str, params: dict, problem) -> float:
    return catalogue.CATALOGUE[effect].amplitude(params, problem.samples.mean(axis=0))


def _evidence_reported(rnd) -> None:
    """Every verdict carries its statistic, p-values and held-out gain."""
    d = rnd.to_dict()
    ev = d["evidence"]
    assert ev is not None and {"statistic", "p", "p_bonferroni", "dbic", "holdout_gain"} <= set(ev)
    assert d["noise"]["source"] in ("declared", "estimated") and d["excess"] is not None
    assert str(round(ev["statistic"], 1)) in rnd.verdict.replace(",", "") or "LR statistic" in rnd.verdict


def _mass_weighed(rnd):
    """An effect confirmed beside the transducer cart's mass, which the CoRs
    absorb: the mass was fitted and tested as its rival first (close_loop)."""
    assert rnd.effect == "mass" or "mass" in [t.effect for t in rnd.tests], [t.effect for t in rnd.tests]


# one seed per effect (180-265 CPU-s a case at 184-187 ns per cart and right-hand side; the out-of-round
# wheel: the two-effects case and the demo). Seeds 12 and 13 of the sensor and 11 and 13 of the mass were
# confirmed too when written (docs/close_loop.md); the rates over many records:
# benchmarks/bench_close_loop_rates.py. The mass's case in make test: the benchmark's cart a quarter heavier, below.
@pytest.mark.parametrize("effect, seed", [pytest.param("sensor", 11, marks=SLOW),
                                          pytest.param("joint_clearance", 11, marks=SLOW),
                                          pytest.param("mass", 12, marks=SLOW)])
def test_undeclared_effect_is_found_and_fitted(fmu_file, effect, seed):
    problem, params = effect_case([effect], seed)
    res = _loop(problem)
    rnd = res.rounds[0]
    assert rnd.confirmed and rnd.effect == effect and rnd.outcome == "confirmed", rnd.verdict
    ev = rnd.evidence
    assert ev.lr.p_adj < ALPHA and ev.lr.dbic > 0 and ev.holdout.gain > 0
    _evidence_reported(rnd)
    assert rnd.f_extended <= 0.5 * rnd.f_base, (rnd.f_base, rnd.f_extended)
    want = _true_amplitude(effect, params, problem)
    got = rnd.amplitude
    if effect == "sensor":  # the same channel on both sides: the most affected one
        sensor, levels = catalogue.CATALOGUE["sensor"], problem.samples.mean(axis=0)
        ch = int(np.argmax(np.abs(sensor.errors(params, levels))))
        got = sensor.amplitude(rnd.identified, levels, channel=ch)
    _record(f"{effect}_{seed}", res, truth=params, amplitude_true=want, amplitude_found=got)
    assert abs(got - want) <= 0.25 * abs(want), (effect, got, want, rnd.identified)


@pytest.mark.parametrize("seed, transducer", [pytest.param(22, None, marks=SLOW), (3, 20)])
def test_clean_record_nothing_confirmed(fmu_file, seed, transducer):
    """No effect at all: the base refitted to its optimum leaves noise, and no
    candidate passes (the old share rule confirmed a track bump on seed 22).
    With the transducer on cart 20 the base found on the whole second stopped
    200 times above the noise ("not in the catalogue"); grown from the first
    0.3 s it reaches it."""
    problem, _ = effect_case([], seed, transducer=transducer)
    res = _loop(problem, **QUICK)
    rnd = res.rounds[0]
    _record(f"none_{seed}" + (f"_cart{transducer}" if transducer is not None else ""), res)
    assert res.found == []
    assert rnd.outcome == "nothing significant", rnd.verdict
    assert rnd.tests and all(not t.supported for t in rnd.tests)
    _evidence_reported(rnd)
    assert float(np.max(rnd.excess.ratio)) < 1.5
    _reach_reported(rnd)


def _reach_reported(rnd) -> None:
    """Every effect with a size is judged (identification.loop.reach), and the
    verdict names the plausible ones the record cannot reveal, and only those."""
    sized = {n for n, e in catalogue.CATALOGUE.items() if e.PLAUSIBLE is not None}
    assert {r.effect for r in rnd.reach} == sized
    assert all(r.best <= r.typical and r.threshold > 0 for r in rnd.reach)
    unseen = [r for r in rnd.reach if not r.visible]
    assert ("cannot reveal" in rnd.verdict) == bool(unseen), rnd.verdict
    assert all(r.name in rnd.verdict for r in unseen)
    assert len(rnd.to_dict()["reach"]) == len(rnd.reach)


def test_gain_only_sensor_error_is_a_sensor_fault(fmu_file):
    """A 5 % gain error on one steering channel, no offset: confirmed as the
    sensor effect (it was confirmed as a motor ripple), the gain identified."""
    params = {"effects.sensor.gain.steering.F_right": 0.05}
    problem, _ = effect_case([], 7, params=params)
    res = _loop(problem)
    rnd = res.rounds[0]
    _record("gain_only_7", res, truth=params)
    assert res.found == ["sensor"], rnd.verdict
    _mass_weighed(rnd)
    assert abs(rnd.identified["effects.sensor.gain.steering.F_right"] - 0.05) <= 0.25 * 0.05, rnd.identified


@pytest.mark.parametrize("effect, params, seed, transducer", [
    pytest.param("mass", {"effects.mass.transducer_factor": 1.25}, 9, 13, marks=SLOW),
    ("track_bump", {"effects.track_bump.height": 0.002, "effects.track_bump.s": 24.646018366025523,
                  "effects.track_bump.length": 0.15}, 5, None)])
def test_the_issues_own_misses_are_confirmed(fmu_file, effect, params, seed, transducer):
    """Issue 18's two misses: a transducer cart a quarter heavier and a 2 mm
    track bump ended as "nothing significant". Both are confirmed now, with
    the transducer on another cart and a bump at another joint than the
    benchmark's records they were developed on: the bump (raised, 15 cm long,
    at the end of a curve) through a probe near its own length
    (catalogue.TrackBump), the mass, whose fit at the base's CoRs raised S,
    identified with the base over growing windows (candidates.regrow). A 2 mm
    *dip* at the same joint is not found (docs/close_loop.md, Limits)."""
    problem, _ = effect_case([], seed, params=params, transducer=transducer, lead=0.8)
    res = _loop(problem, **QUICK)
    rnd = res.rounds[0]
    _record(f"issue_{effect}_{seed}", res, truth=params)
    assert res.found == [effect], rnd.verdict
    _evidence_reported(rnd)
    _mass_weighed(rnd)
    want = _true_amplitude(effect, params, problem)
    assert abs(rnd.amplitude - want) <= 0.25 * abs(want), (rnd.amplitude, want, rnd.identified)


@SLOW   # make test runs this case on the CPU's two widest paths: tests/test_cross_path.py
def test_a_mass_the_cors_absorbed_is_searched_with_them(fmu_file):
    """A record of the rates benchmark with cart 7 a quarter heavier: held at
    the base's CoRs the fitted factor lowered S per sample from 23.5 to 21.3
    only, the linear fit was not significant either, so the mass was never
    searched with the CoRs; a sensor gain took 71 % of the misfit and nothing
    was confirmed. An effect the CoRs absorb (catalogue: ABSORBED) is now
    fitted with them: the mass is confirmed, the model reaches the noise and
    the factor is right."""
    params = {"effects.mass.transducer_factor": 1.25}
    problem, _ = effect_case([], 146954997, params=params, transducer=7)
    res = _loop(problem, **QUICK, fit_evals=20, base_refine_evals=60, candidates=4)
    rnd = res.rounds[0]
    _record("mass_absorbed_a5_r01", res, truth=params)
    assert res.found == ["mass"], rnd.verdict
    _evidence_reported(rnd)
    # what must hold, whichever refinement route the machine's rounding takes
    t = next(t for t in rnd.tests if t.effect == "mass")
    assert t.adequate, t.status
    assert abs(rnd.amplitude - 0.25) <= 0.02, rnd.identified


@SLOW
@pytest.mark.parametrize("seed, transducer", [(1458325094, 26)])   # a record of the rates benchmark
def test_a_share_of_another_effect_is_not_confirmed(fmu_file, seed, transducer):
    """The transducer cart 1 % heavier: a motor ripple fitted in its place
    took a share of the misfit past every test (on one record of the rates
    benchmark: S per sample from 12.1 to 10.5), but the model with it
    stayed ten times above the noise. Only an effect whose model reaches the
    noise, or removes most of the misfit above it, is confirmed: the mass,
    or nothing."""
    params = {"effects.mass.transducer_factor": 1.01}
    problem, _ = effect_case([], seed, params=params, transducer=transducer)
    res = _loop(problem, **QUICK)
    rnd = res.rounds[0]
    _record("mass_share_a3_r04", res, truth=params)
    assert res.found in ([], ["mass"]), rnd.verdict
    for t in rnd.tests:
        assert not t.supported or t.effect == "mass" or not t.adequate, (t.effect, t.status)


@SLOW
@pytest.mark.parametrize("seed, transducer", [(435425658, 26)])   # a record of the rates benchmark
def test_a_small_joint_play_is_not_read_as_a_track_bump(fmu_file, seed, transducer):
    """A 1 um play in every joint: a track bump at one joint, fitted with the
    CoRs, can take most of the misfit; the play is probed on a ladder of gaps
    (catalogue.JointClearance), the candidates after the first that passes are
    examined too (identification.loop.rivals), and an extension stopped on its
    rung's edge walks the ladder (identification.loop.ladder). What must hold,
    whichever route the fits take: the play confirmed at its size, never the
    bump."""
    params = {"effects.joint_clearance.gap": 1e-6}
    problem, _ = effect_case([], seed, params=params, transducer=transducer)
    res = _loop(problem, **QUICK)
    rnd = res.rounds[0]
    _record("clearance_1um_a3_r04", res, truth=params)
    assert res.found == ["joint_clearance"], rnd.verdict
    gap = rnd.evidence.identified["effects.joint_clearance.gap"]
    assert 1e-6 / 1.5 < gap < 1.5e-6, gap
    assert "track_bump" not in res.found


# an out-of-round wheel and zero errors on two channels (seed 32 passed too when written, before issue 18);
# slow: 7 CPU-min, the longest case; make test closes the loop end to end on a start-stop instead
# (tests/test_close_loop_start_stop.py)
@pytest.mark.parametrize("seed", [pytest.param(31, marks=SLOW)])
def test_two_effects_are_found_in_turn(fmu_file, seed):
    problem, params = effect_case(["wheel_oor", "sensor"], seed)
    res = _loop(problem, rounds=2)
    _record(f"two_{seed}", res, truth=params)
    assert sorted(res.found) == ["sensor", "wheel_oor"], [r.verdict for r in res.rounds]


def test_artefact_outside_the_catalogue_is_reported_and_located(fmu_file):
    rng = np.random.default_rng(41)  # a pulse on one channel at one place, outside the catalogue
    art = {"channel": str(rng.choice(["transducer.joint.F_y", "transducer.steering.F_left",
                                      "transducer.driving.F_right"])),
           "t": float(rng.uniform(0.3, 0.8)), "width": float(rng.uniform(0.08, 0.15)),
           "amplitude": float(rng.choice([-1, 1]) * rng.uniform(50.0, 80.0))}
    problem, _ = effect_case([], 41, artefact=art)
    res = _loop(problem, **LEAN)
    rnd = res.rounds[0]
    _record("artefact_41", res, artefact=art, location=rnd.location)
    assert res.found == []
    assert rnd.outcome == "not in the catalogue" and rnd.verdict.startswith("not in the catalogue"), rnd.verdict
    loc = rnd.location
    assert loc["channel"] == art["channel"]
    assert loc["t_start"] - 0.05 <= art["t"] <= loc["t_end"] + 0.05, loc


@pytest.mark.parametrize("name, family", [
    ("crosstalk", "crosstalk"),
    pytest.param("clock_drift", "clock", marks=SLOW)])
def test_disturbance_outside_the_catalogue_is_not_confirmed(fmu_file, name, family):
    """Crosstalk between channels, the logger's clock running fast (drawn by the
    rig, lss_fmu.rig_effects): "not in the catalogue", the disturbance named,
    never a catalogue effect (the interference: tests/test_evidence.py and
    docs/close_loop.md)."""
    problem, _ = effect_case([], 5, artefacts=[name])
    res = _loop(problem, **LEAN)
    rnd = res.rounds[0]
    _record(f"ooc_{name}_5", res)
    assert res.found == [] and rnd.outcome == "not in the catalogue", rnd.verdict
    best = max(rnd.departures, key=lambda d: d.test.dbic)
    assert best.family == family and best.test.significant, [(d.label, d.test.dbic) for d in rnd.departures]
    assert "Where:" in rnd.verdict and rnd.location.get("channel")


def test_degenerate_candidates_are_dropped_and_the_loop_goes_on(fmu_file, monkeypatch):
    """The transducer on a cart on a straight, where the steering channels are
    constant (the guide wheel's preload): a gain there is the same column as
    the offset, and is dropped as not identifiable; the channel's error is
    still found, as an offset (gain times the level plus offset). And
    a candidate whose bounds fall outside the FMU's range (issue 18: the run
    ended with `no room within the FMU's range`) is dropped with its reason."""
    from identification.loop import candidates as CL
    from identification.loop.catalogue import Extension
    params = {"effects.sensor.offset.steering.F_left": 40.0, "effects.sensor.gain.steering.F_left": 0.2}
    problem, _ = effect_case([], 8, params=params, transducer=7)
    assert np.ptp(problem.samples[:, 3]) < 30.0          # the channel barely moves (noise and the fault)
    real = CL.extension_of

    def broken(sc):
        if sc.effect == "mass":   # what the degenerate sensor fit did: bounds beyond the FMU's range
            return Extension({"effects.mass.transducer_factor": (7.0, 9.0)}, {"effects.mass.transducer_factor": 8.0}, {})
        return real(sc)
    monkeypatch.setattr(CL, "extension_of", broken)
    res = _loop(problem, effects=["sensor", "mass", "resistance"], **LEAN)
    rnd = res.rounds[0]
    _record("degenerate_8", res, truth=params)
    notes = [n for h in rnd.attribution.all_hypotheses for n in h.notes]
    assert any("steering.F_left: not identifiable" in n for n in notes), notes
    assert any(d["effect"] == "mass" and "no room within the FMU's range" in d["reason"] for d in rnd.dropped), \
        rnd.dropped
    assert res.found == ["sensor"], rnd.verdict
    measured = float(problem.samples[:, 3].mean())
    want = 0.2 * (measured - 40.0) / 1.2 + 40.0      # the error at the channel's level
    # within 3 sigma of the in-specification zero the record also carries (6 N on this channel)
    assert abs(rnd.identified["effects.sensor.offset.steering.F_left"] - want) < 18.0, (rnd.identified, want)
    assert "effects.sensor.gain.steering.F_left" not in rnd.identified
