"""The verdict of a closed-loop round (issue 18): confirmed, undecided
between two candidates, not in the catalogue, or nothing significant, each
with its evidence."""
from __future__ import annotations

import logging
from typing import Optional

import numpy as np

from lss_fmu.variables import FORCE_CHANNELS

from .candidates import sensor_columns
from .catalogue import CATALOGUE
from .departures import beyond, candidate_beyond
from .locate import localise, where_text
from .loop_result import CandidateTest, Round
from ..objective.problem import IdentificationProblem, weighted_residual
from .rivals import compare, passing

log = logging.getLogger(__name__)


def stats_text(t: CandidateTest) -> str:
    ho = "-" if t.holdout is None else t.holdout.text()
    return (f"LR statistic {t.lr.T:.1f} on {t.lr.dof:.1f} dof (scale {t.lr.scale:.2f}), p = {t.lr.p:.2g}, "
            f"Bonferroni p = {t.lr.p_adj:.2g} (m = {t.lr.m}); dBIC = {t.lr.dbic:+.1f}; held-out gain {ho}")


def decide(rnd: Round, base: IdentificationProblem, r_b: np.ndarray, s, w: np.ndarray) -> None:
    """The verdict from the tests (module docstring)."""
    if _rivals(rnd, base, r_b, s, w):
        return
    supported = [t for t in rnd.tests if t.supported]
    sup = next((t for t in supported if t.adequate), supported[0] if supported else None)
    deps = [d for d in rnd.departures if d.counts]
    best_dep = max(deps, key=lambda d: d.test.dbic) if deps else None
    ev = rnd.evidence
    if ev is not None:   # the extension shown in the report: the confirmed one, else the first tested
        rnd.effect, rnd.problem_extended, rnd.x_extended = ev.effect, ev.problem, ev.x
        rnd.f_extended, rnd.H_extended, rnd.identified = ev.f, ev.H, ev.identified
        rnd.amplitude, rnd.refined = ev.amplitude, ev.refined
    kept = None   # why a candidate that a departure beats by BIC is kept
    r_e = _extended_residual(sup, w) if sup is not None and deps else None   # once, for both tests below
    if sup is not None and best_dep is not None and best_dep.test.dbic > sup.lr.dbic \
            and (kept := _stays_beyond(rnd, sup, best_dep, r_b, w, r_e)) is None:
        sup.supported = False
        sup.why_not.append(f"a disturbance outside the catalogue explains the residual better "
                           f"({best_dep.label}: dBIC {best_dep.test.dbic:+.1f} > {sup.lr.dbic:+.1f})")
        sup = None
    if sup is not None:
        _still_outside(rnd, sup, w, r_e)
        if not sup.supported:
            sup = None
    noise = f"noise {rnd.noise.source}" if rnd.noise else "noise"
    if sup is not None:
        eff = CATALOGUE[sup.effect]
        confirmed = (f"{eff.title} ({sup.effect}, {sup.label}) confirmed: {stats_text(sup)} ({noise}); "
                     f"f from {rnd.f_base:.4g} to {sup.f:.4g}")
        if kept:
            confirmed += "; " + kept
        rival = rnd.rivalry if rnd.rivalry and rnd.rivalry["preferred"] == sup.effect else None
        if rival:
            confirmed += "; " + rival["text"]
        if sup.adequate and (rival is None or rival["confirmable"]):
            rnd.confirmed, rnd.outcome, rnd.verdict = True, "confirmed", confirmed
            return
        # it passes every test but the model with it stays above the noise: a wrong effect taking a
        # share of a missing one's misfit does that; so does the first of two effects (close_loop
        # confirms it once a later round's model, with it, reaches the noise)
        ratio = sup.excess.ratio
        j = int(np.argmax(ratio))
        rnd.provisional, rnd.confirmed, rnd.outcome = True, False, "not in the catalogue"
        rnd.location = localise(base, r_b, s, w)
        rnd.verdict_if_confirmed = confirmed
        share = "" if sup.misfit_share is None else f", {100 * sup.misfit_share:.0f}% of the base's misfit above it removed"
        rnd.verdict = (f"not confirmed: {eff.title} ({sup.effect}, {sup.label}) passes the tests ({stats_text(sup)}; "
                       f"{noise}) but the model with it stays above the noise (mean square / noise up to "
                       f"{float(ratio[j]):.2f} on {FORCE_CHANNELS[j]}{share}); f from {rnd.f_base:.4g} to {sup.f:.4g}. "
                       f"Where the base's residual is: {where_text(rnd.location)}")
        if rival:
            rnd.verdict += f"; {sup.effect} {rival['text']}"
        return
    rnd.confirmed = False
    loc = localise(base, r_b, s, w)
    rnd.location = loc
    best = f"best candidate {ev.effect}: {stats_text(ev)}" if ev is not None else "no candidate could be tested"
    if ev is not None and ev.why_not:
        best += " - " + "; ".join(ev.why_not)
    above = rnd.excess is not None and rnd.excess.any
    if above or best_dep is not None:
        rnd.outcome = "not in the catalogue"
        what = (f"it looks most like {best_dep.family} ({best_dep.label}; T = {best_dep.test.T:.1f}, "
                f"Bonferroni p = {best_dep.test.p_adj:.2g}, dBIC {best_dep.test.dbic:+.1f})"
                if best_dep is not None else "none of the disturbances tried outside it (crosstalk, a periodic "
                                             "interference, the logger's clock) explains it either")
        ratio = "" if rnd.excess is None else (f" (mean square / noise up to "
                                               f"{float(np.max(rnd.excess.ratio)):.2f})")
        rnd.verdict = (f"not in the catalogue: the residual is above the noise{ratio} and no catalogue effect "
                       f"explains it ({best}); {what}. Where: {where_text(loc)}")
    else:
        rnd.outcome = "nothing significant"
        ratio = "" if rnd.excess is None else f" (mean square / noise at most {float(np.max(rnd.excess.ratio)):.2f})"
        rnd.verdict = f"nothing significant: the residual is at the noise level{ratio}; {best}"


def _extended_residual(sup: CandidateTest, w: np.ndarray) -> Optional[np.ndarray]:
    """The candidate's extended residual at its estimate (None if it cannot be simulated)."""
    try:
        return weighted_residual(sup.problem, sup.problem.simulate(sup.x), w)[0]
    except Exception as exc:
        log.warning("%s: extended residual unavailable for the departures: %s", sup.effect, exc)
        return None


def _stays_beyond(rnd: Round, sup: CandidateTest, dep, r_b: np.ndarray, w: np.ndarray,
                  r_e: Optional[np.ndarray]) -> Optional[str]:
    """Whether the candidate still explains a significant part once the
    departure that beats it by BIC has taken its share (departures.
    candidate_beyond: Bonferroni p < ALPHA and dBIC > 0); then the BIC
    ranking alone does not veto it, and _still_outside decides whether the
    departure is there too. Its statistic in the departure's detail, and a
    line for the verdict if it stays (else None)."""
    J = list(rnd.attribution.base_columns if rnd.attribution is not None else ())
    if r_e is None:
        return None
    try:
        t = candidate_beyond(dep, float(np.sum(r_b ** 2 * w)), r_e, sup.signature or [], w, sup.lr.q, sup.lr.m,
                             sup.lr.m_effect, J)
    except Exception as exc:
        log.warning("%s beyond %s unavailable: %s", sup.effect, dep.label, exc)
        return None
    dep.detail["candidate_beyond"] = None if t is None else {"effect": sup.effect, "T": float(t.T),
                                                             "p_bonferroni": float(t.p_adj), "dbic": float(t.dbic)}
    if t is None or not (t.significant and t.dbic > 0):
        return None
    return (f"{dep.family} ({dep.label}) scores a higher dBIC ({dep.test.dbic:+.1f}) but {sup.effect} stays "
            f"significant beyond it (Bonferroni p = {t.p_adj:.2g}, dBIC {t.dbic:+.1f}) and nothing outside the "
            f"catalogue remains beyond {sup.effect}")


def _still_outside(rnd: Round, sup: CandidateTest, w: np.ndarray, r_e: Optional[np.ndarray]) -> None:
    """Each significant disturbance outside the catalogue tested again on the
    supported candidate's extended residual, beyond the base's columns, every
    probe of the candidate's hypothesis and every channel's gain and offset
    (a second effect left for the next round; departures.beyond): if one still
    explains a significant part (its own Bonferroni p < ALPHA and dBIC > 0),
    the candidate only took a share of something the catalogue does not
    contain, and is not confirmed."""
    deps = [d for d in rnd.departures if d.counts]
    if not deps or r_e is None:   # r_e: _extended_residual (None: it could not be simulated)
        return
    # beyond the base and all the effect can do (every probe of its hypothesis: a sensor extension
    # that freed too few channels leaves a gain error that crosstalk from a correlated channel mimics)
    J = list(rnd.attribution.base_columns if rnd.attribution is not None else ()) + list(sup.signature or ())
    J += sensor_columns(rnd.base_problem, rnd.x_base)   # a second effect, most often a sensor fault
    for d in deps:
        t = beyond(d, r_e, w, J, looks=len(deps))
        d.detail["beyond_candidate"] = None if t is None else {"effect": sup.effect, "T": float(t.T),
                                                               "p_bonferroni": float(t.p_adj), "dbic": float(t.dbic)}
        if t is not None and t.significant and t.dbic > 0:
            sup.supported = False
            sup.why_not.append(f"a disturbance outside the catalogue remains beyond it ({d.label}: Bonferroni p = "
                               f"{t.p_adj:.2g}, dBIC {t.dbic:+.1f} on the extended residual)")
            return


def _rivals(rnd: Round, base: IdentificationProblem, r_b: np.ndarray, s, w: np.ndarray) -> bool:
    """The first candidate that passes and is adequate, and the best other one
    that passes (identification.loop.rivals): the one BIC prefers decisively stays
    and the other is marked as beaten (a preferred one above the noise is held
    provisional by decide); if neither is preferred the round ends undecided
    (True), nothing confirmed."""
    ok = passing(rnd.tests)
    if not ok:
        return False
    others = [t for t in rnd.tests if t.supported and t is not ok[0]]
    if not others:
        return False
    rv = compare(ok[0], min(others, key=lambda t: t.S), len(base.free))
    rnd.rivalry = {"first": rv.first.effect, "second": rv.second.effect, "dbic_first": rv.dbic,
                   "preferred": None if rv.preferred is None else rv.preferred.effect,
                   "confirmable": rv.winner is not None, "text": rv.text()}
    if rv.preferred is not None:
        rv.loser.supported = False
        rv.loser.why_not.append(f"{rv.preferred.effect} ({rv.preferred.label}) explains the record better: dBIC "
                                f"{abs(rv.dbic):+.1f} between them")
        return False
    loc = localise(base, r_b, s, w)
    rnd.confirmed, rnd.outcome, rnd.location = False, "undecided", loc
    a, b = rv.first, rv.second
    rnd.effect, rnd.problem_extended, rnd.x_extended = a.effect, a.problem, a.x
    rnd.f_extended, rnd.H_extended, rnd.identified = a.f, a.H, a.identified
    rnd.amplitude = a.amplitude
    rnd.verdict = (f"undecided: {rv.text()}. {a.effect}: {stats_text(a)}, f from {rnd.f_base:.4g} to {a.f:.4g}; "
                   f"{b.effect}: {stats_text(b)}, f to {b.f:.4g}. Where the base's residual is: {where_text(loc)}")
    return True
