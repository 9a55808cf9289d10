"""A CoR found near its box edge, refined again from the edge
(identification.pipeline.edge_probe), on a stand-in problem: a valley at the edge and
a shallower one further in, the refinement a stand-in that goes down the
valley it starts in."""
from __future__ import annotations

import numpy as np
import pytest

from identification.pipeline import edge_probe
from identification.objective.uncertainty import Interval

FREE = ("contact.e_JA", "contact.e_JR", "contact.e_SW", "contact.e_RW", "drive.Kp")
BOUNDS = [(0.2, 0.9)] * 4 + [(125.0, 2000.0)]


class _TwoValleys:
    """f = the distance to the nearer of two valleys of e_RW (deep at 0.203,
    shallow at 0.241), the other variables at their valley floors."""
    free, bounds_array, name = FREE, BOUNDS, "stand-in"

    def __call__(self, x):
        e = float(x[3])
        return min(20.918 + 50 * (e - 0.203) ** 2, 20.9275 + 50 * (e - 0.241) ** 2)


def _descend(problem, x, f, refine_evals, uncertainty, journal):
    """identify.local_stage's stand-in: to the floor of the valley x starts in; intervals if asked."""
    x = np.array(x, float)
    x[3] = 0.203 if abs(x[3] - 0.203) < abs(x[3] - 0.241) else 0.241
    out = {"refined": {"f_start": f, "f": problem(x), "nfev": 7, "iterations": 2}}
    if problem(x) < f:
        out.update(x=x.tolist(), f=problem(x))
    if uncertainty:
        out["intervals"] = [Interval(n, float(v), 0.004, v - 0.008, v + 0.008, True) for n, v in zip(FREE, x)]
    return out


def _ivs(x, identifiable=(True, False, True, True, True)):
    return [Interval(n, float(v), 0.008, v - 0.016, v + 0.016, ok) for n, v, ok in zip(FREE, x, identifiable)]


@pytest.fixture
def stand_in(monkeypatch):
    monkeypatch.setattr(edge_probe, "local_stage", _descend)
    return _TwoValleys()


def test_a_cor_near_its_edge_is_refined_from_the_edge_and_kept_where_lower(stand_in):
    x = np.array([0.35, 0.2, 0.32, 0.241, 500.0])
    xe, fe, ivs, probes = edge_probe.edge_probes(stand_in, x, stand_in(x), _ivs(x), 400, None)
    assert [p["name"] for p in probes] == ["contact.e_RW"]      # e_JR lies on its edge, not identifiable
    assert probes[0]["edge"] == 0.2 and probes[0]["kept"] and probes[0]["nfev"] == 8
    assert xe[3] == pytest.approx(0.203) and fe == pytest.approx(20.918)
    assert ivs[3].value == pytest.approx(0.203)                 # the intervals again, at the point kept
    assert np.array_equal(np.delete(xe, 3), np.delete(x, 3))


def test_a_probe_that_ends_higher_leaves_the_result_alone(stand_in):
    x = np.array([0.35, 0.5, 0.32, 0.203, 500.0])             # already in the deeper valley
    ivs = _ivs(x)
    xe, fe, out_ivs, probes = edge_probe.edge_probes(stand_in, x, stand_in(x), ivs, 400, None)
    assert len(probes) == 1 and not probes[0]["kept"]
    assert np.array_equal(xe, x) and fe == stand_in(x) and out_ivs is ivs


@pytest.mark.parametrize("e_rw, identifiable, probed", [
    (0.241, True, True),      # 0.041 from the edge: within 7.5 % of the range
    (0.26, True, False),      # 0.06: beyond
    (0.2, True, False),       # on the edge already
    (0.241, False, False),    # not identifiable: its profile is flat, the edge says nothing
    (0.87, True, True),       # the upper edge
])
def test_which_cors_are_probed(e_rw, identifiable, probed):
    x = np.array([0.5, 0.5, 0.5, e_rw, 130.0])                 # K_P near its edge: not a CoR, never probed
    near = edge_probe.near_edges(_TwoValleys(), x, _ivs(x, (True, True, True, identifiable, True)))
    assert [n for n, _, _ in near] == (["contact.e_RW"] if probed else [])


def test_no_intervals_or_no_budget_no_probe(stand_in):
    x = np.array([0.35, 0.5, 0.32, 0.241, 500.0])
    assert edge_probe.edge_probes(stand_in, x, 1.0, None, 400, None)[3] == []
    assert edge_probe.edge_probes(stand_in, x, 1.0, _ivs(x), 0, None)[3] == []
