"""Writes data/itaipu/pmu/: the bundled Itaipu record as a PMU would export it (C37.118-style
CSV in kV and A with UTC time stamps, and COMTRADE 1999 ASCII), for the README's import example.
Rated voltage 18 kV line-to-line; P, Q on 1000 MVA; start 2015-06-01T12:00:00Z (made up: the
record carries no date)."""
import csv, math, os

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
        f.write("2015-06-01T12:%02d:%02d.%06dZ,0x0000,%.6f,%.4f,%.2f,%.4f\n" % (us // 60000000, us // 1000000 % 60, us % 1000000, v, va, i, ia))
a = [12.0 / 32767, 180.0 / 32767, 40000.0 / 32767, 180.0 / 32767]
with open(os.path.join(out, "itaipu.cfg"), "w") as f:
    f.write("ITAIPU,PMU-U1,1999\n4,4A,0D\n")
    for k, (n, u) in enumerate([("V1 MAG", "kV"), ("V1 ANG", "deg"), ("I1 MAG", "A"), ("I1 ANG", "deg")]):
        f.write("%d,%s,,,%s,%.12e,0,0,-32767,32767,1,1,P\n" % (k + 1, n, u, a[k]))
    f.write("60\n1\n60,%d\n01/06/2015,12:00:00.000000\n01/06/2015,12:00:01.020000\nASCII\n1\n" % len(ph))
with open(os.path.join(out, "itaipu.dat"), "w") as f:
    for k, (t, v, va, i, ia) in enumerate(ph):
        x = [round(val / a[j]) for j, val in enumerate((v, va, i, ia))]
        f.write("%d,%d,%d,%d,%d,%d\n" % (k + 1, round(t * 1e6), *x))
