"""Shared helpers for the FMI tests: one extracted copy of build/LSSChain.fmu
per test session, and `Slave`, an fmpy FMU2Slave whose log messages are
captured per instance and whose calls can be made either through fmpy
(exceptions on error) or raw (the status code as an int)."""
from __future__ import annotations

import atexit
import ctypes
import shutil
from functools import lru_cache
from pathlib import Path

from fmpy import extract, read_model_description
from fmpy import calloc as fmpy_calloc, free as fmpy_free
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)

from lss_fmu.runner import fmu_path

OK, WARNING, DISCARD, ERROR, FATAL, PENDING = range(6)
STATUS_NAME = {OK: "OK", WARNING: "Warning", DISCARD: "Discard", ERROR: "Error", FATAL: "Fatal",
               PENDING: "Pending"}


@lru_cache(maxsize=1)
def fmu_file() -> Path:
    return fmu_path()


@lru_cache(maxsize=1)
def unzipdir() -> str:
    d = extract(str(fmu_file()))
    atexit.register(shutil.rmtree, d, True)
    return d


@lru_cache(maxsize=1)
def model_description():
    """Read from the extracted copy, so that it always matches the binary used."""
    return read_model_description(unzipdir())


def vr(name: str) -> int:
    for v in model_description().modelVariables:
        if v.name == name:
            return v.valueReference
    raise KeyError(name)


def var(name: str):
    for v in model_description().modelVariables:
        if v.name == name:
            return v
    raise KeyError(name)


class Slave:
    """One FMU instance with its own message list."""

    def __init__(self, name: str = "inst", directory: str | None = None, logging_on: bool = False,
                 instantiate: bool = True, resource_uri: str | None = None):
        md = model_description()
        self.messages: list[tuple[int, str, str]] = []
        self.cb = fmi2CallbackFunctions()
        self.cb.logger = fmi2CallbackLoggerTYPE(self._log)
        self.cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(fmpy_calloc)
        self.cb.freeMemory = fmi2CallbackFreeMemoryTYPE(fmpy_free)
        # not fmpy.logging.addLoggerProxy: it keeps one global logger for the whole
        # process, so messages of several instances would all land in the last one
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=directory or unzipdir(),
                             modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
        self.name = name
        self.freed = False
        if instantiate:
            if resource_uri is None:
                self.fmu.instantiate(callbacks=self.cb, loggingOn=logging_on)
            else:
                self.component = self.fmu.fmi2Instantiate(
                    name.encode(), 1, md.guid.encode(), resource_uri.encode(), ctypes.byref(self.cb),
                    0, int(logging_on))
                assert self.component, "fmi2Instantiate returned NULL"
                self.fmu.component = self.component
                self.fmu.callbacks = self.cb

    def _log(self, env, instance, status, category, message):
        # LSSChain logs pre-formatted text (no varargs) with '%' doubled
        self.messages.append((int(status), (category or b"").decode(errors="replace"),
                              (message or b"").decode(errors="replace").replace("%%", "%")))

    # -- messages --------------------------------------------------------------------
    def clear(self) -> None:
        self.messages.clear()

    def last_error(self) -> str:
        errs = [m for s, _, m in self.messages if s >= DISCARD]
        return errs[-1] if errs else ""

    # -- calls ---------------------------------------------------------------------
    def call(self, method: str, *args) -> int:
        """Call an fmpy FMU2Slave method; the FMI status as an int."""
        try:
            getattr(self.fmu, method)(*args)
        except FMICallException as exc:
            return exc.status
        return OK

    def raw(self, fname: str, *args) -> int:
        """Call the C function `fname` directly (ctypes prototype from fmpy)."""
        return self.fmu._functions[fname](*args)

    def set(self, name: str, value) -> int:
        v = var(name)
        setter = {"Real": "setReal", "Integer": "setInteger", "Boolean": "setBoolean", "String": "setString"}
        return self.call(setter[v.type], [v.valueReference], [value])

    def get(self, name: str):
        v = var(name)
        getter = {"Real": self.fmu.getReal, "Integer": self.fmu.getInteger, "Boolean": self.fmu.getBoolean,
                  "String": self.fmu.getString}[v.type]
        val = getter([v.valueReference])[0]
        return val.decode() if isinstance(val, bytes) else val

    def get_reals(self, names):
        return self.fmu.getReal([vr(n) for n in names])

    def init(self, params=None, tolerance=None, start=0.0) -> None:
        for k, value in (params or {}).items():
            assert self.set(k, value) == OK, (k, value, self.last_error())
        self.fmu.setupExperiment(tolerance=tolerance, startTime=start)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()

    def free(self) -> None:
        if not self.freed:
            self.freed = True
            self.fmu.freeInstance()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.free()


def run(slave: Slave, stop: float, step: float, outputs, t0: float = 0.0, on_step=None):
    """Step an initialised slave from t0 to stop; rows of [t, outputs...]."""
    import numpy as np
    vrs = [vr(o) for o in outputs]
    n = int(round((stop - t0) / step))
    rows = [[t0, *slave.fmu.getReal(vrs)]]
    t = t0
    for k in range(1, n + 1):
        if on_step:
            on_step(slave, t)
        t_next = t0 + k * step
        slave.fmu.doStep(t, t_next - t)
        t = t_next
        rows.append([t, *slave.fmu.getReal(vrs)])
    return np.array(rows)
