"""The two runs of a case and the oracle playback.

* `run_grid` (stage A): the true unit, hidden effect included, against the Thevenin grid whose
  source carries the event; gives the physically consistent terminal voltage and P, Q.
* `playback_dense` (stage B): that terminal voltage (1 kHz, C2 spline of |V| and unwrapped angle)
  played back into the same unit; it must reproduce stage A's P, Q (a check of the network
  solution against the playback form of the same equations).
* `playback_record`: a recorded (noisy, sampled) terminal voltage played back as the tool does
  (linear between the stamps), the unit initialised from the record's first second, with the
  two set-point offsets V_ref, n_ref; `oracle` fits them (the floor of the answer keys)."""

from __future__ import annotations

import cmath
import copy
import math

import numpy as np
from scipy.integrate import solve_ivp

from . import signals as S
from .events import FS, grid_signals
from .unit import TrueUnit

RTOL = 1e-8
ATOL = 1e-10
MAX_STEP = 0.02  # s: below the shortest event pulse, so no step passes over one unseen
INIT_S = 1.0  # the pre-event window the playback is initialised from [s]


def _solve(unit, t_end, t_eval, max_step=np.inf):
    sol = solve_ivp(unit.rhs, (0.0, t_end), unit.x0, method="LSODA", t_eval=t_eval,
                    rtol=RTOL, atol=ATOL, max_step=max_step)
    if sol.status != 0:
        raise RuntimeError(f"integration failed: {sol.message}")
    return sol


def machine_pq(unit: TrueUnit, P_sys, Q_sys, V0):
    """Machine-terminal P, Q (machine base) from the PMU's (system base), adding back a
    terminal load inside the measurement."""
    k = unit.sys_mva / unit.mva
    return P_sys * k + unit.yl.real * V0 * V0, Q_sys * k - unit.yl.imag * V0 * V0


def attach_noise_sources(unit: TrueUnit, duration: float):
    """Builds the time signals an effect carries (torque noise of a shaft, AGC set-point
    moves) from the spec."""
    ext = unit.ext
    n = int(round((duration + 1.0) * FS)) + 1
    if "shaft" in ext and ext["shaft"].get("torque_noise"):
        tn = ext["shaft"]["torque_noise"]
        rng = np.random.default_rng(tn["seed"])
        w = tn["sd"] * S.bandpass_noise(rng, n, FS, tn["f_lo"], tn["f_hi"])
        unit.torque_noise = S.UniformSpline(0.0, 1.0 / FS, w)
    if "agc" in ext:
        a = ext["agc"]
        tt = np.arange(n) / FS
        y = np.zeros(n)
        for st in a["moves"]:
            # each move: the gate set point ramps by `dgate` from `t` over `dur` seconds
            y += st["dgate"] * S.smooth_ramp(tt, st["t"], st["dur"], min(1.0, 0.3 * st["dur"]))
        unit.agc = S.UniformSpline(0.0, 1.0 / FS, y)


def run_grid(spec: dict, op: dict, grid: dict, event: dict, duration: float, t_out: np.ndarray):
    """Stage A. `op`: P_sys, Q_sys (at the PMU), V0, theta0 (rad), f0_hz. `grid`: R_e, X_e
    (machine base). Returns (unit, outputs dict of arrays at t_out, source info)."""
    unit = TrueUnit(spec)
    dw0 = (op["f0_hz"] - unit.fn) / unit.fn
    Pm, Qm = machine_pq(unit, op["P_sys"], op["Q_sys"], op["V0"])
    unit.init(Pm, Qm, op["V0"], op["theta0"], dw0)
    V = cmath.rect(op["V0"], op["theta0"])
    Im = unit.I0
    Ig = Im - unit.yl * V
    Ze = complex(grid["R_e"], grid["X_e"])
    Eg0 = V - Ze * Ig
    tt, m, phi, z = grid_signals(event, duration, event["amb_seed"])
    sm = S.UniformSpline(0.0, 1.0 / FS, m)
    sp = S.UniformSpline(0.0, 1.0 / FS, phi)
    zf = S.UniformSpline(0.0, 1.0 / FS, z) if np.any(z != 1.0) else None
    E0, th_g0, wb = abs(Eg0), cmath.phase(Eg0), unit.wb
    unit.set_grid(lambda t: E0 * (1.0 + sm(t)), lambda t: th_g0 + wb * dw0 * t + sp(t), zf,
                  grid["R_e"], grid["X_e"])
    attach_noise_sources(unit, duration)
    d0 = unit.rhs(0.0, unit.x0)
    d0[0] -= wb * dw0
    init_deriv = max(abs(v) for v in d0)
    sol = _solve(unit, float(t_out[-1]), t_out, max_step=MAX_STEP)
    out = evaluate(unit, t_out, sol.y)
    info = {"Vg0": [Eg0.real, Eg0.imag], "init_max_abs_derivative": init_deriv,
            "nfev": int(sol.nfev)}
    return unit, out, info


def evaluate(unit: TrueUnit, t: np.ndarray, y: np.ndarray) -> dict:
    """Outputs at the times `t` of the states `y` (n_states x len(t))."""
    keys = ("vr", "vi", "P", "Q", "Vt", "Efd", "XadIfd", "dw", "It", "VS", "Pe")
    res = {k: np.empty(len(t)) for k in keys}
    for j, tj in enumerate(t):
        o = unit.outputs(float(tj), y[:, j])
        vr, vi, P, Q = unit.measured(o)
        res["vr"][j], res["vi"][j], res["P"][j], res["Q"][j] = vr, vi, P, Q
        res["Vt"][j], res["Efd"][j], res["XadIfd"][j], res["dw"][j] = o["Vt"], o["Efd"], o["XadIfd"], o["dw"]
        res["It"][j] = math.hypot(o["id"], o["iq"])
        res["VS"][j] = o["VS"]
        res["Pe"][j] = o["P"]
    return res


def playback_dense(spec: dict, op_state: dict, t_dense: np.ndarray, vr: np.ndarray, vi: np.ndarray,
                   t_out: np.ndarray, duration: float):
    """Stage B: plays stage A's terminal voltage (on the uniform grid `t_dense`) back into the
    unit initialised at the same operating point; P, Q (PMU, system base) at `t_out`."""
    unit = TrueUnit(spec)
    dw0 = (op_state["f0_hz"] - unit.fn) / unit.fn
    Pm, Qm = machine_pq(unit, op_state["P_sys"], op_state["Q_sys"], op_state["V0"])
    unit.init(Pm, Qm, op_state["V0"], op_state["theta0"], dw0)
    mag = np.hypot(vr, vi)
    ang = np.unwrap(np.arctan2(vi, vr))
    dt = t_dense[1] - t_dense[0]
    sm = S.UniformSpline(float(t_dense[0]), dt, mag)
    sa = S.UniformSpline(float(t_dense[0]), dt, ang)
    unit.set_playback(sm, sa)
    attach_noise_sources(unit, duration)
    sol = _solve(unit, float(t_out[-1]), t_out, max_step=MAX_STEP)
    return evaluate(unit, t_out, sol.y)


def init_estimate(t, vr, vi, p, q, freq):
    """The pre-event operating point from the record's first second: mean |V|, P, Q, the angle
    of a least-squares line through the unwrapped angle evaluated at the first stamp, the mean
    of the frequency channel (or the line's slope without one)."""
    sel = t <= t[0] + INIT_S + 1e-9  # inclusive, as the engine's init window
    ang = np.unwrap(np.arctan2(vi, vr))
    ts, a = t[sel], ang[sel]
    slope, icpt = np.polyfit(ts - ts.mean(), a, 1)
    th0 = icpt + slope * (t[0] - ts.mean())
    return {
        "n_samples": int(sel.sum()),
        "V0": float(np.mean(np.hypot(vr[sel], vi[sel]))),
        "theta0": float(th0),
        "P_sys": float(np.mean(p[sel])),
        "Q_sys": float(np.mean(q[sel])),
        "f0_hz": float(np.mean(freq[sel])) if freq is not None else None,
        "slope": float(slope),
    }


def playback_record(spec: dict, rec: dict, offsets=(0.0, 0.0), skew=0.0, vratio=1.0,
                    t_start=None):
    """P, Q (system base, at the PMU) of the unit `spec` driven by the record's voltage
    (linear between the stamps, divided by `vratio`), initialised from its first second;
    the P/Q channels delayed by `skew` seconds. `rec`: t, vr, vi, p, q, freq (arrays)."""
    unit = TrueUnit(spec)
    t = rec["t"]
    vr, vi = rec["vr"] / vratio, rec["vi"] / vratio
    est = init_estimate(t, vr, vi, rec["p"], rec["q"], rec.get("freq"))
    f0 = est["f0_hz"] if est["f0_hz"] is not None else unit.fn + est["slope"] / (2 * math.pi)
    dw0 = (f0 - unit.fn) / unit.fn
    Pm, Qm = machine_pq(unit, est["P_sys"], est["Q_sys"], est["V0"])
    unit.init(Pm, Qm, est["V0"], est["theta0"], dw0)
    unit.offsets = [offsets[0], offsets[1]]
    mag = np.hypot(vr, vi)
    ang = np.unwrap(np.arctan2(vi, vr))
    t0 = float(t[0])
    unit.set_playback(S.LinearTable(t - t0, mag), S.LinearTable(t - t0, ang))
    duration = float(t[-1] - t0)
    attach_noise_sources(unit, duration)
    tq = np.clip(t - t0 - skew, 0.0, None)
    te = np.unique(np.concatenate([t - t0, tq]))
    # One solve per interval between stamps: the input is linear there and kinks at the stamps,
    # which a single long solve would cross with repeated step rejections.
    y = np.empty((unit.n, len(te)))
    y[:, 0] = unit.x0
    for k in range(len(te) - 1):
        h = te[k + 1] - te[k]
        sol = solve_ivp(unit.rhs, (te[k], te[k + 1]), y[:, k], method="LSODA", rtol=RTOL,
                        atol=ATOL, first_step=h / 4)
        if sol.status != 0:
            raise RuntimeError(f"integration failed: {sol.message}")
        y[:, k + 1] = sol.y[:, -1]
    res = evaluate(unit, te, y)
    P = np.interp(tq, te, res["P"])
    Q = np.interp(tq, te, res["Q"])
    return P, Q, est, res


def oracle(spec: dict, rec: dict, sd_p: float, sd_q: float, skew=0.0, vratio=1.0):
    """The floor: the record played back through `spec` with the two set-point offsets fitted
    (two Gauss-Newton steps on P, Q from zero offsets with the forward-difference Jacobian at
    zero: the offsets act almost linearly)."""
    p, q = rec["p"], rec["q"]

    def resid(th):
        P, Q, est, _ = playback_record(spec, rec, th, skew, vratio)
        return np.concatenate([P - p, Q - q]), est

    th = np.zeros(2)
    r0, est = resid(th)
    h = np.array([1e-4, 1e-4])
    Jm = np.empty((len(r0), 2))
    for k in range(2):
        d = th.copy()
        d[k] += h[k]
        Jm[:, k] = (resid(d)[0] - r0) / h[k]
    best = (float(r0 @ r0), th.copy(), r0)
    r = r0
    for _ in range(2):
        step, *_ = np.linalg.lstsq(Jm, -r, rcond=None)
        cand = best[1] + step
        rc, _ = resid(cand)
        if float(rc @ rc) < best[0]:
            best = (float(rc @ rc), cand, rc)
            r = rc
        else:
            break
    n = len(p)
    rp, rq = best[2][:n], best[2][n:]
    return {"P": stats(rp, sd_p, rec["t"]), "Q": stats(rq, sd_q, rec["t"]),
            "fitted_offsets": {"Vref": float(best[1][0]), "nref": float(best[1][1])},
            "init_estimate": est}


def stats(r: np.ndarray, sd: float, t: np.ndarray) -> dict:
    rms = float(np.sqrt(np.mean(r * r)))
    # the largest RMS over any one-second window of samples
    m1 = 0.0
    j = 0
    for i in range(len(t)):
        while t[i] - t[j] > 1.0:
            j += 1
        if t[i] - t[0] >= 1.0 or i == len(t) - 1:
            m1 = max(m1, float(np.sqrt(np.mean(r[j : i + 1] ** 2))))
    return {"rms": rms, "max_abs": float(np.max(np.abs(r))), "max_rms_1s": m1,
            "rms_over_noise": rms / sd}


def spec_copy(spec: dict) -> dict:
    return copy.deepcopy(spec)
