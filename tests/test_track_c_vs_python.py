"""The C track (fmu_src/track.c through the cffi API) and the Python geometry
(lss_fmu.track_geometry) give the same frame to 1e-9 on every layout."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lss_fmu.layout_format import CURVE, SPIRAL, STRAIGHT, VCURVE, parse_layout
from lss_fmu.layouts import builtin_layouts, load_track, resolve_layout
from lss_fmu.track_c import CTrack, load_lib
from lss_fmu.track_geometry import Track


@pytest.fixture(scope="module")
def lib():
    return load_lib()


def compare(py: Track, c: CTrack, ds: float = 0.05):
    assert c.length == pytest.approx(py.length, abs=1e-9)
    s = py.sample(ds)
    s = np.concatenate([s, s[::97] - py.length, s[::89] + 2 * py.length])  # wrapped arguments too
    cc, cR, cw = c.frame(s)
    pc, pR, pw, _ = py.frame(s)
    assert np.abs(cc - pc).max() <= 1e-9
    assert np.abs(cR - pR).max() <= 1e-9
    assert np.abs(cw - pw).max() <= 1e-12
    cl, ang = c.closure
    assert np.abs(cl - py.closure).max() <= 1e-12 and abs(ang - py.closure_angle) <= 1e-12
    assert np.abs(c.motors - py.motors).max(initial=0) <= 1e-9
    els = c.elements
    assert [e[0] for e in els] == list(py.kind) and [e[1] for e in els] == py.lines
    assert np.abs(np.array([e[2] for e in els]) - py.s0).max() <= 1e-9
    assert np.abs(np.array([e[3] for e in els]) - py.el_length).max() <= 1e-12
    return s


@pytest.mark.parametrize("name", builtin_layouts())
def test_builtin_frames_agree(lib, name):
    path = resolve_layout(name)
    py, c = load_track(name), CTrack(path, lib=lib)
    compare(py, c)
    h = c.header
    assert (h["name"], h["wheel"], h["coupling"], h["n_motors"]) == \
        (py.spec.name, py.spec.wheel, py.spec.coupling, len(py.motors))


def test_start_pose_and_motor_length(lib):
    text = ("wheel A\ncoupling A\nmotors 7\nstart 12.5 -3 1.5 33\n"
            "straight 10\nvcurve 12 6 up\nstraight 4\nvcurve 12 6 down\ncurve 3 180 left\n"
            "straight 0.4\nstraight 10\ncurve 2.5 90 right\n")
    py = Track(parse_layout(text), motor_length=0.9, tol_pos=1e9, tol_ang=1e9)
    c = CTrack(text=text, motor_length=0.9, tol_pos=1e9, tol_ang=1e9, lib=lib)
    compare(py, c, ds=0.01)
    # a motor longer than its straight is clamped into it
    assert np.all(py.motors[:, 1] - py.motors[:, 0] <= 0.9 + 1e-12)


def test_frame_geometry_on_the_demo():
    """Tangent, lateral, up are orthonormal; the lateral axis stays level;
    curvatures are those of the elements; the loop is seamless at s = L."""
    t = load_track("demo")
    s = t.sample(0.05)
    c, R, w, el = t.frame(s)
    assert np.abs(np.einsum("nij,nik->njk", R, R) - np.eye(3)).max() < 1e-12
    assert np.abs(R[:, 2, 1]).max() < 1e-12  # no banking
    dpsi, dtheta = t.curvature(s)
    inc = t.incline(s)
    for i, e in enumerate(t.spec.elements):
        m = el == i
        if e.kind in (CURVE, SPIRAL):
            assert np.allclose(dpsi[m], math.copysign(1, e.angle) * np.cos(inc[m]) / e.radius, atol=1e-12)
            assert np.allclose(dtheta[m], 0, atol=1e-15)
        elif e.kind == VCURVE:
            assert np.allclose(dtheta[m], math.copysign(1, e.angle) / e.radius, atol=1e-12)
        else:
            assert e.kind == STRAIGHT and np.allclose(w[m], 0)
    # positions: finite differences follow the tangent; the seam at L is closed
    ds = 1e-6
    fd = (t.position(s + ds) - t.position(s - ds)) / (2 * ds)
    assert np.abs(fd - R[:, :, 0]).max() < 1e-6
    assert np.abs(t.position([t.length - 1e-9]) - t.position([0.0])).max() < 1e-8
