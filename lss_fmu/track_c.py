"""The C track geometry (fmu_src/track.c, layout_io.c) through its flat cffi API
(fmu_src/testing/core_api.h, "track geometry"), with numpy in and out.

Used by the tests that hold the C and Python geometry to each other and by
anyone who wants the FMU's own track frame without running the FMU.
"""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Union

import numpy as np

from .layout_format import LayoutError
from .track_geometry import MOTOR_LENGTH, TOL_ANG, TOL_POS

ERRLEN = 1024
TRACK_SOURCES = ("layout_io.c", "track.c", "testing/core_api_track.c")


@lru_cache(maxsize=1)
def _track_only():
    """Just the track sources compiled on their own (when the full core does not build)."""
    import tempfile

    from cffi import FFI

    from . import build, ccore
    out = Path(tempfile.mkdtemp(prefix="lss_track_")) / ("libtrack" + build.shared_suffix())
    build.compile_shared(out, [build.SRC / n for n in TRACK_SOURCES],
                         extra=["-fvisibility=default", "-I", str(build.TESTING)])
    ffi = FFI()
    ffi.cdef(ccore._cdef_from_header(ccore.API_HEADER.read_text()))
    return ffi, ffi.dlopen(str(out))


def load_lib(fallback: bool = True):
    """(ffi, lib): the full core library (lss_fmu.ccore), or with fallback the
    track sources alone if the rest of the core does not compile right now."""
    from . import ccore
    try:
        ffi, lib = ccore.load()
        lib.lss_track_open  # the track API is in this library
        return ffi, lib
    except Exception:
        if not fallback:
            raise
        return _track_only()


class CTrack:
    """A layout parsed and built by the C core. Raises LayoutError with C's message."""

    def __init__(self, path: Union[str, Path, None] = None, text: Union[str, bytes, None] = None,
                 motor_length: float = MOTOR_LENGTH, tol_pos: float = TOL_POS, tol_ang: float = TOL_ANG,
                 lib=None):
        self.ffi, self.lib = lib or load_lib()
        err = self.ffi.new("char[]", ERRLEN)
        if text is not None:
            data = text.encode() if isinstance(text, str) else bytes(text)
            h = self.lib.lss_track_open_text(data, len(data), motor_length, tol_pos, tol_ang, err, ERRLEN)
        else:
            h = self.lib.lss_track_open(str(path).encode(), motor_length, tol_pos, tol_ang, err, ERRLEN)
        if h == self.ffi.NULL:
            raise LayoutError(self.ffi.string(err).decode("latin-1"))
        self._h = self.ffi.gc(h, self.lib.lss_track_close)

    @property
    def length(self) -> float:
        return self.lib.lss_track_length(self._h)

    def frame(self, s):
        """(c (N,3), R (N,3,3), w (N,3)) at arc lengths s."""
        s = np.ascontiguousarray(np.atleast_1d(np.asarray(s, dtype=float)))
        out = np.zeros((len(s), 15))
        self.lib.lss_track_eval_many(self._h, self.ffi.cast("double *", s.ctypes.data), len(s),
                                     self.ffi.cast("double *", out.ctypes.data))
        return out[:, :3], out[:, 3:12].reshape(-1, 3, 3), out[:, 12:]

    @property
    def closure(self):
        out = self.ffi.new("double[4]")
        self.lib.lss_track_closure(self._h, out)
        return np.array(list(out[0:3])), out[3]

    @property
    def motors(self) -> np.ndarray:
        n = self.lib.lss_track_n_motors(self._h)
        buf = self.ffi.new("double[2]")
        out = np.zeros((n, 2))
        for k in range(n):
            self.lib.lss_track_motor(self._h, k, buf)
            out[k] = buf[0], buf[1]
        return out

    @property
    def elements(self) -> list:
        """[(kind, line, s0, length)] per element."""
        kl, sl = self.ffi.new("int[2]"), self.ffi.new("double[2]")
        out = []
        for i in range(self.lib.lss_track_n_elements(self._h)):
            self.lib.lss_track_element(self._h, i, kl, sl)
            out.append((kl[0], kl[1], sl[0], sl[1]))
        return out

    @property
    def header(self) -> dict:
        name = self.ffi.new("char[64]")
        ints, dbls = self.ffi.new("int[4]"), self.ffi.new("double[5]")
        self.lib.lss_track_header(self._h, name, 64, ints, dbls)
        return dict(name=self.ffi.string(name).decode(), wheel=chr(ints[0]), coupling=chr(ints[1]),
                    n_motors=ints[2], n_carts=ints[3], start=tuple(dbls[0:3]), heading=dbls[3],
                    cart_mass=dbls[4])


def c_parse_error(text: Union[str, bytes], lib=None):
    """C's parse-only verdict on layout text: (None, n_el) or (message, 0)."""
    ffi, clib = lib or load_lib()
    data = text.encode() if isinstance(text, str) else bytes(text)
    err = ffi.new("char[]", ERRLEN)
    n = ffi.new("int *")
    rc = clib.lss_layout_check_text(data, len(data), n, err, ERRLEN)
    return (ffi.string(err).decode("latin-1"), 0) if rc else (None, n[0])
