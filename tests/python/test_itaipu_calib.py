"""Tests of the installed itaipu_calib module (build and install it first: `pip install .`)."""

import os
import re
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import itaipu_calib as ic

DATA = Path(__file__).resolve().parents[2] / "data"
EVENT = DATA / "itaipu" / "event.toml"
UNIT = DATA / "itaipu" / "unit.toml"
N_SAMPLES = 280


@pytest.fixture(scope="module")
def traces():
    return ic.simulate(EVENT, UNIT)


def _unit_text(**exciter_overrides):
    """The bundled unit file with some exciter lines replaced."""
    text = UNIT.read_text()
    for key, value in exciter_overrides.items():
        text, n = re.subn(rf"(?m)^{key}\s*=.*$", f"{key} = {value}", text)
        assert n == 1, key
    return text


# --- simulate -------------------------------------------------------------------------------


def test_simulate_bundled_event(traces):
    assert len(traces) == N_SAMPLES
    assert traces.time_s.shape == (N_SAMPLES,)
    assert traces.time_s.dtype == np.float64
    for name in ("p_pu", "q_pu", "p_meas_pu", "q_meas_pu"):
        assert name in traces.columns
    for name in traces.columns:
        col = traces[name]
        assert col.shape == (N_SAMPLES,), name
        assert np.all(np.isfinite(col)), name
    # Starts at the measured pre-event operating point (system base).
    op = ic.load_event(EVENT).operating_point()
    assert abs(traces.p_pu[0] - op["p_pu"]) < 0.01
    assert abs(traces.q_pu[0] - op["q_pu"]) < 0.01
    assert abs(traces.p_pu[0] - traces.p_meas_pu[0]) < 0.01
    assert abs(traces.q_pu[0] - traces.q_meas_pu[0]) < 0.01
    # Machine-base signals are the system-base ones rescaled.
    unit = ic.load_unit(UNIT)
    event = ic.load_event(EVENT)
    k = unit.machine_mva / event.system_mva
    np.testing.assert_allclose(traces.pe * k, traces.p_pu, rtol=1e-12)
    np.testing.assert_allclose(traces.qe * k, traces.q_pu, rtol=1e-12)
    np.testing.assert_array_equal(traces.p_meas_pu, event.p_pu)


def test_simulate_is_deterministic(traces):
    again = ic.simulate(str(EVENT), str(UNIT))
    assert again.columns == traces.columns
    for name in traces.columns:
        np.testing.assert_array_equal(again[name], traces[name])
    assert again.stats == traces.stats


def test_rk4_agrees_with_dopri5(traces):
    rk4 = ic.simulate(EVENT, UNIT, method="rk4", step=0.001)
    assert np.max(np.abs(rk4.p_pu - traces.p_pu)) < 1e-3
    assert np.max(np.abs(rk4.q_pu - traces.q_pu)) < 1e-3
    assert rk4.stats["steps_rejected"] == 0


def test_simulate_accepts_loaded_objects(traces):
    event = ic.load_event(EVENT)
    unit = ic.load_unit(UNIT)
    for ev, un in ((event, unit), (event, UNIT), (os.fspath(EVENT), unit)):
        t = ic.simulate(ev, un)
        np.testing.assert_array_equal(t.p_pu, traces.p_pu)
        np.testing.assert_array_equal(t.q_pu, traces.q_pu)


def test_traces_api(traces):
    assert isinstance(traces, ic.Traces)
    d = traces.to_dict()
    assert list(d) == ["time_s"] + traces.columns
    np.testing.assert_array_equal(d["p_pu"], traces["p_pu"])
    np.testing.assert_array_equal(traces["time_s"], traces.time_s)
    assert "p_pu" in traces and "time_s" in traces and "nope" not in traces
    assert "p_pu" in dir(traces)
    # States are named block.state and reachable by item access.
    assert any(name.startswith("machine.") for name in traces.columns)
    stats = traces.stats
    assert set(stats) == {"steps_accepted", "steps_rejected", "rhs_evals", "events"}
    assert stats["steps_accepted"] > 0 and stats["rhs_evals"] > stats["steps_accepted"]
    assert re.match(r"<Traces: 280 samples, ", repr(traces))
    with pytest.raises(KeyError):
        traces["nope"]
    with pytest.raises(AttributeError, match="nope"):
        traces.nope
    # Arrays are copies: changing one does not change the traces.
    p = traces.p_pu
    p[:] = 0.0
    assert traces.p_pu[0] != 0.0


def test_bad_options():
    with pytest.raises(ValueError, match="method"):
        ic.simulate(EVENT, UNIT, method="euler")
    with pytest.raises(ValueError, match="step"):
        ic.simulate(EVENT, UNIT, method="rk4", step=0.0)
    with pytest.raises(ValueError, match="rtol"):
        ic.simulate(EVENT, UNIT, rtol=-1.0)
    with pytest.raises(TypeError, match="event"):
        ic.simulate(42, UNIT)
    with pytest.raises(TypeError):
        ic.simulate(EVENT, UNIT, "rk4")  # options are keyword-only


def test_gil_released_concurrent_threads(traces):
    results = [None, None]
    errors = []
    barrier = threading.Barrier(2)

    def run(k):
        try:
            barrier.wait()
            results[k] = ic.simulate(EVENT, UNIT)
        except Exception as e:  # pragma: no cover - reported below
            errors.append(e)

    threads = [threading.Thread(target=run, args=(k,)) for k in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert not errors
    for r in results:
        assert r is not None
        np.testing.assert_array_equal(r.p_pu, traces.p_pu)
        np.testing.assert_array_equal(r.q_pu, traces.q_pu)
    np.testing.assert_array_equal(results[0].to_dict()["efd"], results[1].to_dict()["efd"])


def test_gil_released_while_simulating():
    """A pure-Python thread keeps running while simulate() integrates (about 0.5 s of work).

    With the GIL held for the whole call the spinning thread could only run for one switch
    interval (5 ms) around the call; with it released it runs throughout.
    """
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
        ic.simulate(EVENT, UNIT, method="rk4", step=2e-5)
        elapsed = time.perf_counter() - t0
        spins = count[0] - c0
    finally:
        stop.set()
        thread.join()
    assert elapsed > 0.05, "simulation too short to tell"
    assert spins > 0.1 * rate * elapsed, (spins, rate, elapsed)


# --- loading ----------------------------------------------------------------------------------


def test_load_event():
    event = ic.load_event(EVENT)
    assert event.name == "itaipu-60hz-fault"
    assert event.system_mva == 1000.0
    assert event.nominal_hz == 60.0
    assert len(event) == N_SAMPLES
    for arr in (event.time_s, event.v_mag_pu, event.v_ang_rad, event.p_pu, event.q_pu):
        assert arr.shape == (N_SAMPLES,) and arr.dtype == np.float64
    assert event.freq_hz is None
    # The init window is found from the record: from its start to 3 samples before the onset
    # the data show (1.0167 s, sample 61 at 60 samples/s).
    assert event.init == pytest.approx((0.0, 58 / 60), abs=1e-12)
    assert event.toml_path == EVENT
    op = event.operating_point()
    assert set(op) == {"v_mag_pu", "v_ang_rad", "p_pu", "q_pu", "freq_hz", "t0_s", "n_samples"}
    assert 0.9 < op["v_mag_pu"] < 1.1
    assert abs(op["p_pu"] - event.p_pu[0]) < 0.01
    assert "itaipu-60hz-fault" in repr(event)


def test_load_unit(tmp_path):
    unit = ic.load_unit(UNIT)
    assert unit.name == "itaipu-60hz-unit"
    assert unit.machine_mva == 737.0
    assert unit.nominal_hz == 60.0
    assert unit.models() == ["GENSAE", "SEXS", "STAB3", "constant_pm"]
    assert unit.blocks()["exciter"] == "SEXS"
    params = unit.parameters()
    assert params["machine.h"] == 4.5
    assert params["machine.t_d0_prime"] == 7.0
    assert params["exciter.e_max"] == 4.5
    # to_toml writes a file that reads back to the same unit.
    path = tmp_path / "roundtrip.toml"
    path.write_text(unit.to_toml())
    assert ic.load_unit(path).parameters() == params


def test_models_library():
    lib = ic.models()
    by_name = {m["name"]: m for m in lib}
    assert {"GENSAE", "GENSAL", "GENROU", "GENCLS", "SEXS", "STAB3", "IEEEST", "HYGOV"} <= set(by_name)
    gensae = by_name["GENSAE"]
    assert gensae["role"] == "machine"
    assert gensae["summary"]
    params = {p["name"]: p for p in gensae["parameters"]}
    tpd0 = params["t_d0_prime"]
    assert tpd0["alias"] == "Tpd0"
    assert tpd0["unit"] == "s"
    lo, hi = tpd0["range"]
    assert lo <= tpd0["typical"] <= hi
    assert tpd0["doc"]
    assert by_name["SEXS"]["role"] == "exciter"
    assert any(p["name"] == "efd" and p["direction"] == "out" for p in by_name["SEXS"]["ports"])


# --- errors -----------------------------------------------------------------------------------


def test_exception_hierarchy():
    for cls in (ic.EventError, ic.UnitModelError, ic.InitError, ic.SimulationError):
        assert issubclass(cls, ic.ItaipuError)
    assert issubclass(ic.ItaipuError, Exception)


def test_missing_event_file(tmp_path):
    missing = tmp_path / "no_such_event.toml"
    with pytest.raises(ic.EventError) as info:
        ic.simulate(missing, UNIT)
    assert str(missing) in str(info.value)
    assert info.value.kind == "io"
    with pytest.raises(ic.EventError, match="no_such_event.toml"):
        ic.load_event(missing)


def test_missing_unit_file(tmp_path):
    missing = tmp_path / "no_such_unit.toml"
    with pytest.raises(ic.UnitModelError) as info:
        ic.simulate(EVENT, missing)
    assert str(missing) in str(info.value)
    assert info.value.kind == "io"


def test_unknown_unit_parameter(tmp_path):
    path = tmp_path / "unit.toml"
    path.write_text(UNIT.read_text().replace("h = 4.5", "h = 4.5\nx_bogus = 1.0"))
    with pytest.raises(ic.UnitModelError) as info:
        ic.simulate(EVENT, path)
    msg = str(info.value)
    assert msg.startswith(f"{path}: machine.x_bogus: unknown parameter of GENSAE")
    assert info.value.kind == "field"
    with pytest.raises(ic.UnitModelError, match="machine.x_bogus"):
        ic.load_unit(path)


def test_unknown_csv_column(tmp_path):
    csv = tmp_path / "rec.csv"
    rows = ["time_s,v_re_pu,v_im_pu,p_pu,q_pu,bogus"]
    rows += [f"{k / 60},1.0,0.0,0.5,0.1,0" for k in range(30)]
    csv.write_text("\n".join(rows) + "\n")
    event = tmp_path / "event.toml"
    event.write_text('name = "x"\ncsv = "rec.csv"\nsystem_mva = 1000.0\nnominal_hz = 60.0\n')
    with pytest.raises(ic.EventError) as info:
        ic.simulate(event, UNIT)
    assert info.value.kind == "unknown_column"
    # Exactly the Rust message (what the command line prints after "error: ").
    assert str(info.value) == (
        f"{csv} line 1: unknown column 'bogus'; accepted columns are: time_s, v_re_pu, v_im_pu, "
        "v_pu, angle_deg, v_mag_pu, v_ang_rad, p_pu, q_pu, freq_hz, efd_pu, ifd_pu"
    )


def test_exciter_limit_below_initial_field_voltage(tmp_path, traces):
    efd0 = float(traces.efd[0])
    assert efd0 > 0.2
    path = tmp_path / "unit.toml"
    path.write_text(_unit_text(e_min=0.0, e_max=round(efd0 / 2, 4)))
    with pytest.raises(ic.InitError) as info:
        ic.simulate(EVENT, path)
    msg = str(info.value)
    assert msg.startswith("initialisation failed: exciter (SEXS): ")
    assert "E_fd0" in msg and "E_MAX" in msg
    assert info.value.kind == "init"


def test_frequency_mismatch_names_the_event(tmp_path):
    path = tmp_path / "unit50.toml"
    path.write_text(_unit_text().replace("nominal_hz = 60.0", "nominal_hz = 50.0"))
    with pytest.raises(ic.InitError) as info:
        ic.simulate(EVENT, path)
    assert info.value.kind == "frequency_mismatch"
    assert "itaipu-60hz-fault" in str(info.value) and "50 Hz" in str(info.value)


# --- plausibility ------------------------------------------------------------------------------


def test_check_finds_a_dropout_at_its_line_and_passes_the_bundled_record(tmp_path):
    """ic.check runs the command line's plausibility layer (issue 13): on the bundled record
    and unit only the record's measurement drop-out at its end (issue 25, a warning from 4.4 s);
    a one-sample |V| = 0 is an error naming the CSV line, the column and a fix; h = 1e308 in the
    unit a warning naming the parameter."""
    edge = [("warning", "edge_dropout", 266, "|V|")]
    key = lambda fs: [(f["severity"], f["kind"], f["line"], f["column"]) for f in fs]
    assert key(ic.check(EVENT, UNIT)) == edge
    assert [(f["severity"], f["kind"]) for f in
            ic.check(ic.load_event(EVENT), ic.load_unit(UNIT))] == [("warning", "edge_dropout")]
    lines = (DATA / "itaipu" / "itaipu_pmu_60sps.csv").read_text().splitlines()
    cells = lines[201].split(",")  # sample 200, line 202 of the file
    cells[1] = cells[2] = "0"
    lines[201] = ",".join(cells)
    (tmp_path / "e.csv").write_text("\n".join(lines) + "\n")
    (tmp_path / "e.toml").write_text(
        EVENT.read_text().replace("itaipu_pmu_60sps.csv", "e.csv"))
    findings = ic.check(tmp_path / "e.toml", UNIT)
    assert key(findings) == [("error", "dropout", 202, "|V|")] + edge
    assert findings[0]["file"].endswith("e.csv") and findings[0]["fix"]
    (tmp_path / "u.toml").write_text(UNIT.read_text().replace("h = 4.5 ", "h = 1e308 "))
    w = ic.check(EVENT, tmp_path / "u.toml")
    assert [(f["severity"], f["kind"], f["column"]) for f in w] == [
        ("warning", "edge_dropout", "|V|"), ("warning", "parameter_range", "machine.h")]
    with pytest.raises(ic.EventError):
        ic.check(tmp_path / "missing.toml")
    with pytest.raises(TypeError):
        ic.check(EVENT, 3)


# --- user-defined diagrams ------------------------------------------------------------------


def test_a_unit_with_diagrams_matches_the_builtin_blocks(traces):
    """data/diagrams/unit_itaipu_diagrams.toml: the bundled unit with SEXS and STAB3 as diagrams."""
    d = ic.simulate(EVENT, DATA / "diagrams" / "unit_itaipu_diagrams.toml")
    assert np.max(np.abs(d.p_pu - traces.p_pu)) < 1e-6
    assert np.max(np.abs(d.q_pu - traces.q_pu)) < 1e-6


def test_a_bad_diagram_names_the_file_block_and_field(tmp_path):
    text = (DATA / "diagrams" / "sexs.toml").read_text().replace('type = "lead_lag"', 'type = "leadlag"')
    (tmp_path / "sexs.toml").write_text(text)
    unit = tmp_path / "unit.toml"
    unit.write_text(UNIT.read_text().replace('model = "SEXS"', 'model = "diagram"\ndiagram = "sexs.toml"'))
    with pytest.raises(ic.UnitModelError) as info:
        ic.simulate(EVENT, unit)
    msg = str(info.value)
    assert "sexs.toml" in msg and "block 'lead_lag'" in msg and "leadlag" in msg
