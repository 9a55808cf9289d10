"""The profile of a stored recovery result (benchmarks/profile_cor.py): the
likelihood ratio's crossings of chi^2(1) and the ratio itself."""
from __future__ import annotations

import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))

from profile_cor import CHI2_95, crossing, interval_of, main, ratio_stat  # noqa: E402


def test_a_parabola_crosses_where_the_normal_interval_ends():
    sd, est = 0.05, 0.5
    g = np.linspace(0.2, 0.9, 141)
    L = ((g - est) / sd) ** 2
    k0 = int(np.argmin(L))
    assert crossing(g, L, k0, -1) == pytest.approx(est - np.sqrt(CHI2_95) * sd, abs=2e-4)
    assert crossing(g, L, k0, +1) == pytest.approx(est + np.sqrt(CHI2_95) * sd, abs=2e-4)


def test_a_flat_side_runs_to_the_box_edge():
    g = np.linspace(0.2, 0.9, 8)
    L = np.array([0.5, 0.3, 0.2, 0.0, 1.0, 5.0, 9.0, 20.0])
    assert crossing(g, L, 3, -1) == 0.2
    assert 0.6 < crossing(g, L, 3, +1) < 0.7


def test_the_interval_is_measured_from_the_profiles_own_minimum():
    # the estimate (L = 0) stopped short of the bottom, which lies 19 lower at 0.6
    sd = 0.1
    g = np.linspace(0.2, 0.9, 71)
    L = ((g - 0.6) / sd) ** 2 - 19.0
    lower, upper = interval_of(g, L)
    assert lower == pytest.approx(0.6 - np.sqrt(CHI2_95) * sd, abs=1e-3)
    assert upper == pytest.approx(0.6 + np.sqrt(CHI2_95) * sd, abs=1e-3)


def test_the_ratio_is_the_weighted_change_of_the_squared_residual():
    samples = np.zeros((4, 2))
    problem = SimpleNamespace(samples=samples, tare=None)
    r0sq = np.zeros(2)
    sim = np.array([[1.0, 0.0], [1.0, 0.0], [0.0, 2.0], [0.0, 0.0]])
    assert ratio_stat(problem, sim, np.array([0.5, 0.25]), r0sq) == pytest.approx(0.5 * 2 + 0.25 * 4)


def test_an_unknown_variable_is_refused_by_name(tmp_path, capsys):
    src = tmp_path / "m01.json"
    src.write_text('{"free": ["contact.e_JA"], "measurement": "m01"}')
    with pytest.raises(SystemExit):
        main([str(src), "--variable", "e_XY"])
    assert "e_XY" in capsys.readouterr().err
