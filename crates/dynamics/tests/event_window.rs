//! Event windows (defaults, trimming, tolerance, window errors) and the operating point
//! estimated from the init window.

#![allow(clippy::needless_range_loop)] // parallel per-sample arrays read best with an index

use crate::event_support;

use std::f64::consts::{PI, TAU};

use event_support::*;
use itaipu_dynamics::event::*;

// ---- operating point ----------------------------------------------------------------------

/// Noisy record at 60.012 Hz: returns the CSV text and the true values.
fn noisy_record(freq_col: Option<f64>) -> String {
    let n = 240; // 4 s at 60/s
    let mut lcg = Lcg::new(12345);
    let theta0 = 0.3;
    let df = 0.012;
    let mut s = String::from("time_s,v_re_pu,v_im_pu,p_pu,q_pu");
    if freq_col.is_some() {
        s += ",freq_hz";
    }
    s += "\n";
    for i in 0..n {
        let t = 2.0 + i as f64 / 60.0; // time axis that does not start at 0
        let mag = 1.01 + 0.003 * lcg.uniform();
        let ang = theta0 + TAU * df * (t - 2.0) + 0.003 * lcg.uniform();
        let p = 0.8 + 0.004 * lcg.uniform();
        let q = -0.05 + 0.004 * lcg.uniform();
        s += &format!(
            "{},{},{},{},{}",
            g(t),
            g(mag * ang.cos()),
            g(mag * ang.sin()),
            g(p),
            g(q)
        );
        if let Some(f) = freq_col {
            s += &format!(",{}", g(f + 0.01 * lcg.uniform()));
        }
        s += "\n";
    }
    s
}

#[test]
fn operating_point_recovers_frequency_offset_and_means_from_noisy_data() {
    let dir = TempDir::new("op");
    dir.write("n.csv", &noisy_record(None));
    let toml = dir.write(
        "n.toml",
        &toml_text("n.csv", "[init]\nstart_s = 2.0\nend_s = 3.0\n"),
    );
    let ev = Event::from_toml_file(&toml).unwrap();
    assert_eq!(ev.init_range().len(), 61);
    let op = ev.operating_point();
    assert_eq!(op.t0_s, 2.0);
    assert_eq!(op.n_samples, 61);
    // Angle noise of ±0.003 rad per sample gives up to ±0.06 Hz from a two-sample
    // difference; the line fit gets within 1e-3 Hz of the true 60.012 Hz.
    assert!((op.freq_hz - 60.012).abs() < 1e-3, "freq {}", op.freq_hz);
    assert!(
        (op.v_ang_rad - 0.3).abs() < 1.5e-3,
        "angle {}",
        op.v_ang_rad
    );
    // Means of 61 samples with uniform noise ±0.003 (|V|) and ±0.004 (P, Q): standard
    // errors 2.2e-4 and 3.0e-4; tolerances are 4 standard errors.
    assert!((op.v_mag_pu - 1.01).abs() < 9e-4, "v {}", op.v_mag_pu);
    assert!((op.p_pu - 0.8).abs() < 1.2e-3, "p {}", op.p_pu);
    assert!((op.q_pu + 0.05).abs() < 1.2e-3, "q {}", op.q_pu);

    // Init window starting later than the playback start: the fitted line is extrapolated
    // back to t0 (the first playback sample), accounting for the drift in between.
    let toml2 = dir.write(
        "n2.toml",
        &toml_text("n.csv", "[init]\nstart_s = 3.0\nend_s = 4.0\n"),
    );
    let op2 = Event::from_toml_file(&toml2).unwrap().operating_point();
    assert_eq!(op2.t0_s, 2.0);
    assert!((op2.freq_hz - 60.012).abs() < 1e-3, "freq {}", op2.freq_hz);
    assert!(
        (op2.v_ang_rad - 0.3).abs() < 3e-3,
        "angle {}",
        op2.v_ang_rad
    );

    // Trimmed playback: t0 moves to the first playback sample and the angle follows the drift.
    let toml3 = dir.write(
        "n3.toml",
        &toml_text("n.csv", "[playback]\nstart_s = 3.0\n"),
    );
    let ev3 = Event::from_toml_file(&toml3).unwrap();
    assert_eq!(ev3.record.time_s[0], 3.0);
    assert_eq!(ev3.init, Window::new(3.0, 3.5));
    let op3 = ev3.operating_point();
    assert_eq!(op3.t0_s, 3.0);
    let expect = 0.3 + TAU * 0.012 * 1.0;
    assert!(
        (op3.v_ang_rad - expect).abs() < 3e-3,
        "angle {}",
        op3.v_ang_rad
    );
}

#[test]
fn operating_point_uses_freq_column_mean_but_fitted_angle() {
    let dir = TempDir::new("opf");
    dir.write("f.csv", &noisy_record(Some(59.95)));
    let toml = dir.write("f.toml", &toml_text("f.csv", "[init]\nend_s = 3.0\n"));
    let ev = Event::from_toml_file(&toml).unwrap();
    let op = ev.operating_point();
    let r = ev.init_range();
    let f = ev.record.freq_hz.as_ref().unwrap();
    let mean = f[r.clone()].iter().sum::<f64>() / r.len() as f64;
    assert!((op.freq_hz - mean).abs() < 1e-12);
    assert!((op.freq_hz - 59.95).abs() < 3e-3);
    assert!(
        (op.v_ang_rad - 0.3).abs() < 1.5e-3,
        "angle {}",
        op.v_ang_rad
    );
}

#[test]
fn default_init_window_is_extended_to_ten_samples_for_slow_records() {
    // 10 samples/s: 0.5 s holds only 6 samples, so the default takes the first 10.
    let n = 50;
    let t: Vec<f64> = (0..n).map(|i| i as f64 / 10.0).collect();
    let dir = TempDir::new("slow");
    dir.write(
        "s.csv",
        &rect_csv(
            &t,
            &vec![1.0; n],
            &vec![0.0; n],
            &vec![0.5; n],
            &vec![0.0; n],
        ),
    );
    let ev = Event::from_toml_file(&dir.write("s.toml", &toml_text("s.csv", ""))).unwrap();
    assert_eq!(ev.init_range().len(), 10);
    assert!((ev.init.end_s - 0.9).abs() < 1e-12);
}

#[test]
fn playback_trimming_keeps_only_window_samples_and_normalises_angle() {
    let n = 600;
    let t: Vec<f64> = (0..n).map(|i| i as f64 / 60.0).collect();
    let ang: Vec<f64> = t.iter().map(|t| -TAU * 0.5 * t).collect(); // -0.5 Hz
    let dir = TempDir::new("trim");
    dir.write(
        "t.csv",
        &rect_csv(&t, &vec![1.0; n], &ang, &vec![0.5; n], &vec![0.0; n]),
    );
    let toml = dir.write(
        "t.toml",
        &toml_text("t.csv", "[playback]\nstart_s = 4.5\nend_s = 8.0\n"),
    );
    let ev = Event::from_toml_file(&toml).unwrap();
    assert_eq!(ev.record.time_s[0], 4.5);
    assert!((ev.record.end_s() - 8.0).abs() < 1e-12);
    assert_eq!(ev.record.len(), 211);
    // True angle at 4.5 s is -4.5π; the record starts in [-π, π] and stays continuous.
    let a0 = ev.record.v_ang_rad[0];
    assert!((-PI..=PI).contains(&a0), "{a0}");
    assert!((a0 - (-4.5 * PI + 4.0 * PI)).abs() < 1e-9);
    assert!(ev
        .record
        .v_ang_rad
        .windows(2)
        .all(|w| (w[1] - w[0] + TAU * 0.5 / 60.0).abs() < 1e-9));
}

#[test]
fn window_membership_uses_microsecond_tolerance() {
    let mut rec = mem_record(6);
    rec.time_s = vec![0.0, 0.1 + 3e-7, 0.2, 0.3 - 2e-7, 0.3 + 4e-6, 0.5];
    let w = Window::new(0.1 + 5e-7, 0.3 + 5e-7);
    // 0.1+3e-7 is 0.2 µs before the start and 0.3+4e-6 is 3.5 µs after the end.
    assert_eq!(rec.window_range(&w), 1..4);
    assert!(w.contains(0.1) && w.contains(0.3 + 1.4e-6));
    assert!(!w.contains(0.1 - 1e-6) && !w.contains(0.3 + 2e-6));
    assert_eq!(rec.window_range(&Window::new(0.6, 0.7)), 6..6);
    assert!((w.duration_s() - 0.2).abs() < 1e-15);
}

#[test]
fn error_window_upside_down() {
    let dir = TempDir::new("upside");
    dir.write("d.csv", &simple_csv(120));
    let toml = dir.write(
        "e.toml",
        &toml_text("d.csv", "[init]\nstart_s = 0.9\nend_s = 0.2\n"),
    );
    let e = Event::from_toml_file(&toml).unwrap_err();
    assert_err(
        &e,
        "bad_window",
        &[&ps(&toml), "init.end_s", "0.2", "0.9", "upside down"],
    );

    let toml = dir.write(
        "p.toml",
        &toml_text("d.csv", "[playback]\nstart_s = 1.0\nend_s = 1.0\n"),
    );
    let e = Event::from_toml_file(&toml).unwrap_err();
    assert_err(&e, "bad_window", &[&ps(&toml), "playback.end_s"]);

    // Default end before an explicit start: the message says which value was defaulted.
    let toml = dir.write(
        "f.toml",
        &toml_text("d.csv", "[playback]\nend_s = 1.5\n[fit]\nstart_s = 1.6\n"),
    );
    let e = Event::from_toml_file(&toml).unwrap_err();
    assert_err(&e, "bad_window", &[&ps(&toml), "fit.end_s", "(default)"]);
}

#[test]
fn error_window_outside_record() {
    let dir = TempDir::new("outside");
    dir.write("d.csv", &simple_csv(120)); // 0 … 1.983 s
    let toml = dir.write("e.toml", &toml_text("d.csv", "[playback]\nend_s = 10.0\n"));
    let e = Event::from_toml_file(&toml).unwrap_err();
    assert_err(
        &e,
        "bad_window",
        &[
            &ps(&toml),
            "playback.end_s",
            "10",
            "after the end of the record",
            "d.csv",
        ],
    );

    let toml = dir.write("s.toml", &toml_text("d.csv", "[fit]\nstart_s = -1.0\n"));
    let e = Event::from_toml_file(&toml).unwrap_err();
    assert_err(
        &e,
        "bad_window",
        &[
            &ps(&toml),
            "fit.start_s",
            "before the start of the playback window",
        ],
    );

    // init must lie inside the (trimmed) playback window.
    let toml = dir.write(
        "i.toml",
        &toml_text(
            "d.csv",
            "[playback]\nstart_s = 0.5\n[init]\nstart_s = 0.0\nend_s = 1.0\n",
        ),
    );
    let e = Event::from_toml_file(&toml).unwrap_err();
    assert_err(
        &e,
        "bad_window",
        &[&ps(&toml), "init.start_s", "playback window"],
    );

    // Non-finite bound.
    let toml = dir.write("n.toml", &toml_text("d.csv", "[fit]\nend_s = inf\n"));
    let e = Event::from_toml_file(&toml).unwrap_err();
    assert_err(
        &e,
        "bad_window",
        &[&ps(&toml), "fit.end_s", "not a finite number"],
    );

    // Sub-microsecond overshoot is tolerated.
    let last = 119.0 / 60.0;
    let toml = dir.write(
        "ok.toml",
        &toml_text("d.csv", &format!("[playback]\nend_s = {}\n", last + 5e-7)),
    );
    assert_eq!(Event::from_toml_file(&toml).unwrap().record.len(), 120);
}
