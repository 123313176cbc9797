"""One case: draw the true unit, the nominal errors, the operating point, the grid, the event
and the effect from the case's seed; run the unit against the grid (stage A), check the playback
form (stage B), put the PMU chain on it, compute the oracle floors, write the files."""

from __future__ import annotations

import copy
import json
import math
import os
import time

import numpy as np

from . import events as EV
from . import pmu as PMU
from . import sim
from .units import BASES

GENERATOR_VERSION = "families-1.0"

# effect type -> the catalog cause a diagnosis should name (outside the catalog: unexplained)
CATALOG = {
    "none": "none",
    "torsional": "torsional_mode",
    "exciter_ceiling": "exciter_limit",
    "saturation": "saturation",
    "governor_deadband": "governor",
    "measurement_skew": "measurement_skew",
    "terminal_load": "terminal_load",
    "pss_missing": "pss_state",
    "oel": "oel",
}

WHERE = {
    "none": "nothing hidden (only noise and nominal parameter errors)",
    "torsional": "truth dynamics (two-mass shaft replaces the single rotor mass)",
    "exciter_ceiling": "truth dynamics (exciter upper limit lower than nominal / bus-fed)",
    "saturation": "truth dynamics (machine S10/S12 much stronger than nominal)",
    "governor_deadband": "truth dynamics (HYGOV speed deadband)",
    "measurement_skew": "measurement chain (P/Q channels delayed against the V channel)",
    "terminal_load": "measurement chain + network (constant-impedance load between the generator and the PMU current measurement)",
    "pss_missing": "truth dynamics (PSS in service status differs from the nominal model)",
    "oel": "truth dynamics (inverse-time over-excitation limiter at the exciter summing point)",
    "plant_q": "truth dynamics (plant-level reactive-power / HV-voltage controller, slow integral action on the AVR set point)",
    "agc": "truth dynamics (AGC / load-controller moves of the governor's gate set point during the record)",
    "vhz": "truth dynamics (volts-per-hertz limiter at the AVR summing point)",
    "scl": "truth dynamics (inverse-time stator-current limiter at the AVR summing point, acting in the over-excited region)",
    "penstock": "truth dynamics (elastic water column: the penstock as lumped travelling-wave sections instead of HYGOV's rigid column)",
    "rotating_exciter": "truth dynamics (a rotating DC exciter with its own field time constant and saturation between the regulator and the field, in place of SEXS's fast static stage)",
    "backlash": "truth dynamics (backlash in the gate linkage: hysteresis between servo and effective gate)",
    "pss_limit": "truth dynamics (PSS output limiter asymmetric, one side much tighter than the nominal V_LIM)",
    "vt_ratio": "measurement chain (the PMU voltage channel carries a VT ratio error; P and Q from separate transducers)",
}

SIGNATURE = {
    "none": "No hidden effect: after calibration the residual should be white noise. Correct answer: no model extension needed (no false alarm).",
    "torsional": "A lightly damped torsional mode (several Hz) in P, excited by the event and kept alive by hydraulic torque noise on the runner.",
    "exciter_ceiling": "E_fd clipped during the dip: Q recovers more slowly than a linear AVR predicts.",
    "saturation": "More field current for the same flux: the steady Efd and the size of the field response differ from the unsaturated model.",
    "governor_deadband": "Small frequency deviations get no governor response; P follows only beyond the band.",
    "measurement_skew": "P and Q lag the voltage by a fixed delay of 1.5-2 samples.",
    "terminal_load": "Part of the generator's output goes into a constant-impedance load inside the measurement: P and Q move with |V|^2.",
    "pss_missing": "The PSS's damping contribution is absent (or present) against the nominal model.",
    "oel": "Seconds after the event the field current is pulled back to its limit: Q falls slowly while |V| stays low.",
}

ROUND_SIG = 5


def sig(x: float, n: int = ROUND_SIG) -> float:
    if x == 0:
        return 0.0
    return float(f"{x:.{n}g}")


def u(rng, lo, hi):
    return float(rng.uniform(lo, hi))


# ----------------------------------------------------------------------------- draws
def draw_unit(rng, base):
    """True unit: each calibratable parameter of the base scaled by U(0.9, 1.1), X''q = X''d."""
    truth = {s: copy.deepcopy(base[s]) for s in ("machine", "exciter", "pss", "governor")}
    for sec, k in base["free"]:
        truth[sec][k] = sig(base[sec][k] * u(rng, 0.9, 1.1))
    truth["machine"]["Xppq"] = truth["machine"]["Xppd"]
    return truth


def valid_machine(m) -> bool:
    return (m["Xd"] > m["Xpd"] > m["Xppd"] > m["Xl"] and m["Xq"] > m["Xppd"] and m["Xd"] >= m["Xq"]
            and m["Xpd"] - m["Xppd"] > 0.02)


def draw_nominal_errors(rng, base, truth, n_err=4):
    """Four of the calibratable parameters off by 20-50 % (either sign), the nominal machine
    still a valid one."""
    free = base["free"]
    for _ in range(1000):
        picks = rng.choice(len(free), size=n_err, replace=False)
        errs = {}
        nominal = copy.deepcopy(truth)
        for j in picks:
            sec, k = free[j]
            rel = u(rng, 0.2, 0.5) * (1 if rng.random() < 0.5 else -1)
            val = float(f"{truth[sec][k] * (1 + rel):.4g}")
            nominal[sec][k] = val
            errs[f"{sec}.{k}"] = {"true": truth[sec][k], "nominal": val,
                                  "rel_error": round(val / truth[sec][k] - 1, 4)}
        nominal["machine"]["Xppq"] = nominal["machine"]["Xppd"]
        ok = valid_machine(nominal["machine"])
        if "TA_TB" in nominal["exciter"]:
            ok = ok and nominal["exciter"]["TA_TB"] < 1.0
        if "TC" in nominal["exciter"]:
            ok = ok and nominal["exciter"]["TC"] < nominal["exciter"]["TB"]
        if ok:
            return nominal, errs
    raise RuntimeError("no valid nominal draw")


def draw_amb(rng, scale=1.0):
    return {"sd_m": u(rng, 0.0002, 0.0006) * scale, "sd_f": u(rng, 0.002, 0.005) * scale,
            "tau_f": u(rng, 8, 20), "ia_amp_deg": u(rng, 0.03, 0.12) * scale,
            "f_ia": u(rng, 0.3, 0.9), "zeta_ia": u(rng, 0.05, 0.12)}


def draw_primitive(rng, kind, t, edge, over=None):
    over = over or {}
    if kind == "fault":
        p = {"kind": "fault", "t": t, "dip": u(rng, 0.35, 0.6), "dur": u(rng, 0.06, 0.12),
             "edge": edge, "phase_jump_deg": u(rng, -15, 5), "post_dv": u(rng, -0.03, 0.01),
             "post_tau": u(rng, 5, 15), "swing_shift_deg": u(rng, -10, 10),
             "swing_f": u(rng, 0.5, 1.2), "swing_zeta": u(rng, 0.08, 0.2),
             "f_nadir": u(rng, 0.05, 0.25), "t_nadir": u(rng, 2, 5), "f_ss_ratio": u(rng, 0.6, 0.8)}
    elif kind == "freq":
        p = {"kind": "freq", "t": t, "f_nadir": u(rng, 0.1, 0.3), "t_nadir": u(rng, 3, 8),
             "f_ss_ratio": u(rng, 0.6, 0.8), "dv": u(rng, -0.005, 0.002), "edge": max(edge, 0.5)}
    elif kind == "vstep":
        p = {"kind": "vstep", "t": t, "dv": u(rng, 0.02, 0.05) * (1 if rng.random() < 0.5 else -1),
             "dphi_deg": u(rng, -2, 2), "edge": edge}
    elif kind == "ramp":
        p = {"kind": "ramp", "t": t, "dur": u(rng, 8, 20),
             "dv": u(rng, 0.02, 0.04) * (1 if rng.random() < 0.5 else -1), "corner": 1.0}
    elif kind == "trip":
        p = {"kind": "trip", "t": t, "z_factor": u(rng, 1.4, 2.0), "t_out": u(rng, 0.6, 1.5),
             "edge": edge, "fault_dip": 0.0, "fault_dur": 0.0}
    else:
        raise ValueError(kind)
    p.update(over)
    return p


def draw_event(rng, ev, rate, duration):
    """The event of a case from its description `ev`: {"kind": ..., "over": {...}} or
    {"primitives": [{"kind": ..., "t": ..., "over": ...}, ...]} with "amb_scale"."""
    edge = max(2.5 / rate, 0.04)
    prims = []
    if "primitives" in ev:
        for pr in ev["primitives"]:
            t = pr.get("t", u(rng, 2.5, 4.0))
            prims.append(draw_primitive(rng, pr["kind"], t, edge, pr.get("over")))
    elif ev["kind"] != "ambient":
        prims.append(draw_primitive(rng, ev["kind"], ev.get("t", u(rng, 2.5, 4.0)), edge, ev.get("over")))
    amb = draw_amb(rng, ev.get("amb_scale", 1.0))
    return {"primitives": prims, "amb": amb, "amb_seed": int(rng.integers(1, 2**31 - 1))}


# ----------------------------------------------------------------------------- the case
class Case:
    def __init__(self, cs: dict):
        self.cs = cs
        self.rng = np.random.default_rng(cs["seed"])
        self.base = BASES[cs.get("unit", "practice")]

    def spec(self, units: dict, ext=None, mc=None) -> dict:
        b = self.base
        s = {"machine_mva": b["machine_mva"], "system_mva": b["system_mva"], "fn_hz": b["fn_hz"]}
        for k in ("machine", "exciter", "pss", "governor"):
            s[k] = copy.deepcopy(units[k])
        s["ext"] = copy.deepcopy(ext or {})
        s["mc"] = copy.deepcopy(mc or {})
        return s

    def build(self):
        cs, rng, b = self.cs, self.rng, self.base
        t_start = time.time()
        truth = draw_unit(rng, b)
        nominal, nom_errs = draw_nominal_errors(rng, b, truth)
        rate = float(cs["rate"])
        T = float(cs["duration"])
        opo = cs.get("op", {})
        op = {"P_sys": u(rng, *opo.get("P_sys", b["P_sys"])),
              "Q_sys": u(rng, *opo.get("Q_sys", b["Q_sys"])),
              "V0": u(rng, *opo.get("V0", b["V0"])),
              "theta0": u(rng, -math.pi, math.pi),
              "f0_hz": b["fn_hz"] + u(rng, -b["df0_hz"], b["df0_hz"])}
        xe = u(rng, *b["X_e"])
        grid = {"R_e": xe / 50.0, "X_e": xe}
        event = draw_event(rng, cs["event"], rate, T)
        eff = cs.get("effect", {"type": "none"})
        etype = eff["type"]
        noise = copy.deepcopy(b["noise"])
        noise.update(cs.get("noise", {}))
        scale = eff.get("scale", 1.0)
        # sample stamps (P/Q possibly earlier than V: measurement skew)
        n = int(round(T * rate))
        ts = np.arange(n) / rate
        skew = 0.0
        ext, mc = {}, {}
        truth_eff = copy.deepcopy(truth)  # the true unit with the effect's parameter changes
        params = {}
        variant = eff.get("variant")
        # ---------------- effects that need no trajectory of the unit without them
        if etype == "torsional":
            fmax = min(14.0, 0.45 * rate)
            params = {"Ht_frac": round(u(rng, 0.08, 0.15), 3), "f_tor_hz": round(u(rng, 6.0, fmax), 2),
                      "zeta": round(u(rng, 0.001, 0.004), 4),
                      "torque_noise_sd": round(u(rng, 0.008, 0.015) * scale, 4),
                      "torque_noise_seed": int(rng.integers(1, 2**31 - 1))}
            ext["shaft"] = {"Ht_frac": params["Ht_frac"], "f_tor_hz": params["f_tor_hz"],
                            "zeta": params["zeta"],
                            "torque_noise": {"sd": params["torque_noise_sd"], "f_lo": 2.0,
                                             "f_hi": min(20.0, 0.45 * rate * 1.5),
                                             "seed": params["torque_noise_seed"]}}
        elif etype == "saturation":
            m0 = truth["machine"]
            s10 = sig(m0["S10"] * (1 + scale * u(rng, 0.7, 1.5)), 3)
            s12 = sig(m0["S12"] * (1 + scale * u(rng, 1.5, 2.4)), 3)
            truth_eff["machine"]["S10"], truth_eff["machine"]["S12"] = s10, s12
            params = {"S10": s10, "S12": s12, "S10_nominal": m0["S10"], "S12_nominal": m0["S12"]}
        elif etype == "governor_deadband":
            db = round(u(rng, 0.0003, 0.0005) * scale, 6)
            ext["govdb"] = {"db": db}
            params = {"db": db, "db_hz": round(db * b["fn_hz"], 5)}
        elif etype == "measurement_skew":
            samples = round(u(rng, 1.5, 2.0) * scale, 3)
            skew = samples / rate
            mc["skew_s"] = skew
            params = {"samples": samples, "skew_s": skew}
        elif etype == "terminal_load":
            k = b["machine_mva"] / b["system_mva"]
            pl = round(u(rng, 0.03, 0.06) * scale * k, 4)
            ql = round(u(rng, 0.015, 0.04) * scale * k, 4)
            mc["load_P"], mc["load_Q"] = pl, ql
            params = {"P_L": pl, "Q_L": ql, "base": "system, at |V| = 1"}
        elif etype == "pss_missing":
            if variant == "truth_off":
                truth_eff["pss"]["in_service"] = False
            else:
                nominal["pss"]["in_service"] = False
                truth["pss"]["in_service"] = False  # the unit without the effect: as the nominal
        elif etype == "plant_q":
            p = dict(eff["params"])
            params = p
            ext["plant_q"] = p
        elif etype == "agc":
            ext["agc"] = copy.deepcopy(eff["params"])
            params = copy.deepcopy(eff["params"])
        elif etype == "penstock":
            ext["penstock"] = {"sections": 6, "Te": eff["params"]["Te"]}
            params = {"sections": 6, "Te": eff["params"]["Te"],
                      "Zn": round(truth["governor"]["Tw"] / eff["params"]["Te"], 3),
                      "quarter_wave_hz": round(1.0 / (4.0 * eff["params"]["Te"]), 3)}
        elif etype == "rotating_exciter":
            params = dict(eff["params"])
            ext["rotating_exciter"] = params
        elif etype == "backlash":
            params = {"b": eff["params"]["b"], "start": round(u(rng, -0.5, 0.5), 3)}
            ext["backlash"] = params
        elif etype == "pss_limit":
            params = dict(eff["params"])
            ext["pss_limit"] = params
        elif etype == "vt_ratio":
            params = dict(eff["params"])
            mc["v_ratio"] = params["k"]
        # ---------------- effects sized on the trajectory of the unit without them
        needs_ref = etype in ("exciter_ceiling", "oel", "scl", "vhz")
        t_onset = min(EV.onsets(event)) if event["primitives"] else 0.0
        if needs_ref:
            spec0 = self.spec(truth, {}, {})
            _, ref, _ = sim.run_grid(spec0, op, grid, event, T, ts)
            i_ev = ts >= t_onset
            if etype == "exciter_ceiling":
                efd0 = ref["Efd"][0]
                efd_max = float(ref["Efd"].max())
                # the ceiling keeps this fraction of the forcing the unit would reach without it
                reach = round(min(0.9, u(rng, 0.4, 0.65) / min(max(scale, 0.3), 1.5)), 3)
                ceil = efd0 + reach * (efd_max - efd0)
                if b["name"] == "other" or variant == "bus_fed":
                    kc = truth["exciter"].get("KC", 0.1) if b["name"] == "other" else 0.1
                    k = int(np.argmax(ref["Efd"]))
                    vrmax = (ceil + kc * ref["XadIfd"][k]) / ref["Vt"][k]
                    ext["ceiling"] = {"mode": "bus_fed", "VRMAX": round(vrmax, 5), "KC": kc}
                    params = {"reach_frac": reach, "KC": kc, "Efd0": efd0,
                              "Efd_max_without_limit": efd_max, "VRMAX": round(vrmax, 5),
                              "ceiling_at_t0": op["V0"] * vrmax - kc * ref["XadIfd"][0]}
                else:
                    ext["ceiling"] = {"mode": "constant", "EMAX": round(ceil, 5)}
                    params = {"reach_frac": reach, "Efd0": efd0, "Efd_max_without_limit": efd_max,
                              "EMAX": round(ceil, 5)}
                    truth_eff["exciter"]["EMAX"] = round(ceil, 5)
            elif etype in ("oel", "scl"):
                sig_i = ref["XadIfd"] if etype == "oel" else ref["It"]
                i0 = float(sig_i[0])
                if etype == "oel":
                    ratio0 = round(u(rng, 0.95, 0.98), 4)
                    rated = i0 / ratio0
                    I = sig_i / rated
                    I_pu = 1.05
                    # the event must drive the field well above the pickup
                    imax = float(I[i_ev].max())
                else:
                    rated = 1.0
                    I = sig_i
                    imax = float(I[i_ev].max())
                    I_pu = round(i0 + u(rng, 0.25, 0.45) * (imax - i0), 4)
                if imax <= I_pu * 1.01:
                    raise RuntimeError(f"{cs['id']}: event too weak for {etype} (max {imax:.3f})")
                t_act = round(u(rng, 4.0, 8.0) * (1.0 / max(scale, 0.3)), 2)
                dt = 1.0 / rate
                sel = (ts >= t_onset) & (ts <= t_onset + t_act)
                A_max = float(np.sum(np.clip(I[sel] ** 2 - I_pu**2, 0.0, None)) * dt)
                if A_max <= 0.0:
                    A_max = 0.05
                ki = round(u(rng, 0.04, 0.08) * max(scale, 0.3), 4) if etype == "oel" else round(u(rng, 0.1, 0.3) * scale, 4)
                vmin = -0.15 if etype == "oel" else -0.1
                lim = 1.0 if etype == "oel" else round(I_pu * 0.98, 4)
                p = {"ifd_rated": rated, "I_pu": I_pu, "A_max": A_max, "I_lim": lim, "Ki": ki, "Vmin": vmin}
                ext[etype] = p
                params = dict(p)
                params.update({"t_act": t_act, "I_max_without": imax})
                if etype == "oel":
                    params["ifd_ratio0"] = ratio0
            elif etype == "vhz":
                vf = ref["Vt"] / (1.0 + ref["dw"])
                vf0, vfmax = float(vf[0]), float(vf[i_ev].max())
                pick = round(vf0 + u(rng, 0.2, 0.45) * (vfmax - vf0), 5)
                p = {"pickup": pick, "Ki": round(u(rng, 1.0, 3.0) * scale, 3), "Vmin": -0.1, "Treset": 10.0}
                ext["vhz"] = p
                params = dict(p)
                params.update({"VHz0": vf0, "VHz_max_without": vfmax})
        # ---------------- stage A with the effect; stage B check
        spec_eff = self.spec(truth_eff, ext, mc)
        t_need = np.unique(np.concatenate([ts, np.clip(ts - skew, 0, None)]))
        td = np.arange(0, int(round(T * 1000)) + 1) / 1000.0
        t_all = np.unique(np.concatenate([t_need, td]))
        unitA, outA, infoA = sim.run_grid(spec_eff, op, grid, event, T, t_all)
        iv = np.searchsorted(t_all, ts)
        ipq = np.searchsorted(t_all, np.clip(ts - skew, 0, None))
        idd = np.searchsorted(t_all, td)
        # stage B: the 1 kHz terminal voltage played back into the same unit
        outB = sim.playback_dense(spec_eff, op, td, outA["vr"][idd], outA["vi"][idd], ts, T)
        dAB = {"max_abs_dP": float(np.max(np.abs(outB["P"] - outA["P"][iv]))),
               "max_abs_dQ": float(np.max(np.abs(outB["Q"] - outA["Q"][iv]))),
               "max_abs_dEfd": float(np.max(np.abs(outB["Efd"] - outA["Efd"][iv])))}
        # ---------------- PMU chain
        nrng = np.random.default_rng(cs["seed"] * 7919 + 17)
        colour = noise.get("colour", {"kind": "white"})
        vratio = mc.get("v_ratio", 1.0)
        vr = outA["vr"][iv] * vratio + noise["sd_v"] * PMU.coloured(nrng, n, colour, rate)
        vi = outA["vi"][iv] * vratio + noise["sd_v"] * PMU.coloured(nrng, n, colour, rate)
        p = outA["P"][ipq] + noise["sd_p"] * PMU.coloured(nrng, n, colour, rate)
        q = outA["Q"][ipq] + noise["sd_q"] * PMU.coloured(nrng, n, colour, rate)
        quant = noise.get("quant_pq") if cs.get("quantize", False) else None
        p, q = PMU.quantise(p, quant), PMU.quantise(q, quant)
        extra = cs.get("extra_channels", False)
        efd = outA["Efd"][iv] + noise["sd_efd"] * PMU.coloured(nrng, n, colour, rate)
        ifd = outA["XadIfd"][iv] + noise["sd_ifd"] * PMU.coloured(nrng, n, colour, rate)
        keep = PMU.drop_mask(nrng, n, cs.get("drops", {}), rate)
        t_rec = ts[keep]
        vr, vi, p, q, efd, ifd = vr[keep], vi[keep], p[keep], q[keep], efd[keep], ifd[keep]
        vr = np.round(vr, 7)
        vi = np.round(vi, 7)
        p, q = np.round(p, 6), np.round(q, 6)
        freq = np.round(PMU.derive_freq(t_rec, vr, vi, b["fn_hz"]), 5)
        rec = {"t": t_rec, "vr": vr, "vi": vi, "p": p, "q": q, "freq": freq}
        # ---------------- oracle floors
        spec_without = self.spec(truth, {}, {})
        floor_wo = sim.oracle(spec_without, rec, noise["sd_p"], noise["sd_q"])
        if etype == "none":
            floor_w = floor_wo
        else:
            floor_w = sim.oracle(spec_eff, rec, noise["sd_p"], noise["sd_q"], skew=skew, vratio=vratio)
        vis = visibility(floor_wo, floor_w)
        # ---------------- files
        self.t_rec, self.rec = t_rec, rec
        self.outA, self.t_all, self.spec_eff, self.spec_without = outA, t_all, spec_eff, spec_without
        cols = ["time_s", "v_re_pu", "v_im_pu", "p_pu", "q_pu", "freq_hz"]
        if extra:
            cols += ["efd_pu", "ifd_pu"]
        self.csv_rows = (cols, t_rec, vr, vi, p, q, freq, np.round(efd, 5), np.round(ifd, 5), extra)
        self.nominal = self.nominal_json(nominal, rate, cols)
        est = floor_wo["init_estimate"]
        self.key = {
            "case": cs["id"], "seed": cs["seed"], "family": cs["family"],
            "generator_version": GENERATOR_VERSION,
            "hidden_effect": {
                "type": etype, "variant": variant, "cause": CATALOG.get(etype, "unexplained"),
                "outside_catalog": etype not in CATALOG,
                "params": jsonable(params), "where": WHERE[etype],
                "signature": SIGNATURE.get(etype, eff.get("signature", "")),
                "strength": eff.get("strength"),
                "truth_changes": changes(truth, truth_eff),
            },
            "event": {
                "description": EV.describe(event), "primitives": jsonable(event["primitives"]),
                "onsets_s": EV.onsets(event), "amb": jsonable(event["amb"]),
                "amb_seed": event["amb_seed"],
                "metrics": metrics(outA, iv, ts, t_onset, b),
                "grid_equivalent": {"R_e_pu": grid["R_e"], "X_e_pu": grid["X_e"], "base": "machine",
                                    "Vg0": infoA["Vg0"]},
            },
            "operating_point": {
                "P_sys": op["P_sys"], "Q_sys": op["Q_sys"], "V0": op["V0"],
                "theta0_deg": math.degrees(op["theta0"]), "f0_hz": op["f0_hz"],
                "Efd0": unitA.Efd0, "XadIfd0": unitA.XadIfd0, "delta0_rad": unitA.x0[0],
                "Pm0": unitA.Pm0, "gate0": unitA.geff0,
            },
            "true_unit": {"machine_mva": b["machine_mva"], "fn_hz": b["fn_hz"],
                          **{k: truth[k] for k in ("machine", "exciter", "pss", "governor")},
                          "note": "the true unit WITHOUT the hidden effect (the effect's parameter changes are hidden_effect.truth_changes, its added blocks true_unit_ext)"},
            "true_unit_ext": jsonable(ext),
            "measurement_chain": jsonable(mc),
            "nominal_errors": nom_errs,
            "pmu": {
                "rate_sps": rate, "duration_s": T, "samples": int(len(t_rec)),
                "samples_without_dropouts": n,
                "noise": {**{k: noise[k] for k in ("sd_v", "sd_p", "sd_q", "sd_efd", "sd_ifd")},
                          "quant_pq": quant, "colour": colour,
                          "note": "sd is the marginal standard deviation of every channel's noise; P, Q on the system base"},
                "dropouts": cs.get("drops", {}),
                "missing_stamps_s": [float(x) for x in ts[~keep]],
                "columns": cols,
                "freq_hz": "derived from the measured voltage angle (central difference over the stamps, 5-sample centred moving average)",
            },
            "diagnostics": {
                "stageA_vs_stageB": dAB,
                "init_max_abs_derivative_stageA": infoA["init_max_abs_derivative"],
                "oracle": {
                    "true_params_without_effect": strip_est(floor_wo),
                    "true_params_with_effect": strip_est(floor_w),
                    "effect_visibility": vis,
                    "init_estimate": {"n_samples": est["n_samples"], "V0": est["V0"],
                                      "theta0_rad": est["theta0"],
                                      "S0_sys": [est["P_sys"], est["Q_sys"]], "f0_hz": est["f0_hz"]},
                },
            },
            "spec": jsonable(cs),
            "files": {"data": f"cases/{cs['id']}/data.csv", "nominal": f"cases/{cs['id']}/nominal.json"},
            "generation_seconds": round(time.time() - t_start, 1),
        }
        return self

    def nominal_json(self, nominal, rate, cols):
        b = self.base
        out = {"case": self.cs["id"],
               "note": "Nominal (planning/vendor) model of the unit: start values for calibration. Per unit on the machine base unless stated.",
               "bases": {"machine_mva": b["machine_mva"], "system_mva": b["system_mva"],
                         "f_nominal_hz": b["fn_hz"], "pq_columns_base": "system",
                         "voltage_base": "rated terminal voltage"},
               "pmu": {"location": "generator terminal", "rate_sps": rate, "columns": cols}}
        for k in ("machine", "exciter", "pss", "governor"):
            out[k] = nominal[k]
        return out

    def write(self, root: str):
        cid = self.cs["id"]
        cdir = os.path.join(root, "cases", cid)
        os.makedirs(cdir, exist_ok=True)
        os.makedirs(os.path.join(root, "answers"), exist_ok=True)
        cols, t, vr, vi, p, q, f, efd, ifd, extra = self.csv_rows
        with open(os.path.join(cdir, "data.csv"), "w") as fh:
            fh.write(",".join(cols) + "\n")
            for k in range(len(t)):
                row = f"{t[k]:.9f},{vr[k]:.7f},{vi[k]:.7f},{p[k]:.6f},{q[k]:.6f},{f[k]:.5f}"
                if extra:
                    row += f",{efd[k]:.5f},{ifd[k]:.5f}"
                fh.write(row + "\n")
        with open(os.path.join(cdir, "nominal.json"), "w") as fh:
            json.dump(self.nominal, fh, indent=1)
        with open(os.path.join(root, "answers", f"{cid}.json"), "w") as fh:
            json.dump(self.key, fh, indent=1)


def strip_est(fl):
    return {k: v for k, v in fl.items() if k != "init_estimate"}


def visibility(wo, w):
    """How far the true unit without the effect misses the record, in noise sd: per channel the
    excess over the with-effect floor (sqrt(rms_wo^2 - rms_w^2)/sd, also for the worst second),
    and the issue's statistic: the RMS misfit of the unit without the effect over the noise sd,
    pooled over P and Q, `visible` when it exceeds 1.5."""
    out = {}
    for ch in ("P", "Q"):
        a, c = wo[ch], w[ch]
        sd = a["rms"] / a["rms_over_noise"]
        ex = math.sqrt(max(a["rms"] ** 2 - c["rms"] ** 2, 0.0)) / sd
        ex1 = math.sqrt(max(a["max_rms_1s"] ** 2 - c["max_rms_1s"] ** 2, 0.0)) / sd
        out[ch] = {"excess_rms_over_noise": ex, "excess_rms_1s_max_over_noise": ex1}
    pooled = math.sqrt((wo["P"]["rms_over_noise"] ** 2 + wo["Q"]["rms_over_noise"] ** 2) / 2)
    pooled_w = math.sqrt((w["P"]["rms_over_noise"] ** 2 + w["Q"]["rms_over_noise"] ** 2) / 2)
    out["misfit_without_effect_over_noise"] = pooled
    out["misfit_with_effect_over_noise"] = pooled_w
    out["visible"] = bool(pooled > 1.5)
    out["definition"] = ("visible: the true unit without the effect, played back against the record with "
                         "its set-point offsets fitted, misses P and Q by more than 1.5 noise sd RMS "
                         "(pooled over P and Q); a clean record sits at misfit_with_effect_over_noise "
                         "(about 1.2-1.4: the voltage noise drives the playback)")
    return out


def changes(a, b):
    out = {}
    for sec in ("machine", "exciter", "pss", "governor"):
        for k, v in b[sec].items():
            if a[sec].get(k) != v:
                out[f"{sec}.{k}"] = {"without": a[sec].get(k), "with": v}
    return out


def metrics(o, iv, ts, t_onset, b):
    k = b["machine_mva"] / b["system_mva"]
    return {"Vt_pre_pu": float(o["Vt"][iv][0]), "Vt_min_pu": float(o["Vt"][iv].min()),
            "Vt_max_pu": float(o["Vt"][iv].max()),
            "efd_range_pu": [float(o["Efd"][iv].min()), float(o["Efd"][iv].max())],
            "ifd_max_pu": float(o["XadIfd"][iv].max()),
            "stator_current_max_pu": float(o["It"][iv].max()),
            "speed_dev_range_pu": [float(o["dw"][iv].min()), float(o["dw"][iv].max())],
            "p_range_sys_pu": [float(o["P"][iv].min()), float(o["P"][iv].max())],
            "q_range_sys_pu": [float(o["Q"][iv].min()), float(o["Q"][iv].max())]}


def jsonable(x):
    if isinstance(x, dict):
        return {k: jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, (np.floating,)):
        return float(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.ndarray):
        return x.tolist()
    return x
