"""read_dyr / write_dyr / import_pmu: the same library calls as `itaipu-calib dyr` and
`itaipu-calib import`."""

import warnings
from pathlib import Path

import pytest

import itaipu_calib as ic

ROOT = Path(__file__).resolve().parents[2]
ITAIPU = ROOT / "data" / "itaipu"


def test_the_itaipu_dyr_reads_to_the_unit_file_parameters_and_round_trips(tmp_path):
    u = ic.read_dyr(ITAIPU / "unit.dyr")  # bases from unit.bases.toml beside it
    ref = ic.load_unit(ITAIPU / "unit.toml").parameters()
    got = u.parameters()
    assert {k: v for k, v in ref.items() if not k.startswith("governor.")} == dict(got)
    r = ic.write_dyr(u, tmp_path / "u.dyr", bus=7, id="G1", events=ITAIPU / "event.toml")
    assert r["faithful"] and r["lost"] == []
    [e] = r["events"]
    assert e["max_dp"] <= 1e-6 and e["max_dq"] <= 1e-6 and e["j_written"] == e["j_unit"]
    again = ic.read_dyr(tmp_path / "u.dyr", bus=7, id="G1")
    assert dict(again.parameters()) == dict(got)
    # Never over an existing file without force.
    with pytest.raises(ic.UnitModelError) as x:
        ic.write_dyr(u, tmp_path / "u.dyr", bus=7, id="G1")
    assert x.value.kind == "exists"


def test_a_dyr_that_is_not_the_unit_is_refused_unless_lossy(tmp_path):
    # X''q != X''d: PSS/E's GENSAE holds one X''; the written model plays back differently.
    u = ic.load_unit(ITAIPU / "unit.toml").with_params({"machine.x_q_pp": 0.26})
    ev = ITAIPU / "event.toml"
    with pytest.raises(ic.UnitModelError) as x:
        ic.write_dyr(u, tmp_path / "u.dyr", events=ev)
    assert x.value.kind == "lossy" and "machine.x_q_pp" in str(x.value)
    assert "J = " in str(x.value) and not (tmp_path / "u.dyr").exists()
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        r = ic.write_dyr(u, tmp_path / "u.dyr", events=ev, lossy=True)
    assert not r["faithful"] and r["events"][0]["j_written"] != r["events"][0]["j_unit"]
    assert any("not the unit" in str(m.message) for m in w)
    assert (tmp_path / "u.dyr").is_file() and (tmp_path / "u.bases.toml").is_file()


def test_unsupported_records_are_refused_unless_skipped_and_bad_ones_raise(tmp_path):
    f = tmp_path / "x.dyr"
    f.write_text((ITAIPU / "unit.dyr").read_text() + "1 'ESAC1A' 1 1 2 3 /\n")
    with pytest.raises(ic.UnitModelError) as e:
        ic.read_dyr(f, bases=ITAIPU / "unit.bases.toml")
    assert e.value.kind == "unsupported" and "line 5: model ESAC1A" in str(e.value)
    with pytest.warns(ic.ItaipuWarning) as w:
        u = ic.read_dyr(f, bases=ITAIPU / "unit.bases.toml", skip_unsupported=True)
    assert any("line 5" in str(x.message) and "ESAC1A" in str(x.message) for x in w)
    assert u is not None
    f.write_text("1 'GENCLS' 1 4.5\n")
    with pytest.raises(ic.UnitModelError) as e:
        ic.read_dyr(f, mbase=100.0, nominal_hz=60.0, zx=0.3)
    assert e.value.kind == "syntax" and "x.dyr line 1" in str(e.value)
    with pytest.raises(ic.UnitModelError) as e:
        ic.read_dyr(ITAIPU / "unit.dyr", bases=tmp_path / "none.toml")
    assert e.value.kind == "io"


def test_a_comtrade_recording_imports_to_the_bundled_event(tmp_path):
    with pytest.warns(ic.ItaipuWarning, match="drop-out"):
        ev = ic.import_pmu(ITAIPU / "pmu" / "itaipu.cfg", 1000.0, 60.0, v_base_kv=18.0, out=tmp_path / "ev")
    rep = ev.import_report
    ref = ic.load_event(ITAIPU / "event.toml")
    assert len(ev) == len(ref) == 280
    assert rep["format"] == "COMTRADE 2013 BINARY32" and rep["gaps"] == [] and rep["dropouts"] == []
    # 32-bit codes with a multiplier of ~6e-9 kV (kA, MW): the export is lossless to far below
    # any PMU's resolution, |V| and P within 1e-7 pu of the original.
    assert abs(ev.v_mag_pu - ref.v_mag_pu).max() < 1e-7
    assert abs(ev.p_pu - ref.p_pu).max() < 1e-7
    assert (tmp_path / "ev" / "event.toml").is_file()
    with pytest.raises(ValueError, match="v_base_kv"):
        ic.import_pmu(ITAIPU / "pmu" / "itaipu.cfg", 1000.0, 60.0)
    bad = tmp_path / "bad.csv"
    bad.write_text("timestamp,v_mag_kv,v_ang_deg,i_mag_a,i_ang_deg\n2015-01-01T00:00:00Z,x,0,1,0\n")
    with pytest.raises(ic.EventError) as e:
        ic.import_pmu(bad, 1000.0, 60.0, v_base_kv=18.0)
    assert "line 2, column v_mag_kv" in str(e.value) and e.value.kind == "data"
