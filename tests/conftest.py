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


@pytest.fixture
def data_dir() -> Path:
    return DATA
