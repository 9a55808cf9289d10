"""The built-in layouts match Table 2 as measured from their files; names and
paths resolve; level changes are counted as documented; the CLI works."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lss_fmu import layout_design
from lss_fmu.layout_format import CURVE, SPIRAL, STRAIGHT, VCURVE, LayoutError, parse_layout
from lss_fmu.layouts import (LAYOUT_DIR, TABLE2, builtin_layouts, load_track, resolve_layout, summary,
                             table2_mismatches)
from lss_app.cli import main as lss


def layouts_main(argv: list) -> int:
    return lss(["layouts", *argv])
from lss_fmu.track_geometry import PITCH, Track

HEAD = "wheel A\ncoupling A\nmotors 2\n"


@pytest.mark.parametrize("name", sorted(TABLE2))
def test_builtin_matches_table2(name):
    track = load_track(name)  # raises unless it closes within 1 mm / 0.1 mrad
    row = summary(track)
    ref = TABLE2[name]
    assert row["closure_m"] < 1e-9 and row["closure_rad"] < 1e-9
    assert abs(row["length"] - ref["length"]) <= 0.005 * ref["length"]
    assert row["carts"] == ref["carts"] == math.floor(track.length / PITCH + 0.5)
    assert track.spec.n_carts == 0  # the cart count is measured, not declared
    for key in ("motors", "level_changes", "wheel", "coupling"):
        assert row[key] == ref[key], key
    assert table2_mismatches(row) == []
    # odd numbers of level changes need a spiral to come back down
    assert (row["level_changes"] % 2 == 1) <= (row["spirals"] >= 1)


@pytest.mark.parametrize("name", builtin_layouts())
def test_builtin_is_plausible(name):
    t = load_track(name)
    els = t.spec.elements
    for e in els:
        if e.kind in (CURVE, SPIRAL):
            assert 2.0 <= e.radius <= 8.0 and abs(e.angle) <= math.pi + 1e-12
        if e.kind == VCURVE:
            assert 10 <= e.radius <= 20 and abs(e.angle) <= math.radians(7) + 1e-12
    assert max(e.length for e in els if e.kind == STRAIGHT) >= 2.0
    # every motor sits whole on one straight; motors do not overlap
    for m0, m1 in t.motors:
        i = t.element_at([0.5 * (m0 + m1)])[0]
        assert t.kind[i] == STRAIGHT and t.s0[i] - 1e-9 <= m0 and m1 <= t.s0[i] + t.el_length[i] + 1e-9
    assert np.all(np.diff(t.motors[:, 0]) > 0) and np.all(t.motors[1:, 0] >= t.motors[:-1, 1])
    # the track never runs through itself: points far apart along s are apart in space
    s = t.sample(0.5)
    c = t.position(s)
    d = np.linalg.norm(c[:, None, :] - c[None, :, :], axis=2)
    dsm = np.abs(s[:, None] - s[None, :])
    far = np.minimum(dsm, t.length - dsm) > 3.0
    assert d[far].min() > 1.0


def test_demo_and_oval():
    demo = load_track("demo")
    e = demo.spec.elements
    assert {x.kind for x in e} == {STRAIGHT, CURVE, VCURVE, SPIRAL}
    assert any(x.kind == CURVE and x.angle > 0 for x in e) and any(x.kind == CURVE and x.angle < 0 for x in e)
    assert any(x.kind == VCURVE and x.angle > 0 for x in e) and any(x.kind == VCURVE and x.angle < 0 for x in e)
    assert 40 <= demo.length <= 55 and 4 <= len(demo.motors) <= 5
    assert (demo.spec.wheel, demo.spec.coupling) == ("A", "A")
    oval = load_track("oval")
    kinds = [x.kind for x in oval.spec.elements]
    assert sorted(kinds) == [STRAIGHT, STRAIGHT, CURVE, CURVE]
    assert all(x.radius == 3 and abs(x.angle) == pytest.approx(math.pi) for x in oval.spec.elements if x.kind == CURVE)
    assert oval.n_carts == 32 and len(oval.motors) == 4 and oval.inclined_runs() == []
    assert np.abs(oval.position(oval.sample(0.1))[:, 2]).max() == 0


def test_files_are_what_the_designs_give():
    assert layout_design.generate(check=True) == []


def test_layout_texts_are_compared_by_their_numbers():
    """The solved straights' last digits follow the machine's linear algebra: a
    rendering that differs below NUM_TOL is the same layout, one that differs
    above it, or in a word, is not."""
    d = next(d for d in layout_design.DESIGNS if d.name == "layout1")
    text = layout_design.render(d, layout_design.solve(d))
    solved = next(line for line in text.splitlines() if line.startswith("straight ") and "." in line)
    value = float(solved.split()[1])
    same = layout_design.same_layout_text
    assert same(text, text.replace(solved, f"straight {value * (1 + 4e-16)!r}"))
    assert same(text, text.replace(solved, f"straight {value + 0.5 * layout_design.NUM_TOL!r}"))
    assert not same(text, text.replace(solved, f"straight {value + 1e-6!r}"))
    assert not same(text, text.replace("curve 3 90 left", "curve 3 90 right", 1))
    assert not same(text, text + "straight 1\n")


def test_resolve_layout(tmp_path):
    assert set(TABLE2) | {"demo", "oval"} <= set(builtin_layouts())
    assert builtin_layouts()[:7] == [f"layout{i}" for i in range(1, 8)]
    assert resolve_layout("layout3") == LAYOUT_DIR / "layout3.layout"
    own = tmp_path / "mine.txt"
    own.write_text((LAYOUT_DIR / "oval.layout").read_text())
    assert resolve_layout(str(own)) == own
    assert load_track(own).length == pytest.approx(40.0)
    with pytest.raises(LayoutError, match=r"no layout 'layout9'.*layout1, layout2"):
        resolve_layout("layout9")
    with pytest.raises(LayoutError, match="not a file"):
        resolve_layout(tmp_path)


def runs_of(body: str):
    return Track(parse_layout(HEAD + body), check=False).inclined_runs()


def test_level_change_definition():
    ramp = "vcurve 10 5 up\nstraight 4\nvcurve 10 5 down\n"
    down = "vcurve 10 5 down\nstraight 4\nvcurve 10 5 up\n"
    assert runs_of("straight 5\n") == []
    one = runs_of("straight 5\n" + ramp + "straight 5\n")
    assert len(one) == 1 and not one[0].spiral and one[0].lines == (5, 7)
    assert one[0].rise == pytest.approx(2 * 10 * (1 - math.cos(math.radians(5))) + 4 * math.sin(math.radians(5)))
    # a bridge is two level changes; a hump through level is two as well
    assert len(runs_of("straight 5\n" + ramp + "straight 3\n" + down)) == 2
    assert len(runs_of("straight 5\nvcurve 10 5 up\nvcurve 10 5 down\nvcurve 10 5 down\nvcurve 10 5 up\n")) == 2
    # a curve on an incline stays in its level change; a spiral makes the run a spiral
    bend = runs_of("straight 5\nvcurve 10 5 up\ncurve 3 90 left\nvcurve 10 5 down\n")
    assert len(bend) == 1 and not bend[0].spiral
    sp = runs_of("straight 5\n" + ramp + "vcurve 10 5 down\nspiral 3 180 left\nvcurve 10 5 up\n")
    assert [r.spiral for r in sp] == [False, True]
    # the start frame is level (start has no incline), so no run wraps past s = 0


def test_cli_table(capsys):
    assert layouts_main([]) == 0
    out = capsys.readouterr().out
    for name in builtin_layouts():
        assert name in out
    assert out.count("matches") == 7


def test_cli_check(tmp_path, capsys):
    assert layouts_main(["check", "layout7", str(LAYOUT_DIR / "oval.layout")]) == 0
    out = capsys.readouterr().out
    assert "layout7: closes" in out and "52 carts" in out
    bad = tmp_path / "bad.layout"
    bad.write_text(HEAD + "straight 10\ncurve 3 180 left\nstraight 10.5\ncurve 3 180 left\n")
    assert layouts_main(["check", str(bad)]) != 0
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "bad.layout" in err and "does not close" in err
    bad.write_text(HEAD + "straight 10\nloop 3\n")
    assert layouts_main(["check", str(bad)]) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "line 5: unknown keyword 'loop'" in err
    assert layouts_main(["check", str(tmp_path / "nothing.layout")]) != 0


def test_cli_plot(tmp_path, capsys):
    assert layouts_main(["plot", "layout7", "--out", str(tmp_path)]) == 0
    for ext in ("png", "svg"):
        p = tmp_path / f"layout7.{ext}"
        assert p.exists() and p.stat().st_size > 10_000
    assert (tmp_path / "layout7.png").read_bytes()[:4] == b"\x89PNG"
    assert b"<svg" in (tmp_path / "layout7.svg").read_bytes()[:2000]
    assert layouts_main(["plot", "layout7", "--out", str(tmp_path), "--format", "gif"]) == 2
    assert layouts_main(["plot", "nope", "--out", str(tmp_path)]) == 1


def test_docs_example_closes(tmp_path, capsys):
    doc = (LAYOUT_DIR.parent.parent.parent / "docs" / "layouts.md").read_text()
    example = doc.split("```\n", 2)[1]
    assert example.startswith("# A small loop")
    path = tmp_path / "my_sorter.layout"
    path.write_text(example)
    assert layouts_main(["check", str(path)]) == 0
    out = capsys.readouterr().out.strip().replace(str(path), "my_sorter.layout")
    shown = next(line for line in doc.splitlines() if line.startswith("my_sorter.layout: "))
    # the docs show the real answer; the closure's rounding residue (1e-12 mrad) follows the machine
    assert layout_design.same_layout_text(out, shown, tol=1e-9), (out, shown)
    t = load_track(path)
    assert t.spec.name == "my_sorter" and t.n_level_changes == 1 and t.n_spirals == 1
