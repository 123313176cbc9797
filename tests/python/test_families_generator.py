"""The data-family generator (tools/families): deterministic, every unit and effect starts in
exact steady state, a clean case's record is flat before its event, the grid run and the
playback form of the same equations agree, and the practice unit initialises as the practice
set's independent generator did (its bundled key)."""

import copy
import json
import math
import pathlib
import sys

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools" / "families"))


from famgen import sim  # noqa: E402
from famgen.case import Case  # noqa: E402
from famgen.units import BASES  # noqa: E402
from famgen.unit import TrueUnit  # noqa: E402

# Every effect inside the unit, with parameters of its family's size.
EFFECTS = [
    {},
    {"shaft": {"Ht_frac": 0.1, "f_tor_hz": 9.0, "zeta": 0.002}},
    {"govdb": {"db": 0.0004}},
    {"oel": {"ifd_rated": 2.5, "I_pu": 1.05, "A_max": 1.0, "I_lim": 1.0, "Ki": 0.06, "Vmin": -0.15}},
    {"ceiling": {"mode": "bus_fed", "VRMAX": 4.0, "KC": 0.1}},
    {"plant_q": {"mode": "poi_v", "Xt": 0.12, "Tm": 1.0, "Ki": 0.1, "lim": 0.05}},
    {"plant_q": {"mode": "q", "Tm": 1.0, "Ki": 0.02, "lim": 0.05}},
    {"vhz": {"pickup": 1.1, "Ki": 2.0, "Vmin": -0.1, "Treset": 10.0}},
    {"scl": {"I_pu": 1.2, "A_max": 1.0, "I_lim": 1.15, "Ki": 0.2, "Vmin": -0.1}},
    {"penstock": {"sections": 6, "Te": 0.3}},
    {"backlash": {"b": 0.01, "start": 0.3}},
    {"pss_limit": {"VS_max": 0.02, "VS_min": -0.1}},
]
SEXS_ONLY = [{"rotating_exciter": {"TE": 0.8, "E1": 4.1, "SE1": 0.08, "E2": 5.5, "SE2": 0.4}}]


def unit_spec(base, ext, mc=None):
    s = {k: copy.deepcopy(base[k]) for k in ("machine", "exciter", "pss", "governor")}
    s.update(machine_mva=base["machine_mva"], system_mva=base["system_mva"], fn_hz=base["fn_hz"],
             ext=copy.deepcopy(ext), mc=mc or {})
    return s


@pytest.mark.parametrize("base", ["practice", "other"])
def test_every_unit_and_effect_starts_in_steady_state(base):
    b = BASES[base]
    exts = EFFECTS + (SEXS_ONLY if b["exciter"]["model"] == "SEXS" else [])
    for ext in exts:
        for dw0 in (0.0, 2.0e-4):
            u = TrueUnit(unit_spec(b, ext, {"load_P": 0.03, "load_Q": 0.01}))
            P, Q, V0, th0 = 0.85, 0.2, 1.01, 0.4
            x0 = u.init(P, Q, V0, th0, dw0)
            u.set_playback(lambda t: V0, lambda t: th0 + u.wb * dw0 * t)
            dx = u.rhs(0.0, x0)
            dx[0] -= u.wb * dw0
            assert max(abs(v) for v in dx) < 1e-10, (base, ext, dw0, dx)
            o = u.outputs(0.0, x0)
            assert abs(o["P"] - P) < 1e-12 and abs(o["Q"] - Q) < 1e-12


def test_practice_unit_initialises_as_the_practice_generator():
    """The practice set's key (made by an independent generator) states E_fd0, delta0, P_m0 and
    the gate of its true unit at its operating point: ours must give the same."""
    key = json.loads((ROOT / "data" / "practice" / "answers" / "p01.json").read_text())
    tu, op = key["true_unit"], key["operating_point"]
    spec = {"machine_mva": 737.0, "system_mva": 1000.0, "fn_hz": 60.0, "ext": {}, "mc": {},
            **{k: tu[k] for k in ("machine", "exciter", "pss", "governor")}}
    u = TrueUnit(spec)
    x0 = u.init(op["P_gen_machine_pu"], op["Q_gen_machine_pu"], op["V0"],
                math.radians(op["theta0_deg"]), (op["f0_hz"] - 60.0) / 60.0)
    assert abs(u.Efd0 - op["Efd0"]) < 1e-9
    assert abs(x0[0] - op["delta0_rad"]) < 1e-9
    assert abs(u.Pm0 - op["Pm0"]) < 1e-9
    assert abs(u.geff0 - op["gate0"]) < 1e-9


SHORT = {"id": "t01", "family": "test", "unit": "practice", "seed": 4242,
         "effect": {"type": "none"}, "event": {"kind": "vstep", "t": 3.0}, "rate": 30,
         "duration": 6.0}


def build(cs):
    c = Case(copy.deepcopy(cs)).build()
    return c


@pytest.fixture(scope="module")
def short_case():
    return build(SHORT)


def test_the_generator_is_deterministic(short_case, tmp_path):
    again = build(SHORT)
    a, b = tmp_path / "a", tmp_path / "b"
    short_case.write(str(a))
    again.write(str(b))
    for rel in ("cases/t01/data.csv", "cases/t01/nominal.json"):
        assert (a / rel).read_bytes() == (b / rel).read_bytes()
    ka = json.loads((a / "answers/t01.json").read_text())
    kb = json.loads((b / "answers/t01.json").read_text())
    ka.pop("generation_seconds")
    kb.pop("generation_seconds")
    assert ka == kb
    # another seed is another case
    other = build({**SHORT, "seed": 4243})
    assert not np.array_equal(other.rec["p"], short_case.rec["p"])


def test_a_clean_case_is_steady_before_its_event(short_case):
    key = short_case.key
    assert key["diagnostics"]["init_max_abs_derivative_stageA"] < 1e-10
    # the grid run and the playback of its terminal voltage agree (the network solution
    # against the playback form of the same unit)
    ab = key["diagnostics"]["stageA_vs_stageB"]
    assert ab["max_abs_dP"] < 1e-6 and ab["max_abs_dQ"] < 1e-6
    t, rec = short_case.rec["t"], short_case.rec
    pre = t < 2.9
    sd_p, sd_q = key["pmu"]["noise"]["sd_p"], key["pmu"]["noise"]["sd_q"]
    n = pre.sum()
    # flat within noise: the pre-event scatter is the noise (ambient background included),
    # and the pre-event mean is the operating point within 4 standard errors
    for ch, sd, op in (("p", sd_p, key["operating_point"]["P_sys"]), ("q", sd_q, key["operating_point"]["Q_sys"])):
        x = rec[ch][pre]
        assert 0.7 * sd < np.std(x) < 1.4 * sd, (ch, np.std(x), sd)
        assert abs(np.mean(x) - op) < 4 * 1.4 * sd / math.sqrt(n), (ch, np.mean(x), op)
        # no trend before the event: the slope over the window explains nothing
        slope = np.polyfit(t[pre], x, 1)[0]
        assert abs(slope) * (t[pre][-1] - t[pre][0]) < 2 * sd
    # the clean record's floor: the true unit played back misses by about the noise
    vis = key["diagnostics"]["oracle"]["effect_visibility"]
    assert 1.0 < vis["misfit_without_effect_over_noise"] < 1.5


def test_without_ambient_the_pre_event_response_is_exactly_flat():
    """The unit against its grid with no event and no ambient motion stays where it started."""
    b = BASES["other"]
    spec = unit_spec(b, {})
    op = {"P_sys": 2.4, "Q_sys": 0.3, "V0": 1.01, "theta0": 0.5, "f0_hz": 50.004}
    ev = {"primitives": [], "amb": {"sd_m": 0.0, "sd_f": 0.0, "tau_f": 10.0, "ia_amp_deg": 0.0,
                                    "f_ia": 0.5, "zeta_ia": 0.1}, "amb_seed": 1}
    t = np.arange(0, 5.0, 0.05)
    _, out, info = sim.run_grid(spec, op, {"R_e": 0.004, "X_e": 0.2}, ev, 5.0, t)
    assert info["init_max_abs_derivative"] < 1e-10
    assert np.ptp(out["P"]) < 1e-8 and np.ptp(out["Q"]) < 1e-8
    assert abs(out["P"][0] - op["P_sys"]) < 1e-12 and abs(out["Q"][0] - op["Q_sys"]) < 1e-12
