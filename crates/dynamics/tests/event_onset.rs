//! The event's onset: the detector on synthetic records with realistic PMU noise (fixed seeds)
//! and ambient background, the same value on every path (TOML + CSV, in memory, COMTRADE
//! import), the `onset_s` key, the default init window that ends before the onset, and the
//! bundled records (the two practice cases, scored against their answer keys, and Itaipu).

use crate::event_support;

use std::path::{Path, PathBuf};

use event_support::*;
use itaipu_dynamics::event::*;
use itaipu_dynamics::rng::Normal;

const RATE: f64 = 60.0;
const DT: f64 = 1.0 / RATE;
const N: usize = 1200; // 20 s

/// What happens at `T0` in a synthetic record.
#[derive(Clone, Copy, PartialEq)]
enum Kind {
    /// Ambient background only.
    Ambient,
    /// A fault: |V| down 0.3 pu for 0.1 s (edges of 2 samples), P down, Q up, then a swing.
    Fault,
    /// A voltage step: |V| down 2 % (edge of 2 samples), Q up.
    Step,
    /// Generation lost elsewhere: the frequency falls by 0.15 Hz (time constant 1 s), P picks
    /// up 0.04 pu (time constant 0.5 s); |V| does not move.
    Frequency,
}

/// Onset time of the synthetic events: between two samples (sample 180 is at 3 s).
const T0: f64 = 3.0 + 0.4 * DT;

/// A 20 s record at 60 samples/s: |V| 1.0, P 0.6, Q 0.1 at 60.01 Hz, with ambient background
/// (|V| wander 0.03 %, an inter-area angle swing 0.2° at 0.4 Hz, frequency wander 3 mHz) and
/// PMU noise (re and im of V 0.0005 pu, P and Q 0.002 pu), from `seed`; the event at `T0`.
fn synthetic(kind: Kind, seed: u64) -> Record {
    let mut rng = Normal::new(seed);
    let tau = std::f64::consts::TAU;
    let mut t = vec![];
    let (mut re, mut im, mut p, mut q) = (vec![], vec![], vec![], vec![]);
    let mut theta = 0.3;
    for i in 0..N {
        let ti = i as f64 * DT;
        let s = ti - T0; // time since the event
                         // A ramp over two samples from the event's start.
        let edge = |s: f64| (s / (2.0 * DT)).clamp(0.0, 1.0);
        let mut f = 60.01 + 0.003 * (tau * 0.05 * ti).sin();
        let mut v = 1.0 + 0.0003 * (tau * 0.13 * ti + 1.0).sin();
        let mut pi = 0.6 + 0.003 * (tau * 0.4 * ti).sin();
        let mut qi = 0.1;
        match kind {
            Kind::Ambient => {}
            Kind::Fault => {
                let dip = edge(s) - edge(s - 0.1);
                v -= 0.3 * dip;
                qi += 0.4 * dip;
                pi -= 0.2 * dip;
                if s > 0.1 {
                    pi += 0.1 * (-0.5 * s).exp() * (tau * 1.0 * s).sin();
                }
            }
            Kind::Step => {
                v -= 0.02 * edge(s);
                qi += 0.06 * edge(s);
            }
            Kind::Frequency => {
                if s > 0.0 {
                    f -= 0.15 * (1.0 - (-s).exp());
                    pi += 0.04 * (1.0 - (-s / 0.5).exp());
                }
            }
        }
        if i > 0 {
            theta += tau * (f - 60.0) * DT;
        }
        let ang = theta + (0.2f64).to_radians() * (tau * 0.4 * ti).sin();
        t.push(ti);
        re.push(v * ang.cos() + 0.0005 * rng.sample());
        im.push(v * ang.sin() + 0.0005 * rng.sample());
        p.push(pi + 0.002 * rng.sample());
        q.push(qi + 0.002 * rng.sample());
    }
    Record::from_rectangular(t, &re, &im, p, q)
}

fn event(kind: Kind, seed: u64) -> Event {
    Event::from_record("synthetic", synthetic(kind, seed), 1000.0, 60.0, None, None).unwrap()
}

/// The detected onset's error in samples against the first sample after `T0`.
fn err_samples(ev: &Event) -> Option<f64> {
    let first = (T0 / DT).ceil() * DT;
    ev.onset_s().map(|t| (t - first) / DT)
}

#[test]
fn ambient_records_have_no_onset() {
    for seed in [1, 2, 3, 4, 5] {
        let ev = event(Kind::Ambient, seed);
        let d = &ev.onset.detection;
        assert_eq!(ev.onset_s(), None, "seed {seed}: {}", d.describe());
        assert_eq!(ev.onset.source, OnsetSource::Detected);
        // The threshold is the Gaussian union bound at 1 % over every statistic.
        assert!(d.tests > 10_000 && d.threshold_sd > 4.5 && d.threshold_sd < 5.5);
        assert!(d.largest.unwrap().size_sd.abs() < d.threshold_sd);
        assert!(d.describe().starts_with("no onset"), "{}", d.describe());
        // No onset: the init window keeps the older default, 0.5 s from the start.
        assert_eq!(ev.init, Window::new(0.0, 0.5));
    }
}

#[test]
fn faults_and_steps_are_found_within_two_samples_and_the_init_window_ends_before() {
    for kind in [Kind::Fault, Kind::Step] {
        for seed in [11, 12, 13] {
            let ev = event(kind, seed);
            let err = err_samples(&ev)
                .unwrap_or_else(|| panic!("missed: {}", ev.onset.detection.describe()));
            assert!(
                err.abs() <= 2.0,
                "error {err} samples: {}",
                ev.onset.describe()
            );
            let d = &ev.onset.detection;
            assert_eq!(
                d.located_on.unwrap().channel,
                OnsetChannel::VoltageMagnitude,
                "{}",
                d.describe()
            );
            // The default init window: from the start to ONSET_GUARD_SAMPLES before the onset.
            let k = d.index.unwrap();
            assert_eq!(ev.record.time_s[k], ev.onset_s().unwrap());
            assert_eq!(
                ev.init,
                Window::new(0.0, ev.record.time_s[k - ONSET_GUARD_SAMPLES])
            );
            assert!(ev.init.end_s < T0);
        }
    }
}

#[test]
fn a_frequency_event_is_found_within_a_few_samples_from_the_angle_or_p() {
    for seed in [21, 22, 23] {
        let ev = event(Kind::Frequency, seed);
        let err =
            err_samples(&ev).unwrap_or_else(|| panic!("missed: {}", ev.onset.detection.describe()));
        assert!(
            (-2.0..=6.0).contains(&err),
            "error {err} samples: {}",
            ev.onset.describe()
        );
        let ch = ev.onset.detection.located_on.unwrap().channel;
        assert!(
            matches!(ch, OnsetChannel::Angle | OnsetChannel::ActivePower),
            "{ch:?}"
        );
    }
}

#[test]
fn a_single_bad_sample_is_not_an_onset() {
    // A one-sample spike of P (1 pu) and a one-sample |V| glitch on ambient data: the windows'
    // medians ignore one sample, so neither is a sustained departure.
    let mut rec = synthetic(Kind::Ambient, 31);
    rec.p_pu[600] += 1.0;
    rec.v_mag_pu[900] -= 0.2;
    let ev = Event::from_record("spike", rec, 1000.0, 60.0, None, None).unwrap();
    assert_eq!(ev.onset_s(), None, "{}", ev.onset.detection.describe());
}

#[test]
fn noiseless_records_without_a_change_have_no_onset() {
    // Constant channels and a linearly drifting angle: no statistic moves (rounding aside).
    let n = 600;
    let t: Vec<f64> = (0..n).map(|i| i as f64 / 60.0).collect();
    let ang: Vec<f64> = t
        .iter()
        .map(|t| 0.1 - std::f64::consts::TAU * 0.3 * t)
        .collect();
    let rec = Record {
        v_mag_pu: vec![1.0; n],
        v_ang_rad: ang,
        p_pu: vec![0.5; n],
        q_pu: vec![0.1; n],
        freq_hz: None,
        efd_pu: None,
        ifd_pu: None,
        time_s: t,
    };
    let ev = Event::from_record("flat", rec, 100.0, 60.0, None, None).unwrap();
    assert_eq!(ev.onset_s(), None, "{}", ev.onset.detection.describe());
    assert_eq!(ev.init, Window::new(0.0, 0.5));
    // Too short for the shortest windows: no onset, no panic.
    let short = Event::from_record("short", mem_record(5), 100.0, 60.0, None, None).unwrap();
    assert_eq!(short.onset_s(), None);
}

#[test]
fn every_path_gets_the_same_onset() {
    let rec = synthetic(Kind::Fault, 41);
    let mem = Event::from_record("f", rec.clone(), 1000.0, 60.0, None, None).unwrap();
    // The same samples written as the canonical CSV and read through an event TOML.
    let dir = TempDir::new("paths");
    let csv = dir.0.join("f.csv");
    mem.write_csv(&csv).unwrap();
    let toml = dir.write("f.toml", &toml_text("f.csv", ""));
    let file = Event::from_toml_file(&toml).unwrap();
    assert_eq!(file.onset_s(), mem.onset_s());
    assert!(file.onset_s().is_some());
    assert_eq!(file.init, mem.init);
    // An explicit init window does not move the onset (it is the data's).
    let with_init =
        Event::from_record("f", rec, 1000.0, 60.0, Some(Window::new(0.0, 1.0)), None).unwrap();
    assert_eq!(with_init.onset_s(), mem.onset_s());
    assert_eq!(with_init.init, Window::new(0.0, 1.0));
}

#[test]
fn onset_s_in_the_event_file_wins_and_is_checked() {
    let dir = TempDir::new("onset_key");
    let mem = event(Kind::Step, 51);
    mem.write_csv(&dir.0.join("s.csv")).unwrap();
    let detected = mem.onset_s().unwrap();

    // A given time wins; the default init window follows it.
    let ev =
        Event::from_toml_file(&dir.write("a.toml", &toml_text("s.csv", "onset_s = 2\n"))).unwrap();
    assert_eq!(ev.onset_s(), Some(2.0));
    assert_eq!(ev.onset.source, OnsetSource::Given);
    assert_eq!(ev.onset.detection.onset_s, Some(detected));
    assert!(
        (ev.init.end_s - (2.0 - 3.0 * DT)).abs() < 1e-9,
        "{}",
        ev.init
    );
    assert!(ev.onset.describe().contains("given in the event file"));
    // An explicit [init] still wins over the onset's default.
    let ev = Event::from_toml_file(&dir.write(
        "b.toml",
        &toml_text("s.csv", "onset_s = 2.0\n[init]\nend_s = 2.5\n"),
    ))
    .unwrap();
    assert_eq!(ev.init, Window::new(0.0, 2.5));
    // "none": ambient data whatever the detector says; the older init default.
    let ev =
        Event::from_toml_file(&dir.write("c.toml", &toml_text("s.csv", "onset_s = \"none\"\n")))
            .unwrap();
    assert_eq!(ev.onset_s(), None);
    assert_eq!(ev.init, Window::new(0.0, 0.5));
    // Outside the playback window: an error naming the file and the key.
    let p = dir.write(
        "d.toml",
        &toml_text("s.csv", "onset_s = 3.5\n[playback]\nend_s = 3.0\n"),
    );
    let e = Event::from_toml_file(&p).unwrap_err();
    assert_err(
        &e,
        "invalid_value",
        &[&ps(&p), "onset_s", "3.5", "playback window [0, 3] s"],
    );
    let p = dir.write("e.toml", &toml_text("s.csv", "onset_s = -1\n"));
    assert_err(
        &Event::from_toml_file(&p).unwrap_err(),
        "invalid_value",
        &[&ps(&p), "onset_s", "-1"],
    );
    // A word other than "none".
    let p = dir.write("f.toml", &toml_text("s.csv", "onset_s = \"soon\"\n"));
    assert_err(
        &Event::from_toml_file(&p).unwrap_err(),
        "toml_value",
        &[&ps(&p), "onset_s", "soon", "\"none\""],
    );
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The key's `event.t_event` of a bundled practice case (read only to score).
fn key_t_event(case: &str) -> f64 {
    let path = repo().join(format!("data/practice/answers/{case}.json"));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    v["event"]["t_event"].as_f64().unwrap()
}

#[test]
fn bundled_practice_cases_and_itaipu() {
    // The practice protocol's path: the CSV read into memory, init [0, 1] s given.
    for case in ["p01", "p02"] {
        let csv = repo().join(format!("data/practice/cases/{case}/data.csv"));
        let rec = read_csv(&csv, 60.0).unwrap();
        let dt = rec.time_s[1] - rec.time_s[0];
        let ev =
            Event::from_record(case, rec, 1000.0, 60.0, Some(Window::new(0.0, 1.0)), None).unwrap();
        let err = (ev.onset_s().unwrap() - key_t_event(case)) / dt;
        assert!(
            err.abs() <= 2.0,
            "{case}: {err} samples: {}",
            ev.onset.describe()
        );
    }
    // Itaipu: the fault's first sample is 1.0167 s (|V| and the angle move there, P and Q one
    // sample later); the bundled event file gives no init window: it is the pre-event part the
    // onset implies, from the start to 3 samples before it, as for the import below.
    let ev = Event::from_toml_file(&repo().join("data/itaipu/event.toml")).unwrap();
    let t = ev.onset_s().unwrap();
    assert!((t - 61.0 / 60.0).abs() < 1e-6, "{}", ev.onset.describe());
    assert_eq!(ev.init, Window::new(0.0, 58.0 / 60.0));
    // The COMTRADE recording of the same record, imported: the same onset.
    let opts = itaipu_dynamics::pmu_import::ImportOptions {
        v_base_kv: Some(18.0),
        ..itaipu_dynamics::pmu_import::ImportOptions::new(1000.0, 60.0)
    };
    let (imp, _) =
        itaipu_dynamics::pmu_import::import(&repo().join("data/itaipu/pmu/itaipu.cfg"), &opts)
            .unwrap();
    assert!(
        (imp.onset_s().unwrap() - t).abs() < 1e-6,
        "{}",
        imp.onset.describe()
    );
    assert_eq!(imp.init, Window::new(0.0, 58.0 / 60.0));
    // And its C37.118-style CSV export.
    let (c37, _) =
        itaipu_dynamics::pmu_import::import(&repo().join("data/itaipu/pmu/itaipu_c37.csv"), &opts)
            .unwrap();
    assert!(
        (c37.onset_s().unwrap() - t).abs() < 1e-6,
        "{}",
        c37.onset.describe()
    );
    // (Its time stamps are in µs.)
    assert!(
        (c37.init.end_s - imp.init.end_s).abs() < 1e-6,
        "{}",
        c37.init
    );
}

#[test]
fn import_writes_the_detected_onset_and_init_window_and_they_read_back() {
    let opts = itaipu_dynamics::pmu_import::ImportOptions {
        v_base_kv: Some(18.0),
        ..itaipu_dynamics::pmu_import::ImportOptions::new(1000.0, 60.0)
    };
    let (imp, rep) =
        itaipu_dynamics::pmu_import::import(&repo().join("data/itaipu/pmu/itaipu.cfg"), &opts)
            .unwrap();
    assert_eq!(rep.onset_s, imp.onset_s());
    assert_eq!(rep.init_s, [imp.init.start_s, imp.init.end_s]);
    let shown = rep.to_string();
    assert!(
        shown.contains("onset: 1.0167 s, init window [0, 0.9667] s"),
        "{shown}"
    );
    let dir = TempDir::new("import_onset");
    let out = dir.0.join("ev");
    itaipu_dynamics::pmu_import::write_event_folder(&imp, &rep, &out).unwrap();
    let text = std::fs::read_to_string(out.join("event.toml")).unwrap();
    assert!(text.contains("# Detected by itaipu-calib import"), "{text}");
    assert!(text.contains("To override: set"), "{text}");
    assert!(!text.contains("end_s = 0.5\n"), "{text}");
    let back = Event::from_toml_file(&out.join("event.toml")).unwrap();
    assert_eq!(back.onset_s(), imp.onset_s());
    assert_eq!(back.onset.source, OnsetSource::Given);
    assert_eq!(back.init, imp.init);
    assert_eq!(back.onset.detection.onset_s, imp.onset_s());

    // An ambient record: onset_s = "none" and the default init window, read back the same.
    let amb = event(Kind::Ambient, 1);
    let out = dir.0.join("amb");
    itaipu_dynamics::pmu_import::write_event_folder(&amb, &rep, &out).unwrap();
    let text = std::fs::read_to_string(out.join("event.toml")).unwrap();
    assert!(text.contains("onset_s = \"none\"\n"), "{text}");
    let back = Event::from_toml_file(&out.join("event.toml")).unwrap();
    assert_eq!(back.onset_s(), None);
    assert_eq!(back.init, Window::new(0.0, 0.5));
}
