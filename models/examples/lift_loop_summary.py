#!/usr/bin/env python3
"""Sums `lift_loop_probe` lines (stdin or files) per protocol x noise (issue 36, point 2).

Detectable: the absorption check fired (`fit.absorption.ratio` >= 2) or the plain fit was
withheld by the residual gate (verdict `unexplained` with the check not fired counts as
detectable too: the plain residual is > 3x the noise).

Detectable by the issue's rule (issue 36, point 1: the effect, refitted with only the reported
parameters free, leaves >= 2x the noise RMS): the reported-only refit's overall ratio >= 2; where
no such refit ran (ratio NaN: nothing reported, or the refit failed), the plain fit over the
residual gate. Not the plain fit over the gate where the refit ran and left under 2x (before
session 24 it counted): that refit is nested in the plain fit (the same model, fewer parameters
free), so the plain model's optimum is under 2x as well and the plain fit's excess is its
optimiser's, not the record's (`report::residual_loop`, `nested_better`). Measured: `design 2
400 1 offset:10`, plain fit 3.48x, reported-only refit 1.34x. The first definition adds the
lifts the project's own phase rule fires on (a raise's rising phase >= 2x): the raise cannot
name those, and they end `unexplained`; the in-vocabulary column is given both ways.
"""
import sys, statistics
from collections import defaultdict

rows = []
for f in (sys.argv[1:] or ["-"]):
    fh = sys.stdin if f == "-" else open(f)
    for line in fh:
        c = line.rstrip("\n").split("\t")
        if len(c) < 16:
            continue
        rows.append(dict(proto=c[0], k=c[1], case=c[2], cls=c[3], seed=c[4], verdict=c[5],
                         named=c[6], fired=c[7] == "true", ratio=float(c[8]), plain=float(c[9]),
                         flags=c[10], lv=float(c[11]), lo=float(c[12]), hi=float(c[13]),
                         truth=float(c[14]), secs=float(c[15])))

def q(xs, p):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(round(p * (len(xs) - 1))))] if xs else float("nan")

groups = defaultdict(list)
for r in rows:
    groups[(r["proto"], r["k"])].append(r)
print("| protocol | noise | lifts | clean: false named / unexplained | false joint flags | "
      "in-vocab detectable / named right (wrong) | in-vocab by the issue's rule: detectable / named right | OOV detectable / unexplained (wrong name) "
      "[all OOV unexplained] | J1+J3 held / reported | loop s p50 / p95 / max |")
print("|---|---|---|---|---|---|---|---|---|---|")
for (p, k), rs in sorted(groups.items()):
    clean = [r for r in rs if r["cls"] == "clean"]
    cn = sum(r["verdict"] == "named" for r in clean)
    cu = sum(r["verdict"] == "unexplained" for r in clean)
    flags = sum(r["flags"] != "-" for r in rs)
    det = lambda r: r["fired"] or r["verdict"] != "clean"
    voc = [r for r in rs if r["cls"].startswith("vocab:")]
    vd = [r for r in voc if det(r)]
    vright = sum(r["named"] == r["cls"][6:] for r in vd)
    det_issue = lambda r: r["ratio"] >= 2.0 or (r["ratio"] != r["ratio"] and r["verdict"] != "clean")
    vi = [r for r in voc if det_issue(r)]
    viright = sum(r["named"] == r["cls"][6:] for r in vi)
    vwrong = sum(r["named"] not in ("-", r["cls"][6:]) for r in voc)
    oov = [r for r in rs if r["cls"] == "oov"]
    od = [r for r in oov if det(r)]
    ou = sum(r["verdict"] == "unexplained" for r in od)
    owrong = sum(r["named"] != "-" for r in oov)
    oall = sum(r["verdict"] == "unexplained" for r in oov)
    cov = [r for r in rs if r["lv"] == r["lv"] and r["truth"] == r["truth"]]
    held = sum(r["lo"] <= r["truth"] <= r["hi"] for r in cov)
    secs = [r["secs"] for r in rs]
    print(f"| {p} | {k}x | {len(rs)} | {cn} / {cu} of {len(clean)} | {flags} | "
          f"{len(vd)} of {len(voc)} / {vright} ({vwrong}) | {len(vi)} / {viright} | {len(od)} of {len(oov)} / {ou} ({owrong}) "
          f"[{oall} of {len(oov)}] | {held} / {len(cov)} | {q(secs, .5):.2f} / {q(secs, .95):.2f} / "
          f"{max(secs):.1f} |")
if "-v" in sys.argv[0:1] or True:
    print()
    per = defaultdict(list)
    for r in rs if False else rows:
        per[(r["proto"], r["k"], r["case"])].append(r)
    for key, rs in sorted(per.items()):
        v = defaultdict(int)
        for r in rs:
            v[r["verdict"] + ("" if r["named"] == "-" else ":" + r["named"])] += 1
        cov = [r for r in rs if r["lv"] == r["lv"] and r["truth"] == r["truth"]]
        held = sum(r["lo"] <= r["truth"] <= r["hi"] for r in cov)
        rat = [r["ratio"] for r in rs]
        print(f"{key[0]:6} {key[1]:>3} {key[2]:18} {dict(v)} check ratio {min(rat):.2f}-{max(rat):.2f} "
              f"level held {held}/{len(cov)} flags {sum(r['flags'] != '-' for r in rs)}")
