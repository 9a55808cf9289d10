"""The identification's settings (identification.pipeline.settings) and the front
door's checks on the records it is given (identification.pipeline.driver): the
defaults are the recovery table's method, an expert's TOML changes them, bad
keys and values are refused by name, records of two sorters or protocols are
refused before anything runs; `lss identify --help` stays short."""
from __future__ import annotations

import subprocess
import sys

import pytest

from identification.pipeline.driver import RecordsError, check_records, method_of
from identification.pipeline.settings import Settings, SettingsError, load_settings, settings_from
from lss_fmu import measurement as M
from lss_fmu.design import DESIGN
from test_measurement import make_meta, make_samples


def test_defaults_are_the_tables_method():
    s = load_settings(None)
    assert s == Settings()
    assert (s.window, s.max_evals, s.refine_evals, s.restarts, s.start, s.shrink, s.tare) == \
        (2.5, 300, 400, 1, "auto", True, True)
    assert s.free == DESIGN
    d = s.to_dict()
    assert d["free"][:4] == ["e_JA", "e_JR", "e_SW", "e_RW"] and d["window"] == 2.5


def test_a_file_changes_what_it_names(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text('[identify]\nwindow = 1\nrestarts = 0\nfree = ["e_SW", "K_P"]\nshrink = false\n')
    s = load_settings(f)
    assert s.window == 1.0 and isinstance(s.window, float) and s.restarts == 0 and not s.shrink
    assert s.free == ("contact.e_SW", "drive.Kp") and s.max_evals == Settings().max_evals
    assert load_settings(_write(tmp_path, "")) == Settings()   # an empty file: the defaults


def _write(tmp_path, text: str, name: str = "x.toml"):
    f = tmp_path / name
    f.write_text(text)
    return f


@pytest.mark.parametrize("text, fragments", [
    ("[identify]\nwindow = 0\n", ["window = 0.0", "positive"]),
    ("[identify]\nwindow = nan\n", ["window = nan"]),
    ("[identify]\nmax_evals = 2.5\n", ["max_evals = 2.5", "integer"]),
    ("[identify]\nrestarts = 11\n", ["restarts = 11", "0 to 10"]),
    ("[identify]\nshrink = 1\n", ["shrink = 1", "true or false"]),
    ("[identify]\nstart = \"best\"\n", ["start = 'best'", "complex, single, auto"]),
    ("[identify]\nrefine_evals = -1\n", ["refine_evals = -1"]),
    ("[identify]\nfirst_window = 5\n", ["first_window = 5.0"]),
    ("[identify]\nfree = []\n", ["free = []"]),
    ("[identify]\nfree = [\"e_JA\", \"e_JA\"]\n", ["e_JA", "twice"]),
    ("[identify]\nwindw = 2\n", ["unknown key 'windw'", "window"]),
    ("[loop]\nx = 1\n", ["unknown table [loop]"]),
    ("identify = 3\n", ["identify must be a table"]),
    ("[identify\n", ["not TOML"]),
])
def test_bad_settings_are_refused_by_name(tmp_path, text, fragments):
    f = _write(tmp_path, text)
    with pytest.raises(SettingsError) as err:
        load_settings(f)
    msg = str(err.value)
    assert str(f) in msg
    for frag in fragments:
        assert frag in msg, msg


def test_settings_from_a_mapping_name_their_source():
    with pytest.raises(SettingsError, match=r"^campaign\.toml: max_evals = 0"):
        settings_from({"max_evals": 0}, where="campaign.toml")
    assert settings_from({"tare": False}, base=Settings(window=1.0)) == Settings(window=1.0, tare=False)


def _record(folder, **over):
    M.write_measurement(folder, make_samples(), make_meta(**over))
    return M.load_measurement(folder)


def test_records_of_one_sorter_and_protocol_only(tmp_path):
    a = _record(tmp_path / "a" / "m01")
    b = _record(tmp_path / "b" / "m01")
    check_records([a, b])
    assert method_of([a]) == "statistics"   # no protocol declared: steady running
    other = _record(tmp_path / "c" / "m02", layout="layout5", wheel_type="A", id="test-02", number=2)
    with pytest.raises(RecordsError, match=r"m02: layout 'layout5' differs from .*'layout7'.*one sorter"):
        check_records([a, other])
    ss = _record(tmp_path / "d" / "m01", protocol={"name": "start-stop", "step_time": 1.0, "ramp_time": 0.5})
    assert method_of([ss]) == "grown"
    with pytest.raises(RecordsError, match=r"protocol 'start-stop' differs from .*'steady'"):
        check_records([a, ss])
    with pytest.raises(RecordsError, match="no record"):
        check_records([])


def test_the_front_door_has_few_options():
    out = subprocess.run([sys.executable, "-m", "lss_app.cli", "identify", "--help"], capture_output=True,
                         text=True, timeout=120).stdout
    options = [ln.split()[0] for ln in out.splitlines() if ln.strip().startswith("--")]
    assert len(options) <= 8, options
    assert "--settings" in options and "--model" in options


def test_one_file_holds_the_identification_and_the_loop_settings(tmp_path):
    """[identify] and [close_loop] in one file: each reader takes its table, the
    loop's defaults are the loop's own constants and reach close_loop's keywords."""
    from identification.loop import close_loop
    from identification.loop.settings import REFINE_EVALS, RESCORE_EVALS, TEST_MAX, LoopSettings, load_loop_settings
    from identification.pipeline import base_polish
    path = tmp_path / "both.toml"
    path.write_text("[identify]\nmax_evals = 40\n[close_loop]\ncandidates = 2\nrefine_evals = 0\n")
    assert load_settings(path) == Settings(max_evals=40)
    loop = load_loop_settings(path)
    assert loop == LoopSettings(candidates=2, refine_evals=0)
    assert load_loop_settings(None) == LoopSettings(
        fit_evals=RESCORE_EVALS, refine_evals=REFINE_EVALS,
        base_refine_evals=base_polish.BASE_REFINE_EVALS, profile_points=base_polish.PROFILE_POINTS,
        candidates=TEST_MAX)
    assert loop.polish == loop.max_evals == 200 and loop.regrow == 200   # growing windows: regrown
    assert LoopSettings(first_window=None).regrow == 0 and LoopSettings(polish_evals=0).polish == 0
    import inspect
    assert inspect.signature(close_loop.close_loop).parameters["settings"].default is None
