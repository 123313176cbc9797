"""A new user's first hour in Python (issue 62): an imported recording is an Event `fit` takes,
argument errors name the argument, every warning goes through `warnings`, the signed-off HTML
report can be written, `models(name)` is the command line's `models NAME`, a missing file is
said to be missing, the headline is the library's, and the docstrings name the method the code
runs."""

import warnings
from pathlib import Path

import pytest

import itaipu_calib as ic

ROOT = Path(__file__).resolve().parents[2]
ITAIPU = ROOT / "data" / "itaipu"
CFG = ITAIPU / "pmu" / "itaipu.cfg"
QUICK = dict(stages="gen", particles=6, pso_iterations=4, local_iterations=3, threads=2)


def test_an_imported_recording_is_an_event_fit_takes():
    with pytest.warns(ic.ItaipuWarning, match="drop-out"):
        ev = ic.import_pmu(CFG, 1000.0, 60.0, v_base_kv=18.0)
    assert isinstance(ev, ic.Event) and len(ev) == 280
    assert ev.import_report["samples_declared"] == 280
    assert any("drop-out" in w for w in ev.import_report["warnings"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ic.ItaipuWarning)
        r = ic.fit(ev, ITAIPU / "unit.dyr", calib=ITAIPU / "calibration.toml", **QUICK)
    assert r.stages == ["gen"]


def test_a_truncated_recording_is_warned_of_and_can_be_refused(tmp_path):
    (tmp_path / "itaipu.cfg").write_bytes(CFG.read_bytes())
    dat = (ITAIPU / "pmu" / "itaipu.dat").read_bytes()
    (tmp_path / "itaipu.dat").write_bytes(dat[: 125 * (len(dat) // 280)])
    with pytest.raises(ic.EventError, match="declares 280"):
        ic.import_pmu(tmp_path / "itaipu.cfg", 1000.0, 60.0, v_base_kv=18.0, refuse_truncated=True)
    with pytest.warns(ic.ItaipuWarning, match="truncated"):
        ev = ic.import_pmu(tmp_path / "itaipu.cfg", 1000.0, 60.0, v_base_kv=18.0)
    assert len(ev.import_notes) == 1 and "truncated" in ev.import_notes[0]
    # Said again by the commands that use the event.
    with pytest.warns(ic.ItaipuWarning, match="truncated"):
        ic.simulate(ev, ITAIPU / "unit.toml")


def test_argument_errors_name_the_argument():
    for arg, value, err in [
        ("particles", -1, ValueError),
        ("seed", -3, ValueError),
        ("pso_iterations", 2**70, ValueError),
        ("local_iterations", 1.5, TypeError),
    ]:
        with pytest.raises(err, match=arg):
            ic.fit(ITAIPU / "event.toml", ITAIPU / "unit.toml", **{arg: value})
    with pytest.raises(ValueError, match="particles"):
        ic.diagnose(ITAIPU / "event.toml", ITAIPU / "unit.toml", particles=-1)


def test_every_fit_warning_goes_through_warnings_and_the_report_is_the_library_s(tmp_path):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r = ic.fit(ITAIPU / "event.toml", ITAIPU / "unit.toml", calib=ITAIPU / "calibration.toml", **QUICK)
    issued = [str(w.message) for w in caught if issubclass(w.category, ic.ItaipuWarning)]
    assert sorted(issued) == sorted(r.warnings) and len(issued) > 1, (issued, r.warnings)
    # The headline: the library's sentence, in the report and its text.
    h = r.report["headline"]
    assert r.headline == h["sentence"] and f"at most {h['worst']:.2f} × the noise σ" in r.headline
    assert r.headline in r.fit_report()
    # The signed-off page, written beside the files the command line writes.
    out = r.write(tmp_path / "fit", html=True)
    page = (out / "report.html").read_text()
    assert page.startswith("<!DOCTYPE html>") and "Verdict" in page and 'data-json="/headline/worst"' in page
    listed = (out / "manifest.json").read_text()
    assert '"report.html"' in listed


def test_models_takes_a_name_as_the_command_line_does():
    g = ic.models("gensae")
    assert isinstance(g, dict) and g["name"] == "GENSAE"
    assert isinstance(ic.models("diagram"), str)
    with pytest.raises(ValueError, match="unknown model 'NOPE'.*GENSAE"):
        ic.models("NOPE")
    assert len(ic.models()) > 5


def test_a_missing_dyr_is_said_to_be_missing():
    with pytest.raises(ic.UnitModelError) as e:
        ic.read_dyr("nope.dyr")
    assert e.value.kind == "io" and "nope.dyr: cannot read" in str(e.value)
    assert "mbase" not in str(e.value)


def test_the_docstrings_name_the_method_the_code_runs():
    for doc in (ic.__doc__, ic.fit.__doc__):
        flat = " ".join(doc.split())
        assert "then L-BFGS" not in flat and "Levenberg-Marquardt" in flat
