"""The vectorised right-hand side (issue 19) computes the scalar path's physics.

Every path is forced through solver.vector_path (1 scalar, 2 AVX2, 3
AVX-512) and compared with the scalar one on the same states: the
derivatives, every contact's indentation and force, and the outputs, for
each kind of track (straights, plane arcs, the helices the vector code
hands to the scalar one), every contact law and every effect. A path the
CPU lacks is skipped (the FMU falls back to the next narrower one and says
so in solver.vector_path_used). The solver's accuracy on each path, and
DOP853's, is checked by the restart NRMSD of docs/benchmarks.md on short
pieces. The physics tests (test_chain_physics.py, test_effects_fmu.py) run
on each path through the path_sim fixture.
"""
from __future__ import annotations

import numpy as np
import pytest

from lss_fmu import ccore
from lss_fmu.variables import FORCE_CHANNELS, VARIABLES, value_reference

from conftest import VECTOR_PATHS

RES = str(ccore.build.SRC / "resources").encode()
FORCE_IDX = [value_reference(n) - 1 for n in FORCE_CHANNELS]
ALL_EFFECTS = {"effects.wheel_oor.amplitude": 0.001, "effects.wheel_oor.order": 3,
               "effects.track_bump.height": 0.002, "effects.track_bump.s": 0.7, "effects.track_bump.length": 0.5,
               "effects.joint_clearance.gap": 0.0002, "effects.motor_ripple.amplitude": 30.0,
               "effects.resistance.c1": 2.0, "effects.resistance.c2": 0.5, "effects.mass.spread": 0.1,
               "effects.mass.seed": 4, "effects.sensor.gain.joint.F_x": 0.02}


@pytest.fixture(scope="module")
def core():
    return ccore.load()


def best_path(core) -> int:
    ffi, lib = core
    c = new(core, "demo", 0)
    try:
        return int(outputs(core, c)[value_reference("solver.vector_path_used") - 1])
    finally:
        lib.lss_chain_free(c)


def new(core, layout, path, tol=1e-4, **params):
    ffi, lib = core
    p = lib.lss_params_new()
    lib.lss_params_set_string(p, b"layout.name", layout.encode())
    lib.lss_params_set(p, b"solver.vector_path", path)
    lib.lss_params_set(p, b"solver.tolerance", tol)
    for k, v in params.items():
        assert lib.lss_params_set(p, k.encode(), float(v)) == 0, k
    err = ffi.new("char[1024]")
    c = lib.lss_chain_new(p, RES, err, 1024)
    lib.lss_params_free(p)
    assert c != ffi.NULL, ffi.string(err).decode()
    return c


def ptr(core, a):
    return core[0].cast("double *", core[0].from_buffer(a))


def outputs(core, c):
    out = np.empty(len(VARIABLES))
    core[1].lss_chain_outputs(c, ptr(core, out))
    return out


def step(core, c, t):
    ffi, lib = core
    err = ffi.new("char[1024]")
    assert lib.lss_chain_step(c, t, err, 1024) == 0, ffi.string(err).decode()


def save(core, c):
    buf = np.empty(core[1].lss_chain_state_size(c))
    core[1].lss_chain_state_save(c, ptr(core, buf))
    return buf


def evaluate(core, c, buf):
    """At the saved state: dy, the contacts (indentation, rate, force) and the outputs."""
    lib = core[1]
    lib.lss_chain_state_load(c, ptr(core, buf))
    ny, n = lib.lss_chain_ny(c), lib.lss_chain_n_carts(c)
    y, dy = np.empty(ny), np.empty(ny)
    lib.lss_chain_state(c, ptr(core, y))
    out = outputs(core, c)  # evaluates at the state
    lib.lss_chain_rhs(c, float(buf[1]), ptr(core, y), ptr(core, dy))
    d, dd, f = np.empty(6 * n), np.empty(6 * n), np.empty(6 * n)
    lib.lss_chain_contacts(c, ptr(core, d), ptr(core, dd), ptr(core, f))
    return dict(dy=dy, delta=d, ddelta=dd, force=f, out=out)


def need(core, path):
    if path > best_path(core):
        pytest.skip(f"this CPU or build has no {VECTOR_PATHS[path]} path")


def assert_same_physics(a, b, what):
    # derivatives per quantity of the 13 per cart (and the globals), relative to their scale
    dy_a, dy_b = a["dy"], b["dy"]
    n = (len(dy_a) - 6) // 13
    for k in range(13):
        x, y = dy_a[k:13 * n:13], dy_b[k:13 * n:13]
        scale = max(np.abs(y).max(), 1e-3)
        assert np.abs(x - y).max() <= 1e-8 * scale, (what, "dy component", k, np.abs(x - y).max(), scale)
    np.testing.assert_allclose(dy_a[13 * n:], dy_b[13 * n:], rtol=1e-8, atol=1e-6, err_msg=what)
    np.testing.assert_allclose(a["delta"], b["delta"], rtol=0, atol=1e-12, err_msg=what)
    np.testing.assert_allclose(a["ddelta"], b["ddelta"], rtol=0, atol=1e-9, err_msg=what)
    fmax = np.abs(b["force"]).max()
    np.testing.assert_allclose(a["force"], b["force"], rtol=0, atol=1e-9 * fmax, err_msg=what)
    outs = [value_reference(n) - 1 for n in FORCE_CHANNELS + [
        "transducer.wheel.w_sl", "transducer.wheel.w_dr", "transducer.s", "transducer.v",
        "transducer.joint.v_axial", "chain.v_mean", "drive.F_total", "drive.P_total", "drive.F_cmd",
        "energy.E_mech"]]
    np.testing.assert_allclose(a["out"][outs], b["out"][outs], rtol=1e-8, atol=1e-6, err_msg=what)


def test_paths_are_chosen_and_reported(core):
    ffi, lib = core
    best = best_path(core)
    assert best in VECTOR_PATHS
    for path in (1, 2, 3):
        c = new(core, "demo", path)
        used = int(outputs(core, c)[value_reference("solver.vector_path_used") - 1])
        lib.lss_chain_free(c)
        assert used == min(path, best)  # a path the CPU lacks falls back to the next narrower


@pytest.mark.parametrize("path", [2, 3], ids=["avx2", "avx512"])
@pytest.mark.parametrize("layout", ["layout7", "layout1", "layout3", "demo"])
def test_rhs_matches_scalar(core, path, layout):
    """layout3 and demo have helices (carts on them go to the scalar code)."""
    need(core, path)
    ref = new(core, layout, 1)
    vec = new(core, layout, path)
    try:
        for t in (0.05, 0.3):
            step(core, ref, t)
            buf = save(core, ref)
            assert_same_physics(evaluate(core, vec, buf), evaluate(core, ref, buf), f"{layout} t={t}")
    finally:
        core[1].lss_chain_free(ref)
        core[1].lss_chain_free(vec)


@pytest.mark.parametrize("path", [2, 3], ids=["avx2", "avx512"])
@pytest.mark.parametrize("layout", ["layout7", "demo"])
def test_rhs_matches_scalar_with_every_effect(core, path, layout):
    need(core, path)
    ref = new(core, layout, 1, **ALL_EFFECTS)
    vec = new(core, layout, path, **ALL_EFFECTS)
    try:
        for t in (0.1, 0.4):
            step(core, ref, t)
            buf = save(core, ref)
            assert_same_physics(evaluate(core, vec, buf), evaluate(core, ref, buf), f"{layout} effects t={t}")
    finally:
        core[1].lss_chain_free(ref)
        core[1].lss_chain_free(vec)


@pytest.mark.parametrize("path", [2, 3], ids=["avx2", "avx512"])
@pytest.mark.parametrize("law", [1, 2, 3, 4, 5, 6])
def test_contact_laws_match_scalar(core, path, law):
    need(core, path)
    ref = new(core, "layout7", 1, **{"contact.model": law, "contact.e_SW": 0.3, "contact.e_JA": 0.7})
    vec = new(core, "layout7", path, **{"contact.model": law, "contact.e_SW": 0.3, "contact.e_JA": 0.7})
    try:
        step(core, ref, 0.2)
        buf = save(core, ref)
        assert_same_physics(evaluate(core, vec, buf), evaluate(core, ref, buf), f"law {law}")
    finally:
        core[1].lss_chain_free(ref)
        core[1].lss_chain_free(vec)


@pytest.mark.parametrize("path", [1, 2, 3], ids=list(VECTOR_PATHS.values()))
def test_state_restore_replays_bit_for_bit(core, path):
    """fmi2GetFMUstate/SetFMUstate: the vector path's copies of the contact
    memory and the bases are rebuilt from the loaded state."""
    need(core, path)
    ffi, lib = core
    c = new(core, "layout7", path)
    try:
        step(core, c, 0.2)
        buf = save(core, c)
        idx = ffi.new("int[]", FORCE_IDX)
        err = ffi.new("char[1024]")
        runs = []
        for _ in range(2):
            lib.lss_chain_state_load(c, ptr(core, buf))
            out = np.empty((30, 7))
            assert lib.lss_chain_run(c, 1 / 300, 30, idx, 7, ptr(core, out), err, 1024) == 0
            runs.append(out)
        np.testing.assert_array_equal(runs[0], runs[1])
    finally:
        lib.lss_chain_free(c)


def restart_nrmsd(core, layout, path, tol, method=0, settle=1.0, pieces=2, horizon=0.25):
    """Largest 7-channel restart NRMSD (docs/benchmarks.md) against the
    scalar DOPRI5 at 1e-6, pieces of `horizon` s after `settle` s."""
    ffi, lib = core
    idx = ffi.new("int[]", FORCE_IDX)
    err = ffi.new("char[1024]")
    n_hor = int(round(horizon * 300))

    def run(c, n):
        out = np.empty((n, 7))
        assert lib.lss_chain_run(c, 1 / 300, n, idx, 7, ptr(core, out), err, 1024) == 0, ffi.string(err)
        return out

    ref = new(core, layout, 1, 1e-6)
    run(ref, int(round(settle * 300)))
    states, refs = [], []
    for _ in range(pieces):
        states.append(save(core, ref))
        refs.append(run(ref, n_hor))
    lib.lss_chain_free(ref)
    c = new(core, layout, path, tol, **{"solver.method": method})
    got = []
    for buf in states:
        lib.lss_chain_state_load(c, ptr(core, buf))
        got.append(run(c, n_hor))
    lib.lss_chain_free(c)
    r, g = np.vstack(refs), np.vstack(got)
    rng = r.max(axis=0) - r.min(axis=0)
    return float((np.sqrt(np.mean((g - r) ** 2, axis=0)) / rng).max())


@pytest.mark.parametrize("path", [1, 2, 3], ids=list(VECTOR_PATHS.values()))
def test_restart_nrmsd_within_one_percent(core, path):
    need(core, path)
    assert restart_nrmsd(core, "layout7", path, 1e-4) <= 0.01


@pytest.mark.parametrize("path", [1, 3], ids=["scalar", "vector"])
def test_dop853_restart_nrmsd_within_one_percent(core, path):
    """DOP853 at 1e-2 on layout 7 (the setting docs/benchmarks.md measures),
    fewer evaluations per simulated second than DOPRI5 at 1e-4."""
    path = min(path, best_path(core))
    assert restart_nrmsd(core, "layout7", path, 1e-2, method=1) <= 0.01
    ffi, lib = core
    counts = []
    for method, tol in ((0, 1e-4), (1, 1e-2)):
        c = new(core, "layout7", path, tol, **{"solver.method": method})
        step(core, c, 0.5)
        st = ffi.new("long[3]")
        lib.lss_chain_stats(c, st)
        counts.append(st[2])
        lib.lss_chain_free(c)
    assert counts[1] < 0.8 * counts[0], counts
