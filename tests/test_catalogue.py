"""The catalogue's hypotheses (identification.catalogue), without the FMU."""
from __future__ import annotations

import numpy as np

from identification.catalogue import CATALOGUE, Context


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
