"""Designs of the built-in layouts, and the generator of their files.

`lss layouts design` (re)writes `fmu_src/resources/layouts/*.layout` from
them (`generate`); with `--check` it verifies that the shipped files are what
the designs give.

Each design is a list of catalogue elements (straights in 0.5 m steps, curves
of 2.5-4 m radius and 30/45/90/180 deg sweep, vertical curves of 10-15 m radius
and 5-7 deg incline, helical spirals) in which a few straights carry an unknown
extension: "x" and "y" close the loop in plan, "z" (an inclined straight)
closes it in height, and "len" (added to a pair of opposite straights) sets the
track length to exactly carts x 1.25 m, so the chain of Table 2 fits the loop
without a gap. Since element frames do not depend on straight lengths, the end
point is linear in the unknowns: one small linear solve closes each loop to
rounding error (~1e-12 m), and the solved lengths are written in full.

The solve's last digits depend on the machine (the linear-algebra kernel numpy
picks for the CPU), so a shipped file is current when it reads as the design's
solution to within `NUM_TOL`, far above rounding and far below anything a cart
feels, not when its text is the same to the last digit.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np

from .layout_format import (CURVE, DEG, SPIRAL, STRAIGHT, VCURVE, ElementSpec, LayoutSpec,
                            parse_layout)
from .track_geometry import PITCH, Track

LAYOUT_DIR = Path(__file__).resolve().parent.parent / "fmu_src" / "resources" / "layouts"
NUM_TOL = 1e-9   # m (or deg): two renderings of one design agree within this in every number


@dataclass
class Item:
    kind: int
    length: float = 0.0
    radius: float = 0.0
    deg: float = 0.0          # signed: + left / up
    var: Optional[str] = None  # straight extended by an unknown
    note: str = ""


def S(length, var=None, note=""):
    return Item(STRAIGHT, length=length, var=var, note=note)


def L(radius, deg, note=""):
    return Item(CURVE, radius=radius, deg=deg, note=note)


def R(radius, deg, note=""):
    return Item(CURVE, radius=radius, deg=-deg, note=note)


def spiral(radius, deg, note=""):
    return Item(SPIRAL, radius=radius, deg=deg, note=note)


def ramp(direction, rv, deg, length, var=None, note=""):
    """A level change: vertical curve, inclined straight, vertical curve back."""
    sgn = 1 if direction == "up" else -1
    return [Item(VCURVE, radius=rv, deg=sgn * deg, note=note), S(length, var),
            Item(VCURVE, radius=rv, deg=-sgn * deg)]


def bridge(rv, deg, length, deck, note="", var=None):
    """Two level changes: up over a passage and down again."""
    return [*ramp("up", rv, deg, length, var, note=f"{note} up".strip()), S(deck),
            *ramp("down", rv, deg, length, note=f"{note} down".strip())]


def helix_down(rv, deg, radius, sweep, note="spiral down"):
    """Ramp into a descending helical curve and level out again."""
    return [Item(VCURVE, radius=rv, deg=-deg, note=note), spiral(radius, sweep),
            Item(VCURVE, radius=rv, deg=deg)]


def flat(*parts):
    out = []
    for p in parts:
        out.extend(p if isinstance(p, list) else [p])
    return out


@dataclass
class Design:
    name: str
    title: str
    carts: int
    motors: int
    wheel: str
    coupling: str
    items: list


DESIGNS = [
    Design("layout1", "Test layout 1: rounded rectangle with a bridge on each long side", 171, 13, "A", "A", flat(
        S(6, "x"), bridge(15, 6, 10, 14, "bridge 1", var="z"), S(8, "len"),
        L(3, 90), S(12, "y"), L(3, 90),
        S(10), bridge(15, 5, 12, 16, "bridge 2"), S(8, "len"),
        L(3, 90), S(12), L(3, 90))),
    Design("layout2", "Test layout 2: L-shaped loop with a bridge on the long side and on the inner leg",
           169, 13, "A", "A", flat(
        S(20, "x"), *ramp("up", 15, 6, 10, "z", note="bridge 1 up"), S(20, "len"),
        *ramp("down", 15, 6, 10, note="bridge 1 down"), S(6),
        L(3, 90), S(30, "y"), L(3, 90), S(14), L(3, 90), S(10), R(3, 90, "inner corner"),
        S(8, "len"), bridge(12, 5, 8, 4, "bridge 2"), S(4),
        L(3, 90), S(12), L(3, 90))),
    Design("layout3", "Test layout 3: long loop, two bridges and a jog below, a mezzanine with three "
           "bridges above, down by a helix", 685, 54, "B", "B", flat(
        S(40, "x"), bridge(15, 5, 20, 30, "bridge 1"), S(60), bridge(15, 5, 20, 30, "bridge 2"), S(50),
        R(3.5, 30, "jog"), S(6, "y"), L(3.5, 30), S(60, "len"),
        L(3.5, 90), S(12), L(3.5, 90),
        S(20), *ramp("up", 15, 6, 10, "z", note="up to the mezzanine"), S(40),
        bridge(15, 5, 15, 25, "bridge 3"), S(40), bridge(15, 5, 15, 25, "bridge 4"), S(40),
        bridge(15, 5, 15, 25, "bridge 5"), S(30, "len"),
        helix_down(15, 6, 7.5, 180, "helix down from the mezzanine"), S(10))),
    Design("layout4", "Test layout 4: oval, a ramp up on one side, a helical end curve down", 145, 11, "A", "A",
           flat(
        S(10, "x"), *ramp("up", 15, 7, 10, "z", note="ramp up"), S(40, "len"),
        L(3, 90), S(2, "y"), L(3, 90), S(70, "len"),
        helix_down(15, 7, 4, 180), S(4))),
    Design("layout5", "Test layout 5: long loop with one end chamfered by two 45 deg curves, a ramp up "
           "and a helical end curve down",
           131, 11, "A", "A", flat(
        S(30, "x"), L(3, 45), S(4), L(3, 45), S(2, "y"), L(3, 90),
        S(10), *ramp("up", 15, 7, 10, "z", note="ramp up"), S(20, "len"),
        helix_down(15, 7, 5, 180), S(20, "len"))),
    Design("layout6", "Test layout 6: rectangle, ramp up on a short side, one helical corner down",
           117, 11, "A", "A", flat(
        S(20, "x"), L(3, 90), S(4), *ramp("up", 15, 6, 8, "z", note="ramp up"), S(4, "y"),
        L(3, 90), S(30, "len"), L(3, 90), S(20), helix_down(15, 7, 4, 90), S(6, "len"))),
    Design("layout7", "Test layout 7: small oval with a ramp up and a ramp down", 52, 7, "C", "A", flat(
        S(4, "x"), *ramp("up", 12, 7, 8, "z", note="ramp up"), S(6, "len"), L(2.5, 180),
        S(6, "len"), *ramp("down", 12, 7, 8, note="ramp down"), S(4), L(2.5, 180))),
    Design("demo", "Demo layout: every element type (straight, curves left and right, vertical curves up "
           "and down, spiral) on a short loop", 40, 5, "A", "A", flat(
        S(3, "x"), *ramp("up", 10, 7, 4, "z", note="ramp up"), S(3, "len"), L(3, 180),
        S(2, "len"), L(2.5, 20, "jog"), S(2, "y"), R(2.5, 20), S(9),
        helix_down(10, 5, 2.5, 180), S(1))),
    Design("oval", "Level oval: two straights and two 180 deg curves of 3 m radius (statics tests)",
           32, 4, "A", "A", flat(S(10, "len"), L(3, 180), S(10, "len"), L(3, 180))),
]


def _spec(d: Design, values: dict) -> LayoutSpec:
    els = []
    for it in d.items:
        if it.kind == STRAIGHT:
            els.append(ElementSpec(STRAIGHT, length=it.length + values.get(it.var, 0.0)))
        else:
            els.append(ElementSpec(it.kind, radius=float(it.radius), angle=it.deg * DEG))
    return LayoutSpec(name=d.name, wheel=d.wheel, coupling=d.coupling, n_motors=d.motors, elements=els)


def solve(d: Design) -> LayoutSpec:
    """The layout with its unknown straights solved: closed, length = carts x pitch."""
    names = sorted({it.var for it in d.items if it.var})

    def residual(values):
        t = Track(_spec(d, values), check=False)
        return np.append(t.closure, t.length - d.carts * PITCH)

    base = {n: 0.0 for n in names}
    r0 = residual(base)
    J = np.column_stack([residual({**base, n: 1.0}) - r0 for n in names])
    x, *_ = np.linalg.lstsq(J, -r0, rcond=None)
    values = dict(zip(names, x))
    spec = _spec(d, values)
    # add the rise each spiral needs, as a check a reader can see
    t = Track(spec, check=False)
    for e, inc in zip(spec.elements, t.entry_incline):
        if e.kind == SPIRAL:
            e.rise, e.has_rise = round(e.radius * abs(e.angle) * np.tan(inc), 4), True
    bad = [it for it, e in zip(d.items, spec.elements) if e.kind == STRAIGHT and e.length < 0.5]
    if bad or np.abs(residual(values)).max() > 1e-9:
        raise RuntimeError(f"{d.name}: design does not close with sensible straights: {values}")
    return spec


def _num(v: float) -> str:
    v = float(v)
    if abs(v - round(v, 6)) < 1e-9:  # a solved length that is round anyway
        v = round(v, 6)
    return str(int(v)) if v.is_integer() else repr(v)


def render(d: Design, spec: LayoutSpec) -> str:
    head = [f"# {d.title}.",
            "# Written by `python -m lss_fmu.layout_design` (see docs/layouts.md); the straights with",
            "# long numbers are solved so the loop closes and is exactly carts x 1.25 m long.",
            f"name {spec.name}", f"wheel {spec.wheel}", f"coupling {spec.coupling}",
            f"motors {spec.n_motors}", ""]
    body = []
    for it, e in zip(d.items, spec.elements):
        if e.kind == STRAIGHT:
            text = f"straight {_num(e.length)}"
        elif e.kind == VCURVE:
            text = f"vcurve {_num(e.radius)} {_num(abs(it.deg))} {'up' if it.deg > 0 else 'down'}"
        else:
            text = (f"{'spiral' if e.kind == SPIRAL else 'curve'} {_num(e.radius)} {_num(abs(it.deg))} "
                    f"{'left' if it.deg > 0 else 'right'}")
            if e.has_rise:
                text += f" {e.rise:.4f}"
        body.append(f"{text:<34}# {it.note}".rstrip(" #") if it.note else text)
    return "\n".join(head + body) + "\n"


def _tokens(text: str) -> list:
    return [line.split() for line in text.splitlines()]


def _number(tok: str) -> Optional[float]:
    try:
        return float(tok)
    except ValueError:
        return None


def same_layout_text(a: str, b: str, tol: float = NUM_TOL) -> bool:
    """Whether two layout texts say the same: the same lines and words, every
    number within `tol` of its counterpart (the words and comments exactly)."""
    ta, tb = _tokens(a), _tokens(b)
    if [len(x) for x in ta] != [len(x) for x in tb]:
        return False
    for x, y in zip(ta, tb):
        for u, v in zip(x, y):
            nu, nv = _number(u), _number(v)
            if nu is None or nv is None:
                if u != v:
                    return False
            elif not abs(nu - nv) <= tol:
                return False
    return True


def generate(check: bool = False) -> list:
    """Write (or with check=True compare) every design's file; returns the stale
    names: those missing or reading otherwise than the design (`same_layout_text`).
    A current file is left as it is, so its digits do not churn with the machine."""
    stale = []
    LAYOUT_DIR.mkdir(parents=True, exist_ok=True)
    for d in DESIGNS:
        text = render(d, solve(d))
        back = Track(parse_layout(text))  # it must read back and close
        if back.closure_error > 1e-9 or abs(back.length - d.carts * PITCH) > 1e-9:
            raise RuntimeError(f"{d.name}: the written file does not close to 1e-9 m")
        path = LAYOUT_DIR / f"{d.name}.layout"
        if not path.exists() or not same_layout_text(path.read_text(), text):
            stale.append(d.name)
            if not check:
                path.write_text(text)
    return stale
