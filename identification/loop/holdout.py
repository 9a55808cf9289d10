"""Held-out validation of an extension (issue 18, identification.loop.evidence item 3).

The record is cut into HOLDOUT_BLOCKS interleaved blocks; fitted on the even
blocks and validated on the odd ones and the other way round, the extended
model must lower the held-out error below what the base, refitted on the
same blocks, gives.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ..objective.jacobian import demean_columns, one_sided_jacobian
from ..objective.problem import tared

log = logging.getLogger(__name__)

HOLDOUT_BLOCKS = 16     # interleaved blocks of the held-out validation (two folds: even and odd blocks)


@dataclass
class HoldOut:
    E_base: float              # held-out error of the base refitted on the other blocks (noise units)
    E_ext: float               # same for the extended model
    blocks: int
    evals: int

    @property
    def gain(self) -> float:
        return (self.E_base - self.E_ext) / self.E_base if self.E_base > 0 else 0.0

    def text(self) -> str:
        """The gain as a user reads it: a share where the extension's
        held-out error is at most twice the base's, else how many times the
        base's it is (an extension that blows up on the other blocks: -420098%
        says nothing a reader can use)."""
        if self.gain >= -1.0 or not np.isfinite(self.E_ext):
            return f"{100 * self.gain:+.1f}%" if np.isfinite(self.gain) else "extension failed"
        return f"{self.E_ext / self.E_base:.3g} x the base's error"

    def to_dict(self) -> dict:
        return {"E_base": self.E_base, "E_ext": self.E_ext, "gain": self.gain, "blocks": self.blocks,
                "evals": self.evals}


def folds(n: int, blocks: int = HOLDOUT_BLOCKS) -> np.ndarray:
    """Fold (0 or 1) of each sample: interleaved blocks of equal length."""
    blocks = max(2, min(blocks, n // 2))
    edges = np.linspace(0, n, blocks + 1).astype(int)
    f = np.zeros(n, int)
    for b in range(blocks):
        f[edges[b]:edges[b + 1]] = b % 2
    return f


def _tared_residual(problem, sim):
    r = problem.samples - sim
    demean = np.zeros(r.shape[1], bool)
    if problem.tare is not None:
        demean = np.abs(r.mean(axis=0)) <= problem.tare
    return tared(r, problem.tare), demean


def _heldout_error(problem, x, w, fold, rel_step: float = 0.02) -> tuple:
    """Sum over both folds of the validation error after one damped Gauss-Newton
    step fitted on the training fold (from x, the whole record's optimum: to
    first order the training fold's optimum), the step halved up to three times
    until it lowers the training error. Returns (error, simulations)."""
    sim0 = problem.simulate(x)
    r0, demean = _tared_residual(problem, sim0)
    cols = one_sided_jacobian(problem, x, sim0, rel_step=rel_step)
    nsim = 1 + len(x)
    lo, hi = np.array(problem.bounds_array, float).T
    E = 0.0
    for k in (0, 1):
        train, val = fold == k, fold != k
        err_train0 = float(np.sum(r0[train] ** 2 * w))
        best_r = r0
        if len(cols) == len(x):
            A = np.stack([(demean_columns(g, demean)[train] * np.sqrt(w)).ravel() for g in cols], axis=1)
            b = (r0[train] * np.sqrt(w)).ravel()
            AtA = A.T @ A
            d = np.diag(AtA).copy()
            d[d <= 0] = 1.0
            try:
                step = np.linalg.solve(AtA + 1e-3 * np.diag(d), A.T @ b)
            except np.linalg.LinAlgError:
                step = np.zeros(len(x))
            for _ in range(4):
                if not np.any(step):
                    break
                xn = np.clip(x + step, lo, hi)
                nsim += 1
                try:
                    rn, _ = _tared_residual(problem, problem.simulate(xn))
                except Exception as exc:
                    log.warning("held-out step failed: %s", exc)
                    step = 0.5 * step
                    continue
                if float(np.sum(rn[train] ** 2 * w)) < err_train0:
                    best_r = rn
                    break
                step = 0.5 * step
        E += float(np.sum(best_r[val] ** 2 * w))
    return E, nsim


def holdout(base, x_base, ext, x_ext, w: np.ndarray, blocks: int = HOLDOUT_BLOCKS) -> HoldOut:
    """Module docstring (w = 1 / sigma^2 per channel)."""
    fold = folds(len(base.times), blocks)
    Eb, nb = _heldout_error(base, np.asarray(x_base, float), w, fold)
    Ee, ne = _heldout_error(ext, np.asarray(x_ext, float), w, fold)
    return HoldOut(Eb, Ee, int(max(2, min(blocks, len(base.times) // 2))), nb + ne)
