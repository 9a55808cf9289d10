"""Two candidates that both pass (identification.loop.rivals), without the FMU."""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from identification.loop.rivals import DECISIVE, compare, passing

N_BASE = 4   # the base's free variables
N = 2100     # residual values: 300 samples x 7 channels


def _t(effect, S, added, scale=1.0, supported=True, adequate=True, at_noise=True, share=None):
    prob = SimpleNamespace(free=tuple(f"v{i}" for i in range(N_BASE + added)), samples=np.zeros((300, 7)))
    return SimpleNamespace(effect=effect, label=effect, S=S, problem=prob, lr=SimpleNamespace(scale=scale),
                           supported=supported, adequate=adequate, excess=SimpleNamespace(any=not at_noise),
                           misfit_share=share)


def test_the_clearly_better_model_wins_either_way_round():
    clr, bump = _t("joint_clearance", 840.0, 1), _t("track_bump", 4700.0, 2)
    for a, b in ((clr, bump), (bump, clr)):
        rv = compare(a, b, N_BASE)
        assert rv.winner is clr
        assert "preferred to track_bump" in rv.text()
    rv = compare(clr, bump, N_BASE)
    assert math.isclose(rv.dbic, (4700.0 - 840.0) + math.log(N))   # the bump's extra parameter charged


def test_a_difference_within_the_noise_leaves_it_undecided():
    # the better fit by less than its extra parameter's charge plus DECISIVE: nobody wins
    a, b = _t("wheel_oor", 2000.0, 3), _t("motor_ripple", 2000.0 + 2 * math.log(N) + DECISIVE - 1.0, 1)
    rv = compare(a, b, N_BASE)
    assert rv.preferred is None and rv.winner is None and rv.loser is None and "cannot tell them apart" in rv.text()


def test_a_correlated_residual_weighs_the_difference_less():
    a, b = _t("mass", 1000.0, 1), _t("track_bump", 1000.0 + 5 * DECISIVE, 1)
    assert compare(a, b, N_BASE).winner is a
    assert compare(a, _t("track_bump", 1000.0 + 5 * DECISIVE, 1, scale=10.0), N_BASE).preferred is None


def test_only_candidates_that_pass_and_reach_the_noise_compete():
    ts = [_t("a", 1, 1, supported=False), _t("b", 1, 1, adequate=False), _t("c", 1, 1), _t("d", 1, 1)]
    assert [t.effect for t in passing(ts)] == ["c", "d"]


def test_the_better_of_two_models_above_the_noise_is_not_a_winner():
    """A 1 um play, its extension stopped above the noise, against a bump that
    fitted better but stayed above it too: the bump is preferred, but not a
    winner (close_loop holds it provisional)."""
    clr = _t("joint_clearance", 6700.0, 1, at_noise=False, share=0.747)
    bump = _t("track_bump", 4760.0, 2, at_noise=False, share=0.853)
    rv = compare(clr, bump, N_BASE)
    assert rv.dbic < -DECISIVE and rv.preferred is bump and rv.loser is clr
    assert rv.winner is None and "stays above the noise" in rv.text() and "provisional" in rv.text()


def test_a_model_above_the_noise_wins_when_it_leaves_far_less_than_its_rival():
    """A transducer cart 12 % heavier: the mass removes 98 % of the base's
    misfit above the noise but leaves one channel at 9.5 times it; a play
    that passes too leaves far more. The mass wins; with a rival that leaves
    barely more, it does not."""
    mass = _t("mass", 3000.0, 1, at_noise=False, share=0.98)
    assert compare(mass, _t("joint_clearance", 9000.0, 1, at_noise=False, share=0.6), N_BASE).winner is mass
    close = _t("joint_clearance", 3000.0 + 5 * DECISIVE, 1, at_noise=False, share=0.95)
    rv = compare(mass, close, N_BASE)
    assert rv.preferred is mass and rv.winner is None
