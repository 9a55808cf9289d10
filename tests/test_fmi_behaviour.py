"""FMI 2.0 behaviour of LSSChain.fmu, tried through fmpy (issue 2, "FMI
behaviour", and issue 9): validation, fmpy's own simulate_fmu, FMU state
replay and serialization, reset versus a fresh instance, instances that do
not disturb each other (also on several threads), the state machine (every
wrong call order gives fmi2Error and a message), bad parameter values, setters
before fmi2SetupExperiment, initial unknowns in Initialization Mode, and
resource locations with spaces and percent-encoded characters."""
from __future__ import annotations

import math
import shutil
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu
from fmpy.validation import validate_fmu

from fmi_util import DISCARD, ERROR, OK, WARNING, Slave, model_description, run, unzipdir, var
from lss_fmu import build

STEP = 0.01


@pytest.fixture(scope="module", autouse=True)
def _built(fmu_file):
    """The FMU of this session (conftest builds it)."""
    return fmu_file


def real_outputs() -> list[str]:
    return [v.name for v in model_description().modelVariables if v.causality == "output" and v.type == "Real"]


def initial_unknowns() -> list:
    return [v for v in model_description().modelVariables if v.causality in ("output", "calculatedParameter")]


# --- fmpy's own tools -------------------------------------------------------------

def test_validate_fmu_finds_no_problem(fmu_file):
    assert validate_fmu(str(fmu_file)) == []


def test_simulate_fmu_with_default_settings(fmu_file):
    res = simulate_fmu(str(fmu_file), stop_time=0.5)
    assert res["time"][0] == 0.0 and math.isclose(res["time"][-1], 0.5)
    # the default output interval is the DefaultExperiment's step size
    assert np.allclose(np.diff(res["time"]), float(model_description().defaultExperiment.stepSize))
    for name in res.dtype.names:
        assert np.all(np.isfinite(res[name])), name
    assert abs(res["chain.v_mean"][-1] - 2.0) < 0.05  # drive.v_ref starts at 2 m/s


# --- FMU state --------------------------------------------------------------------

def test_get_set_fmu_state_replays_bit_for_bit():
    outs = real_outputs()
    with Slave() as s:
        s.init({"contact.model": 1})
        run(s, 0.05, STEP, outs)
        at_save = s.get_reals(outs)
        state = s.fmu.getFMUstate()
        first = run(s, 0.15, STEP, outs, t0=0.05)
        s.fmu.setFMUstate(state)
        assert s.get_reals(outs) == at_save  # the outputs at the restored point, too
        second = run(s, 0.15, STEP, outs, t0=0.05)
        assert np.array_equal(first, second)
        # the same state again, after a change of input that must not leak through
        s.fmu.setFMUstate(state)
        third = run(s, 0.15, STEP, outs, t0=0.05)
        assert np.array_equal(first, third)
        s.fmu.freeFMUstate(state)


def test_serialize_deserialize_round_trips_into_another_instance():
    outs = real_outputs()
    with Slave("a") as a, Slave("b") as b:
        a.init({"drive.v_ref": 1.7, "contact.model": 4})
        run(a, 0.05, STEP, outs)
        state = a.fmu.getFMUstate()
        blob = a.fmu.serializeFMUstate(state)
        expected = run(a, 0.12, STEP, outs, t0=0.05)
        # b was set up differently: the state brings its parameters and chain with it
        b.init({"drive.v_ref": 2.5, "contact.model": 2, "cart.mass_factor": 1.3})
        restored = b.fmu.deSerializeFMUstate(blob)
        assert b.fmu.serializeFMUstate(restored) == blob  # bytes round-trip
        b.fmu.setFMUstate(restored)
        assert b.get("drive.v_ref") == 1.7 and b.get("contact.model") == 4
        assert np.array_equal(run(b, 0.12, STEP, outs, t0=0.05), expected)
        a.fmu.freeFMUstate(state)
        b.fmu.freeFMUstate(restored)


# --- instances ----------------------------------------------------------------------

P1 = {"contact.model": 1, "drive.v_ref": 1.6, "contact.e_JA": 0.4}
P2 = {"contact.model": 5, "drive.v_ref": 2.4, "wheel.mu_roll": 0.03}


def test_reset_then_initialise_equals_a_fresh_instance():
    outs = real_outputs()
    with Slave("used") as used, Slave("fresh") as fresh:
        used.init(P1)
        run(used, 0.1, STEP, outs)
        used.fmu.reset()
        used.init(P2)
        again = run(used, 0.1, STEP, outs)
        fresh.init(P2)
        assert np.array_equal(again, run(fresh, 0.1, STEP, outs))
        # defaults are back after a reset
        used.fmu.reset()
        assert used.get("drive.v_ref") == float(var("drive.v_ref").start)
        assert used.get("contact.model") == int(var("contact.model").start)


def alone(params, stop=0.1):
    with Slave() as s:
        s.init(params)
        return run(s, stop, STEP, real_outputs())


def test_two_instances_with_different_parameters_do_not_disturb_each_other():
    outs = real_outputs()
    ref1, ref2 = alone(P1), alone(P2)
    with Slave("one") as a, Slave("two") as b:
        a.init(P1)
        b.init(P2)
        rows_a, rows_b = [[0.0, *a.get_reals(outs)]], [[0.0, *b.get_reals(outs)]]
        t = 0.0
        for k in range(1, 11):  # interleaved, step by step (the same time points as run())
            t_next = k * STEP
            a.fmu.doStep(t, t_next - t)
            b.fmu.doStep(t, t_next - t)
            t = t_next
            rows_a.append([t, *a.get_reals(outs)])
            rows_b.append([t, *b.get_reals(outs)])
    assert np.array_equal(np.array(rows_a), ref1)
    assert np.array_equal(np.array(rows_b), ref2)


def test_instances_on_several_threads_match_one_after_another():
    params = [{"contact.model": m, "drive.v_ref": 1.5 + 0.2 * m} for m in range(1, 5)]
    sequential = [alone(p, 0.2) for p in params]
    with ThreadPoolExecutor(max_workers=4) as ex:  # ctypes releases the GIL in the FMU's calls
        parallel = list(ex.map(lambda p: alone(p, 0.2), params))
    for a, b in zip(sequential, parallel):
        assert np.array_equal(a, b)


# --- the state machine ----------------------------------------------------------------

STATES = ["instantiated", "init", "step", "failed", "terminated"]


def crush(s: Slave) -> None:
    """Legal, absurd parameters whose first step collapses: layout 7, carts of
    1/1000 of their mass, the chain half a metre too long for the track."""
    assert s.set("layout.name", "layout7") == OK
    assert s.set("cart.mass_factor", 1e-3) == OK
    assert s.set("chain.pretension", -0.5) == OK


def reach(state: str) -> Slave:
    s = Slave(state)
    if state == "failed":
        crush(s)
    if state != "instantiated":
        s.fmu.setupExperiment(startTime=0.0)
        s.fmu.enterInitializationMode()
    if state in ("step", "failed", "terminated"):
        s.fmu.exitInitializationMode()
    if state == "failed":
        assert s.call("doStep", 0.0, STEP) == DISCARD
        assert "collapsed" in s.last_error()
    if state == "terminated":
        s.fmu.terminate()
    s.clear()
    return s


# (call, states where FMI 2.0 allows it); fmi2Terminate is also accepted in
# Initialization Mode, for masters that terminate after a failed initialisation
CALLS = {
    "fmi2SetupExperiment": (lambda s: s.call("setupExperiment", None, 0.0), {"instantiated"}),
    # (after fmi2SetupExperiment where it is allowed: without it, defaults and a warning, test_hostile_input.py)
    "fmi2EnterInitializationMode": (lambda s: (s.name != "instantiated" or s.call("setupExperiment", None, 0.0),
                                               s.call("enterInitializationMode"))[1], {"instantiated"}),
    "fmi2ExitInitializationMode": (lambda s: s.call("exitInitializationMode"), {"init"}),
    "fmi2DoStep": (lambda s: s.call("doStep", 0.0, STEP), {"step"}),
    "fmi2Terminate": (lambda s: s.call("terminate"), {"init", "step", "failed"}),
    "fmi2SetReal(fixed parameter)": (lambda s: s.set("chain.pretension", 0.02), {"instantiated", "init"}),
    "fmi2SetReal(tunable parameter)": (lambda s: s.set("drive.Kp", 450.0), {"instantiated", "init", "step"}),
    "fmi2SetReal(input)": (lambda s: s.set("drive.v_ref", 1.9), {"instantiated", "init", "step"}),
    "fmi2SetString(layout.name)": (lambda s: s.set("layout.name", "demo"), {"instantiated", "init"}),
    "fmi2SetReal(output)": (lambda s: s.set("chain.v_mean", 1.0), set()),
    "fmi2SetInteger(calculated parameter)": (lambda s: s.set("chain.n_carts", 10), set()),
    "fmi2GetReal(output)": (lambda s: s.call("getReal", [var("chain.v_mean").valueReference]),
                            {"init", "step", "failed", "terminated"}),
    "fmi2Reset": (lambda s: s.call("reset"), set(STATES)),
}


@pytest.mark.parametrize("state", STATES)
@pytest.mark.parametrize("name", list(CALLS))
def test_state_machine(state, name):
    call, allowed = CALLS[name]
    with reach(state) as s:
        status = call(s)
        if state in allowed:
            assert status == OK, s.messages
            assert not [m for m in s.messages if m[0] >= WARNING]
        else:
            assert status == ERROR, f"{name} in state {state} returned {status}"
            fn = name.split("(")[0]
            msg = s.last_error()
            assert msg and fn in msg, s.messages
            if "output" not in name and "calculated" not in name:
                assert "state" in msg  # says which state it was in


def test_wrong_call_changes_nothing():
    outs = real_outputs()
    ref = alone({}, 0.05)
    with Slave() as s:
        s.init()
        assert s.call("doStep", 0.02, STEP) == ERROR          # wrong communication point
        assert "currentCommunicationPoint" in s.last_error()
        assert s.call("setupExperiment", None, 0.0) == ERROR
        assert s.call("enterInitializationMode") == ERROR
        assert s.set("chain.pretension", 0.05) == ERROR     # a fixed parameter in Step Mode
        assert s.set("chain.v_mean", 3.0) == ERROR
        assert np.array_equal(run(s, 0.05, STEP, outs), ref)


def test_discard_after_a_non_finite_state_and_recovery_through_fmu_state():
    with Slave() as s:
        s.init()
        s.fmu.doStep(0.0, STEP)
        good = s.fmu.getFMUstate()
        assert s.get("chain.v_mean") > 1.0
        # a step that cannot be made (set through a corrupted FMU state is not
        # possible: it is checked; so do it with extreme but legal parameters)
    with Slave() as s:
        crush(s)
        s.init()
        assert s.call("doStep", 0.0, STEP) == DISCARD
        assert s.messages[-1][0] == DISCARD and "collapsed" in s.messages[-1][2]
        assert s.fmu.getRealStatus(2) == 0.0  # fmi2LastSuccessfulTime: nothing was done
        assert s.call("doStep", 0.0, STEP) == ERROR  # no step after a discard ...
        s.fmu.reset()                                   # ... but a reset recovers
        s.init()
        s.fmu.doStep(0.0, STEP)
        assert math.isfinite(s.get("chain.v_mean"))


# --- parameter values ---------------------------------------------------------------

BAD_VALUES = [
    ("contact.e_JA", 0.0), ("contact.e_JR", 1.5), ("contact.e_SW", -0.1), ("contact.e_RW", float("nan")),
    ("contact.model", 0), ("contact.model", 7), ("cart.mass_factor", 0.0), ("cart.mass_factor", -2.0),
    ("drive.v_ref", float("inf")), ("drive.v_ref", 1e300), ("drive.Kp", -1.0), ("wheel.mu_roll", 0.9),
    ("chain.pretension", 2.0), ("contact.v_min", 0.0), ("solver.tolerance", 1e-300), ("solver.h_max", 0.0),
    ("chain.transducer", -1), ("track.guide_gap", 1.0), ("drive.motor_length", -0.6),
]


@pytest.mark.parametrize("name,value", BAD_VALUES, ids=[f"{n}={v}" for n, v in BAD_VALUES])
def test_bad_parameter_value_is_refused_with_a_message(name, value):
    with Slave() as s:
        before = s.get(name)
        assert s.set(name, value) == ERROR
        msg = s.last_error()
        assert name in msg, msg
        shown = "nan" if isinstance(value, float) and math.isnan(value) else \
            "inf" if value == float("inf") else None
        if shown:
            assert shown in msg.lower()
        else:
            assert any(f in msg for f in (repr(value), str(value), f"{value:g}", f"{value:.17g}")), msg
        assert s.get(name) == before or (isinstance(before, float) and math.isnan(before))  # unchanged


def test_unknown_layout_is_refused_at_initialisation_naming_it():
    with Slave() as s:
        assert s.set("layout.name", "layout99") == OK  # known only once the resources are read
        s.fmu.setupExperiment()
        s.fmu.enterInitializationMode()
        assert s.call("exitInitializationMode") == ERROR
        assert "layout99" in s.last_error()
        assert s.call("getReal", [var("chain.v_mean").valueReference]) == ERROR


# --- setters, initial unknowns, resources ----------------------------------------------

def test_setters_before_setup_experiment_are_accepted_and_used():
    with Slave() as s:
        assert s.set("drive.v_ref", 1.5) == OK
        assert s.set("contact.model", 2) == OK
        assert s.set("chain.v_init", 1.5) == OK
        s.fmu.setupExperiment(tolerance=1e-4, startTime=0.0, stopTime=0.3)
        s.fmu.enterInitializationMode()
        s.fmu.exitInitializationMode()
        assert s.get("drive.v_ref") == 1.5 and s.get("contact.model") == 2
        out = run(s, 0.3, STEP, ["chain.v_mean"])
        assert abs(out[-1, 1] - 1.5) < 0.05


def test_initial_unknowns_readable_in_initialization_mode():
    with Slave() as s:
        s.fmu.setupExperiment(startTime=0.0)
        s.fmu.enterInitializationMode()
        values = {}
        for v in initial_unknowns():
            values[v.name] = s.get(v.name)
            assert math.isfinite(values[v.name]), v.name
        assert values["chain.n_carts"] == 40 and values["track.length"] == pytest.approx(50.0)
        assert values["chain.v_mean"] == pytest.approx(2.0, rel=0.05)  # starts at drive.v_ref
        # inputs set in Initialization Mode are seen by the initial unknowns
        assert s.set("drive.v_ref", 1.8) == OK
        assert s.get("chain.v_mean") == pytest.approx(0.9 * values["chain.v_mean"], rel=1e-9)
        s.fmu.exitInitializationMode()
        for v in initial_unknowns():  # the same at t = 0 after initialisation
            if v.causality == "calculatedParameter":
                assert s.get(v.name) == values[v.name], v.name


@pytest.mark.parametrize("dirname", ["dir with spaces", "per%cent & [brackets] #hash", "ünïcødé"])
def test_resource_location_with_spaces_and_percent_encoding(tmp_path, dirname):
    target = tmp_path / dirname / "LSSChain"
    shutil.copytree(unzipdir(), target)
    uri = (target / "resources").as_uri()  # percent-encodes spaces, '%', '#', non-ASCII
    assert "%20" in uri or "%25" in uri or "%C3" in uri
    with Slave(directory=str(target)) as s:  # fmpy builds the URI itself
        s.init({"layout.name": "layout1"})
        s.fmu.doStep(0.0, STEP)
        assert s.get("chain.n_carts") > 40
    # spelled by hand: file:/path and file://localhost/path
    for spelled in (uri.replace("file:///", "file:/"), uri.replace("file:///", "file://localhost/")):
        with Slave(directory=str(target), resource_uri=spelled) as s:
            s.init({"layout.name": "oval"})
            assert not [m for m in s.messages if m[0] >= WARNING]


def test_bad_resource_location_warns_and_built_in_layouts_are_then_refused(tmp_path):
    for uri in ("http://example.com/resources", "file:///no%2", "not a uri"):
        with Slave(resource_uri=uri) as s:
            assert any(m[0] == WARNING and "resource location" in m[2] for m in s.messages), uri
            s.fmu.setupExperiment()
            s.fmu.enterInitializationMode()
            assert s.call("exitInitializationMode") == ERROR
            assert "resource" in s.last_error()
    # a layout given as a path still works without resources
    layout = tmp_path / "my oval.layout"
    layout.write_text((Path(unzipdir()) / "resources" / "layouts" / "oval.layout").read_text())
    with Slave(resource_uri="http://example.com/resources") as s:
        s.init({"layout.name": str(layout)})
        s.fmu.doStep(0.0, STEP)


# --- the source FMU ---------------------------------------------------------------------

def test_sources_listed_in_the_model_description_are_complete(fmu_file):
    import re
    import zipfile
    md = read_model_description_of(fmu_file)
    listed = md.buildConfigurations[0].sourceFileSets[0].sourceFiles
    with zipfile.ZipFile(fmu_file) as z:
        names = {n[len("sources/"):] for n in z.namelist() if n.startswith("sources/") and not n.endswith("/")}
        texts = {n: z.read("sources/" + n).decode() for n in names}
    assert set(listed) == {n for n in names if n.endswith(".c")}
    assert not [n for n in listed if n.startswith("test_")]
    for name, text in texts.items():  # every local include ships along
        for inc in re.findall(r'#include\s+"([^"]+)"', text):
            assert inc in names or inc.startswith("fmi2"), f"{name} includes {inc}, not in sources/"


def read_model_description_of(path):
    from fmpy import read_model_description
    return read_model_description(str(path))


@pytest.mark.skipif(shutil.which("cmake") is None, reason="fmpy compile needs cmake")
def test_fmpy_compile_builds_the_source_fmu(fmu_file, tmp_path):
    """`fmpy compile` (CMake, the compiler found there) rebuilds the binary from
    sources/ of a copy without binaries; the result runs like the original."""
    import subprocess
    import sys
    import zipfile
    copy = tmp_path / "source only" / "LSSChain.fmu"
    copy.parent.mkdir()
    with zipfile.ZipFile(fmu_file) as src, zipfile.ZipFile(copy, "w", zipfile.ZIP_DEFLATED) as dst:
        for item in src.infolist():
            if not item.filename.startswith("binaries/"):
                dst.writestr(item, src.read(item))
    res = subprocess.run([sys.executable, "-m", "fmpy", "compile", str(copy)], capture_output=True, text=True,
                         cwd=tmp_path, timeout=600)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    with zipfile.ZipFile(copy) as z:
        assert any(n.startswith("binaries/") and n.endswith(build.shared_suffix()) for n in z.namelist())
    assert validate_fmu(str(copy)) == []
    from lss_fmu.runner import ChainSimulator
    outs = ["chain.v_mean", "transducer.joint.F_x", "transducer.driving.F_left"]
    with ChainSimulator(copy) as rebuilt, ChainSimulator(fmu_file) as original:
        a = rebuilt.simulate(0.2, STEP, outputs=outs)
        b = original.simulate(0.2, STEP, outputs=outs)
    assert np.allclose(a.to_numpy(), b.to_numpy(), rtol=1e-6, atol=1e-6)


def test_an_output_read_alone_is_that_of_the_current_state(fmu_file):
    """The outputs that walk every cart are computed only when one of them is
    read (fmi2_glue: the bulk part). Each output read alone right after a
    step equals its value once every output is brought up to date at the
    same state: an output the bulk part writes without its `bulk` flag in
    the variable table would be read stale."""
    from lss_fmu.runner import ChainSimulator
    from lss_fmu.variables import VARIABLES
    outs = [v.name for v in VARIABLES if v.causality == "output" and v.type in ("Real", "Integer")]
    with ChainSimulator(fmu_file) as s:
        s.start({"layout.name": "layout7", "drive.v_ref": 2.0})
        s.step(0.2)
        for name in outs:
            s.step(0.02)
            alone = s.get(name)
            s.get("energy.E_mech")   # in the bulk part: brings every output up to date
            assert s.get(name) == alone, name
