"""identify(restarts=...): a converged complex is restarted in a smaller box
around the best point until the budget is used (identification/identify.py).

On a stand-in problem with a known optimum, no FMU needed: the 4-variable
Rosenbrock valley, where the published Complex-RF converges early on the
valley floor (docs/optimizer_benchmark.md: 7 % of runs find the optimum).
"""
from __future__ import annotations

import numpy as np
import pytest

from identification.pipeline.identify import identify


class Valley:
    """Duck-typed IdentificationProblem: Rosenbrock-4 on [-2, 2]^4, optimum at 1."""
    name, model, layout = "valley", "LW", "none"
    free = ("a", "b", "c", "d")
    bounds = {k: (-2.0, 2.0) for k in free}
    bounds_array = [(-2.0, 2.0)] * 4

    def __init__(self):
        self.calls = 0

    def x0_vector(self):
        return np.full(4, -1.0)

    def __call__(self, x):
        self.calls += 1
        x = np.asarray(x, float)
        return float(np.sum(100 * (x[1:] - x[:-1] ** 2) ** 2 + (1 - x[:-1]) ** 2))

    def channel_errors(self, x):
        return np.full(7, np.sqrt(self(x) / 7))


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_restarts_reach_what_the_published_method_stops_short_of(seed):
    """Measured (seeds 0-5, 5000 evaluations): the published method stops after
    492-2174 evaluations at f 1.8e-3 to 3.7 (seed 3 far off, x - 1 up to 1.76);
    with restarts every run ends at f 1.6e-4 to 9.4e-4, x within 0.053 of 1."""
    plain = identify(Valley(), max_evals=5000, seed=seed, progress=False)
    again = identify(Valley(), max_evals=5000, seed=seed, progress=False, restarts=50)
    assert plain.restarts == 0 and again.restarts >= 1
    assert again.nfev <= 5000 and len(again.history_f) == again.nfev
    assert again.f < 0.2 * plain.f
    assert again.f < 1e-3 and np.max(np.abs(again.x - 1)) < 0.06, (again.f, again.x, plain.f)
    it = again.iterations
    assert np.all(np.diff(it["nfev"]) >= 0) and np.all(np.diff(it["iteration"]) > 0)
    assert it["nfev"][-1] <= again.nfev


def test_restarted_run_resumes_from_its_journal(tmp_path):
    journal = tmp_path / "j.jsonl"
    full = identify(Valley(), max_evals=600, seed=4, progress=False, restarts=5, journal=journal)
    lines = journal.read_text().splitlines()
    journal.write_text("\n".join(lines[: len(lines) // 2]) + "\n")
    p = Valley()
    again = identify(p, max_evals=600, seed=4, progress=False, restarts=5, journal=journal)
    assert np.array_equal(again.x, full.x) and again.f == full.f and again.restarts == full.restarts
    assert again.replayed >= len(lines) // 2


def test_negative_restarts_are_refused():
    with pytest.raises(ValueError, match="restarts = -1"):
        identify(Valley(), max_evals=100, restarts=-1, progress=False)
