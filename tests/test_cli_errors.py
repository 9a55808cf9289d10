"""Every `lss` command meets bad input with one line on stderr naming what is
wrong, a non-zero exit code and no traceback (unless --traceback is given):
a missing file, a malformed measurement, an unknown layout or model, an
impossible bound (issue 9). Run as a user runs it: a separate process."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from lss_fmu import measurement as M
from test_measurement import make_meta, make_samples, rewrite_csv, set_cell


def lss(*args: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "lss_app.cli", *args], capture_output=True, text=True,
                          timeout=300, cwd=cwd)


def edit_meta(folder, edit) -> None:
    """Spoil meta.json after the writer (which refuses bad metadata) wrote it."""
    path = folder / M.META_FILE
    meta = json.loads(path.read_text())
    edit(meta)
    path.write_text(json.dumps(meta, indent=1))


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    root = tmp_path_factory.mktemp("cli")
    good = root / "good" / "m01"
    M.write_measurement(good, make_samples(), make_meta())
    nan = root / "nan" / "m01"
    M.write_measurement(nan, make_samples(), make_meta())
    rewrite_csv(nan, lambda lines: set_cell(lines, 18, "transducer.joint.F_y", "nan"))
    bound = root / "bound" / "m01"
    M.write_measurement(bound, make_samples(), make_meta())
    edit_meta(bound, lambda m: m["design_variables"].update(
        v_s={"nominal": 2.0, "lower": 3.0, "upper": 1.5, "unit": "m/s"}))
    layout = root / "layout" / "m01"
    M.write_measurement(layout, make_samples(), make_meta())
    edit_meta(layout, lambda m: m.update(layout="layout42"))
    other = root / "other" / "m02"   # another sorter: layout 5
    M.write_measurement(other, make_samples(), make_meta(layout="layout5", wheel_type="A", id="test-02", number=2))
    for name, text in {"zero": "[identify]\nmax_evals = 0\n", "negative": "[identify]\nrestarts = -1\n",
                       "unknown": "[identify]\nbudget = 3\n", "table": "[identfy]\nwindow = 2.0\n",
                       "broken": "[identify\nwindow = 2\n", "free": "[identify]\nfree = [\"e_XY\"]\n"}.items():
        (root / f"{name}.toml").write_text(text)
    return {"root": root, "good": good, "nan": nan, "bound": bound, "layout": layout, "other": other}


CASES = [
    # (id, argv with {placeholders}, fragments that the one line must hold)
    ("simulate unknown layout", ["simulate", "--layout", "layout42", "--stop-time", "0.1", "--out", "{root}/x.csv"],
     ["layout42"]),
    ("simulate missing layout file", ["simulate", "--layout", "{root}/none.layout", "--stop-time", "0.1",
                                      "--out", "{root}/x.csv"], ["none.layout"]),
    ("simulate unknown parameter", ["simulate", "--stop-time", "0.1", "--out", "{root}/x.csv",
                                    "--set", "contact.eJA=0.5"], ["contact.eJA"]),
    ("simulate bad value", ["simulate", "--stop-time", "0.1", "--out", "{root}/x.csv",
                            "--set", "contact.e_JA=1.5"], ["contact.e_JA", "1.5"]),
    ("layouts check missing", ["layouts", "check", "{root}/none.layout"], ["none.layout"]),
    ("layouts plot unknown", ["layouts", "plot", "layout42", "--out", "{root}/plots"], ["layout42"]),
    ("rig unknown set", ["rig", "--set", "nonsense", "--out", "{root}/rig"], ["nonsense"]),
    ("rig unknown effect", ["rig", "--set", "recovery", "--out", "{root}/rig", "--effects", "flat_tyre"],
     ["flat_tyre"]),
    ("identify missing folder", ["identify", "{root}/nowhere", "--model", "HW", "--out", "{root}/o"],
     ["nowhere"]),
    ("identify unknown model", ["identify", "{good}", "--model", "XX", "--out", "{root}/o"], ["XX"]),
    ("identify malformed measurement", ["identify", "{nan}", "--model", "HW", "--out", "{root}/o"],
     ["samples.csv", "transducer.joint.F_y"]),
    ("identify impossible bound", ["identify", "{bound}", "--model", "HW", "--out", "{root}/o"],
     ["meta.json", "design_variables.v_s", "lower"]),
    ("identify unknown layout", ["identify", "{layout}", "--model", "HW", "--out", "{root}/o"], ["layout42"]),
    ("identify bad budget", ["identify", "{good}", "--model", "HW", "--out", "{root}/o", "--settings",
                             "{root}/zero.toml"], ["zero.toml", "max_evals = 0", "at least 1"]),
    ("identify negative restarts", ["identify", "{good}", "--model", "HW", "--out", "{root}/o", "--settings",
                                    "{root}/negative.toml"], ["negative.toml", "restarts = -1"]),
    ("identify unknown setting", ["identify", "{good}", "--model", "HW", "--out", "{root}/o", "--settings",
                                  "{root}/unknown.toml"], ["unknown.toml", "unknown key 'budget'"]),
    ("identify unknown settings table", ["identify", "{good}", "--model", "HW", "--out", "{root}/o", "--settings",
                                         "{root}/table.toml"], ["table.toml", "[identfy]"]),
    ("identify settings not toml", ["identify", "{good}", "--model", "HW", "--out", "{root}/o", "--settings",
                                    "{root}/broken.toml"], ["broken.toml", "not TOML"]),
    ("identify settings unknown variable", ["identify", "{good}", "--model", "HW", "--out", "{root}/o",
                                            "--settings", "{root}/free.toml"], ["free.toml", "e_XY"]),
    ("identify missing settings", ["identify", "{good}", "--model", "HW", "--out", "{root}/o", "--settings",
                                   "{root}/none.toml"], ["none.toml", "cannot read"]),
    ("identify two sorters", ["identify", "{good}", "{other}", "--model", "HW", "--out", "{root}/o"],
     ["m02", "layout", "one sorter"]),
    ("campaign negative restarts", ["campaign", "{root}/good", "--models", "HW", "--out", "{root}/c",
                                    "--settings", "{root}/negative.toml"], ["negative.toml", "restarts = -1"]),
    ("identify no workers", ["identify", "{good}", "--model", "HW", "--out", "{root}/o", "--workers", "0"],
     ["--workers 0"]),
    ("close-loop no workers", ["close-loop", "{good}", "--model", "HW", "--out", "{root}/l", "--workers", "0"],
     ["--workers 0"]),
    ("campaign no workers", ["campaign", "{root}/good", "--models", "HW", "--out", "{root}/c", "--workers", "0"],
     ["workers = 0"]),
    ("campaign bad budget", ["campaign", "{root}/good", "--models", "HW", "--out", "{root}/c", "--settings",
                             "{root}/zero.toml"], ["zero.toml", "max_evals = 0"]),
    ("campaign no data", ["campaign", "--models", "HW", "--out", "{root}/c"], ["DATA", "--manifest"]),
    ("campaign missing folder", ["campaign", "{root}/nowhere", "--models", "HW", "--out", "{root}/c"],
     ["nowhere"]),
    ("campaign unknown model", ["campaign", "{root}/good", "--models", "HW,XX", "--out", "{root}/c"], ["XX"]),
    ("report missing folder", ["report", "{root}/nowhere"], ["nowhere"]),
    ("close-loop missing folder", ["close-loop", "{root}/nowhere", "--model", "HW", "--out", "{root}/l"],
     ["nowhere"]),
    ("close-loop malformed measurement", ["close-loop", "{nan}", "--model", "HW", "--out", "{root}/l"],
     ["samples.csv"]),
]


@pytest.mark.parametrize("argv, fragments", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_one_line_error_no_traceback(folders, fmu_file, argv, fragments):
    argv = [a.format(**folders) for a in argv]
    r = lss(*argv)
    assert r.returncode != 0, r.stdout
    err = r.stderr.strip()
    assert err, "no message"
    assert "Traceback" not in r.stderr
    # argparse's usage block may stand before its own one-line error, as in any command
    lines = [ln for ln in err.splitlines() if not ln.startswith(("WARNING", "usage:", " "))]
    assert len(lines) == 1, err
    for frag in fragments:
        assert frag in lines[0], lines[0]


def test_traceback_on_request(folders, fmu_file):
    r = lss("--traceback", "identify", str(folders["nan"]), "--model", "HW", "--out", str(folders["root"] / "o"))
    assert r.returncode != 0
    assert "Traceback" in r.stderr and "MeasurementError" in r.stderr


def test_measurement_errors_name_the_row(folders):
    """The malformed measurement's one line names the file, the column and the row."""
    r = lss("identify", str(folders["nan"]), "--model", "HW", "--out", str(folders["root"] / "o"))
    line = r.stderr.strip().splitlines()[-1]
    assert "samples.csv" in line and "transducer.joint.F_y" in line and ("row" in line or "line" in line), line
