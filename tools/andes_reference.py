#!/usr/bin/env python3
"""ANDES 2.0 reference traces for the model library (tests/andes_models.rs, data/andes/README.md).

The ANDES peer case of `../shared/reference/andes/` (README.md there; `smib_playback.json`,
`params.py`) is run again with one model replaced by the model under test: the 700 MVA
GENROU-as-GENSAL machine, its SEXS exciter and HYGOV governor, the IEEEST left out (ANDES's
IEEET1 takes no stabiliser input, and the comparison needs none). The terminal is driven by
ANDES's PLBVFU1 playback source through a TimeSeries device fed every 10 ms; 20 s at 1 ms
implicit trapezoidal steps. Two playback profiles:

    dip        the shared case: |V| = 0.6 pu for 1.0-1.1 s, a 0.5 Hz, 3 deg angle swing 3-13 s
               (`playback_prescribed.csv`); for exciters
    dip_freq   the same dip, then a frequency excursion strong enough to drive a governor onto
               its limits: -0.6 % from 2 to 4 s, held to 8 s, +0.4 % by 11 s, held to 14 s, back
               to nominal by 16 s (ramps); for governors

This script only drives ANDES (`pip install andes==2.0.0` in a private venv, GPL-3.0) and keeps
its *outputs*; no ANDES code is copied. Decimated as tools/prepare_andes_reference.py does (every
row 0.98-1.20 s, 2 ms elsewhere, 9 significant digits). For each case, in data/andes/:

    <case>.csv         the event: time_s, v_pu, angle_deg (ANDES's terminal), p_pu, q_pu, efd_pu
    <case>_ref.csv     ANDES's outputs: time_s, efd_pu, pm_pu, speed_pu
    <case>.toml        the event file
    unit_<case>.toml   our unit: unit_gensal.toml's machine, SEXS and HYGOV with the model under
                       test in its section, its parameters by their PSS/E names (our unit files
                       accept them)

The legacy cases `ieeet1` and `esst1a` (tests/andes_exciters.rs) keep their earlier format
(`<case>_ref.csv` with the machine's internals, `unit_gensal_<case>.toml`).

Adding a model's check: add its case below (the model, its section, its parameters by PSS/E
name, the profile), run this script for it, commit the four files, and add one line to the table
of tests/andes_models.rs.

Run from the repository root with ANDES installed:
    python3 tools/andes_reference.py [case ...]        (default: every case)
"""
import copy
import csv
import json
import os
import sys
import tempfile

sys.path.insert(0, os.path.dirname(__file__))
from prepare_andes_reference import decimate, g  # noqa: E402

def _shared_reference():
    """`shared/reference/andes` beside the repository or above it (a worktree sits deeper);
    the environment variable ANDES_REFERENCE overrides."""
    if os.environ.get("ANDES_REFERENCE"):
        return os.environ["ANDES_REFERENCE"]
    d = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))
    while True:
        cand = os.path.join(d, "..", "shared", "reference", "andes")
        if os.path.isdir(cand) or os.path.dirname(d) == d:
            return cand
        d = os.path.dirname(d)


REF = _shared_reference()
DST = os.path.join(os.path.dirname(__file__), "..", "data", "andes")

# ------------------------------------------------------------------------------------------
# The cases. `params` are by PSS/E name: ANDES's parameter names for these models, and aliases
# our unit files accept. `andes_only`: parameters ANDES has and our model has not (given their
# inactive value); `ours_only`: the reverse.
# `andes_model`: the ANDES model to compare with, when not the one of the same name.
# `efd_var`: the ANDES exciter variable compared with our E_fd, when not the machine's E_fd.

# IEEET1: a DC exciter whose saturation is active at the operating point (A = 1.35 < E_fd0) and
# whose regulator reaches VRMAX in the dip (PSS/E's example saturation points).
IEEET1 = dict(TR=0.02, KA=50.0, TA=0.05, VRMAX=3.0, VRMIN=-3.0, KE=1.0, TE=0.5, KF=0.05,
              TF=1.0, Switch=0, E1=2.85, SE1=0.3, E2=3.8, SE2=0.6)
IEEET1_OURS = dict(t_r=0.02, k_a=50.0, t_a=0.05, vr_max=3.0, vr_min=-3.0, k_e=1.0, t_e=0.5,
                   k_f=0.05, t_f=1.0, switch=0.0, e1=2.85, se1=0.3, e2=3.8, se2=0.6)

# ESST1A: the voltage-error limit VIMAX, the regulator limit VAMAX, the supply ceiling
# V_t VRMAX - K_C XadIfd (0.6 x 4 - 0.1 x 2.2 in the dip) and the field current limiter (I_LR
# below the field current reached in the dip) all act; rate feedback on.
ESST1A = dict(TR=0.02, VIMAX=0.1, VIMIN=-0.1, TC=1.0, TB=10.0, TC1=0.0, TB1=0.0, KA=200.0,
              TA=0.02, VAMAX=3.0, VAMIN=-3.0, VRMAX=4.0, VRMIN=-4.0, KC=0.1, KF=0.02, TF=1.0,
              KLR=2.0, ILR=1.8, UELc=1, VOSc=1)
ESST1A_OURS = dict(t_r=0.02, vi_max=0.1, vi_min=-0.1, t_c=1.0, t_b=10.0, t_c1=0.0, t_b1=0.0,
                   k_a=200.0, t_a=0.02, va_max=3.0, va_min=-3.0, vr_max=4.0, vr_min=-4.0,
                   k_c=0.1, k_f=0.02, t_f=1.0, k_lr=2.0, i_lr=1.8)

LEGACY = {
    "ieeet1": dict(model="IEEET1", andes=IEEET1, ours=IEEET1_OURS, vr="LA_y"),
    "esst1a": dict(model="ESST1A", andes=ESST1A, ours=ESST1A_OURS, vr="LA_y"),
}

CASES = {
    # ESST4B: a proportional voltage regulator (K_IR = 0: ANDES's tracking anti-windup and the
    # non-windup state agree) whose output V_R reaches VRMAX in the dip; the field regulator with
    # integral action and the E_fd feedback K_G = 1 (its limits not reached); compound source
    # (K_I, X_L, THETAP) and a commutation factor that takes I_N = K_C X_adI_fd / V_E past 0.433
    # (F_EX's second segment) in the dip. VBMAX is not reached: the bridge's V_E F_EX is highest
    # at the operating point, and ANDES 2.0 does not initialise ESST4B with the bridge on VBMAX
    # (its initial field regulator output E_fd0 / V_B leaves a residual of 0.084 pu in E_fd).
    "esst4b": dict(section="exciter", model="ESST4B", profile="dip", params=dict(
        TR=0.02, KPR=20.0, KIR=0.0, VRMAX=2.0, VRMIN=-2.0, TA=0.05, KPM=1.0, KIM=2.0,
        VMMAX=99.0, VMMIN=-99.0, KG=1.0, KP=5.0, KI=0.1, VBMAX=4.5, KC=0.9, XL=0.124,
        THETAP=10.0), andes_only=dict(VGMAX=99.0)),
    # TGOV1: the valve reaches VMAX in the frequency fall and VMIN in the rise (P_m0 = 0.8).
    "tgov1": dict(section="governor", model="TGOV1", profile="dip_freq", params=dict(
        R=0.05, T1=0.5, VMAX=0.9, VMIN=0.75, T2=1.0, T3=5.0, Dt=0.2)),
    # IEEEG1: the valve is rate-limited (U_O, U_C) in the ramps and reaches PMAX and PMIN; four
    # stages with high- and low-pressure shares on the one shaft.
    "ieeeg1": dict(section="governor", model="IEEEG1", profile="dip_freq", params=dict(
        K=20.0, T1=0.2, T2=0.1, T3=0.1, UO=0.05, UC=-0.05, PMAX=0.9, PMIN=0.75, T4=0.3,
        K1=0.3, K2=0.0, T5=5.0, K3=0.4, K4=0.0, T6=0.5, K5=0.3, K6=0.0, T7=0.05, K7=0.0,
        K8=0.0)),
    # GAST: the fuel valve reaches VMAX in the frequency fall; the exhaust temperature load limit
    # (AT below the droop's demand) then takes over through the low-value gate as the lag T3
    # catches up, and pulls the valve back to AT; VMIN in the rise (P_m0 = 0.8).
    "gast": dict(section="governor", model="GAST", profile="dip_freq", params=dict(
        R=0.05, T1=0.4, T2=0.1, T3=3.0, AT=0.88, KT=2.0, VMAX=0.91, VMIN=0.75, Dt=0.1)),
    # TG2: the lead-lag's output takes P_m onto PMAX in the frequency fall, and to within 1.3e-3
    # of PMIN in the rise (P_m0 = 0.8). Ours has no deadband. ANDES 2.0's TG2 with its deadband disabled (its
    # default) does not respond at all (the disabled deadband's "inside" flag stays 1 and zeroes
    # the speed signal), so its deadband is enabled with zero width: a pass-through.
    "tg2": dict(section="governor", model="TG2", profile="dip_freq", params=dict(
        R=0.05, pmax=0.9, pmin=0.75, T1=2.0, T2=4.0),
        andes_only=dict(dbl=0.0, dbu=0.0, dbc=0.0), andes_config=["TG2.deadband=1"]),
    # IEEEX1: against ANDES's EXDC2 (ANDES's IEEEX1 has PSS/E EXDC2's V_T-scaled limits; its
    # ESDC1A leaves the regulator limits at 0, the replaced V_RMAX service unwired). ANDES's EXDC2 multiplies E_fd by
    # the speed: our E_fd is compared with its exciter state before the multiplier (`vp`), and
    # ANDES's machine sees omega·vp. The regulator reaches VRMAX in the dip; saturation active at
    # the operating point (PSS/E's example points); the lead-lag and the transducer on.
    "ieeex1": dict(section="exciter", model="IEEEX1", andes_model="EXDC2", efd_var="vp",
                   profile="dip", params=dict(
                       TR=0.02, KA=40.0, TA=0.04, TB=1.0, TC=0.5, VRMAX=2.0, VRMIN=-2.0, KE=1.0,
                       TE=0.5, KF=0.05, TF1=1.0, Switch=0, E1=2.85, SE1=0.3, E2=3.8, SE2=0.6),
                   ours_only=("KF", "Switch"), andes_only=dict(KF1=0.05)),
    # EXDC2: against ANDES's IEEEX1 (PSS/E's EXDC2 layout, ANDES's name KF1 for KF). ANDES 2.0
    # declares its limits V·VRMAX, V·VRMIN but its anti-windup limiter keeps the constant
    # VRMAX, VRMIN it was built with (LagAntiWindup binds its bounds before IEEEX1 replaces
    # them), so the case keeps V_R inside V_T·[VRMIN, VRMAX] throughout (K_A = 10: V_R stays
    # under 0.6 x 9 in the dip); our V_T-scaled limits have their own test
    # (tests/exciters.rs). Lead-lag and transducer on.
    "exdc2": dict(section="exciter", model="EXDC2", andes_model="IEEEX1", profile="dip",
                  params=dict(TR=0.02, KA=10.0, TA=0.04, TB=1.0, TC=0.5, VRMAX=9.0, VRMIN=-9.0,
                              KE=1.0, TE=0.5, KF=0.05, TF1=1.0, Switch=0, E1=2.85, SE1=0.3,
                              E2=3.8, SE2=0.6), ours_only=("KF", "Switch"),
                  andes_only=dict(KF1=0.05)),
}

UNIT_HEAD = """name = "andes-{case}"
description = "The ANDES reference unit (unit_gensal.toml) with {what} and no PSS (tools/andes_reference.py). Swing uses ANDES's Tm = Pm."
machine_mva = 700.0
nominal_hz = 60.0
"""


def sections():
    """unit_gensal.toml's sections by name (machine, exciter, pss, governor)."""
    base = open(os.path.join(DST, "unit_gensal.toml")).read()
    out = {}
    names = ["machine", "exciter", "pss", "governor"]
    for i, n in enumerate(names):
        a = base.index(f"[{n}]")
        b = base.index(f"[{names[i + 1]}]") if i + 1 < len(names) else len(base)
        out[n] = base[a:b].rstrip() + "\n"
    return out


def unit_toml(case, c):
    """Our unit file: unit_gensal.toml's machine, exciter and governor, the model of the case
    in its section, no PSS."""
    s = sections()
    block = f'[{c["section"]}]\nmodel = "{c["model"]}"\n' + "".join(
        f"{k} = {float(v)!r}\n" for k, v in c["params"].items())
    s[c["section"]] = block
    what = f'its {c["section"]} replaced by {c["model"]}'
    return (UNIT_HEAD.format(case=case, what=what) + "\n" + s["machine"] + "\n" + s["exciter"]
            + "\n" + s["governor"])


def legacy_unit_toml(case, c):
    """The legacy cases' unit file: unit_gensal.toml's machine and governor, the exciter."""
    base = open(os.path.join(DST, "unit_gensal.toml")).read()
    machine = base[base.index("[machine]"):base.index("[exciter]")]
    governor = base[base.index("[governor]"):]
    exc = f'[exciter]\nmodel = "{c["model"]}"\n' + "".join(
        f"{k} = {float(v)!r}\n" for k, v in c["ours"].items())
    head = UNIT_HEAD.format(case=f"smib-unit-gensal-{case}",
                            what=f'its SEXS replaced by {c["model"]}')
    return head + "\n" + machine + exc + "\n" + governor


def prescribed(profile, work):
    """The 10 ms series of |V| and frequency the playback source follows."""
    rows = list(csv.DictReader(open(os.path.join(REF, "playback_prescribed.csv"))))
    path = os.path.join(work, "playback_ts_10ms.csv")
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t", "V_pu", "f_pu"])
        for k, r in enumerate(rows):
            if k % 10:
                continue
            t = float(r["t"])
            if profile == "dip":
                w.writerow([r["t"], r["V_pu"], r["f_pu"]])
            else:
                w.writerow([r["t"], r["V_pu"], repr(1.0 + excursion(t))])
    return path


def excursion(t):
    """The frequency deviation of the `dip_freq` profile [pu] (piecewise linear)."""
    pts = [(0.0, 0.0), (2.0, 0.0), (4.0, -0.006), (8.0, -0.006), (11.0, 0.004), (14.0, 0.004),
           (16.0, 0.0), (1e9, 0.0)]
    for (t0, f0), (t1, f1) in zip(pts, pts[1:]):
        if t0 <= t <= t1:
            return f0 + (f1 - f0) * (t - t0) / (t1 - t0)
    return 0.0


def run_andes(devices, profile, work, gov_model="HYGOV", exc_model=None, config_option=None):
    """Runs the case with `devices` ({model: [records]}) replacing the shared case's, returns
    ANDES's system after the time-domain simulation."""
    import andes
    andes.config_logger(stream_level=40)
    d = copy.deepcopy(json.load(open(os.path.join(REF, "smib_playback.json"))))
    d.pop("IEEEST", None)
    for m in devices:
        if m in ("TGOV1", "IEEEG1", "GAST", "TG2"):
            d.pop("HYGOV", None)
        if m not in ("TGOV1", "IEEEG1", "GAST", "TG2", "HYGOV"):
            d.pop("SEXS", None)
    d.update(devices)
    ts = prescribed(profile, work)
    d["TimeSeries"] = [dict(idx="TS1", u=1, name="TS1", mode=1, path=ts, sheet="-",
                            fields="V_pu,f_pu", tkey="t", model="PLBVFU1", dev="PLB",
                            dests="Vts,fts")]
    case_file = os.path.join(work, "case.json")
    json.dump(d, open(case_file, "w"))
    ss = andes.load(case_file, no_output=True, default_config=True,
                    config_option=config_option)
    ss.TDS.config.tf = 20.0
    ss.TDS.config.tstep = 0.001
    ss.TDS.config.fixt = 1
    ss.TDS.config.shrinkt = 1
    ss.TDS.config.tol = 1e-4
    ss.TDS.config.no_tqdm = 1
    ss.PFlow.run()
    ss.TDS.run()
    assert ss.exit_code == 0, "ANDES TDS failed"
    return ss


def col(ss, var):
    ts = ss.dae.ts
    return (ts.x if var.v_code == "x" else ts.y)[:, var.a[0]]


def write_event(case, rows, model, what):
    with open(os.path.join(DST, f"{case}.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["time_s", "v_pu", "angle_deg", "p_pu", "q_pu", "efd_pu"])
        for r in rows:
            w.writerow([g(r["t_s"]), g(r["Vt_pu"]), g(r["theta_t_deg"]), g(r["P_pu"]),
                        g(r["Q_pu"]), g(r["Efd_pu"])])
    with open(os.path.join(DST, f"{case}.toml"), "w") as f:
        f.write(f'name = "andes-{case}"\n'
                f'description = "ANDES 2.0 reference case \'{case}\' (tools/andes_reference.py): '
                f'the playback case with {what}; terminal voltage exported by ANDES, played back here."\n'
                f'csv = "{case}.csv"\nsystem_mva = 700.0\nnominal_hz = 60.0\n'
                '# A computed trace, without measurement noise: played back as recorded.\n'
                'input_lowpass_hz = "none"\n\n'
                '[init]\nstart_s = 0.0\nend_s = 0.9\n')


def outputs(ss, extra):
    import numpy as np
    gen, bus = ss.GENROU, ss.Bus
    deg = 180.0 / np.pi
    out = dict(
        t_s=ss.dae.ts.t,
        Vt_pu=col(ss, bus.v),
        theta_t_deg=col(ss, bus.a) * deg,
        P_pu=col(ss, gen.Pe),
        Q_pu=col(ss, gen.Qe),
        speed_pu=col(ss, gen.omega),
        Efd_pu=col(ss, gen.vf),
        Pm_pu=col(ss, gen.tm),
    )
    out.update(extra)
    keys = list(out)
    return [dict((k, str(out[k][i])) for k in keys) for i in range(len(out["t_s"]))]


def run_case(case):
    c = CASES[case]
    andes_params = dict(c["params"])
    andes_params.update(c.get("andes_only", {}))
    for k in c.get("ours_only", ()):
        andes_params.pop(k, None)
    ref = "syn" if c["section"] in ("exciter", "governor") else "avr"
    rec = dict(idx="DUT", u=1, name="DUT", **{ref: "GEN1"}, **andes_params)
    with tempfile.TemporaryDirectory() as work:
        name = c.get("andes_model", c["model"])
        ss = run_andes({name: [rec]}, c["profile"], work,
                       config_option=c.get("andes_config"))
        efd = c.get("efd_var")
        rows = decimate(outputs(ss, {"Efd_ref": col(ss, getattr(ss.__dict__[name], efd))}
                                if efd else {}))
    write_event(case, rows, c["model"], f'a {c["model"]} {c["section"]}')
    with open(os.path.join(DST, f"{case}_ref.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["time_s", "efd_pu", "pm_pu", "speed_pu"])
        for r in rows:
            w.writerow([g(r["t_s"]), g(r.get("Efd_ref", r["Efd_pu"])), g(r["Pm_pu"]),
                        g(r["speed_pu"])])
    with open(os.path.join(DST, f"unit_{case}.toml"), "w") as f:
        f.write(unit_toml(case, c))
    print(case, len(rows), "rows")


def run_legacy(case):
    c = LEGACY[case]
    import numpy as np
    rec = dict(idx="EXC1", u=1, name="EXC1", syn="GEN1", **c["andes"])
    with tempfile.TemporaryDirectory() as work:
        ss = run_andes({c["model"]: [rec]}, "dip", work)
        exc, gov, gen = ss.__dict__[c["model"]], ss.HYGOV, ss.GENROU
        deg = 180.0 / np.pi
        extra = dict(delta_deg=col(ss, gen.delta) * deg, XadIfd_pu=col(ss, gen.XadIfd),
                     VR_pu=col(ss, exc.__dict__[c["vr"]]), Vpss_pu=np.zeros_like(ss.dae.ts.t),
                     gate_pu=col(ss, gov.gtpos))
        rows = decimate(outputs(ss, extra))
    write_event(case, rows, c["model"], f'a {c["model"]} exciter')
    with open(os.path.join(DST, f"{case}_ref.csv"), "w", newline="") as f:
        w = csv.writer(f)
        cols = ["speed_pu", "delta_deg", "Efd_pu", "Pm_pu", "XadIfd_pu", "VR_pu", "Vpss_pu",
                "gate_pu"]
        w.writerow(["time_s"] + [k.lower() for k in cols])
        for r in rows:
            w.writerow([g(r["t_s"])] + [g(r[k]) for k in cols])
    with open(os.path.join(DST, f"unit_gensal_{case}.toml"), "w") as f:
        f.write(legacy_unit_toml(case, c))
    print(case, len(rows), "rows")


def main() -> int:
    names = sys.argv[1:] or list(CASES)
    for case in names:
        if case in LEGACY:
            run_legacy(case)
        elif case in CASES:
            run_case(case)
        else:
            print(f"unknown case {case} (cases: {', '.join(list(CASES) + list(LEGACY))})")
            return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
