#!/usr/bin/env python3
"""A sorter system made of FMUs: LSSChain (the chain), SorterDrive (speed
controller and motors: the thrust of every motor) and Induction (items put
on carts at an induction station, taken off at a chute), coupled as an SSP
(SystemStructure.ssd with the parameters in an SSV file) and run by two
masters nobody here wrote: fmpy's SSP support and libcosim (libcosimpy).

    .venv/bin/python examples/plant/plant_system.py --out build/plant [--stop 6] [--layout layout7]

builds SorterDrive.fmu and Induction.fmu (gcc against fmpy's FMI headers),
writes SorterPlant.ssp next to them with LSSChain.fmu, runs it in both
masters and writes plant.png (chain speed and set point, motor thrust,
largest joint force, items on board) and plant.csv. docs/plant.md explains
how to put LSSChain into your own system model the same way.
"""
from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1]))

from lss_fmu import build  # noqa: E402

# name -> (guid, source, variables: (name, vr, type, causality, variability, unit, start, description))
PLANT_FMUS = {
    "SorterDrive": ("{6a3f0e52-3c1b-4f7e-9a0e-51d0c2b7e801}", "sorter_drive.c", [
        ("v_set", 1, "Real", "parameter", "fixed", "m/s", 1.5, "chain speed set point"),
        ("t_ramp", 2, "Real", "parameter", "fixed", "s", 0.5, "the set point ramps up from 0 over this time"),
        ("Kp", 3, "Real", "parameter", "fixed", "N.s/m", 2000.0, "proportional gain, per motor"),
        ("Ki", 4, "Real", "parameter", "fixed", "N/m", 1000.0, "integral gain, per motor"),
        ("tau", 5, "Real", "parameter", "fixed", "s", 0.02, "time constant of the motors' thrust"),
        ("F_max", 6, "Real", "parameter", "fixed", "N", 400.0, "rating of one motor"),
        ("v", 7, "Real", "input", "continuous", "m/s", 0.0, "chain speed"),
        ("F", 8, "Real", "output", "continuous", "N", None, "thrust of each motor"),
        ("v_ref", 9, "Real", "output", "continuous", "m/s", None, "the ramped set point"),
    ]),
    "Induction": ("{0d9c3e7a-8b21-4c55-b1f4-7e2a6c9d4b02}", "induction.c", [
        ("rate", 1, "Real", "parameter", "fixed", "1/s", 2.0, "items per second at most"),
        ("mass", 2, "Real", "parameter", "fixed", "kg", 10.0, "mass of one item"),
        ("t_first", 3, "Real", "parameter", "fixed", "s", 0.5, "no item before this time"),
        ("put_mass", 4, "Real", "output", "discrete", "kg", None, "mass put on put_cart"),
        ("take_mass", 5, "Real", "output", "discrete", "kg", None, "mass left on take_cart (0)"),
        ("cart_in", 7, "Integer", "input", "discrete", None, 0, "the cart at the induction"),
        ("cart_out", 8, "Integer", "input", "discrete", None, 0, "the cart at the chute"),
        ("put_cart", 9, "Integer", "output", "discrete", None, None, "the cart an item was put on (-1: none)"),
        ("take_cart", 10, "Integer", "output", "discrete", None, None, "the cart an item was taken off (-1: none)"),
        ("n_items", 11, "Integer", "output", "discrete", None, None, "items on board"),
        ("n_put", 12, "Integer", "output", "discrete", None, None, "items put on so far"),
        ("n_taken", 13, "Integer", "output", "discrete", None, None, "items taken off so far"),
    ]),
}

# (from component, connector, to component, connector, type)
CONNECTIONS = [
    ("chain", "chain.v_mean", "drive", "v", "Real"),
    ("drive", "F", "chain", "drive.group1.F", "Real"),
    ("drive", "F", "chain", "drive.group2.F", "Real"),
    ("chain", "station.induction.cart", "induction", "cart_in", "Integer"),
    ("chain", "station.chute.cart", "induction", "cart_out", "Integer"),
    ("induction", "put_cart", "chain", "load1.cart", "Integer"),
    ("induction", "put_mass", "chain", "load1.mass", "Real"),
    ("induction", "take_cart", "chain", "load2.cart", "Integer"),
    ("induction", "take_mass", "chain", "load2.mass", "Real"),
]
# what the plot and the comparison read: (component, variable, type)
WATCH = [("chain", "chain.v_mean", "Real"), ("drive", "v_ref", "Real"), ("drive", "F", "Real"),
         ("chain", "drive.F_total", "Real"), ("chain", "chain.joint.F_max", "Real"),
         ("chain", "chain.items.mass", "Real"), ("induction", "n_items", "Integer")]


def parameters(layout: str = "demo", v_set: float = 1.5, rate: float = 2.0, mass: float = 15.0,
               chute_after: float = 12.0) -> dict:
    """The system's parameters by component: the chain starts at rest in its equilibrium, driven from
    outside in two motor groups; the induction at 5 m, the chute `chute_after` m further. layout.name
    is given only when it is not the FMU's default (fmpy's SSP master sets no String parameter)."""
    from lss_fmu.layouts import load_track
    from lss_fmu.protocol import Protocol
    from lss_fmu.variables import BY_NAME
    length = load_track(layout).length
    chain = {"drive.mode": 1, "drive.n_groups": 2, "chain.v_init": 0.0,
             "chain.relax_time": Protocol(name="start-up").relax_time(length), "station.induction.s": 5.0,
             "station.chute.s": round((5.0 + chute_after) % length, 3)}
    if layout != BY_NAME["layout.name"].start:
        chain = {"layout.name": layout, **chain}
    return {"chain": chain, "drive": {"v_set": v_set}, "induction": {"rate": rate, "mass": mass}}


def _model_description(name: str) -> str:
    guid, _, variables = PLANT_FMUS[name]
    units = sorted({v[5] for v in variables if v[5]})
    rows, outputs = [], []
    for k, (vname, vr, typ, caus, var, unit, start, desc) in enumerate(variables, 1):
        attrs = f'name="{vname}" valueReference="{vr}" causality="{caus}" variability="{var}" description="{desc}"'
        if caus == "parameter":
            attrs += ' initial="exact"'
        elif caus == "output":
            attrs += ' initial="calculated"'
            outputs.append(k)
        u = f' unit="{unit}"' if unit else ""
        s = f' start="{start}"' if start is not None else ""
        rows.append(f"    <ScalarVariable {attrs}><{typ}{u}{s}/></ScalarVariable>")
    unit_defs = "".join(f'<Unit name="{u}"/>' for u in units)
    out = "".join(f'<Unknown index="{k}"/>' for k in outputs)
    return textwrap.dedent(f"""\
        <?xml version="1.0" encoding="UTF-8"?>
        <fmiModelDescription fmiVersion="2.0" modelName="{name}" guid="{guid}"
          generationTool="examples/plant/plant_system.py" variableNamingConvention="structured"
          numberOfEventIndicators="0">
          <CoSimulation modelIdentifier="{name}" canHandleVariableCommunicationStepSize="true"/>
          <UnitDefinitions>{unit_defs}</UnitDefinitions>
          <ModelVariables>
        """) + "\n".join(rows) + textwrap.dedent(f"""
          </ModelVariables>
          <ModelStructure><Outputs>{out}</Outputs><InitialUnknowns>{out}</InitialUnknowns></ModelStructure>
        </fmiModelDescription>
        """)


def build_plant_fmus(out: Path) -> dict:
    """SorterDrive.fmu and Induction.fmu into `out` (gcc and fmpy's FMI 2.0 headers)."""
    if shutil.which("gcc") is None:
        raise RuntimeError("building the plant FMUs needs gcc")
    out.mkdir(parents=True, exist_ok=True)
    paths = {}
    for name, (_, source, _) in PLANT_FMUS.items():
        lib = out / (name + build.shared_suffix())
        cmd = ["gcc", "-std=c11", "-O2", "-fPIC", "-shared", "-Wall", "-Wextra", "-Werror", "-I",
               str(build.fmi_headers()), "-I", str(HERE), "-o", str(lib), str(HERE / source), "-lm"]
        res = subprocess.run(cmd, capture_output=True, text=True)
        if res.returncode:
            raise RuntimeError(f"gcc failed on {source}:\n{res.stderr}")
        fmu = out / f"{name}.fmu"
        with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr("modelDescription.xml", _model_description(name))
            z.write(lib, f"binaries/{build.platform_dir()}/{lib.name}")
            for src in (source, "fmu_common.h"):
                z.write(HERE / src, f"sources/{src}")
        lib.unlink()
        paths[name] = fmu
    return paths


def _ssd(params: dict) -> str:
    fmus = {"chain": "LSSChain", "drive": "SorterDrive", "induction": "Induction"}
    conns = {c: [] for c in fmus}
    for a, ca, b, cb, typ in CONNECTIONS:
        conns[a].append((ca, "output", typ))
        conns[b].append((cb, "input", typ))
    for c, v, typ in WATCH:
        if all(v != name for name, _, _ in conns[c]):
            conns[c].append((v, "output", typ))
    comps = []
    for c, fmu in fmus.items():
        seen, rows = set(), []
        for name, kind, typ in conns[c]:
            if (name, kind) in seen:
                continue
            seen.add((name, kind))
            rows.append(f'<ssd:Connector name="{name}" kind="{kind}"><ssc:{typ}/></ssd:Connector>')
        comps.append(f'<ssd:Component name="{c}" source="resources/{fmu}.fmu" type="application/x-fmu-sharedlibrary">'
                     f'<ssd:Connectors>{"".join(rows)}</ssd:Connectors>'
                     f'<ssd:ParameterBindings><ssd:ParameterBinding source="resources/{c}.ssv"/>'
                     f'</ssd:ParameterBindings></ssd:Component>')
    links = "".join(f'<ssd:Connection startElement="{a}" startConnector="{ca}" endElement="{b}" endConnector="{cb}"/>'
                    for a, ca, b, cb, _ in CONNECTIONS)
    return ('<?xml version="1.0" encoding="UTF-8"?>\n'
            '<ssd:SystemStructureDescription xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" '
            'xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" version="1.0" name="SorterPlant">'
            f'<ssd:System name="Plant"><ssd:Elements>{"".join(comps)}</ssd:Elements>'
            f'<ssd:Connections>{links}</ssd:Connections></ssd:System>'
            f'<ssd:DefaultExperiment startTime="0" stopTime="4"/></ssd:SystemStructureDescription>\n')


def _ssv(values: dict) -> str:
    rows = []
    for name, value in values.items():
        if isinstance(value, str):
            rows.append(f'<ssv:Parameter name="{name}"><ssv:String value="{value}"/></ssv:Parameter>')
        elif isinstance(value, int) and not isinstance(value, bool):
            rows.append(f'<ssv:Parameter name="{name}"><ssv:Integer value="{value}"/></ssv:Parameter>')
        else:
            rows.append(f'<ssv:Parameter name="{name}"><ssv:Real value="{float(value)!r}"/></ssv:Parameter>')
    return ('<?xml version="1.0" encoding="UTF-8"?>\n'
            '<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" '
            f'version="1.0" name="parameters"><ssv:Parameters>{"".join(rows)}</ssv:Parameters></ssv:ParameterSet>\n')


def write_ssp(out: Path, chain_fmu: Path, params: dict) -> Path:
    """SorterPlant.ssp: the three FMUs, SystemStructure.ssd, one SSV of parameters per component."""
    fmus = build_plant_fmus(out)
    ssp = out / "SorterPlant.ssp"
    with zipfile.ZipFile(ssp, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("SystemStructure.ssd", _ssd(params))
        z.write(chain_fmu, "resources/LSSChain.fmu")
        for name, path in fmus.items():
            z.write(path, f"resources/{name}.fmu")
        for comp, values in params.items():
            z.writestr(f"resources/{comp}.ssv", _ssv(values))
    return ssp


def run_fmpy(ssp: Path, params: dict, stop: float, step: float) -> pd.DataFrame:
    """The system in fmpy's SSP master (its parameters given as a parameter set: fmpy does not apply the
    SSD's bindings itself)."""
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import Parameter, ParameterSet
    pset = ParameterSet(name="plant")
    for comp, values in params.items():
        for name, value in values.items():
            if isinstance(value, str):
                raise ValueError(f"{comp}.{name} = {value!r}: fmpy's SSP master sets no String parameter; "
                                 "run this system in libcosim (run_libcosim), or on the FMU's default layout")
            typ = "Integer" if isinstance(value, int) and not isinstance(value, bool) else "Real"
            pset.parameters.append(Parameter(name=f"{comp}.{name}", type=typ, value=value))
    res = simulate_ssp(str(ssp), stop_time=stop, step_size=step, parameter_set=pset)
    cols = {f"{c}.{v}": res[f"{c}.{v}"] for c, v, _ in WATCH}
    df = pd.DataFrame({"time": res["time"] + step, **cols})   # fmpy records a step's outputs at its start
    return df[df["time"] <= stop + 1e-9 * max(1.0, stop)].reset_index(drop=True)  # its float clock may add a step


def run_libcosim(ssp: Path, stop: float, step: float) -> pd.DataFrame:
    """The system in libcosim (its SSP parser applies the SSV bindings), stepped at `step`, the
    watched variables read after every step."""
    import tempfile

    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver
    log_output_level(CosimLogLevel.WARNING)    # its trace level repeats every FMI call
    with tempfile.TemporaryDirectory() as tmp:
        with zipfile.ZipFile(ssp) as z:
            z.extractall(tmp)
        ex = CosimExecution.from_ssp_file(str(Path(tmp)), step_size=int(round(step * 1e9)))
        obs = CosimObserver.create_last_value()
        ex.add_observer(obs)
        index = {s.name.decode(): s.index for s in ex.slave_infos()}
        refs = {}
        for c, v, typ in WATCH:
            ref = next(x.reference for x in ex.slave_variables(index[c]) if x.name.decode() == v)
            refs[(c, v)] = (ref, typ)
        rows = []
        n = int(round(stop / step))
        for k in range(n):
            ex.step()
            row = {"time": (k + 1) * step}
            for (c, v), (ref, typ) in refs.items():
                read = obs.last_real_values if typ == "Real" else obs.last_integer_values
                row[f"{c}.{v}"] = read(index[c], [ref])[0]
            rows.append(row)
        ex.stop()
    return pd.DataFrame(rows)


def plot(runs: dict, path: Path) -> Path:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(4, 1, figsize=(9, 10), sharex=True)
    for label, df in runs.items():
        ls = "-" if label == "fmpy" else "--"
        axes[0].plot(df["time"], df["chain.chain.v_mean"], ls, label=f"chain speed ({label})")
        axes[1].plot(df["time"], df["drive.F"], ls, label=f"thrust per motor ({label})")
        axes[2].plot(df["time"], df["chain.chain.joint.F_max"], ls, label=f"largest joint force ({label})")
        axes[3].plot(df["time"], df["chain.chain.items.mass"], ls, label=f"items on board ({label})")
    first = next(iter(runs.values()))
    axes[0].plot(first["time"], first["drive.v_ref"], ":", color="k", label="set point")
    for ax, unit in zip(axes, ("m/s", "N", "N", "kg")):
        ax.set_ylabel(unit)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    axes[-1].set_xlabel("time, s")
    fig.suptitle("LSSChain in a sorter system: SorterDrive + Induction, " + " and ".join(runs))
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="build/plant")
    ap.add_argument("--stop", type=float, default=14.0)
    ap.add_argument("--step", type=float, default=0.005)
    ap.add_argument("--layout", default="demo", help="a layout other than the FMU's default runs in libcosim only")
    args = ap.parse_args(argv)
    out = Path(args.out)
    params = parameters(args.layout)
    ssp = write_ssp(out, build.build_fmu(quiet=True), params)
    runs = {"libcosim": run_libcosim(ssp, args.stop, args.step)}
    if "layout.name" not in params["chain"]:
        runs = {"fmpy": run_fmpy(ssp, params, args.stop, args.step), **runs}
    png = plot(runs, out / "plant.png")
    if len(runs) == 2:
        both = runs["fmpy"].merge(runs["libcosim"], on="time", suffixes=("_fmpy", "_libcosim"))
        both.to_csv(out / "plant.csv", index=False)
        d = np.abs(both["chain.chain.v_mean_fmpy"] - both["chain.chain.v_mean_libcosim"]).max()
        print(f"wrote {ssp}, {png} and plant.csv; chain speed in the two masters differs by at most {d:.3g} m/s")
    else:
        runs["libcosim"].to_csv(out / "plant.csv", index=False)
        print(f"wrote {ssp}, {png} and plant.csv (libcosim)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
