"""The identification problem of the paper (Eq. 9-13).

Design vector x = [e_JA, e_JR, e_SW, e_RW, v_s, d, mu_d, s_M, K_P, K_I];
objective f(x) = sum_j H_j^2 over the 7 forces, H_j = RMSD_j / (max - min of
the measured force j); the design vector itself is lss_fmu.design's. With
objective "likelihood" H_j = RMSD_j / sigma_j instead, sigma_j the sensor's
declared white noise: f is then the mean chi^2 per sample, about 7 at the
truth, and every channel counts by what it tells rather than by its span
(docs/identification.md, "what a record can tell"). Each
evaluation simulates the chain through the FMU (the problem's simulator: one
instance per process, reused with fmi2Reset), aligned on the trigger point
s_M as the transducer cart logs. A failed or diverging
simulation gives a bad value and a logged line, never an exception.
"""
from __future__ import annotations

import logging
import math
import dataclasses
import hashlib
import pickle
from collections import OrderedDict
from dataclasses import dataclass, field
from functools import cached_property
from typing import Mapping, Optional, Sequence

import numpy as np

from lss_fmu.design import COR_BOUNDS, CORS, DESIGN, BY_SYMBOL, TRIGGER, is_effect_parameter, symbol
from lss_fmu.layouts import load_track
from lss_fmu.protocol import Protocol, TRANSIENT_TOLERANCE
from lss_fmu.runner import LazySimulator
from lss_fmu.sensor import OFFSET_STD, interp_cubic
from lss_fmu.triggered import arriving_cart, sample_rate_of, simulate_from_rest, simulate_triggered
from lss_fmu.variables import BY_NAME, CONTACT_MODELS, FORCE_CHANNELS, N_SENS, sensitivity_output, value_reference

from .features import stat_errors

log = logging.getLogger(__name__)

OBJECTIVES = ("pointwise", "statistics", "likelihood")
LINEARISABLE = ("pointwise", "likelihood")   # sample by sample: refinement and Jacobian intervals apply
BAD_VALUE = 100.0  # worse than any simulation that ran (7 channels at NRMSD ~3.8)
# the other objectives are not bounded like Eq. 10-12 (the likelihood's f is ~7 at the truth and
# thousands far from it): a failed simulation must still rank below every one that ran
BAD_VALUES = {"pointwise": BAD_VALUE, "statistics": 1e12, "likelihood": 1e12}
EXACT_STEP = 1e-6     # a sensitivity follower's step, of the bound range: the derivative of the discrete solution
                      # is the same to 0.1 % from 1e-9 to 1e-7 m of pretension (its most nonlinear variable) and
                      # the difference quotient stands 8 orders above the forces' rounding
MEMO_BYTES = 8 << 20   # simulations kept per problem, the newest first: a central Jacobian's (its base and two
                       # to five runs per variable) fit many times over on a transient window (84 kB each at 2.5 s)


def tared(residual: np.ndarray, tare: Optional[np.ndarray]) -> np.ndarray:
    """The residual with each channel's mean removed as far as the transducer's
    zero tolerance `tare` (N per channel) allows: a zero error within the
    specification is not the model's to explain (None: nothing removed)."""
    if tare is None:
        return residual
    return residual - np.clip(residual.mean(axis=0), -np.asarray(tare), np.asarray(tare))


def weighted_residual(problem, sim: np.ndarray, w: np.ndarray) -> tuple:
    """(tared residual, sum r^2 w) of a simulation of `problem` (w per channel)."""
    r = tared(problem.samples - sim, problem.tare)
    return r, float(np.sum(r ** 2 * w))


def nrmsd(measured: np.ndarray, simulated: np.ndarray, tare: Optional[np.ndarray] = None) -> np.ndarray:
    """H_j per channel (Eq. 11-12); with `tare`, after the zero tolerance (see tared)."""
    span = measured.max(axis=0) - measured.min(axis=0)
    rmsd = np.sqrt(np.mean(tared(measured - simulated, tare) ** 2, axis=0))
    return rmsd / np.where(span > 0, span, 1.0)


@dataclass
class IdentificationProblem:
    """One measurement, one contact model: what to fit and how."""
    samples: np.ndarray                  # (n, 7) measured forces
    times: np.ndarray                    # (n,) s after the trigger
    layout: str                          # built-in name or layout file path
    model: str                           # HC, HW, LW, LN, GZ or FL
    bounds: dict                         # design name -> (lo, hi)
    fixed: dict = field(default_factory=dict)   # other FMU parameters held fixed
    free: Sequence[str] = tuple(DESIGN)  # design variables that are identified
    x0: Optional[dict] = None            # start values (design name -> value)
    settle: float = 3.0
    tolerance: Optional[float] = None
    name: str = "measurement"
    tare: Optional[np.ndarray] = None    # per force channel, N: zero tolerance taken out (None: Eq. 10-12 as is)
    anti_alias: Optional[tuple] = None   # (order, cutoff Hz, causal): the logger's Butterworth filter, if declared
    filter_rate: Optional[float] = None  # Hz, the rate the logger runs that filter at (meta.json
                                         # sensor.internal_rate_Hz); None: the communication grid's
    sample_rate: Optional[float] = None  # Hz; None: read off the times (triggered.sample_rate_of)
    protocol: Protocol = field(default_factory=Protocol)  # what the sorter did (lss_fmu.protocol)
    v_nominal: Optional[float] = None    # the record's nominal set point (scales a speed-step's v_from)
    objective: str = "pointwise"         # pointwise: Eq. 10-12; statistics: spectra and distributions (features);
                                         # likelihood: RMSD over the declared noise
    noise: Optional[np.ndarray] = None   # per force channel, N: the sensor's white noise (likelihood)
    sim: LazySimulator = field(default_factory=LazySimulator, repr=False, compare=False)  # the FMU instance
    sensitivities: bool = False          # Jacobian columns from the FMU's forward sensitivities where it can
                                         # (exact_indices); False: every column by differences of whole runs.
                                         # Not the default: the local derivative leads Levenberg-Marquardt into
                                         # other valleys than the differences' 2 %-of-range steps on some records
                                         # (docs/benchmarks.md, "Levers measured, not taken")
    pool: Optional[object] = field(default=None, repr=False, compare=False)  # an Executor for simulations side by
                                         # side (identification.objective.parallel); not pickled
    # the last simulations, by everything they depend on (see simulate); not copied by replace, not pickled
    _memo: OrderedDict = field(default_factory=OrderedDict, init=False, repr=False, compare=False)

    def __post_init__(self):
        if self.objective not in OBJECTIVES:
            raise ValueError(f"unknown objective {self.objective!r}: use {' or '.join(OBJECTIVES)}")
        if self.model not in CONTACT_MODELS:
            raise ValueError(f"unknown contact model {self.model!r}: use one of {', '.join(CONTACT_MODELS)}")
        self.samples = np.asarray(self.samples, float)
        if self.noise is not None:
            self.noise = np.asarray(self.noise, float)
            if self.noise.shape != (len(FORCE_CHANNELS),) or not np.all(np.isfinite(self.noise) & (self.noise > 0)):
                raise ValueError(f"noise must be {len(FORCE_CHANNELS)} positive values (N), got {self.noise}")
        if self.objective == "likelihood" and self.noise is None:
            raise ValueError("the likelihood objective needs the sensor's noise per channel (meta.json "
                             "sensor.force_noise_std_N)")
        self.times = np.asarray(self.times, float)
        if self.tare is not None:
            self.tare = np.asarray(self.tare, float)
            if self.tare.shape != (len(FORCE_CHANNELS),) or not np.all(self.tare >= 0):
                raise ValueError(f"tare must be {len(FORCE_CHANNELS)} non-negative values (N), got {self.tare}")
        if self.samples.ndim != 2 or self.samples.shape[1] != len(FORCE_CHANNELS):
            raise ValueError(f"samples must have {len(FORCE_CHANNELS)} force columns, got {self.samples.shape}")
        for name in self.free:
            if name not in DESIGN and not is_effect_parameter(name):
                raise ValueError(f"unknown design variable {name!r}: use {', '.join(DESIGN)} "
                                 f"or an FMU parameter effects.*")
            if name not in self.bounds:
                raise ValueError(f"no bounds for design variable {name!r}")
            lo, hi = self.bounds[name]
            if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
                raise ValueError(f"impossible bounds for {name}: [{lo}, {hi}]")
            if self.x0 is not None and name in self.x0 and not lo <= self.x0[name] <= hi:
                raise ValueError(f"start value {name} = {self.x0[name]} lies outside [{lo}, {hi}]")

    # -- vectors and parameters ------------------------------------------------------
    @property
    def dim(self) -> int:
        return len(self.free)

    @property
    def bounds_array(self) -> list:
        return [tuple(self.bounds[n]) for n in self.free]

    def x0_vector(self) -> Optional[np.ndarray]:
        if self.x0 is None:
            return None
        lo_hi = self.bounds_array
        return np.array([self.x0.get(n, 0.5 * (lo + hi)) for n, (lo, hi) in zip(self.free, lo_hi)])

    def values(self, x: Sequence[float]) -> dict:
        """Design name -> value, the free ones from x, the rest from x0/fixed."""
        vals = dict(self.x0 or {})
        vals.update(zip(self.free, map(float, x)))
        return vals

    def fmu_params(self, x: Sequence[float]) -> tuple[dict, float]:
        vals = self.values(x)
        params = {"layout.name": self.layout, "contact.model": CONTACT_MODELS[self.model], **self.fixed}
        for name, v in vals.items():
            if name != "trigger.s_M":
                params[name] = v
        return params, float(vals["trigger.s_M"])

    # -- evaluation --------------------------------------------------------------
    def run(self, x: Sequence[float], extra: Optional[Mapping[str, object]] = None,
            channels: Sequence[str] = FORCE_CHANNELS, times: Optional[np.ndarray] = None,
            history: float = 0.0) -> np.ndarray:
        """FMU outputs `channels` at `times` (default: the measured sample times)
        after the record's t = 0, at x with further FMU values `extra`, as
        simulated (no sensor model), the protocol followed: the set point on
        its schedule, the chain from rest (start-up) or past the photocell
        after its run-in (the others). Raises on failure."""
        params, s_m = self.fmu_params(x)
        params.update(extra or {})
        times = self.times if times is None else times
        v_s = float(params.get("drive.v_ref", BY_NAME["drive.v_ref"].start))
        speed = self.protocol.schedule(v_s, self.v_nominal or v_s)
        if self.protocol.from_rest:
            params.update({"chain.v_init": 0.0, "chain.transducer": 0, "drive.v_ref": 0.0,
                           "chain.s_start": s_m % self.track_length,
                           "chain.relax_time": self.protocol.relax_time(self.track_length)})
            return simulate_from_rest(self.sim(), params, times, channels, tolerance=self.tolerance,
                                      sample_rate=self.rate, history=history, speed=speed)
        params["drive.v_ref"] = self.protocol.v_before(v_s, self.v_nominal or v_s)
        return simulate_triggered(self.sim(), params, s_m, times, settle=self.settle, channels=channels,
                                  tolerance=self.tolerance, sample_rate=self.rate, history=history,
                                  after_trigger=speed if self.protocol.transient else None)

    @cached_property
    def track_length(self) -> float:
        return float(load_track(self.layout).length)

    @property
    def rate(self) -> float:
        """The sample rate, Hz: declared, or read off the times."""
        return float(self.sample_rate) if self.sample_rate else sample_rate_of(self.times)

    def simulate(self, x: Sequence[float], extra: Optional[Mapping[str, object]] = None) -> np.ndarray:
        """The 7 forces as the logger records them at the measured sample times
        (through its anti-alias filter when the record declares one); raises on failure.

        A simulation is a function of what it is run with: asked again with
        the same FMU values, window and protocol it is not run again (the
        last ones, up to MEMO_BYTES, are kept; a copy is returned). A joint problem's Jacobian
        column of one record's trigger point then runs that record alone,
        and a point evaluated twice by two stages runs once."""
        key = self._memo_key(x, extra)
        kept = self._memo.get(key)
        if kept is not None:
            self._memo.move_to_end(key)
            return kept.copy()
        y = self.run(x, extra) if self.anti_alias is None else self._through_filter(x, extra)
        self._keep(key, y)
        return y

    def remember(self, x: Sequence[float], y: np.ndarray) -> None:
        """Keep `y` as the simulation at x (one run elsewhere: a worker's)."""
        self._keep(self._memo_key(x, None), y)

    def _keep(self, key: tuple, y: np.ndarray) -> None:
        self._memo[key] = np.array(y, float)
        self._memo.move_to_end(key)
        while sum(a.nbytes for a in self._memo.values()) > MEMO_BYTES and len(self._memo) > 1:
            self._memo.popitem(last=False)

    def _memo_key(self, x, extra) -> tuple:
        """Everything a simulation depends on: the FMU values (the design's and
        the fixed ones), the trigger point, the solver, the sample times, the
        logger's filter, the protocol and the FMU file."""
        params, s_m = self.fmu_params(x)
        params.update(extra or {})
        return (repr(sorted(params.items())), s_m, self.tolerance, self.settle, hash(self.times.tobytes()),
                len(self.times), self.anti_alias, self.filter_rate, self.sample_rate, repr(self.protocol),
                self.v_nominal, getattr(self.sim, "fmu", None))

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_memo"] = OrderedDict()   # a copy in another process simulates for itself
        state["pool"] = None             # and is not a master of workers
        return state

    def __dask_tokenize__(self) -> str:
        """A Dask key of the problem: what it pickles to (not its pool, not its memo)."""
        return hashlib.sha256(pickle.dumps(self)).hexdigest()

    # -- derivatives from the core ---------------------------------------------------
    def exact_indices(self) -> tuple:
        """The free variables whose columns of the Jacobian the FMU computes
        itself (sensitivity.*: follower chains on the simulation's own steps,
        one run for all of them): on a record from rest, every design
        variable that is a Real parameter of the FMU, the trigger point
        included (it places the chain, chain.s_start); not the set point,
        which the schedule sets as an input. Empty unless the problem asks
        for them (`sensitivities`), and on a record whose trigger is found
        while the chain runs (its time moves with every variable)."""
        if not (self.sensitivities and self.protocol.from_rest):
            return ()
        out = []
        for k, name in enumerate(self.free):
            var = BY_NAME.get("chain.s_start" if name == TRIGGER else name)
            if var is not None and var.type == "Real" and var.causality == "parameter":
                out.append(k)
        return tuple(out[:N_SENS])

    def simulate_exact(self, x: Sequence[float], ks: Sequence[int]) -> tuple:
        """(the simulation at x, {k: d simulation / d x_k}) for the free
        variables ks (a subset of exact_indices), from one run: the FMU's
        followers, each moved by EXACT_STEP of its bound range towards the
        inside. The simulation is the one `simulate` gives, bit for bit, and
        is kept as such."""
        x = np.asarray(x, float)
        extra = {"sensitivity.n": len(ks)}
        for j, k in enumerate(ks, 1):
            name = self.free[k]
            lo, hi = self.bounds[name]
            h = EXACT_STEP * (hi - lo) * (1.0 if x[k] + EXACT_STEP * (hi - lo) <= hi else -1.0)
            extra[f"sensitivity.p{j}.vr"] = value_reference("chain.s_start" if name == TRIGGER else name)
            extra[f"sensitivity.p{j}.step"] = h
        channels = list(FORCE_CHANNELS) + [sensitivity_output(j, c) for j in range(1, len(ks) + 1)
                                           for c in FORCE_CHANNELS]
        if self.anti_alias is None:
            y = self.run(x, extra, channels=channels)
        else:
            y = self._through_filter(x, extra, channels=channels)
        n = len(FORCE_CHANNELS)
        self.remember(x, y[:, :n])
        return y[:, :n].copy(), {k: y[:, n * (j + 1):n * (j + 2)].copy() for j, k in enumerate(ks)}

    def _through_filter(self, x, extra, channels: Sequence[str] = FORCE_CHANNELS) -> np.ndarray:
        """The simulation through the logger's declared anti-alias filter, from
        FILTER_LEAD s before the trigger, so that the filter's 4 ms of group delay
        is in the model and not in the residual: simulated on the communication
        grid (half the sample spacing), filtered there or, when the record
        declares the logger's internal rate, interpolated onto that rate's grid
        and filtered at it, as the logger does."""
        from scipy import signal
        order, cutoff, causal = self.anti_alias
        h = 0.5 / self.rate
        refilter = bool(self.filter_rate) and abs(self.filter_rate * h - 1.0) > 1e-9
        tail = 6 if refilter else 3   # the cubics' support past the last sample, on each grid
        grid = np.arange(-int(np.ceil(FILTER_LEAD / h)), int(np.ceil(self.times[-1] / h)) + tail) * h
        y = self.run(x, extra, channels=channels, times=grid, history=FILTER_LEAD + 2 * h)
        t0 = grid[0]
        if refilter:
            # the filter where the logger runs it: a digital Butterworth's response depends on its
            # rate (at 600 Hz instead of the logger's 1200 Hz the joint force's start and stop
            # transients left up to 0.8 noise variances at the truth, docs/identification.md)
            hf = 1.0 / self.filter_rate
            fine = np.arange(int(np.ceil(grid[1] / hf)), int(np.floor(grid[-2] / hf)) + 1) * hf
            y, t0, h = interp_cubic(grid[0], h, y, fine), fine[0], hf
        sos = signal.butter(int(order), float(cutoff), btype="low", output="sos", fs=1.0 / h)
        if causal:
            y, _ = signal.sosfilt(sos, y, axis=0, zi=signal.sosfilt_zi(sos)[:, :, None] * y[0])
        else:
            y = signal.sosfiltfilt(sos, y, axis=0)
        return interp_cubic(t0, h, y, self.times)

    def model_constants(self, names: Sequence[str] = ("cart.r_drive", "track.length", "chain.n_carts")) -> dict:
        """Calculated parameters of the model this problem simulates (its layout
        and fixed values, at the start point), read from the FMU after
        initialisation."""
        x = self.x0_vector()
        x = np.array([0.5 * (lo + hi) for lo, hi in self.bounds_array]) if x is None else x
        params, _ = self.fmu_params(x)
        sim = self.sim()
        sim.start(params, tolerance=self.tolerance)
        return {n: sim.get(n) for n in names}

    def channel_errors(self, x: Sequence[float]) -> np.ndarray:
        """H_j per channel: Eq. 11-12 (pointwise), or the statistical H_j^stat
        of identification.objective.features (objective = "statistics")."""
        if self.objective == "statistics":
            return stat_errors(self.samples, self.simulate(x), self.rate, self.tare)
        if self.objective == "likelihood":
            return np.sqrt(np.mean(tared(self.samples - self.simulate(x), self.tare) ** 2, axis=0)) / self.noise
        return nrmsd(self.samples, self.simulate(x), self.tare)

    def __call__(self, x: Sequence[float]) -> float:
        """f(x) = sum H_j^2; `bad_value` (logged) if the simulation fails."""
        try:
            H = self.channel_errors(x)
            f = float(np.sum(H ** 2))
            if not np.isfinite(f):
                raise FloatingPointError("non-finite objective")
            return f
        except Exception as exc:  # a failed simulation is a bad point, not the end of the run
            log.warning("%s/%s: simulation failed at %s: %s", self.name, self.model,
                        {symbol(k): round(v, 5) for k, v in self.values(x).items()}, exc)
            return self.bad_value

    @property
    def bad_value(self) -> float:
        """What a failed simulation scores: worse than any that ran."""
        return BAD_VALUES[self.objective]


def drive_known(problem: IdentificationProblem, values: Mapping[str, float]) -> IdentificationProblem:
    """The problem with the four CoRs free and the six layout-dependent
    variables held at `values` (design name -> value): the drive's settings,
    the set point, the pretension and the trigger point as a manufacturer
    knows them (or, in a benchmark, the truth)."""
    held = {n: float(values[n]) for n in DESIGN if n not in CORS}
    return dataclasses.replace(problem, free=tuple(CORS), x0={**(problem.x0 or {}), **held})


def from_measurement(meas, model: str, free: Optional[Sequence[str]] = None, window: Optional[float] = None,
                     fixed: Optional[Mapping[str, object]] = None, settle: Optional[float] = None,
                     tolerance: Optional[float] = None, tare: bool = False,
                     sim: Optional[LazySimulator] = None, objective: str = "pointwise") -> IdentificationProblem:
    """The problem of one loaded measurement (lss_fmu.measurement.Measurement):
    bounds of the layout-dependent variables from its metadata, CoRs 0.2..0.9,
    starting at the nominal values and the middle of the CoR range, following
    the record's protocol (meta.json `protocol`; none: steady running). `window`
    keeps only the first seconds of the record. `settle`: the run-in before the
    photocell is armed (default: the protocol's). `tolerance`: the solver's
    (default: the FMU's; lss_fmu.protocol.TRANSIENT_TOLERANCE for a transient
    record, which keeps the solver's error well below what the CoRs do). `tare`: take out
    zero errors within 3 sigma of the transducer's declared offset (meta.json
    sensor.force_offset_std_N, else the virtual cart's)."""
    protocol = meas.protocol
    settle = protocol.run_in if settle is None else float(settle)
    if tolerance is None and protocol.transient:
        tolerance = TRANSIENT_TOLERANCE
    t = np.asarray(meas.time, float)
    t = t - t[0]
    forces = meas.forces.to_numpy(float)
    if window is not None:
        # the option against the record (issue 20): a window longer than the record is a mistake,
        # not "all of it"; one sample interval of slack
        span = float(t[-1]) if len(t) else 0.0
        interval = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
        if not (math.isfinite(window) and window > 0):
            raise ValueError(f"window = {window} s: must be a positive number of seconds")
        if window > span + interval + 1e-9:
            raise ValueError(f"window = {window:g} s is longer than the record of {meas.id} "
                             f"({span:.6g} s, {len(t)} samples at {float(meas.meta['sample_rate']):g} Hz)")
        keep = t <= window + 1e-9
        t, forces = t[keep], forces[keep]
    bounds = {k: COR_BOUNDS for k in CORS}
    x0 = {k: 0.5 * sum(COR_BOUNDS) for k in CORS}
    for sym, dv in meas.design.items():
        name = BY_SYMBOL[sym]
        bounds[name] = (float(dv.lower), float(dv.upper))
        x0[name] = float(dv.nominal)
    extra = dict(meas.meta.get("fmu_parameters", {}) or {})
    extra.update(fixed or {})
    if "chain.transducer" not in extra and not protocol.from_rest:
        extra["chain.transducer"] = transducer_for(
            meas.track, float(x0.get("trigger.s_M", meas.meta["trigger_point"])),
            float(x0.get("drive.v_ref", meas.meta["speed_nominal"])), settle)
    tol = tare_of(meas.meta) if tare else None
    aa = anti_alias_of(meas.meta)
    noise = noise_of(meas) if objective == "likelihood" else None
    if aa is not None and len(t) > 1 and aa[1] >= 0.99 / float(np.median(np.diff(t))):
        log.warning("%s: anti-alias filter at %g Hz is not below the sample rate; not modelled", meas.id, aa[1])
        aa = None
    try:
        filter_rate = filter_rate_of(meas.meta, aa, float(meas.sample_rate)) if aa is not None else None
    except ValueError as exc:
        raise ValueError(f"{getattr(meas, 'path', None) or meas.id}/meta.json: {exc}") from None
    # a survey's as-built track (`fixed` layout.name) is the problem's layout: its length places the chain
    layout = str(extra.pop("layout.name", meas.layout_for_fmu))
    return IdentificationProblem(forces, t, layout, model, bounds, fixed=extra,
                                 free=tuple(free or DESIGN), x0=x0, settle=settle, tolerance=tolerance,
                                 name=meas.id, tare=tol, anti_alias=aa, filter_rate=filter_rate,
                                 sample_rate=meas.sample_rate,
                                 protocol=protocol, v_nominal=float(meas.meta["speed_nominal"]), objective=objective,
                                 noise=noise, sim=sim or LazySimulator())


FILTER_LEAD = 0.05   # s of simulated history before the trigger for the anti-alias filter (~12 time constants)


def anti_alias_of(meta: Optional[Mapping]) -> Optional[tuple]:
    """(order, cutoff Hz, causal) from meta.json's sensor.anti_alias_filter,
    written as "Butterworth, order 4, 100 Hz, causal"; None if not declared so."""
    import re
    text = str(((meta or {}).get("sensor") or {}).get("anti_alias_filter") or "")
    m = re.search(r"butterworth.*?order\s*(\d+).*?([0-9.]+)\s*hz", text, re.IGNORECASE)
    if not m:
        return None
    order, cutoff = int(m.group(1)), float(m.group(2))
    if not (1 <= order <= 10 and cutoff > 0):
        raise ValueError(f"sensor.anti_alias_filter {text!r}: order 1-10 and a positive cutoff expected")
    return order, cutoff, "zero-phase" not in text.lower()


MAX_FILTER_RATE = 1e6   # Hz: a logger's internal rate above it is refused (the grid would not fit in memory)


def filter_rate_of(meta: Optional[Mapping], anti_alias: tuple, sample_rate: float) -> Optional[float]:
    """The rate the logger runs its anti-alias filter at (meta.json
    sensor.internal_rate_Hz), Hz; None if not declared (the filter then runs on
    the communication grid, twice the sample rate). A declared rate below the
    sample rate, not above twice the filter's cutoff, not finite or above
    MAX_FILTER_RATE is refused with the field and the value."""
    value = ((meta or {}).get("sensor") or {}).get("internal_rate_Hz")
    if value is None:
        return None
    field_ = "sensor.internal_rate_Hz"
    try:
        rate = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{field_} = {value!r}: a rate in Hz expected") from None
    if not (math.isfinite(rate) and sample_rate <= rate <= MAX_FILTER_RATE):
        raise ValueError(f"{field_} = {value!r}: the logger's internal rate must lie between the sample rate "
                         f"({sample_rate:g} Hz) and {MAX_FILTER_RATE:g} Hz")
    if not anti_alias[1] < 0.5 * rate:
        raise ValueError(f"{field_} = {value!r}: the anti-alias filter's cutoff ({anti_alias[1]:g} Hz) must lie "
                         f"below half the rate it runs at")
    return rate


def transducer_for(track, s_m: float, v: float, settle: float) -> int:
    """The cart that passes s_M 1.5 s after settling at the nominal speed (not
    before 1 s, so that s_M and v_s anywhere within their bounds still come
    after it): every evaluation then simulates settle + ~1.5 s + the record,
    not up to a lap more (cart 0 on the field set's layout 3: 117-176 s)."""
    return arriving_cart(float(track.length), int(track.n_carts), s_m, max(abs(v), 0.1), settle + 1.5,
                         earliest=settle + 1.0)[0]


def noise_of(meas) -> np.ndarray:
    """The declared white noise per force channel, N (meta.json
    sensor.force_noise_std_N); an error naming the file and the channel if a
    channel is missing or not a positive number."""
    declared = ((meas.meta or {}).get("sensor") or {}).get("force_noise_std_N")
    where = f"{getattr(meas, 'path', None) or meas.id}/meta.json: sensor.force_noise_std_N"
    if not isinstance(declared, Mapping):
        raise ValueError(f"{where} is not declared: the likelihood objective needs the noise of every channel")
    out = []
    for c in FORCE_CHANNELS:
        v = declared.get(c)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
            raise ValueError(f"{where}[{c!r}] = {v!r}: must be a positive number of newtons")
        out.append(float(v))
    return np.array(out)


def tare_of(meta: Optional[Mapping] = None) -> np.ndarray:
    """3 sigma of the declared zero error per force channel, N."""
    spec = dict(OFFSET_STD)
    declared = ((meta or {}).get("sensor") or {}).get("force_offset_std_N") or {}
    spec.update({k: float(v) for k, v in declared.items() if k in spec})
    return 3.0 * np.array([spec[c] for c in FORCE_CHANNELS])
