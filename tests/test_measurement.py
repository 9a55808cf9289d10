"""The measurement format: exact round trip, and every malformed input rejected
with a message naming the file, the column and the row (docs/measurements.md)."""
from __future__ import annotations

import json
import math
import shutil

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lss_fmu import design
from lss_fmu import measurement as M
from lss_fmu.variables import FORCE_CHANNELS, SPEED_CHANNELS

FS = 300.0


def make_meta(**over):
    meta = {
        "format_version": 1, "id": "test-01", "number": 1, "layout": "layout7", "wheel_type": "C",
        "coupling_type": "A", "speed_nominal": 2.0, "pretension_nominal": 0.023, "sample_rate": FS,
        "trigger_point": 19.8, "date": "2011-05-02", "notes": "unit test",
    }
    meta["design_variables"] = design.bounds_from_meta(meta)
    meta.update(over)
    return meta


def make_samples(n=600, seed=0):
    rng = np.random.default_rng(seed)
    data = {"time": np.arange(n) / FS}
    for c in FORCE_CHANNELS:
        data[c] = rng.normal(300.0, 200.0, n)
    for c in SPEED_CHANNELS:
        data[c] = rng.normal(40.0, 2.0, n)
    return pd.DataFrame(data)


@pytest.fixture
def meas(tmp_path):
    folder = tmp_path / "m01"
    M.write_measurement(folder, make_samples(), make_meta())
    return folder


def rewrite_csv(folder, edit):
    """Apply edit(lines) -> lines to samples.csv."""
    p = folder / "samples.csv"
    lines = p.read_text().split("\n")
    p.write_text("\n".join(edit(lines)))


def set_cell(lines, data_row, column, text):
    """data_row is 1-based; the file has one comment-free header and a units row."""
    cols = lines[0].split(",")
    j = cols.index(column)
    k = 1 + data_row  # header line 1, units line 2, data row 1 on line 3
    f = lines[k].split(",")
    f[j] = text
    lines[k] = ",".join(f)
    return lines


def rejected(folder, *fragments):
    with pytest.raises(M.MeasurementError) as info:
        M.load_measurement(folder)
    msg = str(info.value)
    for frag in fragments:
        assert frag in msg, f"{frag!r} not in: {msg}"
    return info.value


# -------------------------------------------------------------------------- round trip

def test_round_trip_exact(tmp_path):
    s = make_samples(1000, seed=3)
    s["transducer.joint.F_x"] = s["transducer.joint.F_x"] / 3.0 * math.pi  # long decimals
    s.loc[5, "transducer.joint.F_y"] = 5e-324       # subnormal
    s.loc[6, "transducer.joint.F_y"] = -49999.999999999993  # just within the default transducer range
    s.loc[7, "transducer.joint.F_y"] = -0.0
    meta = make_meta(notes="ünïcødé notes, \"quoted\"", operator="A. N. Other", extra_field=[1, 2, 3])
    M.write_measurement(tmp_path / "m", s, meta)
    m = M.load_measurement(tmp_path / "m")
    assert list(m.samples.columns) == M.COLUMNS
    for c in M.COLUMNS:
        a, b = s[c].to_numpy(), m.samples[c].to_numpy()
        assert a.tobytes() == b.tobytes(), c   # bit for bit, signed zero included
    assert m.meta == meta
    assert m.n_samples == 1000 and m.sample_rate == FS
    assert m.design["d"].nominal == 0.023 and m.design_source == "meta.json"
    names, nom, lo, hi = m.bounds()
    assert names == list(design.META_KEYS) and np.all(lo <= nom) and np.all(nom <= hi)
    assert m.layout_for_fmu == "layout7"


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.floats(min_value=-M.MAX_WHEEL_SPEED, max_value=M.MAX_WHEEL_SPEED), min_size=11 * 3,
                max_size=11 * 3))
def test_round_trip_any_finite_float(tmp_path, values):
    """Any float within the physical limits (issue 20: beyond them a value is refused)."""
    s = make_samples(3)
    vals = np.array(values).reshape(3, 11)
    for j, c in enumerate(M.CHANNELS):
        s[c] = vals[:, j]
    folder = tmp_path / f"h{abs(hash(tuple(values))) % 10**9}"
    M.write_measurement(folder, s, make_meta())
    back = M.load_measurement(folder).samples
    assert all(s[c].to_numpy().tobytes() == back[c].to_numpy().tobytes() for c in M.COLUMNS)
    shutil.rmtree(folder)


def test_comments_and_crlf_accepted(meas):
    p = meas / "samples.csv"
    text = p.read_text()
    p.write_bytes(("# exported from the logger\n# second comment\n" + text).replace("\n", "\r\n").encode())
    m = M.load_measurement(meas)
    assert m.n_samples == 600


def test_byte_order_mark_accepted(meas):
    """A spreadsheet's "UTF-8 CSV" export starts each file with a byte-order mark."""
    before = M.load_measurement(meas)
    for name in ("samples.csv", "meta.json"):
        p = meas / name
        p.write_bytes(b"\xef\xbb\xbf" + p.read_bytes())
    after = M.load_measurement(meas)
    assert after.samples.equals(before.samples) and after.meta == before.meta


def test_column_order_free_but_returned_canonical(meas):
    df = pd.read_csv(meas / "samples.csv", skiprows=[1])
    cols = list(reversed(M.COLUMNS))
    units = [M.UNITS[c] for c in cols]
    body = df[cols].to_numpy().tolist()
    (meas / "samples.csv").write_text("\n".join([",".join(cols), ",".join(units)]
                                                + [",".join(map(repr, r)) for r in body]) + "\n")
    assert list(M.load_measurement(meas).samples.columns) == M.COLUMNS


def test_bounds_derived_when_absent(tmp_path):
    meta = make_meta()
    del meta["design_variables"]
    M.write_measurement(tmp_path / "m", make_samples(), meta)
    m = M.load_measurement(tmp_path / "m")
    assert m.design_source.startswith("derived")
    assert m.design["v_s"].lower == pytest.approx(1.9) and m.design["s_M"].upper == pytest.approx(20.3)


def test_layout_file_relative_to_folder(tmp_path):
    from lss_fmu.layouts import resolve_layout
    folder = tmp_path / "m"
    folder.mkdir()
    shutil.copy(resolve_layout("layout7"), folder / "my_track.layout")
    M.write_measurement(folder, make_samples(), make_meta(layout="my_track.layout"), overwrite=True)
    m = M.load_measurement(folder)
    assert m.layout_for_fmu == str((folder / "my_track.layout").resolve())


def test_find_measurements_skips_answers(tmp_path):
    for n in (2, 1):
        M.write_measurement(tmp_path / f"m{n:02d}", make_samples(), make_meta(number=n, id=f"t{n}"))
    (tmp_path / "answers" / "m01").mkdir(parents=True)
    (tmp_path / "answers" / "m01" / "meta.json").write_text("{}")  # would fail if read
    found = M.find_measurements(tmp_path)
    assert [p.name for p in found] == ["m01", "m02"]
    assert [m.number for m in M.load_measurements(tmp_path, numbers=[2])] == [2]


# -------------------------------------------------------------------------- samples.csv

def test_missing_channel(meas):
    def drop(lines):
        j = lines[0].split(",").index("transducer.steering.F_left")
        return [",".join(f for i, f in enumerate(ln.split(",")) if i != j) if ln else ln for ln in lines]
    rewrite_csv(meas, drop)
    e = rejected(meas, "samples.csv", "line 1", "missing channel", "transducer.steering.F_left")
    assert e.column == "transducer.steering.F_left" and e.line == 1


def test_extra_channel(meas):
    def add(lines):
        out = [lines[0] + ",transducer.joint.M_x", lines[1] + ",N.m"]
        return out + [ln + ",0.0" if ln else ln for ln in lines[2:]]
    rewrite_csv(meas, add)
    rejected(meas, "samples.csv", "line 1", "unknown channel", "'transducer.joint.M_x'")


def test_duplicate_channel(meas):
    rewrite_csv(meas, lambda ls: [ls[0].replace("transducer.joint.F_y", "transducer.joint.F_x")] + ls[1:])
    rejected(meas, "samples.csv", "'transducer.joint.F_x'", "more than once")


def test_wrong_unit(meas):
    rewrite_csv(meas, lambda ls: [ls[0], ls[1].replace("N", "kN", 1)] + ls[2:])
    rejected(meas, "samples.csv", "line 2", "column 'transducer.joint.F_x'", "'kN'", "never converted")


def test_non_monotonic_time(meas):
    rewrite_csv(meas, lambda ls: set_cell(ls, 101, "time", repr(99 / FS)))
    e = rejected(meas, "samples.csv", "line 103", "data row 101", "column 'time'", "not strictly increasing")
    assert (e.line, e.row, e.column) == (103, 101, "time")


def test_irregular_time_gap(meas):
    # a dropped sample: remove data row 250
    rewrite_csv(meas, lambda ls: ls[:251] + ls[252:])
    rejected(meas, "samples.csv", "line 252", "data row 250", "column 'time'", "irregular time",
             "samples are missing")


def test_irregular_time_jitter(meas):
    rewrite_csv(meas, lambda ls: set_cell(ls, 400, "time", repr(399 / FS + 0.3 / FS)))
    rejected(meas, "samples.csv", "line 402", "data row 400", "irregular time", "off the 300 Hz grid")


@pytest.mark.parametrize("text,word", [("nan", "not finite"), ("NaN", "not finite"), ("inf", "not finite"),
                                       ("-Infinity", "not finite"), ("1e999", "not finite")])
def test_nan_inf(meas, text, word):
    rewrite_csv(meas, lambda ls: set_cell(ls, 57, "transducer.driving.F_right", text))
    e = rejected(meas, "samples.csv", "line 59", "data row 57", "column 'transducer.driving.F_right'", word)
    assert e.row == 57


@pytest.mark.parametrize("text", ["", "abc", "1,5", " 12.5", "1_000", "0x10"])
def test_not_a_number(meas, text):
    rewrite_csv(meas, lambda ls: set_cell(ls, 12, "transducer.wheel.w_dl", text))
    e = rejected(meas, "samples.csv", "line 14", "data row 12")
    assert e.line == 14


def test_wrong_field_count_and_empty_line(meas):
    rewrite_csv(meas, lambda ls: ls[:30] + [ls[30] + ",1.0"] + ls[31:])
    rejected(meas, "samples.csv", "line 31", "13 fields, the header has 12")
    M.write_measurement(meas, make_samples(), make_meta(), overwrite=True)
    rewrite_csv(meas, lambda ls: ls[:40] + [""] + ls[40:])
    rejected(meas, "samples.csv", "line 41", "empty line")


def test_wrong_sample_rate(meas):
    meta = json.loads((meas / "meta.json").read_text())
    meta["sample_rate"] = 250.0
    (meas / "meta.json").write_text(json.dumps(meta))
    e = rejected(meas, "samples.csv", "column 'time'", "wrong sample rate", "meta.json says 250 Hz",
                 "sampled at 300 Hz")
    assert e.column == "time"


def test_too_few_samples_and_no_units(tmp_path):
    with pytest.raises(M.MeasurementError, match="at least 2 samples"):
        M.write_measurement(tmp_path / "a", make_samples(1), make_meta())
    M.write_measurement(tmp_path / "b", make_samples(), make_meta())
    rewrite_csv(tmp_path / "b", lambda ls: ls[:1] + ls[2:])
    rejected(tmp_path / "b", "samples.csv", "line 2")


def test_missing_files(tmp_path, meas):
    (meas / "samples.csv").unlink()
    rejected(meas, "samples.csv", "file not found")
    rejected(tmp_path / "nowhere", "no such measurement folder")


# -------------------------------------------------------------------------- meta.json

def edit_meta(folder, **changes):
    p = folder / "meta.json"
    meta = json.loads(p.read_text())
    for k, v in changes.items():
        if v is _DELETE:
            del meta[k]
        else:
            meta[k] = v
    p.write_text(json.dumps(meta, indent=2))


_DELETE = object()


def test_unknown_layout(meas):
    edit_meta(meas, layout="layout99")
    e = rejected(meas, "meta.json", "field 'layout'", "unknown layout 'layout99'")
    assert e.column == "layout"


def test_layout_disagrees_with_cart_type(meas):
    edit_meta(meas, wheel_type="A")
    rejected(meas, "meta.json", "field 'wheel_type'", "layout 'layout7' has wheel type 'C'")


def test_trigger_point_off_track(meas):
    edit_meta(meas, trigger_point=70.0)
    rejected(meas, "meta.json", "field 'trigger_point'", "not on the track", "65.000 m")


@pytest.mark.parametrize("field,value,words", [
    ("sample_rate", "300", ["field 'sample_rate'", "must be a number", "the string \"300\""]),
    ("speed_nominal", True, ["field 'speed_nominal'", "must be a number", "boolean"]),
    ("number", 3.0, ["field 'number'", "must be an integer", "the number 3.0"]),
    ("format_version", "1", ["field 'format_version'", "must be an integer"]),
    ("layout", 7, ["field 'layout'", "must be a string", "the integer 7"]),
    ("notes", ["a"], ["field 'notes'", "must be a string", "an array"]),
    ("date", "02/05/2011", ["field 'date'", "ISO date"]),
    ("date", 20110502, ["field 'date'", "must be a string"]),
    ("design_variables", [], ["field 'design_variables'", "must be an object"]),
    ("wheel_type", "D", ["field 'wheel_type'", "one of A, B, C"]),
    ("sample_rate", -300.0, ["field 'sample_rate'", "must be positive"]),
    ("format_version", 2, ["field 'format_version'", "not supported"]),
    ("id", _DELETE, ["meta.json", "required field missing: id"]),
])
def test_meta_wrong_type_or_value(meas, field, value, words):
    edit_meta(meas, **{field: value})
    e = rejected(meas, "meta.json", *words)
    if value is not _DELETE:
        assert e.column == field


def test_design_variable_errors(meas):
    meta = json.loads((meas / "meta.json").read_text())
    dv = meta["design_variables"]
    dv["d"]["lower"] = "0.01"
    edit_meta(meas, design_variables=dv)
    rejected(meas, "field 'design_variables.d.lower'", "must be a number")
    dv["d"]["lower"] = 0.05   # above nominal
    edit_meta(meas, design_variables=dv)
    rejected(meas, "field 'design_variables.d'", "lower <= nominal <= upper")
    dv["d"]["lower"] = 0.01
    del dv["mu_d"]
    edit_meta(meas, design_variables=dv)
    rejected(meas, "field 'design_variables'", "lacks mu_d")


def test_meta_not_json(meas):
    (meas / "meta.json").write_text('{"id": "x",\n "sample_rate": NaN}')
    rejected(meas, "meta.json", "not valid JSON")
    (meas / "meta.json").write_text('{"id": "x",\n  "layout" "layout7"}')
    e = rejected(meas, "meta.json", "line 2", "not valid JSON")
    assert e.line == 2
    (meas / "meta.json").write_text('[1, 2]')
    rejected(meas, "meta.json", "must hold a JSON object")


def test_writer_refuses_bad_input(tmp_path):
    s = make_samples()
    s.loc[10, "transducer.joint.F_z"] = np.nan
    with pytest.raises(M.MeasurementError, match="data row 11.*transducer.joint.F_z|transducer.joint.F_z.*"):
        M.write_measurement(tmp_path / "m", s, make_meta())
    assert not (tmp_path / "m").exists()
    with pytest.raises(M.MeasurementError, match="field 'sample_rate'"):
        M.write_measurement(tmp_path / "m", make_samples(), make_meta(sample_rate="fast"))
    M.write_measurement(tmp_path / "m", make_samples(), make_meta())
    with pytest.raises(FileExistsError):
        M.write_measurement(tmp_path / "m", make_samples(), make_meta())


# -------------------------------------------------------------------------- hostile input (issue 20)

def test_header_check_is_linear_with_a_short_message():
    import time
    cols = M.COLUMNS + [f"x{i}" for i in range(40_000)]
    start = time.perf_counter()
    with pytest.raises(M.MeasurementError) as info:
        M._check_columns(cols, "samples.csv", 1)
    assert time.perf_counter() - start < 0.5
    assert "40,012 columns" in str(info.value) and len(str(info.value)) < 400
    # within the column limit, many unknown and duplicated names: listed, then counted
    with pytest.raises(M.MeasurementError, match=r"and 42 more") as info:
        M._check_columns(M.COLUMNS + [f"y{i}" for i in range(50)], "samples.csv", 1)
    assert len(str(info.value)) < 600
    with pytest.raises(M.MeasurementError, match=r"appear more than once"):
        M._check_columns(M.COLUMNS + ["z"] * 20 + ["w"] * 3, "samples.csv", 1)


def test_two_million_columns_are_refused_at_once(meas):
    import time
    p = meas / "samples.csv"
    lines = p.read_text().split("\n")
    lines[0] = lines[0] + ",x" * 2_000_000
    p.write_text("\n".join(lines))
    start = time.perf_counter()
    err = rejected(meas, "samples.csv", "line 1", "more than the reader's limit of 4,096 per line")
    assert time.perf_counter() - start < 5 and len(str(err)) < 300


def test_file_size_limit(meas, monkeypatch):
    monkeypatch.setattr(M, "MAX_SAMPLES_BYTES", 10_000)
    rejected(meas, "samples.csv", "more than the reader's limit of 10,000 bytes")


def test_fifo_is_refused_without_blocking(meas):
    import os
    if not hasattr(os, "mkfifo"):
        pytest.skip("no FIFOs here")
    (meas / "samples.csv").unlink()
    os.mkfifo(meas / "samples.csv")
    rejected(meas, "samples.csv", "not a regular file")


@pytest.mark.parametrize("column,value,fragment", [
    ("transducer.joint.F_x", "1e308", "beyond the force transducer's range of 50000 N"),
    ("transducer.driving.F_left", "-50000.5", "beyond the force transducer's range"),
    ("transducer.wheel.w_sl", "5000", "beyond 1000 rad/s"),
])
def test_physically_absurd_values_name_file_row_and_column(meas, column, value, fragment):
    rewrite_csv(meas, lambda lines: set_cell(lines, 7, column, value))
    err = rejected(meas, "samples.csv", "line 9 (data row 7)", f"column '{column}'", fragment)
    assert err.row == 7 and err.column == column


def test_declared_force_range(tmp_path):
    s = make_samples()
    meta = make_meta(sensor={"force_range_N": {"transducer.joint.F_x": 400.0}})
    with pytest.raises(M.MeasurementError, match=r"range of 400 N"):
        M.write_measurement(tmp_path / "a", s, meta)
    with pytest.raises(M.MeasurementError, match=r"sensor.force_range_N"):
        M.validate_meta(make_meta(sensor={"force_range_N": -1}), check_layout=False)
    M.write_measurement(tmp_path / "b", s, make_meta(sensor={"force_range_N": 2000.0}))


@pytest.mark.parametrize("field,value", [("speed_nominal", 1e300), ("speed_nominal", 25.0),
                                         ("pretension_nominal", 3.0), ("sample_rate", 1e300),
                                         ("mu_roll_nominal", 7.0)])
def test_absurd_nominal_values_are_refused(field, value):
    with pytest.raises(M.MeasurementError) as info:
        M.validate_meta(make_meta(**{field: value}), check_layout=False)
    assert info.value.column == field


def test_window_longer_than_the_record_names_option_value_and_length(meas):
    from identification.objective.problem import from_measurement
    m = M.load_measurement(meas)
    with pytest.raises(ValueError, match=r"window = 1e\+09 s is longer than the record of test-01 \(1.99667 s, 600"):
        from_measurement(m, "LW", window=1e9)
    for bad in (float("nan"), float("inf"), 0.0, -1.0):
        with pytest.raises(ValueError, match="window"):
            from_measurement(m, "LW", window=bad)
