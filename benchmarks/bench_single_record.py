#!/usr/bin/env python3
"""The plain command on one short record: `lss identify REC --model LW --out
DIR` with nothing else, on single start-stop records of the recovery set,
each compared afterwards with its answer file (which the command never
reads): per CoR the error, whether it was claimed, whether its interval
holds the truth; f, the window the result is for, CPU.

    .venv/bin/python benchmarks/bench_single_record.py --measurements 1,2,5,12,13,19 --seconds 1.5 \\
        --json benchmarks/results/single_record.json

A row is a hit when e_JA, e_SW and e_RW are all claimed and within 0.03.
Each record runs in its own process (`--workers`); rows already in the JSON
for the same code, measurement and length are kept, so a stopped run resumes.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench_common import hash_sources  # noqa: E402
from lss_fmu.atomic import write_json_atomic  # noqa: E402
from lss_fmu.rig import folder_name, load_truth, parse_numbers, run_measurement, true_design_values  # noqa: E402
from lss_fmu.runner import ChainSimulator  # noqa: E402

TOL = 0.03
HEADLINE = ("e_JA", "e_SW", "e_RW")


def code_stamp() -> str:
    return hash_sources(hashlib.sha256()).hexdigest()[:12]


def record(work: Path, number: int, seconds: float) -> Path:
    """The rig's start-stop record of `number`, `seconds` long (made once)."""
    out = work / f"s{seconds:g}"
    if not (out / folder_name(number) / "meta.json").is_file():
        with ChainSimulator() as s:
            run_measurement("recovery", number, out, s, protocol="start-stop", lap_seconds=seconds)
    return out / folder_name(number)


def one(work: Path, number: int, seconds: float) -> dict:
    """The plain command in its own process (its CPU from wait4), then the
    comparison with the answer file."""
    rec = record(work, number, seconds)
    out = work / f"id_m{number:02d}_s{seconds:g}"
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    cmd = [sys.executable, "-m", "lss_app.cli", "identify", str(rec), "--model", "LW", "--out", str(out),
           "--no-progress"]
    with open(out / "stderr.txt", "w") as err:
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        return {"number": number, "seconds": seconds,
                "error": (out / "stderr.txt").read_text().strip().splitlines()[-1:]}
    res = json.loads((out / "result.json").read_text())
    truth = true_design_values(load_truth(rec))
    row = {"number": number, "seconds": seconds, "layout": res["layout"], "f": res["f"],
           "window_s": res["window_s"], "wall_s": time.time() - t0,
           "cpu_s": usage.ru_utime + usage.ru_stime}
    for s in ("e_JA", "e_JR", "e_SW", "e_RW"):
        name, iv = f"contact.{s}", res["interval"][s]
        row[s] = {"error": res["x"][name] - truth[name], "identifiable": iv["identifiable"],
                  "covers": iv["lower"] <= truth[name] <= iv["upper"]}
    row["hit"] = all(row[s]["identifiable"] and abs(row[s]["error"]) <= TOL for s in HEADLINE)
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default="build/bench_single_record")
    ap.add_argument("--measurements", default="1,2,5,12,13,19")
    ap.add_argument("--seconds", type=float, default=1.5)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", default="benchmarks/results/single_record.json")
    args = ap.parse_args(argv)
    work, stamp = Path(args.work), code_stamp()
    work.mkdir(parents=True, exist_ok=True)
    old = json.loads(Path(args.json).read_text()) if Path(args.json).exists() else {}
    rows = {(q["number"], q["seconds"]): q for q in old.get("rows", []) if q.get("code") == stamp}
    todo = [n for n in parse_numbers(args.measurements) if (n, args.seconds) not in rows]
    for n in todo:   # the records first, one simulator in this process
        record(work, n, args.seconds)

    def run(n: int) -> None:
        q = one(work, n, args.seconds)
        q["code"] = stamp
        rows[(n, args.seconds)] = q
        done = sorted(rows.values(), key=lambda r: (r["seconds"], r["number"]))
        ok = [r for r in done if "error" not in r]
        write_json_atomic(args.json, {"rows": done, "code": stamp, "tolerance": TOL,
                                      "hits": sum(r["hit"] for r in ok), "n": len(ok),
                                      "ja_sw_within": sum(all(abs(r[s]["error"]) <= TOL for s in ("e_JA", "e_SW"))
                                                          for r in ok)})
        print(json.dumps({k: q[k] for k in ("number", "seconds", "f", "window_s") if k in q})
              + (" hit" if q.get("hit") else f" {q.get('error') or 'miss'}"), flush=True)

    with ThreadPoolExecutor(max(1, args.workers)) as ex:   # each record is its own process
        list(ex.map(run, todo))
    return 0


if __name__ == "__main__":
    sys.exit(main())
