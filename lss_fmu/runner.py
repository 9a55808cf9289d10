"""Run LSSChain.fmu through fmpy, fast and repeatedly.

`ChainSimulator` extracts the FMU once, instantiates it once and reuses the
instance with `fmi2Reset` for every run; outputs are read through pre-built
ctypes arrays so the per-communication-point overhead stays small. Every FMU
message is collected, and an FMU error becomes a `SimulationError` carrying
the FMU's own words.
"""
from __future__ import annotations

import atexit
import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Iterator, Mapping, Optional, Sequence

import numpy as np
import pandas as pd
from fmpy import calloc as fmpy_calloc, extract, free as fmpy_free, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, fmi2Error, fmi2Real, fmi2ValueReference,
                       fmi2Warning)

from . import build
from .variables import FORCE_CHANNELS, SPEED_CHANNELS, VARIABLES

DEFAULT_OUTPUTS = FORCE_CHANNELS + SPEED_CHANNELS + ["transducer.s", "chain.v_mean"]
# what may change after initialisation, with the FMU's default: a relaxed chain at rest serves every value
TUNABLE = {v.name: v.start for v in VARIABLES if v.causality in ("parameter", "input")
           and v.variability in ("tunable", "continuous")}
_PROCESS_SIMULATORS: dict = {}   # (FMU path, pid) -> the simulator copies sent to this process share
REST_STATES = 12    # relaxed chains kept per simulator: a central Jacobian's (its base, and up to four steps of
                    # each of the two variables the equilibrium depends on, d and s_M) stay while it runs;
                    # a snapshot is about 40 doubles per cart (0.2 MB at 685 carts)


class SimulationError(RuntimeError):
    """The FMU refused a value or a run failed; the message is the FMU's."""


@dataclass
class RunInfo:
    n_steps: int
    n_rejected: int
    n_rhs: int
    h_last: float
    messages: list


def fmu_path(path: Optional[Path] = None) -> Path:
    """The FMU to use: the given one, or build/LSSChain.fmu (built if missing)."""
    if path is not None:
        p = Path(path)
        if not p.exists():
            raise FileNotFoundError(f"FMU not found: {p}")
        return p
    if not build.FMU_PATH.exists():
        build.build_fmu(quiet=True)
    return build.FMU_PATH


class ChainSimulator:
    """One FMU instance, reused for many runs."""

    def __init__(self, path: Optional[Path] = None, instance_name: str = "lss", logging_on: bool = False):
        self.path = fmu_path(path)
        self.md = read_model_description(str(self.path))
        self._unzipdir = extract(str(self.path))
        atexit.register(shutil.rmtree, self._unzipdir, True)
        self.variables = {v.name: v for v in self.md.modelVariables}
        self.messages: list[tuple[int, str, str]] = []
        self._callbacks = fmi2CallbackFunctions()
        self._callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self._callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(fmpy_calloc)
        self._callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(fmpy_free)
        # No fmpy.logging.addLoggerProxy: it keeps ONE global logger, so with two
        # simulators in a process every message would land in the last one's list.
        # LSSChain passes its messages pre-formatted (no varargs, '%' doubled), so
        # the callback only has to undo the doubling (see _log).
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self._unzipdir,
                             modelIdentifier=self.md.coSimulation.modelIdentifier,
                             instanceName=instance_name)
        self.fmu.instantiate(callbacks=self._callbacks, loggingOn=logging_on)
        self._used = False
        self._closed = False
        self._rest: dict = {}   # relaxed chains at rest: key -> FMU state (start)

    # -- messages ---------------------------------------------------------------
    def _log(self, env, instance, status, category, message):
        self.messages.append((int(status), (category or b"").decode(errors="replace"),
                              (message or b"").decode(errors="replace").replace("%%", "%")))

    def _fail(self, what: str, exc: Exception) -> SimulationError:
        errs = [m for s, _, m in self.messages if s >= 2]
        detail = errs[-1] if errs else str(exc)
        return SimulationError(f"{what}: {detail}")

    # -- values --------------------------------------------------------------------
    def vr(self, name: str) -> int:
        try:
            return self.variables[name].valueReference
        except KeyError:
            close = [n for n in self.variables if name.split(".")[-1] in n]
            hint = f" (did you mean {', '.join(close[:4])}?)" if close else ""
            raise KeyError(f"the FMU has no variable '{name}'{hint}") from None

    def set(self, name: str, value) -> None:
        v = self.variables.get(name)
        if v is None:
            self.vr(name)
        try:
            if v.type == "Real":
                self.fmu.setReal([v.valueReference], [float(value)])
            elif v.type == "Integer":
                self.fmu.setInteger([v.valueReference], [int(value)])
            elif v.type == "Boolean":
                self.fmu.setBoolean([v.valueReference], [bool(value)])
            else:
                self.fmu.setString([v.valueReference], [str(value)])
        except FMICallException as exc:
            raise self._fail(f"cannot set {name} = {value!r}", exc) from None

    def get(self, name: str):
        v = self.variables.get(name) or self.variables[self.vr(name)]
        getter = {"Real": self.fmu.getReal, "Integer": self.fmu.getInteger,
                  "Boolean": self.fmu.getBoolean, "String": self.fmu.getString}[v.type]
        try:
            val = getter([v.valueReference])[0]
        except FMICallException as exc:
            raise self._fail(f"cannot read {name}", exc) from None
        return val.decode() if isinstance(val, bytes) else val

    # -- runs ----------------------------------------------------------------------
    def start(self, params: Optional[Mapping[str, object]] = None, tolerance: Optional[float] = None,
              start_time: float = 0.0) -> None:
        """Reset (if used), set parameters, initialise.

        A chain that starts at rest relaxes into its static equilibrium first
        (chain.relax_time > 0), which does not depend on the tunable values
        (the CoRs, mu_roll, the gains, the speed reference): the relaxed state
        is kept as an FMU state, one per set of the other values, and a later
        start with the same other values restores it and sets its own tunable
        values on it instead of relaxing again."""
        self.messages.clear()
        params = dict(params or {})
        key = self._rest_key(params, tolerance, start_time)
        if key is not None and key in self._rest:
            self._rest[key] = self._rest.pop(key)  # most recently used last
            try:
                self.fmu.setFMUstate(self._rest[key])
                for name, value in self._tunables(params).items():
                    self.set(name, value)
            except FMICallException as exc:
                raise self._fail("restoring the relaxed chain failed", exc) from None
            self._used = True
            self.time = start_time
            return
        if self._used:
            self.fmu.reset()
        self._used = True
        try:
            for name, value in params.items():
                self.set(name, value)
            self.fmu.setupExperiment(tolerance=tolerance, startTime=start_time)
            self.fmu.enterInitializationMode()
            self.fmu.exitInitializationMode()
            if key is not None:
                self._keep_rest(key)
        except FMICallException as exc:
            raise self._fail("initialisation failed", exc) from None
        self.time = start_time

    def _rest_key(self, params: Mapping[str, object], tolerance, start_time) -> Optional[tuple]:
        """What the relaxed equilibrium depends on (None: not a start from rest)."""
        if not float(params.get("chain.relax_time", 0.0) or 0.0) > 0:
            return None
        fixed = tuple(sorted((k, repr(v)) for k, v in params.items() if k not in TUNABLE))
        return fixed + (("tolerance", repr(tolerance)), ("start_time", repr(start_time)))

    def _tunables(self, params: Mapping[str, object]) -> dict:
        """Every tunable value of a run: given, else the FMU's default (as a fresh start has it)."""
        return {name: params.get(name, default) for name, default in TUNABLE.items()}

    def _keep_rest(self, key: tuple) -> None:
        while len(self._rest) >= REST_STATES:
            old = self._rest.pop(next(iter(self._rest)))
            self.fmu.freeFMUstate(old)
        self._rest[key] = self.fmu.getFMUstate()

    def step(self, h: float) -> None:
        try:
            self.fmu.doStep(self.time, h)
        except FMICallException as exc:
            raise self._fail(f"step from t = {self.time:g} s failed", exc) from None
        self.time += h

    def stream(self, step: float, outputs: Sequence[str] = DEFAULT_OUTPUTS,
               params: Optional[Mapping[str, object]] = None, tolerance: Optional[float] = None,
               start_time: float = 0.0, inputs: Optional[Mapping[str, Callable[[float], float]]] = None,
               on_step: Optional[Callable[["ChainSimulator", float], None]] = None) -> Iterator[tuple]:
        """The one stepping loop. Resets, sets `params` and initialises now;
        the returned iterator then yields (t, values) at start_time and after
        every communication step, t = start_time + k * step exactly (no drift),
        for as long as the caller goes on. `values` is a numpy view of one
        buffer, overwritten at the next step: copy what you keep.

        `inputs` maps an input or tunable parameter to a function of time, set
        at every communication point before the step (held over the step, as
        FMI co-simulation does): a speed schedule for drive.v_ref, say.
        `on_step(sim, t)` is called before each step as well."""
        if not (step > 0) or not np.isfinite(step):
            raise ValueError(f"step = {step} must be positive and finite")
        vrs = [self.vr(o) for o in outputs]
        types = {self.variables[o].type for o in outputs}
        if types - {"Real"}:
            raise ValueError("the stream records Real outputs only")
        schedule = []
        for name, fn in (inputs or {}).items():
            var = self.variables.get(name) or self.variables[self.vr(name)]
            if var.type != "Real" or not (var.causality == "input" or var.variability == "tunable"):
                raise ValueError(f"{name} cannot follow a schedule: only Real inputs and tunable "
                                 f"parameters can change during a run")
            schedule.append(((fmi2ValueReference * 1)(var.valueReference), fn, name))
        self.start(params, tolerance, start_time)
        nv = len(vrs)
        c_vr = (fmi2ValueReference * nv)(*vrs)
        c_val = (fmi2Real * nv)()
        c_in = (fmi2Real * 1)()
        # The loop calls the FMU's C functions directly (fmpy's wrappers add a
        # Python call and a status check per call); a status above fmi2Warning
        # raises as fmpy would. val is a numpy view of the output buffer.
        raw = getattr(self.fmu, "_functions", {})
        get_real = raw.get("fmi2GetReal") or self.fmu.fmi2GetReal
        set_real = raw.get("fmi2SetReal") or self.fmu.fmi2SetReal
        do_step = raw.get("fmi2DoStep") or self.fmu.fmi2DoStep
        comp = self.fmu.component
        val = np.frombuffer(c_val, dtype=np.float64)
        return self._steps(step, start_time, schedule, on_step, get_real, set_real, do_step, comp, c_vr, nv,
                           c_val, c_in, val)

    def _steps(self, step, start_time, schedule, on_step, get_real, set_real, do_step, comp, c_vr, nv, c_val,
               c_in, val):
        t, k = start_time, 0
        try:
            if get_real(comp, c_vr, nv, c_val) > fmi2Warning:
                raise FMICallException(function="fmi2GetReal", status=fmi2Error)
            yield t, val
            while True:
                if on_step is not None:
                    on_step(self, t)
                for c_ref, fn, name in schedule:
                    c_in[0] = float(fn(t))
                    if set_real(comp, c_ref, 1, c_in) > fmi2Warning:
                        raise FMICallException(function=f"fmi2SetReal ({name} = {c_in[0]!r} at t = {t:g} s)",
                                               status=fmi2Error)
                k += 1
                t_next = start_time + step * k
                status = do_step(comp, t, t_next - t, 1)
                if status > fmi2Warning:
                    raise FMICallException(function="fmi2DoStep", status=status)
                t = t_next
                self.time = t
                if get_real(comp, c_vr, nv, c_val) > fmi2Warning:
                    raise FMICallException(function="fmi2GetReal", status=fmi2Error)
                yield t, val
        except FMICallException as exc:
            self.time = t
            raise self._fail(f"simulation failed after t = {t:g} s", exc) from None

    def simulate(self, stop_time: float, step: float = 1.0 / 300.0,
                 params: Optional[Mapping[str, object]] = None, outputs: Sequence[str] = DEFAULT_OUTPUTS,
                 tolerance: Optional[float] = None, start_time: float = 0.0,
                 on_step: Optional[Callable[["ChainSimulator", float], None]] = None,
                 record_from: float = -np.inf,
                 inputs: Optional[Mapping[str, Callable[[float], float]]] = None) -> pd.DataFrame:
        """Simulate from start_time to stop_time and return the outputs at every
        communication point (a DataFrame with a 'time' column); see `stream`
        for `inputs` and `on_step`."""
        if not (stop_time > start_time) or not np.isfinite(stop_time):
            raise ValueError(f"stop_time = {stop_time} must be finite and after start_time = {start_time}")
        if not (step > 0):
            raise ValueError(f"step = {step} must be positive")
        n = int(round((stop_time - start_time) / step))
        outputs = list(outputs)
        data = np.empty((n + 1, len(outputs)))
        times = np.empty(n + 1)
        for k, (t, val) in enumerate(self.stream(step, outputs, params, tolerance, start_time, inputs, on_step)):
            data[k] = val
            times[k] = t
            if k == n:
                break
        keep = times >= record_from - 1e-12
        df = pd.DataFrame(data[keep], columns=outputs)
        df.insert(0, "time", times[keep])
        return df

    def info(self) -> RunInfo:
        return RunInfo(self.get("solver.n_steps"), self.get("solver.n_rejected"), self.get("solver.n_rhs"),
                       self.get("solver.h_last"), list(self.messages))

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            for state in self._rest.values():
                try:
                    self.fmu.freeFMUstate(state)
                except Exception:
                    pass
            self._rest.clear()
            try:
                self.fmu.terminate()
            except Exception:
                pass
            self.fmu.freeInstance()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class LazySimulator:
    """The simulator of the process that uses it, made on first use: a problem
    carries one and calls it for its FMU instance. It pickles to its FMU path
    only; a copy sent to another process (a worker's task) uses that
    process's one simulator of the FMU, made on the first task and reused by
    every later one with fmi2Reset, its relaxed chains kept: a task costs its
    simulation, not an FMU's extraction and instantiation."""

    def __init__(self, fmu: Optional[Path] = None, shared: bool = False):
        self.fmu = None if fmu is None else str(fmu)
        self.shared = shared
        self._sim: Optional[ChainSimulator] = None
        self._pid: Optional[int] = None

    def __call__(self) -> ChainSimulator:
        if self.shared:
            key = (self.fmu, os.getpid())
            sim = _PROCESS_SIMULATORS.get(key)
            if sim is None or sim._closed:
                sim = _PROCESS_SIMULATORS[key] = ChainSimulator(None if self.fmu is None else Path(self.fmu),
                                                                instance_name=f"lss{os.getpid()}")
            return sim
        if self._sim is None or self._pid != os.getpid():
            self._sim = ChainSimulator(None if self.fmu is None else Path(self.fmu),
                                       instance_name=f"lss{os.getpid()}")
            self._pid = os.getpid()
        return self._sim

    def close(self) -> None:
        """Frees this problem's instance (a process's shared one lives as long as the process)."""
        if self._sim is not None and self._pid == os.getpid():
            self._sim.close()
        self._sim = self._pid = None

    def __getstate__(self):
        return {"fmu": self.fmu}

    def __setstate__(self, state):
        self.__init__(state["fmu"], shared=True)

    def __repr__(self) -> str:
        return f"LazySimulator({self.fmu or 'build/LSSChain.fmu'})"


def simulate(layout: str = "demo", stop_time: float = 10.0, step: float = 1.0 / 300.0,
             params: Optional[Mapping[str, object]] = None, outputs: Iterable[str] = DEFAULT_OUTPUTS,
             tolerance: Optional[float] = None) -> pd.DataFrame:
    """One simulation in a fresh instance (for scripts; loops should reuse a ChainSimulator)."""
    p = {"layout.name": layout, **(params or {})}
    with ChainSimulator() as sim:
        return sim.simulate(stop_time, step, p, list(outputs), tolerance)
