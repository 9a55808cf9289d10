"""The C harness (fmu_src/testing/test_harness.c) drives the FMI 2.0 API without fmpy,
compiled together with the model sources:

- under AddressSanitizer + UndefinedBehaviorSanitizer (LeakSanitizer on,
  detect_stack_use_after_return on), built at -O0 and at -O1: 1000
  instantiate / set / setup / initialise / step / reset / re-initialise /
  step / terminate / free cycles with wrong calls and every error path, 4
  instances on 4 threads, 300 corrupted serialized FMU states, every word of a
  serialized state set to NaN, +-inf, 0, -1, 1e300 in turn; no sanitizer
  report, every allocation returned through the freeMemory callback;
- under ThreadSanitizer: instances stepped at once on several threads, no data
  race, the same results as one after another.

Cycle k and thread k ask for right-hand-side path k % 4 (auto, scalar, AVX2,
AVX-512): every build runs each vector path this CPU has (the -O2 FMU's
choice), and the harness counts the paths it got. The sanitizer builds keep
the vector kernels; only the TSan build leaves out the solver loops'
target_clones (dopri5.c says why). tests/test_vector_sanitizers.py runs longer
simulations of the sanitized sources on each path against the -O2 build.

The longer leak check (10,000 cycles under valgrind or LSan) is
tests/c/leakcheck.sh, outside `make test`.
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from lss_fmu import build

import c_objects
from c_objects import CC

CYCLES = 1000
# one internal step per run: the cycle's cost is then the FMU's life cycle,
# not the physics (0.05 s of simulated time would cost ~0.5 s per cycle here)
STOP = STEP = 1e-4


def _sanitizer_works(flags: list[str], tmp: Path) -> bool:
    probe = tmp / "probe.c"
    probe.write_text("int main(void) { return 0; }\n")
    exe = tmp / "probe"
    res = subprocess.run([CC, *flags, str(probe), "-o", str(exe)], capture_output=True)
    return res.returncode == 0 and subprocess.run([str(exe)], capture_output=True).returncode == 0


def compile_harness(out: Path, flags: list[str], objects: Path) -> Path:
    return c_objects.link(out, build.TESTING / "test_harness.c", flags, objects, libs=("-lm", "-lpthread"))


def resource_uri() -> str:
    return (build.SRC / "resources").resolve().as_uri()


def summary(stdout: str) -> dict:
    line = [ln for ln in stdout.splitlines() if ln.startswith("summary:")][-1]
    return {k.strip().replace(" ", "_"): int(v) for v, k in
            [(m.group(2), m.group(1)) for m in re.finditer(r"([a-z][a-z _]*?) (-?\d+)", line)]}


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    if shutil.which(CC) is None:
        pytest.skip(f"no C compiler ({CC})")
    return tmp_path_factory.mktemp("harness")


@pytest.fixture(scope="module")
def objects(tmp_path_factory):
    return c_objects.shared_dir(tmp_path_factory)


def paths_used(stdout: str) -> dict:
    """solver.vector_path_used counted by the harness: {1: scalar, 2: avx2, 3: avx512}."""
    line = [ln for ln in stdout.splitlines() if ln.startswith("vector paths used:")][-1]
    counts = dict(re.findall(r"(scalar|avx2|avx512) (\d+)", line))
    return {1: int(counts["scalar"]), 2: int(counts["avx2"]), 3: int(counts["avx512"])}


def assert_every_path_ran(stdout: str, best: int) -> None:
    used = paths_used(stdout)
    for p in (1, 2, 3):
        assert (used[p] > 0) == (p <= best), (used, f"the -O2 FMU's widest path is {best}")


@pytest.mark.parametrize("level", [pytest.param("-O0", marks=pytest.mark.slow), "-O1"])
def test_harness_under_asan_ubsan(workdir, objects, best_vector_path, level):
    flags = [level, "-fno-omit-frame-pointer", "-fsanitize=address,undefined", "-fno-sanitize-recover=all"]
    if not _sanitizer_works(flags, workdir):
        pytest.skip("the compiler has no AddressSanitizer/UBSan runtime")
    exe = compile_harness(workdir / f"harness_asan{level}", flags, objects)
    env = dict(os.environ, ASAN_OPTIONS="detect_leaks=1:halt_on_error=1:detect_stack_use_after_return=1",
               UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1")
    res = subprocess.run([str(exe), resource_uri(), "--cycles", str(CYCLES), "--stop", str(STOP),
                          "--step", str(STEP), "--threads", "4", "--corrupt", "300", "--fieldwise"],
                         capture_output=True, text=True, env=env, timeout=600)
    print(res.stdout)
    report = res.stdout + res.stderr
    for marker in ("AddressSanitizer", "LeakSanitizer", "runtime error:", "FAIL"):
        assert marker not in report, report[-4000:]
    assert res.returncode == 0, report[-4000:]
    s = summary(res.stdout)
    assert s["cycles"] == CYCLES
    assert s["live_at_exit"] == 0 and s["failures"] == 0
    assert s["bad_inputs"] > 20 * CYCLES
    assert "threads: 4 instances stepped at once agree" in res.stdout
    # every 8-byte word of a serialized state set to NaN, +-inf, 0, -1, 1e300 (issue 20)
    m = re.search(r"fieldwise states: (\d+) words x 6 values; refused at deserialize (\d+), at set (\d+); "
                  r"stepped (\d+), discarded (\d+)", res.stdout)
    assert m, res.stdout[-2000:]
    words, *counts = map(int, m.groups())
    assert words > 1000 and sum(counts) > 5 * words
    assert_every_path_ran(res.stdout, best_vector_path)


def test_threads_under_tsan(workdir, objects, best_vector_path):
    flags = ["-O1", "-fsanitize=thread"]
    if not _sanitizer_works(flags + ["-lpthread"], workdir):
        pytest.skip("the compiler has no ThreadSanitizer runtime")
    exe = compile_harness(workdir / "harness_tsan", flags, objects)
    res = subprocess.run([str(exe), resource_uri(), "--threads", "4", "--stop", "0.002", "--step", "0.001"],
                         capture_output=True, text=True, env=dict(os.environ, TSAN_OPTIONS="halt_on_error=1"),
                         timeout=600)
    report = res.stdout + res.stderr
    assert "ThreadSanitizer" not in report, report[-4000:]
    assert res.returncode == 0, report[-4000:]
    assert "agree with one after another" in res.stdout
    assert_every_path_ran(res.stdout, best_vector_path)  # the 4 threads: auto, scalar, AVX2, AVX-512


# --- the layout fuzz target: corpus replay (and a short libFuzzer run with clang) -------------

CORPUS = Path(__file__).parent / "c" / "corpus_layout"
FUZZ_SRC = [Path(__file__).parent / "c" / "fuzz_layout.c", build.SRC / "layout_io.c", build.SRC / "track.c"]


def test_layout_fuzz_corpus_replays_clean_under_asan(workdir):
    """Every input the fuzzer kept (tests/c/corpus_layout, minimised) plus the
    built-in layouts, through layout_parse and track_build, with the fuzz
    target's checks, under ASan/UBSan with gcc: a regression test for the
    fuzzing campaign that needs no libFuzzer."""
    flags = ["-O1", "-fno-omit-frame-pointer", "-fsanitize=address,undefined", "-fno-sanitize-recover=all"]
    if not _sanitizer_works(flags, workdir):
        pytest.skip("the compiler has no AddressSanitizer/UBSan runtime")
    exe = workdir / "fuzz_replay"
    cmd = [CC, "-std=c11", "-g", "-DFUZZ_REPLAY", "-D_DEFAULT_SOURCE", *flags, "-I", str(build.SRC),
           "-o", str(exe), *map(str, FUZZ_SRC), "-lm"]
    res = subprocess.run(cmd, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    res = subprocess.run([str(exe), str(CORPUS), str(build.SRC / "resources" / "layouts")], capture_output=True,
                         text=True, timeout=600, env=dict(os.environ, ASAN_OPTIONS="detect_leaks=1"))
    assert res.returncode == 0, (res.stdout + res.stderr)[-4000:]
    n = int(re.search(r"replayed (\d+) inputs", res.stdout).group(1))
    assert n >= len(list(CORPUS.iterdir())) + 9


def test_layout_fuzzer_short_run(workdir, tmp_path):
    """20 s of libFuzzer on the layout reader, seeded with the corpus (only
    where clang with libFuzzer is installed; the campaign itself is recorded
    in docs/robustness.md)."""
    clang = shutil.which("clang")
    if clang is None:
        pytest.skip("clang (libFuzzer) not installed")
    exe = workdir / "fuzz_layout"
    cmd = [clang, "-g", "-O1", "-fsanitize=fuzzer,address,undefined", "-fno-sanitize-recover=all",
           "-I", str(build.SRC), "-o", str(exe), *map(str, FUZZ_SRC), "-lm"]
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0 and "fuzzer" in res.stderr:
        pytest.skip("clang without the libFuzzer runtime")
    assert res.returncode == 0, res.stderr
    work = tmp_path / "corpus"
    work.mkdir()
    res = subprocess.run([str(exe), "-max_total_time=20", "-timeout=10", "-rss_limit_mb=2048",
                          f"-dict={CORPUS.parent / 'layout.dict'}", f"-artifact_prefix={tmp_path}/",
                          str(work), str(CORPUS)], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-4000:]
    assert "Done" in res.stderr
