#!/usr/bin/env python3
"""Writes the bad-input corpus: malformed or hostile uploads, each with the field its rejection
must name (MANIFEST.tsv: file, content type, expected field; a trailing * matches a prefix).
Re-run after changing a case: python3 tests/corpus/generate.py"""
import copy, json, os

HERE = os.path.dirname(os.path.abspath(__file__))
BASE = {
    "format": "pantograph-trace/1", "trace_id": "corpus-base", "vehicle_id": "EN57-1021",
    "pantograph": {"model": "160EC", "serial": "160EC-0042"}, "recorded_at": "2026-03-02T07:15:00Z",
    "test": {"kind": "pendulum", "joint": "J1", "rig": {}},
    "channels": {"t_s": [0.0, 0.002, 0.004, 0.006], "alpha_deg": [74.2, 74.19, 74.17, 74.14]},
}
SLIDER = copy.deepcopy(BASE)
SLIDER["test"] = {"kind": "slider", "joint": "J8", "rig": {}}
SLIDER["channels"] = {"t_s": [0.0, 0.002, 0.004], "h_mm": [18.3, 18.2, 18.0]}
LIFT = copy.deepcopy(BASE)
LIFT["test"] = {"kind": "lift", "rig": {}}
LIFT["channels"] = {"t_s": [0.0, 0.002], "H_m": [1.04, 1.04], "Fs_N": [18.0, 18.0]}

FULL_LIFT = copy.deepcopy(BASE)
FULL_LIFT["test"] = {"kind": "lift", "rig": {}}
FULL_LIFT["channels"] = {"t_s": [0.0, 0.002, 0.004], "H_m": [1.04, 1.04, 1.04], "T_Nm": [1110.0, 1110.0, 1110.0],
                         "Fs_N": [18.0, 18.0, 18.0], "Fm_N": [78.5, 78.5, 78.5]}
QUAD = copy.deepcopy(BASE)
QUAD["test"] = {"kind": "quadrangle_swing", "rig": {}}
QUAD["channels"] = {"t_s": [0.0, 0.002, 0.004, 0.006], "alpha_deg": [-10.1, -10.1, -10.0, -9.9],
                    "beta_deg": [-3.6, -3.6, -3.6, -3.59]}

def point(mass_kg, x):
    return {"kind": "point", "mass_kg": mass_kg, "body": "upper_arm", "position_m": [x, 0.0]}

cases = []  # (name, content_type, bytes, expected field)

def doc(name, field, f, base=BASE):
    d = copy.deepcopy(base)
    f(d)
    cases.append((name, "application/json", json.dumps(d).encode(), field))

def raw(name, field, body, ct="application/json"):
    cases.append((name, ct, body if isinstance(body, bytes) else body.encode(), field))

good = json.dumps(BASE)
raw("truncated", "body", good[: len(good) // 2])
raw("empty", "body", "")
raw("array-root", "body", "[1, 2, 3]")
raw("nan-literal", "body", good.replace("74.19", "NaN"))
raw("infinity-literal", "body", good.replace("74.19", "Infinity"))
raw("number-overflow", "body", good.replace("74.19", "1e999"))
raw("deep-nesting", "body", "[" * 100000 + "]" * 100000)
raw("invalid-utf8", "body", b"{\"format\": \"\xff\xfe\"}")
raw("bom", "body", "\ufeff" + good)
raw("trailing-garbage", "body", good + "}")
doc("format-wrong", "format", lambda d: d.update(format="pantograph-trace/2"))
doc("format-missing", "format", lambda d: d.pop("format"))
doc("format-number", "format", lambda d: d.update(format=1))
doc("vehicle-missing", "vehicle_id", lambda d: d.pop("vehicle_id"))
doc("vehicle-number", "vehicle_id", lambda d: d.update(vehicle_id=1021))
doc("vehicle-empty", "vehicle_id", lambda d: d.update(vehicle_id="  "))
doc("vehicle-huge", "vehicle_id", lambda d: d.update(vehicle_id="V" * 100000))
doc("vehicle-control-chars", "vehicle_id", lambda d: d.update(vehicle_id="EN57\u0000\u001b[31m"))
doc("pantograph-missing", "pantograph", lambda d: d.pop("pantograph"))
doc("pantograph-string", "pantograph", lambda d: d.update(pantograph="160EC"))
doc("model-missing", "pantograph.model", lambda d: d["pantograph"].pop("model"))
doc("serial-object", "pantograph.serial", lambda d: d["pantograph"].update(serial={"a": 1}))
doc("recorded-garbage", "recorded_at", lambda d: d.update(recorded_at="yesterday"))
doc("recorded-feb-30", "recorded_at", lambda d: d.update(recorded_at="2026-02-30T07:15:00Z"))
doc("recorded-no-zone", "recorded_at", lambda d: d.update(recorded_at="2026-03-02T07:15:00"))
doc("recorded-missing", "recorded_at", lambda d: d.pop("recorded_at"))
doc("test-missing", "test", lambda d: d.pop("test"))
doc("kind-unknown", "test.kind", lambda d: d["test"].update(kind="swing"))
doc("kind-number", "test.kind", lambda d: d["test"].update(kind=3))
doc("joint-unknown", "test.joint", lambda d: d["test"].update(joint="J9"))
doc("joint-sql", "test.joint", lambda d: d["test"].update(joint="J1'; DROP TABLE traces; --"))
doc("joint-missing", "test.joint", lambda d: d["test"].pop("joint"))
doc("rig-array", "test.rig", lambda d: d["test"].update(rig=[1]))
doc("rig-unknown-key", "test.rig.colour", lambda d: d["test"].update(rig={"colour": "red"}))
doc("rig-negative-mass", "test.rig.body.mass_kg", lambda d: d["test"].update(rig={"body": {"mass_kg": -1, "inertia_kgm2": 1, "com_distance_m": 0.1}}))  # the stated field itself (was the lumped `test.rig.mass_kg`; issue 17)
doc("rig-inertia-too-small", "test.rig.body.inertia_kgm2", lambda d: d["test"].update(rig={"body": {"mass_kg": 10, "inertia_kgm2": 0.1, "com_distance_m": 1}}))
doc("rig-body-string-mass", "test.rig.body.mass_kg", lambda d: d["test"].update(rig={"body": {"mass_kg": "ten", "inertia_kgm2": 1, "com_distance_m": 0.1}}))
doc("rig-attachment-kind", "test.rig.attachments[0].kind", lambda d: d["test"].update(rig={"attachments": [{"kind": "blob", "mass_kg": 1}]}))
doc("rig-pin-zero", "test.rig.pin_radius_m", lambda d: d["test"].update(rig={"pin_radius_m": 0}))
doc("rig-gravity-negative", "test.rig.gravity_m_s2", lambda d: d["test"].update(rig={"gravity_m_s2": -9.81}))
doc("custom-without-body", "test.rig.body", lambda d: d["test"].update(joint="custom"))
doc("channels-missing", "channels", lambda d: d.pop("channels"))
doc("channels-array", "channels", lambda d: d.update(channels=[[0, 1]]))
doc("t-missing", "channels.t_s", lambda d: d["channels"].pop("t_s"))
doc("t-repeated", "channels.t_s[2]", lambda d: d["channels"].update(t_s=[0.0, 0.002, 0.002, 0.006]))
doc("t-decreasing", "channels.t_s[3]", lambda d: d["channels"].update(t_s=[0.0, 0.002, 0.004, 0.001]))
doc("t-single", "channels.t_s", lambda d: d["channels"].update(t_s=[0.0], alpha_deg=[1.0]))
doc("t-strings", "channels.t_s[0]", lambda d: d["channels"].update(t_s=["0.0", 0.002, 0.004, 0.006]))
doc("alpha-missing", "channels.alpha_deg", lambda d: d["channels"].pop("alpha_deg"))
doc("alpha-short", "channels.alpha_deg", lambda d: d["channels"].update(alpha_deg=[1.0, 2.0]))
doc("alpha-string", "channels.alpha_deg[1]", lambda d: d["channels"]["alpha_deg"].__setitem__(1, "x"))
doc("alpha-null", "channels.alpha_deg[1]", lambda d: d["channels"]["alpha_deg"].__setitem__(1, None))
doc("alpha-bool", "channels.alpha_deg[2]", lambda d: d["channels"]["alpha_deg"].__setitem__(2, True))
doc("channel-name-spaces", "channels", lambda d: d["channels"].update({"bad name": [0, 0, 0, 0]}))
doc("too-many-channels", "channels", lambda d: d["channels"].update({f"c{i}": [0, 0, 0, 0] for i in range(40)}))
doc("root-unknown-key", "comment", lambda d: d.update(comment="hello"))
doc("trace-id-sql", "trace_id", lambda d: d.update(trace_id="x'; DROP TABLE traces; --"))
doc("trace-id-huge", "trace_id", lambda d: d.update(trace_id="a" * 5000))
doc("trace-id-path", "trace_id", lambda d: d.update(trace_id="../../etc/passwd"))
doc("slider-missing-h", "channels.h_mm", lambda d: d["channels"].pop("h_mm"), SLIDER)
doc("slider-joint-j3", "test.joint", lambda d: d["test"].update(joint="J3"), SLIDER)
doc("slider-springs-negative", "test.rig.springs", lambda d: d["test"].update(rig={"springs": -1}), SLIDER)
doc("slider-springs-huge", "test.rig.springs", lambda d: d["test"].update(rig={"springs": 1000}), SLIDER)
doc("lift-missing-torque", "channels.T_Nm", lambda d: None, LIFT)
CSV = """# format: pantograph-trace/1
# trace_id: corpus-csv
# vehicle_id: EN57-1021
# pantograph.model: 160EC
# pantograph.serial: 160EC-0042
# recorded_at: 2026-03-02T07:15:00Z
# test.kind: pendulum
# test.joint: J1
# test.rig: {}
t_s,alpha_deg
0,74.2
0.002,74.19
0.004,74.17
"""
raw("csv-empty", "channels", "", "text/csv")
raw("csv-nan", "channels.alpha_deg[1]", CSV.replace("0.002,74.19", "0.002,nan"), "text/csv")
raw("csv-word", "channels.alpha_deg[1]", CSV.replace("0.002,74.19", "0.002,abc"), "text/csv")
raw("csv-short-row", "csv.line*", CSV.replace("0.004,74.17", "0.004"), "text/csv")
raw("csv-no-vehicle", "vehicle_id", CSV.replace("# vehicle_id: EN57-1021\n", ""), "text/csv")
raw("csv-bad-rig", "test.rig", CSV.replace("# test.rig: {}", "# test.rig: {"), "text/csv")
raw("csv-t-not-first", "*", CSV.replace("t_s,alpha_deg", "alpha_deg,t_s"), "text/csv")
raw("csv-time-back", "channels.t_s[2]", CSV.replace("0.004,74.17", "0.001,74.17"), "text/csv")
raw("csv-binary", "*", b"\x00\x01\x02\xff\xfe", "text/csv")
# Issue 18: dates that leave the years 1-9999 once their offset is applied (SQLite stored the
# first as year 10000 and every later read of the vehicle answered 500).
doc("recorded-year-10000", "recorded_at", lambda d: d.update(recorded_at="9999-12-31T23:59:59-23:59"))
doc("recorded-year-0", "recorded_at", lambda d: d.update(recorded_at="0000-06-01T00:00:00Z"))
# Issue 18: physically absurd rigs and channels (a 1e308 pin radius or angle held a worker for good).
doc("rig-pin-1e308", "test.rig.pin_radius_m", lambda d: d["test"]["rig"].update(pin_radius_m=1e308))
doc("rig-body-mass-1e9", "test.rig.body.mass_kg", lambda d: d["test"]["rig"].update(
    body={"mass_kg": 1e9, "inertia_kgm2": 1e9, "com_distance_m": 0.5}))
doc("rig-gravity-moon", "test.rig.gravity_m_s2", lambda d: d["test"]["rig"].update(gravity_m_s2=1.62))
doc("alpha-1e308", "channels.alpha_deg[2]", lambda d: d["channels"]["alpha_deg"].__setitem__(2, 1e308))
# Issue 17, point 7: a stated release (`test.release_t_s`) outside the trace, of the wrong type,
# or on a test that has no release.
doc("release-after-end", "test.release_t_s", lambda d: d["test"].update(release_t_s=5.0))
doc("release-negative", "test.release_t_s", lambda d: d["test"].update(release_t_s=-1.0))
doc("release-string", "test.release_t_s", lambda d: d["test"].update(release_t_s="0.2 s"))
doc("release-on-slider", "test.release_t_s", lambda d: d["test"].update(release_t_s=0.0), base=SLIDER)
# Issue 18 (D): the rest of the physically absurd values, each outside a span of `[rig_limits]`
# in models/data/160ec.toml (README "Input limits"); the old code accepted every one.
doc("quad-point-mass-1e308", "test.rig.attachments[0].mass_kg",
    lambda d: d["test"]["rig"].update(attachments=[point(1e308, 0.5)]), QUAD)
doc("quad-point-mass-8m-off", "test.rig.attachments[0].position_m",
    lambda d: d["test"]["rig"].update(attachments=[point(5.0, 8.0)]), QUAD)
doc("quad-gravity-moon", "test.rig.gravity_m_s2", lambda d: d["test"]["rig"].update(gravity_m_s2=1.62), QUAD)
doc("quad-alpha-1e308", "channels.alpha_deg[2]", lambda d: d["channels"]["alpha_deg"].__setitem__(2, 1e308), QUAD)
doc("quad-beta-1e308", "channels.beta_deg[1]", lambda d: d["channels"]["beta_deg"].__setitem__(1, 1e308), QUAD)
doc("lift-height-1e308", "channels.H_m[1]", lambda d: d["channels"]["H_m"].__setitem__(1, 1e308), FULL_LIFT)
doc("lift-height-underground", "channels.H_m[0]", lambda d: d["channels"]["H_m"].__setitem__(0, -1.0), FULL_LIFT)
doc("lift-spring-force-1e308", "channels.Fs_N[2]", lambda d: d["channels"]["Fs_N"].__setitem__(2, 1e308), FULL_LIFT)
doc("lift-weight-force-5kN-up", "channels.Fm_N[1]", lambda d: d["channels"]["Fm_N"].__setitem__(1, -5000.0), FULL_LIFT)
doc("t-1e300", "channels.t_s[1]", lambda d: d["channels"].update(t_s=[0.0, 1e300, 2e300, 3e300]))
doc("t-far-from-zero", "channels.t_s[0]", lambda d: d["channels"].update(t_s=[1e12, 1e12 + 0.002, 1e12 + 0.004, 1e12 + 0.006]))
doc("t-interval-10s", "channels.t_s[3]", lambda d: d["channels"].update(t_s=[0.0, 0.002, 0.004, 10.004]))
doc("t-interval-1ns", "channels.t_s[1]", lambda d: d["channels"].update(t_s=[0.0, 1e-9, 0.004, 0.006]))
doc("t-record-over-an-hour", "channels.t_s",
    lambda d: d["channels"].update(t_s=[float(i) for i in range(3602)], alpha_deg=[10.0] * 3602))
doc("lift-t-1e300", "channels.t_s[2]", lambda d: d["channels"].update(t_s=[0.0, 0.002, 1e300]), FULL_LIFT)
doc("quad-t-interval-10s", "channels.t_s[2]", lambda d: d["channels"].update(t_s=[0.0, 0.002, 10.0, 10.002]), QUAD)

# A force-gauge test (static_force, issue 20): 6 readings raising to 1.8 m, then 5 lowering.
GAUGE = copy.deepcopy(BASE)
GAUGE["test"] = {"kind": "static_force", "gauge_resolution_n": 0.1}
GAUGE["channels"] = {"t_s": [float(i) for i in range(11)],
                     "H_m": [0.85, 1.0, 1.2, 1.4, 1.6, 1.8, 1.6, 1.4, 1.2, 1.0, 0.85],
                     "F_N": [80.1, 79.5, 78.9, 78.0, 77.2, 76.4, 104.3, 105.2, 106.0, 106.9, 107.5]}

def gauge_readings(keep):
    def f(d):
        for c in ("t_s", "H_m", "F_N"):
            d["channels"][c] = d["channels"][c][keep]
        d["channels"]["t_s"] = [float(i) for i in range(len(d["channels"]["t_s"]))]
    return f

doc("gauge-height-above-range", "channels.H_m[5]", lambda d: d["channels"]["H_m"].__setitem__(5, 2.3), GAUGE)
doc("gauge-height-1e308", "channels.H_m[3]", lambda d: d["channels"]["H_m"].__setitem__(3, 1e308), GAUGE)
doc("gauge-no-lowering-branch", "channels.H_m", gauge_readings(slice(0, 6)), GAUGE)
doc("gauge-no-raising-branch", "channels.H_m", gauge_readings(slice(5, 11)), GAUGE)
doc("gauge-three-raising-readings", "channels.H_m", gauge_readings(slice(3, 11)), GAUGE)
doc("gauge-height-back-down-while-raising", "channels.H_m[2]", lambda d: d["channels"]["H_m"].__setitem__(2, 0.9), GAUGE)
doc("gauge-resolution-missing", "test.gauge_resolution_n", lambda d: d["test"].pop("gauge_resolution_n"), GAUGE)
doc("gauge-resolution-negative", "test.gauge_resolution_n", lambda d: d["test"].update(gauge_resolution_n=-0.1), GAUGE)
doc("gauge-resolution-string", "test.gauge_resolution_n", lambda d: d["test"].update(gauge_resolution_n="0.1 N"), GAUGE)
doc("gauge-force-missing", "channels.F_N", lambda d: d["channels"].pop("F_N"), GAUGE)
doc("gauge-force-1e308", "channels.F_N[1]", lambda d: d["channels"]["F_N"].__setitem__(1, 1e308), GAUGE)
doc("gauge-on-a-pendulum", "test.gauge_resolution_n", lambda d: d["test"].update(gauge_resolution_n=0.1))
GAUGE_CSV = ("# format: pantograph-trace/1\n# trace_id: corpus-gauge\n# vehicle_id: EN57-1021\n"
             "# pantograph.model: 160EC\n# recorded_at: 2026-03-02T07:15:00Z\n# test.kind: static_force\n"
             "# test.gauge_resolution_n: 0.1\nt_s,H_m,F_N\n"
             + "".join(f"{t},{h},{f}\n" for t, h, f in zip(GAUGE["channels"]["t_s"], GAUGE["channels"]["H_m"],
                                                          GAUGE["channels"]["F_N"])))
raw("csv-gauge-resolution-word", "test.gauge_resolution_n",
    GAUGE_CSV.replace("gauge_resolution_n: 0.1", "gauge_resolution_n: fine"), "text/csv")
raw("csv-gauge-no-lowering-branch", "channels.H_m",
    "".join(l + "\n" for l in GAUGE_CSV.splitlines()[:8 + 6]), "text/csv")

# A rig's stated body uncertainty (issue 17, points 1 and 7): negative, not a number, or not
# below the value it qualifies is refused naming its exact path.
BODY = {"mass_kg": 2.0, "inertia_kgm2": 0.6, "com_distance_m": 0.5}
doc("body-uncertainty-negative", "test.rig.body_uncertainty.inertia_kgm2",
    lambda d: d["test"]["rig"].update(body_uncertainty={"inertia_kgm2": -0.01}))
doc("body-uncertainty-as-large-as-the-mass", "test.rig.body_uncertainty.mass_kg",
    lambda d: d["test"]["rig"].update(body=BODY, body_uncertainty={"mass_kg": 2.0}))
doc("body-uncertainty-above-the-default-body", "test.rig.body_uncertainty.com_distance_m",
    lambda d: d["test"]["rig"].update(body_uncertainty={"com_distance_m": 1e3}))
doc("body-uncertainty-string", "test.rig.body_uncertainty.com_distance_m",
    lambda d: d["test"]["rig"].update(body_uncertainty={"com_distance_m": "1 mm"}))
doc("body-uncertainty-unknown-key", "test.rig.body_uncertainty.inertia",
    lambda d: d["test"]["rig"].update(body_uncertainty={"inertia": 0.01}))
doc("slider-mass-uncertainty-negative", "test.rig.moving_mass_uncertainty_kg",
    lambda d: d["test"]["rig"].update(moving_mass_uncertainty_kg=-0.1), SLIDER)
doc("slider-mass-uncertainty-above-the-mass", "test.rig.moving_mass_uncertainty_kg",
    lambda d: d["test"]["rig"].update(moving_mass_kg=2.0, moving_mass_uncertainty_kg=2.5), SLIDER)

manifest = []
for i, (name, ct, body, field) in enumerate(cases, 1):
    ext = "csv" if ct == "text/csv" else "json"
    fname = f"{i:03d}-{name}.{ext}"
    with open(os.path.join(HERE, fname), "wb") as f:
        f.write(body)
    manifest.append(f"{fname}\t{ct}\t{field}")
with open(os.path.join(HERE, "MANIFEST.tsv"), "w") as f:
    f.write("# file\tcontent type\texpected field (trailing * = prefix, * alone = any named field)\n")
    f.write("\n".join(manifest) + "\n")
print(len(cases), "cases")
