"""Complex-RFP: the Complex-RF method evaluating several candidates per round.

A *round* is one batch of objective evaluations sent at once to an executor
(a ``concurrent.futures`` pool, a dask client through :func:`dask_map`, or any
``map_fn(fn, xs) -> results``).  Two strategies:

``strategy="speculative"`` (default) - task prediction.  The serial method is
run as a state machine; before each round the machine is copied and played
forward along the most probable outcomes (the pending candidate is accepted /
is still the worst, with acceptance rates measured during the run), and the
``n_parallel`` most probable future candidates are evaluated at once: the
pending reflection, its retractions, the next iteration's reflection if the
pending one is accepted, and so on.  The real machine then consumes the
results for as long as its actual requests were among them.  Because every
random perturbation is keyed by (iteration, step) the candidates are pure
functions of the state, so a speculated point is used only if it is exactly
the point the serial method asks for: the run is *identical* to
:func:`identification.optim.complex_rf.minimize_complex` with the same seed (same
used points, values, result), whatever ``n_parallel`` and the executor, and
only the wall-clock rounds drop.  Mispredicted evaluations are recorded in the
history as ``discarded``; ``max_evals`` limits the evaluations used.

``strategy="multidirection"`` - the ``n_parallel`` worst points (at most half
the complex) are reflected at once, each through the centroid of the points
not being moved, and each move retracts in later rounds as in the serial
method until its candidate beats the worst unmoved point.  Fewer rounds on
easy problems, but it is a different search (less robust on narrow valleys,
see docs/complex_rf.md) and does not reproduce the serial run.
"""

from __future__ import annotations

import copy
import heapq
import json
import math
import os
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .complex_rf import (
    DEFAULT_ALPHA,
    DEFAULT_GAMMA,
    DEFAULT_MAX_RETRACTIONS,
    DEFAULT_RETRACT_DECAY,
    DEFAULT_RFAK,
    SafeObjective,
    _build_result,
    _check_options,
    _check_x0,
    _Recorder,
    _seed_repr,
    check_convergence,
    forget,
    forgetting_constant,
    initial_complex,
    intermediate,
    is_worst,
    make_rng,
    parse_bounds,
    random_term,
    reflect,
    retract,
    run_key,
    worst_index,
    x_spread,
)
from .optim_result import STATUS_CALLBACK, STATUS_MAX_EVALS, ComplexResult

__all__ = ["minimize_complex_parallel", "dask_map", "STRATEGIES"]

STRATEGIES = ("speculative", "multidirection")

MapFn = Callable[[Callable[[Any], Any], Sequence[Any]], Iterable[Any]]


def dask_map(client: Any, pure: bool = False) -> MapFn:
    """A ``map_fn`` evaluating a batch on a ``dask.distributed.Client``.

    ``pure=False`` (default) keeps dask from merging tasks with equal inputs.
    """

    def _map(fn: Callable[[Any], Any], xs: Sequence[Any]) -> list[Any]:
        futures = client.map(fn, list(xs), pure=pure)
        return client.gather(futures)

    return _map


def _read_replay(replay: Any) -> dict[bytes, tuple[float, bool, str | None]]:
    """Recorded evaluations as ``{x.tobytes(): (f, bad, error)}``.

    ``replay``: a path to an evaluation log written with ``eval_log`` (JSON lines; a
    torn last line is ignored), a :class:`ComplexResult` or :class:`ComplexHistory`,
    or an iterable of ``(x, f)`` pairs.
    """
    out: dict[bytes, tuple[float, bool, str | None]] = {}
    if replay is None:
        return out

    def put(x: Any, f: Any, bad: bool = False, err: str | None = None) -> None:
        xa = np.asarray(x, dtype=float).ravel()
        fv = math.inf if f is None else float(f)
        bad = bool(bad) or not math.isfinite(fv)
        out[xa.tobytes()] = (math.inf if bad else fv, bad, err)

    if isinstance(replay, (str, os.PathLike)):
        path = Path(replay)
        if not path.exists():
            return out
        with path.open() as fh:
            for line in fh:
                try:
                    rec = json.loads(line)
                    put(rec["x"], rec["f"], rec.get("bad", False), rec.get("error"))
                except (ValueError, KeyError, TypeError):
                    continue  # a line torn by a kill
        return out
    hist = getattr(replay, "history", replay)
    if hasattr(hist, "x") and hasattr(hist, "f"):
        errors = dict(getattr(hist, "errors", []))
        for i, (x, f) in enumerate(zip(hist.x, hist.f)):
            put(x, f, bool(hist.bad[i]), errors.get(i))
        return out
    for x, f in replay:
        put(x, f)
    return out


class _Evaluator:
    """Batches through the executor / map_fn, with replay of recorded evaluations
    and an append-only evaluation log."""

    def __init__(self, safe: SafeObjective, executor: Any, map_fn: MapFn | None,
                 replay: dict[bytes, tuple[float, bool, str | None]], eval_log: Any):
        self.safe, self.executor, self.map_fn, self.replay = safe, executor, map_fn, replay
        self.log = None
        if eval_log is not None:
            Path(eval_log).parent.mkdir(parents=True, exist_ok=True)
            self.log = open(eval_log, "a")

    def close(self) -> None:
        if self.log is not None:
            self.log.close()

    def lookup(self, x: np.ndarray) -> tuple[float, bool, str | None] | None:
        return self.replay.get(x.tobytes())

    def batch(self, xs: list[np.ndarray]) -> tuple[list[tuple[float, bool, str | None]], list[bool]]:
        """Results for ``xs`` and, per point, whether it came from the replay."""
        outs: list[Any] = [self.lookup(x) for x in xs]
        replayed = [o is not None for o in outs]
        todo = [x for x, o in zip(xs, outs) if o is None]
        if todo:
            if self.map_fn is not None:
                res = list(self.map_fn(self.safe, todo))
            elif self.executor is not None:
                res = list(self.executor.map(self.safe, todo))
            else:
                res = [self.safe(x) for x in todo]
            if len(res) != len(todo):
                raise RuntimeError(f"map returned {len(res)} results for {len(todo)} points")
            it = iter(res)
            outs = [o if o is not None else next(it) for o in outs]
            if self.log is not None:
                for x, (f, bad, err), rep in zip(xs, outs, replayed):
                    if not rep:
                        line = {"x": np.asarray(x).tolist(), "f": None if bad else float(f), "bad": bool(bad),
                                "error": err}
                        self.log.write(json.dumps(line) + "\n")
                self.log.flush()
        return [_normalize(o) for o in outs], replayed


def _normalize(out: Any) -> tuple[float, bool, str | None]:
    """A result from the map: the ``SafeObjective`` triple, or - from a ``map_fn``
    that calls the objective itself - a plain value (non-finite -> bad point)."""
    if isinstance(out, tuple) and len(out) == 3:
        f, bad, err = out
        return float(f), bool(bad), err
    try:
        v = float(np.asarray(out, dtype=float).reshape(()))
    except (TypeError, ValueError) as exc:
        return math.inf, True, f"map returned {out!r}: {exc}"[:500]
    return (v, False, None) if math.isfinite(v) else (math.inf, True, None)


def _cpu_count() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - non-Linux
        return os.cpu_count() or 1


@dataclass(frozen=True)
class _Ctx:
    """Immutable settings shared by the state machine and its copies."""

    lo: np.ndarray
    hi: np.ndarray
    span: np.ndarray
    k: int
    alpha: float
    rfak: float
    kf: float
    f_tol: float
    x_tol: float
    decay: float
    max_ret: int
    max_evals: int
    base: int


class _Machine:
    """The serial Complex-RF loop as a state machine (same steps as minimize_complex).

    ``request()`` returns the next point the method wants evaluated (or None
    when it has stopped, ``status`` set); ``feed(f)`` gives it that point's value
    and returns ``(accepted, iteration_ended)``.
    """

    def __init__(self, ctx: _Ctx, X: np.ndarray, F: np.ndarray):
        self.ctx = ctx
        self.X = X.copy()
        self.F = F.copy()
        self.R = F.copy()
        self.birth = np.arange(ctx.k, dtype=np.int64)
        self.n_path = ctx.k
        self.nit = 0
        self.active = False
        self.w = self.b = self.q = 0
        self.xc: np.ndarray | None = None
        self.xnew: np.ndarray | None = None
        self.kind = ""
        self.status: int | None = None

    def clone(self) -> "_Machine":
        c = copy.copy(self)
        c.X, c.F, c.R, c.birth = self.X.copy(), self.F.copy(), self.R.copy(), self.birth.copy()
        return c  # xc / xnew are replaced, never modified in place: sharing is safe

    def request(self) -> np.ndarray | None:
        if self.status is not None:
            return None
        if not self.active:
            c = self.ctx
            conv = check_convergence(self.X, self.F, c.span, c.f_tol, c.x_tol)
            if conv is not None:
                self.status = conv
                return None
            if self.n_path >= c.max_evals:
                self.status = STATUS_MAX_EVALS
                return None
            self.nit += 1
            forget(self.R, c.kf)
            self.w = w = worst_index(self.R, self.birth)
            self.b = int(np.argmin(self.R))
            self.xc = (self.X.sum(axis=0) - self.X[w]) / (c.k - 1)
            noise = random_term(c.base, self.nit, -1, c.rfak, c.span, x_spread(self.X, c.span))
            self.xnew = reflect(self.xc, self.X[w], c.alpha, noise, c.lo, c.hi)
            self.kind, self.q, self.active = "reflect", 0, True
        return self.xnew

    def feed(self, f: float) -> tuple[bool, bool]:
        c, w = self.ctx, self.w
        self.X[w] = self.xnew
        self.F[w] = self.R[w] = f
        self.birth[w] = self.n_path
        self.n_path += 1
        if not is_worst(self.R, w):
            self.active = False
            return True, True
        if self.q >= c.max_ret or self.n_path >= c.max_evals:
            self.active = False
            return False, True
        noise = random_term(c.base, self.nit, self.q, c.rfak, c.span, x_spread(self.X, c.span))
        self.xnew = retract(self.xc, self.X[self.b], self.xnew, self.q, c.decay, noise, c.lo, c.hi)
        self.kind = "retract"
        self.q += 1
        return False, False

    def accept_guess(self) -> float | None:
        """A value the pending candidate is accepted with, for forecasting: the
        median of the others (so the best and the next worst stay as they are)."""
        others = np.delete(self.R, self.w)
        fin = others[np.isfinite(others)]
        if fin.size == 0:
            return 0.0
        guess = float(np.median(fin))
        return guess if guess < others.max() else None


def _speculate(root: _Machine, n_slots: int, cache: dict[bytes, int], f_of: Callable[[int], float],
               p_accept: dict[str, float]) -> list[tuple[np.ndarray, str, int]]:
    """The ``n_slots`` most probable future requests of ``root`` not yet evaluated."""
    batch: list[tuple[np.ndarray, str, int]] = []
    in_batch: set[bytes] = set()
    tie = 0
    heap: list[tuple[float, int, _Machine]] = [(-1.0, tie, root.clone())]
    while heap and len(batch) < n_slots:
        neg_p, _, st = heapq.heappop(heap)
        prob = -neg_p
        x = st.xnew
        assert x is not None
        key = x.tobytes()
        if key in cache:  # already evaluated: follow the actual outcome
            child = st.clone()
            child.feed(f_of(cache[key]))
            if child.request() is not None:
                tie += 1
                heapq.heappush(heap, (-prob, tie, child))
            continue
        if key not in in_batch:
            batch.append((x, st.kind, st.nit))
            in_batch.add(key)
        pa = p_accept[st.kind]
        guess = st.accept_guess()
        if guess is not None:
            child = st.clone()
            child.feed(guess)
            if child.request() is not None:
                tie += 1
                heapq.heappush(heap, (-prob * pa, tie, child))
        child = st.clone()
        child.feed(math.inf)
        if child.request() is not None:
            tie += 1
            heapq.heappush(heap, (-prob * (1.0 - pa), tie, child))
    return batch


@dataclass
class _Move:
    """Multi-direction: one Complex-RF iteration on point ``w`` in progress."""

    w: int
    xc: np.ndarray
    iteration: int
    q: int = 0
    fresh: bool = True
    done: bool = False


def _unmoved(k: int, moved: Sequence[int]) -> np.ndarray:
    mask = np.ones(k, dtype=bool)
    mask[list(moved)] = False
    return np.flatnonzero(mask)


def minimize_complex_parallel(
    fun: Callable[..., float],
    bounds: Any,
    x0: Any = None,
    *,
    args: tuple = (),
    n_parallel: int | None = None,
    strategy: str = "speculative",
    executor: Any = None,
    map_fn: MapFn | None = None,
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
    eval_log: str | os.PathLike | None = None,
    replay: Any = None,
) -> ComplexResult:
    """Complex-RF with up to ``n_parallel`` objective evaluations per round.

    Same parameters and result as :func:`identification.optim.complex_rf.minimize_complex`, plus:

    n_parallel : evaluations per round. Default: the executor's worker count if
        it exposes one, else the number of usable CPUs.
    strategy : ``"speculative"`` (default; reproduces the serial run exactly) or
        ``"multidirection"`` (see the module docstring).
    executor : a :class:`concurrent.futures.Executor`; batches go through
        ``executor.map``. With a process pool ``fun`` and ``args`` must be picklable.
    map_fn : instead of ``executor``: ``map_fn(fn, xs)`` returning the results in
        order, e.g. ``dask_map(client)``; it should apply ``fn`` (the wrapped
        objective), but plain objective values are accepted too. With neither, the batch is evaluated in
        this process, one point after the other (same run, no speed-up).

    callback : as in the serial optimiser, after every iteration (speculative) or
        every round (multidirection).
    eval_log : path of an append-only log (JSON lines) of every evaluation, written
        as each batch returns.
    replay : recorded evaluations to reuse instead of calling ``fun`` - an
        ``eval_log`` path (may be the same path), a ComplexResult / ComplexHistory,
        or ``(x, f)`` pairs.  With the same seed and settings the run retraces the
        recorded one exactly, so an interrupted run restarted with
        ``replay=eval_log`` loses no evaluation.  Replayed points have ``round = -1``
        in the history and cost no round.

    ``result.nrounds`` counts the rounds (batches, including the initial complex).
    ``result.nfev`` counts every evaluation, ``result.nfev_used`` those the method
    used (``<= max_evals``); ``history.discarded`` marks mispredicted ones.
    Errors of the executor itself (e.g. a broken process pool) propagate;
    errors of ``fun`` are bad points.
    """
    if executor is not None and map_fn is not None:
        raise ValueError("give either executor or map_fn, not both")
    if strategy not in STRATEGIES:
        raise ValueError(f"strategy = {strategy!r} must be one of {STRATEGIES}")
    lo, hi = parse_bounds(bounds)
    m = lo.size
    x0a = _check_x0(x0, lo, hi)
    k = _check_options(m, n_points, alpha, rfak, gamma, max_evals, f_tol, x_tol,
                       retract_decay, max_retractions)
    max_evals = int(max_evals)
    if n_parallel is None:
        n_parallel = int(getattr(executor, "_max_workers", 0) or _cpu_count())
    p = int(n_parallel)
    if p < 1:
        raise ValueError(f"n_parallel = {n_parallel!r} must be >= 1")

    span = hi - lo
    rng = make_rng(seed)
    ev = _Evaluator(SafeObjective(fun, args), executor, map_fn, _read_replay(replay), eval_log)
    rec = _Recorder(m, max_evals, progress, f"Complex-RFP x{p}")
    try:
        X = initial_complex(rng, k, lo, hi, x0a)
        F = np.empty(k)
        outs, replayed = ev.batch([X[i] for i in range(k)])
        n_real = 0
        for i, (out, rep) in enumerate(zip(outs, replayed)):
            idx = rec.record(X[i], out, "init", 0, -1 if rep else n_real // p)
            n_real += not rep
            rec.accept(idx)
            F[i] = out[0]
        rounds = -(-n_real // p)
        rec.iteration_row(0, max(rounds - 1, 0), F, X, span)
        ctx = _Ctx(lo=lo, hi=hi, span=span, k=k, alpha=alpha, rfak=rfak,
                   kf=forgetting_constant(alpha, gamma, k), f_tol=f_tol, x_tol=x_tol,
                   decay=retract_decay, max_ret=int(max_retractions), max_evals=max_evals,
                   base=run_key(rng))
        run = _run_speculative if strategy == "speculative" else _run_multidirection
        X, F, nit, rounds, status = run(ctx, X, F, rec, ev, p, rounds, callback)
    finally:
        rec.close()
        ev.close()

    return _build_result(rec, X, F, nit, rounds, status, dict(
        method=f"complex-rfp/{strategy}", n_points=k, alpha=alpha, rfak=rfak, gamma=gamma,
        max_evals=max_evals, f_tol=f_tol, x_tol=x_tol, seed=_seed_repr(seed),
        retract_decay=retract_decay, max_retractions=int(max_retractions), n_parallel=p))


def _run_speculative(ctx: _Ctx, X: np.ndarray, F: np.ndarray, rec: _Recorder, ev: _Evaluator,
                     p: int, rounds: int, callback: Callable | None):
    machine = _Machine(ctx, X, F)
    cache: dict[bytes, int] = {}  # evaluated point -> evaluation index
    counts = {"reflect": [1, 2], "retract": [1, 2]}  # accepted, tried (prior 1/2)
    status = STATUS_MAX_EVALS

    def f_of(idx: int) -> float:
        return rec.rows_f[idx]

    while True:
        # consume every evaluated point the method asks for, in its own order
        while True:
            x = machine.request()
            if x is None:
                break
            idx = cache.get(x.tobytes())
            if idx is None:
                out = ev.lookup(x)
                if out is None:
                    break
                idx = cache[x.tobytes()] = rec.record(x, out, machine.kind, machine.nit, -1, discarded=True)
            elif rec.rows_path[idx] >= 0:
                # asked again (a retraction clipped onto the same point): the serial method evaluates it
                # again and counts it, so a new row with the known value, no new simulation
                idx = rec.record(x, (rec.rows_f[idx], rec.rows_bad[idx], None), machine.kind, machine.nit, -1,
                                 discarded=True, repeat=True)
            rec.use(idx)
            kind = machine.kind
            accepted, ended = machine.feed(f_of(idx))
            counts[kind][0] += accepted
            counts[kind][1] += 1
            if accepted:
                rec.accept(idx)
            if ended:
                rec.iteration_row(machine.nit, rounds - 1, machine.F, machine.X, ctx.span)
                if callback is not None and callback(intermediate(rec, machine.nit, machine.F)) is True:
                    return machine.X, machine.F, machine.nit, rounds, STATUS_CALLBACK
        if x is None:
            status = machine.status if machine.status is not None else STATUS_MAX_EVALS
            break
        p_accept = {kd: a / n for kd, (a, n) in counts.items()}
        batch = _speculate(machine, p, cache, f_of, p_accept)
        outs, replayed = ev.batch([b[0] for b in batch])
        for (xb, kind, it), out, rep in zip(batch, outs, replayed):
            cache[xb.tobytes()] = rec.record(xb, out, kind, it, -1 if rep else rounds, discarded=True)
        rounds += not all(replayed)
    return machine.X, machine.F, machine.nit, rounds, status


def _run_multidirection(ctx: _Ctx, X: np.ndarray, F: np.ndarray, rec: _Recorder, ev: _Evaluator,
                        p: int, rounds: int, callback: Callable | None):
    k, span = ctx.k, ctx.span
    d = max(1, min(p, k // 2))
    R = F.copy()
    birth = np.arange(k, dtype=np.int64)
    nit = started = 0
    moves: list[_Move] = []
    status = STATUS_MAX_EVALS
    while True:
        n_new = d - len(moves)
        if n_new > 0:
            conv = check_convergence(X, F, span, ctx.f_tol, ctx.x_tol)
            if conv is not None:
                status = conv
                break
        budget = ctx.max_evals - rec.nfev
        if budget <= 0:
            break
        for _ in range(n_new):
            forget(R, ctx.kf)
            w = worst_index(R, birth, exclude=[mv.w for mv in moves])
            xc = X[_unmoved(k, [mv.w for mv in moves] + [w])].mean(axis=0)
            started += 1
            moves.append(_Move(w=w, xc=xc, iteration=started))
        b = int(np.argmin(R))
        plan: list[tuple[_Move, np.ndarray, str]] = []
        for mv in moves[:budget]:
            if mv.fresh:
                noise = random_term(ctx.base, mv.iteration, -1, ctx.rfak, span, x_spread(X, span))
                x = reflect(mv.xc, X[mv.w], ctx.alpha, noise, ctx.lo, ctx.hi)
                plan.append((mv, x, "reflect"))
            else:
                noise = random_term(ctx.base, mv.iteration, mv.q, ctx.rfak, span, x_spread(X, span))
                x = retract(mv.xc, X[b], X[mv.w], mv.q, ctx.decay, noise, ctx.lo, ctx.hi)
                plan.append((mv, x, "retract"))
        outs, replayed = ev.batch([pl[1] for pl in plan])
        for (mv, x, kind), out, rep in zip(plan, outs, replayed):
            idx = rec.record(x, out, kind, mv.iteration, -1 if rep else rounds)
            w = mv.w
            X[w] = x
            F[w] = R[w] = out[0]
            birth[w] = idx
            if kind == "retract":
                mv.q += 1
            mv.fresh = False
            # accepted when better than the worst unmoved point (serial: than the
            # worst of the others), so a move never trades a good point for a
            # candidate that only beats other moves' pending candidates
            if R[w] < R[_unmoved(k, [o.w for o in moves if not o.done])].max():
                rec.accept(idx)
                mv.done = True
            elif mv.q >= ctx.max_ret:
                mv.done = True  # left in the complex, as in the serial method
        done = sum(mv.done for mv in moves)
        nit += done
        moves = [mv for mv in moves if not mv.done]
        rec.iteration_row(nit, rounds, F, X, span)
        rounds += not all(replayed)
        if callback is not None and callback(intermediate(rec, nit, F)) is True:
            status = STATUS_CALLBACK
            break
    return X, F, nit, rounds, status
