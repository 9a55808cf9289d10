"""Close the loop (issues 7 and 18): residual -> missing effect -> extended model.

One round: the base refitted to its own optimum (Levenberg-Marquardt in the
likelihood's metric, identification.refine), the noise of each channel
(declared or estimated: identification.evidence), the residual analysis
(identification.residual), every effect of the catalogue scored by the share
of the objective it explains beyond the base parameters
(identification.attribution) and the best fitted through the FMU (rescore);
the leading candidates (TEST_MAX) are switched on, their parameters added to
the design vector and identified again from the refitted base
(identification.extension, then refine). An effect is *confirmed* only by
evidence (identification.evidence): a likelihood-ratio test against the noise
that allows for a correlated residual, Bonferroni-corrected for every
hypothesis scanned in the round; BIC; no disturbance outside the catalogue
(crosstalk, a periodic interference, the logger's clock) explaining the
residual better; and held-out validation against the refitted base. A
residual above the noise that no candidate explains is "not in the
catalogue", located in channel, frequency, track position and time. A
candidate that cannot be built or fitted (a degenerate fit, bounds outside
the FMU's range, a failed simulation) is dropped with its reason; the round
goes on. A second round starts from the extended model.

From the command line: `lss close-loop` (lss_app.cmd_close_loop). Every
identification keeps a journal in DIR, the attribution of each round is
written atomically once done: a run killed at any point resumes where it was.
"""
from __future__ import annotations

import dataclasses
import json
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Optional, Sequence

import numpy as np

from lss_fmu.atomic import write_json_atomic
from lss_fmu.variables import FORCE_CHANNELS

from .attribution import Attribution, attribute, demean_columns, simulate_with
from .catalogue import CATALOGUE, Context, SensorError
from .evidence import (ALPHA, Departure, HoldOut, LRTest, Noise, beyond, departures, excess, fit_gain, holdout,
                       lr_test, named_bands, noise_levels, project_out)
from .extension import extended_problem, extension_of
from .identify import identify
from .problem import IdentificationProblem, nrmsd, tared
from .refine import refine

log = logging.getLogger(__name__)

LOCAL_SHARE = 0.5    # unexplained residual 'concentrates' if half of it sits in ...
LOCAL_WINDOW = 0.1   # ... this fraction of the record (or 0.1 s, whichever is longer) of one channel
RESCORE = 3          # effects fitted through the FMU after the linear ranking ...
RESCORE_EVALS = 20   # ... with this many evaluations each
TEST_MAX = 2         # candidates taken through the extended identification and the tests, best first
REFINE_EVALS = 80    # simulations of the local refinement (identification.refine) ending each extension
BASE_REFINE_EVALS = 60   # ... and of the base's refinement to its own optimum before anything is tested
PROFILE_POINTS = 9       # the base's least-determined variable scanned at this many values ...
PROFILE_EVALS = 24       # ... the others refitted with this many simulations at each (profile_polish) ...
ZOOM_EVALS = 8           # ... then Brent's method around the best value, at most this many profile points
STEP = 0.003             # difference step of the refinements, of each bound range: the CoR landscape is rough
                         # and its valleys narrow (e_SW to 0.005): 0.02 leads Levenberg-Marquardt astray
SIGNALS = ["transducer.s", "transducer.v", "transducer.joint.v_axial"]


@dataclass
class CandidateTest:
    """One candidate effect through the extended identification and the tests."""
    effect: str
    label: str
    problem: IdentificationProblem = field(repr=False)
    x: np.ndarray
    f: float                     # the objective (Eq. 10-12) at x
    H: np.ndarray
    S: float                     # sum r^2 / sigma^2 at x
    lr: LRTest
    holdout: Optional[HoldOut]
    identified: dict
    amplitude: Optional[float]
    refined: dict
    supported: bool = False
    why_not: list = field(default_factory=list)
    base_alt: Optional[tuple] = field(default=None, repr=False)   # (x, S) of the base refitted from here
    signature: list = field(default=None, repr=False)   # the hypothesis' columns at the base, every probe

    def to_dict(self) -> dict:
        return {"effect": self.effect, "hypothesis": self.label, "f": self.f, "S": self.S,
                "parameters": list(self.identified), "lr": self.lr.to_dict(),
                "holdout": None if self.holdout is None else self.holdout.to_dict(),
                "identified": self.identified, "amplitude": self.amplitude, "supported": self.supported,
                "why_not": self.why_not, "refined": self.refined}


@dataclass
class Round:
    number: int
    f_base: float
    H_base: np.ndarray
    attribution: Attribution
    verdict: str
    effect: Optional[str] = None
    f_extended: Optional[float] = None
    H_extended: Optional[np.ndarray] = None
    identified: dict = field(default_factory=dict)   # effect parameter -> value
    amplitude: Optional[float] = None
    confirmed: bool = False
    location: dict = field(default_factory=dict)
    x_base: Optional[np.ndarray] = None
    x_extended: Optional[np.ndarray] = None
    problem_extended: Optional[IdentificationProblem] = field(default=None, repr=False)
    base_problem: Optional[IdentificationProblem] = field(default=None, repr=False)
    residual: object = field(default=None, repr=False)
    refined: dict = field(default_factory=dict)   # the local refinement of the extension: f before/after, runs
    # issue 18: the evidence
    outcome: str = ""                              # confirmed, not in the catalogue, nothing significant
    noise: Optional[Noise] = None
    excess: object = None                          # evidence.Excess of the refitted base
    base_refined: dict = field(default_factory=dict)
    S_base: Optional[float] = None
    tests: list = field(default_factory=list)      # CandidateTest, in the order tested
    departures: list = field(default_factory=list)  # evidence.Departure
    dropped: list = field(default_factory=list)    # {"effect", "stage", "reason"}
    hypotheses: int = 0                            # m of the Bonferroni correction
    base_restarts: list = field(default_factory=list)  # better bases found through an extension

    @property
    def evidence(self) -> Optional[CandidateTest]:
        """The test behind the verdict: the confirmed candidate, else the first tested."""
        for t in self.tests:
            if t.supported:
                return t
        return self.tests[0] if self.tests else None

    def to_dict(self) -> dict:
        chans = FORCE_CHANNELS
        ev = self.evidence
        return {
            "round": self.number, "verdict": self.verdict, "outcome": self.outcome, "effect": self.effect,
            "confirmed": self.confirmed,
            "f_base": self.f_base, "nrmsd_base": dict(zip(chans, map(float, self.H_base))),
            "f_extended": self.f_extended,
            "nrmsd_extended": None if self.H_extended is None else dict(zip(chans, map(float, self.H_extended))),
            "identified": self.identified, "amplitude": self.amplitude, "location": self.location,
            "refined": self.refined, "base_refined": self.base_refined,
            "evidence": None if ev is None else {"effect": ev.effect, "statistic": ev.lr.T, "dof": ev.lr.dof,
                                                 "p": ev.lr.p, "p_bonferroni": ev.lr.p_adj, "dbic": ev.lr.dbic,
                                                 "holdout_gain": None if ev.holdout is None else ev.holdout.gain},
            "alpha": ALPHA, "hypotheses": self.hypotheses, "S_base": self.S_base,
            "base_restarts": self.base_restarts,
            "noise": None if self.noise is None else self.noise.to_dict(),
            "excess": None if self.excess is None else self.excess.to_dict(),
            "tests": [t.to_dict() for t in self.tests],
            "departures": [d.to_dict() for d in self.departures],
            "dropped": self.dropped,
            "attribution": self.attribution.to_dict(),
        }


@dataclass
class CloseLoopResult:
    problem: IdentificationProblem
    x_base: np.ndarray
    rounds: list
    seconds: float

    @property
    def found(self) -> list:
        return [r.effect for r in self.rounds if r.confirmed]

    @property
    def verdict(self) -> str:
        return self.rounds[-1].verdict if self.rounds else "no analysis"

    @property
    def outcome(self) -> str:
        return self.rounds[-1].outcome if self.rounds else "no analysis"

    def to_dict(self) -> dict:
        return {"measurement": self.problem.name, "model": self.problem.model, "layout": self.problem.layout,
                "protocol": self.problem.protocol.name, "found": self.found, "verdict": self.verdict,
                "outcome": self.outcome, "seconds": self.seconds, "rounds": [r.to_dict() for r in self.rounds]}


def context(problem: IdentificationProblem, x: np.ndarray, sensor_offset_std: Optional[dict] = None,
            noise: Optional[np.ndarray] = None, s: Optional[np.ndarray] = None) -> Context:
    """What the catalogue needs; `sensor_offset_std` (N per force channel) is the
    transducer's declared zero tolerance (meta.json 'sensor'), by default the
    virtual transducer cart's; `noise` the white noise per channel (N); `s`
    the transducer cart's simulated track position over the record (unwrapped),
    else estimated from the set point (wrong for a start-up or a stop)."""
    from lss_fmu.layouts import load_track
    tr = load_track(problem.layout)
    vals = problem.values(x)
    v = float(vals.get("drive.v_ref", problem.fixed.get("drive.v_ref", 2.0)))
    s0 = float(vals.get("trigger.s_M", 0.0))
    window = (float(s[0]), float(s[-1])) if s is not None and len(s) else (s0, s0 + v * float(problem.times[-1]))
    ctx = Context(problem.layout, float(tr.length), np.asarray(tr.s0, float), window, int(tr.n_carts), v)
    if sensor_offset_std:
        ctx.sensor_offset_tol = 3.0 * np.array([float(sensor_offset_std[c]) for c in FORCE_CHANNELS])
    elif problem.tare is not None:
        ctx.sensor_offset_tol = np.asarray(problem.tare, float)
    if noise is not None:
        ctx.sensor_noise = np.asarray(noise, float)
    return ctx


def localise(problem: IdentificationProblem, r: np.ndarray, s: Optional[np.ndarray] = None,
             w: Optional[np.ndarray] = None) -> dict:
    """Where the residual concentrates: the channel with the largest share of
    the weighted squared residual (w per channel, by default the objective's
    1 / span^2; with 1 / sigma^2 the share of the excess over the noise), the
    shortest stretch of the record holding LOCAL_SHARE of it, and the
    channel's dominant frequency (the periodogram's peak, against its median)."""
    if w is None:
        w = 1.0 / np.maximum(problem.samples.max(0) - problem.samples.min(0), 1e-12) ** 2
    e = r ** 2 * w
    per_ch = e.sum(0)
    j = int(np.argmax(per_ch))
    t = problem.times
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    n = max(2, int(round(max(LOCAL_WINDOW * (t[-1] - t[0]), 0.1) / dt)))
    n = min(n, len(t))
    c = np.concatenate([[0.0], np.cumsum(e[:, j])])
    win = c[n:] - c[:-n]
    i = int(np.argmax(win))
    share = float(win[i] / c[-1]) if c[-1] > 0 else 0.0
    out = {"channel": FORCE_CHANNELS[j], "channel_share": float(per_ch[j] / per_ch.sum()) if per_ch.sum() > 0 else 0.0,
           "t_start": float(t[i]), "t_end": float(t[i + n - 1]), "window_share": share,
           "window_fraction": n / len(t)}
    if s is not None:
        out.update({"s_start": float(s[i]), "s_end": float(s[i + n - 1])})
    out["concentrated"] = bool(share >= LOCAL_SHARE and share >= 3 * out["window_fraction"])
    # the dominant frequency of that channel's residual
    x = r[:, j] - r[:, j].mean()
    if len(x) >= 16:
        nfft = 1 << int(math.ceil(math.log2(8 * len(x))))
        X = np.abs(np.fft.rfft(x * np.hanning(len(x)), n=nfft))
        f = np.fft.rfftfreq(nfft, dt)
        ok = f >= 3.0 / max(t[-1] - t[0], 1e-9)
        if ok.any():
            k = int(np.argmax(np.where(ok, X, -1.0)))
            med = float(np.median(X[ok]))
            out["frequency_hz"] = float(f[k])
            out["frequency_peak_ratio"] = float(X[k] / med) if med > 0 else float("inf")
            if s is not None and t[-1] > t[0] and abs(s[-1] - s[0]) > 0:
                out["order_per_m"] = float(f[k] / (abs(s[-1] - s[0]) / (t[-1] - t[0])))
    # is the residual's energy growing with time (a clock, a drift)?
    halves = np.array_split(e[:, j], 2)
    if len(halves) == 2 and halves[0].sum() > 0:
        out["late_to_early"] = float(halves[1].sum() / halves[0].sum())
    return out


def _signals(problem, x) -> dict:
    try:
        sig = simulate_with(problem, x, channels=SIGNALS)
    except Exception as exc:  # older FMU without the diagnostic outputs: the track position alone
        log.warning("model signals unavailable (%s); using transducer.s only", exc)
        sig = np.column_stack([simulate_with(problem, x, channels=["transducer.s"])[:, 0]] +
                              [np.full(len(problem.times), np.nan)] * 2)
    return dict(zip(SIGNALS, sig.T))


def _unwrap(s: np.ndarray, length: float) -> np.ndarray:
    jumps = np.diff(s) < -0.5 * length
    return s + length * np.concatenate([[0], np.cumsum(jumps)])


def analyse(problem: IdentificationProblem, x: np.ndarray, sim: np.ndarray, signals: Optional[dict] = None):
    """The residual analysis at x (None if the module or the layout lacks what it needs)
    and the transducer cart's unwrapped track position."""
    from lss_fmu.layouts import load_track
    try:
        from .residual import analyse_residual
    except ImportError:
        return None, None
    sig = signals if signals is not None else _signals(problem, x)
    tr = load_track(problem.layout)
    s = _unwrap(sig["transducer.s"], float(tr.length))
    r_drive = float(problem.model_constants(("cart.r_drive",))["cart.r_drive"])
    model_signals = {"v": sig["transducer.v"], "v_joint": sig["transducer.joint.v_axial"]}
    model_signals = {k: v for k, v in model_signals.items() if np.all(np.isfinite(v))}
    try:
        ra = analyse_residual(problem.samples, sim, problem.times, s, float(tr.length), layout=problem.layout,
                              r_drive=r_drive, pitch=float(tr.length) / tr.n_carts,
                              motor_positions=np.asarray(tr.motors), model_signals=model_signals)
    except Exception as exc:
        log.warning("residual analysis failed: %s", exc)
        ra = None
    return ra, s


def close_loop(problem: IdentificationProblem, x_base: Optional[Sequence[float]] = None, *,
               effects: Optional[Sequence[str]] = None, rounds: int = 1, base_evals: int = 300,
               max_evals: int = 200, seed: int = 0, out: Optional[Path] = None, progress: bool = False,
               workers: int = 1, sensor_offset_std: Optional[dict] = None,
               fit_evals: int = RESCORE_EVALS, refine_evals: int = REFINE_EVALS,
               base_refine_evals: int = BASE_REFINE_EVALS, noise_std: Optional[Mapping[str, float]] = None,
               test_max: int = TEST_MAX, polish_evals: Optional[int] = None,
               profile_points: int = PROFILE_POINTS) -> CloseLoopResult:
    """The loop on one problem: base identification (unless x_base is given),
    then up to `rounds` rounds of analysis, attribution, extension and tests.
    `sensor_offset_std`: the transducer's declared zero tolerance per force
    channel (N); offsets and gains within 3 sigma of it are not faults.
    `noise_std`: its declared white noise per force channel (N; meta.json
    sensor.force_noise_std_N), else estimated from the residual.
    `polish_evals`: the complex run again from the base point at the start of
    each round (default `max_evals`, what an extension gets; 0: none);
    `profile_points`: the profile of the base's least-determined variable
    (profile_polish; 0: none)."""
    t0 = time.time()
    out = Path(out) if out else None
    if out:
        out.mkdir(parents=True, exist_ok=True)
    if x_base is None:
        res = identify(problem, max_evals=base_evals, seed=seed, progress=progress, workers=workers,
                       journal=out / "base_journal.jsonl" if out else None)
        x_base = res.x
    x = np.asarray(x_base, float)
    base, result_rounds = problem, []
    remaining = list(effects or CATALOGUE)
    for k in range(1, rounds + 1):
        rnd = one_round(base, x, k, remaining, max_evals=max_evals, seed=seed + k, out=out, progress=progress,
                        workers=workers, sensor_offset_std=sensor_offset_std, fit_evals=fit_evals,
                        refine_evals=refine_evals, base_refine_evals=base_refine_evals, noise_std=noise_std,
                        test_max=test_max, polish_evals=max_evals if polish_evals is None else polish_evals,
                        profile_points=profile_points)
        result_rounds.append(rnd)
        if not rnd.confirmed or not [e for e in remaining if e != rnd.effect]:
            break
        remaining.remove(rnd.effect)
        # the next round's base is the extended model, the found effect still free: a second
        # effect in the data distorts the first one's fit, and with its parameters in the base
        # Jacobian the attribution scores the next effect beyond what refitting it could do;
        # the next extension then identifies both together
        base = dataclasses.replace(rnd.problem_extended, x0=rnd.problem_extended.values(rnd.x_extended))
        x = np.asarray(rnd.x_extended, float)
    return CloseLoopResult(problem, np.asarray(x_base, float), result_rounds, time.time() - t0)


def _S(problem: IdentificationProblem, sim: np.ndarray, w: np.ndarray) -> tuple:
    """(tared residual, sum r^2 w) of a simulation."""
    r = tared(problem.samples - sim, problem.tare)
    return r, float(np.sum(r ** 2 * w))


def hypothesis_counts(att: Attribution) -> dict:
    """Per effect, the hypotheses the round scanned (failed ones included): the
    Bonferroni correction's m. The sensor effect counts its channels (the
    extension chooses among them)."""
    out: dict = {}
    for h in att.all_hypotheses:
        out[h.effect] = out.get(h.effect, 0) + 1
    for fl in att.failed:
        out[fl["effect"]] = out.get(fl["effect"], 0) + 1
    if "sensor" in out:
        out["sensor"] = max(out["sensor"], len(FORCE_CHANNELS))
    return out


def one_round(base: IdentificationProblem, x: np.ndarray, number: int, effects: Sequence[str], *,
              max_evals: int, seed: int, out: Optional[Path], progress: bool, workers: int = 1,
              sensor_offset_std: Optional[dict] = None, fit_evals: int = RESCORE_EVALS,
              refine_evals: int = REFINE_EVALS, base_refine_evals: int = BASE_REFINE_EVALS,
              noise_std: Optional[Mapping[str, float]] = None, test_max: int = TEST_MAX,
              polish_evals: Optional[int] = None, profile_points: int = PROFILE_POINTS) -> Round:
    """One round (module docstring). The base must have had every chance the
    extension had: after each candidate's extended identification the base is
    refitted from the extension's base parameters, and if that lowers the base
    below where it stood (the complex had stopped in another basin) the round
    starts again from there (at most BASE_RESTARTS times)."""
    x = np.asarray(x, float)
    restarts = []
    for attempt in range(BASE_RESTARTS + 1):
        rnd, better = _attempt(base, x, number, effects, max_evals=max_evals, seed=seed, out=out, progress=progress,
                               workers=workers, sensor_offset_std=sensor_offset_std, fit_evals=fit_evals,
                               refine_evals=refine_evals, base_refine_evals=base_refine_evals, noise_std=noise_std,
                               test_max=test_max, last=attempt == BASE_RESTARTS, attempt=attempt,
                               polish_evals=max_evals if polish_evals is None else polish_evals,
                               profile_points=profile_points)
        rnd.base_restarts = restarts
        if better is None:
            return rnd
        restarts.append({"from_S": rnd.S_base, "to_S": better[1], "after": better[2],
                         "x": dict(zip(base.free, map(float, better[0])))})
        log.info("round %d: the base refitted from %s's point lowers S from %.6g to %.6g: round again",
                 number, better[2], rnd.S_base, better[1])
        x = better[0]
    return rnd


BASE_RESTARTS = 2        # times a round starts again from a better base found through an extension
BASE_IMPROVE = 0.02      # ... when that base lowers S by at least this share


def _attempt(base, x, number, effects, *, max_evals, seed, out, progress, workers, sensor_offset_std, fit_evals,
             refine_evals, base_refine_evals, noise_std, test_max, last, attempt=0, polish_evals=0,
             profile_points=PROFILE_POINTS) -> tuple:
    """(Round, None) or, if an extension's base parameters refit the base lower
    than it stands, (Round, (x, S, effect)) unless `last`."""
    sim = base.simulate(x)
    r0 = tared(base.samples - sim, base.tare)
    noise = noise_levels(r0, noise_std)
    w = 1.0 / noise.sigma ** 2
    # 1. the base at its own optimum, in the likelihood's metric: a base that stopped above the
    # noise floor would hand its remainder to any flexible candidate
    S0 = float(np.sum(r0 ** 2 * w))
    base_refined = {"S_start": S0, "S": S0, "nfev": 0}
    if polish_evals > 0:
        # the base gets what an extension gets: the complex from its point with the same budget ...
        pol = identify(dataclasses.replace(base, x0=base.values(x)), max_evals=max(polish_evals, len(base.free) + 3),
                       seed=seed + 101, progress=False,
                       journal=out / f"round{number}_base{attempt}_journal.jsonl" if out else None)
        base_refined["complex_evals"] = int(pol.nfev) if hasattr(pol, "nfev") else polish_evals
        try:
            sim_p = base.simulate(pol.x)
            rp = tared(base.samples - sim_p, base.tare)
            if float(np.sum(rp ** 2 * w)) < S0:
                x, sim, S0 = np.asarray(pol.x, float), sim_p, float(np.sum(rp ** 2 * w))
        except Exception as exc:
            log.warning("base polish failed: %s", exc)
        base_refined["S_complex"] = S0
    if base_refine_evals > 0:
        # ... and Levenberg-Marquardt in the likelihood's metric to the bottom of its basin
        ref = refine(base, x, max_evals=base_refine_evals, central=True, channel_weights=w, rel_step=STEP)
        base_refined.update({"S": min(S0, ref.f), "nfev": ref.nfev, "iterations": ref.iterations})
        if ref.f < S0 and ref.sim is not None:
            x, sim = np.asarray(ref.x, float), ref.sim
    if profile_points > 1:
        try:
            xp, Sp, base_refined["profile"] = profile_polish(base, x, w, points=profile_points)
            if Sp < base_refined["S"]:
                x, sim = xp, base.simulate(xp)
                base_refined["S"] = Sp
        except Exception as exc:
            log.warning("profile polish failed: %s", exc)
    r_b = tared(base.samples - sim, base.tare)
    if noise.source == "estimated":   # at the refitted base
        noise = noise_levels(r_b, None)
        w = 1.0 / noise.sigma ** 2
    S_b = float(np.sum(r_b ** 2 * w))
    H = nrmsd(base.samples, sim, base.tare)
    f_base = float(np.sum(H ** 2))
    exc = excess(r_b, noise.sigma, len(base.free))
    sig = _signals(base, x)
    ra, s = analyse(base, x, sim, sig)
    ctx = context(base, x, sensor_offset_std, noise.sigma, s)
    cache = out / f"round{number}_attribution.json" if out else None
    att = attribute(base, x, ctx, effects=effects, progress=progress)
    if cache:
        write_json_atomic(cache, att.to_dict())
    counts = hypothesis_counts(att)
    m = max(1, sum(counts.values()))
    rnd = Round(number, f_base, H, att, "", x_base=x, residual=ra, base_problem=base, noise=noise, excess=exc,
                base_refined=base_refined, S_base=S_b, hypotheses=m)
    fits, dropped = rescore(base, x, att, f_base, n=RESCORE, evals=fit_evals, seed=seed, out=out, number=number)
    rnd.dropped = dropped
    if cache:
        write_json_atomic(cache, att.to_dict())
    # 2. the disturbances outside the catalogue, fitted to the same residual
    bands = _catalogue_bands(base, sig, effects)
    try:
        rnd.departures = departures(base, x, sim, r_b, att.base_columns, w, excluded_hz=bands)
    except Exception as exc:   # the verdict goes on without them
        log.warning("departures outside the catalogue failed: %s", exc)
        rnd.dropped.append({"effect": "(departures)", "stage": "fit", "reason": str(exc)[:300]})
    # 3. the leading candidates through the extended identification and the tests
    better = None
    for fit in fits[:max(1, test_max)]:
        try:
            t = _test_candidate(base, x, fit, att, S_b, w, m, counts.get(fit.score.effect, 1), max_evals=max_evals,
                                seed=seed, out=out, number=number, progress=progress, workers=workers,
                                refine_evals=refine_evals, base_refine_evals=base_refine_evals)
        except Exception as exc:   # a degenerate candidate: dropped, the loop goes on
            log.warning("round %d: candidate %s dropped: %s", number, fit.score.effect, exc)
            rnd.dropped.append({"effect": fit.score.effect, "stage": "extension", "reason": str(exc)[:300]})
            continue
        rnd.tests.append(t)
        if t.base_alt is not None and t.base_alt[1] < (1.0 - BASE_IMPROVE) * S_b and not last:
            if better is None or t.base_alt[1] < better[1]:
                better = (t.base_alt[0], t.base_alt[1], t.effect)
            break
        if t.supported:
            break
    if better is not None:
        return rnd, better
    _decide(rnd, base, r_b, s, w)
    return rnd, None


def _catalogue_bands(problem: IdentificationProblem, sig: dict, effects: Sequence[str]) -> list:
    """Frequency bands (Hz) the catalogue's effects can fill in this record
    (evidence.named_bands at the record's speeds)."""
    from lss_fmu.layouts import load_track
    try:
        tr = load_track(problem.layout)
        v = np.asarray(sig.get("transducer.v"), float)
        v = v[np.isfinite(v)]
        if not len(v):
            v = np.array([float((problem.x0 or {}).get("drive.v_ref", problem.fixed.get("drive.v_ref", 2.0)))])
        r_drive = float(problem.model_constants(("cart.r_drive",))["cart.r_drive"])
        return named_bands(float(np.min(np.abs(v))), float(np.max(np.abs(v))), r_drive,
                           float(tr.length) / int(tr.n_carts), len(tr.motors), float(tr.length),
                           ripple="motor_ripple" in effects)
    except Exception as exc:
        log.warning("catalogue frequency bands unavailable: %s", exc)
        return []


def _signature_columns(base: IdentificationProblem, x: np.ndarray, sc, ext, sim0: np.ndarray,
                       every: bool = False) -> list:
    """The effect's signature at the base (the attribution's probes; for the
    sensor those of the channels the extension frees, unless `every`), tared
    channels demeaned."""
    from .attribution import _signatures
    probes = sc.hypothesis.probes
    if isinstance(CATALOGUE[sc.effect], SensorError) and not every:
        names = set(ext.free)
        probes = [p for p in probes if f"effects.sensor.{p.label.replace(' ', '.')}" in names]
    hyp = dataclasses.replace(sc.hypothesis, probes=probes)
    G = _signatures(base, x, sim0, hyp, None)
    demean = np.zeros(sim0.shape[1], bool)
    if base.tare is not None:
        demean = np.abs((base.samples - sim0).mean(axis=0)) <= base.tare
    return [demean_columns(g, demean) for g in G]


def _test_candidate(base, x_b, fit, att, S_b, w, m, m_effect, *, max_evals, seed, out, number, progress,
                    workers, refine_evals, base_refine_evals=BASE_REFINE_EVALS) -> CandidateTest:
    """The candidate through the tests. What the effect explains is measured
    where the base cannot move into another valley (the CoR landscape is rough
    and many-valleyed: a wider search with more parameters finds a lower valley
    of the *base* and credits the effect with it): the larger of (a) the linear
    fit of its signature to the refitted base's residual beyond the base
    columns and (b) the fit of its parameters through the FMU with the base held
    at its optimum (Levenberg-Marquardt from the rescore's complex), each tested
    against the noise (evidence.lr_test; the Bonferroni m doubled for taking the
    larger). Held-out: the base and (b), each refitted on the other blocks.
    Only a candidate that passes is identified globally (the complex over all
    parameters, then refine) for its estimates, and the base refitted from that
    point's base parameters (a better base restarts the round, one_round)."""
    sc, ext, prob_ext = fit.score, fit.ext, fit.problem
    x0 = {**prob_ext.x0, **fit.stage1.problem.values(fit.stage1.x)}
    stage2 = dataclasses.replace(prob_ext, x0=x0)
    # (b) the effect alone, base held
    held = dataclasses.replace(prob_ext, free=tuple(ext.free), x0=x0)
    xh0 = np.array([x0[n] for n in held.free])
    rh = refine(held, xh0, max_evals=max(refine_evals // 2, 2 * len(held.free) + 2), central=True,
                channel_weights=w, rel_step=STEP)
    x_held_full = np.array([held.values(rh.x)[n] for n in stage2.free])
    sim_h = rh.sim if rh.sim is not None else stage2.simulate(x_held_full)
    r_h, S_h = _S(stage2, sim_h, w)
    refined = {"held": {"S_start": rh.f_start, "S": S_h, "nfev": rh.nfev, "iterations": rh.iterations}}
    # (a) the linear signature beyond the base columns
    sim_b = base.simulate(x_b)
    r_b, _ = _S(base, sim_b, w)
    G_raw = _signature_columns(base, x_b, sc, ext, sim_b)
    G = project_out(G_raw, att.base_columns, w)
    _, fit_lin, S0, S1 = fit_gain(r_b, G, w)
    kw = dict(q=len(ext.free), m=2 * m, m_effect=m_effect, J=att.base_columns)
    lr_lin = lr_test(S_b, S_b - (S0 - S1), G, r_b - fit_lin, w, **kw)
    lr_held = lr_test(S_b, S_h, G, r_h, w, **kw)
    lr = lr_held if lr_held.T >= lr_lin.T else lr_lin
    lr.method = ("held" if lr is lr_held else "linear") + "/" + lr.method
    ho = holdout(base, x_b, stage2, x_held_full, w)
    why = []
    if not lr.significant:
        why.append(f"likelihood ratio not significant (p = {lr.p:.2g}, x {lr.m} hypotheses = {lr.p_adj:.2g} "
                   f">= {ALPHA:g})")
    if not lr.dbic > 0:
        why.append(f"BIC prefers the base (dBIC = {lr.dbic:.1f})")
    if not ho.gain > 0:
        why.append(f"no held-out gain ({100 * ho.gain:+.1f}% against the refitted base)")
    x_e, S_e, sim_e = x_held_full, S_h, sim_h
    base_alt = None
    if not why:
        # the estimates: the extended identification from there (it may walk the base far: a missing
        # mass drags the CoRs onto their bounds), then the refinement
        tag = "" if sc.effect == (att.ranking[0].effect if att.ranking else None) else f"_{sc.effect}"
        st = dataclasses.replace(stage2, x0=stage2.values(x_held_full))
        res = identify(st, max_evals=_budget(max_evals, st, sc.effect), seed=seed + 1, progress=progress,
                       workers=workers, journal=out / f"round{number}{tag}_journal.jsonl" if out else None)
        xg = np.asarray(res.x, float)
        if refine_evals > 0:
            ref = refine(stage2, xg, max_evals=refine_evals, channel_weights=w, rel_step=STEP)
            refined["global"] = {"S_start": ref.f_start, "S": ref.f, "nfev": ref.nfev, "iterations": ref.iterations}
            xg = np.asarray(ref.x, float)
        try:
            sim_g = stage2.simulate(xg)
            r_g, S_g = _S(stage2, sim_g, w)
            if S_g < S_e:
                x_e, S_e, sim_e = xg, S_g, sim_g
        except Exception as exc:
            log.warning("%s: the global extension's point cannot be simulated: %s", sc.effect, exc)
        # the base from the extension's base parameters: if it gets lower there, the base had
        # stopped in another valley (the round starts again from that base, one_round)
        vals_e = stage2.values(x_e)
        xb2 = np.array([vals_e[n] for n in base.free])
        if base_refine_evals > 0 and not np.allclose(xb2, x_b):
            try:
                rb = refine(base, xb2, max_evals=base_refine_evals, central=True, channel_weights=w, rel_step=STEP)
                if np.isfinite(rb.f):
                    base_alt = (np.asarray(rb.x, float), float(rb.f))
            except Exception as exc:
                log.warning("base refit from the %s extension failed: %s", sc.effect, exc)
    H_e = nrmsd(stage2.samples, sim_e, stage2.tare)
    vals = stage2.values(x_e)
    identified = {n: float(vals[n]) for n in ext.free}
    identified.update({n: v for n, v in ext.fixed.items()})
    amp = CATALOGUE[sc.effect].amplitude(vals, base.samples.mean(axis=0))
    every = _signature_columns(base, x_b, sc, ext, sim_b, every=True) \
        if isinstance(CATALOGUE[sc.effect], SensorError) else G_raw
    return CandidateTest(sc.effect, sc.label, stage2, x_e, float(np.sum(H_e ** 2)), H_e, S_e, lr, ho, identified,
                         amp, refined, supported=not why, why_not=why, base_alt=base_alt, signature=every)


def profile_polish(base: IdentificationProblem, x: np.ndarray, w: np.ndarray, *, points: int = PROFILE_POINTS,
                   evals: int = PROFILE_EVALS) -> tuple:
    """The base's least-determined variable (the smallest sensitivity over its
    bound range, in the likelihood's metric: e_JR on the release transient,
    twenty times weaker than the other CoRs and many-valleyed) scanned over its
    range, the others refitted at each value (Levenberg-Marquardt, `evals`
    simulations); the best then refined with everything free. Returns (x, S,
    info); x is the start when nothing is lower."""
    from .attribution import base_jacobian
    x = np.asarray(x, float)
    sim0 = base.simulate(x)
    _, S_start = _S(base, sim0, w)
    info = {"S_start": S_start, "S": S_start}
    if len(base.free) < 2 or points < 2:
        return x, S_start, info
    cols = base_jacobian(base, x, sim0)
    if len(cols) != len(x):
        return x, S_start, info
    lo, hi = np.array(base.bounds_array, float).T
    sens = np.array([math.sqrt(float(np.sum(g ** 2 * w))) * (hi[k] - lo[k]) for k, g in enumerate(cols)])
    k = int(np.argmin(sens))
    name = base.free[k]
    others = tuple(n for n in base.free if n != name)
    best = (S_start, x)
    count = {"nfev": len(x) + 1}
    xs0 = np.array([xv for n, xv in zip(base.free, x) if n != name])

    def profile(v):
        """S with `name` at v, the others refitted (from the start's values)."""
        q = dataclasses.replace(base, free=others, x0={**base.values(x), name: float(v)})
        try:
            r = refine(q, xs0, max_evals=evals, central=False, channel_weights=w, rel_step=STEP)
        except Exception as exc:
            log.warning("profile of %s at %g failed: %s", name, v, exc)
            return math.inf, None
        count["nfev"] += r.nfev
        vals = q.values(r.x)
        return r.f, np.array([vals[n] for n in base.free])

    grid = np.linspace(lo[k], hi[k], points)
    values = []
    for v in grid:
        f, xv = profile(v)
        values.append(f)
        if f < best[0]:
            best = (f, xv)
    # the valley can be narrower than the grid: Brent's method within a grid step of the best point
    i = int(np.argmin(values))
    if np.isfinite(values[i]):
        from scipy.optimize import minimize_scalar
        step = grid[1] - grid[0]
        found = {}

        def f1(v):
            fv, xv = profile(v)
            found[v] = (fv, xv)
            return fv
        minimize_scalar(f1, bounds=(max(lo[k], grid[i] - step), min(hi[k], grid[i] + step)), method="bounded",
                        options={"xatol": 2e-3 * (hi[k] - lo[k]), "maxiter": ZOOM_EVALS})
        for fv, xv in found.values():
            if xv is not None and fv < best[0]:
                best = (fv, xv)
    nfev = count["nfev"]
    info.update({"variable": name, "points": points, "nfev": nfev, "S_profile": best[0]})
    if best[0] < S_start:
        r = refine(base, best[1], max_evals=BASE_REFINE_EVALS, central=True, channel_weights=w, rel_step=STEP)
        info["nfev"] = nfev + r.nfev
        xb, Sb = (np.asarray(r.x, float), r.f) if r.f < best[0] else (best[1], best[0])
        info["S"] = Sb
        return xb, Sb, info
    return x, S_start, info


def _where(loc: dict) -> str:
    parts = [f"{loc['channel']} ({100 * loc['channel_share']:.0f}% of the excess)"]
    if "frequency_hz" in loc:
        fr = f"{loc['frequency_hz']:.1f} Hz"
        if "order_per_m" in loc:
            fr += f" ({loc['order_per_m']:.2f} cycles/m)"
        parts.append(f"dominant frequency {fr}, {loc['frequency_peak_ratio']:.0f} x the median spectrum")
    tw = f"t = {loc['t_start']:.2f}-{loc['t_end']:.2f} s"
    if "s_start" in loc:
        tw += f", track s = {loc['s_start']:.2f}-{loc['s_end']:.2f} m"
    parts.append(f"densest at {tw} ({100 * loc['window_share']:.0f}% of that channel's excess"
                 f"{', concentrated' if loc['concentrated'] else ''})")
    if loc.get("late_to_early") is not None:
        parts.append(f"second half / first half of the record {loc['late_to_early']:.1f}")
    return "; ".join(parts)


def _stats(t: CandidateTest) -> str:
    ho = "-" if t.holdout is None else f"{100 * t.holdout.gain:+.1f}%"
    return (f"LR statistic {t.lr.T:.1f} on {t.lr.dof:.1f} dof (scale {t.lr.scale:.2f}), p = {t.lr.p:.2g}, "
            f"Bonferroni p = {t.lr.p_adj:.2g} (m = {t.lr.m}); dBIC = {t.lr.dbic:+.1f}; held-out gain {ho}")


def _decide(rnd: Round, base: IdentificationProblem, r_b: np.ndarray, s, w: np.ndarray) -> None:
    """The verdict from the tests (module docstring)."""
    sup = next((t for t in rnd.tests if t.supported), None)
    deps = [d for d in rnd.departures if d.counts]
    best_dep = max(deps, key=lambda d: d.test.dbic) if deps else None
    ev = rnd.evidence
    if ev is not None:   # the extension shown in the report: the confirmed one, else the first tested
        rnd.effect, rnd.problem_extended, rnd.x_extended = ev.effect, ev.problem, ev.x
        rnd.f_extended, rnd.H_extended, rnd.identified = ev.f, ev.H, ev.identified
        rnd.amplitude, rnd.refined = ev.amplitude, ev.refined
    if sup is not None and best_dep is not None and best_dep.test.dbic > sup.lr.dbic:
        sup.supported = False
        sup.why_not.append(f"a disturbance outside the catalogue explains the residual better "
                           f"({best_dep.label}: dBIC {best_dep.test.dbic:+.1f} > {sup.lr.dbic:+.1f})")
        sup = None
    if sup is not None:
        _still_outside(rnd, sup, w)
        if not sup.supported:
            sup = None
    noise = f"noise {rnd.noise.source}" if rnd.noise else "noise"
    if sup is not None:
        eff = CATALOGUE[sup.effect]
        rnd.confirmed, rnd.outcome = True, "confirmed"
        rnd.verdict = (f"{eff.title} ({sup.effect}, {sup.label}) confirmed: {_stats(sup)} ({noise}); "
                       f"f from {rnd.f_base:.4g} to {sup.f:.4g}")
        return
    rnd.confirmed = False
    loc = localise(base, r_b, s, w)
    rnd.location = loc
    best = f"best candidate {ev.effect}: {_stats(ev)}" if ev is not None else "no candidate could be tested"
    if ev is not None and ev.why_not:
        best += " - " + "; ".join(ev.why_not)
    above = rnd.excess is not None and rnd.excess.any
    if above or best_dep is not None:
        rnd.outcome = "not in the catalogue"
        what = (f"it looks most like {best_dep.family} ({best_dep.label}; T = {best_dep.test.T:.1f}, "
                f"Bonferroni p = {best_dep.test.p_adj:.2g}, dBIC {best_dep.test.dbic:+.1f})"
                if best_dep is not None else "none of the disturbances tried outside it (crosstalk, a periodic "
                                             "interference, the logger's clock) explains it either")
        ratio = "" if rnd.excess is None else (f" (mean square / noise up to "
                                               f"{float(np.max(rnd.excess.ratio)):.2f})")
        rnd.verdict = (f"not in the catalogue: the residual is above the noise{ratio} and no catalogue effect "
                       f"explains it ({best}); {what}. Where: {_where(loc)}")
    else:
        rnd.outcome = "nothing significant"
        ratio = "" if rnd.excess is None else f" (mean square / noise at most {float(np.max(rnd.excess.ratio)):.2f})"
        rnd.verdict = f"nothing significant: the residual is at the noise level{ratio}; {best}"


def _still_outside(rnd: Round, sup: CandidateTest, w: np.ndarray) -> None:
    """Each significant disturbance outside the catalogue tested again on the
    supported candidate's extended residual, beyond the base's columns, every
    probe of the candidate's hypothesis and every channel's gain and offset
    (a second effect left for the next round; evidence.beyond): if one still
    explains a significant part (its own Bonferroni p < ALPHA and dBIC > 0),
    the candidate only took a share of something the catalogue does not
    contain, and is not confirmed."""
    deps = [d for d in rnd.departures if d.counts]
    if not deps:
        return
    try:
        r_e, _ = _S(sup.problem, sup.problem.simulate(sup.x), w)
    except Exception as exc:
        log.warning("%s: extended residual unavailable for the departures: %s", sup.effect, exc)
        return
    # beyond the base and all the effect can do (every probe of its hypothesis: a sensor extension
    # that freed too few channels leaves a gain error that crosstalk from a correlated channel mimics)
    J = list(rnd.attribution.base_columns if rnd.attribution is not None else ()) + list(sup.signature or ())
    J += _sensor_columns(rnd.base_problem, rnd.x_base)   # a second effect, most often a sensor fault
    for d in deps:
        t = beyond(d, r_e, w, J, looks=len(deps))
        d.detail["beyond_candidate"] = None if t is None else {"effect": sup.effect, "T": float(t.T),
                                                               "p_bonferroni": float(t.p_adj), "dbic": float(t.dbic)}
        if t is not None and t.significant and t.dbic > 0:
            sup.supported = False
            sup.why_not.append(f"a disturbance outside the catalogue remains beyond it ({d.label}: Bonferroni p = "
                               f"{t.p_adj:.2g}, dBIC {t.dbic:+.1f} on the extended residual)")
            return


def _sensor_columns(base: Optional[IdentificationProblem], x) -> list:
    """Every channel's gain and offset at the base (no run beyond the base's):
    what a sensor fault can do, tared channels demeaned. Empty when the base
    cannot be simulated."""
    if base is None or x is None:
        return []
    try:
        sim = base.simulate(np.asarray(x, float))
    except Exception as exc:
        log.warning("sensor columns unavailable: %s", exc)
        return []
    demean = np.zeros(sim.shape[1], bool)
    if base.tare is not None:
        demean = np.abs((base.samples - sim).mean(axis=0)) <= base.tare
    out = []
    for j in range(sim.shape[1]):
        for col in (sim[:, j], np.ones(len(sim))):
            g = np.zeros_like(sim)
            g[:, j] = col
            out.append(demean_columns(g, demean))
    return out


def _budget(evals: int, problem: IdentificationProblem, effect: str) -> int:
    """At least one step beyond the initial complex (m + 2 points): an effect
    with many parameters (sensor, per channel) must not end the loop because
    the budget was set for a smaller design."""
    need = len(problem.free) + 3
    if evals < need:
        log.warning("%s: %d evaluations raised to %d (the complex has %d points)", effect, evals, need, need - 1)
    return max(evals, need)


def _evidence(score) -> float:
    """The order in which candidates are tested: the stronger of the share of f
    the linear fit credits beyond what the base parameters could still do, and
    the share removed by the fit through the FMU with the base held. Either
    alone misleads (a missing effect drags the base optimum away; a fit with the
    base held can stand in for base parameters that stopped short); neither
    decides (identification.evidence does)."""
    return max(score.share, score.share_fit or 0.0)


@dataclass
class Fit:
    score: object            # HypothesisScore
    ext: object              # Extension
    problem: IdentificationProblem
    stage1: object           # IdentificationResult of the effect alone


def rescore(base: IdentificationProblem, x: np.ndarray, att: Attribution, f_base: float, *, n: int, evals: int,
            seed: int, out: Optional[Path], number: int) -> tuple:
    """The linear fit ranks; the FMU orders: the top `n` effects are fitted
    through the FMU (their parameters alone, base held at x, `evals`
    evaluations from the linear estimate) and re-ranked by _evidence.
    Returns (fits, dropped): a candidate whose extension cannot be built (bounds
    outside the FMU's range, a degenerate fit) or fitted is dropped with its
    reason, and the next one of the ranking takes its place."""
    fits, dropped = [], []
    for sc in att.ranking:
        if len(fits) >= n:
            break
        try:
            ext = extension_of(sc)
            prob = extended_problem(base, x, ext)
            stage1 = dataclasses.replace(prob, free=tuple(ext.free))
            r = identify(stage1, max_evals=_budget(evals, stage1, sc.effect), seed=seed, progress=False,
                         journal=out / f"round{number}_fit_{sc.effect}.jsonl" if out else None)
        except Exception as exc:
            log.warning("round %d: candidate %s dropped: %s", number, sc.effect, exc)
            dropped.append({"effect": sc.effect, "stage": "fit", "reason": str(exc)[:300]})
            continue
        sc.share_fit = max(0.0, (f_base - r.f) / f_base) if f_base > 0 else 0.0
        fits.append(Fit(sc, ext, prob, r))
    fits.sort(key=lambda f: -_evidence(f.score))
    ranked = [f.score for f in fits]
    att.ranking = ranked + [sc for sc in att.ranking if all(sc is not r for r in ranked)]
    return fits, dropped


def base_from_result(path, problem: IdentificationProblem) -> np.ndarray:
    """The base point of a problem from an earlier identification's result.json (or its folder)."""
    p = Path(path)
    if p.is_dir():
        p = p / "result.json"
    try:
        d = json.loads(p.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"base result {p}: cannot read it ({exc})") from None
    if d.get("model") != problem.model:
        raise ValueError(f"base result {p}: identified with model {d.get('model')}, not {problem.model}")
    xs = d.get("x", {})
    missing = [n for n in problem.free if n not in xs]
    if missing:
        raise ValueError(f"base result {p}: no value for {', '.join(missing)}")
    x = np.array([float(xs[n]) for n in problem.free])
    for n, v in zip(problem.free, x):
        lo, hi = problem.bounds[n]
        if not lo <= v <= hi:
            raise ValueError(f"base result {p}: {n} = {v} lies outside the bounds [{lo}, {hi}]")
    return x


__all__ = ["close_loop", "one_round", "CloseLoopResult", "Round", "localise", "base_from_result"]
