"""The sorter system of examples/plant (issue 52): LSSChain with a drive FMU
(speed controller, motors with a lag) and an induction FMU (items on at an
induction, off at a chute), coupled as an SSP and run by fmpy's SSP master
and by libcosim. Both masters give the same system within the communication
step's error; the drive holds the set point; items come on and go off and
the chain's item mass follows the induction's count."""
from __future__ import annotations

import importlib.util
import shutil
from pathlib import Path

import numpy as np
import pytest
from fmpy.validation import validate_fmu

ROOT = Path(__file__).resolve().parents[1]
STOP, STEP = 4.0, 0.005


def plant_module():
    spec = importlib.util.spec_from_file_location("plant_system", ROOT / "examples" / "plant" / "plant_system.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def system(tmp_path_factory, fmu_file):
    if shutil.which("gcc") is None:
        pytest.skip("no gcc to build the plant FMUs")
    pytest.importorskip("libcosimpy")
    plant = plant_module()
    out = tmp_path_factory.mktemp("plant")
    # items on every cart passing from 0.5 s; the chute 2 m after the induction: items come off within the run
    params = plant.parameters("demo", v_set=1.5, rate=5.0, mass=20.0, chute_after=2.0)
    ssp = plant.write_ssp(out, fmu_file, params)
    runs = {"fmpy": plant.run_fmpy(ssp, params, STOP, STEP), "libcosim": plant.run_libcosim(ssp, STOP, STEP)}
    return plant, out, ssp, runs


def test_the_plant_fmus_are_valid(system):
    _, out, _, _ = system
    for name in ("SorterDrive", "Induction"):
        assert validate_fmu(str(out / f"{name}.fmu")) == []


def test_both_masters_run_the_same_system(system):
    _, _, _, runs = system
    a, b = runs["fmpy"], runs["libcosim"]
    assert len(a) == len(b) == int(round(STOP / STEP))
    assert np.array_equal(a["time"].round(9), b["time"].round(9))
    # the same Jacobi coupling at the same step: equal to far below the step's own error
    assert np.abs(a["chain.chain.v_mean"] - b["chain.chain.v_mean"]).max() < 1e-3
    assert np.array_equal(a["chain.chain.items.mass"], b["chain.chain.items.mass"])


def test_the_drive_holds_the_set_point_and_the_items_come_and_go(system):
    _, _, _, runs = system
    for df in runs.values():
        late = df["time"] > STOP - 1.0
        assert np.abs(df["chain.chain.v_mean"][late] - 1.5).max() < 0.03
        assert df["drive.F"].max() == pytest.approx(400.0, rel=1e-6)       # saturated while accelerating
        assert np.all(df["chain.drive.F_total"][late] > 0)
        items = df["chain.chain.items.mass"].to_numpy()
        # the chain carries what the induction counts, one communication step later (the coupling's delay)
        assert np.all(items[1:] == 20.0 * df["induction.n_items"].to_numpy()[:-1])
        assert items.max() >= 40.0 and np.any(np.diff(items) < 0)          # on, and off again at the chute
        # every item put on a moving cart jolts the chain: the largest joint force jumps above its run level
        assert df["chain.chain.joint.F_max"].max() > 2.0 * df["chain.chain.joint.F_max"][df["time"] < 0.5].max()


def test_a_layout_fmpy_cannot_set_is_said(system, fmu_file):
    plant, _, ssp, _ = system
    with pytest.raises(ValueError, match="fmpy's SSP master sets no String parameter"):
        plant.run_fmpy(ssp, plant.parameters("layout7"), 0.1, STEP)
