"""Two candidates that both pass (issue 18): which one the record prefers.

A candidate that passes every test only shows that the base is missing
*something* its parameters can imitate: two effects whose signatures
overlap can each take most of the other's misfit (a play in every joint and
a bump at one joint, both straining the joints, are such a pair;
docs/close_loop.md). So before
the first candidate that passes is confirmed, the next one in the order is
examined too (close_loop._attempt); if it passes as well (adequate or not),
the two extended models are compared by BIC. The models are not nested: each is scored on the same
residual metric (sum r^2 / sigma^2), scaled by the larger of their
correlated-residual factors (evidence.lr_test's Satterthwaite scale), with
each model's added parameters charged ln N. A difference of DECISIVE or more
picks one: confirmed if its model reaches the noise or leaves at most a
quarter (LEAVES) of what the other leaves of the base's misfit above the
noise, else held provisional (of two models short of the noise the better
one may still be a share of something else; close_loop confirms a
provisional effect only once a later round's model reaches the noise). A smaller difference leaves the round
undecided: neither is confirmed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Sequence

from .loop_result import CandidateTest

DECISIVE = 10.0   # BIC difference taken as decisive (Kass and Raftery's "very strong")
LEAVES = 0.25     # a preferred model above the noise wins if it leaves at most this share of what the rival
                  # leaves of the base's misfit above the noise (a cart 12 % heavier: the mass 2 %, a 58 um
                  # play far more; a 1 um play's bump 15 % against the play's own 25 %: not a winner)


@dataclass
class Rivalry:
    preferred: Optional[CandidateTest]   # the one BIC prefers by DECISIVE or more; None: undecided
    first: CandidateTest
    second: CandidateTest
    dbic: float                          # for `first` over `second` (> 0: first preferred)

    @property
    def winner(self) -> Optional[CandidateTest]:
        """The preferred one if its model reaches the noise, or leaves at most
        LEAVES of what the rival leaves of the base's misfit above it: it may
        be confirmed."""
        p = self.preferred
        if p is None:
            return None
        if at_noise(p):
            return p
        left_p, left_r = _left(p), _left(self.loser)
        ok = left_p is not None and left_r is not None and left_r > 0 and left_p <= LEAVES * left_r
        return p if ok else None

    @property
    def loser(self) -> Optional[CandidateTest]:
        if self.preferred is None:
            return None
        return self.second if self.preferred is self.first else self.first

    def text(self) -> str:
        a, b = self.first, self.second
        if self.preferred is None:
            return (f"{a.effect} ({a.label}) and {b.effect} ({b.label}) both pass; the record cannot tell them "
                    f"apart (dBIC {self.dbic:+.1f} for {a.effect}, |dBIC| < {DECISIVE:g})")
        lo = self.loser
        d = self.dbic if self.preferred is a else -self.dbic
        out = f"preferred to {lo.effect} ({lo.label}), which passes too: dBIC {d:+.1f} between them"
        if self.winner is None:
            out += (" but its model stays above the noise and leaves more than a quarter of the misfit the other "
                    "leaves: the better of two approximations, held provisional (each may be a share of "
                    "something else)")
        return out


def _left(t: CandidateTest) -> Optional[float]:
    """The share of the base's misfit above the noise the extension leaves."""
    share = getattr(t, "misfit_share", None)
    return None if share is None else 1.0 - float(share)


def _added(t: CandidateTest, n_base: int) -> int:
    return max(0, len(t.problem.free) - n_base)


def compare(first: CandidateTest, second: CandidateTest, n_base: int) -> Rivalry:
    """BIC of `first` against `second` (module docstring)."""
    a = max(1.0, first.lr.scale, second.lr.scale)
    N = max(2, int(first.problem.samples.size))
    dbic = (second.S - first.S) / a - (_added(first, n_base) - _added(second, n_base)) * math.log(N)
    preferred = first if dbic >= DECISIVE else second if dbic <= -DECISIVE else None
    return Rivalry(preferred, first, second, float(dbic))


def at_noise(t: CandidateTest) -> bool:
    """The extended model leaves no channel above the noise."""
    exc = getattr(t, "excess", None)
    return exc is not None and not exc.any


def passing(tests: Sequence[CandidateTest]) -> list:
    """The tests that pass and are adequate (CandidateTest.adequate: at the
    noise, or most of the misfit removed), in the order tested."""
    return [t for t in tests if t.supported and t.adequate]


__all__ = ["DECISIVE", "LEAVES", "Rivalry", "at_noise", "compare", "passing"]
