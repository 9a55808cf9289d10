"""A survey of a sorter (lss_fmu.survey) given to the FMU in place of the
design drawing: the file and its errors, the rig's survey of the field set,
and what it changes for identification (the surveyed condition of a
campaign)."""
from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from identification.pipeline.campaign import CampaignError, run_campaign
from identification.pipeline.driver import build_problem
from identification.pipeline.settings import Settings
from lss_fmu import rig
from lss_fmu.measurement import load_measurement
from lss_fmu.survey import SurveyError, load_survey, survey_path

SECONDS = 1.5   # s of each record: the braking at 1 s inside it


@pytest.fixture(scope="module")
def field(tmp_path_factory, fmu_file):
    """One start-stop of the field set on its shortest chain (layout 7: as-built
    track, mass spread, guide gap; GZ contacts)."""
    number = next(n for n in range(1, 23) if rig.make_case("field", n).layout == "layout7")
    out = tmp_path_factory.mktemp("field")
    res = rig.generate_set("field", out, [number], workers=1, fmu=fmu_file, lap_seconds=SECONDS, progress=False,
                           protocol="start-stop", log=lambda *_: None)
    assert "error" not in res[0], res[0]
    return out / rig.folder_name(number)


def test_the_rig_writes_what_a_survey_of_the_field_sorter_gives(field):
    truth = rig.load_truth(field)
    dev = truth["field_deviations"]
    s = load_survey(survey_path(field))
    assert s["cart.mass_factor"] == dev["cart.mass_factor"] and s["track.guide_gap"] == dev["track.guide_gap"]
    # the as-built track, a copy beside the survey: nothing of the answers folder is referred to
    assert "answers" not in s["layout.name"]
    assert open(s["layout.name"]).read() == (field.parent / dev["as_built_file"]).read_text()


def test_the_survey_brings_the_model_to_the_noise_on_the_field_set(field):
    """At the true design values and the true law, the survey given, only the
    noise is left (about 7 per record); on the design drawing the model is off
    the record (on this layout-7 sorter about 75 times the noise; 1.06 times
    on a layout-1 one, 66 times on a layout-5 one)."""
    meas = load_measurement(field)
    truth = rig.true_design_values(rig.load_truth(field))
    settings = Settings(window=SECONDS)
    f = {}
    for name, survey in (("design", None), ("surveyed", load_survey(survey_path(field)))):
        p = build_problem([meas], "GZ", settings, survey=survey)
        f[name] = p(np.array([truth[n] for n in p.free]))
    assert f["surveyed"] < 10.0 and f["design"] > 3 * f["surveyed"], f


@pytest.mark.parametrize("content, message", [
    ({"track.gap": 0.001}, "unknown key 'track.gap'"),
    ({"cart.mass_factor": "heavy"}, "cart.mass_factor = 'heavy': must be a number"),
    ({"cart.mass_factor": 50.0}, "outside the FMU's range"),
    ({"track": "tracks/none.layout"}, "no such file"),
    ([1, 2], "a JSON object"),
])
def test_a_bad_survey_is_refused_naming_the_file_and_the_key(tmp_path, content, message):
    path = tmp_path / "survey.json"
    path.write_text(json.dumps(content))
    with pytest.raises(SurveyError, match=message) as err:
        load_survey(path)
    assert str(path) in str(err.value)


def test_a_surveyed_campaign_checks_every_survey_and_keeps_its_condition(field, tmp_path):
    """A record without a survey is refused before anything runs; a campaign
    begun on the design drawing does not resume with the survey."""
    lonely = tmp_path / "data"
    lonely.mkdir()
    shutil.copytree(field, lonely / field.name)
    with pytest.raises(CampaignError, match="no survey file"):
        run_campaign([lonely], ["GZ"], tmp_path / "c0", surveyed=True, progress=False)
    out = tmp_path / "c1"
    (out / "results").mkdir(parents=True)
    (out / "results" / f"{field.name}_GZ.json").write_text("{}")   # finished: nothing runs
    run_campaign([field.parent], ["GZ"], out, progress=False)
    assert json.loads((out / "campaign.json").read_text())["surveyed"] is False
    with pytest.raises(CampaignError, match="began on the design drawing, now with --surveyed"):
        run_campaign([field.parent], ["GZ"], out, surveyed=True, progress=False)
