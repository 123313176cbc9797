#!/usr/bin/env python3
"""Independent reference traces for the ST5B exciter driven alone on prescribed inputs.

Written from the block equations (IEEE 421.5-2005 type ST5B as PSS/E and OpenIPSL define it;
`crates/dynamics/src/models/exciter/st5b.rs` documents the same equations), not from the Rust
code: scipy's solve_ivp (DOP853, rtol 1e-10, atol 1e-12) between the input breakpoints, with
the non-windup limits, the pure-lag lead-lag limits and the OEL gate handled as hybrid modes
whose switching instants are located by solve_ivp's event functions.

    T_R dV_m/dt = V_t - V_m                                   (T_R = 0: V_m = V_t)
    V_e = V_ref - V_m ;  V_h = V_e + V_UEL (or max) ;  V_l = V_h + V_OEL (or min with the OEL gate)
    u = V_l + V_S
    path p in {main, UEL, OEL}: y_p = LL2_p(LL1_p(u)), each lead-lag limited to [V_RMIN, V_RMAX]/K_R
        lead-lag (T_C > 0): w = x + T_C/T_B (u - x), y = clamp(w), T_C dx/dt = y - x
        lead-lag (T_C = 0): non-windup lag, T_B dx/dt = u - x frozen on a limit while pushing out
        lead-lag (T_B = 0): y = clamp(u)
    V_R = clamp(K_R y_path, V_RMIN, V_RMAX)
    T_1 dE_fd/dt = V_R - K_C I_fd - E_fd, non-windup in [V_t V_RMIN, V_t V_RMAX]   (T_1 = 0: clamp)

Inputs (V_t, X_adI_fd = I_fd, V_S, V_OEL) are piecewise linear with breakpoints on the 5 ms
output grid, so that linear interpolation of the CSV columns reproduces them exactly.

Output, for each case: data/st5b/<case>.json (parameters, options, E_fd0) and
data/st5b/<case>.csv (time_s, v_t, xadifd, vs, voel, efd, v_r), 5 ms rows.

Run from the repository root:  python3 tools/st5b_reference.py      (needs numpy and scipy)
"""
import json
import math
import os
import sys

import numpy as np
from scipy.integrate import solve_ivp

DST = os.path.join(os.path.dirname(__file__), "..", "data", "st5b")
DT = 0.005
RTOL, ATOL = 1e-10, 1e-12
TOL_AT, TOL_PUSH = 1e-9, 1e-12

MOSTAR = dict(t_r=0.025, t_c1=1.071137, t_b1=10.7561, t_c2=3.414283, t_b2=1.701033,
              k_r=358.6086, vr_max=5.0, vr_min=-4.0, t_1=0.01, k_c=0.3,
              t_uc1=2.0, t_ub1=10.0, t_uc2=0.1, t_ub2=0.05,
              t_oc1=0.1, t_ob1=2.0, t_oc2=0.08, t_ob2=0.08)

# Terminal voltage: overvoltage to 1.1 (the floor V_t V_RMIN binds), back, a sag to 0.9 with the
# field current rising (V_R on V_RMAX: the K_C-reduced ceiling V_RMAX - K_C I_fd binds), a dip
# to 0.6 (the supply ceiling V_t V_RMAX binds), recovery.
VT = [(0.0, 1.0), (0.5, 1.0), (0.505, 1.1), (1.2, 1.1), (1.205, 1.0), (2.0, 1.0), (2.005, 0.9),
      (3.0, 0.9), (3.005, 0.6), (3.3, 0.6), (3.305, 0.9), (4.0, 0.9), (4.05, 1.0), (7.0, 1.0)]
IFD = [(0.0, 1.8), (2.0, 1.8), (3.0, 2.6), (3.3, 2.6), (4.5, 1.6), (7.0, 1.8)]
VS = [(0.0, 0.0), (4.5, 0.0), (4.7, 0.03), (5.5, 0.03), (5.7, -0.03), (6.2, -0.03), (6.4, 0.0),
      (7.0, 0.0)]
NO_OEL = [(0.0, 0.0), (7.0, 0.0)]
# An OEL signal parked high, then brought below the error (the LV gate selects it), then back.
OEL = [(0.0, 1.0), (2.2, 1.0), (2.3, -0.02), (3.2, -0.02), (3.3, 1.0), (7.0, 1.0)]

CASES = {
    "mostar_like": dict(params=MOSTAR, oel_gate=False, efd0=2.0, voel=NO_OEL),
    "zero_time_constants": dict(
        params=dict(MOSTAR, t_r=0.0, t_c1=0.0, t_b1=2.0, t_c2=0.5, t_b2=0.0, k_r=200.0,
                    t_1=0.0, k_c=0.2),
        oel_gate=False, efd0=2.0, voel=NO_OEL),
    "oel_gate": dict(params=MOSTAR, oel_gate=True, efd0=2.0, voel=OEL),
}


def pwl(points):
    t = np.array([p[0] for p in points])
    v = np.array([p[1] for p in points])
    return lambda s: float(np.interp(s, t, v)), t


def clamp(v, lo, hi):
    return min(max(v, lo), hi)


class St5bRef:
    """The ST5B block on prescribed inputs, as a hybrid system."""

    def __init__(self, p, oel_gate, efd0, vt, ifd, vs, voel):
        self.p, self.oel_gate = p, oel_gate
        self.vt, self.ifd, self.vs, self.voel = vt, ifd, vs, voel
        self.lo, self.hi = p["vr_min"] / p["k_r"], p["vr_max"] / p["k_r"]
        self.tc = [p["t_c1"], p["t_c2"], p["t_uc1"], p["t_uc2"], p["t_oc1"], p["t_oc2"]]
        self.tb = [p["t_b1"], p["t_b2"], p["t_ub1"], p["t_ub2"], p["t_ob1"], p["t_ob2"]]
        # Initial steady state.
        vr0 = efd0 + p["k_c"] * ifd(0.0)
        assert p["vr_min"] <= vr0 <= p["vr_max"]
        assert vt(0.0) * p["vr_min"] <= efd0 <= vt(0.0) * p["vr_max"]
        u0 = vr0 / p["k_r"]
        v_l0 = u0 - vs(0.0)
        if oel_gate:
            assert voel(0.0) >= v_l0
            v_e0 = v_l0
        else:
            v_e0 = v_l0 - voel(0.0)
        self.v_ref = vt(0.0) + v_e0
        self.y = np.array([vt(0.0)] + [u0] * 6 + [efd0])
        self.ll_mode = [0] * 6      # pure lags: 0 free, +1 on the upper limit, -1 on the lower
        self.br_mode = 0            # bridge: same
        self.efd0 = efd0

    # --- algebra -------------------------------------------------------------------------------
    def pure(self, k):
        return self.tb[k] > 0.0 and self.tc[k] == 0.0

    def ll_out(self, k, x, u):
        if self.tb[k] == 0.0:
            return clamp(u, self.lo, self.hi)
        if self.pure(k):
            return {0: clamp(x, self.lo, self.hi), 1: self.hi, -1: self.lo}[self.ll_mode[k]]
        return clamp(x + self.tc[k] / self.tb[k] * (u - x), self.lo, self.hi)

    def inputs(self, t, y):
        p = self.p
        vm = y[0] if p["t_r"] > 0.0 else self.vt(t)
        v_e = self.v_ref - vm
        v_h = v_e  # no UEL in these cases (summing, 0)
        vo = self.voel(t)
        if self.oel_gate:
            path = 2 if vo < v_h else 0
            v_l = min(v_h, vo)
        else:
            path = 0
            v_l = v_h + vo
        return v_l + self.vs(t), path, v_h, vo

    def chain(self, t, y):
        u, path, v_h, vo = self.inputs(t, y)
        y1 = [self.ll_out(2 * k, y[1 + 2 * k], u) for k in range(3)]
        y2 = [self.ll_out(2 * k + 1, y[2 + 2 * k], y1[k]) for k in range(3)]
        vr = clamp(self.p["k_r"] * y2[path], self.p["vr_min"], self.p["vr_max"])
        return u, y1, vr, path, v_h, vo

    def limits(self, t):
        v = self.vt(t)
        return v * self.p["vr_min"], v * self.p["vr_max"]

    def efd(self, t, y):
        lo, hi = self.limits(t)
        if self.p["t_1"] == 0.0:
            _, _, vr, _, _, _ = self.chain(t, y)
            return clamp(vr - self.p["k_c"] * self.ifd(t), lo, hi)
        return {0: clamp(y[7], lo, hi), 1: hi, -1: lo}[self.br_mode]

    # --- dynamics ------------------------------------------------------------------------------
    def rhs(self, t, y, dvt):
        p = self.p
        d = np.zeros(8)
        if p["t_r"] > 0.0:
            d[0] = (self.vt(t) - y[0]) / p["t_r"]
        u, y1, vr, _, _, _ = self.chain(t, y)
        ins = [u, y1[0], u, y1[1], u, y1[2]]
        for k in range(6):
            if k >= 2 and not (self.oel_gate and k >= 4):
                continue  # the UEL pair is unused; the OEL pair only with its gate
            x = y[1 + k]
            if self.tb[k] == 0.0:
                continue
            if self.pure(k):
                d[1 + k] = 0.0 if self.ll_mode[k] != 0 else (ins[k] - x) / self.tb[k]
            else:
                w = x + self.tc[k] / self.tb[k] * (ins[k] - x)
                d[1 + k] = (clamp(w, self.lo, self.hi) - x) / self.tc[k]
        if p["t_1"] > 0.0:
            if self.br_mode == 0:
                d[7] = (vr - p["k_c"] * self.ifd(t) - y[7]) / p["t_1"]
            else:  # pinned: the state follows the moving limit exactly
                d[7] = dvt * (p["vr_max"] if self.br_mode == 1 else p["vr_min"])
        return d

    def event_functions(self):
        """Functions whose zero marks a mode change or a kink, for the current modes."""
        p, fs = self.p, []
        if p["t_1"] > 0.0:
            def bridge(t, y):
                lo, hi = self.limits(t)
                v = self.chain(t, y)[2] - p["k_c"] * self.ifd(t)
                if self.br_mode == 0:
                    return min(hi - y[7], y[7] - lo)
                return v - (hi if self.br_mode == 1 else lo)
            fs.append(bridge)
        for k in range(6):
            if self.pure(k):
                def lag(t, y, k=k):
                    u, y1, _, _, _, _ = self.chain(t, y)
                    inp = [u, y1[0], u, y1[1], u, y1[2]][k]
                    x = y[1 + k]
                    if self.ll_mode[k] == 0:
                        return min(self.hi - x, x - self.lo)
                    return inp - x
                fs.append(lag)
        if self.oel_gate:
            fs.append(lambda t, y: self.inputs(t, y)[3] - self.inputs(t, y)[2])
        for f in fs:
            f.terminal = True
        return fs

    def update_modes(self, t, y):
        p = self.p
        u, y1, vr, _, _, _ = self.chain(t, y)
        ins = [u, y1[0], u, y1[1], u, y1[2]]
        # On a limit (within TOL_AT) a block stays or gets pinned only while its input pushes
        # beyond the limit by more than TOL_PUSH: at a release event the input has just crossed
        # the limit and the difference is rounding.
        for k in range(6):
            if self.pure(k):
                x = y[1 + k]
                if x >= self.hi - TOL_AT and ins[k] > self.hi + TOL_PUSH:
                    self.ll_mode[k], y[1 + k] = 1, self.hi
                elif x <= self.lo + TOL_AT and ins[k] < self.lo - TOL_PUSH:
                    self.ll_mode[k], y[1 + k] = -1, self.lo
                else:
                    self.ll_mode[k], y[1 + k] = 0, clamp(x, self.lo, self.hi)
        if p["t_1"] > 0.0:
            lo, hi = self.limits(t)
            u, y1, vr, _, _, _ = self.chain(t, y)
            v = vr - p["k_c"] * self.ifd(t)
            e = y[7] if self.br_mode == 0 else (hi if self.br_mode == 1 else lo)
            # Decided at the output (the state clamped into the limits): a state above a ceiling
            # that fell below it is clipped to it, and pinned if the regulator pushes beyond it.
            if e >= hi - TOL_AT and v > hi + TOL_PUSH:
                self.br_mode, y[7] = 1, hi
            elif e <= lo + TOL_AT and v < lo - TOL_PUSH:
                self.br_mode, y[7] = -1, lo
            else:
                self.br_mode, y[7] = 0, clamp(e, lo, hi)
        return y

    # --- driver --------------------------------------------------------------------------------
    def run(self, knots, t_end):
        grid = np.round(np.arange(0.0, t_end + DT / 2, DT), 9)
        rows = {}
        y = self.update_modes(0.0, self.y.copy())
        edges = sorted(set(np.round(knots, 9)) | {0.0, t_end})
        n_events = 0
        for a, b in zip(edges[:-1], edges[1:]):
            dvt = (self.vt(b) - self.vt(a)) / (b - a)
            t = a
            masked = True  # after a start or an event, let the state leave the switching surface
            while t < b - 1e-13:
                fs = self.event_functions()
                if masked:
                    for tg in grid[np.abs(grid - t) < 1e-12]:
                        rows.setdefault(round(float(tg), 6), (self.efd(tg, y), self.chain(tg, y)[2]))
                    t_next = min(t + 1e-9, b)
                    sol = solve_ivp(lambda s, z: self.rhs(s, z, dvt), (t, t_next), y,
                                    method="DOP853", rtol=RTOL, atol=ATOL)
                    y, t, masked = sol.y[:, -1], t_next, False
                    continue
                sol = solve_ivp(lambda s, z: self.rhs(s, z, dvt), (t, b), y, method="DOP853",
                                rtol=RTOL, atol=ATOL, events=fs, dense_output=True)
                t_stop = sol.t[-1]
                for tg in grid[(grid >= t - 1e-12) & (grid <= t_stop + 1e-12)]:
                    z = sol.sol(tg) if tg <= t_stop else sol.y[:, -1]
                    rows[round(float(tg), 6)] = (self.efd(tg, z), self.chain(tg, z)[2])
                y, t = sol.y[:, -1].copy(), t_stop
                if sol.status == 1:
                    n_events += 1
                    y = self.update_modes(t, y)
                    masked = True
            y = self.update_modes(t, y)
        return grid, rows, n_events


def main() -> int:
    os.makedirs(DST, exist_ok=True)
    for name, c in CASES.items():
        vt, kv = pwl(VT)
        ifd, ki = pwl(IFD)
        vs, ks = pwl(VS)
        voel, ko = pwl(c["voel"])
        t_end = VT[-1][0]
        m = St5bRef(c["params"], c["oel_gate"], c["efd0"], vt, ifd, vs, voel)
        knots = np.concatenate([kv, ki, ks, ko])
        assert all(abs(k / DT - round(k / DT)) < 1e-9 for k in knots), "breakpoints on the grid"
        grid, rows, n_events = m.run(knots, t_end)
        with open(os.path.join(DST, f"{name}.json"), "w") as f:
            json.dump(dict(case=name, params=c["params"],
                           options=dict(oel="gate" if c["oel_gate"] else "summing"),
                           efd0=c["efd0"], v_ref=m.v_ref,
                           note="ST5B alone on prescribed inputs; tools/st5b_reference.py"),
                      f, indent=1)
        lo_hits = hi_hits = kc_hits = 0
        with open(os.path.join(DST, f"{name}.csv"), "w") as f:
            f.write("time_s,v_t,xadifd,vs,voel,efd,v_r\n")
            for tg in grid:
                efd, vr = rows[round(float(tg), 6)]
                p = c["params"]
                hi_hits += abs(efd - vt(tg) * p["vr_max"]) < 1e-9
                lo_hits += abs(efd - vt(tg) * p["vr_min"]) < 1e-9
                kc_hits += abs(vr - p["vr_max"]) < 1e-12
                f.write(f"{tg:.3f},{vt(tg):.12g},{ifd(tg):.12g},{vs(tg):.12g},{voel(tg):.12g},"
                        f"{efd:.12g},{vr:.12g}\n")
        print(f"{name}: {len(grid)} rows, {n_events} mode events; rows on V_t*VRMAX {hi_hits}, "
              f"on V_t*VRMIN {lo_hits}, with V_R = VRMAX {kc_hits}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
