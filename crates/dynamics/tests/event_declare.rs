//! What an event declares (`channels`, `time_base`, `[[step]]`): the bundled Mostar record reads
//! as declared, and every bad declaration or bad record is an error naming the file and the key
//! (or the column and line).

use crate::event_support;

use std::path::{Path, PathBuf};

use event_support::{assert_err, ps, TempDir};
use itaipu_dynamics::event::{
    Channel, Declaration, Event, Record, SetpointStep, StepReference, TimeBase,
};
use itaipu_dynamics::simulate::{simulate, SimError, SimOptions};
use itaipu_dynamics::unit_file::read_unit;

fn mostar(file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../data/mostar")
        .join(file)
}

/// A magnitude-only CSV (time, |V|, P, Q, E_fd) at 100 samples/s, 2 s, a step-like rise of E_fd
/// at 1 s.
fn v_only_csv() -> String {
    let mut s = String::from("time_s,v_pu,p_pu,q_pu,efd_pu\n");
    for i in 0..=200 {
        let t = i as f64 * 0.01;
        let efd = if t < 1.0 { 1.2 } else { 1.9 };
        s += &format!("{t},0.97,0.17,0.07,{efd}\n");
    }
    s
}

/// An event file with `extra` keys over `csv`.
fn event_toml(csv: &str, extra: &str) -> String {
    format!("name = \"decl\"\ncsv = \"{csv}\"\nsystem_mva = 30.0\nnominal_hz = 50.0\n{extra}")
}

const V_ONLY: &str = "channels = [\"v\", \"p\", \"q\", \"efd\"]\n";

fn read(dir: &TempDir, csv: &str, extra: &str) -> Result<Event, itaipu_dynamics::EventError> {
    dir.write("data.csv", csv);
    let p = dir.write("event.toml", &event_toml("data.csv", extra));
    Event::from_toml_file(&p)
}

#[test]
fn the_mostar_event_reads_as_declared() {
    let ev = Event::from_toml_file(&mostar("event.toml")).unwrap();
    assert_eq!(
        ev.channels,
        [Channel::V, Channel::P, Channel::Q, Channel::Efd]
    );
    assert!(!ev.has_angle());
    assert_eq!(ev.time_base, TimeBase::NonUniform);
    assert_eq!(ev.record.len(), 3752);
    assert!(ev.record.v_ang_rad.iter().all(|a| *a == 0.0));
    assert_eq!(
        ev.steps,
        [
            SetpointStep {
                time_s: 1.73,
                size_pu: 0.05,
                reference: StepReference::VRef
            },
            SetpointStep {
                time_s: 10.245,
                size_pu: -0.05,
                reference: StepReference::VRef
            }
        ]
    );
    // The operating point is the pre-step one.
    assert!(ev.init.end_s < 1.73, "init {}", ev.init);
    let notes = ev.declaration_notes().join("\n");
    for n in [
        "no voltage angle",
        "non-uniform, intervals 4.00-5.10 ms; kept as recorded",
        "step[0]: v_ref +0.05 pu at 1.73 s",
        "step[1]: v_ref -0.05 pu at 10.245 s",
    ] {
        assert!(notes.contains(n), "{n:?} not in {notes}");
    }
    // RaPId's pre-step operating point (Mostar.mo: |V| 0.9705, Q 0.07332 pu) and E_fd0.
    let op = ev.operating_point();
    assert!((op.v_mag_pu - 0.9704).abs() < 5e-4, "{op:?}");
    assert!((op.q_pu - 0.0740).abs() < 1e-3, "{op:?}");
    assert!((ev.init_mean(Channel::Efd).unwrap() - 1.202).abs() < 2e-3);
}

#[test]
fn a_record_without_an_angle_has_no_phasor_playback() {
    let ev = Event::from_toml_file(&mostar("event.toml")).unwrap();
    let unit = read_unit(&mostar("unit.toml")).unwrap();
    let e = simulate(&unit, &ev, &SimOptions::default()).unwrap_err();
    assert!(matches!(e, SimError::NoAngle { .. }), "{e}");
    assert_eq!(e.kind(), "no_angle");
    let msg = e.to_string();
    assert!(
        msg.contains("mostar-avr-step") && msg.contains("closed_loop"),
        "{msg}"
    );
}

#[test]
fn a_magnitude_only_csv_needs_the_declaration() {
    let dir = TempDir::new("decl-needs");
    // Without channels, a CSV with v_pu alone misses its angle, and the message says how to
    // declare a record without one.
    let e = read(&dir, &v_only_csv(), "").unwrap_err();
    assert_err(&e, "missing_column", &["'angle_deg'", "channels = ["]);
    let ev = read(&dir, &v_only_csv(), V_ONLY).unwrap();
    assert!(!ev.has_angle() && ev.has(Channel::Efd));
}

#[test]
fn declared_channels_must_match_the_csv() {
    let dir = TempDir::new("decl-channels");
    let toml = ps(&dir.0.join("event.toml"));
    let cases: [(&str, &str, &[&str]); 6] = [
        (
            "channels = [\"v\", \"p\", \"q\", \"efd\", \"ifd\"]\n",
            "declaration",
            &["channels", "\"ifd\" is declared", "ifd_pu"],
        ),
        (
            "channels = [\"v\", \"p\", \"q\"]\n",
            "declaration",
            &["channels", "holds \"efd\"", "efd_pu"],
        ),
        (
            "channels = [\"v\", \"p\", \"efd\"]\n",
            "declaration",
            &["channels", "must list \"q\""],
        ),
        (
            "channels = [\"v\", \"p\", \"q\", \"field\"]\n",
            "declaration",
            &["channels", "unknown channel \"field\""],
        ),
        (
            "channels = [\"v\", \"angle\", \"p\", \"q\", \"efd\"]\n",
            "missing_column",
            &["'angle_deg'"],
        ),
        (
            "channels = [\"v\", \"p\", \"q\", \"efd\"]\ntime_base = \"jittery\"\n",
            "declaration",
            &["time_base", "\"jittery\""],
        ),
    ];
    for (extra, kind, needles) in cases {
        let e = read(&dir, &v_only_csv(), extra).unwrap_err();
        let mut n = needles.to_vec();
        if kind == "declaration" {
            n.push(&toml);
        }
        assert_err(&e, kind, &n);
    }
}

#[test]
fn steps_are_checked_against_the_record() {
    let dir = TempDir::new("decl-steps");
    let toml = ps(&dir.0.join("event.toml"));
    let step = |t: &str, size: &str, reference: &str| {
        format!("[[step]]\ntime_s = {t}\nsize_pu = {size}\n{reference}\n")
    };
    let r = "reference = \"v_ref\"";
    let cases: Vec<(String, &str, Vec<&str>)> = vec![
        // Outside the record (it runs 0-2 s): before its first sample, at it, after its last.
        (
            step("-0.5", "0.05", r),
            "declaration",
            vec!["step[0].time_s", "outside"],
        ),
        (
            step("0", "0.05", r),
            "declaration",
            vec!["step[0].time_s", "outside"],
        ),
        (
            step("2.5", "0.05", r),
            "declaration",
            vec!["step[0].time_s", "outside"],
        ),
        (
            step("1.5", "0.05", r) + &step("1.2", "-0.05", r),
            "declaration",
            vec!["step[1].time_s", "increasing"],
        ),
        (step("1.0", "0", r), "declaration", vec!["step[0].size_pu"]),
        (
            step("1.0", "0.05", ""),
            "declaration",
            vec!["step[0].reference", "v_ref"],
        ),
        (
            step("1.0", "0.05", "reference = \"n_ref\""),
            "declaration",
            vec!["step[0].reference", "\"n_ref\""],
        ),
        (
            step("1.0", "0.05", "reference = \"v_ref\"\nsize_mw = 3"),
            "unknown_field",
            vec!["step[0].size_mw", "line"],
        ),
        // An init window given in the file must end before the first step.
        (
            step("1.0", "0.05", r) + "[init]\nend_s = 1.2\n",
            "bad_window",
            vec!["init.end_s", "step[0].time_s"],
        ),
    ];
    for (extra, kind, mut needles) in cases {
        let e = read(&dir, &v_only_csv(), &format!("{V_ONLY}{extra}")).unwrap_err();
        needles.push(&toml);
        assert_err(&e, kind, &needles);
    }
    // A good step: the default init window ends before it.
    let ev = read(
        &dir,
        &v_only_csv(),
        &format!("{V_ONLY}{}", step("1.0", "0.05", r)),
    )
    .unwrap();
    assert!(ev.init.end_s < 1.0 - 0.02, "{}", ev.init);
    assert_eq!(ev.steps.len(), 1);
}

#[test]
fn bad_records_without_an_angle_name_the_file_line_and_column() {
    let dir = TempDir::new("decl-records");
    let csv_path = ps(&dir.0.join("data.csv"));
    // A duplicated time stamp, then one that goes back.
    for (bad, line) in [("0.01", "line 4"), ("0.005", "line 4")] {
        let text = v_only_csv().replacen("0.02,", &format!("{bad},"), 1);
        let e = read(&dir, &text, V_ONLY).unwrap_err();
        assert_err(&e, "non_monotonic_time", &[&csv_path, line, "time_s"]);
    }
    // E_fd in volts (a 150 V field for 1.2 pu) is refused, naming the column.
    let text = v_only_csv()
        .replace(",1.2\n", ",150\n")
        .replace(",1.9\n", ",240\n");
    let e = read(&dir, &text, V_ONLY).unwrap_err();
    assert_err(&e, "units", &[&csv_path, "efd_pu", "volts"]);
}

#[test]
fn an_event_without_an_angle_round_trips_through_its_csv() {
    let dir = TempDir::new("decl-roundtrip");
    let ev = read(&dir, &v_only_csv(), V_ONLY).unwrap();
    let out = dir.0.join("out.csv");
    ev.write_csv(&out).unwrap();
    let text = std::fs::read_to_string(&out).unwrap();
    assert_eq!(text.lines().next().unwrap(), "time_s,v_pu,p_pu,q_pu,efd_pu");
    let back = read(&dir, &text, V_ONLY).unwrap();
    assert_eq!(back.record, ev.record);
}

#[test]
fn in_memory_events_take_the_same_declaration() {
    let n = 201;
    let t: Vec<f64> = (0..n).map(|i| i as f64 * 0.01).collect();
    let rec = Record {
        v_mag_pu: vec![0.97; n],
        v_ang_rad: vec![0.3; n],
        p_pu: vec![0.17; n],
        q_pu: vec![0.07; n],
        freq_hz: None,
        efd_pu: Some(vec![1.2; n]),
        ifd_pu: None,
        time_s: t,
    };
    let decl = Declaration {
        channels: Some(vec![Channel::V, Channel::P, Channel::Q, Channel::Efd]),
        time_base: TimeBase::Uniform,
        steps: vec![SetpointStep {
            time_s: 1.0,
            size_pu: 0.05,
            reference: StepReference::VRef,
        }],
    };
    let ev =
        Event::from_record_declared("mem", rec.clone(), 30.0, 50.0, None, None, &decl).unwrap();
    assert!(!ev.has_angle());
    assert!(
        ev.record.v_ang_rad.iter().all(|a| *a == 0.0),
        "the angle is not kept"
    );
    let bad = Declaration {
        steps: vec![SetpointStep {
            time_s: 3.0,
            ..decl.steps[0]
        }],
        ..decl.clone()
    };
    let e = Event::from_record_declared("mem", rec, 30.0, 50.0, None, None, &bad).unwrap_err();
    assert_err(
        &e,
        "declaration",
        &["<in-memory event 'mem'>", "step[0].time_s"],
    );
}
