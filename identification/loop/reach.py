"""What a record can reveal of each effect of the catalogue (issue 53).

A miss is either the loop's or the record's. At the base, the attribution
has each hypothesis' signature columns; projected off the base's columns in
the noise's metric they carry the Fisher information F (attribution,
`noise_w`) that is left to tell the effect from a change of the base. The
loop confirms q added parameters only when the likelihood-ratio statistic
passes both the Bonferroni bound over the round's m hypotheses and BIC
(identification.loop.evidence), so an effect of size a in the configuration
d (a phase, unit size in the probes' coefficients) is confirmed in 90 % of
records when its noncentrality a^2 d'Fd reaches lambda_90:

    a_90 = sqrt(lambda_90 / d'F d),   P(chi2_q(lambda_90) > threshold) = 0.9.

The white-noise test is the most lenient the loop applies (a correlated
residual only raises its threshold), so below a_90 fewer than 9 records in
10 of this kind confirm the effect, whatever the optimiser (as far as the
record's answer is linear in the effect near the base). An effect whose
size is a ladder of hypotheses (a joint's play: the chain's answer is far
from linear in it) is reached at the smallest rung whose own signature
passes. Per effect and kind (a runout's lobes): the median over its
hypotheses (places, pitches) and phases (`typical`), the most favourable
(`best`) and the share of them where the size it reaches in service
(catalogue PLAUSIBLE) shows; an effect whose typical a_90 is above that
size is plausible but invisible on this record, and the verdict says so.
The information of an effect that acts all the time grows with the time it
acts, so the record that would show it is estimated as that much more
running time at speed (a rule of thumb: a start-stop's braked rest adds
nothing); one felt at a place needs a record that passes more places.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Optional

import numpy as np
from scipy import optimize, stats

from ..objective.noise import ALPHA
from .attribution import Attribution
from .catalogue import CATALOGUE


def threshold(n_values: int, m: int, m_effect: int, q: int) -> float:
    """The statistic the loop needs to confirm q parameters: Bonferroni at
    ALPHA over the round's m hypotheses, and BIC over n_values residual values
    with the effect's own m_effect hypotheses."""
    return max(float(stats.chi2.isf(ALPHA / max(1, m), q)),
               q * math.log(max(2, n_values)) + 2.0 * math.log(max(1, m_effect)))


def lambda_90(c: float, q: int) -> float:
    """The noncentrality at which chi2_q exceeds c with probability 0.9."""
    hi = max(10.0, 4.0 * c)
    while stats.ncx2.sf(c, q, hi) < 0.9:
        hi *= 2.0
    return float(optimize.brentq(lambda lam: stats.ncx2.sf(c, q, lam) - 0.9, 1e-9, hi))


@dataclass
class Reach:
    """The smallest size of one effect (one kind of it) this record reveals in 90 % of records."""
    effect: str
    kind: str             # '' or the kind (catalogue Effect.kind: a runout's lobes)
    unit: str
    typical: float        # a_90, median over its hypotheses and phases (inf: never)
    best: float           # a_90 in the most favourable hypothesis and phase
    plausible: float      # the size it reaches in service (catalogue PLAUSIBLE)
    share: float          # of its hypotheses and phases, those where a plausible size shows
    seconds: float        # the record's length
    stationary: bool      # it acts all the time the chain runs (catalogue STATIONARY)
    q: int                # the test's degrees of freedom
    threshold: float
    configurations: int = 1   # hypotheses times phases judged

    @property
    def visible(self) -> bool:
        return self.typical <= self.plausible

    @property
    def name(self) -> str:
        return f"{self.effect} ({self.kind})" if self.kind else self.effect

    @property
    def seconds_needed(self) -> Optional[float]:
        """The running time at which a stationary effect of plausible size shows
        (its information growing with time); None where that rule does not hold."""
        if not self.stationary or not math.isfinite(self.typical):
            return None
        return self.seconds * (self.typical / self.plausible) ** 2

    def size_text(self, v: float) -> str:
        if not math.isfinite(v):
            return "no size"
        if self.unit == "m":
            return f"{1e6 * v:.3g} um" if v < 1e-3 else f"{1e3 * v:.3g} mm"
        return f"{v:.3g} {self.unit}" if self.unit != "1" else f"{v:.3g}"

    def text(self) -> str:
        head = f"{self.name} of {self.size_text(self.plausible)}, a plausible size"
        if self.configurations == 1:
            where = f"revealed only from {self.size_text(self.typical)}"
        elif self.share <= 0.0:
            where = "in none of its places or phases"
        else:
            where = (f"in {100 * self.share:.0f} % of its places or phases "
                     f"(from {self.size_text(self.best)} in the most favourable)")
        need = self.seconds_needed
        if need is not None:
            more = f"; about {need:.3g} s of running at speed would show it"
        elif not self.stationary:
            more = "; a record in which the transducer cart passes more of the track would"
        else:
            more = "; no longer record of this kind would"
        return f"{head}: {where}{more}" if self.configurations == 1 else f"{head}, shows {where}{more}"

    def to_dict(self) -> dict:
        def f(v):
            return float(v) if v is not None and math.isfinite(v) else None
        return {"effect": self.effect, "kind": self.kind, "unit": self.unit, "typical": f(self.typical),
                "best": f(self.best), "plausible": self.plausible, "share": self.share, "visible": self.visible,
                "seconds": self.seconds, "seconds_needed": f(self.seconds_needed), "q": self.q,
                "threshold": self.threshold, "configurations": self.configurations}


def reach(att: Attribution, n_values: int, m: int, counts: Mapping[str, int], seconds: float) -> list:
    """Per effect with a size, and per kind of it, what the record reveals
    (module docstring); `att` from attribute(..., noise_w=...), `counts` the
    hypotheses per effect (the round's Bonferroni m is their sum)."""
    groups: dict = {}
    for sc in att.all_hypotheses:
        eff = CATALOGUE[sc.effect]
        if sc.information is not None and eff.PLAUSIBLE is not None and eff.directions(sc.hypothesis) is not None:
            groups.setdefault((sc.effect, eff.kind(sc.hypothesis)), []).append(sc)
    out = []
    for (name, kind), scores in groups.items():
        eff = CATALOGUE[name]
        dirs = eff.directions(scores[0].hypothesis)
        # the test's degrees of freedom: the parameters added, at least the signature's directions
        q = max(len(eff.extension(scores[0].hypothesis, dirs[0] * eff.PLAUSIBLE).free), dirs.shape[1])
        c = threshold(n_values, m, counts.get(name, len(scores)), q)
        lam = lambda_90(c, q)
        ladder = getattr(eff, "LADDER", None)
        a90 = []
        for sc in scores:
            d = eff.directions(sc.hypothesis)
            info = np.einsum("ij,jk,ik->i", d, sc.information, d)
            a = np.full(info.shape, np.inf)
            a[info > 0] = np.sqrt(lam / info[info > 0])
            if ladder:   # a rung counts at its own size only: the answer is not linear across rungs
                size = float(sc.hypothesis.probes[0].params[ladder])
                a = np.where(a <= size, size, np.inf)
            a90.append(a)
        a90 = np.concatenate(a90)
        if ladder:   # one size, the smallest rung that shows
            typical = best = float(np.min(a90))
            share = float(typical <= eff.PLAUSIBLE)
        else:
            typical, best = float(np.median(a90)), float(np.min(a90))
            share = float(np.mean(a90 <= eff.PLAUSIBLE))
        out.append(Reach(name, kind, eff.unit, typical, best, float(eff.PLAUSIBLE), share, float(seconds),
                         bool(eff.STATIONARY), q, c, int(a90.size)))
    return out


def unseen_text(reaches: list) -> Optional[str]:
    """The verdict's sentence on the plausible effects this record cannot reveal
    in 90 % of records at their median place or phase (None: it reveals them all)."""
    unseen = [r for r in reaches if not r.visible]
    if not unseen:
        return None
    return "this record cannot reveal (in 90 % of records): " + "; ".join(r.text() for r in unseen)


__all__ = ["Reach", "reach", "threshold", "lambda_90", "unseen_text"]
