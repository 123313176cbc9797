"""The base units the families draw their true units from, and the calibratable parameters a
nominal model may get wrong (one list per unit: the practice runner frees the same set)."""

from __future__ import annotations

# The practice family's large hydro unit (GENSAE + SEXS + STAB3 + HYGOV, 737 MVA, 60 Hz): the
# centre of the practice sets' true units.
PRACTICE = {
    "name": "practice",
    "machine_mva": 737.0,
    "system_mva": 1000.0,
    "fn_hz": 60.0,
    "machine": {"model": "GENSAE", "Tpd0": 7.4, "Tppd0": 0.06, "Tppq0": 0.12, "H": 5.0, "D": 0.0,
                "Xd": 0.91, "Xq": 0.66, "Xpd": 0.31, "Xppd": 0.24, "Xppq": 0.24, "Xl": 0.15,
                "S10": 0.1, "S12": 0.3, "R_a": 0.0025},
    "exciter": {"model": "SEXS", "TA_TB": 0.1, "TB": 10.0, "K": 120.0, "TE": 0.04, "EMIN": -3.0,
                "EMAX": 5.5},
    "pss": {"model": "STAB3", "in_service": True, "Tt": 0.02, "TX1": 0.04, "TX2": 2.0, "KX": 1.5,
            "VLIM": 0.1},
    "governor": {"model": "HYGOV", "R": 0.05, "r": 0.35, "Tr": 7.0, "Tf": 0.05, "Tg": 0.5,
                 "VELM": 0.15, "GMAX": 1.0, "GMIN": 0.0, "Tw": 1.5, "At": 1.15, "Dturb": 0.3,
                 "qNL": 0.08, "h0": 1.0},
    "free": [("machine", "H"), ("machine", "Xd"), ("machine", "Xq"), ("machine", "Xpd"),
             ("machine", "Xppd"), ("machine", "Tpd0"), ("machine", "Tppd0"), ("machine", "Tppq0"),
             ("exciter", "K"), ("exciter", "TA_TB"), ("exciter", "TB"), ("exciter", "TE"),
             ("pss", "KX"), ("pss", "TX1"), ("pss", "TX2"),
             ("governor", "R"), ("governor", "r"), ("governor", "Tr"), ("governor", "Tg"),
             ("governor", "Tw")],
    # operating point (system base at the PMU), grid
    "P_sys": (0.55, 0.70), "Q_sys": (-0.05, 0.20), "V0": (0.97, 1.03), "df0_hz": 0.015,
    "X_e": (0.18, 0.30),
    "noise": {"sd_v": 0.0005, "sd_p": 0.002, "sd_q": 0.002, "sd_efd": 0.01, "sd_ifd": 0.005,
              "quant_pq": 0.0014},
}

# Another unit: a medium 50 Hz hydro unit with a salient-pole machine of quadratic saturation
# (GENSAL), a bus-fed static exciter (ESST1A: transducer, transient gain reduction TC/TB,
# commutation loading KC), a speed-input lead-lag stabiliser (IEEEST) and a HYGOV; 300 MVA on a
# 100 MVA system base, so P and Q on the system base run to 3 pu.
OTHER = {
    "name": "other",
    "machine_mva": 300.0,
    "system_mva": 100.0,
    "fn_hz": 50.0,
    "machine": {"model": "GENSAL", "Tpd0": 6.0, "Tppd0": 0.05, "Tppq0": 0.09, "H": 3.5, "D": 0.0,
                "Xd": 1.05, "Xq": 0.68, "Xpd": 0.33, "Xppd": 0.25, "Xppq": 0.25, "Xl": 0.16,
                "S10": 0.12, "S12": 0.38, "R_a": 0.003},
    "exciter": {"model": "ESST1A", "TR": 0.02, "VIMAX": 0.5, "VIMIN": -0.5, "TC": 1.0, "TB": 12.0,
                "TC1": 0.0, "TB1": 0.0, "KA": 200.0, "TA": 0.03, "VAMAX": 7.0, "VAMIN": -6.0,
                "VRMAX": 6.0, "VRMIN": -5.0, "KC": 0.08, "KF": 0.0, "TF": 1.0, "KLR": 0.0,
                "ILR": 4.0},
    "pss": {"model": "IEEEST", "in_service": True, "A1": 0.0, "A2": 0.0, "A3": 0.0, "A4": 0.0,
            "A5": 0.0, "A6": 0.0, "T1": 0.2, "T2": 0.04, "T3": 0.25, "T4": 0.04, "T5": 3.0,
            "T6": 3.0, "KS": 15.0, "LSMAX": 0.1, "LSMIN": -0.1, "VCU": 0.0, "VCL": 0.0},
    "governor": {"model": "HYGOV", "R": 0.04, "r": 0.4, "Tr": 6.0, "Tf": 0.05, "Tg": 0.4,
                 "VELM": 0.2, "GMAX": 1.0, "GMIN": 0.0, "Tw": 1.2, "At": 1.2, "Dturb": 0.5,
                 "qNL": 0.1, "h0": 1.0},
    "free": [("machine", "H"), ("machine", "Xd"), ("machine", "Xq"), ("machine", "Xpd"),
             ("machine", "Xppd"), ("machine", "Tpd0"), ("machine", "Tppd0"), ("machine", "Tppq0"),
             ("exciter", "KA"), ("exciter", "TC"), ("exciter", "TB"), ("exciter", "TA"),
             ("pss", "KS"), ("pss", "T1"), ("pss", "T3"),
             ("governor", "R"), ("governor", "r"), ("governor", "Tr"), ("governor", "Tg"),
             ("governor", "Tw")],
    "P_sys": (2.1, 2.7), "Q_sys": (-0.15, 0.75), "V0": (0.97, 1.03), "df0_hz": 0.012,
    "X_e": (0.15, 0.28),
    # 0.27 % of the rating in P and Q, as the practice family's 2 MW on 737 MVA
    "noise": {"sd_v": 0.0005, "sd_p": 0.008, "sd_q": 0.008, "sd_efd": 0.01, "sd_ifd": 0.005,
              "quant_pq": 0.005},
}

BASES = {"practice": PRACTICE, "other": OTHER}
