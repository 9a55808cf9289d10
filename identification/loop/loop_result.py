"""What the closed loop hands back (issue 18): each candidate's test, each round,
the whole run; their dictionaries are what result.json holds."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from lss_fmu.variables import FORCE_CHANNELS

from .attribution import Attribution
from .evidence import LRTest
from .holdout import HoldOut
from ..objective.noise import ALPHA, Noise
from ..objective.problem import IdentificationProblem


MISFIT_SHARE = 0.8   # a candidate above the noise must remove this share of the base's misfit above it


@dataclass
class CandidateTest:
    """One candidate effect through the extended identification and the tests."""
    effect: str
    label: str
    problem: IdentificationProblem = field(repr=False)
    x: np.ndarray
    f: float                     # the objective (Eq. 10-12) at x
    H: np.ndarray
    S: float                     # sum r^2 / sigma^2 at x
    lr: LRTest
    holdout: Optional[HoldOut]
    identified: dict
    amplitude: Optional[float]
    refined: dict
    supported: bool = False
    why_not: list = field(default_factory=list)
    base_alt: Optional[tuple] = field(default=None, repr=False)   # (x, S) of the base refitted from here
    signature: list = field(default=None, repr=False)   # the hypothesis' columns at the base, every probe
    excess: object = None        # noise.Excess of the extension's residual (computed once the tests pass)
    misfit_share: Optional[float] = None   # the share of the base's S above the noise (S - dof) it removes

    @property
    def adequate(self) -> bool:
        """The extended model leaves noise (no channel's residual above it), or
        it removes at least MISFIT_SHARE of the base's misfit above the noise
        (a second effect, or the base's last digits, may hold the rest)."""
        if self.excess is None:
            return False
        return not self.excess.any or (self.misfit_share is not None and self.misfit_share >= MISFIT_SHARE)

    @property
    def status(self) -> str:
        """The candidate's own verdict, for the reports."""
        if not self.supported:
            return "; ".join(self.why_not)
        if self.excess is None:
            return "passes every test"
        if not self.excess.any:
            return "passes every test; the model with it reaches the noise"
        share = "" if self.misfit_share is None else f"{100 * self.misfit_share:.0f}% of the base's misfit above it"
        if self.adequate:
            return f"passes every test; removes {share}"
        return (f"passes every test; the model with it stays above the noise (mean square / noise up to "
                f"{float(np.max(self.excess.ratio)):.2f}; {share or 'its share unknown'} removed)")

    def to_dict(self) -> dict:
        return {"effect": self.effect, "hypothesis": self.label, "f": self.f, "S": self.S,
                "parameters": list(self.identified), "lr": self.lr.to_dict(),
                "holdout": None if self.holdout is None else self.holdout.to_dict(),
                "identified": self.identified, "amplitude": self.amplitude, "supported": self.supported,
                "why_not": self.why_not, "refined": self.refined, "adequate": self.adequate,
                "misfit_share": self.misfit_share,
                "excess": None if self.excess is None else self.excess.to_dict()}


@dataclass
class Round:
    number: int
    f_base: float
    H_base: np.ndarray
    attribution: Attribution
    verdict: str
    effect: Optional[str] = None
    f_extended: Optional[float] = None
    H_extended: Optional[np.ndarray] = None
    identified: dict = field(default_factory=dict)   # effect parameter -> value
    amplitude: Optional[float] = None
    confirmed: bool = False
    location: dict = field(default_factory=dict)
    x_base: Optional[np.ndarray] = None
    x_extended: Optional[np.ndarray] = None
    problem_extended: Optional[IdentificationProblem] = field(default=None, repr=False)
    base_problem: Optional[IdentificationProblem] = field(default=None, repr=False)
    residual: object = field(default=None, repr=False)
    refined: dict = field(default_factory=dict)   # the local refinement of the extension: f before/after, runs
    # issue 18: the evidence
    outcome: str = ""                              # confirmed, undecided, not in the catalogue, nothing significant
    noise: Optional[Noise] = None
    excess: object = None                          # noise.Excess of the refitted base
    base_refined: dict = field(default_factory=dict)
    S_base: Optional[float] = None
    tests: list = field(default_factory=list)      # CandidateTest, in the order tested
    departures: list = field(default_factory=list)  # departures.Departure
    dropped: list = field(default_factory=list)    # {"effect", "stage", "reason"}
    hypotheses: int = 0                            # m of the Bonferroni correction
    base_restarts: list = field(default_factory=list)  # better bases found through an extension
    provisional: bool = False    # a candidate passed the tests but its extension stays above the noise: confirmed
                                 # only if a later round's model (with it) reaches the noise
    verdict_if_confirmed: str = field(default="", repr=False)
    rivalry: Optional[dict] = None   # two candidates that both passed, compared (identification.loop.rivals)
    reach: list = field(default_factory=list)   # what the record can reveal of each effect (identification.loop.reach)

    @property
    def evidence(self) -> Optional[CandidateTest]:
        """The test behind the verdict: the supported candidate that reaches the
        noise, else the first supported one (provisional), else the first tested."""
        for t in self.tests:
            if t.supported and t.adequate:
                return t
        for t in self.tests:
            if t.supported:
                return t
        return self.tests[0] if self.tests else None

    def to_dict(self) -> dict:
        chans = FORCE_CHANNELS
        ev = self.evidence
        return {
            "round": self.number, "verdict": self.verdict, "outcome": self.outcome, "effect": self.effect,
            "confirmed": self.confirmed, "provisional": self.provisional,
            "f_base": self.f_base, "nrmsd_base": dict(zip(chans, map(float, self.H_base))),
            "f_extended": self.f_extended,
            "nrmsd_extended": None if self.H_extended is None else dict(zip(chans, map(float, self.H_extended))),
            "identified": self.identified, "amplitude": self.amplitude, "location": self.location,
            "refined": self.refined, "base_refined": self.base_refined,
            "evidence": None if ev is None else {"effect": ev.effect, "statistic": ev.lr.T, "dof": ev.lr.dof,
                                                 "p": ev.lr.p, "p_bonferroni": ev.lr.p_adj, "dbic": ev.lr.dbic,
                                                 "holdout_gain": None if ev.holdout is None else ev.holdout.gain},
            "alpha": ALPHA, "hypotheses": self.hypotheses, "S_base": self.S_base,
            "base_restarts": self.base_restarts,
            "noise": None if self.noise is None else self.noise.to_dict(),
            "excess": None if self.excess is None else self.excess.to_dict(),
            "tests": [t.to_dict() for t in self.tests],
            "departures": [d.to_dict() for d in self.departures],
            "dropped": self.dropped, "rivalry": self.rivalry, "reach": [r.to_dict() for r in self.reach],
            "attribution": self.attribution.to_dict(),
        }


@dataclass
class CloseLoopResult:
    problem: IdentificationProblem
    x_base: np.ndarray
    rounds: list
    seconds: float
    grown: Optional[dict] = None   # the base's growing windows (identification.pipeline.growing), if it grew

    @property
    def found(self) -> list:
        return [r.effect for r in self.rounds if r.confirmed]

    @property
    def verdict(self) -> str:
        return self.rounds[-1].verdict if self.rounds else "no analysis"

    @property
    def outcome(self) -> str:
        return self.rounds[-1].outcome if self.rounds else "no analysis"

    def to_dict(self) -> dict:
        return {"measurement": self.problem.name, "model": self.problem.model, "layout": self.problem.layout,
                "protocol": self.problem.protocol.name, "found": self.found, "verdict": self.verdict,
                "outcome": self.outcome, "seconds": self.seconds,
                "x_base": dict(zip(self.problem.free, map(float, self.x_base))), "base_grown": self.grown,
                "rounds": [r.to_dict() for r in self.rounds]}
