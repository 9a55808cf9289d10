"""A survey of a sorter: what was measured on the machine itself beyond its
design drawing, given to the FMU in place of the design's values.

A survey is a JSON file:

    {"track": "tracks/layout1.layout",   # the as-built track (a layout file; relative to this file)
     "cart.mass_factor": 1.013,          # the carts' mass against the cart type's
     "track.guide_gap": 0.00052}         # the steering wheels' play against their guides, m

Every key is optional; an unknown key, a value that is not a number or lies
outside the FMU's range, or a track file that is missing or unreadable is
refused with the file, the key and the value named. The virtual rig writes
one for each measurement of the field set as `DATA/survey/mNN.json` (the
surveyed condition of a campaign, `lss campaign --surveyed`); what the rig
drew is also in `DATA/answers/`, which identification never reads.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Mapping, Union

from .atomic import write_json_atomic
from .layouts import load_track
from .variables import BY_NAME

NUMBERS = ("cart.mass_factor", "track.guide_gap")
KEYS = ("track",) + NUMBERS
FOLDER = "survey"


class SurveyError(ValueError):
    pass


def survey_path(record: Union[str, Path]) -> Path:
    """Where the survey of a record folder DATA/mNN lives: DATA/survey/mNN.json."""
    p = Path(record)
    return p.parent / FOLDER / f"{p.name}.json"


def load_survey(path: Union[str, Path]) -> dict:
    """The FMU parameters of a survey file: `layout.name` (the track file's
    absolute path) and the numbers it gives."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise SurveyError(f"{path}: no survey file") from None
    except (OSError, json.JSONDecodeError) as exc:
        raise SurveyError(f"{path}: not a readable JSON survey ({exc})") from None
    if not isinstance(data, dict):
        raise SurveyError(f"{path}: a survey is a JSON object of {', '.join(KEYS)}")
    unknown = sorted(set(data) - set(KEYS))
    if unknown:
        raise SurveyError(f"{path}: unknown key {unknown[0]!r}: a survey gives {', '.join(KEYS)}")
    out = {}
    for key in NUMBERS:
        if key not in data:
            continue
        v, var = data[key], BY_NAME[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise SurveyError(f"{path}: {key} = {v!r}: must be a number")
        if not var.min <= v <= var.max:
            raise SurveyError(f"{path}: {key} = {v!r} lies outside the FMU's range [{var.min:g}, {var.max:g}]")
        out[key] = float(v)
    if "track" in data:
        track = data["track"]
        if not isinstance(track, str) or not track:
            raise SurveyError(f"{path}: track = {track!r}: must be the path of a layout file")
        file = (path.parent / track).resolve()
        if not file.is_file():
            raise SurveyError(f"{path}: track = {track!r}: no such file ({file})")
        try:
            load_track(str(file))
        except Exception as exc:   # the layout reader's own message names what is wrong
            raise SurveyError(f"{path}: track = {track!r}: not a layout the FMU can run ({exc})") from None
        out["layout.name"] = str(file)
    return out


def write_survey(path: Union[str, Path], values: Mapping[str, float], track: Union[str, Path, None] = None) -> Path:
    """Write a survey file (atomically): the numbers of `values` and the
    track file `track`, referred to relative to the survey's folder."""
    path = Path(path)
    data = {}
    if track is not None:
        data["track"] = Path(track).resolve().relative_to(path.parent.resolve()).as_posix()
    data.update({k: float(values[k]) for k in NUMBERS if k in values})
    path.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(path, data)
    return path


def same_survey(a: Mapping[str, object], b: Mapping[str, object]) -> bool:
    """Two surveys' FMU parameters describe the same sorter (the track files
    compared by their text, as repeats keep their own copy)."""
    if {k: v for k, v in a.items() if k != "layout.name"} != {k: v for k, v in b.items() if k != "layout.name"}:
        return False
    ta, tb = a.get("layout.name"), b.get("layout.name")
    if (ta is None) != (tb is None):
        return False
    return ta is None or ta == tb or Path(str(ta)).read_text() == Path(str(tb)).read_text()


__all__ = ["SurveyError", "load_survey", "write_survey", "survey_path", "same_survey", "KEYS", "FOLDER"]
