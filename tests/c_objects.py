"""The model's C sources compiled once per set of flags and test session, and linked
with a test driver (tests/test_c_harness.py, tests/test_vector_sanitizers.py).

Under AddressSanitizer at -O1 each SIMD kernel takes about half a minute to
compile, and the two sanitized tests build the same sources with the same
flags: the objects are made once, in parallel, in a folder the test
processes share (pytest-xdist's workers lock it), and each driver is linked
against them.
"""
from __future__ import annotations

import fcntl
import hashlib
import os
import subprocess
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from lss_fmu import build

CC = os.environ.get("CC", "gcc")
COMMON = ["-std=c11", "-g", "-Wall", "-Wextra", "-Werror"]


def shared_dir(tmp_path_factory) -> Path:
    """A folder of this test session that every xdist worker sees."""
    base = tmp_path_factory.getbasetemp()
    root = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base
    out = root / "c_objects"
    out.mkdir(exist_ok=True)
    return out


def _includes() -> list[str]:
    return ["-I", str(build.GEN), "-I", str(build.SRC), "-I", str(build.fmi_headers())]


def model_objects(flags: list[str], where: Path) -> list[Path]:
    """The objects of the model's sources (and the generated variable table)
    compiled with `flags`, made by the first caller of a session."""
    build.generate()
    if not (build.GEN / "lss_guid.h").exists():
        build.build_fmu(quiet=True)
    sources = [*build.model_sources(), build.GEN / "lss_vars.c"]
    key = hashlib.sha1("\0".join([CC, *flags]).encode()).hexdigest()[:12]
    folder = where / key
    objects = [folder / f"{s.stem}.o" for s in sources]
    with open(where / f"{key}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (folder / "done").exists():
            folder.mkdir(exist_ok=True)

            def one(src_obj):
                src, obj = src_obj
                cmd = [CC, *COMMON, *flags, *_includes(), "-c", "-o", str(obj), str(src)]
                res = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
                assert res.returncode == 0, f"{src.name} does not compile:\n{' '.join(cmd)}\n{res.stderr}"

            with ThreadPoolExecutor(max_workers=os.cpu_count() or 2) as pool:
                list(pool.map(one, zip(sources, objects)))
            (folder / "done").touch()
    return objects


def link(out: Path, driver: Path, flags: list[str], where: Path, libs=("-lm",)) -> Path:
    """`driver` compiled with `flags` and linked with the model's objects into `out`."""
    objects = model_objects(flags, where)
    cmd = [CC, *COMMON, *flags, *_includes(), "-o", str(out), str(driver), *map(str, objects), *libs]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, f"{driver.name} does not compile or link:\n{' '.join(cmd)}\n{res.stderr}"
    return out
