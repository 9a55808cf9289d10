"""How a held-out gain reads in the reports (identification.loop.holdout.HoldOut.text)."""
from __future__ import annotations

import math

import pytest

from identification.loop.holdout import HoldOut


@pytest.mark.parametrize("E_base, E_ext, text", [
    (100.0, 41.1, "+58.9%"),
    (100.0, 142.0, "-42.0%"),
    (100.0, 200.0, "-100.0%"),                      # twice the base's: still a share
    (1.0, 4201.0, "4.2e+03 x the base's error"),    # a blown-up extension: not -420000%
    (1.0, math.inf, "extension failed"),
])
def test_a_gain_reads_as_a_share_or_as_times_the_base(E_base, E_ext, text):
    assert HoldOut(E_base, E_ext, 16, 1).text() == text
