"""itaipu_calib.diagnose and synth(hide=...): a cause hidden in a synthetic truth is named.

The diagnoses here are small (8 particles, a few iterations, two causes; about a second): they
check the glue (arguments, results, errors), and that a strong hidden effect is found.
"""

import json
import re
from pathlib import Path

import numpy as np
import pytest

import itaipu_calib as ic

DATA = Path(__file__).resolve().parents[2] / "data"
TRUTH = DATA / "synthetic" / "unit_gensae_sexs_stab3_hygov.toml"
SKEW = [("measurement_skew", {"measurement.pq_delay_s": 0.012})]
QUICK = dict(particles=8, pso_iterations=6, local_iterations=5)


@pytest.fixture(scope="module")
def skewed():
    return ic.synth(TRUTH, duration=8.0, hide=SKEW, seed=1)


@pytest.fixture(scope="module")
def diagnosis(skewed):
    return ic.diagnose(skewed, TRUTH, causes=["measurement_skew", "terminal_load"], **QUICK)


def test_synth_hide_builds_the_extended_truth(skewed):
    ev, truth = ic.synth(TRUTH, duration=8.0, hide={"measurement_skew": {"measurement.pq_delay_s": 0.012}},
                         seed=1, return_truth=True)
    # The dict and list forms are the same request: same event.
    assert np.array_equal(ev.p_pu, skewed.p_pu) and np.array_equal(ev.q_pu, skewed.q_pu)
    assert "pmu_measurement" in truth.models()
    assert truth.parameters()["measurement.pq_delay_s"] == 0.012
    # The extended truth plays the event back to the noise level; the unit as given does not.
    rms = lambda tr: np.sqrt(np.mean((tr.p_pu - tr.p_meas_pu) ** 2))
    assert rms(ic.simulate(ev, truth)) < 0.003
    assert rms(ic.simulate(ev, TRUTH)) > 0.005
    plain = ic.synth(TRUTH, duration=8.0, seed=1)
    assert not np.array_equal(plain.p_pu, skewed.p_pu)


def test_diagnose_names_the_hidden_skew(diagnosis, skewed):
    d = diagnosis
    assert isinstance(d, ic.Diagnosis)
    assert d.cause == "measurement_skew"
    v = d.verdict
    assert set(v) >= {"cause", "title", "statement", "key_parameters", "gains", "where"}
    assert v["cause"] == "measurement_skew"
    key = {p: val for p, val, _unit in v["key_parameters"]}
    # About 12.0 ms recovered (12 ms hidden).
    assert abs(key["measurement.pq_delay_s"] - 0.012) < 0.003, key
    assert v["gains"]["delta_bic"] > 10.0
    assert [c["cause"] for c in d.candidates][0] == "measurement_skew"
    assert {c["cause"] for c in d.candidates} == {"measurement_skew", "terminal_load"}
    assert d.evidence[0]["event"] == skewed.name
    toml = d.extended_unit_toml
    assert toml is not None and 'model = "pmu_measurement"' in toml
    assert "pmu_measurement" in d.extended_unit.models()
    before, after = d.traces_before[skewed.name], d.traces_after[skewed.name]
    assert isinstance(before["p_pu"], np.ndarray) and len(before["time_s"]) == len(skewed)
    rms = lambda tr: np.sqrt(np.mean((tr["p_pu"] - tr["p_meas_pu"]) ** 2))
    assert rms(after) < rms(before)
    assert re.match(r"<Diagnosis of .*: measurement_skew", repr(d))


def test_the_report_round_trips_through_json(diagnosis):
    report = diagnosis.report
    assert report["verdict"]["cause"] == "measurement_skew"
    assert json.loads(json.dumps(report)) == report
    assert json.loads(diagnosis.to_json()) == report


def test_diagnose_errors(skewed):
    # An unknown cause is a bad argument: ValueError, its kind the option at fault (the command
    # line's usage error, exit 2).
    with pytest.raises(ValueError, match="unknown cause 'earthquake'") as e:
        ic.diagnose(skewed, TRUTH, causes=["earthquake"], **QUICK)
    assert e.value.kind == "cause"
    with pytest.raises(ValueError, match="causes"):
        ic.diagnose(skewed, TRUTH, causes=[])
    with pytest.raises(ValueError, match="particles"):
        ic.diagnose(skewed, TRUTH, particles=1)
    with pytest.raises(ValueError, match="threads"):
        ic.diagnose(skewed, TRUTH, threads=0)
    with pytest.raises(TypeError):
        ic.diagnose(42, TRUTH)
    with pytest.raises(ic.UnitModelError):
        ic.diagnose(skewed, DATA / "no-such-unit.toml")


def test_diagnose_refit_frees_calibrated_parameters_again(skewed):
    d = ic.diagnose(skewed, TRUTH, causes=["measurement_skew"], refit={"machine.h": (3.0, 6.0)}, **QUICK)
    assert d.cause == "measurement_skew"
    (b,) = d.report["refit"]
    assert (b["param"], b["min"], b["max"], b["polish_only"]) == ("machine.h", 3.0, 6.0, True)
    # Re-freed in the candidate's re-fit, within its bounds.
    (skew,) = d.candidates
    h = next(p for p in skew["parameters"] if p["param"] == "machine.h")
    assert 3.0 <= h["result"] <= 6.0 and not h["extension"]
    # A list of paths takes each model's declared range.
    d = ic.diagnose(skewed, TRUTH, causes=["measurement_skew"], refit=["exciter.k"], **QUICK)
    (b,) = d.report["refit"]
    assert b["param"] == "exciter.k" and b["min"] < 100.0 < b["max"]


def test_diagnose_refit_errors(skewed):
    with pytest.raises(ValueError, match="machine.nope") as e:
        ic.diagnose(skewed, TRUTH, causes=["measurement_skew"], refit=["machine.nope"], **QUICK)
    assert e.value.kind == "refit"
    with pytest.raises(ValueError, match="machine.h.*upside down"):
        ic.diagnose(skewed, TRUTH, causes=["measurement_skew"], refit={"machine.h": (6.0, 3.0)}, **QUICK)
    with pytest.raises(TypeError, match="refit"):
        ic.diagnose(skewed, TRUTH, refit=3)
    with pytest.raises(TypeError, match=r"refit\['machine.h'\]"):
        ic.diagnose(skewed, TRUTH, refit={"machine.h": "wide"})


def test_synth_hide_errors():
    with pytest.raises(ValueError, match="unknown cause 'earthquake'"):
        ic.synth(TRUTH, duration=3.0, hide=[("earthquake", {})])
    with pytest.raises(ValueError, match="unknown parameter 'shaft.nope'"):
        ic.synth(TRUTH, duration=3.0, hide=[("torsional_mode", {"shaft.nope": 1.0})])
    with pytest.raises(TypeError):
        ic.synth(TRUTH, duration=3.0, hide="torsional_mode")
    # A ceiling below the operating point's field voltage: the truth cannot initialise.
    with pytest.raises(ic.InitError):
        ic.synth(TRUTH, duration=3.0, hide={"exciter_limit": {"exciter.e_max": 0.5}})


def test_diagnose_refits_the_whole_calibrated_set_of_a_fit(skewed):
    # A quick generator-stage fit of the synthetic unit on the skewed event; diagnose(fit=...)
    # re-frees every parameter that stage freed, within the spec's bounds (as `diagnose --fit`).
    spec = DATA / "itaipu" / "calibration.toml"
    f = ic.fit(skewed, TRUTH, calib=spec, stages="gen", seed=1, particles=4, pso_iterations=2,
               local_iterations=1, polish=False)
    d = ic.diagnose(skewed, f.unit, causes=["measurement_skew"], fit=f, **QUICK)
    freed = {b["param"]: (b["min"], b["max"]) for b in d.report["refit"]}
    stage = {p["param"]: (p["min"], p["max"]) for p in f.report["stages"][0]["parameters"]}
    assert freed == stage and len(freed) == 11
    assert all(b["polish_only"] for b in d.report["refit"])
    with pytest.raises(TypeError, match="FitResult"):
        ic.diagnose(skewed, f.unit, causes=["measurement_skew"], fit="not a fit", **QUICK)


# --- a cause written by the user ------------------------------------------------------------

DROOP = DATA / "causes" / "reactive_droop.toml"


def test_a_user_cause_file_is_tried_and_named(tmp_path):
    """The truth has a reactive-current compensator (a user-defined diagram) in front of its SEXS;
    the cause file data/causes/reactive_droop.toml adds the same diagram as an extension."""
    diagram = DATA / "causes" / "reactive_droop.diagram.toml"
    text = TRUTH.read_text().replace('model = "SEXS"', 'model = "SEXS"\nwiring = { v_term = "v_comp" }')
    text += f'\n[[block]]\nname = "droop"\nmodel = "diagram"\ndiagram = "{diagram}"\nx_c = 0.07\n'
    truth = tmp_path / "truth.toml"
    truth.write_text(text)
    ev = ic.synth(truth, duration=10.0, seed=5)
    d = ic.diagnose(ev, TRUTH, causes=["reactive_droop", "terminal_load"], user_causes=DROOP, **QUICK)
    assert d.cause == "reactive_droop"
    # A named cause carries its grade and posterior probability; nothing competes with it.
    assert d.verdict["grade"] in ("strong", "moderate")
    assert 0.0 < d.verdict["probability"] <= 1.0
    assert d.verdict["competing"] == []
    x_c = {p: v for p, v, _ in d.verdict["key_parameters"]}["droop.x_c"]
    assert abs(x_c - 0.07) < 0.01
    assert "diagram" in d.extended_unit.models()


def test_a_bad_user_cause_file_raises_naming_the_file_and_field(tmp_path):
    bad = tmp_path / "bad.toml"
    diagram = str(DATA / "causes" / "reactive_droop.diagram.toml")
    text = DROOP.read_text().replace("reactive_droop.diagram.toml", diagram)
    bad.write_text(text.replace('param = "droop.x_c"', 'param = "droop.k"'))
    with pytest.raises(ic.CalibrationError) as e:
        ic.diagnose(DATA / "itaipu" / "event.toml", TRUTH, user_causes=[bad], **QUICK)
    assert "bad.toml" in str(e.value) and "free[0].param" in str(e.value)
    assert e.value.kind == "spec"
    with pytest.raises(TypeError):
        ic.diagnose(DATA / "itaipu" / "event.toml", TRUTH, user_causes=3, **QUICK)


def test_the_cause_list_is_the_registry_the_diagnosis_uses():
    """ic.causes() is the catalog `diagnose` and `synth(hide=...)` accept: the same ids, in the
    order the unknown-cause message lists them, each with its descriptions."""
    listed = [c["id"] for c in ic.causes()]
    assert len(listed) == len(set(listed)) >= 8
    with pytest.raises(ValueError) as e:
        ic.synth(TRUTH, duration=3.0, hide=[("earthquake", {})])
    known = re.search(r"known: ([a-z_, ]+)", str(e.value)).group(1)
    assert [k.strip() for k in known.split(",")] == listed
    for c in ic.causes():
        assert c["title"] and c["signature"] and c["extension"] and c["key_params"]


MOSTAR = DATA / "mostar"


def test_a_record_without_an_angle_is_diagnosed_in_the_mode_named():
    event, unit = MOSTAR / "event.toml", MOSTAR / "calibrated.toml"
    # Without a mode: the phasor playback needs the angle the record lacks.
    with pytest.raises(ic.EventError, match="angle.*mode="):
        ic.diagnose(event, unit, causes=["terminal_load"], **QUICK)
    with pytest.raises(ValueError, match="mode"):
        ic.diagnose(event, unit, causes=["terminal_load"], mode="open_loop", **QUICK)
    # In exciter_alone only E_fd is compared, each σ from its own pre-step residual; a cause the
    # mode cannot show says why instead of being re-fitted.
    d = ic.diagnose(event, unit, causes=["terminal_load"], mode="exciter_alone", **QUICK)
    noise = d.report["noise"]
    assert noise["playback"] == "exciter_alone: Efd"
    (signal, sigma), = noise["sigmas"]
    assert signal == "Efd" and 0.005 < sigma < 0.1
    (c,) = d.candidates
    assert not c["applicable"] and "exciter_alone" in c["note"]
    assert [s["signal"] for s in d.evidence[0]["signals"]] == ["Efd"]
