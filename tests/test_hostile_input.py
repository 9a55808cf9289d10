"""Hostile input (issue 20): the solver's guards, corrupted solver fields of
an FMU state, files that are not regular files. The word-by-word fuzz of the
serialized state is in test_fmi_robustness.py (counted in the tally) and, under
ASan/UBSan, in the C harness (test_c_harness.py)."""
from __future__ import annotations

import ctypes
import os
import shutil
import struct
import subprocess
import time
from ctypes import byref, c_void_p
from pathlib import Path

import pytest

from fmi_util import DISCARD, ERROR, OK, Slave
from lss_fmu import build
from lss_fmu.layout_format import LayoutError, read_layout

HERE = Path(__file__).parent


@pytest.fixture(scope="module", autouse=True)
def _built(fmu_file):
    return fmu_file


# --- the solver ---------------------------------------------------------------------------------

def test_solver_refuses_a_state_that_cannot_advance(tmp_path):
    cc = os.environ.get("CC", "gcc")
    if shutil.which(cc) is None:
        pytest.skip("no C compiler")
    exe = tmp_path / "dopri_guard"
    subprocess.run([cc, "-std=c11", "-O2", "-Wall", "-Wextra", "-Werror", "-I", str(build.SRC), "-o", str(exe),
                    str(HERE / "c" / "dopri_guard.c"), str(build.SRC / "dopri5.c"), "-lm"], check=True)
    out = subprocess.run([str(exe)], capture_output=True, text=True, timeout=60, check=True).stdout
    rows = {ln.split()[0]: ln.split(maxsplit=3)[1:] for ln in out.splitlines()}
    assert rows["legal"][0] == "0"
    assert rows["legal_hmax_1e-6"][:2] == ["0", "10000"]  # the smallest h_max over 0.01 s: 10,000 steps
    for case in ("h_zero", "h_negative", "h_nan", "h_inf", "t_nan", "t_end_nan", "t_end_inf", "err_prev_zero",
                 "err_prev_negative"):
        rc, steps, msg = rows[case]
        assert rc == "1" and steps == "0" and msg.startswith("invalid solver state"), (case, rows[case])
    assert rows["no_progress"][0] == "1" and "below the resolution of the time" in rows["no_progress"][2]
    rc, steps, msg = rows["stiff"]  # would need ~3 million steps: ends at the limit
    assert rc == "1" and steps == "100002" and "more than 100002 internal steps" in msg


# --- corrupted solver fields of an FMU state (the cases) -----------------------------------

# chain snapshot after the header: 0 n_y, 1 t, 2 h, 3 error memory, ..., 12-19 the motor groups' thrust,
# 20-23 the item ports as applied, 24 the items' energy (chain.c, chain_state_save)
SOLVER_CASES = [(1, float("nan")), (1, 1e300), (1, -1.0), (1, 0.02), (1, 0.0), (2, 0.0), (2, float("nan")),
                (2, -1e-3), (2, 1e300), (3, -1.0), (3, 0.0), (3, float("nan")), (7, 1e300), (7, -1.0), (7, 0.5),
                (11, 0.5), (0, 7.0), (12, 5.0), (19, float("nan")), (20, 3.0), (23, -2.0), (24, float("inf"))]
CHAIN_HEADER = 25   # doubles before the state vector in a chain snapshot


@pytest.mark.parametrize("word,value", SOLVER_CASES)
def test_corrupted_solver_fields_are_refused(word, value):
    with Slave() as s:
        s.init()
        s.fmu.doStep(0.0, 0.01)
        good = s.fmu.getFMUstate()
        blob = bytes(s.fmu.serializeFMUstate(good))
        n_chain = CHAIN_HEADER + 12 + 46 * s.get("chain.n_carts")
        at = len(blob) - 8 * n_chain + 8 * word
        bad = blob[:at] + struct.pack("=d", value) + blob[at + 8:]
        buf = ctypes.create_string_buffer(bad, len(bad))
        state = c_void_p()
        n = len(s.messages)
        status = s.fmu._functions["fmi2DeSerializeFMUstate"](s.fmu.component, buf, len(bad), byref(state))
        assert status == ERROR and "corrupt FMU state" in s.last_error() and len(s.messages) > n
        # the same bytes put into a state taken in memory: fmi2SetFMUstate refuses them too
        size = len(blob)
        ctypes.memmove(good, buf, size)
        assert s.fmu._functions["fmi2SetFMUstate"](s.fmu.component, good) == ERROR
        assert "corrupt FMU state" in s.last_error()
        start = time.perf_counter()
        assert s.call("doStep", 0.01, 0.01) == OK  # the instance is untouched
        assert time.perf_counter() - start < 10 and s.fmu.getRealStatus(2) == pytest.approx(0.02)


def test_state_after_a_discarded_step_round_trips():
    """A state taken in Step Failed has the chain past the FMU's time: legal."""
    with Slave() as s:  # legal, absurd parameters whose first step collapses (test_fmi_behaviour.crush)
        s.init({"layout.name": "layout7", "cart.mass_factor": 1e-3, "chain.pretension": -0.5})
        assert s.call("doStep", 0.0, 0.01) == DISCARD
        state = s.fmu.getFMUstate()
        back = s.fmu.deSerializeFMUstate(s.fmu.serializeFMUstate(state))
        s.fmu.setFMUstate(back)
        assert s.fmu.getRealStatus(2) == 0.0
        assert s.call("doStep", 0.0, 0.01) == ERROR  # Step Failed: no further step
        assert s.call("terminate") == OK


# --- files that are not regular files -------------------------------------------------------------

def special_files(tmp_path):
    fifo = tmp_path / "fifo.layout"
    out = [str(tmp_path), "/dev/null", "/dev/zero"]
    if hasattr(os, "mkfifo"):
        os.mkfifo(fifo)
        out.insert(0, str(fifo))
    return out


def test_fmu_refuses_fifos_devices_and_directories_without_blocking(tmp_path):
    for path in special_files(tmp_path):
        with Slave() as s:
            assert s.set("layout.name", path) == OK
            s.fmu.setupExperiment()
            s.fmu.enterInitializationMode()
            start = time.perf_counter()
            assert s.call("exitInitializationMode") == ERROR
            assert time.perf_counter() - start < 5
            msg = s.last_error()
            assert path in msg and ("not a regular file" in msg or "is a directory" in msg), msg


def test_python_reader_refuses_them_too(tmp_path):
    for path in special_files(tmp_path):
        with pytest.raises(LayoutError, match="not a regular file|is a directory"):
            read_layout(path)


# --- fmi2EnterInitializationMode without fmi2SetupExperiment ------------------------------------

def test_enter_initialization_without_setup_experiment_warns_and_uses_defaults():
    with Slave() as s:
        n = len(s.messages)
        status = s.fmu._functions["fmi2EnterInitializationMode"](s.fmu.component)
        assert status == 1  # fmi2Warning
        assert any(m[0] == 1 and "without fmi2SetupExperiment" in m[2] for m in s.messages[n:])
        s.fmu.exitInitializationMode()
        assert s.fmu.getRealStatus(2) == 0.0  # startTime 0
        s.fmu.doStep(0.0, 0.01)
        assert s.fmu.getRealStatus(2) == pytest.approx(0.01)
        # after fmi2Reset the rule applies again; with fmi2SetupExperiment no warning
        s.fmu.reset()
        s.clear()
        s.fmu.setupExperiment(startTime=2.0)
        assert s.fmu._functions["fmi2EnterInitializationMode"](s.fmu.component) == OK
        assert not s.messages
