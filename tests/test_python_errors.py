"""Python side of issue 9: ChainSimulator turns FMU refusals into clear
errors that name what was wrong (and stays usable afterwards), and
lss_fmu.atomic writes files so that nobody ever sees half of one."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from lss_fmu.atomic import write_atomic, write_json_atomic
from lss_fmu.runner import ChainSimulator, SimulationError
from test_layout_parser import MALFORMED


@pytest.fixture(scope="module")
def csim(fmu_file):
    s = ChainSimulator(fmu_file, instance_name="errors")
    yield s
    s.close()


def short(s: ChainSimulator, **params):
    return s.simulate(0.02, 0.01, params=params, outputs=["chain.v_mean"])


# --- ChainSimulator ----------------------------------------------------------------------

def test_unknown_layout_names_the_layout(csim):
    with pytest.raises(SimulationError) as exc:
        short(csim, **{"layout.name": "layout42"})
    assert "layout42" in str(exc.value)
    assert "\n" not in str(exc.value)
    assert len(short(csim)) == 3  # still usable


def test_missing_layout_file_names_the_path(csim, tmp_path):
    path = tmp_path / "no such dir" / "track.layout"
    with pytest.raises(SimulationError) as exc:
        short(csim, **{"layout.name": str(path)})
    assert str(path) in str(exc.value) and "cannot open" in str(exc.value)


def test_malformed_layout_file_names_the_line(csim, tmp_path):
    path = tmp_path / "bad.layout"
    path.write_text("wheel A\ncoupling A\nmotors 2\nstraight 10\ncurve 3 180 sideways\n")
    with pytest.raises(SimulationError) as exc:
        short(csim, **{"layout.name": str(path)})
    assert "line 5" in str(exc.value) and "sideways" in str(exc.value)


@pytest.mark.parametrize("text,line,fragment", [m[1:] for m in MALFORMED] + [
    ("wheel A\ncoupling A\nmotors 2\nstraight 10\ncurve 3 180 left\nstraight 10\ncurve 3 90 left\n",
     None, "does not close")], ids=[m[0] for m in MALFORMED] + ["does not close"])
def test_every_malformed_layout_is_refused_by_the_fmu(csim, tmp_path, text, line, fragment):
    """The layout reader's refusals (test_layout_parser.MALFORMED) reach the
    FMU's user in one line, with the file and the line number."""
    path = tmp_path / "bad.layout"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    with pytest.raises(SimulationError) as exc:
        short(csim, **{"layout.name": str(path)})
    msg = str(exc.value)
    assert fragment in msg and "bad.layout" in msg and "\n" not in msg
    if line is not None:
        assert f"line {line}:" in msg
    assert len(short(csim)) == 3  # the instance stays usable


def test_unknown_variable_raises_key_error_naming_it(csim):
    with pytest.raises(KeyError) as exc:
        csim.set("drive.vref", 1.0)
    assert "drive.vref" in str(exc.value)
    with pytest.raises(KeyError) as exc:
        short(csim, **{"contact.eJA": 0.5})
    assert "contact.eJA" in str(exc.value)
    with pytest.raises(KeyError) as exc:
        csim.simulate(0.02, 0.01, outputs=["chain.vmean"])
    assert "chain.vmean" in str(exc.value)
    with pytest.raises(KeyError) as exc:
        csim.get("no.such.thing")
    assert "no.such.thing" in str(exc.value)


def test_bad_value_names_variable_and_value(csim):
    with pytest.raises(SimulationError) as exc:
        short(csim, **{"contact.e_JA": 1.5})
    assert "contact.e_JA" in str(exc.value) and "1.5" in str(exc.value)
    with pytest.raises(SimulationError) as exc:
        short(csim, **{"contact.model": 9})
    assert "contact.model" in str(exc.value) and "9" in str(exc.value)
    assert len(short(csim)) == 3


def test_messages_stay_with_their_simulator(fmu_file):
    """Two simulators in one process: each error carries its own FMU's message."""
    with ChainSimulator(fmu_file, instance_name="a") as a, ChainSimulator(fmu_file, instance_name="b") as b:
        with pytest.raises(SimulationError) as exc:
            a.simulate(0.02, 0.01, params={"layout.name": "nowhere_a"})
        assert "nowhere_a" in str(exc.value)
        assert not [m for m in b.messages if m[0] >= 2]
        with pytest.raises(SimulationError) as exc:
            b.simulate(0.02, 0.01, params={"layout.name": "nowhere_b"})
        assert "nowhere_b" in str(exc.value) and "nowhere_a" not in str(exc.value)


def test_discarded_step_is_a_simulation_error(csim):
    with pytest.raises(SimulationError) as exc:  # legal, absurd parameters (test_fmi_behaviour.crush)
        short(csim, **{"layout.name": "layout7", "cart.mass_factor": 1e-3, "chain.pretension": -0.5})
    assert "collapsed" in str(exc.value) or "non-finite" in str(exc.value)
    assert len(short(csim)) == 3


def test_bad_arguments_to_simulate(csim):
    with pytest.raises(ValueError, match="stop_time"):
        csim.simulate(float("nan"), 0.01)
    with pytest.raises(ValueError, match="step"):
        csim.simulate(0.1, 0.0)


# --- atomic writes ------------------------------------------------------------------------

def test_write_atomic_text_bytes_and_json(tmp_path):
    p = tmp_path / "sub" / "out.txt"
    write_atomic(p, "h\u00e9llo")
    assert p.read_text(encoding="utf-8") == "h\u00e9llo"
    write_atomic(p, b"\x00\x01")
    assert p.read_bytes() == b"\x00\x01"
    q = write_json_atomic(tmp_path / "r.json", {"a": [1, 2.5], "b": "x"})
    assert json.loads(q.read_text()) == {"a": [1, 2.5], "b": "x"}
    assert sorted(x.name for x in tmp_path.rglob("*")) == ["out.txt", "r.json", "sub"]
    with pytest.raises(TypeError):
        write_atomic(p, 3.14)


def test_failed_write_leaves_the_old_file_and_no_litter(tmp_path, monkeypatch):
    p = tmp_path / "result.json"
    write_json_atomic(p, {"v": 1})
    with pytest.raises(TypeError):
        write_json_atomic(p, {"v": object()})  # not serialisable: the file is not touched
    assert json.loads(p.read_text()) == {"v": 1}

    def broken_replace(src, dst):
        raise OSError("disk full")
    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(OSError, match="disk full"):
        write_json_atomic(p, {"v": 2})
    monkeypatch.undo()
    assert json.loads(p.read_text()) == {"v": 1}
    assert [x.name for x in tmp_path.iterdir()] == ["result.json"]


def test_permissions_of_the_replaced_file_are_kept(tmp_path):
    p = tmp_path / "f.txt"
    write_atomic(p, "a")
    os.chmod(p, 0o640)
    write_atomic(p, "b")
    assert p.stat().st_mode & 0o777 == 0o640


WRITER = """
import sys
from lss_fmu.atomic import write_json_atomic
path = sys.argv[1]
i = 0
while True:
    i += 1
    write_json_atomic(path, {"i": i, "pad": "x" * 200000})
"""


@pytest.mark.skipif(sys.platform == "win32", reason="SIGKILL")
def test_a_writer_killed_at_any_moment_leaves_a_whole_file(tmp_path):
    p = tmp_path / "state.json"
    write_json_atomic(p, {"i": 0, "pad": ""})
    root = Path(__file__).resolve().parent.parent
    for delay in (0.05, 0.13, 0.21, 0.34):
        proc = subprocess.Popen([sys.executable, "-c", WRITER, str(p)], cwd=root)
        time.sleep(delay + 0.3)  # let it start and write for a while
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        data = json.loads(p.read_text())  # always a complete document
        assert data["i"] >= 0 and (data["i"] == 0 or len(data["pad"]) == 200000)
