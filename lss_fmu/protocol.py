"""Measurement protocols: what the sorter did while the transducer cart logged.

A record declares its protocol in meta.json (`protocol`); the virtual
transducer cart follows it and so does the identification problem: the speed
reference `drive.v_ref` follows the same schedule, and what is simulated
before the first sample follows from the protocol, not from a constant.

    steady      running at v_s; the photocell at s_M starts logging, the
                trigger armed `run_in` s after the start of the simulation
                (the chain has reached steady running by then)
    start-up    from standstill: the chain at rest in its static equilibrium,
                the transducer cart's axle parked at s_M; logging starts with
                the start command (t = 0), the set point ramps from 0 to v_s
                in `ramp_time` s (0: a step; the drive then starts at full
                thrust)
    speed-step  running at `v_from` (nominal); logging from the photocell at
                s_M; `step_time` s after the trigger the set point goes to
                v_s, in `ramp_time` s
    stop        running at v_s; logging from the photocell; `step_time` s
                after the trigger the set point goes to 0 in `ramp_time` s
                (0: at once, the drive brakes at full thrust)
    start-stop  a start-up braked again before the chain runs steadily: from
                rest, the set point ramps to v_s at t = 0 and back to 0 at
                `step_time`, both in `ramp_time` s. The whole record stays
                a transient from a known state (never the chaotic steady
                running), and the braking loads the joints and wheels a
                second time: it holds more about the CoRs than a start-up
                of the same length (docs/identification.md, information)

Speeds are set points. The design variable v_s is the set point the record
reaches (`speed_nominal` is its nominal value); a speed-step's `v_from`
scales with it, as a calibration error of the set point would.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Callable, Mapping, Optional

from .variables import BY_NAME

NAMES = ("steady", "start-up", "speed-step", "stop", "start-stop")
FROM_REST = ("start-up", "start-stop")
WITH_STEP = ("speed-step", "stop", "start-stop")
RUN_IN = 4.0                 # s: steady running before the photocell is armed (the rig's default)
RELAX_MIN = 1.0     # s, the shortest relaxation at rest (ten decay times of its viscous damping)
V_MAX = float(BY_NAME["drive.v_ref"].max)   # the drive's set-point range, m/s
TRANSIENT_TOLERANCE = 1e-3   # solver tolerance for identifying a transient record: the solver's error stays
                             # below 0.02 of the noise and moves the fitted e_JA, e_SW and e_RW by <= 6e-4
                             # (linearised), for 0.53-0.61 of the right-hand sides of 1e-4; the relaxation at
                             # rest keeps 1e-5 at most (chain_relax.c)
                             # (benchmarks/bench_transient_tolerance.py, docs/benchmarks.md)


class ProtocolError(ValueError):
    """A protocol the FMU cannot follow; names the meta.json field and the value."""

    def __init__(self, field: str, message: str):
        self.field = field
        super().__init__(f"field 'protocol.{field}': {message}" if field else f"field 'protocol': {message}")


@dataclass(frozen=True)
class Protocol:
    name: str = "steady"
    ramp_time: float = 0.0
    step_time: Optional[float] = None
    v_from: Optional[float] = None
    run_in: float = RUN_IN

    # -- what it means for a simulation ----------------------------------------------
    @property
    def from_rest(self) -> bool:
        """The record starts with the chain at rest (no photocell: t = 0 is the start command)."""
        return self.name in FROM_REST

    @property
    def transient(self) -> bool:
        return self.name != "steady"

    def v_before(self, v_s: float, v_nominal: float) -> float:
        """The set point before the record starts."""
        if self.from_rest:
            return 0.0
        if self.name == "speed-step":
            return float(self.v_from) * v_s / v_nominal
        return v_s

    def schedule(self, v_s: float, v_nominal: float) -> Callable[[float], float]:
        """v_ref as a function of the time since the record's t = 0."""
        v0, ramp = self.v_before(v_s, v_nominal), float(self.ramp_time)
        if self.name == "steady":
            return lambda t: v_s
        if self.name == "start-up":
            return _ramp(0.0, v_s, 0.0, ramp)
        if self.name == "start-stop":
            up, down, t_stop = _ramp(0.0, v_s, 0.0, ramp), _ramp(v_s, 0.0, float(self.step_time), ramp), \
                float(self.step_time)
            return lambda t: up(t) if t < t_stop else down(t)
        target = v_s if self.name == "speed-step" else 0.0
        return _ramp(v0, target, float(self.step_time), ramp)

    def relax_time(self, track_length: float) -> float:
        """How long the chain at rest relaxes into its equilibrium before a
        start-up (chain.relax_time): at least RELAX_MIN, for the viscous
        relaxation to damp the loop's slowest modes, and longer on a long
        track, whose axial modes are slower (after it, the forces of a chain
        left at rest drift by under 3 N on layouts 1-7: docs/benchmarks.md)."""
        return round(max(RELAX_MIN, 0.5 + float(track_length) / 400.0), 3) if self.from_rest else 0.0

    # -- meta.json ---------------------------------------------------------------------
    def to_meta(self) -> dict:
        """The fields that mean something for this protocol, for meta.json."""
        keep = {"steady": ("name", "run_in"), "start-up": ("name", "ramp_time"),
                "speed-step": ("name", "v_from", "step_time", "ramp_time", "run_in"),
                "stop": ("name", "step_time", "ramp_time", "run_in"),
                "start-stop": ("name", "step_time", "ramp_time")}.get(self.name, tuple(asdict(self)))
        return {k: v for k, v in asdict(self).items() if k in keep and v is not None}

    def check(self, speed_nominal: float, duration: Optional[float] = None) -> "Protocol":
        """Raise ProtocolError for what the FMU cannot follow."""
        if self.name not in NAMES:
            raise ProtocolError("name", f"{self.name!r} is not a protocol ({', '.join(NAMES)})")
        _finite_nonneg("ramp_time", self.ramp_time)
        _finite_nonneg("run_in", self.run_in)
        if not 0.0 < speed_nominal <= V_MAX:
            raise ProtocolError("", f"speed_nominal {speed_nominal!r} m/s is beyond the drive's range (0, {V_MAX:g}]")
        if self.name in WITH_STEP:
            if self.step_time is None:
                raise ProtocolError("step_time", f"a {self.name} needs the time of the change after the trigger, s")
            _finite_nonneg("step_time", self.step_time)
            if duration is not None and not self.step_time < duration:
                raise ProtocolError("step_time", f"{self.step_time!r} s lies outside the record (it is "
                                                 f"{duration:.3f} s long)")
        elif self.step_time is not None:
            raise ProtocolError("step_time", f"a {self.name} has no step")
        if self.name == "speed-step":
            if self.v_from is None or not (isinstance(self.v_from, (int, float)) and math.isfinite(self.v_from)):
                raise ProtocolError("v_from", f"a speed-step needs the set point before the step, m/s, "
                                              f"got {self.v_from!r}")
            if not 0.0 < self.v_from <= V_MAX:
                raise ProtocolError("v_from", f"{self.v_from!r} m/s is beyond the drive's range (0, {V_MAX:g}]")
        elif self.v_from is not None:
            raise ProtocolError("v_from", f"only a speed-step starts from another set point")
        if self.from_rest and duration is not None and self.ramp_time > duration:
            raise ProtocolError("ramp_time", f"{self.ramp_time!r} s is longer than the record ({duration:.3f} s)")
        if self.name == "stop" and duration is not None and self.step_time + self.ramp_time > 10 * duration:
            raise ProtocolError("ramp_time", f"{self.ramp_time!r} s: the stop would end far outside the record")
        return self


def _finite_nonneg(field: str, x) -> None:
    if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) or x < 0:
        raise ProtocolError(field, f"{x!r} must be a finite number, 0 or more (s)")


def _ramp(v0: float, v1: float, t0: float, ramp: float) -> Callable[[float], float]:
    if ramp <= 0:
        return lambda t: v0 if t < t0 else v1
    return lambda t: v0 if t < t0 else (v1 if t >= t0 + ramp else v0 + (v1 - v0) * (t - t0) / ramp)


def from_meta(meta: Mapping) -> Protocol:
    """The record's protocol; a record that declares none is steady running
    with the rig's run-in (how every record before the protocols was made)."""
    block = meta.get("protocol")
    if block is None:
        return Protocol()
    if isinstance(block, str):
        block = {"name": block}
    if not isinstance(block, Mapping):
        raise ProtocolError("", f"must be an object or a protocol name, got {block!r}")
    known = {"name", "ramp_time", "step_time", "v_from", "run_in"}
    extra = sorted(set(block) - known)
    if extra:
        raise ProtocolError(extra[0], f"unknown (known: {', '.join(sorted(known))})")
    name = block.get("name")
    if not isinstance(name, str):
        raise ProtocolError("name", f"{name!r} is not a protocol ({', '.join(NAMES)})")
    p = Protocol(name=name, ramp_time=block.get("ramp_time", 0.0), step_time=block.get("step_time"),
                 v_from=block.get("v_from"), run_in=block.get("run_in", RUN_IN))
    return p
