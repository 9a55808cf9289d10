"""The layout format: malformed files name their line in Python and in C, the
two readers agree on every input (property tests), and files round-trip."""
from __future__ import annotations

import re

import locale
import math
from collections import Counter
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lss_fmu.layout_format import (DEG, MAX_BYTES, LayoutError, check_chain, format_layout, parse_layout,
                                   read_layout)
from lss_fmu.layouts import LAYOUT_DIR, check_layout
from lss_fmu.track_c import CTrack, c_parse_error, load_lib
from lss_fmu.track_geometry import Track

HEAD = "name t\nwheel A\ncoupling A\nmotors 2\n"
OVAL = HEAD + "straight 10\ncurve 3 180 left\nstraight 10\ncurve 3 180 left\n"


@pytest.fixture(scope="module")
def lib():
    return load_lib()


def py_error(text):
    try:
        parse_layout(text)
    except LayoutError as exc:
        return exc
    return None


# (text, line that must be named, a fragment of the message)
MALFORMED = [
    ("empty", "", 1, "no track elements"),
    ("only comments", "# nothing\n\n   # here\n", 4, "no track elements"),
    ("unknown element", HEAD + "straight 5\nbend 3 90 left\n", 6, "unknown keyword 'bend'"),
    ("missing value", HEAD + "curve 3 90\n", 5, "takes 3 values, got 2"),
    ("extra value", HEAD + "straight 5 6\n", 5, "takes 1 value, got 2"),
    ("negative radius", HEAD + "straight 4\ncurve -3 90 left\n", 6, "curve radius must be positive"),
    ("zero length", HEAD + "straight 0\n", 5, "must be positive"),
    ("negative length", HEAD + "straight -2.5\n", 5, "must be positive"),
    ("non-numeric", HEAD + "straight 4\nstraight five\n", 6, "'five' is not a number"),
    ("comma decimal", HEAD + "straight 4,5\n", 5, "is not a number"),
    ("nan", HEAD + "straight nan\n", 5, "is not a number"),
    ("infinite", HEAD + "straight 1e999\n", 5, "is not finite"),
    ("too long", HEAD + "straight 20000\n", 5, "too large"),
    ("zero sweep", HEAD + "curve 3 0 left\n", 5, "sweep must be positive"),
    ("sweep beyond 3600", HEAD + "curve 3 3600.5 left\n", 5, "too large"),
    ("vcurve angle zero", HEAD + "vcurve 10 0 up\n", 5, "angle must be positive"),
    ("bad direction", HEAD + "curve 3 90 up\n", 5, "'left' or 'right'"),
    ("bad vdirection", HEAD + "vcurve 10 5 left\n", 5, "'up' or 'down'"),
    ("spiral arity", HEAD + "spiral 3 90 left 1 2\n", 5, "takes 3 or 4 values"),
    ("duplicate header", HEAD + "wheel B\nstraight 3\n", 5, "duplicate 'wheel' (first given on line 2)"),
    ("bad wheel", "wheel D\n", 1, "wheel type must be A, B or C"),
    ("bad coupling", "coupling C\n", 1, "coupling type must be A or B"),
    ("motors not int", "motors 2.5\n", 1, "not a whole number"),
    ("motors negative", "motors -1\n", 1, "not a whole number"),
    ("carts too few", "carts 1\n", 1, "carts must be 3 to 100000"),
    ("two carts", "carts 2\n", 1, "carts must be 3 to 100000"),
    ("start far away", "start 1e300 0 0 0\n", 1, "start x is too large: 1e300 (limit 10000)"),
    ("start heading", "start 0 0 0 1e6\n", 1, "start heading is too large"),
    ("start arity", "start 0 0 0\n", 1, "takes 4 values"),
    ("mass zero", "mass 0\n", 1, "mass must be positive"),
    ("bad name", "name a/b\n", 1, "name 'a/b' must be"),
    ("missing motors", "name t\nwheel A\ncoupling A\nstraight 3\n", 5, "lacks 'motors N'"),
    ("NUL byte", HEAD + "straight 3\nstr\0aight 4\n", 6, "NUL byte"),
    ("NUL in comment", HEAD + "straight 3 # x\0\n", 5, "NUL byte"),
    ("binary junk", b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR", 1, "unknown keyword"),
    ("too many elements", HEAD + "straight 1\n" * 10001, 10005, "too many track elements"),
]


@pytest.mark.parametrize("text,line,fragment", [m[1:] for m in MALFORMED], ids=[m[0] for m in MALFORMED])
def test_malformed_named_by_line_in_python_and_c(lib, text, line, fragment):
    exc = py_error(text)
    assert exc is not None and exc.line == line
    assert fragment in str(exc)
    msg, _ = c_parse_error(text, lib)
    assert msg == f"line {line}: {exc.message}"  # the same words from both readers
    with pytest.raises(LayoutError, match=f"^line {line}: "):
        CTrack(text=text, lib=lib)


def test_huge_file(lib, tmp_path):
    text = OVAL + ("# padding " + "x" * 80 + "\n") * (MAX_BYTES // 90 + 10)
    exc = py_error(text)
    assert exc is not None and "larger than 1 MiB" in str(exc)
    line = text.encode().count(b"\n", 0, MAX_BYTES) + 1
    assert exc.line == line
    assert c_parse_error(text, lib)[0] == f"line {line}: {exc.message}"
    path = tmp_path / "huge.layout"
    path.write_text(text)
    with pytest.raises(LayoutError, match=f"huge.layout: line {line}: the layout is larger"):
        read_layout(path)
    with pytest.raises(LayoutError, match=f"huge.layout: line {line}: the layout is larger"):
        CTrack(path, lib=lib)


def test_file_errors_name_the_file(lib, tmp_path):
    path = tmp_path / "bad.layout"
    path.write_text(HEAD + "straight 4\ncurve 3 90 sideways\n")
    with pytest.raises(LayoutError, match=r"bad.layout: line 6: curve direction"):
        read_layout(path)
    with pytest.raises(LayoutError, match=r"bad.layout: line 6: curve direction"):
        CTrack(path, lib=lib)
    with pytest.raises(LayoutError, match="cannot open"):
        read_layout(tmp_path / "missing.layout")
    with pytest.raises(LayoutError, match="cannot open"):
        CTrack(tmp_path / "missing.layout", lib=lib)


def test_loop_that_does_not_close(lib):
    text = HEAD + "straight 10\ncurve 3 180 left\nstraight 10.25\ncurve 3 180 left\n"
    with pytest.raises(LayoutError) as info:
        Track(parse_layout(text))
    exc = info.value
    assert "does not close" in str(exc) and "misses the start by 0.25 m" in str(exc)
    assert exc.line == 5  # the gap lies along both straights: it names both
    assert "shortening the straight at line 7 or lengthening the straight at line 5 by 0.25 m" in str(exc)
    with pytest.raises(LayoutError, match=r"does not close: end point misses the start by 0\.25 m"):
        CTrack(text=text, lib=lib)
    # within 1 mm it is accepted, and the rest is blended away
    ok = HEAD + "straight 10\ncurve 3 180 left\nstraight 10.0009\ncurve 3 180 left\n"
    assert Track(parse_layout(ok)).closure_error == pytest.approx(9e-4)
    assert CTrack(text=ok, lib=lib).length == pytest.approx(20.0009 + 6 * math.pi)


def test_direction_budgets_are_named():
    heading = HEAD + "straight 10\ncurve 3 180 left\nstraight 10\ncurve 3 170 left\n"
    with pytest.raises(LayoutError, match=r"sweeps add up to 350 deg.*misses by -10 deg"):
        Track(parse_layout(heading))
    incline = HEAD + "straight 10\nvcurve 10 5 up\nstraight 3\ncurve 3 180 left\nstraight 10\ncurve 3 180 left\n"
    with pytest.raises(LayoutError, match=r"vcurve angles add up to \+5 deg.*climb from line 6") as info:
        Track(parse_layout(incline))
    assert info.value.line == 6
    rise = (HEAD + "straight 10\nvcurve 10 5 up\nstraight 3\nvcurve 10 5 down\ncurve 3 180 left\n"
            "straight 10\ncurve 3 180 left\n")
    with pytest.raises(LayoutError, match=r"level changes do not cancel.*lines 6-8.*straight at line"):
        Track(parse_layout(rise))


def test_spiral_rise_is_checked(lib):
    base = HEAD + "straight 5\nvcurve 10 6 up\nspiral 3 360 left {}\nvcurve 10 6 down\nstraight 1\n"
    rise = 3 * 2 * math.pi * math.tan(6 * DEG)
    ok, bad = base.format(f"{rise:.4f}"), base.format(f"{rise + 0.01:.4f}")
    Track(parse_layout(ok), check=False)
    with pytest.raises(LayoutError, match="line 7: spiral rise"):
        Track(parse_layout(bad), check=False)
    with pytest.raises(LayoutError, match="line 7: spiral rise"):
        CTrack(text=bad, tol_pos=1e30, tol_ang=1e30, lib=lib)


def test_header_defaults_and_values(lib, tmp_path):
    text = ("# a user's sorter\nwheel B   # comment\ncoupling B\nmotors 3\ncarts 33\n"
            "start 1 2 3 90\nmass 52.5\r\n" + "straight 10\ncurve 3 180 left\nstraight 10\ncurve 3 180 left")
    spec = parse_layout(text)
    assert (spec.name, spec.wheel, spec.coupling, spec.n_motors, spec.n_carts) == ("", "B", "B", 3, 33)
    assert spec.start == (1.0, 2.0, 3.0) and spec.heading == 90 * DEG and spec.cart_mass == 52.5
    path = tmp_path / "my-sorter.v2.layout"
    path.write_text(text)
    assert read_layout(path).name == "my-sorter.v2"
    h = CTrack(path, lib=lib).header
    assert h == dict(name="my-sorter.v2", wheel="B", coupling="B", n_motors=3, n_carts=33,
                     start=(1.0, 2.0, 3.0), heading=90 * DEG, cart_mass=52.5)
    assert Track(spec).n_carts == 33


def test_round_trip():
    spec = parse_layout(OVAL + "vcurve 12 5.5 up\nspiral 3 45 right -0.25\nvcurve 12 5.5 down\n")
    again = parse_layout(format_layout(spec, comment="round trip"))
    assert again.elements == [type(e)(**{**e.__dict__}) for e in again.elements]
    assert [(e.kind, e.length, e.radius, e.angle, e.rise, e.has_rise) for e in spec.elements] == \
           [(e.kind, e.length, e.radius, e.angle, e.rise, e.has_rise) for e in again.elements]


def test_c_parser_ignores_the_c_locale(lib):
    """A host that sets a comma-decimal locale must not change how numbers read."""
    for name in ("de_DE.UTF-8", "de_DE.utf8", "fr_FR.UTF-8", "da_DK.UTF-8"):
        try:
            old = locale.setlocale(locale.LC_NUMERIC)
            locale.setlocale(locale.LC_NUMERIC, name)
            break
        except locale.Error:
            continue
    else:
        pytest.skip("no comma-decimal locale installed")
    try:
        assert CTrack(text=OVAL.replace("straight 10", "straight 10.5"), lib=lib).length == \
            pytest.approx(21 + 6 * math.pi)
    finally:
        locale.setlocale(locale.LC_NUMERIC, old)


# --- property tests: the two readers agree on everything ------------------------------

def agree(text: bytes, lib):
    """Both readers must accept, or both reject with the same line and message."""
    try:
        spec, py_msg = parse_layout(text), None
    except LayoutError as exc:
        spec, py_msg = None, str(exc)
    c_msg, n_el = c_parse_error(text, lib)
    assert c_msg == py_msg
    if spec is not None:
        assert n_el == len(spec.elements)
    return spec


TOKENS = st.sampled_from([b"straight", b"curve", b"vcurve", b"spiral", b"name", b"wheel", b"coupling",
                          b"motors", b"carts", b"start", b"mass", b"left", b"right", b"up", b"down",
                          b"A", b"B", b"C", b"0", b"-1", b"2.5", b"1e3", b"1e999", b".5", b"5.", b"+3",
                          b"90", b"3600", b"nan", b"#", b"x", b"\t", b"\r"])
SHORT = settings(max_examples=250, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@SHORT
@given(st.binary(max_size=200))
def test_random_bytes(lib, data):
    agree(data, lib)


@SHORT
@given(st.integers(0, len(OVAL)), st.integers(0, 3), st.binary(max_size=4))
def test_mutated_valid_file(lib, at, cut, insert):
    data = OVAL.encode()
    agree(data[:at] + insert + data[at + cut:], lib)


@SHORT
@given(st.lists(st.lists(TOKENS, min_size=0, max_size=6).map(b" ".join), max_size=12).map(b"\n".join))
def test_random_token_lines(lib, text):
    agree(text, lib)


def element_line():
    num = st.floats(min_value=0.05, max_value=50, allow_nan=False).map(lambda v: repr(round(v, 3)))
    ang = st.sampled_from(["5", "7", "30", "45", "90", "180", "12.5"])
    return st.one_of(
        num.map(lambda n: f"straight {n}"),
        st.tuples(num, ang, st.sampled_from(["left", "right"])).map(lambda t: "curve %s %s %s" % t),
        st.tuples(num, ang, st.sampled_from(["up", "down"])).map(lambda t: "vcurve %s %s %s" % t),
        st.tuples(num, ang, st.sampled_from(["left", "right"])).map(lambda t: "spiral %s %s %s" % t))


@SHORT
@given(st.lists(element_line(), min_size=1, max_size=15), st.integers(0, 4))
def test_random_element_lists(lib, lines, motors):
    """Random (mostly open) element lists: the same parse, the same geometry or the same error."""
    import numpy as np
    text = (f"wheel A\ncoupling A\nmotors {motors}\n" + "\n".join(lines)).encode()
    spec = agree(text, lib)
    assert spec is not None
    try:
        py, py_msg = Track(spec, tol_pos=1e30, tol_ang=1e30), None
    except LayoutError as exc:
        py, py_msg = None, str(exc)
    try:
        c, c_msg = CTrack(text=text, tol_pos=1e30, tol_ang=1e30, lib=lib), None
    except LayoutError as exc:
        c, c_msg = None, str(exc)
    assert c_msg == py_msg
    if py is not None:
        assert c.length == pytest.approx(py.length, rel=1e-12)
        s = np.linspace(-0.1 * py.length, 1.1 * py.length, 37)
        cc, cR, cw = c.frame(s)
        pc, pR, pw, _ = py.frame(s)
        assert np.abs(cc - pc).max() <= 1e-9 * max(1.0, py.length)
        assert np.abs(cR - pR).max() <= 1e-9
        assert np.abs(c.motors - py.motors).max(initial=0) <= 1e-9


# --- one set of rules: the checker and the FMU agree (issue 20) ----------------------------------

CORPUS = Path(__file__).parent / "c" / "corpus_layout"
LOOP = "wheel A\ncoupling A\nmotors 0\n"
# the five cases the checker used to accept and the FMU refused, then
# rule boundaries, then a layout within the rules whose chain the FMU cannot assemble
RULE_CASES = {
    "two carts": LOOP + "carts 2\ncurve 0.5 360 left\n",
    "0.1 mm full circle": LOOP + "curve 0.0001 360 left\n",
    "loop of tiny curves": LOOP + "curve 0.01 90 left\n" * 4 + "carts 3\n",
    "tiny curves, derived carts": LOOP + "straight 0.01\ncurve 0.01 90 left\n" * 4,
    "start 1e300": LOOP + "start 1e300 0 0 0\nstraight 10\ncurve 3 180 left\nstraight 10\ncurve 3 180 left\n",
    "pitch too long": LOOP + "carts 3\nstraight 10\ncurve 6 180 left\nstraight 10\ncurve 6 180 left\n",
    "radius below the pitch": LOOP + "carts 12\nstraight 10\ncurve 3 180 left\nstraight 10\ncurve 3 180 left\n",
    "start at the limits": LOOP + "start 10000 -10000 10000 3600\nstraight 10\ncurve 3 180 left\nstraight 10\n"
                           "curve 3 180 left\n",
    "too many carts": LOOP + "straight 9000\ncurve 3 180 left\nstraight 9000\ncurve 3 180 left\n" * 7,
    "assembly fails": LOOP + "carts 18\n" + "straight 3.070831169693203\ncurve 2.5277921940805563 180 left\n" * 2,
}


def rules_c(lib, data: bytes):
    """(ok, message): every rule the FMU applies before assembling (lss_layout_rules_text)."""
    ffi = FFI_LIB[0]
    err, n = ffi.new("char[1024]"), ffi.new("int *")
    ok = lib.lss_layout_rules_text(data, len(data), 0.6, n, err, 1024) == 0
    return ok, ffi.string(err).decode("latin-1")


def rules_python(data: bytes):
    try:
        spec = parse_layout(data)
        check_chain(spec, Track(spec).length)
    except LayoutError as exc:
        return False, str(exc)
    return True, ""


def fmu_builds(lib, path: Path):
    """(ok, message) of the FMU's chain_create on the file, default parameters."""
    ffi = FFI_LIB[0]
    par = lib.lss_params_new()
    lib.lss_params_set_string(par, b"layout.name", str(path).encode())
    err = ffi.new("char[1024]")
    c = lib.lss_chain_new(par, ffi.NULL, err, 1024)
    lib.lss_params_free(par)
    if c != ffi.NULL:
        lib.lss_chain_free(c)
    return c != ffi.NULL, ffi.string(err).decode("latin-1")


FFI_LIB: list = []


_NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")


def _same_words(c_msg: str, py_msg: str) -> bool:
    """The C message stands at the start or the end of the Python one, word for
    word; the numbers in it (each side's %.6g of its own arithmetic) within
    1e-5 of each other, not to the last printed digit."""
    mc, mp = _NUMBER.sub("#", c_msg), _NUMBER.sub("#", py_msg)
    nc = [float(v) for v in _NUMBER.findall(c_msg)]
    npy = [float(v) for v in _NUMBER.findall(py_msg)]

    def close(a, b):
        return len(a) == len(b) and all(u == v or abs(u - v) <= 1e-5 * max(abs(u), abs(v), 1e-12)
                                        for u, v in zip(a, b))
    if mp.startswith(mc) and close(nc, npy[:len(nc)]):
        return True
    return mp.endswith(mc) and close(nc, npy[len(npy) - len(nc):])


def test_checker_and_fmu_agree_on_the_corpus_and_the_rule_cases(tmp_path):
    """Every file of the fuzzing corpus, the built-in layouts and RULE_CASES:
    the rules in Python (layout_format) and in C (layout_io.c, as chain_create
    applies them) give the same verdict with the same words, and
    `lss layouts check` (check_layout) accepts exactly what the FMU builds."""
    from lss_fmu import ccore
    FFI_LIB[:] = ccore.load()
    lib = FFI_LIB[1]
    paths = sorted(CORPUS.iterdir()) + sorted(LAYOUT_DIR.glob("*.layout"))
    for name, text in RULE_CASES.items():
        paths.append(tmp_path / (name.replace(" ", "_").replace(",", "") + ".layout"))
        paths[-1].write_text(text)
    verdicts = Counter()
    for path in paths:
        data = path.read_bytes()
        (c_ok, c_msg), (py_ok, py_msg) = rules_c(lib, data), rules_python(data)
        assert c_ok == py_ok, (path.name, c_msg, py_msg)  # the same rules on both sides ...
        if not c_ok and "does not close" not in c_msg:
            assert _same_words(c_msg, py_msg), (path.name, c_msg, py_msg)  # ... same words
        # the whole verdict: the FMU building the chain against `lss layouts check`
        fmu_ok, fmu_msg = fmu_builds(lib, path.resolve()) if c_ok else (False, c_msg)
        try:
            check_layout(path.resolve())
            checker_ok = True
        except LayoutError:
            checker_ok = False
        assert checker_ok == fmu_ok, (path.name, fmu_msg)
        verdicts[(c_ok, fmu_ok)] += 1
    print(f"\nlayout verdicts (rules ok, FMU builds): {dict(verdicts)} of {len(paths)} files")
    assert verdicts[(True, True)] >= 15 and verdicts[(False, False)] >= 300 and verdicts[(True, False)] >= 1
    for name in ("two carts", "0.1 mm full circle", "loop of tiny curves", "start 1e300", "radius below the pitch"):
        assert not rules_python(RULE_CASES[name].encode())[0], name
    assert rules_python(RULE_CASES["start at the limits"].encode())[0]
