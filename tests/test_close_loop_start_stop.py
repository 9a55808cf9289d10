"""The closed loop end to end on the record a sorter makes: a start-stop from
the virtual transducer cart, `lss close-loop`'s path (the base by the front
door, then the loop; identification.loop.on_record), with an effect the
metadata does not declare, and without one. The budgets are smaller than the
defaults (a base of 120 complex evaluations, no restarts, no shorter windows;
3 candidates) to keep the case short; the effect is the rig's own draw."""
from __future__ import annotations

import pytest

from identification.loop.on_record import close_loop_record
from identification.loop.settings import LoopSettings
from identification.pipeline.settings import Settings
from lss_fmu import measurement as M
from lss_fmu.rig import folder_name, load_truth, run_measurement

NUMBER, SECONDS = 20, 1.2   # layout 7: started from rest, braked at 1 s
EFFECT_SEED = 11            # the rig draws two lobes of runout on the transducer cart's driving wheels
BASE = Settings(max_evals=120, refine_evals=80, restarts=0, shrink=False)
LOOP = LoopSettings(max_evals=120, refine_evals=40, base_refine_evals=40, profile_points=5, candidates=3)


def _record(folder, effects=()):
    from lss_fmu.runner import ChainSimulator
    with ChainSimulator() as s:
        run_measurement("recovery", NUMBER, folder, s, protocol="start-stop", lap_seconds=SECONDS,
                        effects=list(effects), effect_seed=EFFECT_SEED if effects else None)
    return M.load_measurement(folder / folder_name(NUMBER))


@pytest.fixture(scope="module")
def with_runout(tmp_path_factory, fmu_file):
    return _record(tmp_path_factory.mktemp("ss_runout"), ["wheel_oor"])


@pytest.fixture(scope="module")
def clean(tmp_path_factory, fmu_file):
    return _record(tmp_path_factory.mktemp("ss_clean"))


def test_an_undeclared_runout_is_found_on_a_start_stop(with_runout, tmp_path):
    truth = load_truth(with_runout)["effects"]["wheel_oor"]["parameters"]
    res = close_loop_record(with_runout, "LW", tmp_path, settings=BASE, loop_settings=LOOP, rounds=1)
    rnd = res.rounds[0]
    assert res.found == ["wheel_oor"], rnd.verdict
    assert rnd.identified["effects.wheel_oor.order"] == truth["effects.wheel_oor.order"]
    amp, true_amp = rnd.identified["effects.wheel_oor.amplitude"], truth["effects.wheel_oor.amplitude"]
    assert abs(amp / true_amp - 1) < 0.1, (amp, true_amp)
    assert rnd.f_extended < 0.7 * rnd.f_base
    assert (tmp_path / "base" / "result.json").is_file() and (tmp_path / "result.json").is_file()
    # what the record can reveal (identification.loop.reach): an effect it confirmed is not below the
    # smallest size it reveals in the most favourable phase
    order = str(int(truth["effects.wheel_oor.order"]))
    lobes = next(r for r in rnd.reach if r.effect == "wheel_oor" and r.kind.startswith(order))
    assert lobes.best <= amp, (lobes.best, amp)


def test_a_clean_start_stop_confirms_nothing(clean, tmp_path):
    res = close_loop_record(clean, "LW", tmp_path, settings=BASE, loop_settings=LOOP, rounds=1)
    assert res.found == [], res.verdict
    unseen = [r for r in res.rounds[0].reach if not r.visible]
    assert ("cannot reveal" in res.verdict) == bool(unseen), res.verdict


def test_a_bad_noise_choice_is_refused_before_anything_runs(clean, tmp_path):
    with pytest.raises(ValueError, match="noise 'guess'"):
        close_loop_record(clean, "LW", tmp_path, noise="guess")
    assert not (tmp_path / "base").exists()
