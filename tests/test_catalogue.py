"""The catalogue's hypotheses (identification.loop.catalogue), without the FMU."""
from __future__ import annotations

import numpy as np

from identification.loop.catalogue import CATALOGUE, Context


def _ctx(starts) -> Context:
    return Context("layout7", 65.0, np.asarray(starts, float), (0.0, 2.0), 52, 2.0)


def test_a_bump_is_probed_at_every_joint_and_every_length():
    """The chain's answer to a bump is not linear in its length (a 0.2 m probe
    scored a 2 mm, 0.13 m bump's joint at 0.03 % of f): each joint is probed
    at each of the lengths, and the extension starts from the probe's."""
    bump = CATALOGUE["track_bump"]
    hyps = bump.hypotheses(_ctx([0.0, 4.0, 13.47]))
    lengths = sorted({h.probes[0].params["effects.track_bump.length"] for h in hyps})
    assert len(hyps) == 3 * len(bump.LENGTHS) and lengths == sorted(bump.LENGTHS)
    assert min(lengths) <= 0.1 and max(lengths) >= 0.3        # the drawn range of a sorter's joints
    for h in hyps:
        ln = h.probes[0].params["effects.track_bump.length"]
        assert f"{100 * ln:.0f} cm" in h.label and h.fixed["effects.track_bump.s"] in (0.0, 4.0, 13.47)
        ext = bump.extension(h, np.array([0.0015]))
        assert ext.x0["effects.track_bump.length"] == ln and ext.x0["effects.track_bump.height"] == 0.0015
        lo, hi = ext.free["effects.track_bump.length"]
        assert lo < ln < hi


def test_a_joint_play_is_probed_on_a_ladder_of_gaps():
    """A 1 um play moved a steady record's misfit from 126 to 0.3 per sample,
    a 2 um one to 133: the answer to the gap is a valley about 20 % wide, which
    one 0.2 mm probe never ranked. The rungs cover 0.3 um to 2 mm without a
    hole, each extension stays on its own rung (one valley) and inside the
    FMU's range (5 mm)."""
    clr = CATALOGUE["joint_clearance"]
    hyps = clr.hypotheses(_ctx([0.0, 4.0]))
    gaps = [h.probes[0].params["effects.joint_clearance.gap"] for h in hyps]
    assert gaps == sorted(gaps) and gaps[0] <= 3e-7 and gaps[-1] >= 2e-3
    assert max(b / a for a, b in zip(gaps, gaps[1:])) <= clr.RATIO * (1 + 1e-9)
    for h, g in zip(hyps, gaps):
        assert h.probes[0].scale == g and f"{1e6 * g:.3g} um" in h.label
        ext = clr.extension(h, np.array([10.0]))              # a wild linear estimate is held on the rung
        lo, hi = ext.free["effects.joint_clearance.gap"]
        assert 0 < lo < g < hi <= 5e-3 and lo <= ext.x0["effects.joint_clearance.gap"] <= hi
    # neighbouring rungs' extensions meet: every gap in the range is some rung's
    spans = [clr.extension(h, np.array([g])).free["effects.joint_clearance.gap"] for h, g in zip(hyps, gaps)]
    assert all(a[1] >= b[0] for a, b in zip(spans, spans[1:]))
