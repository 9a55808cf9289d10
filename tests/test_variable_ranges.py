"""The ranges in modelDescription.xml are the ranges the FMU enforces.

Both come from one table (lss_fmu/variables.py): for every Real and Integer
parameter and input with a declared min or max, the value at the bound is
accepted and a value just outside it is refused with fmi2Error and a message
naming the variable; the XML the FMU ships says exactly that."""
from __future__ import annotations

import ctypes
import math
import xml.etree.ElementTree as ET
import zipfile

import pytest

from lss_fmu.runner import SimulationError
from lss_fmu.variables import VARIABLES

RANGED = [v for v in VARIABLES if v.causality in ("parameter", "input") and v.type in ("Real", "Integer")
          and (v.min is not None or v.max is not None)]


def _outside(v, bound: float, side: int) -> float:
    if v.type == "Integer":
        return int(bound) + side
    return bound + side * max(abs(bound) * 1e-9, 1e-12)


def test_the_xml_declares_the_table_ranges(fmu_file):
    with zipfile.ZipFile(fmu_file) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    declared = {}
    for sv in root.iter("ScalarVariable"):
        t = next(iter(sv))
        declared[sv.get("name")] = (t.get("min"), t.get("max"))
    for v in RANGED:
        lo, hi = declared[v.name]
        assert (lo is None) == (v.min is None) and (hi is None) == (v.max is None), v.name
        if v.min is not None:
            assert float(lo) == v.min, v.name
        if v.max is not None:
            assert float(hi) == v.max, v.name


@pytest.mark.parametrize("var", RANGED, ids=lambda v: v.name)
def test_the_fmu_enforces_the_declared_range(sim, var):
    sim.start({"layout.name": "layout7"})
    sim.fmu.reset()  # back to Instantiated: every parameter may be set
    for bound, side in ((var.min, -1), (var.max, +1)):
        if bound is None:
            continue
        sim.set(var.name, bound)                      # the bound itself is inside
        assert sim.get(var.name) == pytest.approx(bound)
        bad = _outside(var, bound, side)
        sim.messages.clear()
        with pytest.raises(SimulationError) as info:
            sim.set(var.name, bad)
        assert var.name in str(info.value)
        assert sim.get(var.name) == pytest.approx(bound)   # the old value stands
    if var.type == "Real":
        vr = (ctypes.c_uint * 1)(var_ref(sim, var.name))
        for x in (math.nan, math.inf, -math.inf):
            status = sim.fmu.dll.fmi2SetReal(sim.fmu.component, vr, 1, (ctypes.c_double * 1)(x))
            assert status == 3, (var.name, x)


def var_ref(sim, name: str) -> int:
    return sim.variables[name].valueReference


def test_unranged_reals_take_any_finite_value(sim):
    sim.start({"layout.name": "layout7"})
    sim.fmu.reset()
    free = [v for v in VARIABLES if v.causality == "parameter" and v.type == "Real"
            and v.min is None and v.max is None]
    assert free, "every Real parameter has a range: this test has nothing left to check"
    for v in free:
        sim.set(v.name, 1e6)
        assert sim.get(v.name) == 1e6
        sim.set(v.name, v.start)
