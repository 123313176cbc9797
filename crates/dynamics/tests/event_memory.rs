//! Events built in memory with `Event::from_record`: unwrapping, windows and errors that name
//! the in-memory source and the sample index.

#![allow(clippy::needless_range_loop)] // parallel per-sample arrays read best with an index

use crate::event_support;

use std::f64::consts::{PI, TAU};

use event_support::*;
use itaipu_dynamics::event::*;

// ---- in-memory events ---------------------------------------------------------------------

#[test]
fn from_record_unwraps_and_applies_windows() {
    let n = 300;
    let t: Vec<f64> = (0..n).map(|i| i as f64 / 60.0).collect();
    let truth: Vec<f64> = t.iter().map(|t| 3.0 + TAU * 0.4 * t).collect();
    let re: Vec<f64> = truth.iter().map(|a| a.cos()).collect();
    let im: Vec<f64> = truth.iter().map(|a| a.sin()).collect();
    let rec = Record::from_rectangular(t, &re, &im, vec![0.5; n], vec![0.1; n]);
    let ev = Event::from_record(
        "syn",
        rec,
        100.0,
        60.0,
        Some(Window::new(0.0, 1.0)),
        Some(Window::new(1.0, 4.0)),
    )
    .unwrap();
    assert_eq!(ev.toml_path, None);
    assert_eq!(ev.fit_range(), 60..241);
    for (a, b) in ev.record.v_ang_rad.iter().zip(&truth) {
        assert!((a - b).abs() < 1e-9);
    }
    let op = ev.operating_point();
    assert!((op.freq_hz - 60.4).abs() < 1e-9);
    assert!((op.v_ang_rad - 3.0).abs() < 1e-9);

    // A wrapped angle handed in directly is unwrapped too.
    let mut rec2 = mem_record(10);
    rec2.v_ang_rad = vec![3.0, -3.0, -2.9, 3.1, 3.0, 2.9, -3.1, 3.1, 3.0, 2.9];
    let ev2 = Event::from_record("w", rec2, 100.0, 60.0, None, None).unwrap();
    assert!(ev2
        .record
        .v_ang_rad
        .windows(2)
        .all(|w| (w[1] - w[0]).abs() < PI));
}

#[test]
fn from_record_errors_name_source_and_sample() {
    let mut r = mem_record(10);
    r.p_pu.pop();
    let e = Event::from_record("m", r, 100.0, 60.0, None, None).unwrap_err();
    assert_err(
        &e,
        "record_shape",
        &["<in-memory event 'm'>", "p_pu has 9 samples"],
    );

    let mut r = mem_record(10);
    r.q_pu[4] = f64::NAN;
    let e = Event::from_record("m", r, 100.0, 60.0, None, None).unwrap_err();
    assert_err(
        &e,
        "bad_number",
        &["<in-memory event 'm'>", "sample 4", "q_pu", "NaN"],
    );

    let mut r = mem_record(10);
    r.time_s[6] = r.time_s[5];
    let e = Event::from_record("m", r, 100.0, 60.0, None, None).unwrap_err();
    assert_err(
        &e,
        "non_monotonic_time",
        &["<in-memory event 'm'>", "sample 6", "sample 5"],
    );

    let mut r = mem_record(10);
    r.v_mag_pu = vec![400.0; 10];
    let e = Event::from_record("m", r, 100.0, 60.0, None, None).unwrap_err();
    assert_err(&e, "units", &["<in-memory event 'm'>", "v_mag_pu", "kV"]);

    let e = Event::from_record("m", mem_record(10), 0.0, 60.0, None, None).unwrap_err();
    assert_err(
        &e,
        "invalid_value",
        &["<in-memory event 'm'>", "system_mva"],
    );
    let e = Event::from_record("m", mem_record(10), 100.0, f64::NAN, None, None).unwrap_err();
    assert_err(&e, "invalid_value", &["nominal_hz"]);

    let e = Event::from_record(
        "m",
        mem_record(10),
        100.0,
        60.0,
        Some(Window::new(0.1, 0.05)),
        None,
    )
    .unwrap_err();
    assert_err(&e, "bad_window", &["<in-memory event 'm'>", "init.end_s"]);
    let e = Event::from_record(
        "m",
        mem_record(10),
        100.0,
        60.0,
        None,
        Some(Window::new(0.0, 1.0)),
    )
    .unwrap_err();
    assert_err(&e, "bad_window", &["fit.end_s", "after the end"]);
}
