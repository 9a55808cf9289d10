"""The Hunt-Crossley damping laws, the exact restitution relation, and the
single-impact harness of the C core.

Every contact of the chain uses F = K d^n (1 + chi(e) d'/v_i), clipped at 0.
The laws differ only in chi(e). One impact of a body of mass m on such a
contact obeys m v dv/dd = -K d^n (1 + chi v / v_i); integrating compression
and restitution and equating the two (the peak elastic energy is the same)
gives the exact relation

    ln((1 + chi) / (1 - e chi)) = (1 + e) chi,

free of m, K, n and v_i (see docs/contact_laws.md). Read one way it gives the
chi a nominal e needs (law GZ); read the other way it gives the restitution a
law's chi(e) really produces. This module solves it in Python with scipy
(independently of the bisection in fmu_src/contact.c) and wraps the C
single-impact harness (`lss_impact_run` in fmu_src/testing/core_api_impact.c), which
runs the chain's own solver, force and onset-memory code.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np
from scipy.optimize import brentq

LAWS: dict[str, int] = {"HC": 1, "HW": 2, "LW": 3, "LN": 4, "GZ": 5, "FL": 6}
LAW_NAMES: dict[int, str] = {v: k for k, v in LAWS.items()}
LAW_TITLES: dict[str, str] = {
    "HC": "Hunt & Crossley 1975",
    "HW": "Herbert & McWhannell 1977",
    "LW": "Lee & Wang 1983",
    "LN": "Lankarani & Nikravesh 1990",
    "GZ": "exact (Gonthier et al. 2004, Zhang & Sharf 2009)",
    "FL": "Flores et al. 2011",
}


def law_code(law) -> int:
    """Law code 1..6 from a code or a name ('HC', 'hw', ...)."""
    if isinstance(law, str):
        try:
            return LAWS[law.upper()]
        except KeyError:
            raise ValueError(f"unknown contact law {law!r}: use one of {', '.join(LAWS)}") from None
    code = int(law)
    if code not in LAW_NAMES:
        raise ValueError(f"unknown contact law code {law!r}: use 1..6 ({', '.join(LAWS)})")
    return code


def _check_e(e: float) -> float:
    e = float(e)
    if not (0.0 < e <= 1.0):
        raise ValueError(f"e = {e!r}: a coefficient of restitution must lie in (0, 1]")
    return e


# --- the exact relation ------------------------------------------------------------

def _g_over_x2(x: float, e: float) -> float:
    """g(x, e) / x^2, g = ln(1+x) - ln(1-e x) - (1+e) x; a power series near
    x = 0, where the three terms of g cancel to O(x^2)."""
    if x < 0.02:
        s, xp, ek, sign = 0.0, 1.0, e * e, -1.0
        for k in range(2, 40):
            s += (sign + ek) * xp / k
            sign, ek, xp = -sign, ek * e, xp * x
        return s
    return (math.log1p(x) - math.log1p(-e * x) - (1.0 + e) * x) / (x * x)


def restitution_relation(chi: float, e: float) -> float:
    """Residual ln((1+chi)/(1-e chi)) - (1+e) chi of the exact relation."""
    return math.log1p(chi) - math.log1p(-e * chi) - (1.0 + e) * chi


def chi_exact(e: float) -> float:
    """The chi that makes one impact restitute exactly e: the nonzero root of
    the relation in (0, 1/e); 0 for e = 1."""
    e = _check_e(e)
    if e == 1.0:
        return 0.0
    hi = (1.0 / e) * (1.0 - 1e-14)
    if _g_over_x2(hi, e) <= 0.0:   # root closer to 1/e than the bracket (e below about 0.03)
        return hi
    return brentq(lambda x: _g_over_x2(x, e), 1e-300, hi, xtol=1e-300, rtol=4 * np.finfo(float).eps,
                  maxiter=500)


def restitution_of_chi(chi: float) -> float:
    """The restitution one impact really has with damping factor chi (the
    inverse of chi_exact): the root e in (0, min(1, 1/chi))."""
    chi = float(chi)
    if not (chi >= 0.0 and math.isfinite(chi)):
        raise ValueError(f"chi = {chi!r} must be finite and >= 0")
    if chi == 0.0:
        return 1.0
    hi = min(1.0, 1.0 / chi) * (1.0 - 1e-15)
    if _g_over_x2(chi, hi) <= 0.0:
        return hi
    return brentq(lambda e: _g_over_x2(chi, e), 0.0, hi, xtol=1e-16, rtol=4 * np.finfo(float).eps,
                  maxiter=500)


# --- the laws ---------------------------------------------------------------------

def chi(law, e: float) -> float:
    """chi(e) of a law (brief section 2 table); GZ by the exact relation."""
    code, e = law_code(law), _check_e(e)
    if code == 1:
        return 1.5 * (1.0 - e)
    if code == 2:
        return 6.0 * (1.0 - e) / ((2.0 * e - 1.0) ** 2 + 3.0)
    if code == 3:
        return 0.75 * (1.0 - e)
    if code == 4:
        return 0.75 * (1.0 - e * e)
    if code == 5:
        return chi_exact(e)
    return 8.0 * (1.0 - e) / (5.0 * e)


def effective_restitution(law, e: float) -> float:
    """The restitution an impact really has when the law is given nominal e."""
    return restitution_of_chi(chi(law, e))


# --- the C core -------------------------------------------------------------------

def c_chi(law, e: float) -> float:
    """contact_chi() of fmu_src/contact.c (NaN for invalid input)."""
    from . import ccore
    _, lib = ccore.load()
    return lib.lss_contact_chi(law_code(law) if isinstance(law, str) else int(law), float(e))


def c_chi_exact(e: float) -> float:
    from . import ccore
    _, lib = ccore.load()
    return lib.lss_contact_chi_exact(float(e))


def c_restitution_of_chi(chi_: float) -> float:
    from . import ccore
    _, lib = ccore.load()
    return lib.lss_contact_restitution_of_chi(float(chi_))


@dataclass
class Impact:
    """Result of one simulated impact (SI units)."""
    law: str
    e: float              # nominal restitution given to the law
    chi: float            # chi(e) of the law
    e_eff: float          # v_out / v_in
    v_in: float
    v_out: float
    v_onset: float        # the onset velocity the contact remembered
    F_max: float
    duration: float
    delta_max: float
    n_steps: int
    n_rejected: int
    n_rhs: int
    trace: Optional[np.ndarray] = None   # rows t, delta, delta_dot, F at accepted steps


_NOUT = 13


def simulate_impact(law, e: float, *, K: float = 1e6, n: float = 1.5, m: float = 1.0, v_i: float = 1.0,
                    v_min: float = 1e-3, tol: float = 1e-8, h_max: Optional[float] = None,
                    scale_delta: Optional[float] = None, scale_rate: Optional[float] = None,
                    rel_rate: Optional[float] = None, onset_rule: int = 0, gap: Optional[float] = None,
                    trace: int = 0) -> Impact:
    """Run one impact through the C harness (the chain's solver, force and
    onset memory).

    The solver's error scales default to the impact's natural scales (the
    elastic peak indentation d* and v_i), which makes the result free of m, K
    and v_i; `scale_delta` (m), `scale_rate` (m/s) and `rel_rate` set them as
    the chain does (there: 1e-2 m, 1e-2 m/s and 1 at solver.tolerance 1e-4).
    `onset_rule` 0 is the chain's (linear interpolation of the rate at the
    crossing), 1 a cubic Hermite alternative. `trace` > 0 keeps up to that
    many accepted points. Raises ValueError with the C message on bad input or
    a failed run."""
    from . import ccore
    ffi, lib = ccore.load()
    code = law_code(law)
    opts = [h_max, scale_delta, scale_rate, rel_rate, float(onset_rule), gap]
    c_opts = ffi.new("double[]", [math.nan if v is None else float(v) for v in opts])
    out = ffi.new("double[]", _NOUT)
    tr = ffi.new("double[]", 4 * trace) if trace > 0 else ffi.NULL
    err = ffi.new("char[]", 512)
    rc = lib.lss_impact_run(code, float(e), float(K), float(n), float(m), float(v_i), float(v_min),
                            float(tol), c_opts, len(opts), out, _NOUT, tr, int(trace), err, 512)
    if rc != 0:
        raise ValueError(f"impact {LAW_NAMES[code]} e = {e}: {ffi.string(err).decode()}")
    o = list(out)
    rows = None
    if trace > 0:
        k = int(o[11])
        rows = np.frombuffer(ffi.buffer(tr, 8 * 4 * k), dtype=float).reshape(k, 4).copy()
    return Impact(law=LAW_NAMES[code], e=float(e), chi=o[6], e_eff=o[0], v_in=o[1], v_out=o[2],
                  v_onset=o[12], F_max=o[3], duration=o[4], delta_max=o[5], n_steps=int(o[7]),
                  n_rejected=int(o[8]), n_rhs=int(o[9]), trace=rows)
