#!/usr/bin/env python3
"""Writes the fuzzers' seed inputs (fuzz/seeds/trace_json, fuzz/seeds/trace_csv): every shared
example trace and the lift reference, cut to their first 24 samples (small seeds keep libFuzzer
fast), as JSON and in the CSV logger shape. The malformed-upload corpus (tests/corpus) is passed
to both targets by scripts/fuzz.sh as well. Re-run: python3 fuzz/make_seeds.py"""
import glob, json, os

HERE = os.path.dirname(os.path.abspath(__file__))
SHARED = os.path.join(HERE, "..", "..", "shared")
N = 24

def csv_of(d):
    lines = []
    meta = lambda k, v: lines.append(f"# {k}: {v}")
    meta("format", d["format"])
    if "trace_id" in d:
        meta("trace_id", d["trace_id"])
    meta("vehicle_id", d["vehicle_id"])
    meta("pantograph.model", d["pantograph"]["model"])
    if "serial" in d["pantograph"]:
        meta("pantograph.serial", d["pantograph"]["serial"])
    meta("recorded_at", d["recorded_at"])
    meta("test.kind", d["test"]["kind"])
    if "joint" in d["test"]:
        meta("test.joint", d["test"]["joint"])
    if "rig" in d["test"]:
        meta("test.rig", json.dumps(d["test"]["rig"], separators=(",", ":")))
    names = ["t_s"] + sorted(k for k in d["channels"] if k != "t_s")
    lines.append(",".join(names))
    for i in range(len(d["channels"]["t_s"])):
        lines.append(",".join(repr(float(d["channels"][n][i])) for n in names))
    return "\n".join(lines) + "\n"

sources = sorted(glob.glob(os.path.join(SHARED, "data", "examples", "*.json")))
sources.append(os.path.join(SHARED, "reference", "lift-example.json"))
for sub in ("trace_json", "trace_csv"):
    os.makedirs(os.path.join(HERE, "seeds", sub), exist_ok=True)
for path in sources:
    d = json.load(open(path))
    if d.get("format") != "pantograph-trace/1":
        continue  # truth.json and other non-traces
    d["channels"] = {k: v[:N] for k, v in d["channels"].items()}
    name = os.path.splitext(os.path.basename(path))[0]
    with open(os.path.join(HERE, "seeds", "trace_json", name + ".json"), "w") as f:
        json.dump(d, f)
    with open(os.path.join(HERE, "seeds", "trace_csv", name + ".csv"), "w") as f:
        f.write(csv_of(d))
