"""Shared pieces of the speed benchmarks: the C core without FMI (cffi), a
run at 300 Hz communication, CPU time, and the 7-channel NRMSD.

NRMSD of channel j (the identification's H_j, brief section 5): the RMS of
the difference against the reference divided by the reference's range
(max - min). The 7 channels are the transducer forces (FORCE_CHANNELS). We
report the largest of the seven (the figure held to <= 1 %) and their RMS.
"""
from __future__ import annotations

import os
import platform
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Optional

# numpy's BLAS threads would spin on the second core and count as this
# process's CPU time: one thread, so CPU time is the chain's.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from lss_fmu import build  # noqa: E402
from lss_fmu.variables import FORCE_CHANNELS, value_reference  # noqa: E402

RESOURCES = ROOT / "fmu_src" / "resources"
COMM = 1.0 / 300.0
DEFAULT_TOL = 1e-4
FORCE_IDX = [value_reference(n) - 1 for n in FORCE_CHANNELS]
LAYOUT_CARTS = {"layout7": 52, "layout1": 171, "layout3": 685}


def load_core(lib_path: Optional[str] = None):
    """(ffi, lib) of the C core: lss_fmu.ccore's (rebuilt if stale) or a given
    shared library with the same API (e.g. a snapshot of an older version)."""
    from lss_fmu import ccore
    if lib_path is None:
        return ccore.load()
    from cffi import FFI
    ffi = FFI()
    ffi.cdef(ccore._cdef_from_header(ccore.API_HEADER.read_text()))
    return ffi, ffi.dlopen(str(lib_path))


@dataclass
class CoreResult:
    forces: np.ndarray        # [n_samples, 7] at every communication point of the window
    cpu: float                # CPU seconds of the timed window
    n_carts: int
    window: float             # simulated seconds timed
    stats: tuple              # steps, rejected, rhs over the timed window

    @property
    def throughput(self) -> float:
        return self.n_carts * self.window / self.cpu


def run_core(layout: str, tol: float, settle: float, window: float, params: Optional[Mapping] = None,
             core=None, comm: float = COMM) -> CoreResult:
    """Create the chain, integrate `settle` seconds untimed, then `window`
    seconds timed, stepping to every communication point and reading the
    outputs there (what an FMI master does, minus the FMI layer)."""
    ffi, lib = core or load_core()
    p = lib.lss_params_new()
    lib.lss_params_set_string(p, b"layout.name", layout.encode())
    lib.lss_params_set(p, b"solver.tolerance", tol)
    for k, v in (params or {}).items():
        if isinstance(v, str):
            lib.lss_params_set_string(p, k.encode(), v.encode())
        elif lib.lss_params_set(p, k.encode(), float(v)):
            raise KeyError(k)
    err = ffi.new("char[1024]")
    c = lib.lss_chain_new(p, str(RESOURCES).encode(), err, 1024)
    lib.lss_params_free(p)
    if c == ffi.NULL:
        raise RuntimeError(ffi.string(err).decode())
    nvar = len(__import__("lss_fmu.variables", fromlist=["VARIABLES"]).VARIABLES)
    out = np.empty(nvar)
    out_p = ffi.cast("double *", ffi.from_buffer(out))
    st = ffi.new("long[3]")
    try:
        n_settle = int(round(settle / comm))
        for k in range(1, n_settle + 1):
            if lib.lss_chain_step(c, k * comm, err, 1024):
                raise RuntimeError(ffi.string(err).decode())
        lib.lss_chain_stats(c, st)
        s0 = tuple(st)
        n_win = int(round(window / comm))
        forces = np.empty((n_win + 1, len(FORCE_IDX)))
        lib.lss_chain_outputs(c, out_p)
        forces[0] = out[FORCE_IDX]
        t0 = time.process_time()
        for k in range(1, n_win + 1):
            if lib.lss_chain_step(c, (n_settle + k) * comm, err, 1024):
                raise RuntimeError(ffi.string(err).decode())
            lib.lss_chain_outputs(c, out_p)
            forces[k] = out[FORCE_IDX]
        cpu = time.process_time() - t0
        lib.lss_chain_stats(c, st)
        stats = tuple(int(a - b) for a, b in zip(st, s0))
        n = lib.lss_chain_n_carts(c)
    finally:
        lib.lss_chain_free(c)
    return CoreResult(forces, cpu, n, n_win * comm, stats)


def nrmsd(x: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Per-channel RMS(x - ref) / (max(ref) - min(ref))."""
    rng = ref.max(axis=0) - ref.min(axis=0)
    rmsd = np.sqrt(np.mean((x - ref) ** 2, axis=0))
    return rmsd / np.where(rng > 0, rng, 1.0)


def nrmsd_summary(x: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    """(largest of the 7 channels, RMS over the 7 channels)."""
    h = nrmsd(x, ref)
    return float(h.max()), float(np.sqrt(np.mean(h ** 2)))


def machine() -> str:
    model, cores = "?", os.cpu_count()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem = ""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal"):
                mem = f", {int(line.split()[1]) / 1048576:.1f} GiB RAM"
    except OSError:
        pass
    return (f"{model}, {cores} cores{mem}; {platform.system()} {platform.release()}; "
            f"Python {platform.python_version()}; CC {os.environ.get('CC', 'gcc')} {' '.join(build.CFLAGS)}")


def hash_sources(h):
    """`h` (a hashlib object) updated with the path and bytes of every source file of
    identification/, lss_fmu/ and fmu_src/, in sorted order: what decides a result, for a
    benchmark's code stamp. Returns h."""
    for folder in ("identification", "lss_fmu", "fmu_src"):
        for path in sorted((ROOT / folder).rglob("*")):
            if path.is_file() and "__pycache__" not in path.parts and path.suffix != ".pyc":
                h.update(path.relative_to(ROOT).as_posix().encode())
                h.update(path.read_bytes())
    return h


def code_version() -> str:
    """The commit a result was computed on, '+changes' when the model or
    identification code differs from it (so a table says which code it is from)."""
    import subprocess
    root = Path(__file__).resolve().parents[1]
    try:
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True,
                             text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "fmu_src", "lss_fmu", "identification"],
                               cwd=root, capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return rev + ("+changes" if dirty else "")


def write_between(doc: Path, tag: str, text: str) -> None:
    """Put `text` into `doc` between <!-- TAG:begin --> and <!-- TAG:end -->
    (the prose around them is kept); an error naming the file and the markers
    if they are missing."""
    begin, end = f"<!-- {tag}:begin -->", f"<!-- {tag}:end -->"
    old = Path(doc).read_text()
    if begin not in old or end not in old:
        raise SystemExit(f"{doc} has no {begin} ... {end} block")
    head, rest = old.split(begin, 1)
    _, tail = rest.split(end, 1)
    Path(doc).write_text(head + begin + "\n" + text.strip("\n") + "\n" + end + tail)
