"""Independence check: a case's true unit without its hidden effect, played back through the
project's engine (`itaipu-calib simulate`, the record as recorded, initialised from its first
second, no offsets) and through this generator's own playback; the RMS and largest difference
of P and Q (system base)."""

from __future__ import annotations

import json
import os
import subprocess
import tempfile

import numpy as np

from . import sim
from .engine_names import unit_toml


def read_record(case_dir: str) -> dict:
    d = np.genfromtxt(os.path.join(case_dir, "data.csv"), delimiter=",", names=True)
    return {"t": d["time_s"], "vr": d["v_re_pu"], "vi": d["v_im_pu"], "p": d["p_pu"],
            "q": d["q_pu"], "freq": d["freq_hz"]}


def spec_without(key: dict, nominal: dict) -> dict:
    tu = key["true_unit"]
    return {"machine_mva": tu["machine_mva"], "system_mva": nominal["bases"]["system_mva"],
            "fn_hz": tu["fn_hz"], "machine": tu["machine"], "exciter": tu["exciter"],
            "pss": tu["pss"], "governor": tu["governor"], "ext": {}, "mc": {}}


def engine_playback(engine: str, case_dir: str, key: dict, nominal: dict, work: str):
    unit = dict(key["true_unit"])
    with open(os.path.join(work, "unit.toml"), "w") as fh:
        fh.write(unit_toml(unit, name=key["case"] + "-truth"))
    with open(os.path.join(work, "event.toml"), "w") as fh:
        fh.write(f'name = "{key["case"]}"\ncsv = "{os.path.abspath(os.path.join(case_dir, "data.csv"))}"\n'
                 f'system_mva = {nominal["bases"]["system_mva"]}\nnominal_hz = {nominal["bases"]["f_nominal_hz"]}\n'
                 f'input_lowpass_hz = "none"\n[init]\nstart_s = 0.0\nend_s = 1.0\n')
    out = os.path.join(work, "out")
    r = subprocess.run([engine, "simulate", "--event", os.path.join(work, "event.toml"), "--unit",
                        os.path.join(work, "unit.toml"), "--out", out, "--force", "--no-plot",
                        "--rtol", "1e-9", "--atol", "1e-11"], capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"{key['case']}: engine failed: {r.stderr.strip()}")
    e = np.genfromtxt(os.path.join(out, "traces.csv"), delimiter=",", names=True)
    return e["p_pu"], e["q_pu"]


def check_case(root: str, case: str, engine: str) -> dict:
    cdir = os.path.join(root, "cases", case)
    key = json.load(open(os.path.join(root, "answers", f"{case}.json")))
    nominal = json.load(open(os.path.join(cdir, "nominal.json")))
    rec = read_record(cdir)
    P, Q, _, _ = sim.playback_record(spec_without(key, nominal), rec)
    with tempfile.TemporaryDirectory() as work:
        Pe, Qe = engine_playback(engine, cdir, key, nominal, work)
    dp, dq = Pe - P, Qe - Q
    return {"case": case, "effect": key["hidden_effect"]["type"],
            "rms_dP": float(np.sqrt(np.mean(dp * dp))), "rms_dQ": float(np.sqrt(np.mean(dq * dq))),
            "max_dP": float(np.max(np.abs(dp))), "max_dQ": float(np.max(np.abs(dq))),
            "samples": int(len(P))}


def check_family(root: str, family: str, cases, engine: str):
    if not cases:
        cases = sorted(os.listdir(os.path.join(root, "cases")))
    rows = []
    print(f"{'case':<5} {'effect':<18} {'rms dP':>10} {'rms dQ':>10} {'max dP':>10} {'max dQ':>10}")
    for c in cases:
        r = check_case(root, c, engine)
        rows.append(r)
        print(f"{c:<5} {r['effect']:<18} {r['rms_dP']:10.2e} {r['rms_dQ']:10.2e} {r['max_dP']:10.2e} {r['max_dQ']:10.2e}",
              flush=True)
    return rows
