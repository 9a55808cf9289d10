"""Reader of the plain-text layout format (docs/layouts.md).

The same grammar as the C reader in `fmu_src/layout_io.c`, with the same checks
in the same order, so both name the same line with the same message for the
same file (tests/test_layout_parser.py holds them to it). The file is read as
bytes: keywords, numbers and names are ASCII; comments may hold anything but
a NUL byte.
"""
from __future__ import annotations

import math
import os
import re
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Union

# The layout rules, one place on the Python side (fmu_src/layout_io.h has the
# same numbers; docs/layouts.md states them).
MAX_BYTES = 1 << 20
MAX_ELEMENTS = 10000
MAX_NUMBER_CHARS = 64
MAX_SIZE_M = 10000.0        # lengths, radii, rise, |start x, y, z|
MAX_ANGLE_DEG = 3600.0      # sweeps, angles, |start heading|
MAX_MOTORS = 10000
MIN_CARTS, MAX_CARTS = 3, 100000
MAX_MASS = 10000.0
NOMINAL_PITCH = 1.25        # carts = round(length / 1.25 m) unless given
MIN_PITCH, MAX_PITCH = 0.5, 5.0   # track length per cart, m
DEG = math.pi / 180.0

STRAIGHT, CURVE, VCURVE, SPIRAL = 1, 2, 3, 4
KIND_NAMES = {STRAIGHT: "straight", CURVE: "curve", VCURVE: "vcurve", SPIRAL: "spiral"}
ELEMENT_KEYWORDS = {v: k for k, v in KIND_NAMES.items()}
HEADER_NVAL = {"name": 1, "wheel": 1, "coupling": 1, "motors": 1, "carts": 1, "start": 4, "mass": 1}
HEADER_USAGE = {"name": "name NAME", "wheel": "wheel A|B|C", "coupling": "coupling A|B",
                "motors": "motors N", "carts": "carts N", "start": "start X Y Z HEADING_DEG",
                "mass": "mass KG"}
REQUIRED = ("wheel", "coupling", "motors")

_BLANKS = re.compile(rb"[ \t\r\v\f]+")
_NUMBER = re.compile(rb"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_NAME = re.compile(rb"[A-Za-z0-9_.+-]{1,63}")


class LayoutError(ValueError):
    """A layout that cannot be used; `line` is the 1-based line in the file
    (None when no single line is to blame), `source` the file, if any."""

    def __init__(self, message: str, line: Optional[int] = None, source: Optional[str] = None):
        self.message, self.line, self.source = message, line, source
        text = f"line {line}: {message}" if line is not None else message
        super().__init__(f"{source}: {text}" if source else text)


@dataclass
class ElementSpec:
    kind: int                 # STRAIGHT, CURVE, VCURVE, SPIRAL
    length: float = 0.0       # straight, m
    radius: float = 0.0       # m; horizontal radius for curve and spiral
    angle: float = 0.0        # rad, signed: + left (curve, spiral), + up (vcurve)
    rise: float = 0.0         # spiral: expected rise, m (checked when has_rise)
    has_rise: bool = False
    line: int = 0

    @property
    def keyword(self) -> str:
        return KIND_NAMES[self.kind]

    def to_line(self) -> str:
        """The element as a line of the layout format (exact round trip)."""
        if self.kind == STRAIGHT:
            return f"straight {self.length!r}"
        deg = abs(self.angle) / DEG
        if self.kind == VCURVE:
            return f"vcurve {self.radius!r} {deg!r} {'up' if self.angle > 0 else 'down'}"
        text = f"{self.keyword} {self.radius!r} {deg!r} {'left' if self.angle > 0 else 'right'}"
        return text + (f" {self.rise!r}" if self.has_rise else "")


@dataclass
class LayoutSpec:
    name: str = ""
    wheel: str = ""
    coupling: str = ""
    n_motors: int = 0
    n_carts: int = 0               # 0: round(track length / 1.25 m)
    start: tuple = (0.0, 0.0, 0.0)
    heading: float = 0.0           # rad
    cart_mass: float = 0.0         # kg, 0: from the wheel/coupling type
    elements: list = field(default_factory=list)
    source: Optional[str] = None   # file the layout came from


def _show(tok: bytes, size: int = 32) -> str:
    out = []
    for i, c in enumerate(tok):
        if len(out) + 1 >= size:
            break
        if i == 24:
            if len(out) + 4 < size:
                out.append("...")
            break
        out.append(chr(c) if 0x20 <= c < 0x7F else "?")
    return "".join(out)


class _Fail(Exception):
    def __init__(self, line: int, message: str):
        self.line, self.message = line, message


def _number(tok: bytes, line: int, what: str, positive: bool, limit: float) -> float:
    show = _show(tok)
    if len(tok) > MAX_NUMBER_CHARS or not _NUMBER.fullmatch(tok):
        raise _Fail(line, f"{what}: '{show}' is not a number")
    v = float(tok)
    if not math.isfinite(v):
        raise _Fail(line, f"{what}: '{show}' is not finite")
    if positive and not v > 0:
        raise _Fail(line, f"{what} must be positive, got {show}")
    if limit > 0 and not abs(v) <= limit:
        raise _Fail(line, f"{what} is too large: {show} (limit {limit:g})")
    return v


def _integer(tok: bytes, line: int, what: str, lo: int, hi: int) -> int:
    show = _show(tok)
    digits = tok[1:] if tok.startswith(b"+") else tok
    if not digits or len(digits) > 9 or not all(48 <= c <= 57 for c in digits):
        raise _Fail(line, f"{what}: '{show}' is not a whole number")
    v = int(digits)
    if not lo <= v <= hi:
        raise _Fail(line, f"{what} must be {lo} to {hi}, got {show}")
    return v


def _element(toks: list, line: int) -> ElementSpec:
    kw = toks[0].decode("ascii")
    nval = len(toks) - 1
    if kw == "straight":
        if nval != 1:
            raise _Fail(line, f"'straight LENGTH' takes 1 value, got {nval}")
        return ElementSpec(STRAIGHT, length=_number(toks[1], line, "straight length", True, MAX_SIZE_M),
                           line=line)
    spiral, vertical = kw == "spiral", kw == "vcurve"
    kind = SPIRAL if spiral else VCURVE if vertical else CURVE
    usage = ("'spiral RADIUS SWEEP_DEG left|right [RISE]'" if spiral else
             "'vcurve RADIUS ANGLE_DEG up|down'" if vertical else "'curve RADIUS SWEEP_DEG left|right'")
    if not (nval == 3 or (spiral and nval == 4)):
        raise _Fail(line, f"{usage} takes {'3 or 4' if spiral else '3'} values, got {nval}")
    radius = _number(toks[1], line, f"{kw} radius", True, MAX_SIZE_M)
    deg = _number(toks[2], line, f"{kw} {'angle' if vertical else 'sweep'}", True, MAX_ANGLE_DEG)
    d = toks[3]
    if vertical and d in (b"up", b"down"):
        sign = 1.0 if d == b"up" else -1.0
    elif not vertical and d in (b"left", b"right"):
        sign = 1.0 if d == b"left" else -1.0
    elif vertical:
        raise _Fail(line, f"vcurve direction must be 'up' or 'down', got '{_show(d)}'")
    else:
        raise _Fail(line, f"{kw} direction must be 'left' or 'right', got '{_show(d)}'")
    e = ElementSpec(kind, radius=radius, angle=sign * (deg * DEG), line=line)
    if spiral and nval == 4:
        e.rise = _number(toks[4], line, "spiral rise", False, MAX_SIZE_M)
        e.has_rise = True
    return e


def _header(key: str, toks: list, line: int, spec: LayoutSpec) -> None:
    n = HEADER_NVAL[key]
    if len(toks) - 1 != n:
        raise _Fail(line, f"'{HEADER_USAGE[key]}' takes {n} value{'s' if n > 1 else ''}, got {len(toks) - 1}")
    v = toks[1]
    show = _show(v)
    if key == "name":
        if not _NAME.fullmatch(v):
            raise _Fail(line, f"name '{show}' must be 1 to 63 of the characters A-Z a-z 0-9 _ . - +")
        spec.name = v.decode("ascii")
    elif key == "wheel":
        if v not in (b"A", b"B", b"C"):
            raise _Fail(line, f"wheel type must be A, B or C, got '{show}'")
        spec.wheel = v.decode("ascii")
    elif key == "coupling":
        if v not in (b"A", b"B"):
            raise _Fail(line, f"coupling type must be A or B, got '{show}'")
        spec.coupling = v.decode("ascii")
    elif key == "motors":
        spec.n_motors = _integer(v, line, "motors", 0, MAX_MOTORS)
    elif key == "carts":
        spec.n_carts = _integer(v, line, "carts", MIN_CARTS, MAX_CARTS)
    elif key == "start":
        xyz = tuple(_number(toks[1 + i], line, f"start {c}", False, MAX_SIZE_M) for i, c in enumerate("xyz"))
        heading = _number(toks[4], line, "start heading", False, MAX_ANGLE_DEG)
        spec.start, spec.heading = xyz, heading * DEG
    elif key == "mass":
        spec.cart_mass = _number(v, line, "mass", True, MAX_MASS)


def _parse(data: bytes) -> LayoutSpec:
    if len(data) > MAX_BYTES:
        raise _Fail(data.count(b"\n", 0, MAX_BYTES) + 1,
                    "the layout is larger than 1 MiB (1048576 bytes); is this a layout file?")
    spec = LayoutSpec()
    seen: dict = {}
    line = 0
    for raw in data.split(b"\n"):
        line += 1
        if b"\0" in raw:
            raise _Fail(line, "NUL byte in the layout (a binary file?)")
        toks = [t for t in _BLANKS.split(raw.split(b"#", 1)[0]) if t]
        if not toks:
            continue
        kw = toks[0]
        if kw in (b"name", b"wheel", b"coupling", b"motors", b"carts", b"start", b"mass"):
            key = kw.decode("ascii")
            if key in seen:
                raise _Fail(line, f"duplicate '{key}' (first given on line {seen[key]})")
            seen[key] = line
            _header(key, toks, line, spec)
        elif kw in (b"straight", b"curve", b"vcurve", b"spiral"):
            if len(spec.elements) >= MAX_ELEMENTS:
                raise _Fail(line, f"too many track elements (limit {MAX_ELEMENTS})")
            spec.elements.append(_element(toks, line))
        else:
            raise _Fail(line, f"unknown keyword '{_show(kw)}' (expected straight, curve, vcurve, spiral, "
                              "name, wheel, coupling, motors, carts, start or mass)")
    if not spec.elements:
        raise _Fail(line, "end of file: the layout has no track elements")
    for key in REQUIRED:
        if key not in seen:
            raise _Fail(line, f"end of file: the header lacks '{HEADER_USAGE[key]}'")
    return spec


def parse_layout(text: Union[str, bytes], source: Optional[str] = None) -> LayoutSpec:
    """Parse layout text; raises LayoutError naming `source` and the line."""
    data = text.encode("utf-8") if isinstance(text, str) else bytes(text)
    try:
        spec = _parse(data)
    except _Fail as f:
        raise LayoutError(f.message, f.line, source) from None
    spec.source = source
    return spec


def _read_regular(path: Path) -> bytes:
    """At most MAX_BYTES + 1 bytes of a regular file. As the C reader: opened
    without blocking, then checked on the open file, so that a FIFO, a device or
    a directory is refused instead of read (a FIFO would block for ever)."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0))
    except OSError as exc:
        raise LayoutError(f"cannot open the layout file ({exc.strerror or exc})", None, str(path)) from None
    try:
        mode = os.fstat(fd).st_mode
        if stat.S_ISDIR(mode):
            raise LayoutError("is a directory, not a layout file", None, str(path))
        if not stat.S_ISREG(mode):
            raise LayoutError("is not a regular file (a FIFO, device or socket is not read)", None, str(path))
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        with os.fdopen(fd, "rb") as f:
            fd = -1
            return f.read(MAX_BYTES + 1)
    except OSError as exc:
        raise LayoutError(f"read error ({exc.strerror or exc})", None, str(path)) from None
    finally:
        if fd >= 0:
            os.close(fd)


def read_layout(path: Union[str, Path]) -> LayoutSpec:
    """Parse a layout file. Without a `name` line the name is the file's stem."""
    path = Path(path)
    data = _read_regular(path)
    spec = parse_layout(data, str(path))
    if not spec.name:
        stem = path.name
        dot = stem.rfind(".")
        spec.name = (stem[:dot] if dot > 0 else stem)[:63]
    return spec


def n_carts_of(spec: LayoutSpec, length: float) -> float:
    """The number of carts: given, or round(length / 1.25 m) (halves up)."""
    return float(spec.n_carts) if spec.n_carts > 0 else math.floor(length / NOMINAL_PITCH + 0.5)


def check_chain(spec: LayoutSpec, length: float) -> int:
    """The rules that need the track's length, as layout_check_chain in C: the
    number of carts in [3, 100000], the pitch length / carts in [0.5, 5] m, no
    curve radius below the pitch. The number of carts, or LayoutError."""
    n = n_carts_of(spec, length)
    derived = "" if spec.n_carts > 0 else f" (the {length:.6g} m track at one cart per {NOMINAL_PITCH:g} m)"
    if not MIN_CARTS <= n <= MAX_CARTS:
        shown = n if math.isfinite(n) else -1.0
        raise LayoutError(f"a chain of {shown:.0f} carts is not supported ({MIN_CARTS} to {MAX_CARTS}){derived}",
                          None, spec.source)
    pitch = length / n
    if not MIN_PITCH <= pitch <= MAX_PITCH:
        raise LayoutError(f"{n:.0f} carts on the {length:.6g} m track make a pitch of {pitch:.6g} m; it must lie "
                          f"in [{MIN_PITCH:g}, {MAX_PITCH:g}] m", None, spec.source)
    for e in spec.elements:
        if e.kind != STRAIGHT and not e.radius >= pitch:
            raise LayoutError(f"{KIND_NAMES[e.kind]} radius {e.radius:.6g} m is smaller than the cart pitch "
                              f"{pitch:.6g} m ({n:.0f} carts on {length:.6g} m): the chain cannot follow it",
                              e.line or None, spec.source)
    return int(n)


def format_layout(spec: LayoutSpec, comment: str = "") -> str:
    """A LayoutSpec as layout text (numbers written so they read back exactly)."""
    lines = [f"# {ln}".rstrip() for ln in comment.strip().splitlines()] if comment else []
    if spec.name:
        lines.append(f"name {spec.name}")
    lines += [f"wheel {spec.wheel}", f"coupling {spec.coupling}", f"motors {spec.n_motors}"]
    if spec.n_carts:
        lines.append(f"carts {spec.n_carts}")
    if any(spec.start) or spec.heading:
        lines.append("start " + " ".join(repr(float(v)) for v in spec.start) + f" {spec.heading / DEG!r}")
    if spec.cart_mass:
        lines.append(f"mass {spec.cart_mass!r}")
    lines += [e.to_line() for e in spec.elements]
    return "\n".join(lines) + "\n"
