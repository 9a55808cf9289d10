"""A journal answers for the objective that wrote it only (identification.optim.journal).

Resumed into an objective that has changed since (here: another bowl; on a
record, the logger's filter run at another rate, as when it left the
communication grid), its values would steer the optimiser through a landscape that is
not there. The journal's best point is evaluated again first: a journal that
disagrees is set aside (`.stale`, its refinement with it) and the run is the
fresh run; one that agrees is replayed as before.
"""
from __future__ import annotations

import dataclasses
import json
import logging

import numpy as np
import pytest

from identification.pipeline.identify import Journal, identify
from identification.objective.problem import DESIGN, IdentificationProblem, from_measurement

CORS = DESIGN[:4]


@dataclasses.dataclass
class Bowl(IdentificationProblem):
    """A quadratic bowl in the four CoRs around `centre`: no FMU."""
    centre: tuple = (0.46, 0.558, 0.351, 0.645)

    def __call__(self, x) -> float:
        return float(np.sum((np.asarray(x, float) - np.asarray(self.centre)) ** 2))

    def channel_errors(self, x) -> np.ndarray:
        return np.full(7, np.sqrt(self(x) / 7))


def bowl(centre=(0.46, 0.558, 0.351, 0.645)) -> Bowl:
    t = np.arange(10) / 300.0
    return Bowl(np.zeros((len(t), 7)), t, "layout7", "LW", {k: (0.2, 0.9) for k in CORS}, free=CORS,
                x0={k: 0.55 for k in CORS}, name="bowl", centre=centre)


def run(problem, journal, **kw):
    return identify(problem, max_evals=120, seed=3, progress=False, journal=journal, refine_evals=12, **kw)


def test_a_journal_of_another_objective_is_set_aside(tmp_path, caplog):
    journal = tmp_path / "m01.jsonl"
    first = run(bowl(), journal)
    lines = journal.read_text()
    assert (tmp_path / "m01.local.json").exists()
    moved = bowl(centre=(0.30, 0.70, 0.40, 0.50))
    fresh = run(moved, None)
    with caplog.at_level(logging.WARNING, logger="identification.optim.journal"):
        again = run(moved, journal)
    # the stale journal answered nothing: the run is the fresh run, point for point
    assert again.replayed == 0 and again.evaluated == fresh.evaluated
    np.testing.assert_array_equal(again.x, fresh.x)
    np.testing.assert_array_equal(again.history_f, fresh.history_f)
    assert np.allclose(again.x, moved.centre, atol=0.02) and not np.allclose(again.x, first.x, atol=0.02)
    # nothing lost: the old journal and its refinement kept aside, named in the warning
    assert (tmp_path / "m01.stale.jsonl").read_text() == lines
    assert (tmp_path / "m01.stale.local.json").exists()
    assert any("m01.stale.jsonl" in r.getMessage() and "starts afresh" in r.getMessage() for r in caplog.records)
    # the new journal is the new objective's: a resume replays it whole, nothing set aside
    third = run(moved, journal)
    assert third.evaluated == 0 and third.replayed > 0
    np.testing.assert_array_equal(third.x, fresh.x)
    assert not (tmp_path / "m01.stale2.jsonl").exists()
    # and a second change is set aside beside the first, not over it
    run(bowl(), journal)
    assert (tmp_path / "m01.stale2.jsonl").exists() and (tmp_path / "m01.stale.jsonl").read_text() == lines


def test_a_journal_of_another_dimension_is_set_aside(tmp_path):
    journal = tmp_path / "j.jsonl"
    jr = Journal(journal)
    jr.put(np.array([0.5, 0.5, 0.5]), 0.1)   # three variables: another problem's
    jr.close()
    jr = Journal(journal)
    assert not jr.vouch(bowl(), 4)
    assert jr.cache == {} and (tmp_path / "j.stale.jsonl").exists()
    jr.close()


def test_a_journal_of_failed_points_only_is_kept(tmp_path):
    """Nothing to evaluate again: kept (its points fail again, as they did)."""
    journal = tmp_path / "j.jsonl"
    jr = Journal(journal)
    jr.put(np.array([0.5, 0.5, 0.5, 0.5]), 1e9)
    jr.close()
    jr = Journal(journal)
    assert jr.vouch(bowl(), 4, bad=1e9) and len(jr.cache) == 1
    jr.close()


@pytest.fixture(scope="module")
def record(rig_record):
    return rig_record(1, "start-stop", 1.2)


def test_a_journal_of_the_filter_on_the_grid_is_not_replayed(record, tmp_path):
    """A journal written while the logger's filter still ran on the
    communication grid (as three-record runs once did): resumed into today's
    objective, it would have been replayed as it stood."""
    p = from_measurement(record, "LW", window=0.3, tare=True, objective="likelihood")
    assert p.filter_rate is not None
    grid = dataclasses.replace(p, filter_rate=None)
    x = p.x0_vector()
    journal = tmp_path / "j.jsonl"
    jr = Journal(journal)
    jr.put(x, grid(x))
    jr.close()
    assert Journal(journal).vouch(grid, grid.dim)             # its own objective: kept
    jr = Journal(journal)
    assert not jr.vouch(p, p.dim)                             # today's: set aside
    jr.close()
    stale = [json.loads(ln) for ln in (tmp_path / "j.stale.jsonl").read_text().splitlines()]
    assert len(stale) == 1 and stale[0]["f"] != pytest.approx(p(x), rel=1e-6)
