"""The last stage of `make demo`: close the loop on data with an undeclared effect.

The virtual transducer cart records a start-stop of another sorter than the
identification's (recovery measurement 5, layout 2), with out-of-round
driving wheels on the transducer cart (runout, lobes and phases drawn from a
seed by the rig's own draw); the record's metadata declares nothing of it.
The loop runs as `lss close-loop REC --model LW` does
(identification.loop.on_record): the base identified by the front door, refit
to its own optimum, the catalogue ranked, the leading candidates tested
against the noise, the model extended with the one the evidence confirms.
The README shows the verdict with its evidence (the likelihood-ratio
statistic, its p-value before and after the Bonferroni correction, BIC, the
held-out gain, the disturbances outside the catalogue it was weighed
against, what the record cannot reveal), f before and after, and the drawn
truth beside what was found. A second record carries a disturbance outside
the catalogue (crosstalk between two channels, drawn by the rig) on layout
7's release transient: its verdict says so and where. The budgets are
smaller than the defaults (`LOOP_BASE`, `LOOP`) to keep the demo short.
"""
from __future__ import annotations

import math
from pathlib import Path

from identification.loop.settings import LoopSettings
from identification.objective.noise import ALPHA
from identification.pipeline.settings import Settings
from lss_fmu.atomic import write_json_atomic

EFFECT = "wheel_oor"
MEASUREMENT, SECONDS, SEED = 5, 1.2, 6   # layout 2, a start-stop braked at 1 s; the effect's draw (two lobes)
LOOP_BASE = Settings(max_evals=120, refine_evals=80, restarts=0, shrink=False)
LOOP = LoopSettings(max_evals=120, refine_evals=40, base_refine_evals=40, profile_points=5, candidates=3)
OOC, OOC_SEED = "crosstalk", 5


def run_close_loop_stage(out: Path, workers: int = 2) -> list[str]:
    from identification.loop.catalogue import CATALOGUE
    from identification.loop.close_loop import close_loop
    from identification.loop.on_record import close_loop_record
    from identification.loop.synthetic import effect_case
    from lss_fmu import measurement as M
    from lss_fmu.rig import folder_name, load_truth, run_measurement
    from lss_fmu.runner import ChainSimulator

    from .close_loop_report import write_report

    work = out / "close_loop"
    work.mkdir(parents=True, exist_ok=True)
    for old in work.rglob("*.jsonl"):
        old.unlink()  # a demo starts afresh, journals included
    print(f"[4] closing the loop: a start-stop of recovery measurement {MEASUREMENT} with an undeclared effect "
          f"(drawn from seed {SEED}) ...", flush=True)
    data = out / "data_close_loop"
    with ChainSimulator() as sim:
        run_measurement("recovery", MEASUREMENT, data, sim, overwrite=True, protocol="start-stop",
                        lap_seconds=SECONDS, effects=[EFFECT], effect_seed=SEED)
    meas = M.load_measurement(data / folder_name(MEASUREMENT))
    truth = load_truth(meas)["effects"][EFFECT]["parameters"]
    res = close_loop_record(meas, "LW", work, settings=LOOP_BASE, loop_settings=LOOP, rounds=1,
                            workers=workers, progress=True)
    write_json_atomic(work / "result.json", {**res.to_dict(), "undeclared_truth": truth})
    report = write_report(res, work)
    rnd = res.rounds[0]
    print(f"    verdict: {rnd.verdict}", flush=True)
    # a disturbance the catalogue cannot represent
    print(f"[4b] closing the loop on a record with {OOC} (outside the catalogue, seed {OOC_SEED}) ...", flush=True)
    work2 = work / OOC
    work2.mkdir(parents=True, exist_ok=True)
    problem2, _ = effect_case([], OOC_SEED, artefacts=[OOC])
    from lss_fmu import rig_effects
    from lss_fmu.layouts import load_track
    drawn = rig_effects.draw_artefacts([OOC], OOC_SEED, float(load_track("layout7").length))[OOC]
    res2 = close_loop(problem2, rounds=1, settings=LoopSettings(base_evals=80, max_evals=100, refine_evals=40),
                      seed=0, out=work2, progress=True)
    write_json_atomic(work2 / "result.json", {**res2.to_dict(), "undeclared_artefact": drawn})
    report2 = write_report(res2, work2)
    print(f"    verdict: {res2.verdict}", flush=True)
    eff = CATALOGUE[EFFECT]
    true_amp = eff.amplitude(truth, res.problem.samples.mean(axis=0))
    rows = ["| | in the data (undeclared) | found by the loop |", "|---|---|---|",
            f"| effect | {EFFECT} ({eff.title}) | {rnd.effect or 'none'} |",
            f"| amplitude ({eff.unit}) | {true_amp:.4g} | "
            f"{'-' if rnd.amplitude is None else f'{rnd.amplitude:.4g}'} |"]
    for k, v in sorted(truth.items()):
        rows.append(f"| `{k}` | {_show(k, v)} | {_show(k, rnd.identified.get(k))} |")
    f_ext = "-" if rnd.f_extended is None else f"{rnd.f_extended:.4g}"
    return [
        "## Closing the loop\n",
        f"A start-stop of recovery measurement {MEASUREMENT} ({res.problem.layout}, another sorter than the one "
        f"identified above; {SECONDS:g} s) measured with an "
        "effect switched on that the metadata does not declare, closed as `lss close-loop REC --model LW` does "
        f"(smaller budgets: the base {LOOP_BASE.max_evals} complex evaluations without restarts or shorter windows, "
        f"{LOOP.candidates} candidates, {LOOP.max_evals} evaluations each): the base by the front door, refitted "
        f"to its own optimum, attribution over the catalogue of {len(CATALOGUE)} effects, the leading candidates "
        f"tested against the noise, extended identification; {res.seconds:.0f} s in all.\n",
        f"**Verdict ({rnd.outcome}):** {res.verdict}.\n",
        *_evidence(rnd),
        f"Objective f: {rnd.f_base:.4g} with the base model, {f_ext} with the extended one.\n",
        "\n".join(rows) + "\n",
        f"The full report with the residual analysis and overlays: [{report.relative_to(out)}]"
        f"({report.relative_to(out)}).\n",
        f"![attribution](close_loop/round{rnd.number}_attribution.png)\n",
        "### A disturbance outside the catalogue\n",
        f"Layout 7's release transient with {OOC} drawn by the rig ({_drawn(drawn)}); "
        "nothing in the catalogue is switched on.\n",
        f"**Verdict ({res2.outcome}):** {res2.verdict}.\n",
        *_evidence(res2.rounds[0]),
        f"Its report: [{report2.relative_to(out)}]({report2.relative_to(out)}).\n",
    ]


def _drawn(drawn: dict) -> str:
    """The drawn disturbance's parameters, for a sentence."""
    return ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in drawn.items()
                     if k != "description")


def _evidence(rnd) -> list:
    """The tests behind a round's verdict, as a Markdown table."""
    rows = ["| candidate | statistic T (dof) | p | Bonferroni p (m) | dBIC | held-out gain | verdict |",
            "|---|---|---|---|---|---|---|"]
    for t in rnd.tests:
        ho = "-" if t.holdout is None else t.holdout.text()
        rows.append(f"| {t.effect} ({t.label}) | {t.lr.T:.4g} ({t.lr.dof:.2g}) | {t.lr.p:.2g} | "
                    f"{t.lr.p_adj:.2g} ({t.lr.m}) | {t.lr.dbic:+.1f} | {ho} | "
                    f"{t.status} |")
    for d in rnd.departures:
        rows.append(f"| outside: {d.family}, {d.label} | {d.test.T:.4g} ({d.test.dof:.2g}) | {d.test.p:.2g} | "
                    f"{d.test.p_adj:.2g} ({d.test.m}) | {d.test.dbic:+.1f} | - | - |")
    noise = rnd.noise.source if rnd.noise is not None else "-"
    return [f"The evidence (noise {noise}; confirmed when the Bonferroni p < {ALPHA:g}, dBIC > 0, held-out gain "
            f"> 0 and no disturbance outside the catalogue does better):\n", "\n".join(rows) + "\n"]


def _show(name: str, value) -> str:
    """A table cell: '-' for a value not identified, phases in [0, 2 pi)."""
    if value is None:
        return "-"
    if "phase" in name:
        value = math.fmod(float(value), 2 * math.pi) % (2 * math.pi)
    return f"{value:.4g}"
