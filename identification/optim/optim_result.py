"""Result and history containers of the Complex-RF optimisers.

Both :func:`identification.optim.complex_rf.minimize_complex` (serial reference) and
:func:`identification.optim.complex_rfp.minimize_complex_parallel` return a
:class:`ComplexResult`.  Everything in it is plain numpy / Python data, and
:meth:`ComplexResult.to_dict` gives a JSON-ready dictionary (non-finite floats
become ``None``) that :meth:`ComplexResult.from_dict` reads back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = [
    "ComplexHistory",
    "ComplexResult",
    "STATUS_FUNCTION_SPREAD",
    "STATUS_PARAMETER_SPREAD",
    "STATUS_MAX_EVALS",
    "STATUS_CALLBACK",
    "MESSAGES",
]

#: exit status codes (``ComplexResult.status``) and their messages
STATUS_FUNCTION_SPREAD = 0
STATUS_PARAMETER_SPREAD = 1
STATUS_MAX_EVALS = 2
STATUS_CALLBACK = 3
MESSAGES = {
    STATUS_FUNCTION_SPREAD: "function spread",
    STATUS_PARAMETER_SPREAD: "parameter spread",
    STATUS_MAX_EVALS: "max evaluations",
    STATUS_CALLBACK: "callback",
}

# Columns of the two history tables.
EVAL_COLUMNS = ("eval_index", "x", "f", "accepted", "bad", "kind", "iteration", "round", "path_index")
ITER_COLUMNS = ("iteration", "round", "nfev", "best_f", "worst_f", "f_spread", "x_spread")


def jsonable(value: Any) -> Any:
    """Convert numpy containers / scalars to JSON types; non-finite floats -> None."""
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return v if math.isfinite(v) else None
    return value


def _float_array(values: Any) -> np.ndarray:
    """Inverse of :func:`_jsonable` for float data: ``None`` -> +inf."""
    arr = np.asarray(
        [np.inf if v is None else v for v in values] if isinstance(values, list) else values,
        dtype=float,
    )
    return arr


@dataclass
class ComplexHistory:
    """Everything the optimiser evaluated, and the state of the complex over time.

    Per evaluation (arrays of length ``nfev``, in evaluation order):

    ``eval_index``  0, 1, ... (the evaluation counter)
    ``x``           the evaluated point, shape ``(nfev, m)``
    ``f``           the objective value returned (``inf`` for a bad evaluation)
    ``accepted``    the point entered the complex and was not its worst member
                    (initial points are accepted; a reflection or retraction is
                    accepted when it ended its iteration successfully)
    ``bad``         the objective raised, or returned a non-finite value
    ``kind``        ``'init'``, ``'reflect'`` or ``'retract'``
    ``iteration``   the complex iteration the point belongs to (0 = initial complex)
    ``round``       the wall-clock round (sequential batch of evaluations) it was
                    evaluated in; equals ``eval_index`` for the serial optimiser
    ``path_index``  position of the point in the sequence of evaluations the
                    method used (serial: ``eval_index``); -1 for a point the
                    parallel optimiser evaluated speculatively and never used
                    (``discarded``; its ``kind`` and ``iteration`` are the ones it
                    would have had).  ``x[order]`` with ``order = used_order()``
                    is the run as the serial optimiser sees it.

    Per iteration (arrays of length ``nit + 1`` for the serial optimiser, one row
    per round for the parallel one; row 0 is the initial complex):

    ``iteration``, ``round``, ``nfev`` (evaluations so far), ``best_f`` and
    ``worst_f`` (true objective values over the complex), ``f_spread``
    (max - min of f over the complex) and ``x_spread`` (largest range of a
    coordinate over the complex, relative to its bound range).

    ``errors`` lists ``(eval_index, message)`` for evaluations that raised.
    """

    eval_index: np.ndarray
    x: np.ndarray
    f: np.ndarray
    accepted: np.ndarray
    bad: np.ndarray
    kind: list[str]
    iteration: np.ndarray
    round: np.ndarray
    iterations: dict[str, np.ndarray]
    path_index: np.ndarray | None = None
    errors: list[tuple[int, str]] = field(default_factory=list)

    def __post_init__(self) -> None:
        if self.path_index is None:
            self.path_index = np.arange(len(self.f))

    @property
    def discarded(self) -> np.ndarray:
        """Mask of speculative evaluations the method never used."""
        return np.asarray(self.path_index) < 0

    def used_order(self) -> np.ndarray:
        """Evaluation indices of the used points, in the order the method used them."""
        pi = np.asarray(self.path_index)
        used = np.flatnonzero(pi >= 0)
        return used[np.argsort(pi[used], kind="stable")]

    def to_dict(self) -> dict[str, Any]:
        return {
            "evaluations": {
                "eval_index": jsonable(self.eval_index),
                "x": jsonable(self.x),
                "f": jsonable(self.f),
                "accepted": jsonable(self.accepted),
                "bad": jsonable(self.bad),
                "kind": list(self.kind),
                "iteration": jsonable(self.iteration),
                "round": jsonable(self.round),
                "path_index": jsonable(self.path_index),
            },
            "iterations": {k: jsonable(v) for k, v in self.iterations.items()},
            "errors": [[int(i), str(msg)] for i, msg in self.errors],
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "ComplexHistory":
        ev = d["evaluations"]
        its = d["iterations"]
        x = np.asarray(ev["x"], dtype=float)
        return cls(
            eval_index=np.asarray(ev["eval_index"], dtype=int),
            x=x.reshape(len(ev["eval_index"]), -1) if x.size else x.reshape(0, 0),
            f=_float_array(ev["f"]),
            accepted=np.asarray(ev["accepted"], dtype=bool),
            bad=np.asarray(ev["bad"], dtype=bool),
            kind=list(ev["kind"]),
            iteration=np.asarray(ev["iteration"], dtype=int),
            round=np.asarray(ev["round"], dtype=int),
            path_index=np.asarray(ev["path_index"], dtype=int) if "path_index" in ev else None,
            iterations={
                k: (np.asarray(v, dtype=int) if k in ("iteration", "round", "nfev") else _float_array(v))
                for k, v in its.items()
            },
            errors=[(int(i), str(m)) for i, m in d.get("errors", [])],
        )


@dataclass
class ComplexResult:
    """Outcome of a Complex-RF run (scipy-``OptimizeResult``-like attributes).

    ``x``, ``fun``      best point ever evaluated and its objective value
    ``nfev``            number of objective evaluations (for the parallel optimiser
                        including discarded speculative ones; ``max_evals`` limits
                        the evaluations the method uses, ``nfev_used``)
    ``nit``             complex iterations (a reflection plus its retractions);
                        for the parallel optimiser: completed iterations
    ``nrounds``         wall-clock rounds, i.e. sequential batches of evaluations
                        (serial: ``nfev``; parallel: batches incl. the initial complex)
    ``success``         stopped on function or parameter spread with a finite best value
    ``status``          0 function spread, 1 parameter spread, 2 max evaluations, 3 callback
    ``message``         ``'function spread'``, ``'parameter spread'``,
                        ``'max evaluations'`` or ``'callback'``
    ``n_bad``           evaluations that raised or returned a non-finite value
    ``complex_x``, ``complex_f``  the final complex (points and true objective values)
    ``history``         :class:`ComplexHistory`
    ``options``         the settings used (for reproducibility records)
    """

    x: np.ndarray
    fun: float
    nfev: int
    nfev_used: int
    nit: int
    nrounds: int
    success: bool
    status: int
    message: str
    n_bad: int
    complex_x: np.ndarray
    complex_f: np.ndarray
    history: ComplexHistory
    options: dict[str, Any] = field(default_factory=dict)

    def __repr__(self) -> str:  # short, like scipy's OptimizeResult
        return (
            f"ComplexResult(message={self.message!r}, success={self.success}, "
            f"fun={self.fun:.6g}, x={np.array2string(np.asarray(self.x), precision=6)}, "
            f"nfev={self.nfev}, nfev_used={self.nfev_used}, nit={self.nit}, nrounds={self.nrounds}, "
            f"n_bad={self.n_bad})"
        )

    def to_dict(self, include_history: bool = True) -> dict[str, Any]:
        """JSON-ready dictionary (``json.dumps(result.to_dict())`` works)."""
        d: dict[str, Any] = {
            "x": jsonable(self.x),
            "fun": jsonable(self.fun),
            "nfev": int(self.nfev),
            "nfev_used": int(self.nfev_used),
            "nit": int(self.nit),
            "nrounds": int(self.nrounds),
            "success": bool(self.success),
            "status": int(self.status),
            "message": str(self.message),
            "n_bad": int(self.n_bad),
            "complex_x": jsonable(self.complex_x),
            "complex_f": jsonable(self.complex_f),
            "options": jsonable(self.options),
        }
        if include_history:
            d["history"] = self.history.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "ComplexResult":
        """Rebuild a result written by :meth:`to_dict` (with its history)."""
        hist = d.get("history")
        return cls(
            x=np.asarray(d["x"], dtype=float),
            fun=float("inf") if d["fun"] is None else float(d["fun"]),
            nfev=int(d["nfev"]),
            nfev_used=int(d.get("nfev_used", d["nfev"])),
            nit=int(d["nit"]),
            nrounds=int(d["nrounds"]),
            success=bool(d["success"]),
            status=int(d["status"]),
            message=str(d["message"]),
            n_bad=int(d["n_bad"]),
            complex_x=np.asarray(d["complex_x"], dtype=float),
            complex_f=_float_array(d["complex_f"]),
            history=ComplexHistory.from_dict(hist) if hist is not None else None,  # type: ignore[arg-type]
            options=dict(d.get("options", {})),
        )
