"""Shared fixtures: the FMU is built once per session; one simulator instance
is reused (with fmi2Reset between runs), as identification does."""
from __future__ import annotations

from pathlib import Path

import pytest

from lss_fmu import build

DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="session")
def fmu_file() -> Path:
    return build.build_fmu(quiet=True)


@pytest.fixture(scope="session")
def sim(fmu_file):
    from lss_fmu.runner import ChainSimulator
    s = ChainSimulator(fmu_file)
    yield s
    s.close()


@pytest.fixture(scope="session")
def rig_record(tmp_path_factory, fmu_file):
    """rig_record(number, protocol, seconds, repeat=0): a recovery measurement
    made by the virtual transducer cart (lss_fmu.rig), loaded back as a
    Measurement from its own folder (its answers beside it)."""
    from lss_fmu import measurement as M
    from lss_fmu.rig import folder_name, run_measurement
    from lss_fmu.runner import ChainSimulator

    def make(number: int, protocol: str, seconds: float, repeat: int = 0):
        out = tmp_path_factory.mktemp(f"rig_{protocol}_m{number}_r{repeat}")
        with ChainSimulator() as s:
            run_measurement("recovery", number, out, s, protocol=protocol, lap_seconds=seconds, repeat=repeat)
        return M.load_measurement(out / folder_name(number))
    return make


@pytest.fixture
def data_dir() -> Path:
    return DATA


# --- the right-hand-side paths (issue 19) --------------------------------------------
VECTOR_PATHS = {1: "scalar", 2: "avx2", 3: "avx512"}


def path_available(fmu_file, path: int) -> bool:
    """Whether this CPU and build run solver.vector_path = path (the FMU
    reports the path it took in solver.vector_path_used)."""
    from lss_fmu.runner import ChainSimulator
    with ChainSimulator(fmu_file) as s:
        s.start({"layout.name": "demo", "solver.vector_path": path})
        return int(s.get("solver.vector_path_used")) == path


@pytest.fixture(scope="session")
def best_vector_path(fmu_file) -> int:
    """The widest path the -O2 FMU runs on this CPU (what solver.vector_path
    = 0, auto, picks)."""
    from lss_fmu.runner import ChainSimulator
    with ChainSimulator(fmu_file) as s:
        s.start({"layout.name": "demo", "solver.vector_path": 0})
        return int(s.get("solver.vector_path_used"))


@pytest.fixture(scope="session", params=sorted(VECTOR_PATHS), ids=list(VECTOR_PATHS.values()))
def path_sim(request, fmu_file):
    """A simulator forced onto one right-hand-side path (solver.vector_path
    set in every run unless the test sets it): the physics tests run on each
    path through it; skipped where the CPU lacks the path."""
    from lss_fmu.runner import ChainSimulator
    path = request.param
    if not path_available(fmu_file, path):
        pytest.skip(f"this CPU or build has no {VECTOR_PATHS[path]} path")

    class PathSimulator(ChainSimulator):
        def start(self, params=None, tolerance=None, start_time=0.0):
            super().start({"solver.vector_path": path, **(params or {})}, tolerance, start_time)

    s = PathSimulator(fmu_file)
    s.vector_path = path
    yield s
    s.close()
