"""Close the loop (issues 7 and 18): residual -> missing effect -> extended model.

One round: the base refitted to its own optimum (Levenberg-Marquardt in the
likelihood's metric, identification.pipeline.refine), the noise of each channel
(declared or estimated: identification.loop.evidence), the residual analysis
(identification.loop.residual), every effect of the catalogue scored by the share
of the objective it explains beyond the base parameters
(identification.loop.attribution) and the best fitted through the FMU (rescore);
the leading candidates (TEST_MAX) are switched on, their parameters added to
the design vector and identified again from the refitted base
(identification.loop.extension, then refine). An effect is *confirmed* only by
evidence (identification.loop.evidence): a likelihood-ratio test against the noise
that allows for a correlated residual, Bonferroni-corrected for every
hypothesis scanned in the round; BIC; no disturbance outside the catalogue
(crosstalk, a periodic interference, the logger's clock) explaining the
residual better; and held-out validation against the refitted base. A
residual above the noise that no candidate explains is "not in the
catalogue", located in channel, frequency, track position and time. A
candidate that cannot be built or fitted (a degenerate fit, bounds outside
the FMU's range, a failed simulation) is dropped with its reason; the round
goes on. A second round starts from the extended model.

Each round's verdict also names the effects that, at the size they reach in
service, the record cannot reveal (identification.loop.reach).

The pieces: identification.pipeline.base_polish (the base at its own optimum),
identification.loop.candidates (rescore and the tests of each candidate),
identification.loop.verdict, identification.loop.settle (a provisional effect at the
end: confirmed only if still needed in the final model), identification.loop.locate
(where the residual sits), identification.loop.loop_result (what is handed back).

From the command line: `lss close-loop` (lss_app.cmd_close_loop). Every
identification keeps a journal in DIR, the attribution of each round is
written atomically once done: a run killed at any point resumes where it was.
"""
from __future__ import annotations

import dataclasses
import json
import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Optional, Sequence

import numpy as np

from lss_fmu.atomic import write_json_atomic
from lss_fmu.variables import FORCE_CHANNELS

from .attribution import Attribution, attribute
from ..pipeline.base_polish import polish_base
from .candidates import RESCORE, examine_candidate, fit_score, rescore
from .catalogue import CATALOGUE
from .departures import departures
from ..pipeline.growing import grow
from ..pipeline.identify import identify
from .locate import analyse, catalogue_bands, context, localise, signals_at
from .loop_result import CloseLoopResult, Round
from ..objective.noise import excess, noise_levels
from ..objective.problem import IdentificationProblem, nrmsd, tared
from .reach import reach, unseen_text
from .ripple_line import ripple_lines
from .settings import LoopSettings
from .verdict import decide
from .settle import settle_provisional, still_needed

log = logging.getLogger(__name__)

BASE_RESTARTS = 2        # times a round starts again from a better base found through an extension
BASE_IMPROVE = 0.02      # ... when that base lowers S by at least this share


@dataclass(frozen=True)
class Run:
    """What one run of the loop works with beside its settings: the seed (a
    round's own: the run's plus the round's number), where it journals, its
    processes, and what the sensor declares (the zero tolerance and the white
    noise per force channel, N)."""
    seed: int = 0
    out: Optional[Path] = None
    progress: bool = False
    workers: int = 1
    sensor_offset_std: Optional[dict] = None
    noise_std: Optional[Mapping[str, float]] = None


def close_loop(problem: IdentificationProblem, x_base: Optional[Sequence[float]] = None, *,
               effects: Optional[Sequence[str]] = None, rounds: int = 1, settings: Optional[LoopSettings] = None,
               seed: int = 0, out: Optional[Path] = None, progress: bool = False, workers: int = 1,
               sensor_offset_std: Optional[dict] = None,
               noise_std: Optional[Mapping[str, float]] = None) -> CloseLoopResult:
    """The loop on one problem: base identification (unless x_base is given),
    then up to `rounds` rounds of analysis, attribution, extension and tests,
    with the budgets of `settings` (identification.loop.settings; default
    LoopSettings()). `sensor_offset_std`: the transducer's declared zero
    tolerance per force channel (N); offsets and gains within 3 sigma of it
    are not faults. `noise_std`: its declared white noise per force channel
    (N; meta.json sensor.force_noise_std_N), else estimated from the
    residual. A base not given is identified on growing windows from
    `settings.first_window` s (identification.pipeline.growing; the complex's
    `settings.base_evals` counted in simulations of the whole record), or
    with the complex on the whole record where that is None or 0."""
    t0 = time.time()
    settings = settings or LoopSettings()
    out = Path(out) if out else None
    if out:
        out.mkdir(parents=True, exist_ok=True)
    run = Run(seed=seed, out=out, progress=progress, workers=workers, sensor_offset_std=sensor_offset_std,
              noise_std=noise_std)
    grown = None
    first = settings.first_window
    if x_base is None and first:
        duration = float(problem.times[-1] - problem.times[0])
        evals = int(round(settings.base_evals * max(1.0, duration / float(first))))
        x_base, grown = grow(problem, evals=evals, noise_std=noise_std, first=float(first),
                             profile_points=settings.profile_points, seed=seed,
                             journal=out / f"base_first{float(first):g}s_journal.jsonl" if out else None)
    elif x_base is None:
        res = identify(problem, max_evals=settings.base_evals, seed=seed, progress=progress, workers=workers,
                       journal=out / "base_journal.jsonl" if out else None)
        x_base = res.x
    x = np.asarray(x_base, float)
    base, result_rounds = problem, []
    remaining = list(effects or CATALOGUE)
    for k in range(1, rounds + 1):
        rnd = one_round(base, x, k, remaining, settings, dataclasses.replace(run, seed=seed + k))
        result_rounds.append(rnd)
        if not (rnd.confirmed or rnd.provisional) or not [e for e in remaining if e != rnd.effect]:
            break
        remaining.remove(rnd.effect)
        # the next round's base is the extended model, the found effect still free: a second
        # effect in the data distorts the first one's fit, and with its parameters in the base
        # Jacobian the attribution scores the next effect beyond what refitting it could do;
        # the next extension then identifies both together
        base = dataclasses.replace(rnd.problem_extended, x0=rnd.problem_extended.values(rnd.x_extended))
        x = np.asarray(rnd.x_extended, float)
    settle_provisional(result_rounds, still_needed)
    for rnd in result_rounds:   # what the record could not have shown, whatever the verdict
        unseen = unseen_text(rnd.reach)
        if unseen:
            rnd.verdict += "; " + unseen
    return CloseLoopResult(problem, np.asarray(x_base, float), result_rounds, time.time() - t0, grown)


def hypothesis_counts(att: Attribution) -> dict:
    """Per effect, the hypotheses the round scanned (failed ones included): the
    Bonferroni correction's m. The sensor effect counts its channels (the
    extension chooses among them), the ripple its whole pitch scan (its
    hypotheses may be built around the residual's lines instead)."""
    out: dict = {}
    for h in att.all_hypotheses:
        out[h.effect] = out.get(h.effect, 0) + 1
    for fl in att.failed:
        out[fl["effect"]] = out.get(fl["effect"], 0) + 1
    for name, n in out.items():   # a search the attribution did not run counts as if it had
        count = getattr(CATALOGUE[name], "hypothesis_count", None)
        if count is not None:
            out[name] = count(n)
    if "sensor" in out:
        out["sensor"] = max(out["sensor"], len(FORCE_CHANNELS))
    return out


def one_round(base: IdentificationProblem, x: np.ndarray, number: int, effects: Sequence[str],
              settings: LoopSettings, run: Run) -> Round:
    """One round (module docstring). The base must have had every chance the
    extension had: after each candidate's extended identification the base is
    refitted from the extension's base parameters, and if that lowers the base
    below where it stood (the complex had stopped in another basin) the round
    starts again from there (at most BASE_RESTARTS times)."""
    x = np.asarray(x, float)
    restarts = []
    for attempt in range(BASE_RESTARTS + 1):
        rnd, better = _attempt(base, x, number, effects, settings, run, last=attempt == BASE_RESTARTS,
                               attempt=attempt)
        rnd.base_restarts = restarts
        if better is None:
            return rnd
        restarts.append({"from_S": rnd.S_base, "to_S": better[1], "after": better[2],
                         "x": dict(zip(base.free, map(float, better[0])))})
        log.info("round %d: the base refitted from %s's point lowers S from %.6g to %.6g: round again",
                 number, better[2], rnd.S_base, better[1])
        x = better[0]
    return rnd


def _attempt(base, x, number, effects, settings: LoopSettings, run: Run, *, last: bool, attempt: int = 0) -> tuple:
    """(Round, None) or, if an extension's base parameters refit the base lower
    than it stands, (Round, (x, S, effect)) unless `last`."""
    sim = base.simulate(x)
    r0 = tared(base.samples - sim, base.tare)
    seed, out = run.seed, run.out
    noise = noise_levels(r0, run.noise_std)
    w = 1.0 / noise.sigma ** 2
    # 1. the base at its own optimum, in the likelihood's metric: a base that stopped above the
    # noise floor would hand its remainder to any flexible candidate
    x, sim, base_refined = polish_base(base, x, sim, w, seed=seed, polish_evals=settings.polish,
                                       base_refine_evals=settings.base_refine_evals,
                                       profile_points=settings.profile_points,
                                       journal=out / f"round{number}_base{attempt}_journal.jsonl" if out else None)
    r_b = tared(base.samples - sim, base.tare)
    if noise.source == "estimated":   # at the refitted base
        noise = noise_levels(r_b, None)
        w = 1.0 / noise.sigma ** 2
    S_b = float(np.sum(r_b ** 2 * w))
    H = nrmsd(base.samples, sim, base.tare)
    f_base = float(np.sum(H ** 2))
    exc = excess(r_b, noise.sigma, len(base.free))
    sig = signals_at(base, x)
    ra, s = analyse(base, x, sim, sig)
    ctx = context(base, x, run.sensor_offset_std, noise.sigma, s)
    if s is not None and "motor_ripple" in effects:
        ripple = CATALOGUE["motor_ripple"]
        ctx.ripple_lines = ripple_lines(r_b, s, (ripple.P_MIN, ripple.P_MAX))
    cache = out / f"round{number}_attribution.json" if out else None
    att = attribute(base, x, ctx, effects=effects, progress=run.progress, noise_w=w)
    if cache:
        write_json_atomic(cache, att.to_dict())
    counts = hypothesis_counts(att)
    m = max(1, sum(counts.values()))
    rnd = Round(number, f_base, H, att, "", x_base=x, residual=ra, base_problem=base, noise=noise, excess=exc,
                base_refined=base_refined, S_base=S_b, hypotheses=m,
                reach=reach(att, r_b.size, m, counts, float(base.times[-1] - base.times[0])))
    fits, dropped = rescore(base, x, att, f_base, n=max(RESCORE, settings.candidates), evals=settings.fit_evals,
                            seed=seed, out=out, number=number)
    rnd.dropped = dropped
    if cache:
        write_json_atomic(cache, att.to_dict())
    # 2. the disturbances outside the catalogue, fitted to the same residual
    bands = catalogue_bands(base, sig, effects)
    try:
        rnd.departures = departures(base, x, sim, r_b, att.base_columns, w, excluded_hz=bands)
    except Exception as exc:   # the verdict goes on without them
        log.warning("departures outside the catalogue failed: %s", exc)
        rnd.dropped.append({"effect": "(departures)", "stage": "fit", "reason": str(exc)[:300]})
    # 3. the leading candidates through the extended identification and the tests
    better, passed = None, None
    for fit in fits[:max(1, settings.candidates)]:
        try:
            t = examine_candidate(base, x, fit, att, S_b, w, m, counts.get(fit.score.effect, 1), settings, run,
                                  number=number)
        except Exception as exc:   # a degenerate candidate: dropped, the loop goes on
            log.warning("round %d: candidate %s dropped: %s", number, fit.score.effect, exc)
            rnd.dropped.append({"effect": fit.score.effect, "stage": "extension", "reason": str(exc)[:300]})
            continue
        rnd.tests.append(t)
        if t.base_alt is not None and t.base_alt[1] < (1.0 - BASE_IMPROVE) * S_b and not last:
            if better is None or t.base_alt[1] < better[1]:
                better = (t.base_alt[0], t.base_alt[1], t.effect)
            break
        if passed is not None:
            break   # the rival of the one that passed, examined (identification.loop.rivals)
        if t.supported and t.adequate:
            passed = t   # (one that passes but leaves the model above the noise: the next may do better)
    if better is not None:
        return rnd, better
    if passed is not None:
        _absorbed_rivals(base, x, att, effects, f_base, S_b, w, m, counts, rnd, settings, run, number)
    decide(rnd, base, r_b, s, w)
    return rnd, None


def _absorbed_rivals(base, x, att, effects, f_base, S_b, w, m, counts, rnd: Round, settings: LoopSettings,
                     run: Run, number: int) -> None:
    """Before a candidate that passes is confirmed, every effect the base's
    CoRs can absorb (catalogue ABSORBED: the transducer cart's mass) that was
    not tested is fitted and tested too, as its rival: such an effect changes
    the record in ways the CoRs half imitate, so its linear score ranks it
    low, and another candidate can take its misfit (verdict._rivals then
    weighs the two by BIC)."""
    tested = {t.effect for t in rnd.tests}
    for name in [e for e in effects if CATALOGUE[e].ABSORBED and e not in tested]:
        sc = next((s for s in att.ranking if s.effect == name), None)
        if sc is None:
            continue
        fit = fit_score(base, x, sc, f_base, evals=settings.fit_evals, seed=run.seed, out=run.out, number=number,
                        dropped=rnd.dropped)
        if fit is None:
            continue
        try:
            rnd.tests.append(examine_candidate(base, x, fit, att, S_b, w, m, counts.get(name, 1), settings, run,
                                               number=number))
        except Exception as exc:   # a degenerate rival: dropped, the verdict goes on without it
            log.warning("round %d: rival %s dropped: %s", number, name, exc)
            rnd.dropped.append({"effect": name, "stage": "rival", "reason": str(exc)[:300]})


def base_from_result(path, problem: IdentificationProblem) -> np.ndarray:
    """The base point of a problem from an earlier identification's result.json (or its folder)."""
    p = Path(path)
    if p.is_dir():
        p = p / "result.json"
    try:
        d = json.loads(p.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"base result {p}: cannot read it ({exc})") from None
    if d.get("model") != problem.model:
        raise ValueError(f"base result {p}: identified with model {d.get('model')}, not {problem.model}")
    xs = d.get("x", {})
    missing = [n for n in problem.free if n not in xs]
    if missing:
        raise ValueError(f"base result {p}: no value for {', '.join(missing)}")
    x = np.array([float(xs[n]) for n in problem.free])
    for n, v in zip(problem.free, x):
        lo, hi = problem.bounds[n]
        if not lo <= v <= hi:
            raise ValueError(f"base result {p}: {n} = {v} lies outside the bounds [{lo}, {hi}]")
    return x


__all__ = ["close_loop", "one_round", "Run", "CloseLoopResult", "Round", "localise", "base_from_result",
           "settle_provisional"]
