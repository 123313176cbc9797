"""index.json and the README of a family, written from its answer keys."""

from __future__ import annotations

import json
import os

INTRO = {
    "other_unit": """Another unit than the practice family's: a medium **50 Hz** hydro unit, **GENSAL** (quadratic
saturation on E'q, d-axis only) + **ESST1A** (bus-fed static exciter: transducer T_R, error
limits, transient gain reduction T_C/T_B, regulator K_A/T_A, ceiling V_t·V_RMAX − K_C·X_adI_fd) +
**IEEEST** (lead-lag stabiliser on rotor speed, washout T5/T6) + **HYGOV**; 300 MVA on a **100 MVA**
system base, so P and Q run to about 3 pu and the PMU reports at 25 or 50 samples/s. The
catalog's effects that make sense for it (the exciter ceiling is ESST1A's own V_RMAX lowered, at
its K_C; the OEL sums into ESST1A's error), and clean records.

The 20 calibratable parameters a nominal may get wrong (4 per case): machine H, Xd, Xq, X'd,
X''d (= X''q), T'd0, T''d0, T''q0; exciter KA, TC, TB, TA; PSS KS, T1, T3; governor R, r, Tr,
Tg, Tw (the practice runner frees this set for an ESST1A/IEEEST unit). Exact in every nominal:
everything else (Xl, R_a 0.003, S10/S12 unless the effect is saturation, the ESST1A limits and
K_C unless the effect is the ceiling, IEEEST T2/T4/T5/T6 and limits, HYGOV Tf, VELM, gate limits,
At, Dturb, qNL).""",
    "coloured_noise_dropouts": """The practice unit (GENSAE + SEXS + STAB3 + HYGOV, 737 MVA, 60 Hz) with the catalog's effects
and clean records, recorded through another PMU chain: **coloured noise** (AR(1) with
coefficient 0.6-0.9 per sample, or white noise low-passed (3rd-order Butterworth, zero phase) at
2-10 Hz; the stated sd is the marginal sd), **quantisation** of P/Q (0.0014 or 0.002 pu),
**drop-outs** (single samples and short gaps of 3-24 samples missing from the export: the time
base is then non-uniform, never inside the first 1.2 s), and **other reporting rates** (10, 15,
20, 60, 120 samples/s).""",
    "event_shapes": """The practice unit (GENSAE + SEXS + STAB3 + HYGOV, 737 MVA, 60 Hz) with the catalog's effects
and clean records, under **other events**: a line trip and reclose (the Thevenin impedance
rises by 1.4-2.0 for 0.6-1.5 s, with or without a fault dip before the trip: two steps and a
swing of the unit's own), a slow grid-voltage ramp (2-8 % over 8-20 s), two disturbances in one
record (voltage step + fault, fault + loss of generation, fault + voltage step), records with
only ambient fluctuations (60 s, ambient background 1.5-2.5 times the practice family's), and
long records (120-150 s, two disturbances far apart).""",
    "outside_catalog": """The practice unit (GENSAE + SEXS + STAB3 + HYGOV, 737 MVA, 60 Hz) with effects that **neither the
diagnosis catalog nor the look-alike list (data/causes/: reactive droop, AVR voltage-transducer
lag, governor speed filter, PSS lead-lag, UEL) holds**, from plant experience and the literature
on unit model validation, each in two or three strengths and events, plus one clean record. The
right verdict is `unexplained` where the effect is visible (and no catalog name anywhere);
`hidden_effect.cause` says `unexplained`, `diagnostics.oracle.effect_visibility.visible` whether
the true unit without the effect misses the record by more than 1.5 noise sd RMS. **A held-out
test: do not run the diagnosis's development against it, and do not add a look-alike for one of
these effects without moving that effect out of this family.**

| effect (`hidden_effect.type`) | what the truth does |
|---|---|
| `plant_q` | a plant-level controller acting slowly (integral, 1 s measurement lag, ±0.05 pu authority) on the AVR set point, holding the unit's Q (`mode = q`) or the HV-side voltage |V_t − jX_t I| (`mode = poi_v`) at its pre-event value; closed-loop time 8-30 s |
| `agc` | AGC / load-controller moves of the HYGOV gate set point during the record (`moves`: smooth ramps of `dgate` over `dur` s from `t`) |
| `vhz` | a volts-per-hertz limiter: above the pickup (V_t/(1+Δω)) it integrates the excess into a negative signal at the AVR summing point (K_i, floor V_min), reset with 10 s below it |
| `scl` | an inverse-time stator-current limiter: I²t above the pickup, then integral action pulling the stator current back to I_lim through the AVR summing point while over-excited |
| `penstock` | an elastic water column: the penstock as 6 lumped travelling-wave sections (wave travel time T_e, surge impedance Z_n = T_w/T_e, quarter-wave resonance 1/(4T_e)) in place of HYGOV's rigid column |
| `rotating_exciter` | a rotating DC exciter between the SEXS regulator and the field: T_E dE_fd/dt = V_R − (K_E + S_E(E_fd))E_fd, K_E set for unity gain at the operating point, quadratic exciter saturation through (E1, SE1), (E2, SE2) |
| `backlash` | backlash (play `b`, hysteresis, not a speed deadband) between the gate servo and the effective gate |
| `pss_limit` | the STAB3 output limiter asymmetric: one side far tighter than the nominal ±V_LIM |
| `vt_ratio` | the PMU's voltage channel reads k·V (a VT ratio error); P and Q come from their own transducers |""",
}

COMMON = """## How a case was made (after ../../../shared/practice/README.md, by our own generator)
1. True unit: the base unit's calibratable parameters each scaled by U(0.9, 1.1); X''q = X''d.
   Nominal: 4 of the 20 off by 20-50 % (either sign), the rest exact; the answer key's
   `nominal_errors` says which.
2. Operating point from the family's ranges, any start angle, pre-event frequency off nominal by
   up to ±0.015 Hz (±0.012 Hz at 50 Hz).
3. The true unit (hidden effect included) runs against a Thevenin grid (R_e + jX_e, X_e
   0.15-0.30 pu machine base, R/X 0.02) whose source carries the event and an ambient background
   (|V| noise, frequency wander, an inter-area angle oscillation), so the terminal voltage is
   physically consistent with the unit's own response (stage A).
4. The terminal voltage (1 kHz, C2 spline of magnitude and unwrapped angle) is played back into
   the same true unit; stage A and this playback agree to `diagnostics.stageA_vs_stageB` (about
   1e-7 pu).
5. PMU chain: point samples from t = 0 at the case's rate; V re/im + noise sd 0.0005; P, Q +
   noise (sd in the key, system base); on some cases P/Q quantised; `freq_hz` derived from the
   measured angle; on some cases `efd_pu` (+ sd 0.01) and `ifd_pu` (X_ad I_fd, + sd 0.005).
   Event edges last at least 2.5 sample intervals (and 40 ms).

The models follow /work/shared/reference/models.md (OpenIPSL/PSS/E conventions: stator at
ω = 1, non-windup limits freezing the state, HYGOV velocity limit on dc/dt, STAB3 on P_elec with
P_REF frozen); integration by scipy `solve_ivp` (LSODA, rtol 1e-8, atol 1e-10, steps ≤ 5 ms).
The generator (`tools/families/`, Python + numpy/scipy) does not use the project's engine.

## The floor
`diagnostics.oracle.true_params_without_effect`: the record played back (|V| and unwrapped angle
linear between the stamps, as the tool does) through the true unit without the hidden effect,
initialised from the record's first second (0-1 s inclusive: mean |V|, P, Q, the angle of a
least-squares line at the first stamp, the mean of `freq_hz`), with the two set-point offsets
(V_ref, n_ref) fitted by Gauss-Newton; `true_params_with_effect` the same with the effect (a
measurement-chain effect applied to the playback: the skew delays the simulated P/Q, the terminal
load is subtracted, the VT ratio divides the played-back voltage). `J = N (rms_P² + rms_Q²)`
with N = `pmu.samples` (the rows present). `effect_visibility`: per channel the excess of the
first over the second in noise sd, and `misfit_without_effect_over_noise` (pooled over P and Q),
`visible` when it exceeds 1.5.

## Files
As the practice sets: `cases/<id>/data.csv` (`time_s, v_re_pu, v_im_pu, p_pu, q_pu, freq_hz[,
efd_pu, ifd_pu]`), `cases/<id>/nominal.json` (bases and the nominal unit with PSS/E names),
`answers/<id>.json` (the key: `hidden_effect` with `type`, `variant`, `params`, the catalog
`cause` to name (`unexplained` outside the catalog), `true_unit` WITHOUT the effect, the effect's
parameter changes in `hidden_effect.truth_changes` and added blocks in `true_unit_ext`,
`nominal_errors`, `event`, `pmu`, `diagnostics`), `answers/index.json` (one line per case).
Answer keys are for scoring only, never input to a run.

## Regenerate
```sh
python3 -m venv target/genvenv && target/genvenv/bin/pip install -r tools/families/requirements.txt
cd tools/families && ../../target/genvenv/bin/python -m famgen make {family} --out ../../data/families
```
Deterministic: every draw comes from the case's seed (`spec.seed` in the key).
"""


def write_index_and_readme(root: str, family: str):
    adir = os.path.join(root, "answers")
    keys = []
    for f in sorted(os.listdir(adir)):
        if f.endswith(".json") and f != "index.json":
            keys.append(json.load(open(os.path.join(adir, f))))
    index = []
    for k in keys:
        he = k["hidden_effect"]
        vis = k["diagnostics"]["oracle"]["effect_visibility"]
        index.append({
            "case": k["case"], "effect": he["type"], "variant": he["variant"], "cause": he["cause"],
            "event": " + ".join(p["kind"] for p in k["event"]["primitives"]) or "ambient",
            "rate_sps": k["pmu"]["rate_sps"], "duration_s": k["pmu"]["duration_s"],
            "samples": k["pmu"]["samples"], "seed": k["seed"],
            "misfit_without_effect_over_noise": round(vis["misfit_without_effect_over_noise"], 2),
            "visible": vis["visible"],
        })
    with open(os.path.join(adir, "index.json"), "w") as fh:
        json.dump(index, fh, indent=1)
    lines = [f"# Data family `{family}`: {len(keys)} PMU events made by our own generator", "",
             INTRO[family], "", COMMON.replace("{family}", family), "", "## Cases", "",
             "| case | effect | variant / strength | cause to name | event | rate | s | rows | noise | misfit without / with effect [sd] | visible |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for k, ix in zip(keys, index):
        he = k["hidden_effect"]
        vis = k["diagnostics"]["oracle"]["effect_visibility"]
        nz = k["pmu"]["noise"]
        col = nz["colour"]
        noise = {"white": "white", "ar1": f"AR(1) {col.get('phi')}", "band": f"band {col.get('f_hi')} Hz"}[col.get("kind", "white")]
        if nz.get("quant_pq"):
            noise += f", quant {nz['quant_pq']}"
        dr = k["pmu"].get("dropouts") or {}
        if dr:
            noise += f", {dr.get('single', 0)} drops, {dr.get('gaps', 0)} gaps"
        if "efd_pu" in k["pmu"]["columns"]:
            noise += ", E_fd/I_fd"
        var = he["variant"] or he.get("strength") or ""
        lines.append(f"| {k['case']} | {he['type']} | {var} | {he['cause']} | {ix['event']} | {ix['rate_sps']:.0f} | "
                     f"{ix['duration_s']:.0f} | {ix['samples']} | {noise} | "
                     f"{vis['misfit_without_effect_over_noise']:.2f} / {vis['misfit_with_effect_over_noise']:.2f} | "
                     f"{'yes' if vis['visible'] else 'no'} |")
    with open(os.path.join(root, "README.md"), "w") as fh:
        fh.write("\n".join(lines) + "\n")
