#!/usr/bin/env python3
"""Markdown table: SciPy peer vs pantowatch, against truth.json.

  python3 bench/compare.py --truth EX/truth.json --peer peer.jsonl [--rust rust.jsonl]

peer.jsonl: lines of bench/scipy_peer.py ({"file", "viscous", "dry", "seconds", ...}).
rust.jsonl: lines of `pantowatch-tools bench --json` ({"file", "viscous", "dry",
"seconds_per_fit", "fits", ...}). Without --rust the Rust columns stay empty.
Files are matched by base name; truth.json is keyed by base name without .json.
"""
import argparse
import json
import os
import platform
import subprocess
import sys


def die(msg):
    print(f"compare.py: {msg}", file=sys.stderr)
    sys.exit(1)


def read_jsonl(path, what):
    rows = {}
    with open(path) as f:
        for n, line in enumerate(f, 1):
            line = line.strip()
            if not line.startswith("{"):
                continue  # tolerate log lines
            try:
                r = json.loads(line)
            except json.JSONDecodeError as e:
                die(f"{what} output {path}:{n} is not JSON: {e}")
            if "file" not in r:
                die(f"{what} output {path}:{n} has no 'file' field")
            rows[os.path.basename(r["file"])] = r
    if not rows:
        die(f"{what} output {path} has no JSON lines")
    return rows


def err_pct(est, true):
    if est is None or true in (None, 0):
        return None
    return 100.0 * (est / true - 1.0)


def fmt_pct(x):
    return "–" if x is None else f"{x:+.2f}"


def cmd(args):
    try:
        return subprocess.run(args, capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "n/a"


def machine_line():
    cpu = "n/a"
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        import numpy
        import scipy
        npv, spv = numpy.__version__, scipy.__version__
    except ImportError:
        npv = spv = "n/a"
    return (f"Machine: nproc {cmd(['nproc'])}, CPU {cpu}; {cmd(['rustc', '--version'])}; "
            f"Python {platform.python_version()}, numpy {npv}, scipy {spv}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--truth", required=True)
    ap.add_argument("--peer", required=True)
    ap.add_argument("--rust")
    a = ap.parse_args()

    with open(a.truth) as f:
        truth = json.load(f)
    peer = read_jsonl(a.peer, "peer")
    rust = read_jsonl(a.rust, "pantowatch-tools bench") if a.rust else {}

    missing = [f for f in peer if a.rust and f not in rust]
    if missing:
        die(f"pantowatch-tools bench gave no line for: {', '.join(missing)}")

    print("| file | peer s | rust ms | speed-up × | peer viscous err % | rust viscous err % "
          "| peer dry err % | rust dry err % |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    tot_p = tot_r = 0.0
    all_r = bool(rust)
    for fname in peer:  # keep the peer's (= command line) order
        key = fname[:-5] if fname.endswith(".json") else fname
        if key not in truth:
            die(f"{fname}: not in {a.truth}")
        tv = truth[key]
        p = peer[fname]
        r = rust.get(fname)
        ps = p.get("seconds")
        rs = r.get("seconds_per_fit") if r else None
        if ps is None or p.get("viscous") is None:
            all_r = False
        if ps is not None:
            tot_p += ps
        if rs is not None:
            tot_r += rs
        else:
            all_r = False
        speed = f"{ps / rs:.0f}" if (ps and rs) else "–"
        print(f"| {fname} | {ps:.2f} | " if ps is not None else f"| {fname} | failed | ", end="")
        print(f"{rs * 1e3:.1f} | " if rs is not None else "– | ", end="")
        print(f"{speed} | {fmt_pct(err_pct(p.get('viscous'), tv['viscous']))} | "
              f"{fmt_pct(err_pct(r.get('viscous'), tv['viscous']) if r else None)} | "
              f"{fmt_pct(err_pct(p.get('dry'), tv['dry']))} | "
              f"{fmt_pct(err_pct(r.get('dry'), tv['dry']) if r else None)} |")
    speed = f"{tot_p / tot_r:.0f}" if (all_r and tot_r > 0) else "–"
    rtot = f"{tot_r * 1e3:.1f}" if all_r else "–"
    print(f"| **total** | {tot_p:.2f} | {rtot} | {speed} | | | | |")
    print()
    print(machine_line())


if __name__ == "__main__":
    main()
