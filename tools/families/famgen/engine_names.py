"""PSS/E names of `nominal.json` -> the engine's unit-file names, for the independence check
(the engine's unit files accept its PSS/E aliases; the practice family's JSON names that differ
from them are mapped here, as crates/calib/src/practice.rs maps them)."""

RENAME = {
    "exciter": {"TA_TB": "ta_tb", "TB": "tb", "K": "k", "TE": "te", "EMIN": "e_min", "EMAX": "e_max"},
    "pss": {"Tt": "t_t", "TX1": "t_x1", "TX2": "t_x2", "KX": "k_x", "VLIM": "v_lim"},
    "governor": {"R": "r_perm", "r": "r_temp", "Tr": "t_r", "Tf": "t_f", "Tg": "t_g", "VELM": "velm",
                 "GMAX": "g_max", "GMIN": "g_min", "Tw": "t_w", "At": "a_t", "Dturb": "d_turb",
                 "qNL": "q_nl"},
    "machine": {"D": "d", "Xppq": "x_q_pp", "Xl": "x_l", "S10": "s10", "S12": "s12", "R_a": "r_a"},
}
SKIP = ("model", "in_service", "h0")


def unit_toml(unit: dict, name: str = "truth") -> str:
    """The engine's unit TOML of a unit in the keys' JSON form (bases in `machine_mva`,
    `fn_hz`)."""
    s = f'name = "{name}"\nmachine_mva = {unit["machine_mva"]}\nnominal_hz = {unit["fn_hz"]}\n'
    for sec in ("machine", "exciter", "pss", "governor"):
        d = unit.get(sec)
        if d is None or d.get("in_service", True) is False:
            continue
        s += f'\n[{sec}]\nmodel = "{d["model"]}"\n'
        ren = RENAME[sec] if d["model"] in ("GENSAE", "GENSAL", "SEXS", "STAB3", "HYGOV") else {}
        for k, v in d.items():
            if k in SKIP:
                continue
            s += f"{ren.get(k, k)} = {float(v)!r}\n"
    return s
