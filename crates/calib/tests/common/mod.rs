//! What several test files share: the bundled Mostar unit and a synthetic step test of it.

#![allow(dead_code)]

use std::path::{Path, PathBuf};

use itaipu_dynamics::event::{Channel, Declaration, Event, Record, SetpointStep, StepReference};
use itaipu_dynamics::mode::{simulate_mode, PlaybackMode};
use itaipu_dynamics::rng::Normal;
use itaipu_dynamics::simulate::{PreparedEvent, SimOptions};
use itaipu_dynamics::unit::Unit;
use itaipu_dynamics::unit_file::read_unit;

pub fn mostar(file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../data/mostar")
        .join(file)
}

/// The truth: the bundled Mostar unit (RaPId's ST5B behind X = 0.1169 pu).
pub fn truth() -> Unit {
    read_unit(&mostar("unit.toml")).unwrap()
}

/// A +5 % / −5 % V_ref step test of `unit` in closed loop, 12 s at 200 samples/s, recorded as
/// an exciter's recorder would: |V|, P, Q, E_fd without an angle, with white noise (σ: |V| 1e-4
/// pu, P and Q 1e-3 pu, E_fd 0.01 pu; seed fixed).
pub fn noisy_step_test(unit: &Unit, seed: u64) -> Event {
    let n = 2401;
    let steps = vec![
        SetpointStep {
            time_s: 1.0,
            size_pu: 0.05,
            reference: StepReference::VRef,
        },
        SetpointStep {
            time_s: 7.0,
            size_pu: -0.05,
            reference: StepReference::VRef,
        },
    ];
    let flat = Record {
        time_s: (0..n).map(|i| i as f64 * 0.005).collect(),
        v_mag_pu: vec![0.97043; n],
        v_ang_rad: vec![0.0; n],
        p_pu: vec![0.17153; n],
        q_pu: vec![0.07401; n],
        freq_hz: None,
        efd_pu: None,
        ifd_pu: None,
    };
    let decl = |ch: Vec<Channel>| Declaration {
        channels: Some(ch),
        steps: steps.clone(),
        ..Default::default()
    };
    let setup = Event::from_record_declared(
        "setup",
        flat.clone(),
        30.0,
        50.0,
        None,
        None,
        &decl(vec![Channel::V, Channel::P, Channel::Q]),
    )
    .unwrap();
    let o = simulate_mode(
        unit,
        &PreparedEvent::new(&setup),
        PlaybackMode::ClosedLoop,
        &SimOptions::default(),
    )
    .unwrap();
    let mut rng = Normal::new(seed);
    let mut noisy =
        |y: &[f64], s: f64| -> Vec<f64> { y.iter().map(|v| v + s * rng.sample()).collect() };
    let rec = Record {
        v_mag_pu: noisy(&o.v, 1e-4),
        p_pu: noisy(&o.p, 1e-3),
        q_pu: noisy(&o.q, 1e-3),
        efd_pu: Some(noisy(&o.efd, 0.01)),
        ..flat
    };
    Event::from_record_declared(
        "synthetic-step",
        rec,
        30.0,
        50.0,
        Some(setup.init),
        None,
        &decl(vec![Channel::V, Channel::P, Channel::Q, Channel::Efd]),
    )
    .unwrap()
}
