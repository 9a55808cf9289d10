"""The paired tests of a campaign (identification.pipeline.stats): every
measurement identified under every model is a block, so a model that fits
better on each measurement is found even when the measurements differ far
more among themselves than the models do; under the null the tests keep
their level; Holm's adjustment matches its definition."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from identification.pipeline.stats import holm, model_tests, paired_tests

MODELS = ("HC", "HW", "LN", "LW")


def campaign(rng, n: int, factors: dict, spread: float = 1.5, noise: float = 0.1) -> pd.DataFrame:
    """f = (a measurement's own level, log-normal with `spread`) x the model's factor x noise."""
    level = np.exp(rng.normal(0.0, spread, n))
    rows = [{"measurement": f"m{k:02d}", "model": m, "f": level[k] * factors[m] * np.exp(rng.normal(0.0, noise))}
            for k in range(n) for m in factors]
    return pd.DataFrame(rows)


def test_a_model_better_on_every_measurement_is_found_where_the_unpaired_tests_miss_it():
    rng = np.random.default_rng(1)
    df = campaign(rng, 12, {"HC": 1.0, "HW": 0.7, "LN": 1.0, "LW": 1.0})
    paired = paired_tests(df)
    assert paired["n"] == 12 and paired["left_out"] == []
    assert paired["best"]["HW"] >= 10
    assert paired["friedman_p"] < 1e-3
    hw = {(q["a"], q["b"]): q for q in paired["pairs"] if "HW" in (q["a"], q["b"])}
    assert all(q["p_holm"] < 0.05 for q in hw.values())
    assert hw[("HC", "HW")]["median_ratio"] == pytest.approx(1 / 0.7, rel=0.15)
    # the between-measurement spread hides it from the tests that treat the results as independent
    assert model_tests(df)["kruskal_p"] > 0.05


@pytest.mark.parametrize("n", [6, 15])
def test_the_paired_tests_keep_their_level_under_the_null(n):
    rng = np.random.default_rng(n)
    runs = 300
    friedman = pairs_any = 0
    for _ in range(runs):
        paired = paired_tests(campaign(rng, n, dict.fromkeys(MODELS, 1.0)))
        friedman += paired["friedman_p"] < 0.05
        pairs_any += min(q["p_holm"] for q in paired["pairs"]) < 0.05
    # binomial(300, 0.05) stays below 27 with probability > 0.99; Holm keeps the family's error below the level
    assert friedman / runs < 0.09
    assert pairs_any / runs < 0.09


def test_measurements_missing_a_model_are_left_out_and_named():
    rng = np.random.default_rng(3)
    df = campaign(rng, 5, {"HW": 1.0, "LW": 0.5})
    df = df[~((df["measurement"] == "m02") & (df["model"] == "LW"))]
    paired = paired_tests(df)
    assert paired["n"] == 4 and paired["left_out"] == ["m02"]
    assert "friedman_p" not in paired and [(q["a"], q["b"]) for q in paired["pairs"]] == [("HW", "LW")]


def test_too_few_blocks_say_so_and_a_non_positive_f_is_refused():
    one = pd.DataFrame([{"measurement": "m01", "model": "HW", "f": 1.0}, {"measurement": "m01", "model": "LW", "f": 2.0}])
    assert "note" in paired_tests(one) and "pairs" not in paired_tests(one)
    bad = pd.DataFrame([{"measurement": m, "model": k, "f": 0.0 if (m, k) == ("m1", "LW") else 1.0}
                        for m in ("m1", "m2", "m3") for k in ("HW", "LW")])
    with pytest.raises(ValueError, match="positive"):
        paired_tests(bad)


def test_holm_matches_its_definition():
    p = np.array([0.01, 0.04, 0.03, 0.005])
    # sorted 0.005, 0.01, 0.03, 0.04 -> 4x, 3x, 2x, 1x, made monotone
    expect = {3: 0.02, 0: 0.03, 2: 0.06, 1: 0.06}
    assert holm(p) == pytest.approx([expect[k] for k in range(4)])
    assert holm([0.5, 0.6]).max() <= 1.0


def test_the_reports_verdict_names_the_best_law_only_when_the_test_says_so():
    from lss_app.campaign_report import _verdict
    rng = np.random.default_rng(5)
    better = paired_tests(campaign(rng, 12, {"HC": 1.0, "HW": 0.7, "LN": 1.0, "LW": 1.0}))
    assert _verdict(better).startswith("**HW fits best**")
    null = paired_tests(campaign(rng, 12, dict.fromkeys(MODELS, 1.0)))
    assert _verdict(null).startswith("**No law fits significantly better")
