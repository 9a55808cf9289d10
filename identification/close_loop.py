"""Close the loop (issue 7): residual -> missing effect -> extended model.

One round: at the base optimum, analyse the residual (identification.residual),
score every effect of the catalogue by the share of the objective it explains
beyond the base parameters (identification.attribution), and if the best one
explains a significant share, switch it on, add its parameters to the design
vector and identify again from the previous optimum (identification.extension).
The round is *confirmed* when the extended identification lowers f by at
least CONFIRM; a second round starts from the extended model.

From the command line: `lss close-loop` (lss_app.cmd_close_loop). Every
identification keeps a journal in DIR, the attribution of each round is
written atomically once done: a run killed at any point resumes where it was.
"""
from __future__ import annotations

import dataclasses
import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from lss_fmu.atomic import write_json_atomic
from lss_fmu.variables import FORCE_CHANNELS

from .attribution import Attribution, attribute, simulate_with
from .catalogue import CATALOGUE, Context
from .extension import extended_problem, extension_of
from .identify import identify
from .problem import IdentificationProblem, nrmsd, tared
from .refine import refine

log = logging.getLogger(__name__)

SHARE_MIN = 0.25     # an effect must explain this share of f (beyond the base parameters) ...
CONFIRM = 0.25       # ... and the extended identification must lower f by this share
LOCAL_SHARE = 0.5    # unexplained residual 'concentrates' if half of it sits in ...
LOCAL_WINDOW = 0.1   # ... this fraction of the record (or 0.1 s, whichever is longer) of one channel
RESCORE = 3          # effects fitted through the FMU after the linear ranking ...
RESCORE_EVALS = 20   # ... with this many evaluations each
REFINE_EVALS = 80    # simulations of the local refinement (identification.refine) ending each extension
SIGNALS = ["transducer.s", "transducer.v", "transducer.joint.v_axial"]


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

    def to_dict(self) -> dict:
        chans = FORCE_CHANNELS
        return {
            "round": self.number, "verdict": self.verdict, "effect": self.effect, "confirmed": self.confirmed,
            "f_base": self.f_base, "nrmsd_base": dict(zip(chans, map(float, self.H_base))),
            "f_extended": self.f_extended,
            "nrmsd_extended": None if self.H_extended is None else dict(zip(chans, map(float, self.H_extended))),
            "identified": self.identified, "amplitude": self.amplitude, "location": self.location,
            "refined": self.refined,
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

    def to_dict(self) -> dict:
        return {"measurement": self.problem.name, "model": self.problem.model, "layout": self.problem.layout,
                "found": self.found, "verdict": self.verdict, "seconds": self.seconds,
                "rounds": [r.to_dict() for r in self.rounds]}


def context(problem: IdentificationProblem, x: np.ndarray, sensor_offset_std: Optional[dict] = None) -> Context:
    """What the catalogue needs; `sensor_offset_std` (N per force channel) is the
    transducer's declared zero tolerance (meta.json 'sensor'), by default the
    virtual transducer cart's."""
    from lss_fmu.layouts import load_track
    tr = load_track(problem.layout)
    vals = problem.values(x)
    v = float(vals.get("drive.v_ref", problem.fixed.get("drive.v_ref", 2.0)))
    s0 = float(vals.get("trigger.s_M", 0.0))
    ctx = Context(problem.layout, float(tr.length), np.asarray(tr.s0, float),
                  (s0, s0 + v * float(problem.times[-1])), int(tr.n_carts), v)
    if sensor_offset_std:
        ctx.sensor_offset_tol = 3.0 * np.array([float(sensor_offset_std[c]) for c in FORCE_CHANNELS])
    elif problem.tare is not None:
        ctx.sensor_offset_tol = np.asarray(problem.tare, float)
    return ctx


def localise(problem: IdentificationProblem, r: np.ndarray, s: Optional[np.ndarray] = None) -> dict:
    """Where the residual concentrates: the channel with the largest share of
    f, and the shortest stretch of the record holding LOCAL_SHARE of it."""
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


def analyse(problem: IdentificationProblem, x: np.ndarray, sim: np.ndarray):
    """The residual analysis at x (None if the module or the layout lacks what it needs)."""
    from lss_fmu.layouts import load_track
    try:
        from .residual import analyse_residual
    except ImportError:
        return None, None
    sig = _signals(problem, x)
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
               fit_evals: int = RESCORE_EVALS, refine_evals: int = REFINE_EVALS) -> CloseLoopResult:
    """The loop on one problem: base identification (unless x_base is given),
    then up to `rounds` rounds of analysis, attribution and extension.
    `sensor_offset_std`: the transducer's declared zero tolerance per force
    channel (N); offsets and gains within 3 sigma of it are not faults."""
    t0 = time.time()
    out = Path(out) if out else None
    if out:
        out.mkdir(parents=True, exist_ok=True)
    if x_base is None:
        res = identify(problem, max_evals=base_evals, seed=seed, progress=progress, workers=workers,
                       journal=out / "base_journal.jsonl" if out else None)
        x_base = res.x
    x = np.asarray(x_base, float)
    base, done, result_rounds = problem, [], []
    remaining = list(effects or CATALOGUE)
    for k in range(1, rounds + 1):
        rnd = one_round(base, x, k, remaining, max_evals=max_evals, seed=seed + k, out=out, progress=progress,
                        workers=workers, sensor_offset_std=sensor_offset_std, fit_evals=fit_evals,
                        refine_evals=refine_evals)
        result_rounds.append(rnd)
        if not rnd.confirmed:
            break
        remaining.remove(rnd.effect)
        # the next round's base is the extended model, the found effect still free: a second
        # effect in the data distorts the first one's fit, and with its parameters in the base
        # Jacobian the attribution scores the next effect beyond what refitting it could do;
        # the next extension then identifies both together
        base = dataclasses.replace(rnd.problem_extended, x0=rnd.problem_extended.values(rnd.x_extended))
        x = np.asarray(rnd.x_extended, float)
        done.append(rnd.effect)
    return CloseLoopResult(problem, np.asarray(x_base, float), result_rounds, time.time() - t0)


def one_round(base: IdentificationProblem, x: np.ndarray, number: int, effects: Sequence[str], *,
              max_evals: int, seed: int, out: Optional[Path], progress: bool, workers: int = 1,
              sensor_offset_std: Optional[dict] = None, fit_evals: int = RESCORE_EVALS,
              refine_evals: int = REFINE_EVALS) -> Round:
    sim = base.simulate(x)
    H = nrmsd(base.samples, sim, base.tare)
    f_base = float(np.sum(H ** 2))
    ra, s = analyse(base, x, sim)
    ctx = context(base, x, sensor_offset_std)
    cache = out / f"round{number}_attribution.json" if out else None
    att = attribute(base, x, ctx, effects=effects, progress=progress)
    if cache:
        write_json_atomic(cache, att.to_dict())
    rnd = Round(number, f_base, H, att, "", x_base=x, residual=ra, base_problem=base)
    fits = rescore(base, x, att, f_base, n=RESCORE, evals=fit_evals, seed=seed, out=out, number=number)
    if cache:
        write_json_atomic(cache, att.to_dict())
    best = fits[0] if fits else None
    if best is None or _evidence(best.score) < SHARE_MIN:
        loc = localise(base, tared(base.samples - sim, base.tare), s)
        rnd.location = loc
        share = 0.0 if best is None else _evidence(best.score)
        name = best.score.effect if best else "-"
        if loc["concentrated"]:
            where = f"t = {loc['t_start']:.2f}-{loc['t_end']:.2f} s"
            if "s_start" in loc:
                where += f", track s = {loc['s_start']:.2f}-{loc['s_end']:.2f} m"
            rnd.verdict = (f"no effect in the catalogue explains the residual (best: {name}, {100 * share:.0f}% "
                           f"of f); it concentrates in {loc['channel']} ({100 * loc['channel_share']:.0f}% of f) at "
                           f"{where} ({100 * loc['window_share']:.0f}% of that channel's residual)")
        else:
            rnd.verdict = (f"nothing significant: no effect in the catalogue explains more than "
                           f"{100 * share:.0f}% of f (best: {name}; threshold {100 * SHARE_MIN:.0f}%), and the "
                           f"residual does not concentrate in one place")
        return rnd
    sc, ext, prob_ext = best.score, best.ext, best.problem
    x0 = {**prob_ext.x0, **best.stage1.problem.values(best.stage1.x)}
    stage2 = dataclasses.replace(prob_ext, x0=x0)
    res = identify(stage2, max_evals=_budget(max_evals, stage2, sc.effect), seed=seed + 1, progress=progress,
                   workers=workers,
                   journal=out / f"round{number}_journal.jsonl" if out else None)
    rnd.effect, rnd.problem_extended, rnd.x_extended = sc.effect, stage2, np.asarray(res.x)
    rnd.f_extended = float(min(res.f, best.stage1.f))
    if best.stage1.f < res.f:  # the joint run did not beat the effect-only fit: keep that
        rnd.x_extended = np.array([x0[n] for n in stage2.free])
        rnd.H_extended = best.stage1.H
    else:
        rnd.H_extended = res.H
    if refine_evals > 0:
        # the complex contracts onto a ridge before the minimum (docs/complex_rf.md); this point
        # is the next round's base, and what it leaves unexplained is the denominator of every
        # share there: a local refinement walks the rest of the way (identification.refine)
        ref = refine(stage2, rnd.x_extended, max_evals=refine_evals)
        rnd.refined = {"f_start": ref.f_start, "f": ref.f, "nfev": ref.nfev, "iterations": ref.iterations}
        if ref.f < rnd.f_extended:
            rnd.x_extended, rnd.f_extended = ref.x, ref.f
            rnd.H_extended = nrmsd(stage2.samples, ref.sim, stage2.tare)
    vals = stage2.values(rnd.x_extended)
    rnd.identified = {n: float(vals[n]) for n in ext.free}
    rnd.identified.update({n: v for n, v in ext.fixed.items()})
    rnd.amplitude = CATALOGUE[sc.effect].amplitude(vals, base.samples.mean(axis=0))
    rnd.confirmed = rnd.f_extended <= (1.0 - CONFIRM) * f_base
    eff = CATALOGUE[sc.effect]
    if rnd.confirmed:
        rnd.verdict = (f"{eff.title} ({sc.effect}, {sc.label}) explains {100 * _evidence(sc):.0f}% of f; "
                       f"with it the identification lowers f from {f_base:.4g} to {rnd.f_extended:.4g}")
    else:
        rnd.verdict = (f"nothing significant: {sc.effect} explained {100 * _evidence(sc):.0f}% of f, but the "
                       f"extended identification only lowers f from {f_base:.4g} to "
                       f"{rnd.f_extended:.4g} (less than {100 * CONFIRM:.0f}%)")
    return rnd


def _budget(evals: int, problem: IdentificationProblem, effect: str) -> int:
    """At least one step beyond the initial complex (m + 2 points): an effect
    with many parameters (sensor, per channel) must not end the loop because
    the budget was set for a smaller design."""
    need = len(problem.free) + 3
    if evals < need:
        log.warning("%s: %d evaluations raised to %d (the complex has %d points)", effect, evals, need, need - 1)
    return max(evals, need)


def _evidence(score) -> float:
    """The share of f an effect explains, the stronger of two estimates: the
    linear fit beyond what the base parameters could still do, and the fit
    through the FMU with the base held. Either alone misleads: a missing effect
    drags the base optimum away (mass: the CoRs onto their bounds), which the
    held base cannot undo, and a fit with the base held can stand in for base
    parameters that stopped short (noise-level data). The extended
    identification then confirms or rejects (CONFIRM)."""
    return max(score.share, score.share_fit or 0.0)


@dataclass
class Fit:
    score: object            # HypothesisScore
    ext: object              # Extension
    problem: IdentificationProblem
    stage1: object           # IdentificationResult of the effect alone


def rescore(base: IdentificationProblem, x: np.ndarray, att: Attribution, f_base: float, *, n: int, evals: int,
            seed: int, out: Optional[Path], number: int) -> list:
    """The linear fit ranks; the FMU decides: the top `n` effects are fitted
    through the FMU (their parameters alone, base held at x, `evals`
    evaluations from the linear estimate) and re-ranked by their evidence
    (_evidence: the stronger of the linear and the fitted share). Contacts that open and close make the response to an effect
    rough, so a linear share can be far off either way."""
    fits = []
    for sc in att.ranking[:n]:
        ext = extension_of(sc)
        prob = extended_problem(base, x, ext)
        stage1 = dataclasses.replace(prob, free=tuple(ext.free))
        r = identify(stage1, max_evals=_budget(evals, stage1, sc.effect), seed=seed, progress=False,
                     journal=out / f"round{number}_fit_{sc.effect}.jsonl" if out else None)
        sc.share_fit = max(0.0, (f_base - r.f) / f_base) if f_base > 0 else 0.0
        fits.append(Fit(sc, ext, prob, r))
    fits.sort(key=lambda f: -_evidence(f.score))
    att.ranking = [f.score for f in fits] + att.ranking[len(fits):]
    return fits


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
