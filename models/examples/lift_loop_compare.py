#!/usr/bin/env python3
"""Compares two runs of `lift_loop_probe` (issue 36, point 2): the lift loop's decisions and its
work before and after a change, per protocol x noise.

    python3 models/examples/lift_loop_compare.py BEFORE.tsv AFTER.tsv [--tol 1e-3]

A lift is matched on (protocol, k, case, seed). Its decisions: verdict, named effect, the
absorption check (fired, ratio, plain ratio, worst phase and its ratio), joint flags, the J1+J3
level and interval, the reported residual and its phases, the named effect's parameters —
numbers equal within --tol (relative; default 0: to the printed digit). Work: evaluations,
integrator steps and the per-step list (the loop's own, without `spare:` candidates tried ahead
on another thread, which are summed apart). Wall seconds are shown, never compared (load).
Exit status 1 when a decision changed.
"""
import sys
from collections import defaultdict

DECISION = {5: "verdict", 6: "named", 7: "fired", 8: "ratio", 9: "plain_ratio", 10: "flags",
            11: "level", 12: "lo", 13: "hi", 16: "final_ratio", 17: "t1", 18: "t2", 19: "hlo",
            20: "hhi", 21: "up", 22: "down", 23: "params", 24: "check_phase", 25: "check_ratio"}
WORK = {26: "evaluations", 27: "steps", 28: "per_step"}


def load(path):
    rows = {}
    for line in open(path):
        c = line.rstrip("\n").split("\t")
        if len(c) < 29 or c[5] == "error":
            if len(c) > 5 and c[5] == "error":
                rows[tuple(c[0:3] + [c[4]])] = c
            continue
        rows[tuple(c[0:3] + [c[4]])] = c
    return rows


def same(a, b, tol):
    if a == b:
        return True
    try:
        x, y = float(a), float(b)
    except ValueError:
        return False
    if x != x and y != y:
        return True
    return abs(x - y) <= tol * max(abs(x), abs(y), 1e-12)


def spare_steps(c):
    if len(c) < 30 or c[29] == "-":
        return 0
    return sum(int(p.split("=")[1].split("/")[1]) for p in c[29].split(";"))


def q(xs, p):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(round(p * (len(xs) - 1))))] if xs else float("nan")


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    tol = float(sys.argv[sys.argv.index("--tol") + 1]) if "--tol" in sys.argv else 0.0
    if "--tol" in sys.argv:
        args.remove(sys.argv[sys.argv.index("--tol") + 1])
    before, after = load(args[0]), load(args[1])
    keys = sorted(set(before) & set(after))
    missing = sorted(set(before) ^ set(after))
    groups = defaultdict(list)
    changed_any = 0
    for key in keys:
        b, a = before[key], after[key]
        if b[5] == "error" or a[5] == "error":
            dec = [] if b[5:] == a[5:] else ["error"]
            wrk = []
        else:
            dec = [n for i, n in DECISION.items() if not same(b[i], a[i], tol)]
            wrk = [n for i, n in WORK.items() if b[i] != a[i]]
        if dec:
            changed_any += 1
            print(f"DECISION CHANGED {key}: {dec}", file=sys.stderr)
            for i, n in DECISION.items():
                if n in dec:
                    print(f"    {n}: {b[i]} -> {a[i]}", file=sys.stderr)
        groups[(key[0], key[1])].append((b, a, dec, wrk))
    print("| protocol | noise | lifts | decisions changed | work changed | steps before → after "
          "(loop's own) | spare steps after | loop s p50 / p95 / max, before → after |")
    print("|---|---|---|---|---|---|---|---|")
    tb = ta = ts = 0
    for (p, k), rs in sorted(groups.items()):
        ok = [(b, a) for b, a, _, _ in rs if b[5] != "error" and a[5] != "error"]
        sb = sum(int(b[27]) for b, _ in ok)
        sa = sum(int(a[27]) for _, a in ok)
        sp = sum(spare_steps(a) for _, a in ok)
        tb, ta, ts = tb + sb, ta + sa, ts + sp
        secs = lambda rows, j: [float(r[j][15]) for r in rows]
        b_s, a_s = secs(ok, 0), secs(ok, 1)
        print(f"| {p} | {k}x | {len(rs)} | {sum(bool(d) for _, _, d, _ in rs)} | "
              f"{sum(bool(w) for _, _, _, w in rs)} | {sb:,} → {sa:,} | {sp:,} | "
              f"{q(b_s, .5):.2f} / {q(b_s, .95):.2f} / {max(b_s, default=float('nan')):.1f} → "
              f"{q(a_s, .5):.2f} / {q(a_s, .95):.2f} / {max(a_s, default=float('nan')):.1f} |")
    print(f"\nall {len(keys)} lifts: {changed_any} decisions changed; loop's own steps "
          f"{tb:,} → {ta:,}; spare steps after {ts:,}")
    if missing:
        print(f"not in both runs: {len(missing)} lifts, e.g. {missing[:3]}")
    sys.exit(1 if changed_any else 0)


main()
