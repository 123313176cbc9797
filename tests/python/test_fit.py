"""Tests of itaipu_calib.fit (build and install the module first: `pip install .`).

Every fit here is tiny (a few swarm and L-BFGS iterations, about a second): the tests check the
glue (arguments, results, errors, the GIL), not the quality of a calibration, which the Rust
tests and the command line's end-to-end tests cover.
"""

import _thread
import re
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import itaipu_calib as ic

DATA = Path(__file__).resolve().parents[2] / "data"
EVENT = DATA / "itaipu" / "event.toml"
UNIT = DATA / "itaipu" / "unit.toml"
CALIB = DATA / "itaipu" / "calibration.toml"
N_SAMPLES = 280
QUICK = dict(particles=6, pso_iterations=3, local_iterations=2)


@pytest.fixture(scope="module")
def gen_fit():
    return ic.fit(EVENT, UNIT, calib=CALIB, stages="gen", seed=1, **QUICK)


def _spec_with(tmp_path, old, new):
    """The bundled calibration spec with `old` replaced by `new`, written to a file."""
    text = CALIB.read_text()
    assert old in text, old
    path = tmp_path / "calibration.toml"
    path.write_text(text.replace(old, new))
    return path


def _j(traces):
    """RaPId's J = sum(dP^2 + dQ^2) over every sample (system base)."""
    return float(np.sum((traces.p_pu - traces.p_meas_pu) ** 2 + (traces.q_pu - traces.q_meas_pu) ** 2))


# --- results ----------------------------------------------------------------------------------


def test_fit_report(gen_fit):
    assert isinstance(gen_fit, ic.FitResult)
    assert gen_fit.stages == ["gen"]
    report = gen_fit.report
    assert report["unit"] == "itaipu-60hz-unit"
    assert report["events"] == ["itaipu-60hz-fault"] and report["held_out"] == []
    assert report["seed"] == 1 and report["strategy"] == "sequential"
    [stage] = report["stages"]
    assert stage["stage"] == "gen"
    assert stage["objective_after"] <= stage["objective_before"]
    assert [p["phase"] for p in stage["phases"]][0] == "pso"
    assert stage["phases"][0]["iterations"] == 3
    assert stage["phases"][1]["phase"].startswith("levenberg-marquardt")
    assert stage["fitness"][0]["samples"] == N_SAMPLES
    assert stage["simulations"] > 0
    # The fitness table of the command line: start first, then one row per stage.
    assert gen_fit.fitness == [
        ("start", report["start_fitness"][0]["j_pq"]),
        ("gen", stage["fitness"][0]["j_pq"]),
    ]
    # A new dict on each access.
    report["stages"] = None
    assert gen_fit.report["stages"][0]["stage"] == "gen"
    assert re.match(r"<FitResult 'itaipu-60hz-unit' on itaipu-60hz-fault: stages gen, J ", repr(gen_fit))


def test_fit_calibrated_unit(gen_fit, tmp_path):
    stage = gen_fit.report["stages"][0]
    params = gen_fit.parameters("gen")
    assert list(params) == [p["param"] for p in stage["parameters"]]
    assert len(params) == 11 and "machine.x_d" in params
    for p in stage["parameters"]:
        assert params[p["param"]] == p["result"]
        assert p["min"] <= p["result"] <= p["max"]
    unit = gen_fit.unit
    assert isinstance(unit, ic.Unit) and unit.path is None
    assert unit.models() == ["GENSAE", "SEXS", "STAB3", "constant_pm"]
    calibrated = unit.parameters()
    for name, value in params.items():
        assert calibrated[name] == value, name
    # The stage's `set` values are kept; the blocks the stage left alone are unchanged.
    assert calibrated["machine.x_l"] == 0.13
    start = ic.load_unit(UNIT).parameters()
    assert calibrated["exciter.k"] == start["exciter.k"]
    assert "calibrated by itaipu-calib fit, stages gen, seed 1" in unit.description
    # to_toml writes a unit file that reads back to the same parameters.
    path = tmp_path / "calibrated.toml"
    path.write_text(unit.to_toml())
    assert ic.load_unit(path).parameters() == calibrated
    with pytest.raises(KeyError, match="no stage 'avr'"):
        gen_fit.parameters("avr")


def test_fit_traces(gen_fit):
    start, calibrated = gen_fit.traces("gen")
    assert isinstance(start, ic.Traces) and isinstance(calibrated, ic.Traces)
    event = ic.load_event(EVENT)
    for tr in (start, calibrated):
        assert len(tr) == N_SAMPLES
        assert tr.p_pu.shape == (N_SAMPLES,) and tr.p_pu.dtype == np.float64
        np.testing.assert_array_equal(tr.p_meas_pu, event.p_pu)
    # The traces are those the report scores (the fit window is the whole record).
    stage = gen_fit.report["stages"][0]
    # The stage objective is J plus the datasheet prior's term, reported on its own.
    assert stage["prior_before"] >= 0.0
    assert _j(start) == pytest.approx(stage["objective_before"] - stage["prior_before"], rel=1e-12)
    assert _j(calibrated) == pytest.approx(stage["fitness"][0]["j_pq"], rel=1e-12)
    # Every stage simulates the whole unit (stage_blocks = "keep"): the gen stage's unit has the
    # exciter, at its starting values.
    assert any(c.startswith("exciter.") for c in calibrated.columns)
    again = gen_fit.traces("gen", event="itaipu-60hz-fault")[1]
    np.testing.assert_array_equal(again.q_pu, calibrated.q_pu)
    with pytest.raises(KeyError, match="no stage 'pss'"):
        gen_fit.traces("pss")
    with pytest.raises(KeyError, match="no event 'other'"):
        gen_fit.traces("gen", event="other")


def test_fit_is_deterministic(gen_fit):
    # Same seed (loaded objects this time, and a list of events): the same numbers.
    # A held-out event (here the same record) is scored, not fitted, and not in `fitness`.
    event = ic.load_event(EVENT)
    same = ic.fit([event], ic.load_unit(UNIT), calib=str(CALIB), stages=["gen"], seed=1, held_out=event, **QUICK)
    assert same.parameters("gen") == gen_fit.parameters("gen")
    assert same.fitness == gen_fit.fitness
    assert same.report["held_out"] == ["itaipu-60hz-fault"]
    rows = same.report["stages"][0]["fitness"]
    assert [row["held_out"] for row in rows] == [False, True]
    assert rows[1]["j_pq"] == rows[0]["j_pq"]
    other = ic.fit(EVENT, UNIT, calib=CALIB, stages="gen", seed=2, **QUICK)
    pso = lambda r: r.report["stages"][0]["phases"][0]  # noqa: E731
    assert pso(other)["best_objective"] != pso(gen_fit)["best_objective"]
    assert other.parameters("gen") != gen_fit.parameters("gen")
    assert other.report["seed"] == 2


def test_fit_threads_set_the_pool_not_the_numbers(gen_fit):
    # `threads`: a pool of its own for the call (as diagnose's); the same seed gives the same
    # numbers on 1 and 3 threads as on the default pool.
    for n in (1, 3):
        r = ic.fit(EVENT, UNIT, calib=CALIB, stages="gen", seed=1, threads=n, **QUICK)
        assert r.report["threads"] == n
        assert r.fitness == gen_fit.fitness
        assert r.parameters("gen") == gen_fit.parameters("gen")
    with pytest.raises(ValueError, match="threads must be at least 1"):
        ic.fit(EVENT, UNIT, calib=CALIB, stages="gen", threads=0)
    with pytest.raises(ValueError, match="threads"):
        ic.fit(EVENT, UNIT, calib=CALIB, stages="gen", threads=-1)


def test_fit_two_stages_then_joint_polish():
    r = ic.fit(EVENT, UNIT, calib=CALIB, stages="gen,avr", **QUICK)
    assert r.stages == ["gen", "avr", "joint"]
    assert [row[0] for row in r.fitness] == ["start", "gen", "avr", "joint"]
    for stage in r.report["stages"]:
        assert stage["objective_after"] <= stage["objective_before"]
    joint = r.parameters("joint")
    assert set(joint) == set(r.parameters("gen")) | set(r.parameters("avr"))
    calibrated = r.unit.parameters()
    for name, value in joint.items():
        assert calibrated[name] == value, name
    # Stages run in the fixed order whatever order they are given in; no polish on request.
    r = ic.fit(EVENT, UNIT, calib=CALIB, stages=["avr", "GEN"], polish=False, **QUICK)
    assert r.stages == ["gen", "avr"]


def test_gil_released_while_fitting():
    """A pure-Python thread keeps running while fit() works (the generator stage with the
    default swarm, about half a second; the quick options' fit takes 0.04 s since its
    identifiability Jacobian comes from exact sensitivities, too short to tell); see
    test_gil_released_while_simulating."""
    count = [0]
    stop = threading.Event()

    def spin():
        while not stop.is_set():
            count[0] += 1

    thread = threading.Thread(target=spin)
    thread.start()
    try:
        time.sleep(0.05)
        c0, t0 = count[0], time.perf_counter()
        time.sleep(0.1)
        rate = (count[0] - c0) / (time.perf_counter() - t0)  # spins per second, GIL free
        c0, t0 = count[0], time.perf_counter()
        ic.fit(EVENT, UNIT, calib=CALIB, stages="gen")
        elapsed = time.perf_counter() - t0
        spins = count[0] - c0
    finally:
        stop.set()
        thread.join()
    assert elapsed > 0.05, "fit too short to tell"
    assert spins > 0.1 * rate * elapsed, (spins, rate, elapsed)


def test_ctrl_c_stops_a_fit_promptly():
    """Ctrl-C (KeyboardInterrupt) during fit() stops it at its next candidate evaluation and is
    raised at once, instead of after the whole calibration (issue 13).

    A process started in the background by a non-interactive shell (as a CI runner may start
    the suite) inherits SIGINT ignored, and then Python installs no handler and
    `interrupt_main` does nothing: the test installs Python's own handler, as an interactive
    session has it, for its duration."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(0.3, _thread.interrupt_main)
    t0 = time.perf_counter()
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            # Tens of seconds uninterrupted.
            ic.fit(EVENT, UNIT, calib=CALIB, stages="gen,avr,pss", particles=40,
                   pso_iterations=400, local_iterations=100)
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
    elapsed = time.perf_counter() - t0
    assert 0.3 <= elapsed < 5.0, elapsed
    # The module works on afterwards.
    r = ic.fit(EVENT, UNIT, calib=CALIB, stages="gen", **QUICK)
    assert r.stages == ["gen"]


# --- errors -----------------------------------------------------------------------------------


def test_fit_bad_options(gen_fit):
    with pytest.raises(ValueError, match="unknown stage 'foo'"):
        ic.fit(EVENT, UNIT, calib=CALIB, stages="gen,foo")
    with pytest.raises(ValueError, match="stages"):
        ic.fit(EVENT, UNIT, calib=CALIB, stages=[])
    with pytest.raises(TypeError, match="stages"):
        ic.fit(EVENT, UNIT, calib=CALIB, stages=3)
    with pytest.raises(ValueError, match="strategy"):
        ic.fit(EVENT, UNIT, calib=CALIB, strategy="greedy")
    with pytest.raises(ValueError, match="particles"):
        ic.fit(EVENT, UNIT, calib=CALIB, particles=1)
    with pytest.raises(TypeError, match="events"):
        ic.fit(42, UNIT, calib=CALIB)
    with pytest.raises(TypeError, match=re.escape("events[1]")):
        ic.fit([EVENT, 42], UNIT, calib=CALIB)
    with pytest.raises(TypeError, match="unit"):
        ic.fit(EVENT, 42, calib=CALIB)
    with pytest.raises(TypeError):
        ic.fit(EVENT, UNIT, CALIB)  # options are keyword-only
    # A unit that was not read from a file has no [calibration] table of its own.
    with pytest.raises(ValueError, match="calib"):
        ic.fit(EVENT, gen_fit.unit)


def test_calibration_error_hierarchy():
    assert issubclass(ic.CalibrationError, ic.ItaipuError)


def test_upside_down_bounds(tmp_path):
    spec = _spec_with(
        tmp_path,
        '{ param = "machine.x_d", min = 0.6, max = 2.0 }',
        '{ param = "machine.x_d", min = 2.0, max = 0.6 }',
    )
    with pytest.raises(ic.CalibrationError) as info:
        ic.fit(EVENT, UNIT, calib=spec, stages="gen", **QUICK)
    assert info.value.kind == "field"
    assert str(info.value) == (
        f"{spec}: calibration.stage[0].free[0] (machine.x_d): bounds upside down or empty: min 2 >= max 0.6"
    )


def test_unknown_free_parameter(tmp_path):
    spec = _spec_with(tmp_path, 'param = "machine.x_d",', 'param = "machine.x_dd",')
    with pytest.raises(ic.CalibrationError) as info:
        ic.fit(EVENT, UNIT, calib=spec, stages="gen", **QUICK)
    assert "machine.x_dd" in str(info.value)
    assert info.value.kind == "spec"


def test_missing_calibration_table_takes_the_default_spec_by_roles():
    # The bundled unit file has no [calibration] table: the fit derives the default spec from
    # the models' roles (the machine's reactances and time constants in the generator stage).
    for unit in (UNIT, ic.load_unit(UNIT)):
        r = ic.fit(EVENT, unit, stages="gen", **QUICK)
        params = r.parameters("gen")
        assert {"machine.x_d", "machine.x_q", "machine.h"} <= set(params), sorted(params)
        assert r.fitness[-1][1] <= r.fitness[0][1]


def test_stage_not_in_spec(tmp_path):
    spec = tmp_path / "gen_only.toml"
    text = CALIB.read_text()
    spec.write_text(text[: text.index('[[calibration.stage]]\nname = "avr"')])
    with pytest.raises(ic.CalibrationError) as info:
        ic.fit(EVENT, UNIT, calib=spec, stages="avr", **QUICK)
    assert info.value.kind == "setup"
    assert "'avr'" in str(info.value)


def test_fit_file_errors(tmp_path):
    missing = tmp_path / "no_such_calib.toml"
    with pytest.raises(ic.CalibrationError) as info:
        ic.fit(EVENT, UNIT, calib=missing)
    assert info.value.kind == "io" and str(missing) in str(info.value)
    with pytest.raises(ic.EventError) as info:
        ic.fit([EVENT, tmp_path / "no_such_event.toml"], UNIT, calib=CALIB)
    assert info.value.kind == "io"
    with pytest.raises(ic.EventError, match="no_such_held_out.toml"):
        ic.fit(EVENT, UNIT, calib=CALIB, held_out=[tmp_path / "no_such_held_out.toml"])
    with pytest.raises(ic.UnitModelError) as info:
        ic.fit(EVENT, tmp_path / "no_such_unit.toml", calib=CALIB)
    assert info.value.kind == "io"
