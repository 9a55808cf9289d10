"""Evidence for a missing effect (issue 18): a verdict by tests that know the noise.

The closed loop used to confirm an effect when it lowered f by a fixed share.
That confirms whatever is flexible enough whenever the base identification
stopped above the noise floor. Here an effect is confirmed only when

1. the **likelihood-ratio test** says so. With the noise sigma_j of each
   force channel (declared in meta.json's sensor block, or estimated from the
   residual's high-frequency part, `noise_levels`), the residual's weighted
   sum of squares S = sum_j sum_t r_tj^2 / sigma_j^2 falls from S_base (the base
   refitted to its own optimum) to S_ext when the effect's q parameters are
   added. For white noise dS = S_base - S_ext is chi^2(q) if the effect is
   not there. A residual that is not white (a model error, a second effect,
   a disturbance outside the catalogue) makes dS larger by chance along the
   effect's smooth signatures: `hac_eigenvalues` estimates by how much, from
   the extended residual's autocovariance (Bartlett-weighted, heteroscedasticity
   and autocorrelation consistent: the 'effective sample count' of a
   correlated residual, per signature direction), never less than the white
   noise. dS is then compared with sum_i lambda_i chi^2(1) through
   Satterthwaite's scaled chi^2 (scale a, nu degrees of freedom). The p-value
   is multiplied by the number m of hypotheses scanned in the round
   (Bonferroni: every effect's hypotheses, the pitches of the ripple, the
   joints of the bump, the channels of the sensor) and compared with ALPHA.
2. **BIC** agrees: dBIC = T - nu ln N - 2 ln m_e > 0 (T = dS / a, N the
   number of residual values, m_e the effect's own hypotheses), and no
   disturbance outside the catalogue (`departures`: crosstalk between
   channels, a periodic interference at a frequency no catalogue effect
   makes, a logger clock running fast or slow) explains the residual better
   by the same criterion.
3. **held-out validation** agrees (`holdout`): the record is cut into
   HOLDOUT_BLOCKS interleaved blocks; fitted on the even blocks and validated
   on the odd ones and the other way round, the extended model must lower
   the held-out error below what the base, refitted on the same blocks,
   gives.

Here: the likelihood-ratio test (item 1) and the linear algebra it rests on.
The noise and the excess over it: identification.objective.noise; the disturbances
outside the catalogue: identification.loop.departures; held-out validation:
identification.loop.holdout. Pure numpy/scipy.
"""
from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy import signal, stats

from ..objective.noise import ALPHA, autocov

log = logging.getLogger(__name__)

HAC_FRACTION = 0.25     # Bartlett bandwidth of the autocovariance estimate, as a fraction of the record


# ------------------------------------------------------------------------------------- linear algebra
def _stack(cols: Sequence[np.ndarray], sw: np.ndarray) -> np.ndarray:
    return np.stack([(np.asarray(g, float) * sw).ravel() for g in cols], axis=1)


def project_out(G: Sequence[np.ndarray], J: Sequence[np.ndarray], w: np.ndarray) -> list:
    """The columns G without what the columns J can do, in the metric w per channel."""
    if not J or not G:
        return [np.asarray(g, float) for g in G]
    sw = np.sqrt(w)
    A = _stack(J, sw)
    out = []
    for g in G:
        b = (np.asarray(g, float) * sw).ravel()
        c, *_ = np.linalg.lstsq(A, b, rcond=None)
        out.append(np.asarray(g, float) - np.tensordot(c, np.stack(J), axes=1))
    return out


def fit_gain(r: np.ndarray, cols: Sequence[np.ndarray], w: np.ndarray) -> tuple:
    """(coefficients, fitted part, weighted SS before, after) of r on cols."""
    sw = np.sqrt(w)
    b = (r * sw).ravel()
    S0 = float(b @ b)
    if not cols:
        return np.zeros(0), np.zeros_like(r), S0, S0
    A = _stack(cols, sw)
    c, *_ = np.linalg.lstsq(A, b, rcond=None)
    fit = np.tensordot(c, np.stack(cols), axes=1)
    res = b - A @ c
    return c, fit, S0, float(res @ res)


# ---------------------------------------------------------------- correlated residuals (HAC, Satterthwaite)
def hac_eigenvalues(G: Sequence[np.ndarray], r: np.ndarray, w: np.ndarray,
                    fraction: float = HAC_FRACTION) -> np.ndarray:
    """How much more than the white noise sigma_j the residual r varies along the
    signature columns G (already projected off the base columns): the
    eigenvalues of A^-1 B, A = G' W G, B = G' W Sigma W G with Sigma the
    Bartlett-weighted autocovariance of r per channel; each at least 1 (the
    white noise is there whatever the estimate says). White noise at sigma: all 1."""
    G = [np.asarray(g, float) for g in G]
    if not G:
        return np.zeros(0)
    n, k = r.shape
    sw = np.sqrt(w)
    A_full = _stack(G, sw)
    # a basis of the signatures' span (drops collinear and empty columns)
    U, s, Vt = np.linalg.svd(A_full, full_matrices=False)
    keep = s > 1e-8 * (s[0] if len(s) and s[0] > 0 else 1.0)
    if not keep.any():
        return np.zeros(0)
    basis = [(U[:, i] * s[i]).reshape(n, k) / sw for i in np.where(keep)[0]]   # back in force units
    K = max(1, min(n - 1, int(fraction * n)))
    rc = r - r.mean(axis=0)
    gam = autocov(rc, K)                                         # (K+1, k)
    lam = 1.0 - np.arange(K + 1) / (K + 1.0)                      # Bartlett
    kern = gam * lam[:, None]
    kern_full = np.concatenate([kern[:0:-1], kern], axis=0)       # lags -K..K, (2K+1, k)
    SG = [np.stack([signal.fftconvolve(g[:, j], kern_full[:, j], mode="same") for j in range(k)], axis=1)
          for g in basis]
    A = np.array([[float(np.sum(a * b * w)) for b in basis] for a in basis])
    B = np.array([[float(np.sum(a * sb * w ** 2)) for sb in SG] for a in basis])
    B = 0.5 * (B + B.T)
    try:
        from scipy.linalg import eigh
        ev = eigh(B, A, eigvals_only=True)
    except Exception:   # A ill-conditioned after all: the white noise only
        ev = np.ones(len(basis))
    return np.maximum(np.real(ev), 1.0)


def shift_null(G: Sequence[np.ndarray], J: Sequence[np.ndarray], r: np.ndarray, w: np.ndarray,
               n_shifts: int = 48) -> np.ndarray:
    """What the signature columns G explain of the residual r (beyond the base
    columns J) when shifted in time against it, circularly, by lags between an
    eighth and seven eighths of the record: the null distribution of dS for a
    signature unrelated to r, whatever r's structure (a model error, a
    disturbance concentrated in one stretch, a second effect)."""
    n = r.shape[0]
    if n < 16 or not G:
        return np.zeros(0)
    lags = np.unique(np.linspace(n // 8, n - n // 8, n_shifts).astype(int))
    out = []
    for L in lags:
        Gs = project_out([np.roll(np.asarray(g, float), int(L), axis=0) for g in G], J, w)
        _, _, S0, S1 = fit_gain(r, Gs, w)
        out.append(S0 - S1)
    return np.asarray(out)


@dataclass
class LRTest:
    """The likelihood-ratio test of q added parameters against the noise."""
    dS: float            # S_base - S_ext, in units of the noise variance
    q: int               # parameters added
    rank: int            # independent signature directions
    scale: float         # Satterthwaite scale a (1: white residual at the noise level)
    dof: float           # its degrees of freedom nu
    T: float             # dS / a
    p: float             # P(chi^2_nu >= T)
    m: int               # hypotheses scanned in the round (Bonferroni)
    p_adj: float         # min(1, m p)
    dbic: float          # T - nu ln N - 2 ln m_e: > 0 for the extended model by BIC
    n_values: int        # N, residual values
    m_effect: int = 1
    method: str = "white"   # which null gave the (larger) p-value: hac or shift
    hac_scale: float = 1.0
    shift_mean: float = 0.0  # mean and standard deviation of dS over the shifted signatures
    shift_sd: float = 0.0

    @property
    def significant(self) -> bool:
        return self.p_adj < ALPHA

    def to_dict(self) -> dict:
        return {k: (float(v) if isinstance(v, (float, np.floating)) else v)
                for k, v in dataclasses.asdict(self).items()} | {"significant": self.significant}


def lr_test(S_base: float, S_ext: float, G: Sequence[np.ndarray], r_ext: np.ndarray, w: np.ndarray, q: int,
            m: int, m_effect: int = 1, J: Sequence[np.ndarray] = ()) -> LRTest:
    """The test of module docstring item 1 (S in units of the noise variance,
    i.e. with w = 1 / sigma^2); G: the effect's signature columns projected off
    the base columns J; q: its parameters in the extended identification.
    Two nulls for a residual that is not white noise: the HAC estimate
    (hac_eigenvalues: a stationary correlated residual) and the shifted
    signatures (shift_null: any structure, matched to a scaled chi^2 by its
    first two moments); the one with the larger p-value decides, and neither
    scale goes below the white noise's."""
    lam = hac_eigenvalues(G, r_ext, w)
    N = int(r_ext.size)
    rank = len(lam)
    dS = max(0.0, float(S_base - S_ext))
    if rank == 0 or q <= 0:
        return LRTest(dS, int(q), 0, 1.0, 0.0, 0.0, 1.0, int(m), 1.0, -math.inf, N, int(m_effect))
    s1, s2 = float(lam.sum()), float((lam ** 2).sum())
    a = s2 / s1
    nu = (s1 * s1 / s2) * max(q, rank) / rank
    method, a_hac = "hac", a
    p = float(stats.chi2.sf(dS / a, nu))
    null = shift_null(G, J, r_ext, w)
    mu = sd = 0.0
    if len(null) >= 8:
        mu, sd = float(np.mean(null)), float(np.std(null, ddof=1))
        # scaled chi^2 a' chi^2_nu' with the shifted signatures' mean and variance, nu' at most
        # the white noise's, a' at least 1
        nu_s = min(nu, max(0.5, 2.0 * mu * mu / max(sd * sd, 1e-30)))
        a_s = max(1.0, mu / nu_s)
        p_s = float(stats.chi2.sf(dS / a_s, nu_s))
        if p_s > p:
            p, a, nu, method = p_s, a_s, nu_s, "shift"
    T = dS / a
    dbic = T - nu * math.log(N) - 2.0 * math.log(max(1, m_effect))
    return LRTest(dS, int(q), rank, a, nu, T, p, int(m), min(1.0, m * p), dbic, N, int(m_effect), method, a_hac,
                  mu, sd)


__all__ = ["ALPHA", "lr_test", "LRTest", "hac_eigenvalues", "shift_null", "project_out", "fit_gain"]
