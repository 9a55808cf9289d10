"""Attribution: which effect of the catalogue explains the residual?

At the base optimum x* the residual r = measured - sim(x*) is fitted, in the
objective's own metric (channel j weighted by 1 / span_j^2, so a share of the
fit is a share of f), by linear combinations of sensitivity signatures
computed through the FMU:

* the base design's own columns J (one-sided differences at x*): what the
  base model could still explain by moving its parameters (the optimiser
  may have stopped short on a rough landscape);
* each hypothesis of each effect, G (probe runs minus the base run).

An effect's score is the share of f it explains *beyond* J:
(f_J - f_JG) / f_base. Ranking by that keeps an effect from taking credit for
what the CoRs would do anyway. The probes are one FMU run each; a failed run
drops the hypothesis with a logged line.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np

from ..objective.jacobian import demean_columns, one_sided_jacobian, weights
from ..objective.problem import IdentificationProblem
from .catalogue import CATALOGUE, Context, Effect, Hypothesis, SensorError

log = logging.getLogger(__name__)


def simulate_with(problem: IdentificationProblem, x, extra: Optional[dict] = None,
                  channels=None) -> np.ndarray:
    """The problem's simulation at x with further FMU values set: the forces as
    the objective sees them (through the logger's filter where declared), or
    other `channels` as simulated."""
    if channels is None:
        return problem.simulate(x, extra)
    return problem.run(x, extra, channels=channels)


def _lsq(r: np.ndarray, cols: list, w: np.ndarray) -> tuple:
    """min_c sum_j w_j |r_j - sum_k c_k G_kj|^2 -> (c, f_fit)."""
    sw = np.sqrt(w)
    b = (r * sw).ravel()
    if not cols:
        return np.zeros(0), float(b @ b)
    A = np.stack([(g * sw).ravel() for g in cols], axis=1)
    c, *_ = np.linalg.lstsq(A, b, rcond=None)
    res = b - A @ c
    return c, float(res @ res)


@dataclass
class HypothesisScore:
    effect: str
    label: str
    share: float          # of f_base explained beyond the base columns
    share_alone: float    # of f_base explained by the effect alone
    coef: np.ndarray      # effect coefficients (in the probes' units), from the joint fit
    probe_gain: np.ndarray  # per probe: share lost if it were dropped (sensor selection)
    hypothesis: Hypothesis = field(repr=False)
    share_fit: Optional[float] = None   # share of f removed when fitted through the FMU (candidates.rescore)
    notes: list = field(default_factory=list)   # probes dropped as not identifiable, and why
    # the probes' Fisher information beyond the base columns, in the noise's metric (noise_w given)
    information: Optional[np.ndarray] = field(default=None, repr=False)

    def to_dict(self) -> dict:
        return {"effect": self.effect, "hypothesis": self.label, "share": self.share, "share_fit": self.share_fit,
                "share_alone": self.share_alone, "coef": [float(c) for c in self.coef],
                "probes": [p.label for p in self.hypothesis.probes], "notes": list(self.notes)}


@dataclass
class Attribution:
    f_base: float
    f_base_refit: float               # after the linear refit of the base parameters alone
    ranking: list                     # best hypothesis per effect, best first
    all_hypotheses: list
    base_columns: list = field(repr=False, default_factory=list)
    failed: list = field(default_factory=list)

    @property
    def best(self) -> Optional[HypothesisScore]:
        return self.ranking[0] if self.ranking else None

    def to_dict(self) -> dict:
        return {"f_base": self.f_base, "f_base_refit": self.f_base_refit,
                "ranking": [h.to_dict() for h in self.ranking], "failed": self.failed,
                "hypotheses": [h.to_dict() for h in self.all_hypotheses]}


def attribute(problem: IdentificationProblem, x: Sequence[float], ctx: Context,
              effects: Optional[Sequence[str]] = None, base_columns: bool = True,
              progress: bool = False, noise_w: Optional[np.ndarray] = None) -> Attribution:
    """Score every hypothesis of every effect (in `effects`, default all).
    With `noise_w` (1 / sigma^2 per channel) each score also carries its
    probes' Fisher information beyond the base columns (what the record can
    reveal of the effect: identification.loop.reach)."""
    x = np.asarray(x, float)
    sim0 = problem.simulate(x)
    r = problem.samples - sim0
    # the objective's tare: where the channel's mean lies within the zero
    # tolerance it is taken out of the residual and of every signature alike
    demean = np.zeros(r.shape[1], bool)
    taken = np.zeros(r.shape[1])
    if problem.tare is not None:
        m = r.mean(axis=0)
        demean = np.abs(m) <= problem.tare
        taken = np.clip(m, -problem.tare, problem.tare)
        r = r - taken
    w = weights(problem)
    _, f_base = _lsq(r, [], w)
    J = [demean_columns(g, demean) for g in one_sided_jacobian(problem, x, sim0)] if base_columns else []
    _, f_J = _lsq(r, J, w)
    beyond = _complement(J, noise_w) if noise_w is not None else None
    chosen = [CATALOGUE[e] for e in (effects or CATALOGUE)]
    todo = [(e, h) for e in chosen for h in e.hypotheses(ctx)]
    bar = None
    if progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=sum(len(h.probes) for _, h in todo), desc="attribution", unit="run")
    scores, failed = [], []
    for effect, hyp in todo:
        try:
            G = [demean_columns(g, demean) for g in sensitivity_signatures(problem, x, sim0, hyp, bar)]
        except Exception as exc:
            log.warning("effect %s, %s: probe failed: %s", effect.name, hyp.label, exc)
            failed.append({"effect": effect.name, "hypothesis": hyp.label, "error": str(exc)[:300]})
            continue
        scores.append(_score(effect, hyp, G, r, J, w, f_base, f_J, ctx, taken))
        if beyond is not None:
            scores[-1].information = beyond(G)
    if bar is not None:
        bar.close()
    best = {}
    for s in scores:
        if s.effect not in best or s.share > best[s.effect].share:
            best[s.effect] = s
    ranking = sorted(best.values(), key=lambda s: -s.share)
    return Attribution(f_base, f_J, ranking, scores, J, failed)


def _complement(J: list, w: np.ndarray):
    """G -> G' W G of the columns G projected off the span of J in the metric w
    per channel (the Fisher information of G's coefficients with the base
    free, for white noise of variance 1 / w)."""
    sw = np.sqrt(np.asarray(w, float))
    U = np.zeros((0, 0))
    if J:
        U, sv, _ = np.linalg.svd(np.stack([(g * sw).ravel() for g in J], axis=1), full_matrices=False)
        U = U[:, sv > 1e-10 * sv[0]] if sv.size and sv[0] > 0 else U[:, :0]   # a dead column spans nothing

    def info(G: list) -> np.ndarray:
        A = np.stack([(np.asarray(g, float) * sw).ravel() for g in G], axis=1)
        norm = np.sum(A * A, axis=0)
        if U.size:
            A = A - U @ (U.T @ A)
        A[:, np.sum(A * A, axis=0) <= 1e-12 * norm] = 0.0   # what is left is round-off: nothing beyond J
        return A.T @ A
    return info


def sensitivity_signatures(problem, x, sim0, hyp: Hypothesis, bar) -> list:
    G = []
    for p in hyp.probes:
        if p.analytic is not None:
            G.append(p.analytic(sim0) / p.scale)
        else:
            G.append((simulate_with(problem, x, p.params) - sim0) / p.scale)
        if bar is not None:
            bar.update(1)
    return G


def _score(effect: Effect, hyp: Hypothesis, G: list, r, J: list, w, f_base: float, f_J: float,
           ctx: Context, taken=None) -> HypothesisScore:
    c_all, f_JG = _lsq(r, J + G, w)
    coef = c_all[len(J):]
    if isinstance(effect, SensorError):
        # a gain or offset within the transducer's specification is not a fault: only
        # the probes fitted beyond it count (and are refitted alone). An offset is
        # fitted to the tared residual, so the channel's zero error is the fitted
        # offset plus what the tare took: that sum, not the fitted part alone, is
        # what the specification bounds (else the tolerance counts twice)
        # A probe the record cannot identify (the gain of a channel that barely moves) is
        # dropped first: with it the fit is degenerate (issue 18: a gain of 180 against an
        # offset of -24 kN)
        ident, notes = effect.identifiable(G, ctx, r.shape[0])
        if not ident.all():
            G = [g if o else np.zeros_like(g) for g, o in zip(G, ident)]
            c_all, f_JG = _lsq(r, J + G, w)
            coef = np.where(ident, c_all[len(J):], 0.0)
        zero = np.zeros(len(coef))
        if taken is not None:
            zero[1::2] = taken
        out = (np.abs(coef + zero) > effect.tolerance(ctx)) & ident
        G = [g if o else np.zeros_like(g) for g, o in zip(G, out)]
        c_all, f_JG = _lsq(r, J + G, w)
        coef = np.where(out, c_all[len(J):], 0.0)
    _, f_G = _lsq(r, G, w)
    share = max(0.0, (f_J - f_JG) / f_base) if f_base > 0 else 0.0
    alone = max(0.0, (f_base - f_G) / f_base) if f_base > 0 else 0.0
    gains = np.zeros(len(G))
    if isinstance(effect, SensorError) and f_base > 0:
        # what each probe adds: the share lost without it (for choosing the channels to identify)
        for i in range(len(G)):
            _, f_wo = _lsq(r, J + G[:i] + G[i + 1:], w)
            gains[i] = (f_wo - f_JG) / f_base
    return HypothesisScore(effect.name, hyp.label, float(share), float(alone), np.asarray(coef), gains, hyp,
                           notes=notes if isinstance(effect, SensorError) else [])
