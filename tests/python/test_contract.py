"""One answer whatever the path (issue 25), from Python: the bundled Itaipu record reached from
files, from objects loaded in memory, from a COMTRADE import in memory and from the import's
written files, and through the command line (in process) gives the same fit J (1e-9 relative,
same seed), the same noise floor and warnings, and the same diagnosis verdict as the command
line's `diagnose --fit`. (The Rust side: tests/contract.rs; a one-job fleet: test_fleet.py.)"""

import json
import warnings
from pathlib import Path

import pytest

import itaipu_calib as ic

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "data"
EVENT = DATA / "itaipu" / "event.toml"
UNIT = DATA / "itaipu" / "unit.toml"
DYR = DATA / "itaipu" / "unit.dyr"
CALIB = DATA / "itaipu" / "calibration.toml"
CFG = DATA / "itaipu" / "pmu" / "itaipu.cfg"
# A quick staged fit: the contract holds for any budget.
QUICK = dict(stages="gen,avr,pss", seed=5, particles=10, pso_iterations=12, local_iterations=8, threads=2)
CLI_QUICK = ["--stage", "gen,avr,pss", "--seed", "5", "--particles", "10", "--pso-iterations", "12",
             "--local-iterations", "8", "--threads", "2", "--no-plot"]
DQUICK = dict(causes=["measurement_skew", "saturation"], particles=8, pso_iterations=6, local_iterations=5)
CLI_DQUICK = ["--cause", "measurement_skew,saturation", "--particles", "8", "--pso-iterations", "6",
              "--local-iterations", "5", "--no-plot"]


def _j(report):
    return report["stages"][-1]["fitness"][0]["j_pq"]


def _rel(a, b):
    return abs(a - b) / max(abs(b), 1e-300)


@pytest.fixture(scope="module")
def cli_fit(tmp_path_factory):
    out = tmp_path_factory.mktemp("contract") / "fit"
    assert ic._core._cli_main(["itaipu-calib", "fit", "--event", str(EVENT), "--out", str(out), *CLI_QUICK]) == 0
    return out


def test_files_objects_and_the_command_line_give_one_fit(cli_fit):
    cli = json.loads((cli_fit / "report.json").read_text())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ic.ItaipuWarning)  # the record's edge drop-out
        from_files = ic.fit(EVENT, UNIT, calib=CALIB, **QUICK)
        in_memory = ic.fit(ic.load_event(EVENT), ic.load_unit(UNIT), calib=CALIB, **QUICK)
    for what, r in (("from files", from_files), ("in memory", in_memory)):
        rep = r.report
        assert _rel(_j(rep), _j(cli)) < 1e-9, f"{what}: J {_j(rep)} against the command line's {_j(cli)}"
        assert rep["noise"] == cli["noise"], what
        assert [w["kind"] for w in rep["warnings"]] == [w["kind"] for w in cli["warnings"]], what
        # The report's text is the one the command line prints.
        assert "fit statistics:" in rep() and "determined" in rep()


def test_an_import_in_memory_and_from_its_files_give_one_fit(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ic.ItaipuWarning)
        ev = ic.import_pmu(CFG, 1000.0, 60.0, v_base_kv=18.0, out=tmp_path / "ev")
        report = ev.import_report
        written = ic.load_event(tmp_path / "ev" / "event.toml")
        a = ic.fit(ev, UNIT, calib=CALIB, **QUICK)
        b = ic.fit(written, UNIT, calib=CALIB, **QUICK)
    # The onset and init window come from the data, not from an import default.
    assert abs(report["onset_s"] - 61 / 60) < 1e-9
    assert ev.init == written.init == ic.load_event(EVENT).init
    assert _rel(_j(a.report), _j(b.report)) < 1e-9
    assert a.report["noise"] == b.report["noise"]


def test_a_dyr_unit_fits_and_diagnose_fit_is_the_command_lines(cli_fit, tmp_path):
    """The issue's Python session: a unit read from .dyr fits (the path, or read_dyr's Unit);
    diagnose(fit=r) diagnoses r's calibrated unit, as `diagnose --fit`, with the same verdict;
    passing the datasheet unit beside fit= is a usage error, as the command line's --fit with
    --unit."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ic.ItaipuWarning)
        by_path = ic.fit(EVENT, DYR, calib=CALIB, **QUICK)
        u = ic.read_dyr(DYR)
        r = ic.fit(EVENT, u, calib=CALIB, **QUICK)
        assert _rel(_j(r.report), _j(by_path.report)) < 1e-9
        with pytest.raises(ValueError, match="fit's own calibrated unit") as e:
            ic.diagnose(EVENT, u, fit=r, **DQUICK)
        assert e.value.kind == "unit"
        d = ic.diagnose(EVENT, fit=r, **DQUICK)
        d_cli = tmp_path / "diag"
        r.write(tmp_path / "fit")
        code = ic._core._cli_main(["itaipu-calib", "diagnose", "--event", str(EVENT), "--fit",
                                   str(tmp_path / "fit"), "--out", str(d_cli), *CLI_DQUICK])
    assert code == 0
    cli = json.loads((d_cli / "diagnosis.json").read_text())
    assert d.cause == cli["verdict"]["cause"]
    assert d.report["noise"]["sigma_p"] == cli["noise"]["sigma_p"]
    for c, k in zip(d.candidates, cli["candidates"]):
        assert c["cause"] == k["cause"]
        if c["gains"] is not None:
            assert _rel(c["gains"]["delta_bic"], k["gains"]["delta_bic"]) < 1e-9, c["cause"]
