"""Writes data/itaipu/pmu/: the bundled Itaipu record as a PMU would export it (C37.118-style
CSV in kV and A with UTC time stamps, and COMTRADE 2013 BINARY32), for the README's import example.
Rated voltage 18 kV line-to-line; P, Q on 1000 MVA; start 2015-06-01T12:00:00Z (made up: the
record carries no date).

Both carry the record without loss worth speaking of (the CSV with 17 significant digits, exact to the last bit of the conversion, the
COMTRADE with 32-bit samples: about 1e-9 of each channel's range), so that importing them gives the
bundled record's numbers: a contract test compares the fit on each path (tests/contract.rs)."""
import csv, math, os, struct

here = os.path.join(os.path.dirname(__file__), "..", "data", "itaipu")
rows = list(csv.DictReader(open(os.path.join(here, "itaipu_pmu_60sps.csv"))))
out = os.path.join(here, "pmu")
os.makedirs(out, exist_ok=True)
ph = []
for r in rows:
    t = float(r["time_s"]); vr = float(r["v_re_pu"]); vi = float(r["v_im_pu"])
    p = float(r["p_pu"]) * 1000.0; q = float(r["q_pu"]) * 1000.0
    v = math.hypot(vr, vi) * 18.0 / math.sqrt(3.0); th = math.atan2(vi, vr)
    i = math.hypot(p, q) / (3.0 * v) * 1e3; ia = th - math.atan2(q, p)
    ph.append((t, v, math.degrees(th), i, (math.degrees(ia) + 180.0) % 360.0 - 180.0))
with open(os.path.join(out, "itaipu_c37.csv"), "w") as f:
    f.write("Timestamp,STAT,V1.MAG [kV],V1.ANG [deg],I1.MAG [A],I1.ANG [deg]\n")
    for t, v, va, i, ia in ph:
        us = round(t * 1e6)
        f.write("2015-06-01T12:%02d:%02d.%06dZ,0x0000,%.17g,%.17g,%.17g,%.17g\n" % (us // 60000000, us // 1000000 % 60, us % 1000000, v, va, i, ia))
# 32-bit samples: the channel range over 2^31 - 1 steps.
full = 2147483647
a = [12.0 / full, 180.0 / full, 40000.0 / full, 180.0 / full]
with open(os.path.join(out, "itaipu.cfg"), "w") as f:
    f.write("ITAIPU,PMU-U1,2013\n4,4A,0D\n")
    for k, (n, u) in enumerate([("V1 MAG", "kV"), ("V1 ANG", "deg"), ("I1 MAG", "A"), ("I1 ANG", "deg")]):
        f.write("%d,%s,,,%s,%.17e,0,0,-%d,%d,1,1,P\n" % (k + 1, n, u, a[k], full, full))
    f.write("60\n1\n60,%d\n01/06/2015,12:00:00.000000\n01/06/2015,12:00:01.020000\nBINARY32\n1\n" % len(ph))
    f.write("0,0\n0,0\n")  # time code, local code; tmq_code, leapsec (2013)
with open(os.path.join(out, "itaipu.dat"), "wb") as f:
    for k, (t, v, va, i, ia) in enumerate(ph):
        x = [round(val / a[j]) for j, val in enumerate((v, va, i, ia))]
        f.write(struct.pack("<II4i", k + 1, round(t * 1e6), *x))
