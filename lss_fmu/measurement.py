"""Measurement files: one folder per measurement (docs/measurements.md).

    MEAS/
      samples.csv   comment lines '# ...' (optional), a header row with the
                    column names, a units row, then one row per sample:
                    time (s), the 7 forces (N), the 4 wheel speeds (rad/s)
      meta.json     what the test engineer wrote down (layout, cart type,
                    nominal speed and pretension, sample rate, trigger point,
                    date, notes) and the nominal values and bounds of the
                    layout-dependent design variables

The same reader takes real logger exports and the virtual transducer cart's
output. It checks everything and changes nothing: a file that does not fit is
rejected with a `MeasurementError` naming the file, the line (and data row)
and the column; no sample is dropped, reordered in time or resampled.

    from lss_fmu.measurement import load_measurement
    m = load_measurement("data/recovery/mNN")
    m.samples            # DataFrame: time + 11 channels, as in the file
    m.forces             # the 7 force channels (DataFrame)
    m.meta               # dict from meta.json
    m.design             # {'v_s': DesignBounds(nominal, lower, upper, unit), ...}
    m.layout_for_fmu     # what to give the FMU's layout.name
"""
from __future__ import annotations

import datetime as _dt
import json
import math
import os
import stat
from collections import Counter
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Mapping, Optional, Union

import numpy as np
import pandas as pd

from .layout_format import LayoutError
from . import design, protocol
from .variables import BY_NAME, FORCE_CHANNELS, SPEED_CHANNELS

FORMAT_VERSION = 1
SAMPLES_FILE = "samples.csv"
META_FILE = "meta.json"
TIME = "time"
CHANNELS = FORCE_CHANNELS + SPEED_CHANNELS
COLUMNS = [TIME] + CHANNELS
UNITS = {TIME: "s", **{c: BY_NAME[c].unit for c in CHANNELS}}
TIME_TOLERANCE = 0.05       # a time stamp may miss its grid point by this fraction of the interval
RATE_TOLERANCE = 1e-3       # relative: the rate in meta.json against the time column

# Hard limits of the reader (docs/measurements.md, "Limits"): a file beyond them
# is refused with a message before it costs time or memory.
MAX_SAMPLES_BYTES = 256 << 20   # samples.csv
MAX_META_BYTES = 1 << 20        # meta.json
MAX_COLUMNS = 64                # fields in the header row (the format has 12)
MAX_LINE_CHARS = 4096           # characters in any line of samples.csv
MAX_LISTED = 8                  # names listed in a message before "and N more"
# Physical limits of the values: a force beyond the transducer's range (meta.json
# sensor.force_range_N, a number or one per channel; else this default), a
# wheel speed beyond what the fastest drive could turn the smallest wheel at
FORCE_RANGE_DEFAULT = 50e3      # N, per channel
MAX_WHEEL_SPEED = 1000.0        # rad/s: 20 m/s (drive.v_ref's limit) on a 35 mm wheel is 571 rad/s
MAX_SAMPLE_RATE = 1e6           # Hz
# nominal values in meta.json must lie within the FMU's range of what they set
META_RANGES = {"speed_nominal": "drive.v_ref", "pretension_nominal": "chain.pretension",
               "mu_roll_nominal": "wheel.mu_roll", "Kp_nominal": "drive.Kp", "Ki_nominal": "drive.Ki"}

# meta.json fields: name -> (type, unit or description); type 'number' is int or float
REQUIRED_META = {
    "format_version": ("int", f"format version, {FORMAT_VERSION}"),
    "id": ("str", "measurement id"),
    "layout": ("str", "built-in layout name or layout file (relative to the folder)"),
    "wheel_type": ("str", "A, B or C"),
    "coupling_type": ("str", "A or B"),
    "speed_nominal": ("number", "m/s"),
    "pretension_nominal": ("number", "m"),
    "sample_rate": ("number", "Hz"),
    "trigger_point": ("number", "m"),
    "date": ("str", "ISO date YYYY-MM-DD or date and time"),
}
OPTIONAL_META = {
    "number": ("int", "measurement number"),
    "set": ("str", "campaign or set name"),
    "notes": ("str", "free text"),
    "operator": ("str", "who measured"),
    "site": ("str", "where"),
    "transducer_cart": ("str", "transducer cart id"),
    "source": ("str", "logger, export or generator"),
    "mu_roll_nominal": ("number", "rolling resistance coefficient from the wheel data sheet"),
    "Kp_nominal": ("number", "N.s/m per motor"),
    "Ki_nominal": ("number", "N/m per motor"),
    "design_variables": ("dict", "nominal value and bounds of v_s, d, mu_d, s_M, K_P, K_I"),
    "sensor": ("dict", "sensor and logger description"),
    "protocol": ("protocol", "what the sorter did: steady, start-up, speed-step, stop or start-stop (lss_fmu.protocol)"),
}
WHEEL_TYPES, COUPLING_TYPES = ("A", "B", "C"), ("A", "B")


def _unit(symbol: str) -> str:
    return design.UNIT[design.BY_SYMBOL[symbol]]


class MeasurementError(ValueError):
    """A measurement that cannot be used. `path` is the file, `line` the 1-based
    line in it (header = first non-comment line), `row` the 1-based data row,
    `column` the column or meta.json field; any of them may be None."""

    def __init__(self, message: str, path=None, column: Optional[str] = None,
                 line: Optional[int] = None, row: Optional[int] = None):
        self.message, self.path, self.column, self.line, self.row = message, path, column, line, row
        where = []
        if line is not None:
            where.append(f"line {line}" + (f" (data row {row})" if row is not None else ""))
        elif row is not None:
            where.append(f"data row {row}")
        if column is not None:
            where.append(f"column '{column}'" if str(path or "").endswith(".csv") else f"field '{column}'")
        head = str(path) if path is not None else ""
        if where:
            head = f"{head}: {', '.join(where)}" if head else ", ".join(where)
        super().__init__(f"{head}: {message}" if head else message)


@dataclass(frozen=True)
class DesignBounds:
    """One layout-dependent design variable of a measurement."""
    nominal: float
    lower: float
    upper: float
    unit: str


# ----------------------------------------------------------------------------------------
# the measurement object

@dataclass
class Measurement:
    path: Path                      # the folder
    meta: dict
    samples: pd.DataFrame           # 'time' and the 11 channels, in the order of COLUMNS
    design_source: str = "meta.json"

    @property
    def id(self) -> str:
        return self.meta["id"]

    @property
    def number(self) -> Optional[int]:
        return self.meta.get("number")

    @property
    def sample_rate(self) -> float:
        return float(self.meta["sample_rate"])

    @property
    def time(self) -> np.ndarray:
        return self.samples[TIME].to_numpy()

    @property
    def forces(self) -> pd.DataFrame:
        return self.samples[FORCE_CHANNELS]

    @property
    def speeds(self) -> pd.DataFrame:
        return self.samples[SPEED_CHANNELS]

    @property
    def n_samples(self) -> int:
        return len(self.samples)

    @property
    def duration(self) -> float:
        """Logged time span, s (n_samples / sample_rate)."""
        return self.n_samples / self.sample_rate

    @property
    def layout(self) -> str:
        return self.meta["layout"]

    @property
    def protocol(self):
        """What the sorter did while the cart logged (lss_fmu.protocol.Protocol)."""
        return protocol_of(self.meta, self.path / META_FILE, self.duration)

    @property
    def layout_for_fmu(self) -> str:
        """The FMU's layout.name: the built-in name or the absolute path of the file."""
        return _layout_for_fmu(self.meta["layout"], self.path)

    @cached_property
    def track(self):
        from .layouts import load_track
        return load_track(self.layout_for_fmu)

    @property
    def design(self) -> dict:
        dv = self.meta.get("design_variables") or design.bounds_from_meta(self.meta)
        return {k: DesignBounds(float(dv[k]["nominal"]), float(dv[k]["lower"]), float(dv[k]["upper"]),
                                dv[k].get("unit", _unit(k))) for k in design.META_KEYS}

    def bounds(self):
        """(names, nominal, lower, upper) of the layout-dependent design variables (Eq. 13 order)."""
        d = self.design
        names = list(design.META_KEYS)
        return (names, np.array([d[k].nominal for k in names]), np.array([d[k].lower for k in names]),
                np.array([d[k].upper for k in names]))

    def fmu_bounds(self) -> dict:
        """{FMU name: (lower, upper)} of the layout-dependent design variables
        (drive.v_ref, chain.pretension, ..., trigger.s_M; lss_fmu.design)."""
        return {design.BY_SYMBOL[k]: (v.lower, v.upper) for k, v in self.design.items()}

    def fmu_nominal(self) -> dict:
        """{FMU name: nominal value} of the layout-dependent design variables."""
        return {design.BY_SYMBOL[k]: v.nominal for k, v in self.design.items()}

    def __repr__(self) -> str:
        return (f"Measurement({self.id!r}, layout={self.layout!r}, {self.n_samples} samples at "
                f"{self.sample_rate:g} Hz, {self.duration:.1f} s)")


def _layout_for_fmu(layout: str, folder: Path) -> str:
    from .layouts import builtin_layouts
    if layout in builtin_layouts():
        return layout
    p = Path(layout).expanduser()
    if not p.is_absolute():
        p = Path(folder) / p
    return str(p.resolve())


# ----------------------------------------------------------------------------------------
# metadata

def _type_ok(value, kind: str) -> bool:
    if kind == "int":
        return isinstance(value, int) and not isinstance(value, bool)
    if kind == "number":
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if kind == "str":
        return isinstance(value, str)
    if kind == "dict":
        return isinstance(value, dict)
    if kind == "protocol":
        return isinstance(value, (dict, str))
    raise AssertionError(kind)


_KIND_WORDS = {"int": "an integer", "number": "a number", "str": "a string", "dict": "an object",
               "protocol": "an object or a protocol name"}


def _json_kind(value) -> str:
    if isinstance(value, bool):
        return f"the boolean {json.dumps(value)}"
    if isinstance(value, int):
        return f"the integer {value}"
    if isinstance(value, float):
        return f"the number {value!r}"
    if isinstance(value, str):
        return f"the string {json.dumps(value[:40])}"
    if value is None:
        return "null"
    if isinstance(value, list):
        return "an array"
    return "an object"


def validate_meta(meta, path="meta.json", folder: Optional[Path] = None, check_layout: bool = True) -> dict:
    """Check a metadata dict; returns it unchanged, or raises MeasurementError
    naming the field. With check_layout the layout must resolve (relative to
    `folder`) and agree with the wheel and coupling types and the trigger point."""
    if not isinstance(meta, dict):
        raise MeasurementError(f"must hold a JSON object, got {_json_kind(meta)}", path)
    missing = [k for k in REQUIRED_META if k not in meta]
    if missing:
        raise MeasurementError(f"required field{'s' if len(missing) > 1 else ''} missing: "
                               + ", ".join(missing), path)
    for table in (REQUIRED_META, OPTIONAL_META):
        for key, (kind, what) in table.items():
            if key not in meta:
                continue
            v = meta[key]
            if not _type_ok(v, kind):
                raise MeasurementError(f"must be {_KIND_WORDS[kind]} ({what}), got {_json_kind(v)}", path, key)
            if kind == "number" and not math.isfinite(v):
                raise MeasurementError(f"must be finite, got {v!r}", path, key)
    if meta["format_version"] != FORMAT_VERSION:
        raise MeasurementError(f"format version {meta['format_version']} is not supported "
                               f"(this reader knows {FORMAT_VERSION})", path, "format_version")
    if not meta["id"].strip():
        raise MeasurementError("must not be empty", path, "id")
    if meta["wheel_type"] not in WHEEL_TYPES:
        raise MeasurementError(f"must be one of {', '.join(WHEEL_TYPES)}, got {meta['wheel_type']!r}",
                               path, "wheel_type")
    if meta["coupling_type"] not in COUPLING_TYPES:
        raise MeasurementError(f"must be one of {', '.join(COUPLING_TYPES)}, got {meta['coupling_type']!r}",
                               path, "coupling_type")
    for key in ("speed_nominal", "sample_rate"):
        if not meta[key] > 0:
            raise MeasurementError(f"must be positive, got {meta[key]!r}", path, key)
    for key in ("pretension_nominal", "trigger_point", "mu_roll_nominal", "Kp_nominal", "Ki_nominal"):
        if key in meta and meta[key] < 0:
            raise MeasurementError(f"must not be negative, got {meta[key]!r}", path, key)
    for key, fmu_name in META_RANGES.items():
        hi = BY_NAME[fmu_name].max
        if key in meta and hi is not None and meta[key] > hi:
            raise MeasurementError(f"{meta[key]!r} is beyond what the model can run ({fmu_name} <= {hi:g} "
                                   f"{BY_NAME[fmu_name].unit or ''})".rstrip(), path, key)
    if meta["sample_rate"] > MAX_SAMPLE_RATE:
        raise MeasurementError(f"{meta['sample_rate']!r} Hz is beyond {MAX_SAMPLE_RATE:g} Hz", path, "sample_rate")
    if "sensor" in meta:
        force_ranges(meta, path)
        sensor_spreads(meta, path)
    try:
        _parse_date(meta["date"])
    except ValueError:
        raise MeasurementError(f"must be an ISO date (YYYY-MM-DD, optionally with a time), got "
                               f"{meta['date']!r}", path, "date") from None
    if "design_variables" in meta:
        _validate_design(meta["design_variables"], path)
    protocol_of(meta, path)
    if check_layout:
        _validate_layout(meta, path, folder if folder is not None else Path(path).parent)
    return meta


def protocol_of(meta: Mapping, path="meta.json", duration: Optional[float] = None):
    """The record's protocol (lss_fmu.protocol), checked; a MeasurementError
    names the meta.json field and the value the FMU cannot follow."""
    try:
        return protocol.from_meta(meta).check(float(meta["speed_nominal"]), duration)
    except protocol.ProtocolError as exc:
        raise MeasurementError(str(exc).split(": ", 1)[1], path, f"protocol.{exc.field}".rstrip(".")) from None


def force_ranges(meta: Optional[Mapping], path="meta.json") -> dict:
    """{force channel: range in N}: meta.json's sensor.force_range_N (a number
    for every channel, or one per channel), else FORCE_RANGE_DEFAULT."""
    spec = ((meta or {}).get("sensor") or {}).get("force_range_N") if isinstance((meta or {}).get("sensor"), dict) \
        else None
    out = {c: FORCE_RANGE_DEFAULT for c in FORCE_CHANNELS}
    if spec is None:
        return out
    items = spec.items() if isinstance(spec, dict) else ((c, spec) for c in FORCE_CHANNELS)
    for c, v in items:
        if c not in out:
            raise MeasurementError(f"unknown force channel {str(c)[:40]!r}", path, "sensor.force_range_N")
        if not _type_ok(v, "number") or not (math.isfinite(v) and v > 0):
            raise MeasurementError(f"must be a positive number of newtons, got {_json_kind(v)}", path,
                                   "sensor.force_range_N")
        out[c] = float(v)
    return out


def sensor_spreads(meta: Optional[Mapping], path="meta.json") -> None:
    """Check meta.json's sensor.force_noise_std_N (each > 0: the likelihood
    weighs a channel by 1 / sigma^2) and sensor.force_offset_std_N (each >= 0);
    a channel left out is the virtual cart's or estimated where it is used."""
    sensor = (meta or {}).get("sensor")
    if not isinstance(sensor, dict):
        return
    for key, least in (("force_noise_std_N", "positive"), ("force_offset_std_N", "not negative")):
        spec = sensor.get(key)
        if spec is None:
            continue
        field = f"sensor.{key}"
        if not isinstance(spec, dict):
            raise MeasurementError(f"must be an object {{force channel: N}}, got {_json_kind(spec)}", path, field)
        for c, v in spec.items():
            if c not in FORCE_CHANNELS:
                raise MeasurementError(f"unknown force channel {str(c)[:40]!r}", path, field)
            ok = _type_ok(v, "number") and math.isfinite(v) and (v > 0 if least == "positive" else v >= 0)
            if not ok:
                raise MeasurementError(f"{c}: must be a {least} number of newtons, got {_json_kind(v)}", path, field)


def _listed(names, k: int = MAX_LISTED) -> str:
    """'a', 'b', ... and N more: a bounded list of names for a message."""
    names = list(names)
    shown = ", ".join(repr(str(n)[:40]) for n in names[:k])
    return shown + (f" and {len(names) - k:,} more" if len(names) > k else "")


def _read_limited(path: Path, limit: int) -> bytes:
    """The bytes of a regular file of at most `limit` bytes. A FIFO, device or
    directory is refused without blocking (opened non-blocking, checked on
    the open file), as the FMU's layout reader does."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0))
    except FileNotFoundError:
        raise MeasurementError("file not found", path) from None
    except OSError as exc:
        raise MeasurementError(f"cannot read: {exc.strerror or exc}", path) from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise MeasurementError("is not a regular file (a directory, FIFO or device is not read)", path)
        if st.st_size > limit:
            raise MeasurementError(f"is {st.st_size:,} bytes, more than the reader's limit of {limit:,} bytes", path)
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        with os.fdopen(fd, "rb") as f:
            fd = -1
            data = f.read(limit + 1)
    except OSError as exc:
        raise MeasurementError(f"cannot read: {exc.strerror or exc}", path) from None
    finally:
        if fd >= 0:
            os.close(fd)
    if len(data) > limit:
        raise MeasurementError(f"is more than the reader's limit of {limit:,} bytes", path)
    return data


def _parse_date(text: str):
    try:
        return _dt.date.fromisoformat(text)
    except ValueError:
        return _dt.datetime.fromisoformat(text)


def _validate_design(dv, path) -> None:
    if not isinstance(dv, dict):
        raise MeasurementError(f"must be an object, got {_json_kind(dv)}", path, "design_variables")
    missing = [k for k in design.META_KEYS if k not in dv]
    if missing:
        raise MeasurementError(f"lacks {', '.join(missing)} (needs {', '.join(design.META_KEYS)})",
                               path, "design_variables")
    extra = [k for k in dv if k not in design.META_KEYS]
    if extra:
        raise MeasurementError(f"unknown design variable{'s' if len(extra) > 1 else ''} {', '.join(extra)} "
                               f"(known: {', '.join(design.META_KEYS)})", path, "design_variables")
    for k in design.META_KEYS:
        entry = dv[k]
        name = f"design_variables.{k}"
        if not isinstance(entry, dict):
            raise MeasurementError(f"must be an object with nominal, lower, upper, got {_json_kind(entry)}",
                                   path, name)
        for f in ("nominal", "lower", "upper"):
            if f not in entry:
                raise MeasurementError("missing", path, f"{name}.{f}")
            v = entry[f]
            if not _type_ok(v, "number"):
                raise MeasurementError(f"must be a number ({_unit(k)}), got {_json_kind(v)}",
                                       path, f"{name}.{f}")
            if not math.isfinite(v):
                raise MeasurementError(f"must be finite, got {v!r}", path, f"{name}.{f}")
        if "unit" in entry and entry["unit"] != _unit(k):
            raise MeasurementError(f"unit must be {_unit(k)!r}, got {entry['unit']!r}",
                                   path, f"{name}.unit")
        if not entry["lower"] <= entry["nominal"] <= entry["upper"] or not entry["lower"] < entry["upper"]:
            raise MeasurementError(f"needs lower < upper and lower <= nominal <= upper, got lower "
                                   f"{entry['lower']!r}, nominal {entry['nominal']!r}, upper {entry['upper']!r}",
                                   path, name)


_TRACK_CACHE: dict = {}


def _validate_layout(meta, path, folder: Path) -> None:
    from .layouts import load_spec, load_track, resolve_layout
    layout = meta["layout"]
    target = _layout_for_fmu(layout, folder)
    try:
        resolve_layout(target)
        spec = load_spec(target)
    except LayoutError as exc:
        raise MeasurementError(f"unknown layout {layout!r}: {exc}", path, "layout") from None
    if spec.wheel != meta["wheel_type"]:
        raise MeasurementError(f"is {meta['wheel_type']!r} but layout {layout!r} has wheel type {spec.wheel!r}",
                               path, "wheel_type")
    if spec.coupling != meta["coupling_type"]:
        raise MeasurementError(f"is {meta['coupling_type']!r} but layout {layout!r} has coupling type "
                               f"{spec.coupling!r}", path, "coupling_type")
    key = (target, os.path.getmtime(resolve_layout(target)))
    track = _TRACK_CACHE.get(key)
    if track is None:
        try:
            track = load_track(target)
        except LayoutError as exc:
            raise MeasurementError(f"layout {layout!r} cannot be used: {exc}", path, "layout") from None
        _TRACK_CACHE[key] = track
    if not meta["trigger_point"] < track.length:
        raise MeasurementError(f"{meta['trigger_point']!r} m is not on the track (layout {layout!r} is "
                               f"{track.length:.3f} m long)", path, "trigger_point")


def read_meta(path: Union[str, Path], check_layout: bool = True) -> dict:
    path = Path(path)
    try:
        # utf-8-sig: a spreadsheet's "UTF-8" export starts with a byte-order mark
        text = _read_limited(path, MAX_META_BYTES).decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise MeasurementError(f"cannot read: {exc}", path) from None
    try:
        meta = json.loads(text, parse_constant=_reject_constant)
    except json.JSONDecodeError as exc:
        raise MeasurementError(f"not valid JSON: {exc.msg} (column {exc.colno})", path, line=exc.lineno) from None
    except ValueError as exc:
        raise MeasurementError(str(exc), path) from None
    return validate_meta(meta, path, path.parent, check_layout)


def _reject_constant(name):
    raise ValueError(f"not valid JSON: {name} is not a JSON number")


# ----------------------------------------------------------------------------------------
# samples

def validate_samples(df: pd.DataFrame, sample_rate: float, path="samples", line_of_row=None,
                     force_range: Optional[Mapping] = None) -> None:
    """Columns, finiteness, strictly increasing regular time at sample_rate;
    forces within the transducer's range (`force_range`: {channel: N}, default
    FORCE_RANGE_DEFAULT) and wheel speeds within MAX_WHEEL_SPEED."""
    cols = list(df.columns)
    _check_columns(cols, path, header_line=None)
    n = len(df)
    if n < 2:
        raise MeasurementError(f"needs at least 2 samples, has {n}", path)
    line_of_row = line_of_row or (lambda r: None)
    for c in COLUMNS:
        x = df[c].to_numpy()
        if x.dtype.kind not in "fiu":
            raise MeasurementError(f"is not numeric (dtype {x.dtype})", path, c)
        bad = np.nonzero(~np.isfinite(x.astype(float)))[0]
        if len(bad):
            r = int(bad[0])
            raise MeasurementError(f"value {float(x[r])!r} is not finite (NaN or Inf): a gap in the logger's "
                                   f"record must be cut or filled by hand, not here"
                                   + (f" ({len(bad)} such values)" if len(bad) > 1 else ""),
                                   path, c, line_of_row(r), r + 1)
    ranges = dict(force_range or {})
    for c in CHANNELS:
        limit = ranges.get(c, FORCE_RANGE_DEFAULT) if c in FORCE_CHANNELS else MAX_WHEEL_SPEED
        x = df[c].to_numpy(dtype=float)
        bad = np.nonzero(np.abs(x) > limit)[0]
        if len(bad):
            r = int(bad[0])
            what = ("the force transducer's range of {:g} N (meta.json sensor.force_range_N; default {:g} N)"
                    .format(limit, FORCE_RANGE_DEFAULT) if c in FORCE_CHANNELS else
                    f"{MAX_WHEEL_SPEED:g} rad/s, faster than any drive turns a wheel")
            raise MeasurementError(f"value {float(x[r])!r} {UNITS[c]} is beyond {what}"
                                   + (f" ({len(bad):,} such values)" if len(bad) > 1 else ""),
                                   path, c, line_of_row(r), r + 1)
    _check_time(df[TIME].to_numpy(dtype=float), float(sample_rate), path, line_of_row)


def _check_columns(cols, path, header_line):
    """Linear in the number of columns; a message lists at most MAX_LISTED names."""
    if len(cols) > MAX_COLUMNS:
        raise MeasurementError(f"{len(cols):,} columns, more than the reader's limit of {MAX_COLUMNS} (the format "
                               f"has {len(COLUMNS)}: {', '.join(COLUMNS)})", path, line=header_line)
    counts = Counter(cols)
    dup = sorted(c for c, k in counts.items() if k > 1)
    if dup:
        raise MeasurementError(f"column{'s' if len(dup) > 1 else ''} {_listed(dup)} "
                               f"appear more than once", path, line=header_line)
    known = set(COLUMNS)
    missing = [c for c in COLUMNS if c not in counts]
    extra = [c for c in cols if c not in known]
    if missing:
        raise MeasurementError(f"missing channel{'s' if len(missing) > 1 else ''}: {', '.join(missing)}"
                               + (f" (found instead: {_listed(extra)})" if extra else ""),
                               path, missing[0], header_line)
    if extra:
        raise MeasurementError(f"unknown channel{'s' if len(extra) > 1 else ''} {_listed(extra)}"
                               f" (the columns are {', '.join(COLUMNS)})", path, str(extra[0])[:40], header_line)


def _check_time(t: np.ndarray, rate: float, path, line_of_row) -> None:
    dt = np.diff(t)
    bad = np.nonzero(~(dt > 0))[0]
    if len(bad):
        r = int(bad[0]) + 1
        raise MeasurementError(f"time is not strictly increasing: {float(t[r])!r} s follows {float(t[r - 1])!r} s",
                               path, TIME, line_of_row(r), r + 1)
    h = 1.0 / rate
    med = float(np.median(dt))
    if abs(med - h) > RATE_TOLERANCE * h:
        raise MeasurementError(f"wrong sample rate: meta.json says {rate:g} Hz, the time column is "
                               f"sampled at {1.0 / med:.6g} Hz (median interval {med:.6g} s)",
                               path, TIME)
    k = np.arange(len(t))
    off = np.abs(t - (t[0] + k * h))
    bad = np.nonzero(off > TIME_TOLERANCE * h)[0]
    if len(bad):
        r = int(bad[0])
        gap = t[r] - t[r - 1]
        what = (f"a gap of {gap:.6g} s ({gap * rate:.3g} intervals) after {float(t[r - 1])!r} s: samples are "
                f"missing" if gap > 1.5 * h else f"time {float(t[r])!r} s is {t[r] - (t[0] + r * h):+.3g} s off "
                f"the {rate:g} Hz grid")
        raise MeasurementError(f"irregular time: {what} (tolerance {TIME_TOLERANCE:g} of the interval)",
                               path, TIME, line_of_row(r), r + 1)


def read_samples(path: Union[str, Path], sample_rate: float, force_range: Optional[Mapping] = None) -> pd.DataFrame:
    """Read and check samples.csv; the columns are returned in the order of COLUMNS.
    Linear in the file's size; the limits MAX_SAMPLES_BYTES, MAX_LINE_CHARS and
    MAX_COLUMNS apply (docs/measurements.md)."""
    path = Path(path)
    raw = _read_limited(path, MAX_SAMPLES_BYTES)
    try:
        text = raw.decode("utf-8-sig")   # a byte-order mark (a spreadsheet's export) is not part of the header
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise MeasurementError("not UTF-8 text", path, line=line) from None
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    lines = [ln[:-1] if ln.endswith("\r") else ln for ln in lines]
    long = next((k for k, ln in enumerate(lines) if len(ln) > MAX_LINE_CHARS), None)
    if long is not None:
        raise MeasurementError(f"{len(lines[long]):,} characters, more than the reader's limit of "
                               f"{MAX_LINE_CHARS:,} per line", path, line=long + 1)
    i = 0
    while i < len(lines) and lines[i].startswith("#"):
        i += 1
    if i >= len(lines):
        raise MeasurementError("no header row (the column names)", path)
    header_line = i + 1
    cols = [c.strip() for c in lines[i].split(",")]
    _check_columns(cols, path, header_line)
    if i + 1 >= len(lines):
        raise MeasurementError("no units row after the header", path, line=header_line + 1)
    units = [u.strip() for u in lines[i + 1].split(",")]
    if len(units) != len(cols):
        raise MeasurementError(f"the units row has {len(units)} fields, the header {len(cols)}",
                               path, line=header_line + 1)
    for c, u in zip(cols, units):
        if u != UNITS[c]:
            raise MeasurementError(f"unit {u!r} is not {UNITS[c]!r} (values are read as they are, "
                                   f"never converted)", path, c, header_line + 1)
    first = i + 2
    body = lines[first:]
    ncol = len(cols)
    rows = []
    for r, ln in enumerate(body):
        f = ln.split(",")
        if len(f) != ncol:
            if ln.strip() == "":
                raise MeasurementError("empty line among the samples", path, line=first + r + 1, row=r + 1)
            raise MeasurementError(f"{len(f)} fields, the header has {ncol}", path,
                                   line=first + r + 1, row=r + 1)
        rows.append(f)
    if len(rows) < 2:
        raise MeasurementError(f"needs at least 2 samples, has {len(rows)}", path)
    arr = np.array(rows, dtype=object)
    data = {}
    for j, c in enumerate(cols):
        col = arr[:, j]
        try:
            x = np.array(col, dtype=np.float64)
        except ValueError:
            x = None
        joined = "".join(col)
        if x is None or any(ch in joined for ch in " \t_") or min(map(len, col)) == 0:
            for r, s in enumerate(col):
                ok = s == s.strip() and s != "" and "_" not in s
                if ok:
                    try:
                        float(s)
                    except ValueError:
                        ok = False
                if not ok:
                    raise MeasurementError(f"{s!r} is not a number", path, c, first + r + 1, r + 1)
        data[c] = x
    df = pd.DataFrame({c: data[c] for c in COLUMNS})
    validate_samples(df, sample_rate, path, line_of_row=lambda r: first + r + 1, force_range=force_range)
    return df


def format_samples(df: pd.DataFrame, comments: Optional[list] = None) -> str:
    out = [f"# {c}".rstrip() for c in (comments or [])]
    out.append(",".join(COLUMNS))
    out.append(",".join(UNITS[c] for c in COLUMNS))
    cols = [df[c].to_numpy(dtype=float).tolist() for c in COLUMNS]
    out.extend(",".join(map(repr, row)) for row in zip(*cols))
    return "\n".join(out) + "\n"


# ----------------------------------------------------------------------------------------
# the public entry points

def load_measurement(path: Union[str, Path], check_layout: bool = True) -> Measurement:
    """Load and check one measurement folder (or its meta.json / samples.csv)."""
    path = Path(path)
    if path.is_file() and path.name in (META_FILE, SAMPLES_FILE):
        path = path.parent
    if not path.is_dir():
        raise MeasurementError("no such measurement folder", path)
    meta = read_meta(path / META_FILE, check_layout)
    samples = read_samples(path / SAMPLES_FILE, float(meta["sample_rate"]), force_ranges(meta, path / META_FILE))
    protocol_of(meta, path / META_FILE, len(samples) / float(meta["sample_rate"]))
    source = "meta.json" if "design_variables" in meta else "derived from the nominal values in meta.json"
    return Measurement(path, meta, samples, source)


def find_measurements(root: Union[str, Path]) -> list:
    """The measurement folders under root (any depth; folders holding meta.json),
    never looking into a folder named 'answers'; sorted by number, then path."""
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"no such measurement folder: {root}")
    if (root / META_FILE).is_file():
        return [root]
    found = []
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = sorted(d for d in dirnames if d != "answers")
        if META_FILE in filenames:
            found.append(Path(dirpath))
            dirnames[:] = []

    def key(p):
        try:
            n = json.loads((p / META_FILE).read_text()).get("number")
        except Exception:
            n = None
        return (n if isinstance(n, int) and not isinstance(n, bool) else 10 ** 9, str(p))
    return sorted(found, key=key)


def load_measurements(root: Union[str, Path], numbers=None) -> list:
    """All measurements under root (see find_measurements), optionally only the given numbers."""
    out = []
    for p in find_measurements(root):
        m = load_measurement(p)
        if numbers is None or m.number in set(numbers):
            out.append(m)
    return out


def write_measurement(folder: Union[str, Path], samples: pd.DataFrame, meta: Mapping,
                      overwrite: bool = False, comments: Optional[list] = None) -> Path:
    """Write a measurement folder; checks first (same rules as the loader), so
    what is written always loads back, exactly."""
    folder = Path(folder)
    meta = dict(meta)
    validate_meta(meta, META_FILE, folder, check_layout=True)
    samples = samples[COLUMNS] if all(c in samples.columns for c in COLUMNS) else samples
    validate_samples(samples, float(meta["sample_rate"]), SAMPLES_FILE, force_range=force_ranges(meta, META_FILE))
    if folder.exists() and any(folder.iterdir()) and not overwrite:
        raise FileExistsError(f"{folder} exists and is not empty (overwrite=True to replace)")
    folder.mkdir(parents=True, exist_ok=True)
    tmp = folder / (SAMPLES_FILE + ".tmp")
    tmp.write_text(format_samples(samples, comments))
    tmp.replace(folder / SAMPLES_FILE)
    (folder / META_FILE).write_text(json.dumps(meta, indent=2, allow_nan=False) + "\n")
    return folder
