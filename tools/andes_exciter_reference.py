#!/usr/bin/env python3
"""ANDES 2.0 reference traces for the exciters beyond SEXS (IEEET1, ESST1A).

The ANDES peer case of `../shared/reference/andes/` (README.md there; `smib_playback.json`,
`params.py`) is run again with its SEXS replaced by another exciter and without the IEEEST (ANDES's
IEEET1 has no stabiliser input; the comparison then needs none): the 700 MVA GENROU-as-GENSAL
machine and HYGOV unchanged, the terminal driven by ANDES's PLBVFU1 playback source following
`playback_prescribed.csv` (|V| = 0.6 pu for 1.0-1.1 s, a 0.5 Hz, 3 deg angle swing 3-13 s; fed
through a TimeSeries device every 10 ms), 20 s at 1 ms implicit trapezoidal steps.

This script only drives ANDES (pip install andes==2.0.0, GPL-3.0) and keeps its *outputs*; no
ANDES code is copied. Output, for each case, in data/andes/ (decimated as
tools/prepare_andes_reference.py does: every row 0.98-1.20 s, 2 ms elsewhere, 9 digits):

    <case>.csv       canonical event CSV (time_s, v_pu, angle_deg, p_pu, q_pu, efd_pu)
    <case>_ref.csv   ANDES's speed, rotor angle, Efd, Pm, XadIfd, regulator output V_R, gate
    <case>.toml      the event; unit_gensal_<case>.toml, the unit in our format

Run from the repository root with ANDES installed:
    python3 tools/andes_exciter_reference.py [case ...]        (cases: ieeet1, esst1a)
"""
import copy
import csv
import json
import os
import sys
import tempfile

sys.path.insert(0, os.path.dirname(__file__))
from prepare_andes_reference import decimate, g  # noqa: E402

REF = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "reference", "andes")
DST = os.path.join(os.path.dirname(__file__), "..", "data", "andes")

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

CASES = {
    "ieeet1": dict(model="IEEET1", andes=IEEET1, ours=IEEET1_OURS, vr="LA_y"),
    "esst1a": dict(model="ESST1A", andes=ESST1A, ours=ESST1A_OURS, vr="LA_y"),
}

UNIT_HEAD = """name = "andes-smib-unit-gensal-{case}"
description = "The ANDES reference unit (unit_gensal.toml) with its SEXS replaced by {model} and no PSS (tools/andes_exciter_reference.py). Swing uses ANDES's Tm = Pm."
machine_mva = 700.0
nominal_hz = 60.0
"""


def unit_toml(case, c):
    """Our unit file: unit_gensal.toml's machine and governor, the exciter of the case."""
    base = open(os.path.join(DST, "unit_gensal.toml")).read()
    machine = base[base.index("[machine]"):base.index("[exciter]")]
    governor = base[base.index("[governor]"):]
    exc = f'[exciter]\nmodel = "{c["model"]}"\n' + "".join(
        f"{k} = {float(v)!r}\n" for k, v in c["ours"].items())
    return UNIT_HEAD.format(case=case, model=c["model"]) + "\n" + machine + exc + "\n" + governor


def run_andes(c, work):
    import andes
    andes.config_logger(stream_level=40)
    d = json.load(open(os.path.join(REF, "smib_playback.json")))
    d = copy.deepcopy(d)
    for k in ("SEXS", "IEEEST"):
        d.pop(k, None)
    d[c["model"]] = [dict(idx="EXC1", u=1, name="EXC1", syn="GEN1", **c["andes"])]
    # The prescribed |V| and frequency every 10 ms (the dip edges 1.0 and 1.1 s are on it).
    rows = list(csv.DictReader(open(os.path.join(REF, "playback_prescribed.csv"))))
    ts = os.path.join(work, "playback_ts_10ms.csv")
    with open(ts, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t", "V_pu", "f_pu"])
        for k, r in enumerate(rows):
            if k % 10 == 0:
                w.writerow([r["t"], r["V_pu"], r["f_pu"]])
    d["TimeSeries"] = [dict(idx="TS1", u=1, name="TS1", mode=1, path=ts, sheet="-",
                            fields="V_pu,f_pu", tkey="t", model="PLBVFU1", dev="PLB",
                            dests="Vts,fts")]
    case_file = os.path.join(work, "case.json")
    json.dump(d, open(case_file, "w"))
    ss = andes.load(case_file, no_output=True, default_config=True)
    ss.TDS.config.tf = 20.0
    ss.TDS.config.tstep = 0.001
    ss.TDS.config.fixt = 1
    ss.TDS.config.shrinkt = 1
    ss.TDS.config.tol = 1e-4
    ss.TDS.config.no_tqdm = 1
    ss.PFlow.run()
    ss.TDS.run()
    assert ss.exit_code == 0, "ANDES TDS failed"
    ts = ss.dae.ts
    gen, exc, gov, bus = ss.GENROU, ss.__dict__[c["model"]], ss.HYGOV, ss.Bus
    def col(var):
        return (ts.x if var.v_code == "x" else ts.y)[:, var.a[0]]
    import numpy as np
    deg = 180.0 / np.pi
    out = dict(
        t_s=ts.t,
        Vt_pu=col(bus.v),
        theta_t_deg=col(bus.a) * deg,
        P_pu=col(gen.Pe),
        Q_pu=col(gen.Qe),
        speed_pu=col(gen.omega),
        delta_deg=col(gen.delta) * deg,
        Efd_pu=col(gen.vf),
        Pm_pu=col(gen.tm),
        XadIfd_pu=col(gen.XadIfd),
        VR_pu=col(exc.__dict__[c["vr"]]),
        Vpss_pu=np.zeros_like(ts.t),
        gate_pu=col(gov.gtpos),
    )
    keys = list(out)
    return [dict((k, str(out[k][i])) for k in keys) for i in range(len(ts.t))]


def main() -> int:
    names = sys.argv[1:] or list(CASES)
    for case in names:
        c = CASES[case]
        with tempfile.TemporaryDirectory() as work:
            rows = decimate(run_andes(c, work))
        with open(os.path.join(DST, f"{case}.csv"), "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["time_s", "v_pu", "angle_deg", "p_pu", "q_pu", "efd_pu"])
            for r in rows:
                w.writerow([g(r["t_s"]), g(r["Vt_pu"]), g(r["theta_t_deg"]), g(r["P_pu"]),
                            g(r["Q_pu"]), g(r["Efd_pu"])])
        with open(os.path.join(DST, f"{case}_ref.csv"), "w", newline="") as f:
            w = csv.writer(f)
            cols = ["speed_pu", "delta_deg", "Efd_pu", "Pm_pu", "XadIfd_pu", "VR_pu", "Vpss_pu",
                    "gate_pu"]
            w.writerow(["time_s"] + [k.lower() for k in cols])
            for r in rows:
                w.writerow([g(r["t_s"])] + [g(r[k]) for k in cols])
        with open(os.path.join(DST, f"{case}.toml"), "w") as f:
            f.write(f'name = "andes-{case}"\n'
                    f'description = "ANDES 2.0 reference case \'{case}\' (tools/andes_exciter_reference.py): '
                    f'the playback case with a {c["model"]} exciter; terminal voltage exported by ANDES, played back here."\n'
                    f'csv = "{case}.csv"\nsystem_mva = 700.0\nnominal_hz = 60.0\n\n'
                    '[init]\nstart_s = 0.0\nend_s = 0.9\n')
        with open(os.path.join(DST, f"unit_gensal_{case}.toml"), "w") as f:
            f.write(unit_toml(case, c))
        print(case, len(rows), "rows")
    return 0


if __name__ == "__main__":
    sys.exit(main())
