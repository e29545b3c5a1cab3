#!/usr/bin/env python3
"""SciPy peer of pantowatch's base-model fit: what an engineer would write by hand.

Model (same as the Rust code, see bench/README.md):
  pendulum  J a = -m g d sin(alpha) - D w - R mu N(a) s,  N implicit in a
  slider    m x'' = -k x - D v - Fn mu s (+ F(t))
integrated with scipy.integrate.solve_ivp (DOP853 by default, rtol 1e-8,
atol 1e-10), one solver call per segment of constant motion direction s,
a terminal event at rate = 0 deciding stick or restart. Fitted with
scipy.optimize.least_squares (method 'trf', forward-difference Jacobian
with steps of 1e-4 x parameter scale, bounds viscous >= 0, dry >= 0) on
every sample of the trace.
Parameters: viscous D, dry mu, start (alpha0 / x0), start rate (w0 / v0),
sensor zero offset o.

Usage: python3 bench/scipy_peer.py FILE.json [FILE.json ...] [--repeat N]
Prints one JSON line per file.
"""
import argparse
import json
import math
import os
import statistics
import sys
import time

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares, nnls
from scipy.signal import savgol_filter

RTOL = 1e-8
ATOL = 1e-10
MAX_SEGMENTS = 100000


# --------------------------------------------------------------------------
# Trace loading
# --------------------------------------------------------------------------

def load_trace(path):
    with open(path) as f:
        doc = json.load(f)
    test = doc["test"]
    kind = test["kind"]
    rig = test.get("rig") or {}
    ch = doc["channels"]
    t = np.asarray(ch["t_s"], dtype=float)
    if kind == "pendulum":
        if "body" not in rig or "pin_radius_m" not in rig:
            raise SystemExit(f"{path}: the peer needs test.rig.body and pin_radius_m written out")
        b = rig["body"]
        m = float(b["mass_kg"])
        J = float(b["inertia_kgm2"])
        mom = m * float(b["com_distance_m"])
        for a in rig.get("attachments") or []:
            if a["kind"] == "point":
                ma, da = float(a["mass_kg"]), float(a["distance_m"])
                m += ma
                J += ma * da * da
                mom += ma * da
            elif a["kind"] == "rod":
                ma, L = float(a["mass_kg"]), float(a["length_m"])
                m += ma
                J += ma * L * L / 3.0
                mom += ma * L / 2.0
            else:
                raise SystemExit(f"{path}: unknown attachment kind {a['kind']!r}")
        model = PendulumModel(
            m=m, J=J, d=mom / m, R=float(rig["pin_radius_m"]),
            g=float(rig.get("gravity_m_s2", 9.81)),
        )
        y = np.asarray(ch["alpha_deg"], dtype=float)
        w0 = math.radians(float(rig.get("initial_rate_deg_s", 0.0)))
    elif kind == "slider":
        k = float(rig.get("springs", 1)) * float(rig.get("spring_stiffness_n_per_mm", 4.0)) * 1000.0
        F = np.asarray(ch["F_N"], dtype=float) if "F_N" in ch else None
        model = SliderModel(
            m=float(rig["moving_mass_kg"]), k=k,
            Fn=float(rig.get("normal_force_n", 4.05)), t_in=t, F_in=F,
        )
        y = np.asarray(ch["h_mm"], dtype=float)
        w0 = 0.0
    else:
        raise SystemExit(f"{path}: kind {kind!r} is not handled by the peer (pendulum, slider)")
    return dict(file=os.path.basename(path), kind=kind, joint=test.get("joint"),
                t=t, y=y, model=model, rate0=w0)


# --------------------------------------------------------------------------
# Models. State y = [q, qdot]; q in rad (pendulum) or mm (slider).
# --------------------------------------------------------------------------

class PendulumModel:
    unit = "deg"

    def __init__(self, m, J, d, R, g):
        self.m, self.J, self.d, self.R, self.g = m, J, d, R, g

    def rhs_factory(self, D, mu, s):
        m, J, d, R, g = self.m, self.J, self.d, self.R, self.g
        mgd, md, mg = m * g * d, m * d, m * g
        kf = R * mu * s  # friction torque = D w + kf * N
        sin, cos, hypot = math.sin, math.cos, math.hypot

        def rhs(t, y):
            al, w = y[0], y[1]
            sa, ca = sin(al), cos(al)
            c = mgd * sa + D * w
            q = mg * sa
            B = md * w * w + mg * ca
            # first guess N with a = 0, then Newton on J a + c + kf N(a) = 0
            N = hypot(q, B)
            a = -(c + kf * N) / J
            for _ in range(6):
                u = md * a + q
                N = hypot(u, B)
                f = J * a + c + kf * N
                fp = J + (kf * md * u / N if N > 0.0 else 0.0)
                da = f / fp
                a -= da
                if abs(da) <= 1e-13 * (1.0 + abs(a)):
                    break
            return (w, a)

        return rhs

    def sticks(self, mu, t, q):
        # static capacity with N = m g: m g d |sin a| <= R mu m g
        return self.d * abs(math.sin(q)) <= self.R * mu

    def restart_dir(self, t, q):
        return -1.0 if math.sin(q) > 0 else 1.0

    def to_channel(self, q):
        return np.degrees(q)


class SliderModel:
    unit = "mm"

    def __init__(self, m, k, Fn, t_in, F_in):
        self.m, self.k, self.Fn, self.t_in, self.F_in = m, k, Fn, t_in, F_in

    def force(self, t):
        if self.F_in is None:
            return 0.0
        return float(np.interp(t, self.t_in, self.F_in))

    def rhs_factory(self, D, mu, s):
        # state in mm, mm/s: m x'' = -k x - D v - Fn mu s + F, all SI inside
        m, k, Fn = self.m, self.k, self.Fn
        fr = Fn * mu * s
        if self.F_in is None:
            def rhs(t, y):
                return (y[1], (-k * y[0] - D * y[1] - 1000.0 * fr) / m)
        else:
            force = self.force

            def rhs(t, y):
                return (y[1], (-k * y[0] - D * y[1] + 1000.0 * (force(t) - fr)) / m)
        return rhs

    def net_force(self, t, q):
        return self.force(t) - self.k * q / 1000.0

    def sticks(self, mu, t, q):
        return abs(self.net_force(t, q)) <= self.Fn * mu

    def restart_dir(self, t, q):
        return 1.0 if self.net_force(t, q) > 0 else -1.0

    def to_channel(self, q):
        return q


# --------------------------------------------------------------------------
# Simulation with stick-slip events
# --------------------------------------------------------------------------

class Sim:
    def __init__(self, method):
        self.method = method
        self.count = 0

    def run(self, model, t, D, mu, q0, r0):
        """Return q at every sample time t (state units)."""
        self.count += 1
        n = len(t)
        out = np.empty(n)
        idx = 0
        tc, q, r = t[0], q0, r0
        t_end = t[-1]
        for _ in range(MAX_SEGMENTS):
            if r == 0.0:
                if model.sticks(mu, tc, q):
                    # at rest; a slider with an input force may break loose later
                    j = n
                    if isinstance(model, SliderModel) and model.F_in is not None:
                        j = idx
                        while j < n and model.sticks(mu, t[j], q):
                            j += 1
                    out[idx:j] = q
                    idx = j
                    if idx >= n:
                        break
                    tc = t[idx]
                    s = model.restart_dir(tc, q)
                else:
                    s = model.restart_dir(tc, q)
            else:
                s = 1.0 if r > 0 else -1.0

            ev = lambda tt, yy: yy[1]
            ev.terminal = True
            ev.direction = -s
            if tc >= t_end:
                out[idx:] = q
                idx = n
                break
            t_eval = t[idx:]  # all > the last event time, which solve_ivp covered
            sol = solve_ivp(model.rhs_factory(D, mu, s), (tc, t_end), (q, r),
                            method=self.method, t_eval=t_eval, events=ev,
                            rtol=RTOL, atol=ATOL)
            if sol.status == -1:
                raise RuntimeError(sol.message)
            k = sol.t.size
            out[idx:idx + k] = sol.y[0]
            idx += k
            if sol.status != 1 or idx >= n:
                break
            te = sol.t_events[0][0]
            qe = sol.y_events[0][0][0]
            if te <= tc:  # no progress: the direction cannot be held, it is rest
                out[idx:] = qe
                idx = n
                break
            tc, q, r = te, qe, 0.0
        if idx < n:
            out[idx:] = q
        return out


# --------------------------------------------------------------------------
# Initial guess: energy balance on the smoothed trace (non-negative LS)
# --------------------------------------------------------------------------

def energy_guess(tr):
    model, t, y = tr["model"], tr["t"], tr["y"]
    dt = float(np.median(np.diff(t)))
    tu = np.arange(t[0], t[-1] + 0.5 * dt, dt)
    yu = np.interp(tu, t, y)
    q = np.radians(yu) if isinstance(model, PendulumModel) else yu / 1000.0  # rad or m
    if isinstance(model, PendulumModel):
        stiff, inert = model.m * model.g * model.d, model.J
    else:
        stiff, inert = model.k, model.m
    period = 2 * math.pi * math.sqrt(inert / stiff) if stiff > 0 else (t[-1] - t[0]) / 10
    win = max(7, int(period / 8 / dt) | 1)
    win = min(win, len(q) if len(q) % 2 else len(q) - 1)
    qs = savgol_filter(q, win, 3)
    v = savgol_filter(q, win, 3, deriv=1, delta=dt)
    a = savgol_filter(q, win, 3, deriv=2, delta=dt)
    if isinstance(model, PendulumModel):
        m, g, d = model.m, model.g, model.d
        N = np.hypot(m * d * a + m * g * np.sin(qs), m * d * v * v + m * g * np.cos(qs))
        E = 0.5 * model.J * v * v + m * g * d * (1 - np.cos(qs))
        dry_rate = model.R * N * np.abs(v)
        work_in = np.zeros_like(v)
    else:
        E = 0.5 * model.m * v * v + 0.5 * model.k * qs * qs
        dry_rate = model.Fn * np.abs(v)
        F = np.array([model.force(x) for x in tu]) if model.F_in is not None else np.zeros_like(v)
        work_in = F * v
    visc_rate = v * v
    # cumulative energy balance on every sample past the filter edge:
    #   E(t) - W_in(t) = E0 - mu * int(dry_rate) - D * int(w^2)
    def cumint(f):
        return np.concatenate(([0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * dt)))
    # stop where the motion has died out: a body at rest adds noise, not work
    tail = max(10, len(q) // 20)
    sig = float(np.std(q - qs))
    moving = np.nonzero(np.abs(qs - np.median(qs[-tail:])) > 10 * sig)[0]
    last = (moving[-1] + win) if moving.size else len(q)
    sl = slice(win // 2, min(len(q) - win // 2, last))
    C1, C2, W = cumint(dry_rate)[sl], cumint(visc_rate)[sl], cumint(work_in)[sl]
    if len(C1) < 10:
        return None
    # unknowns E0, mu, D, all >= 0
    A = np.column_stack([np.ones_like(C1), -C1, -C2])
    sc = np.abs(A).max(axis=0)
    sc[sc == 0] = 1.0
    x, _ = nnls(A / sc, E[sl] - W)
    _, mu, D = x / sc
    if not (np.isfinite(mu) and np.isfinite(D)):
        return None
    return float(D), float(mu)


def start_guess(tr):
    """Start value: intercept of a parabola through the first 50 ms (released from rest)."""
    t, y = tr["t"], tr["y"]
    sel = t <= t[0] + 0.05
    if sel.sum() < 4:
        return float(y[0])
    tt = t[sel] - t[0]
    c = np.polyfit(tt, y[sel], 2)
    return float(c[-1])


# --------------------------------------------------------------------------
# Fit
# --------------------------------------------------------------------------

def fit(tr, method="DOP853", guess="energy", fd_step=1e-4):
    model, t, y = tr["model"], tr["t"], tr["y"]
    pend = isinstance(model, PendulumModel)
    sim = Sim(method)
    t0 = time.perf_counter()
    used = "fixed"
    # generic Table-4-like values (not the joint's own baseline)
    if pend:
        D0, mu0 = 0.05, 0.1
    else:
        D0, mu0 = 1.0, 0.1
    if guess == "energy":
        g = energy_guess(tr)
        if g is not None:
            D0, mu0 = g
            used = "energy"
        start = start_guess(tr)
    else:
        start = float(y[0])
    # keep the start strictly inside the bounds
    D0 = max(D0, 1e-4 if pend else 1e-2)
    mu0 = max(mu0, 1e-3)
    q0 = math.radians(start) if pend else start
    x0 = np.array([D0, mu0, q0, tr["rate0"], 0.0])

    # Parameter scales for the finite-difference steps. least_squares' own
    # '2-point' step (sqrt(eps) * max(1, |x|)) is far below the integration
    # noise at rtol 1e-8 and gives Jacobian columns wrong by O(100 %); so the
    # Jacobian is plain forward differences with h_i = fd_step * scale_i.
    if pend:
        stiff, inert, qscale = model.m * model.g * model.d, model.J, 1.0  # rad
    else:
        stiff, inert, qscale = model.k, model.m, 10.0                      # mm
    wn = math.sqrt(stiff / inert) if stiff > 0 else 1.0
    dcrit = 2.0 * math.sqrt(stiff * inert) if stiff > 0 else inert
    floor = np.array([0.01 * dcrit, 0.01, qscale, qscale * wn, 1.0])
    cache = {}

    def residuals(x):
        D, mu, qs, rs, off = x
        q = sim.run(model, t, D, mu, qs, rs)
        f = model.to_channel(q) + off - y
        cache["x"], cache["f"] = x.copy(), f
        return f

    def jacobian(x):
        if "x" in cache and np.array_equal(cache["x"], x):
            f0 = cache["f"]
        else:
            f0 = residuals(x)
        Jm = np.empty((f0.size, x.size))
        h = fd_step * np.maximum(np.abs(x), floor)
        Jm[:, 4] = 1.0  # the offset enters linearly: its difference quotient is exactly 1
        for i in range(4):
            xi = x.copy()
            xi[i] += h[i]  # forward: stays inside the bounds D, mu >= 0
            D, mu, qs, rs, off = xi
            Jm[:, i] = (model.to_channel(sim.run(model, t, D, mu, qs, rs)) + off - y - f0) / h[i]
        return Jm

    res = least_squares(residuals, x0, jac=jacobian, method="trf",
                        bounds=([0, 0, -np.inf, -np.inf, -np.inf], np.inf),
                        x_scale="jac")
    secs = time.perf_counter() - t0
    rmse = float(np.sqrt(np.mean(res.fun ** 2)))
    D, mu, qs, rs, off = res.x
    return {
        "file": tr["file"], "kind": tr["kind"], "joint": tr["joint"],
        "viscous": float(D), "dry": float(mu), "rmse": rmse,
        "seconds": secs, "nfev": int(res.nfev), "status": int(res.status),
        # extras (not in the shared schema)
        "njev": int(res.njev), "nsim": sim.count,
        "start": float(math.degrees(qs) if pend else qs),
        "start_rate": float(math.degrees(rs) if pend else rs),
        "offset": float(off), "unit": model.unit,
        "guess": used, "guess_viscous": float(x0[0]), "guess_dry": float(x0[1]),
        "method": method, "message": res.message,
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("files", nargs="+")
    ap.add_argument("--repeat", type=int, default=1,
                    help="fit each file N times; 'seconds' is the median, 'seconds_all' lists all")
    ap.add_argument("--method", default="DOP853", choices=["DOP853", "RK45"])
    ap.add_argument("--guess", default="energy", choices=["energy", "fixed"],
                    help="initial guess: energy balance on the smoothed trace (default) "
                         "or fixed Table-4-like values (pendulum D 0.05, mu 0.1; slider D 1.0, mu 0.1) with the start read off sample 0")
    ap.add_argument("--fd-step", type=float, default=1e-4,
                    help="forward-difference step relative to each parameter's scale")
    a = ap.parse_args(argv)
    for f in a.files:
        tr = load_trace(f)
        runs = []
        for _ in range(max(1, a.repeat)):
            try:
                runs.append(fit(tr, a.method, a.guess, a.fd_step))
            except Exception as e:  # report, do not stop the batch
                runs.append({"file": tr["file"], "kind": tr["kind"], "joint": tr["joint"],
                             "viscous": None, "dry": None, "rmse": None, "seconds": None,
                             "nfev": None, "status": "error", "message": repr(e)})
                break
        out = runs[-1]
        secs = [r["seconds"] for r in runs if r.get("seconds") is not None]
        if secs:
            out["seconds"] = statistics.median(secs)
            if len(secs) > 1:
                out["seconds_all"] = secs
        print(json.dumps(out), flush=True)


if __name__ == "__main__":
    sys.exit(main())
