"""Complex-RF: Box's Complex method with randomisation and a forgetting factor.

This is the serial reference implementation of the optimiser used to identify
the contact parameters (design brief section 5, paper section 3).  The method,
its parameters and its references are described in ``docs/complex_rf.md``.

    >>> from identification import minimize_complex
    >>> res = minimize_complex(lambda x: ((x - 0.3) ** 2).sum(), [(-1, 1)] * 3, seed=1)
    >>> res.message, bool(abs(res.x - 0.3).max() < 1e-2)
    ('parameter spread', True)

The parallel variant (Complex-RFP) is :func:`identification.optim.complex_rfp.minimize_complex_parallel`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from .optim_result import (
    MESSAGES,
    STATUS_CALLBACK,
    STATUS_FUNCTION_SPREAD,
    STATUS_MAX_EVALS,
    STATUS_PARAMETER_SPREAD,
    ComplexHistory,
    ComplexResult,
)

__all__ = ["minimize_complex", "ComplexResult", "parse_bounds", "forgetting_constant"]

log = logging.getLogger(__name__)

#: defaults of the published Complex-RF (Krus & Andersson 2003)
DEFAULT_ALPHA = 1.3
DEFAULT_RFAK = 0.3
DEFAULT_GAMMA = 0.3
#: retraction: weight of the best point grows as 1 - exp(-q / RETRACT_DECAY)
DEFAULT_RETRACT_DECAY = 4.0
#: retractions of one candidate before it is left in the complex as it is
DEFAULT_MAX_RETRACTIONS = 30


# --------------------------------------------------------------------------
# input validation
# --------------------------------------------------------------------------


def parse_bounds(bounds: Any) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(lo, hi)`` float arrays from a sequence of ``(lo, hi)`` pairs or a
    :class:`scipy.optimize.Bounds`.

    Raises ``ValueError`` naming the offending index and values when a bound is
    not finite, when ``lo >= hi``, or when the range ``hi - lo`` overflows.
    """
    if hasattr(bounds, "lb") and hasattr(bounds, "ub"):  # scipy.optimize.Bounds
        lo = np.atleast_1d(np.asarray(bounds.lb, dtype=float))
        hi = np.atleast_1d(np.asarray(bounds.ub, dtype=float))
        if lo.shape != hi.shape:
            try:
                lo, hi = np.broadcast_arrays(lo, hi)
            except ValueError:
                raise ValueError(
                    f"bounds: lower bounds of shape {lo.shape} and upper bounds of shape "
                    f"{hi.shape} do not match"
                ) from None
        lo, hi = lo.astype(float).ravel(), hi.astype(float).ravel()
    else:
        try:
            pairs = [tuple(b) for b in bounds]
        except TypeError:
            raise ValueError("bounds must be a sequence of (lo, hi) pairs or scipy.optimize.Bounds") from None
        for i, p in enumerate(pairs):
            if len(p) != 2:
                raise ValueError(f"bounds[{i}] = {p!r} is not a (lo, hi) pair")
        try:
            lo = np.array([float(p[0]) if p[0] is not None else np.nan for p in pairs], dtype=float)
            hi = np.array([float(p[1]) if p[1] is not None else np.nan for p in pairs], dtype=float)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"bounds: not numeric ({exc})") from None
    if lo.size == 0:
        raise ValueError("bounds: at least one design variable is needed")
    for i, (a, b) in enumerate(zip(lo.tolist(), hi.tolist())):
        if not (math.isfinite(a) and math.isfinite(b)):
            raise ValueError(f"bounds[{i}] = ({a!r}, {b!r}) is not finite; explicit finite bounds are required")
        if not a < b:
            raise ValueError(f"bounds[{i}] = ({a!r}, {b!r}): lower bound must be < upper bound")
        if not math.isfinite(b - a):
            raise ValueError(f"bounds[{i}] = ({a!r}, {b!r}): range hi - lo overflows")
    return lo, hi


def _check_x0(x0: Any, lo: np.ndarray, hi: np.ndarray) -> np.ndarray | None:
    if x0 is None:
        return None
    x = np.asarray(x0, dtype=float).ravel()
    if x.shape != lo.shape:
        raise ValueError(f"x0 has {x.size} elements but bounds have {lo.size}")
    for i, (v, a, b) in enumerate(zip(x.tolist(), lo.tolist(), hi.tolist())):
        if not math.isfinite(v):
            raise ValueError(f"x0[{i}] = {v!r} is not finite")
        if not a <= v <= b:
            raise ValueError(f"x0[{i}] = {v!r} is outside bounds[{i}] = ({a!r}, {b!r})")
    return x


def _check_options(m: int, n_points: int | None, alpha: float, rfak: float, gamma: float,
                   max_evals: int, f_tol: float, x_tol: float, retract_decay: float,
                   max_retractions: int) -> int:
    k = m + 2 if n_points is None else int(n_points)
    if k < 2:
        raise ValueError(f"n_points = {n_points!r}: the complex needs at least 2 points")
    if not alpha > 0:
        raise ValueError(f"alpha = {alpha!r} must be > 0")
    if not rfak >= 0:
        raise ValueError(f"rfak = {rfak!r} must be >= 0")
    if not gamma >= 0:
        raise ValueError(f"gamma = {gamma!r} must be >= 0")
    if not f_tol >= 0 or not x_tol >= 0:
        raise ValueError(f"f_tol = {f_tol!r} and x_tol = {x_tol!r} must be >= 0")
    if not retract_decay > 0:
        raise ValueError(f"retract_decay = {retract_decay!r} must be > 0")
    if int(max_retractions) < 0:
        raise ValueError(f"max_retractions = {max_retractions!r} must be >= 0")
    if int(max_evals) < k:
        raise ValueError(f"max_evals = {max_evals!r} is smaller than the complex ({k} points)")
    return k


def forgetting_constant(alpha: float, gamma: float, k: int) -> float:
    """Per-iteration forgetting increment factor ``kf = 1 - (alpha/2) ** (gamma/k)``.

    Each iteration every stored objective value of the complex grows by
    ``kf * (max f - min f)``; a new point enters with its true value, so a point
    that has been in the complex for ``n`` iterations carries an age penalty of
    roughly ``n * kf`` spreads.  With ``gamma = 0`` nothing is forgotten.
    """
    return 1.0 - (alpha / 2.0) ** (gamma / k)


# --------------------------------------------------------------------------
# evaluation (shared with the parallel variant)
# --------------------------------------------------------------------------


class SafeObjective:
    """Picklable wrapper: ``(value, bad, error_message)`` instead of raising.

    A value that is not a finite real scalar, or an exception raised by the
    objective, gives ``(inf, True, message)``.  Used as the task function sent
    to executors, so ``fun`` itself must be picklable for process pools.
    """

    def __init__(self, fun: Callable[..., Any], args: tuple = ()):
        self.fun = fun
        self.args = tuple(args)

    def __call__(self, x: np.ndarray) -> tuple[float, bool, str | None]:
        try:
            v = self.fun(np.array(x, dtype=float), *self.args)
            v = float(np.asarray(v, dtype=float).reshape(()))
        except Exception as exc:  # noqa: BLE001 - a bad point, never a crash
            msg = f"{type(exc).__name__}: {exc}"
            return math.inf, True, msg[:500]
        if not math.isfinite(v):
            return math.inf, True, None
        return v, False, None


class _Recorder:
    """Counts evaluations, records the history, drives the progress bar."""

    def __init__(self, m: int, max_evals: int, progress: bool, desc: str):
        self.m = m
        self.rows_x: list[np.ndarray] = []
        self.rows_f: list[float] = []
        self.rows_acc: list[bool] = []
        self.rows_bad: list[bool] = []
        self.rows_kind: list[str] = []
        self.rows_it: list[int] = []
        self.rows_round: list[int] = []
        self.rows_path: list[int] = []
        self.nfev_used = 0
        self.n_repeat = 0   # rows that repeat a known evaluation (no call of the objective)
        self.errors: list[tuple[int, str]] = []
        self.its: dict[str, list] = {k: [] for k in
                                     ("iteration", "round", "nfev", "best_f", "worst_f", "f_spread", "x_spread")}
        self.best_x: np.ndarray | None = None
        self.best_f = math.inf
        self.n_bad = 0
        self.bar = None
        if progress:
            from tqdm.auto import tqdm

            self.bar = tqdm(total=max_evals, desc=desc, unit="eval", leave=True)

    @property
    def nfev(self) -> int:
        return len(self.rows_f) - self.n_repeat

    def record(self, x: np.ndarray, out: tuple[float, bool, str | None], kind: str,
               iteration: int, rnd: int, discarded: bool = False, repeat: bool = False) -> int:
        """Store one evaluation; ``discarded=True`` marks it unused until :meth:`use`;
        ``repeat=True``: a row for a point asked again, its value known (not an evaluation)."""
        f, bad, err = out
        self.n_repeat += bool(repeat)
        idx = len(self.rows_f)
        self.rows_x.append(np.array(x, dtype=float))
        self.rows_f.append(float(f))
        self.rows_acc.append(False)
        self.rows_bad.append(bool(bad))
        self.rows_kind.append(kind)
        self.rows_it.append(int(iteration))
        self.rows_round.append(int(rnd))
        self.rows_path.append(-1)
        if bad:
            self.n_bad += 1
            if err is not None:
                self.errors.append((idx, err))
                log.warning("objective failed at evaluation %d, x=%s: %s", idx,
                            np.array2string(np.asarray(x), precision=6), err)
            else:
                log.warning("objective returned a non-finite value at evaluation %d, x=%s", idx,
                            np.array2string(np.asarray(x), precision=6))
        if not discarded:
            self.use(idx)
        return idx

    def use(self, idx: int) -> None:
        """Mark evaluation ``idx`` as used by the method (it may become the best)."""
        if self.rows_path[idx] >= 0:
            return
        self.rows_path[idx] = self.nfev_used
        self.nfev_used += 1
        f = self.rows_f[idx]
        if self.best_x is None or (not self.rows_bad[idx] and f < self.best_f):
            self.best_f = float(f)
            self.best_x = self.rows_x[idx].copy()
        if self.bar is not None:
            self.bar.update(1)

    def accept(self, idx: int) -> None:
        self.rows_acc[idx] = True

    def iteration_row(self, iteration: int, rnd: int, F: np.ndarray, X: np.ndarray, span: np.ndarray) -> None:
        self.its["iteration"].append(int(iteration))
        self.its["round"].append(int(rnd))
        self.its["nfev"].append(self.nfev_used)
        self.its["best_f"].append(float(np.min(F)))
        self.its["worst_f"].append(float(np.max(F)))
        with np.errstate(invalid="ignore", over="ignore"):
            self.its["f_spread"].append(float(np.max(F) - np.min(F)))
        self.its["x_spread"].append(x_spread(X, span))
        if self.bar is not None:
            self.bar.set_postfix(best=f"{self.best_f:.6g}", refresh=False)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()

    def history(self) -> ComplexHistory:
        n = len(self.rows_f)   # every row, repeats included
        its = {
            k: np.asarray(v, dtype=int if k in ("iteration", "round", "nfev") else float)
            for k, v in self.its.items()
        }
        return ComplexHistory(
            eval_index=np.arange(n),
            x=np.array(self.rows_x, dtype=float).reshape(n, self.m),
            f=np.array(self.rows_f, dtype=float),
            accepted=np.array(self.rows_acc, dtype=bool),
            bad=np.array(self.rows_bad, dtype=bool),
            kind=list(self.rows_kind),
            iteration=np.array(self.rows_it, dtype=int),
            round=np.array(self.rows_round, dtype=int),
            path_index=np.array(self.rows_path, dtype=int),
            iterations=its,
            errors=list(self.errors),
        )


# --------------------------------------------------------------------------
# algorithm pieces (shared with the parallel variant)
# --------------------------------------------------------------------------


def x_spread(X: np.ndarray, span: np.ndarray) -> float:
    """Largest coordinate range over the complex, relative to the bound range."""
    return float(np.max((X.max(axis=0) - X.min(axis=0)) / span))


def function_spread_converged(F: np.ndarray, f_tol: float) -> bool:
    """``max f - min f <= f_tol * |min f|`` (absolute when ``min f == 0``)."""
    if not np.all(np.isfinite(F)):
        return False
    fmin, fmax = float(np.min(F)), float(np.max(F))
    spread = fmax - fmin
    if not math.isfinite(spread):
        return False
    scale = abs(fmin) if fmin != 0.0 else 1.0
    return spread <= f_tol * scale


def check_convergence(X: np.ndarray, F: np.ndarray, span: np.ndarray, f_tol: float, x_tol: float) -> int | None:
    if function_spread_converged(F, f_tol):
        return STATUS_FUNCTION_SPREAD
    if x_spread(X, span) <= x_tol:
        return STATUS_PARAMETER_SPREAD
    return None


def forget(R: np.ndarray, kf: float) -> None:
    """Age every stored value by ``kf`` times the (finite) spread, in place."""
    fin = np.isfinite(R)
    if kf > 0 and np.count_nonzero(fin) >= 2:
        r = R[fin]
        R[fin] = r + (r.max() - r.min()) * kf


def worst_index(R: np.ndarray, birth: np.ndarray, exclude: Sequence[int] = ()) -> int:
    """Index of the highest (aged) value; ties go to the oldest point."""
    for i in np.lexsort((birth, -R)):
        if int(i) not in exclude:
            return int(i)
    raise RuntimeError("no eligible point in the complex")


def is_worst(R: np.ndarray, j: int) -> bool:
    """True if point ``j`` is (jointly) the worst of the complex by aged value."""
    others = np.delete(R, j)
    return bool(R[j] >= others.max())


def random_term(base: int, iteration: int, q: int, rfak: float, span: np.ndarray, spread: float) -> np.ndarray:
    """Uniform perturbation of width ``rfak * span * spread`` centred on zero.

    The uniform numbers are keyed by the run's ``base`` key, the iteration and the
    step within it (``q = -1`` for the reflection, ``0, 1, ...`` for the
    retractions), so a candidate is a pure function of the state of the complex.
    This is what lets the parallel variant compute the serial run's future
    candidates speculatively and reproduce it exactly.
    """
    u = np.random.default_rng((base, iteration, q + 1)).random(span.size)
    return rfak * span * spread * (u - 0.5)


def run_key(rng: np.random.Generator) -> int:
    """Key of the per-step random streams, drawn once after the initial complex."""
    return int(rng.integers(0, 2**63 - 1))


def reflect(xc: np.ndarray, xw: np.ndarray, alpha: float, noise: np.ndarray,
            lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Reflect ``xw`` through ``xc`` by ``alpha``, perturb, clip into the box."""
    return np.clip(xc + alpha * (xc - xw) + noise, lo, hi)


def retract(xc: np.ndarray, xb: np.ndarray, xprev: np.ndarray, q: int, decay: float,
            noise: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Move halfway from ``xprev`` toward a target sliding from the centroid to the best point."""
    a = 1.0 - math.exp(-q / decay)
    target = (1.0 - a) * xc + a * xb
    return np.clip(0.5 * (target + xprev) + noise, lo, hi)


def initial_complex(rng: np.random.Generator, k: int, lo: np.ndarray, hi: np.ndarray,
                    x0: np.ndarray | None) -> np.ndarray:
    X = lo + (hi - lo) * rng.random((k, lo.size))
    X = np.clip(X, lo, hi)
    if x0 is not None:
        X[0] = x0
    return X


def make_rng(seed: Any) -> np.random.Generator:
    if isinstance(seed, np.random.Generator):
        return seed
    return np.random.default_rng(seed)


def _seed_repr(seed: Any) -> Any:
    if seed is None or isinstance(seed, (int, np.integer)):
        return None if seed is None else int(seed)
    return repr(seed)


def intermediate(rec: _Recorder, nit: int, F: np.ndarray):
    from scipy.optimize import OptimizeResult

    return OptimizeResult(x=rec.best_x.copy(), fun=rec.best_f, nit=nit, nfev=rec.nfev,
                          nfev_used=rec.nfev_used, complex_f=F.copy())


# --------------------------------------------------------------------------
# the serial optimiser
# --------------------------------------------------------------------------


def minimize_complex(
    fun: Callable[..., float],
    bounds: Any,
    x0: Any = None,
    *,
    args: tuple = (),
    n_points: int | None = None,
    alpha: float = DEFAULT_ALPHA,
    rfak: float = DEFAULT_RFAK,
    gamma: float = DEFAULT_GAMMA,
    max_evals: int = 5000,
    f_tol: float = 1e-6,
    x_tol: float = 1e-4,
    seed: Any = None,
    callback: Callable[[Any], Any] | None = None,
    progress: bool = False,
    retract_decay: float = DEFAULT_RETRACT_DECAY,
    max_retractions: int = DEFAULT_MAX_RETRACTIONS,
) -> ComplexResult:
    """Minimise ``fun(x, *args)`` within explicit bounds with the Complex-RF method.

    Parameters
    ----------
    fun : callable ``fun(x, *args) -> float``. Exceptions and non-finite values
        are bad points (ranked worst, counted in ``n_bad``), never a crash.
    bounds : sequence of ``(lo, hi)`` or :class:`scipy.optimize.Bounds`; finite, ``lo < hi``.
    x0 : optional point inside the bounds; it becomes one of the initial points.
    n_points : size of the complex, default ``m + 2`` (``m`` = dimension).
    alpha : reflection distance through the centroid (1.3).
    rfak : randomisation factor (0.3): reflections and retractions get a uniform
        perturbation of width ``rfak * (hi - lo) * spread``, where ``spread`` is
        the current relative size of the complex.
    gamma : forgetting factor (0.3): stored values age by
        ``forgetting_constant(alpha, gamma, n_points)`` spreads per iteration.
    max_evals : evaluation budget (5000).
    f_tol : stop when ``max f - min f <= f_tol * |min f|`` over the complex.
    x_tol : stop when every coordinate's range over the complex is ``<= x_tol``
        times its bound range.
    seed : int, ``None`` or :class:`numpy.random.Generator`; same seed, same run.
    callback : ``callback(intermediate_result)`` after every iteration, with an
        :class:`scipy.optimize.OptimizeResult` (x, fun, nit, nfev, nfev_used, complex_f);
        returning ``True`` stops the run (status 3).
    progress : show a tqdm progress bar with the best objective.
    retract_decay, max_retractions : retraction schedule (4, 30).

    Returns
    -------
    ComplexResult (``x``/``fun`` is the best point ever evaluated).
    """
    lo, hi = parse_bounds(bounds)
    m = lo.size
    x0a = _check_x0(x0, lo, hi)
    k = _check_options(m, n_points, alpha, rfak, gamma, max_evals, f_tol, x_tol,
                       retract_decay, max_retractions)
    max_evals = int(max_evals)
    span = hi - lo
    rng = make_rng(seed)
    kf = forgetting_constant(alpha, gamma, k)
    evaluate = SafeObjective(fun, args)
    rec = _Recorder(m, max_evals, progress, "Complex-RF")

    try:
        # initial complex: uniformly random in the box (x0 replaces the first point)
        X = initial_complex(rng, k, lo, hi, x0a)
        F = np.empty(k)
        birth = np.empty(k, dtype=np.int64)
        for i in range(k):
            out = evaluate(X[i])
            idx = rec.record(X[i], out, "init", 0, rec.nfev)
            rec.accept(idx)
            F[i] = out[0]
            birth[i] = idx
        R = F.copy()  # aged values used for ranking (true values stay in F)
        base = run_key(rng)
        nit = 0
        rec.iteration_row(0, rec.nfev - 1, F, X, span)

        status = STATUS_MAX_EVALS
        while True:
            conv = check_convergence(X, F, span, f_tol, x_tol)
            if conv is not None:
                status = conv
                break
            if rec.nfev >= max_evals:
                status = STATUS_MAX_EVALS
                break
            nit += 1
            forget(R, kf)
            w = worst_index(R, birth)
            b = int(np.argmin(R))
            xc = (X.sum(axis=0) - X[w]) / (k - 1)
            # reflection of the worst point through the centroid of the others
            xnew = reflect(xc, X[w], alpha, random_term(base, nit, -1, rfak, span, x_spread(X, span)), lo, hi)
            kind = "reflect"
            q = 0
            while True:
                out = evaluate(xnew)
                idx = rec.record(xnew, out, kind, nit, rec.nfev)
                X[w] = xnew
                F[w] = R[w] = out[0]
                birth[w] = idx
                if not is_worst(R, w):
                    rec.accept(idx)
                    break
                if q >= max_retractions or rec.nfev >= max_evals:
                    break  # left in the complex; it will be the worst next time
                # still the worst: retract toward the centroid, then the best point
                xnew = retract(xc, X[b], xnew, q, retract_decay,
                               random_term(base, nit, q, rfak, span, x_spread(X, span)), lo, hi)
                kind = "retract"
                q += 1
            rec.iteration_row(nit, rec.nfev - 1, F, X, span)
            if callback is not None and callback(intermediate(rec, nit, F)) is True:
                status = STATUS_CALLBACK
                break
    finally:
        rec.close()

    return _build_result(rec, X, F, nit, rec.nfev, status, dict(
        method="complex-rf", n_points=k, alpha=alpha, rfak=rfak, gamma=gamma, max_evals=max_evals,
        f_tol=f_tol, x_tol=x_tol, seed=_seed_repr(seed), retract_decay=retract_decay,
        max_retractions=int(max_retractions)))


def _build_result(rec: _Recorder, X: np.ndarray, F: np.ndarray, nit: int, nrounds: int, status: int,
                  options: dict[str, Any]) -> ComplexResult:
    converged = status in (STATUS_FUNCTION_SPREAD, STATUS_PARAMETER_SPREAD)
    return ComplexResult(
        x=rec.best_x.copy(),
        fun=float(rec.best_f),
        nfev=rec.nfev,
        nfev_used=rec.nfev_used,
        nit=int(nit),
        nrounds=int(nrounds),
        success=bool(converged and math.isfinite(rec.best_f)),
        status=int(status),
        message=MESSAGES[status],
        n_bad=rec.n_bad,
        complex_x=X.copy(),
        complex_f=F.copy(),
        history=rec.history(),
        options=options,
    )
