"""The four families: per case the unit, the effect (type, variant, strength), the event, the
PMU rate and chain. Everything else (true unit, nominal errors, operating point, grid, event and
effect details, noise) is drawn from the case's seed in `case.py`."""

from __future__ import annotations

# Practice-family strengths are drawn as there; `scale` multiplies an effect's size where the
# family fixes one (the practice2 convention).

AR = lambda phi: {"kind": "ar1", "phi": phi}  # noqa: E731
BAND = lambda f: {"kind": "band", "f_hi": f}  # noqa: E731


def _fam(name, unit, seed0, rows):
    out = []
    for k, r in enumerate(rows):
        cs = {"family": name, "unit": unit, "seed": seed0 + 101 * k}
        cs.update(r)
        out.append(cs)
    return out


# ---------------------------------------------------------------------------------------------
# other_unit: GENSAL + ESST1A + IEEEST (speed) + HYGOV, 50 Hz, 300 MVA; the catalog's effects
# that make sense there, and clean records.
OTHER_UNIT = _fam("other_unit", "other", 31000, [
    {"id": "o01", "effect": {"type": "none"}, "event": {"kind": "fault"}, "rate": 50, "duration": 20},
    {"id": "o02", "effect": {"type": "none"}, "event": {"kind": "freq"}, "rate": 25, "duration": 30},
    {"id": "o03", "effect": {"type": "none"}, "event": {"kind": "vstep"}, "rate": 50, "duration": 25, "extra_channels": True},
    {"id": "o04", "effect": {"type": "none"}, "event": {"kind": "ambient", "amb_scale": 1.5}, "rate": 25, "duration": 30, "quantize": True},
    {"id": "o05", "effect": {"type": "torsional"}, "event": {"kind": "fault"}, "rate": 50, "duration": 20},
    {"id": "o06", "effect": {"type": "exciter_ceiling", "variant": "bus_fed"}, "event": {"kind": "fault"}, "rate": 50, "duration": 20},
    {"id": "o07", "effect": {"type": "exciter_ceiling", "variant": "bus_fed"}, "event": {"kind": "fault", "over": {"dip": 0.55}}, "rate": 25, "duration": 25, "extra_channels": True},
    {"id": "o08", "effect": {"type": "saturation"}, "event": {"kind": "fault"}, "rate": 50, "duration": 25},
    {"id": "o09", "effect": {"type": "governor_deadband", "variant": "deadband"}, "event": {"kind": "freq"}, "rate": 50, "duration": 30},
    {"id": "o10", "effect": {"type": "measurement_skew"}, "event": {"kind": "fault"}, "rate": 50, "duration": 20},
    {"id": "o11", "effect": {"type": "terminal_load"}, "event": {"kind": "vstep"}, "rate": 25, "duration": 25},
    {"id": "o12", "effect": {"type": "pss_missing", "variant": "truth_off"}, "event": {"kind": "fault"}, "rate": 50, "duration": 25},
    {"id": "o13", "effect": {"type": "pss_missing", "variant": "nominal_off"}, "event": {"kind": "fault"}, "rate": 25, "duration": 25},
    {"id": "o14", "effect": {"type": "oel"}, "event": {"kind": "vstep", "over": {"dv": -0.07}}, "rate": 25, "duration": 30},
    {"id": "o15", "effect": {"type": "oel"}, "event": {"kind": "fault", "over": {"post_dv": -0.03, "post_tau": 30.0}}, "rate": 50, "duration": 25, "extra_channels": True},
    {"id": "o16", "effect": {"type": "governor_deadband", "variant": "deadband"}, "event": {"kind": "ambient", "amb_scale": 2.0}, "rate": 50, "duration": 30},
])

# ---------------------------------------------------------------------------------------------
# coloured_noise_dropouts: the practice unit; coloured (AR(1) / band-limited) noise, quantisation,
# single-sample drop-outs and short gaps, other reporting rates.
SINGLE = lambda n: {"single": n}  # noqa: E731
GAPS = lambda g, lo, hi, s=0: {"single": s, "gaps": g, "gap_len": [lo, hi]}  # noqa: E731
COLOURED = _fam("coloured_noise_dropouts", "practice", 32000, [
    {"id": "c01", "effect": {"type": "none"}, "event": {"kind": "fault"}, "rate": 60, "duration": 20, "noise": {"colour": AR(0.9)}, "drops": SINGLE(8)},
    {"id": "c02", "effect": {"type": "none"}, "event": {"kind": "vstep"}, "rate": 20, "duration": 25, "noise": {"colour": BAND(4.0)}, "drops": GAPS(2, 5, 15)},
    {"id": "c03", "effect": {"type": "none"}, "event": {"kind": "freq"}, "rate": 120, "duration": 30, "noise": {"colour": AR(0.7)}, "quantize": True, "drops": SINGLE(20)},
    {"id": "c04", "effect": {"type": "none"}, "event": {"kind": "fault"}, "rate": 15, "duration": 25, "quantize": True, "drops": GAPS(1, 4, 8, 3)},
    {"id": "c05", "effect": {"type": "none"}, "event": {"kind": "ambient"}, "rate": 10, "duration": 30, "noise": {"colour": BAND(2.0)}},
    {"id": "c06", "effect": {"type": "torsional"}, "event": {"kind": "fault"}, "rate": 120, "duration": 20, "noise": {"colour": AR(0.8)}, "drops": SINGLE(10)},
    {"id": "c07", "effect": {"type": "exciter_ceiling", "variant": "bus_fed"}, "event": {"kind": "fault"}, "rate": 60, "duration": 20, "noise": {"colour": BAND(8.0)}, "drops": SINGLE(6)},
    {"id": "c08", "effect": {"type": "saturation"}, "event": {"kind": "fault"}, "rate": 20, "duration": 25, "noise": {"colour": AR(0.9)}, "quantize": True},
    {"id": "c09", "effect": {"type": "governor_deadband", "variant": "deadband"}, "event": {"kind": "freq"}, "rate": 10, "duration": 30, "noise": {"colour": BAND(2.0)}, "drops": GAPS(2, 3, 6)},
    {"id": "c10", "effect": {"type": "measurement_skew"}, "event": {"kind": "fault"}, "rate": 120, "duration": 20, "noise": {"colour": AR(0.6)}, "drops": SINGLE(12)},
    {"id": "c11", "effect": {"type": "terminal_load"}, "event": {"kind": "vstep"}, "rate": 15, "duration": 25, "noise": {"quant_pq": 0.002}, "quantize": True, "drops": SINGLE(4)},
    {"id": "c12", "effect": {"type": "pss_missing", "variant": "truth_off"}, "event": {"kind": "fault"}, "rate": 60, "duration": 25, "noise": {"colour": BAND(10.0)}, "drops": GAPS(1, 10, 20)},
    {"id": "c13", "effect": {"type": "oel"}, "event": {"kind": "vstep", "over": {"dv": -0.07}}, "rate": 20, "duration": 30, "noise": {"colour": AR(0.85)}, "drops": SINGLE(5), "extra_channels": True},
    {"id": "c14", "effect": {"type": "exciter_ceiling", "variant": "constant"}, "event": {"kind": "fault"}, "rate": 30, "duration": 25, "noise": {"colour": AR(0.75)}, "quantize": True, "drops": GAPS(2, 4, 10)},
    {"id": "c15", "effect": {"type": "measurement_skew"}, "event": {"kind": "vstep"}, "rate": 20, "duration": 25, "noise": {"colour": BAND(5.0)}},
    {"id": "c16", "effect": {"type": "pss_missing", "variant": "nominal_off"}, "event": {"kind": "fault"}, "rate": 120, "duration": 20, "noise": {"colour": AR(0.8)}, "drops": GAPS(1, 12, 24, 6)},
])

# ---------------------------------------------------------------------------------------------
# event_shapes: the practice unit; line trip and reclose, slow voltage ramps, two disturbances
# in one record, ambient only, long records.
TRIP = lambda **o: {"primitives": [{"kind": "trip", "t": 3.5, "over": o}]}  # noqa: E731
EVENT_SHAPES = _fam("event_shapes", "practice", 33000, [
    {"id": "e01", "effect": {"type": "none"}, "event": TRIP(), "rate": 30, "duration": 25},
    {"id": "e02", "effect": {"type": "exciter_ceiling", "variant": "constant"}, "event": TRIP(fault_dip=0.5, fault_dur=0.08, z_factor=1.8), "rate": 60, "duration": 25},
    {"id": "e03", "effect": {"type": "measurement_skew"}, "event": TRIP(fault_dip=0.35, fault_dur=0.07), "rate": 60, "duration": 25},
    {"id": "e04", "effect": {"type": "none"}, "event": {"kind": "ramp"}, "rate": 30, "duration": 40},
    {"id": "e05", "effect": {"type": "terminal_load"}, "event": {"kind": "ramp", "over": {"dv": 0.04}}, "rate": 30, "duration": 40},
    {"id": "e06", "effect": {"type": "oel"}, "event": {"kind": "ramp", "over": {"dv": -0.08, "dur": 12.0}}, "rate": 30, "duration": 45, "extra_channels": True},
    {"id": "e07", "effect": {"type": "none"}, "event": {"primitives": [{"kind": "vstep", "t": 3.0}, {"kind": "fault", "t": 14.0}]}, "rate": 60, "duration": 30},
    {"id": "e08", "effect": {"type": "governor_deadband", "variant": "deadband"}, "event": {"primitives": [{"kind": "fault", "t": 3.0, "over": {"f_nadir": 0.05}}, {"kind": "freq", "t": 15.0}]}, "rate": 30, "duration": 35},
    {"id": "e09", "effect": {"type": "pss_missing", "variant": "nominal_off"}, "event": {"primitives": [{"kind": "fault", "t": 3.0}, {"kind": "vstep", "t": 13.0}]}, "rate": 60, "duration": 30},
    {"id": "e10", "effect": {"type": "none"}, "event": {"kind": "ambient", "amb_scale": 2.0}, "rate": 30, "duration": 60},
    {"id": "e11", "effect": {"type": "governor_deadband", "variant": "deadband"}, "event": {"kind": "ambient", "amb_scale": 2.5}, "rate": 30, "duration": 60},
    {"id": "e12", "effect": {"type": "torsional"}, "event": {"kind": "ambient", "amb_scale": 1.5}, "rate": 60, "duration": 40},
    {"id": "e13", "effect": {"type": "none"}, "event": {"primitives": [{"kind": "fault", "t": 20.0}, {"kind": "freq", "t": 90.0}], "amb_scale": 1.5}, "rate": 30, "duration": 150},
    {"id": "e14", "effect": {"type": "governor_deadband", "variant": "deadband"}, "event": {"primitives": [{"kind": "freq", "t": 15.0}, {"kind": "vstep", "t": 70.0}], "amb_scale": 1.5}, "rate": 30, "duration": 120},
    {"id": "e15", "effect": {"type": "saturation"}, "event": {"primitives": [{"kind": "vstep", "t": 10.0, "over": {"dv": 0.04}}, {"kind": "fault", "t": 60.0}], "amb_scale": 1.2}, "rate": 30, "duration": 120},
    {"id": "e16", "effect": {"type": "none"}, "event": TRIP(fault_dip=0.45, fault_dur=0.09), "rate": 60, "duration": 25, "extra_channels": True},
])

# ---------------------------------------------------------------------------------------------
# outside_catalog: effects neither the catalog nor the look-alike list holds, each in two or
# three strengths and events; the practice unit.
HIGH_LOAD = {"P_sys": (0.68, 0.72), "Q_sys": (0.20, 0.26), "V0": (0.99, 1.01)}
HIGH_V = {"V0": (1.035, 1.045), "Q_sys": (0.0, 0.15)}
OUTSIDE = _fam("outside_catalog", "practice", 34000, [
    {"id": "x01", "effect": {"type": "plant_q", "strength": "strong", "params": {"mode": "q", "Ki": 0.025, "Tm": 1.0, "lim": 0.05, "closed_loop_tau_s": 8}}, "event": {"kind": "vstep"}, "rate": 30, "duration": 40},
    {"id": "x02", "effect": {"type": "plant_q", "strength": "weak", "params": {"mode": "q", "Ki": 0.007, "Tm": 1.0, "lim": 0.05, "closed_loop_tau_s": 30}}, "event": {"kind": "fault"}, "rate": 60, "duration": 25},
    {"id": "x03", "effect": {"type": "plant_q", "strength": "medium", "params": {"mode": "poi_v", "Xt": 0.12, "Ki": 0.15, "Tm": 1.0, "lim": 0.05, "closed_loop_tau_s": 15}}, "event": {"kind": "vstep", "over": {"dv": -0.04}}, "rate": 30, "duration": 40},
    {"id": "x04", "effect": {"type": "agc", "strength": "strong", "params": {"moves": [{"t": 6.0, "dur": 20.0, "dgate": 0.012}]}}, "event": {"kind": "ambient"}, "rate": 30, "duration": 40},
    {"id": "x05", "effect": {"type": "agc", "strength": "edge", "params": {"moves": [{"t": 8.0, "dur": 20.0, "dgate": 0.0025}]}}, "event": {"kind": "freq"}, "rate": 30, "duration": 30},
    {"id": "x06", "effect": {"type": "agc", "strength": "medium", "params": {"moves": [{"t": 5.0, "dur": 2.0, "dgate": 0.004}, {"t": 11.0, "dur": 2.0, "dgate": 0.004}, {"t": 17.0, "dur": 2.0, "dgate": -0.003}]}}, "event": {"kind": "fault"}, "rate": 60, "duration": 25},
    {"id": "x07", "effect": {"type": "vhz", "strength": "strong"}, "event": {"kind": "vstep", "over": {"dv": 0.05}}, "rate": 30, "duration": 30, "op": HIGH_V},
    {"id": "x08", "effect": {"type": "vhz", "strength": "medium", "scale": 0.5}, "event": {"kind": "ramp", "over": {"dv": 0.05, "dur": 10.0}}, "rate": 30, "duration": 35, "op": HIGH_V},
    {"id": "x09", "effect": {"type": "scl", "strength": "strong"}, "event": {"kind": "vstep", "over": {"dv": -0.05}}, "rate": 30, "duration": 35, "op": HIGH_LOAD},
    {"id": "x10", "effect": {"type": "scl", "strength": "medium", "scale": 0.5}, "event": {"kind": "fault", "over": {"post_dv": -0.03, "post_tau": 40.0}}, "rate": 60, "duration": 30, "op": HIGH_LOAD},
    {"id": "x11", "effect": {"type": "penstock", "strength": "strong", "params": {"Te": 0.5}}, "event": {"kind": "freq"}, "rate": 30, "duration": 30},
    {"id": "x12", "effect": {"type": "penstock", "strength": "medium", "params": {"Te": 0.3}}, "event": {"kind": "fault"}, "rate": 60, "duration": 25},
    {"id": "x13", "effect": {"type": "penstock", "strength": "edge", "params": {"Te": 0.15}}, "event": {"kind": "freq"}, "rate": 30, "duration": 30},
    {"id": "x14", "effect": {"type": "rotating_exciter", "strength": "strong", "params": {"TE": 1.0, "E1": 4.1, "SE1": 0.08, "E2": 5.5, "SE2": 0.4}}, "event": {"kind": "vstep"}, "rate": 30, "duration": 30},
    {"id": "x15", "effect": {"type": "rotating_exciter", "strength": "medium", "params": {"TE": 0.4, "E1": 4.1, "SE1": 0.05, "E2": 5.5, "SE2": 0.3}}, "event": {"kind": "fault"}, "rate": 60, "duration": 25, "extra_channels": True},
    {"id": "x16", "effect": {"type": "backlash", "strength": "strong", "params": {"b": 0.02}}, "event": {"kind": "freq"}, "rate": 30, "duration": 30},
    {"id": "x17", "effect": {"type": "backlash", "strength": "edge", "params": {"b": 0.006}}, "event": {"kind": "ambient", "amb_scale": 2.0}, "rate": 30, "duration": 40},
    {"id": "x18", "effect": {"type": "pss_limit", "strength": "strong", "params": {"VS_max": 0.02, "VS_min": -0.1}}, "event": {"kind": "fault"}, "rate": 60, "duration": 25},
    {"id": "x19", "effect": {"type": "pss_limit", "strength": "medium", "params": {"VS_max": 0.1, "VS_min": -0.03}}, "event": {"kind": "fault"}, "rate": 30, "duration": 25},
    {"id": "x20", "effect": {"type": "vt_ratio", "strength": "edge", "params": {"k": 1.015}}, "event": {"kind": "fault"}, "rate": 60, "duration": 20},
    {"id": "x21", "effect": {"type": "none"}, "event": {"kind": "fault"}, "rate": 60, "duration": 20},
])

FAMILIES = {
    "other_unit": OTHER_UNIT,
    "coloured_noise_dropouts": COLOURED,
    "event_shapes": EVENT_SHAPES,
    "outside_catalog": OUTSIDE,
}
