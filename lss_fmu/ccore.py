"""Direct access to the C core (without the FMI layer) through cffi.

Used by tests and benchmarks that need what the FMU does not expose: the track
frame at any arc length, a single-impact harness for the contact laws, the raw
cost of the solver. Builds `build/liblsscore.so` from the model sources (all of
`fmu_src/*.c` except the FMI glue) and the flat API of `fmu_src/testing/`
(declared in `core_api.h`, whose declarations cffi reads as they are). The
FMU contains none of the testing API.
"""
from __future__ import annotations

import re
from functools import lru_cache
from pathlib import Path

from cffi import FFI

from . import build

CORE_LIB = build.BUILD / ("liblsscore" + build.shared_suffix())
API_HEADER = build.TESTING / "core_api.h"


def _cdef_from_header(text: str) -> str:
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    keep = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    return "\n".join(keep)


def _stale(out: Path, inputs: list[Path]) -> bool:
    return not out.exists() or any(p.stat().st_mtime > out.stat().st_mtime for p in inputs)


@lru_cache(maxsize=1)
def load():
    """(ffi, lib) for the C core, rebuilt when a source is newer than the library."""
    build.generate()
    sources = ([p for p in build.model_sources() if p.name not in build.FMI_GLUE] + build.testing_sources()
               + [build.GEN / "lss_vars.c"])
    headers = sorted(build.SRC.glob("*.h")) + sorted(build.TESTING.glob("*.h"))
    # the build's own scripts count too: a change of what is compiled makes the library stale
    if _stale(CORE_LIB, sources + headers + [Path(build.__file__), Path(__file__)]):
        build.BUILD.mkdir(exist_ok=True)
        tmp = CORE_LIB.with_suffix(".tmp" + CORE_LIB.suffix)
        build.compile_shared(tmp, sources, extra=["-fvisibility=default", "-I", str(build.TESTING)])
        tmp.replace(CORE_LIB)
    ffi = FFI()
    ffi.cdef(_cdef_from_header(API_HEADER.read_text()))
    return ffi, ffi.dlopen(str(CORE_LIB))
