"""itaipu_calib.synth: synthetic events from the engine, deterministic, usable by simulate."""

from pathlib import Path

import numpy as np
import pytest

import itaipu_calib as ic

DATA = Path(__file__).resolve().parents[2] / "data"
TRUTH = DATA / "synthetic" / "unit_gensae_sexs_stab3_hygov.toml"


@pytest.mark.parametrize("kind", ["dip", "frequency", "step", "ambient"])
def test_synth_plays_back_to_the_noise_level(kind):
    ev = ic.synth(TRUTH, kind=kind, duration=6.0, rate=30.0, v_sigma=0.0, seed=3)
    assert len(ev.time_s) == 181
    assert ev.name == f"synthetic-{kind}-3"
    tr = ic.simulate(ev, TRUTH)
    rp = np.sqrt(np.mean((tr.p_pu - tr.p_meas_pu) ** 2))
    assert 0.0015 < rp < 0.0026, rp


def test_synth_is_deterministic_and_seeded():
    a = ic.synth(TRUTH, duration=4.0, seed=5)
    b = ic.synth(TRUTH, duration=4.0, seed=5)
    c = ic.synth(TRUTH, duration=4.0, seed=6)
    assert np.array_equal(a.p_pu, b.p_pu) and np.array_equal(a.q_pu, b.q_pu)
    assert not np.array_equal(a.p_pu, c.p_pu)


def test_synth_bad_options():
    with pytest.raises(ValueError, match="kind"):
        ic.synth(TRUTH, kind="earthquake")
    with pytest.raises(ValueError, match="rate"):
        ic.synth(TRUTH, rate=0.0)
    with pytest.raises(ValueError, match="skew_ms"):
        ic.synth(TRUTH, skew_ms=-1.0)
    with pytest.raises(ic.UnitModelError):
        ic.synth(DATA / "no-such-unit.toml")
