"""Track layouts: the built-in ones, names or paths, and what a layout measures.

A layout is a plain-text file (docs/layouts.md). This module ties together the
reader (`layout_format`), the geometry (`track_geometry`) and the built-in
files shipped in the FMU's resources (`fmu_src/resources/layouts/NAME.layout`).

    from lss_fmu.layouts import load_track, summary
    track = load_track("layout2")        # or a path to your own file
    track.frame(s)                       # positions, frames, turn rates
    summary(track)                       # Table 2 row, measured
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Union

from .layout_format import LayoutError, LayoutSpec, check_chain, parse_layout, read_layout  # noqa: F401
from .track_geometry import MOTOR_LENGTH, PITCH, TOL_ANG, TOL_POS, Track  # noqa: F401

LAYOUT_DIR = Path(__file__).resolve().parent.parent / "fmu_src" / "resources" / "layouts"
SUFFIX = ".layout"

# Table 2 of the paper (brief section 2): the reference the built-ins are held to.
TABLE2 = {
    "layout1": dict(length=214, carts=171, motors=13, level_changes=4, wheel="A", coupling="A"),
    "layout2": dict(length=212, carts=169, motors=13, level_changes=4, wheel="A", coupling="A"),
    "layout3": dict(length=858, carts=685, motors=54, level_changes=11, wheel="B", coupling="B"),
    "layout4": dict(length=181, carts=145, motors=11, level_changes=1, wheel="A", coupling="A"),
    "layout5": dict(length=164, carts=131, motors=11, level_changes=1, wheel="A", coupling="A"),
    "layout6": dict(length=146, carts=117, motors=11, level_changes=1, wheel="A", coupling="A"),
    "layout7": dict(length=65, carts=52, motors=7, level_changes=2, wheel="C", coupling="A"),
}
LENGTH_TOLERANCE = 0.005  # relative, against the Table 2 length

# Calibrated nominal pretension d (m) per layout: the mean axial joint force on
# straights over one lap at 2 m/s is about 900 N (docs/measurements.md,
# `lss_fmu.rig.calibrate_pretension`).
NOMINAL_PRETENSION = {
    "layout1": 0.035, "layout2": 0.045, "layout3": 0.072, "layout4": 0.031,
    "layout5": 0.022, "layout6": 0.025, "layout7": 0.023, "demo": 0.015, "oval": 0.012,
}


def builtin_layouts() -> list:
    """Names of the built-in layouts: layout1..layout7 first, then the others."""
    names = [p.stem for p in LAYOUT_DIR.glob("*" + SUFFIX)]
    return sorted(names, key=lambda n: (n not in TABLE2, n))


def resolve_layout(name_or_path: Union[str, Path]) -> Path:
    """The file of a built-in layout name, or an existing file path."""
    text = str(name_or_path)
    if text in builtin_layouts():
        return LAYOUT_DIR / (text + SUFFIX)
    path = Path(text).expanduser()
    if path.is_file():
        return path
    if path.exists():
        raise LayoutError(f"{text} is not a file")
    raise LayoutError(f"no layout '{text}': neither a file nor a built-in layout "
                      f"({', '.join(builtin_layouts())})")


def load_spec(name_or_path: Union[str, Path]) -> LayoutSpec:
    return read_layout(resolve_layout(name_or_path))


def load_track(name_or_path: Union[str, Path], motor_length: float = MOTOR_LENGTH,
               tol_pos: float = TOL_POS, tol_ang: float = TOL_ANG) -> Track:
    """Parse and build a layout and apply the rules of a chain on it (carts,
    pitch, radii: layout_format.check_chain); LayoutError (with file and line)
    if it is unusable."""
    track = Track(load_spec(name_or_path), motor_length, tol_pos, tol_ang)
    check_chain(track.spec, track.length)
    return track


def check_layout(name_or_path: Union[str, Path], fmu: bool = True) -> Track:
    """What `lss layouts check` answers: the layout rules (load_track), then,
    with fmu, the chain assembled by the FMU itself, so that the checker accepts
    exactly what the FMU accepts. Assembly is the one step no rule predicts:
    carts are placed one after the other along the track and the pitch is
    solved for the loop to close, which can fail on tight curves (near one
    curve radius per two cart pitches, docs/layouts.md). LayoutError naming
    the file."""
    track = load_track(name_or_path)
    if fmu:
        from .runner import ChainSimulator, SimulationError
        target = str(name_or_path) if str(name_or_path) in builtin_layouts() else str(resolve_layout(name_or_path))
        try:
            with ChainSimulator(instance_name="layout_check") as sim:
                sim.start({"layout.name": target})
        except SimulationError as exc:
            raise LayoutError(f"the FMU cannot build a chain on it: {exc}", None, track.spec.source) from None
    return track


def summary(track: Track) -> dict:
    """What Table 2 lists, measured from the layout, plus the closure error."""
    runs = track.inclined_runs()
    return dict(
        name=track.spec.name, length=track.length, carts=track.n_carts, motors=len(track.motors),
        level_changes=sum(not r.spiral for r in runs), spirals=sum(r.spiral for r in runs),
        wheel=track.spec.wheel, coupling=track.spec.coupling,
        closure_m=track.closure_error, closure_rad=track.closure_angle,
        elements=track.n, rise_max=max((abs(r.rise) for r in runs), default=0.0))


def table2_mismatches(row: dict) -> list:
    """How a measured row differs from its Table 2 reference (empty: it matches)."""
    ref = TABLE2.get(row["name"])
    if ref is None:
        return []
    out = []
    if not abs(row["length"] - ref["length"]) <= LENGTH_TOLERANCE * ref["length"]:
        out.append(f"length {row['length']:.2f} m is not within 0.5% of {ref['length']} m")
    for key in ("carts", "motors", "level_changes", "wheel", "coupling"):
        if row[key] != ref[key]:
            out.append(f"{key} {row[key]} != {ref[key]}")
    if not math.isfinite(row["closure_m"]) or row["closure_m"] > TOL_POS or row["closure_rad"] > TOL_ANG:
        out.append("does not close")
    return out
