"""System test (issue 9): LSSChain.fmu coupled to a second FMU that this test
builds, a speed-profile FMU (tests/c/speed_profile_fmu.c, compiled with gcc
against fmpy's FMI headers), whose output v_ref drives the chain's input
drive.v_ref: a step from 2.0 to 1.5 m/s at t = 0.3 s.

The coupled system runs
- as an SSP (SystemStructure.ssd + both FMUs) through fmpy's SSP support
  (fmpy.ssp.simulation.simulate_ssp), and
- as a container FMU made with fmpy (fmpy.container_fmu, the successor of
  fmpy.fmucontainer), simulated with fmpy.simulate_fmu.

In both, the chain follows the commanded speed: it runs at 2 m/s, then slows
towards 1.5 m/s after the step, as the same profile applied directly through
ChainSimulator does."""
from __future__ import annotations

import shutil
import subprocess
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.validation import validate_fmu

from lss_fmu import build
from lss_fmu.runner import ChainSimulator

HERE = Path(__file__).parent
STOP, H, T_STEP, V0, V1 = 1.5, 0.01, 0.3, 2.0, 1.5

PROFILE_XML = textwrap.dedent("""\
    <?xml version="1.0" encoding="UTF-8"?>
    <fmiModelDescription fmiVersion="2.0" modelName="SpeedProfile"
      guid="{8c4e810f-3df3-4a00-8276-176fa3c9f001}" description="speed step for the chain"
      generationTool="tests/test_cosimulation.py" variableNamingConvention="flat" numberOfEventIndicators="0">
      <CoSimulation modelIdentifier="SpeedProfile" canHandleVariableCommunicationStepSize="true"/>
      <UnitDefinitions>
        <Unit name="m/s"><BaseUnit m="1" s="-1"/></Unit>
        <Unit name="s"><BaseUnit s="1"/></Unit>
      </UnitDefinitions>
      <DefaultExperiment startTime="0" stopTime="1.5" stepSize="0.01"/>
      <ModelVariables>
        <ScalarVariable name="v0" valueReference="1" causality="parameter" variability="fixed" initial="exact">
          <Real unit="m/s" start="2.0"/></ScalarVariable>
        <ScalarVariable name="v1" valueReference="2" causality="parameter" variability="fixed" initial="exact">
          <Real unit="m/s" start="1.5"/></ScalarVariable>
        <ScalarVariable name="t_step" valueReference="3" causality="parameter" variability="fixed" initial="exact">
          <Real unit="s" start="0.3"/></ScalarVariable>
        <ScalarVariable name="v_ref" valueReference="4" causality="output" variability="discrete" initial="calculated">
          <Real unit="m/s"/></ScalarVariable>
      </ModelVariables>
      <ModelStructure>
        <Outputs><Unknown index="4"/></Outputs>
        <InitialUnknowns><Unknown index="4"/></InitialUnknowns>
      </ModelStructure>
    </fmiModelDescription>
    """)


@pytest.fixture(scope="module")
def fmus(tmp_path_factory, fmu_file):
    """(SpeedProfile.fmu, LSSChain.fmu) in a fresh directory."""
    if shutil.which("gcc") is None:
        pytest.skip("no gcc to build the speed-profile FMU")
    d = tmp_path_factory.mktemp("cosim")
    lib = d / ("SpeedProfile" + build.shared_suffix())
    cmd = ["gcc", "-std=c11", "-O1", "-fPIC", "-shared", "-Wall", "-Wextra", "-Werror",
           "-I", str(build.fmi_headers()), "-o", str(lib), str(HERE / "c" / "speed_profile_fmu.c")]
    res = subprocess.run(cmd, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    profile = d / "SpeedProfile.fmu"
    with zipfile.ZipFile(profile, "w") as z:
        z.writestr("modelDescription.xml", PROFILE_XML)
        z.write(lib, f"binaries/{build.platform_dir()}/{lib.name}")
        z.write(HERE / "c" / "speed_profile_fmu.c", "sources/speed_profile_fmu.c")
    chain = d / "LSSChain.fmu"
    shutil.copy(fmu_file, chain)
    return profile, chain


@pytest.fixture(scope="module")
def reference():
    """The same profile applied directly (input changed at each communication
    point to the profile's value at that point), through ChainSimulator."""
    def on_step(sim, t):
        sim.set("drive.v_ref", V1 if t >= T_STEP - 1e-12 else V0)
    with ChainSimulator() as sim:
        df = sim.simulate(STOP, H, outputs=["chain.v_mean"], on_step=on_step)
    return df["time"].to_numpy(), df["chain.v_mean"].to_numpy()


def check_follows(t, v_ref, v_mean, reference):
    """The coupled signals make sense: the command is the profile, the chain
    runs at V0 before the step and slows towards V1 after it."""
    assert np.all(np.isfinite(v_mean)) and len(t) >= int(STOP / H) - 1
    after = t > T_STEP + 2 * H
    assert np.allclose(v_ref[after], V1) and np.allclose(v_ref[(t > 2 * H) & (t < T_STEP - 2 * H)], V0)
    before = (t > 0.05) & (t < T_STEP)
    assert np.all(np.abs(v_mean[before] - V0) < 0.06)
    late = t > STOP - 0.2
    assert np.all(np.abs(v_mean[late] - V1) < 0.1)           # close to the new command ...
    assert v_mean[late].mean() < v_mean[before].mean() - 0.35  # ... and far from the old one
    # as the direct run (the coupling adds at most one communication step of delay)
    t_ref, v_ref_mean = reference
    interp = np.interp(t, t_ref, v_ref_mean)
    assert np.max(np.abs(v_mean[t > 0.05] - interp[t > 0.05])) < 0.03


def test_speed_profile_fmu_is_valid(fmus):
    profile, _ = fmus
    assert validate_fmu(str(profile)) == []
    res = simulate_fmu(str(profile), stop_time=0.5, output_interval=0.1)
    assert np.allclose(res["v_ref"], [2.0, 2.0, 2.0, 1.5, 1.5, 1.5])


SSD = textwrap.dedent("""\
    <?xml version="1.0" encoding="UTF-8"?>
    <ssd:SystemStructureDescription xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
        xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" version="1.0" name="ChainWithProfile">
      <ssd:System name="Plant">
        <ssd:Connectors>
          <ssd:Connector name="v_mean" kind="output"><ssc:Real unit="m/s"/></ssd:Connector>
        </ssd:Connectors>
        <ssd:Elements>
          <ssd:Component name="profile" source="resources/SpeedProfile.fmu" type="application/x-fmu-sharedlibrary">
            <ssd:Connectors>
              <ssd:Connector name="v_ref" kind="output"><ssc:Real unit="m/s"/></ssd:Connector>
            </ssd:Connectors>
          </ssd:Component>
          <ssd:Component name="chain" source="resources/LSSChain.fmu" type="application/x-fmu-sharedlibrary">
            <ssd:Connectors>
              <ssd:Connector name="drive.v_ref" kind="input"><ssc:Real unit="m/s"/></ssd:Connector>
              <ssd:Connector name="chain.v_mean" kind="output"><ssc:Real unit="m/s"/></ssd:Connector>
            </ssd:Connectors>
          </ssd:Component>
        </ssd:Elements>
        <ssd:Connections>
          <ssd:Connection startElement="profile" startConnector="v_ref" endElement="chain" endConnector="drive.v_ref"/>
          <ssd:Connection startElement="chain" startConnector="chain.v_mean" endConnector="v_mean"/>
        </ssd:Connections>
      </ssd:System>
    </ssd:SystemStructureDescription>
    """)


def test_ssp_with_fmpy(fmus, reference, tmp_path):
    from fmpy.ssp.simulation import simulate_ssp
    profile, chain = fmus
    ssp = tmp_path / "ChainWithProfile.ssp"
    with zipfile.ZipFile(ssp, "w") as z:
        z.writestr("SystemStructure.ssd", SSD)
        z.write(profile, "resources/SpeedProfile.fmu")
        z.write(chain, "resources/LSSChain.fmu")
    res = simulate_ssp(str(ssp), stop_time=STOP, step_size=H)
    names = res.dtype.names
    col = {n.split(".", 1)[1] if n.startswith("Plant.") else n: n for n in names}
    t = res["time"] + H  # simulate_ssp records each step's outputs at the step's start time
    v_ref = res[col["profile.v_ref"]]
    v_mean = res[col["chain.chain.v_mean"]]
    assert np.array_equal(v_mean, res[col["v_mean"]])  # the system's own output connector
    check_follows(t, v_ref, v_mean, reference)


def test_container_fmu_with_fmpy(fmus, reference, tmp_path):
    from attrs import evolve
    from fmpy.container_fmu.cli import create_container_fmu
    from fmpy.container_fmu.config import Component, Configuration, Connection
    from fmpy.model_description import CoSimulation, DefaultExperiment, ModelDescription, ModelVariable
    profile, chain = fmus
    md_p, md_c = read_model_description(str(profile)), read_model_description(str(chain))
    vp = {v.name: v for v in md_p.modelVariables}
    vc = {v.name: v for v in md_c.modelVariables}
    out_v_ref = ModelVariable(type="Real", variability="discrete", causality="output", initial="calculated",
                              name="v_ref", description="commanded speed")
    out_v_mean = ModelVariable(type="Real", variability="continuous", causality="output", initial="calculated",
                               name="v_mean", description="mean chain speed")
    out_force = ModelVariable(type="Real", variability="continuous", causality="output", initial="calculated",
                              name="F_total", description="total motor thrust")
    par_step = ModelVariable(type="Real", variability="fixed", causality="parameter", initial="exact",
                             name="t_step", start=str(T_STEP), description="time of the speed step")
    md = ModelDescription(
        fmiVersion="2.0", modelName="ChainWithProfile", instantiationToken="{5f0c2d2e-95a4-4c44-9a56-3f0e4b3f6a10}",
        description="LSSChain driven by a speed profile", defaultExperiment=DefaultExperiment(stopTime=str(STOP),
                                                                                            stepSize=str(H)),
        coSimulation=CoSimulation(fixedInternalStepSize=H),
        # value reference 0 is the container's time (as in fmpy's own container tests);
        # the mapped variables follow in the order of variableMappings
        modelVariables=[ModelVariable(type="Real", variability="continuous", causality="independent", name="time"),
                        out_v_ref, out_v_mean, out_force, par_step])
    comp_p = Component(name="profile", filename=profile, modelDescription=md_p)
    comp_c = Component(name="chain", filename=chain, modelDescription=md_c)
    # fmpy 0.3.32 writes a connection's FMI 2 type ("Real") into container.json,
    # which its container binary does not accept; it wants the FMI 3 name
    # (write_configuration converts the type for variables, not for connections)
    src, dst = (evolve(v, type="Float64") for v in (vp["v_ref"], vc["drive.v_ref"]))
    config = Configuration(
        parallelDoStep=False, modelDescription=md, components=[comp_p, comp_c],
        connections=[Connection(comp_p, [src], comp_c, [dst])],
        variableMappings={out_v_ref: [(comp_p, vp["v_ref"])], out_v_mean: [(comp_c, vc["chain.v_mean"])],
                          out_force: [(comp_c, vc["drive.F_total"])], par_step: [(comp_p, vp["t_step"])]})
    work = tmp_path / "container"
    work.mkdir()
    container = tmp_path / "ChainWithProfile.fmu"
    create_container_fmu(config, work, container)
    res = simulate_fmu(str(container), stop_time=STOP, output_interval=H)
    check_follows(res["time"], res["v_ref"], res["v_mean"], reference)
    assert np.all(np.isfinite(res["F_total"]))
    # the container's parameter reaches the nested profile FMU
    later = simulate_fmu(str(container), stop_time=0.6, output_interval=H, start_values={"t_step": 0.5})
    t = later["time"]
    assert np.allclose(later["v_ref"][(t > 0.05) & (t < 0.48)], V0)
    assert np.allclose(later["v_ref"][t > 0.52], V1)
