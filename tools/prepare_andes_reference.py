#!/usr/bin/env python3
"""Convert the ANDES 2.0 reference traces into itaipu-calib events + reference columns.

Input:  ../shared/reference/andes/{playback,fault}_h1ms.csv (ANDES 2.0.0 outputs, 1 ms steps,
        700 MVA machine base = system base, 60 Hz; see that folder's README.md and params.py).
Output: data/andes/<case>.csv        canonical event CSV (time_s, v_pu, angle_deg, p_pu, q_pu, efd_pu)
        data/andes/<case>_ref.csv    ANDES's other traces for the comparison test
The rows are decimated to 2 ms, except 0.98-1.20 s (the dip / fault and its clearing), where
every ANDES row is kept. Values are rounded to 9 significant digits.

Run from the repository root:  python3 tools/prepare_andes_reference.py
"""
import csv
import os
import sys

SRC = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "reference", "andes")
DST = os.path.join(os.path.dirname(__file__), "..", "data", "andes")

def decimate(rows):
    """Every row in 0.98-1.20 s; elsewhere a row when 2 ms have passed since the last kept one
    (ANDES's grid is offset by 0.1 ms after an event, so times are not multiples of 2 ms)."""
    out, last = [], -1.0
    for i, r in enumerate(rows):
        t = float(r["t_s"])
        if 0.98 <= t <= 1.20 or t - last >= 0.0019999 or i == len(rows) - 1:
            out.append(r)
            last = t
    return out

def g(x: str) -> str:
    return f"{float(x):.9g}"

def main() -> int:
    os.makedirs(DST, exist_ok=True)
    for case, src in (("playback", "playback_h1ms.csv"), ("fault", "fault_h1ms.csv")):
        rows = list(csv.DictReader(open(os.path.join(SRC, src))))
        rows = decimate(rows)
        with open(os.path.join(DST, f"{case}.csv"), "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["time_s", "v_pu", "angle_deg", "p_pu", "q_pu", "efd_pu"])
            for r in rows:
                w.writerow([g(r["t_s"]), g(r["Vt_pu"]), g(r["theta_t_deg"]), g(r["P_pu"]), g(r["Q_pu"]), g(r["Efd_pu"])])
        with open(os.path.join(DST, f"{case}_ref.csv"), "w", newline="") as f:
            w = csv.writer(f)
            cols = ["speed_pu", "delta_deg", "Efd_pu", "Pm_pu", "XadIfd_pu", "Vpss_pu", "gate_pu"]
            w.writerow(["time_s"] + [c.lower() for c in cols])
            for r in rows:
                w.writerow([g(r["t_s"])] + [g(r[c]) for c in cols])
        print(case, len(rows), "rows")
    return 0

if __name__ == "__main__":
    sys.exit(main())
