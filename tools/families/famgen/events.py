"""The grid the unit runs against: a Thevenin source E_g(t) behind R_e + jX_e, whose magnitude,
angle and (for line trips) impedance carry the event and an ambient background.

Every event is a list of primitive disturbances with all their parameters explicit (drawn in
`families.py`, recorded in the answer key); `grid_signals` turns them into sampled signals on a
1 kHz grid that the simulation splines:

* `m(t)`: relative change of |E_g| (|E_g| = E_g0 (1 + m));
* `phi(t)`: change of the source angle [rad] on top of the pre-event frequency's ramp;
* `z(t)`: factor on the Thevenin impedance (1 except during a line outage).
All three are 0 (1 for z) at t = 0, so the unit starts in exact steady state."""

from __future__ import annotations

import math

import numpy as np

from . import signals as S

FS = 1000.0  # Hz, the grid on which the source signals are sampled and splined


def _freq_dip(tt: np.ndarray, t0: float, df_nadir: float, t_nadir: float, ss_ratio: float):
    """Grid frequency deviation [Hz] after a loss of generation at t0: a second-order response
    that reaches -df_nadir at t0 + t_nadir and settles at -ss_ratio*df_nadir."""
    os_ = 1.0 / ss_ratio - 1.0
    lo = math.log(os_)
    zeta = -lo / math.sqrt(math.pi**2 + lo * lo)
    wd = math.pi / t_nadir
    wn = wd / math.sqrt(1 - zeta * zeta)
    ss = df_nadir * ss_ratio
    tp = np.clip(tt - t0, 0.0, None)
    resp = 1 - np.exp(-zeta * wn * tp) * (np.cos(wd * tp) + zeta / math.sqrt(1 - zeta**2) * np.sin(wd * tp))
    return -ss * resp * (tt >= t0)


def _swing(tt: np.ndarray, t0: float, shift: float, f: float, zeta: float):
    """A damped angle swing to a new angle `shift` [rad] after t0 (a second-order step
    response: the grid angle moving to its post-event value)."""
    wn = 2 * math.pi * f / math.sqrt(1 - zeta * zeta)
    wd = 2 * math.pi * f
    tp = np.clip(tt - t0, 0.0, None)
    resp = 1 - np.exp(-zeta * wn * tp) * (np.cos(wd * tp) + zeta / math.sqrt(1 - zeta**2) * np.sin(wd * tp))
    return shift * resp * (tt >= t0)


def grid_signals(event: dict, duration: float, seed_amb: int):
    """(t, m, phi, z) sampled at FS over [0, duration + 1] for the `event` dict
    {"primitives": [...], "amb": {...}}."""
    n = int(round((duration + 1.0) * FS)) + 1
    tt = np.arange(n) / FS
    m = np.zeros(n)
    phi = np.zeros(n)
    z = np.ones(n)
    df = np.zeros(n)  # grid frequency deviation [Hz] from the events (integrated into phi)
    amb = event["amb"]
    rng = np.random.default_rng(seed_amb)
    # Ambient background: |V| noise, frequency wander, an inter-area angle oscillation.
    m += amb["sd_m"] * S.lowpass_noise(rng, n, FS, amb.get("f_m", 2.0))
    df += amb["sd_f"] * S.ou_process(rng, n, 1.0 / FS, amb["tau_f"])
    phi += math.radians(amb["ia_amp_deg"]) * S.resonant_noise(rng, n, 1.0 / FS, amb["f_ia"], amb["zeta_ia"])
    for p in event["primitives"]:
        k = p["kind"]
        if k == "fault":
            # Voltage dip with a phase jump during the fault; after clearing a voltage change
            # recovering with tau, an angle swing and (loss of generation) a frequency dip.
            pu = S.pulse(tt, p["t"], p["dur"], p["edge"])
            m -= p["dip"] * pu
            phi += math.radians(p["phase_jump_deg"]) * pu
            tc = p["t"] + 2 * p["edge"] + p["dur"]
            post = S.smooth_step(tt, tc - p["edge"], p["edge"])
            m += p["post_dv"] * post * np.exp(-np.clip(tt - tc, 0, None) / p["post_tau"])
            phi += _swing(tt, tc, math.radians(p["swing_shift_deg"]), p["swing_f"], p["swing_zeta"])
            if p.get("f_nadir", 0.0) > 0:
                df += _freq_dip(tt, tc, p["f_nadir"], p["t_nadir"], p["f_ss_ratio"])
        elif k == "freq":
            df += _freq_dip(tt, p["t"], p["f_nadir"], p["t_nadir"], p["f_ss_ratio"])
            m += p.get("dv", 0.0) * S.smooth_step(tt, p["t"], p["edge"])
        elif k == "vstep":
            m += p["dv"] * S.smooth_step(tt, p["t"], p["edge"])
            phi += math.radians(p.get("dphi_deg", 0.0)) * S.smooth_step(tt, p["t"], p["edge"])
        elif k == "ramp":
            m += p["dv"] * S.smooth_ramp(tt, p["t"], p["dur"], p["corner"])
        elif k == "trip":
            # A line out of a double circuit: the Thevenin impedance rises by `z_factor` at
            # t (after an optional fault dip on that line), and the line recloses after
            # `t_out` seconds.
            t_trip = p["t"]
            if p.get("fault_dip", 0.0) > 0:
                pu = S.pulse(tt, p["t"], p["fault_dur"], p["edge"])
                m -= p["fault_dip"] * pu
                t_trip = p["t"] + p["fault_dur"] + p["edge"]
            out = S.smooth_step(tt, t_trip, p["edge"]) - S.smooth_step(tt, t_trip + p["t_out"], p["edge"])
            z += (p["z_factor"] - 1.0) * out
        else:
            raise ValueError(f"unknown event primitive {k}")
    df -= df[0]
    phi += 2 * math.pi * np.cumsum(df) / FS
    m -= m[0]
    phi -= phi[0]
    return tt, m, phi, z


def describe(event: dict) -> str:
    """A sentence per primitive, for the answer key and the README."""
    out = []
    for p in event["primitives"]:
        k = p["kind"]
        if k == "fault":
            out.append(
                f"fault-like dip at t={p['t']:.2f} s: grid voltage down {100 * p['dip']:.0f} % for "
                f"{1000 * p['dur']:.0f} ms (edges {1000 * p['edge']:.0f} ms), phase jump "
                f"{p['phase_jump_deg']:+.1f} deg; after clearing the grid voltage changes by "
                f"{100 * p['post_dv']:+.1f} % (recovering with tau {p['post_tau']:.1f} s), the grid "
                f"angle swings to {p['swing_shift_deg']:+.1f} deg at {p['swing_f']:.2f} Hz "
                f"(zeta {p['swing_zeta']:.2f})"
                + (f" and the grid frequency falls by {p['f_nadir']:.3f} Hz (nadir {p['t_nadir']:.1f} s after)"
                   if p.get("f_nadir", 0) > 0 else ""))
        elif k == "freq":
            out.append(f"loss of generation elsewhere at t={p['t']:.2f} s: grid frequency down "
                       f"{p['f_nadir']:.3f} Hz at the nadir ({p['t_nadir']:.1f} s after), settling at "
                       f"{p['f_ss_ratio']:.2f} of it")
        elif k == "vstep":
            out.append(f"grid voltage step {100 * p['dv']:+.2f} % at t={p['t']:.2f} s (edge {1000 * p['edge']:.0f} ms)")
        elif k == "ramp":
            out.append(f"slow grid voltage ramp {100 * p['dv']:+.2f} % from t={p['t']:.1f} s over {p['dur']:.1f} s")
        elif k == "trip":
            pre = (f"a fault dip of {100 * p['fault_dip']:.0f} % for {1000 * p['fault_dur']:.0f} ms, then "
                   if p.get("fault_dip", 0) > 0 else "")
            out.append(f"line trip at t={p['t']:.2f} s: {pre}the Thevenin impedance x{p['z_factor']:.2f} "
                       f"for {p['t_out']:.2f} s until the line recloses (edges {1000 * p['edge']:.0f} ms)")
    a = event["amb"]
    out.append(f"ambient background: |V| sd {100 * a['sd_m']:.2f} %, frequency wander sd "
               f"{1000 * a['sd_f']:.1f} mHz (tau {a['tau_f']:.0f} s), inter-area angle oscillation "
               f"{a['ia_amp_deg']:.2f} deg rms at {a['f_ia']:.2f} Hz")
    return "; ".join(out)


def onsets(event: dict) -> list[float]:
    """Start times of the disturbances (for the key's timing)."""
    return [p["t"] for p in event["primitives"]]
