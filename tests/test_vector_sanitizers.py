"""The FMU's sources at -O0 and -O1 under AddressSanitizer + UndefinedBehaviorSanitizer
run every right-hand-side path this CPU has, cleanly, and agree with the -O2 build.

The source FMU may be compiled anywhere with any reasonable flags; issue 19's
AVX-512 kernel crashed in such builds (ASan with detect_stack_use_after_return:
at -O1, GCC derived a 64-byte alignment for a stack array of lanes that ASan's
fake stack frame did not give, chain_simd_kernel.h, Lanes; at any level with
-fstack-protector-strong, the guard shifted the fake frame and the kernel's
__m512d arrays with it, hence -O0 is built with the stack protector here).
tests/c/vector_paths_run.c, linked with the model sources, runs 100
communication steps of 1 ms on layouts 7 and 3 with solver.vector_path 1
(scalar), 2 (AVX2) and 3 (AVX-512), skipping the paths the CPU lacks; each
sanitized build must take the same paths as the -O2 build (no silent scalar
fallback), report nothing, and end within the solver tolerance of the -O2
outputs (with -std=c11 there is no FMA contraction, so they agree bit for bit
today; the tolerance leaves room for other compilers' choices).

tests/test_c_harness.py runs the FMI life cycle, threads and corrupted states
under the same sanitizers (and ThreadSanitizer) on every path.
"""
from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import c_objects
from c_objects import CC
from conftest import VECTOR_PATHS
from test_c_harness import _sanitizer_works, resource_uri

DRIVER = Path(__file__).parent / "c" / "vector_paths_run.c"
# 0.1 s: every cart takes its element kind's kernel from the first step; longer adds time, not code
STOP, STEP, TOL = 0.1, 0.001, 1e-6
LAYOUTS = ("layout7", "layout3")
ASAN = ["-fno-omit-frame-pointer", "-fsanitize=address,undefined", "-fno-sanitize-recover=all"]
ENV = dict(os.environ, ASAN_OPTIONS="detect_leaks=1:halt_on_error=1:detect_stack_use_after_return=1",
           UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1")
# -O0 also with the stack protector (Ubuntu's GCC default): with ASan's fake stack GCC 12 misplaced
# the AVX-512 kernels' 64-byte locals by the guard (chain_simd_kernel.h)
LEVELS = {"-O0": ["-O0", "-fstack-protector-strong"], "-O1": ["-O1"]}


def _run(exe: Path, cases: list[str]) -> dict:
    res = subprocess.run([str(exe), resource_uri(), str(STOP), str(STEP), str(TOL), *cases], capture_output=True,
                         text=True, env=ENV, timeout=600)
    report = res.stdout + res.stderr
    for marker in ("AddressSanitizer", "LeakSanitizer", "runtime error:", "FAIL"):
        assert marker not in report, report[-4000:]
    assert res.returncode == 0, report[-4000:]
    lines = res.stdout.splitlines()
    names = lines[0].split()[1:]
    runs = {}
    for ln in lines[1:]:
        f = ln.split()
        runs[(f[1], int(f[2]))] = dict(used=int(f[3]), steps=int(f[4]), out=np.array([float(v) for v in f[5:]]))
    return dict(names=names, runs=runs)


def _compile(work: Path, objects: Path, level: str, flags: list[str]) -> Path:
    return c_objects.link(work / f"run{level}", DRIVER, flags, objects)


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    if shutil.which(CC) is None:
        pytest.skip(f"no C compiler ({CC})")
    work = tmp_path_factory.mktemp("vector_sanitizers")
    if not _sanitizer_works(["-O1", *ASAN], work):
        pytest.skip("the compiler has no AddressSanitizer/UBSan runtime")
    return work


@pytest.fixture(scope="module")
def objects(tmp_path_factory):
    return c_objects.shared_dir(tmp_path_factory)


@pytest.fixture(scope="module")
def reference(work, objects):
    """The -O2 build's results on every path, and the paths this CPU has."""
    ref = _run(_compile(work, objects, "-O2", ["-O2"]), [f"{lay}:{p}" for lay in LAYOUTS for p in VECTOR_PATHS])
    paths = [p for p in VECTOR_PATHS if all(ref["runs"][(lay, p)]["used"] == p for lay in LAYOUTS)]
    for p in VECTOR_PATHS:
        if p not in paths:
            print(f"this CPU or build has no {VECTOR_PATHS[p]} path: not run")
    assert 1 in paths
    return ref, paths


@pytest.mark.parametrize("level", [pytest.param(lv, marks=pytest.mark.slow) if lv == "-O0" else lv
                                   for lv in sorted(LEVELS)])
def test_sanitized_build_runs_every_path_like_O2(work, objects, reference, level):
    ref, paths = reference
    exe = _compile(work, objects, level, [*LEVELS[level], *ASAN])
    got = _run(exe, [f"{lay}:{p}" for lay in LAYOUTS for p in paths])
    assert got["names"] == ref["names"]
    names = ref["names"]
    forces = [i for i, n in enumerate(names) if ".F_" in n]
    for lay in LAYOUTS:
        for p in paths:
            a, b = got["runs"][(lay, p)], ref["runs"][(lay, p)]
            what = f"{level} {lay} {VECTOR_PATHS[p]}"
            assert a["used"] == p, f"{what}: the sanitized build took path {a['used']} (the -O2 build takes {p})"
            assert a["steps"] == b["steps"] == round(STOP / STEP)
            assert np.isfinite(a["out"]).all(), what
            # within the solver tolerance (100 times the local one, TOL, over the run): relative, the
            # forces judged by the largest of them
            scale = np.maximum(np.abs(b["out"]), 1e-3)
            scale[forces] = np.abs(b["out"][forces]).max()
            bad = np.abs(a["out"] - b["out"]) > 100 * TOL * scale
            assert not bad.any(), (what, [(names[i], a["out"][i], b["out"][i]) for i in np.flatnonzero(bad)])
