//! Event TOML files: defaults, integer values, relative CSV paths, the full example, and the
//! TOML errors (unknown and missing keys, syntax, types).

#![allow(clippy::needless_range_loop)] // parallel per-sample arrays read best with an index

use crate::event_support;

use event_support::*;
use itaipu_dynamics::event::*;

// ---- TOML ---------------------------------------------------------------------------------

#[test]
fn toml_defaults_integers_and_relative_csv_path() {
    let dir = TempDir::new("defaults");
    dir.write("sub/data.csv", &simple_csv(120)); // 2 s at 60/s
    let toml = dir.write(
        "ev.toml",
        "name = \"x\"\ncsv = \"sub/data.csv\"\nsystem_mva = 100\nnominal_hz = 60\n",
    );
    let ev = Event::from_toml_file(&toml).unwrap();
    assert_eq!(ev.name, "x");
    assert_eq!(ev.description, "");
    assert_eq!(ev.system_mva, 100.0);
    assert_eq!(ev.nominal_hz, 60.0);
    assert_eq!(ev.toml_path.as_deref(), Some(toml.as_path()));
    assert_eq!(ev.csv_path, dir.0.join("sub/data.csv"));
    let last = 119.0 / 60.0;
    assert_eq!(ev.playback, Window::new(0.0, last));
    assert_eq!(ev.fit, ev.playback);
    assert_eq!(ev.init, Window::new(0.0, 0.5));
    assert_eq!(ev.init_range(), 0..31);
    assert_eq!(ev.record.len(), 120);
}

#[test]
fn full_example_toml_parses() {
    let dir = TempDir::new("example");
    let (t, mag, ang, p, q) = itaipu_like();
    dir.write("itaipu_pmu_60sps.csv", &rect_csv(&t, &mag, &ang, &p, &q));
    let text = r#"
name = "itaipu-60hz-fault"
description = "free text"
csv = "itaipu_pmu_60sps.csv"     # path relative to the TOML file's folder
system_mva = 1000.0               # base of p_pu, q_pu in the CSV
nominal_hz = 60.0
[playback]            # optional
start_s = 0.0
end_s = 4.25
[init]
start_s = 0.0
end_s = 0.95
[fit]
start_s = 1.0
end_s = 4.25
"#;
    let ev = Event::from_toml_file(&dir.write("ev.toml", text)).unwrap();
    assert_eq!(ev.name, "itaipu-60hz-fault");
    assert_eq!(ev.description, "free text");
    assert_eq!(ev.playback, Window::new(0.0, 4.25));
    assert_eq!(ev.fit, Window::new(1.0, 4.25));
    assert_eq!(ev.record.len(), 256);
}

// ---- TOML errors --------------------------------------------------------------------------

#[test]
fn error_unknown_toml_key() {
    let dir = TempDir::new("unkkey");
    dir.write("d.csv", &simple_csv(60));
    let toml = dir.write("e.toml", &toml_text("d.csv", "nominal_freq = 60.0\n"));
    let e = Event::from_toml_file(&toml).unwrap_err();
    assert_err(
        &e,
        "unknown_field",
        &[&ps(&toml), "line 6", "`nominal_freq`", "nominal_hz"],
    );

    let toml = dir.write(
        "w.toml",
        &toml_text("d.csv", "[init]\nstart_s = 0.0\nstop_s = 0.5\n"),
    );
    let e = Event::from_toml_file(&toml).unwrap_err();
    assert_err(
        &e,
        "unknown_field",
        &[&ps(&toml), "line 8", "`init.stop_s`", "start_s, end_s"],
    );

    // An unknown table is an unknown key too.
    let toml = dir.write("t.toml", &toml_text("d.csv", "[initial]\nstart_s = 0.0\n"));
    let e = Event::from_toml_file(&toml).unwrap_err();
    assert_err(&e, "unknown_field", &[&ps(&toml), "`initial`"]);
}

#[test]
fn error_missing_toml_key_syntax_and_types() {
    let dir = TempDir::new("tomlerr");
    dir.write("d.csv", &simple_csv(60));
    let toml = dir.write(
        "m.toml",
        "name = \"x\"\ncsv = \"d.csv\"\nnominal_hz = 60.0\n",
    );
    let e = Event::from_toml_file(&toml).unwrap_err();
    assert_err(&e, "missing_field", &[&ps(&toml), "`system_mva`"]);

    let toml = dir.write("s.toml", "name = \"x\"\ncsv = \"d.csv\nsystem_mva = 1\n");
    let e = Event::from_toml_file(&toml).unwrap_err();
    assert_err(&e, "toml_syntax", &[&ps(&toml), "line 2"]);

    let toml = dir.write(
        "ty.toml",
        "name = \"x\"\ncsv = \"d.csv\"\nsystem_mva = \"1000\"\nnominal_hz = 60.0\n",
    );
    let e = Event::from_toml_file(&toml).unwrap_err();
    assert_err(&e, "toml_value", &[&ps(&toml), "line 3", "system_mva"]);

    let toml = dir.write("z.toml", &toml_text("d.csv", "").replace("1000.0", "-5.0"));
    let e = Event::from_toml_file(&toml).unwrap_err();
    assert_err(&e, "invalid_value", &[&ps(&toml), "system_mva = -5"]);

    let toml = dir.write("nf.toml", &toml_text("d.csv", "").replace("60.0", "nan"));
    let e = Event::from_toml_file(&toml).unwrap_err();
    assert_err(&e, "invalid_value", &[&ps(&toml), "nominal_hz = NaN"]);
}

#[test]
fn input_lowpass_is_read_played_and_checked() {
    let dir = TempDir::new("input-lowpass");
    // 10 s at 60/s: |V| 1.0 with an alternating ±1e-3 (noise at the Nyquist frequency) and a
    // 0.1 pu step at 5 s.
    let n = 600;
    let t: Vec<f64> = (0..n).map(|i| i as f64 / 60.0).collect();
    let mag: Vec<f64> = (0..n)
        .map(|i| 1.0 - if i >= 300 { 0.1 } else { 0.0 } + if i % 2 == 0 { 1e-3 } else { -1e-3 })
        .collect();
    let ang: Vec<f64> = t.iter().map(|t| 0.1 + 0.05 * t).collect();
    dir.write(
        "d.csv",
        &rect_csv(&t, &mag, &ang, &vec![0.6; n], &vec![0.02; n]),
    );

    let plain = Event::from_toml_file(&dir.write(
        "plain.toml",
        &toml_text("d.csv", "input_lowpass_hz = \"None\"\n"),
    ))
    .unwrap();
    assert_eq!(plain.input_lowpass_hz, None);
    let (v, _) = plain.playback_voltage();
    assert_eq!(
        v, plain.record.v_mag_pu,
        "with \"none\" the record plays as recorded"
    );

    // Without the key a phasor record is smoothed at the default cut-off; with it, at its own.
    let default = Event::from_toml_file(&dir.write("d.toml", &toml_text("d.csv", ""))).unwrap();
    assert_eq!(default.input_lowpass_hz, Some(smoothing::DEFAULT_CUTOFF_HZ));
    let toml = dir.write("lp.toml", &toml_text("d.csv", "input_lowpass_hz = 4\n"));
    let ev = Event::from_toml_file(&toml).unwrap();
    assert_eq!(ev.input_lowpass_hz, Some(4.0));
    assert_eq!(default.playback_voltage(), ev.playback_voltage());
    let toml = dir.write("lp2.toml", &toml_text("d.csv", "input_lowpass_hz = 2.5\n"));
    let other = Event::from_toml_file(&toml).unwrap();
    assert_eq!(other.input_lowpass_hz, Some(2.5));
    // The reports say how the voltage was played back when it is not the default.
    assert!(default.declaration_notes().is_empty());
    let note = |e: &Event| e.declaration_notes().join("\n");
    assert!(note(&plain).contains("as recorded"), "{}", note(&plain));
    assert!(
        note(&other).contains("low-passed at 2.5 Hz"),
        "{}",
        note(&other)
    );
    let (v, a) = ev.playback_voltage();
    // The alternation (30 Hz) is gone away from the step and the ends; the step's samples are
    // as recorded.
    for k in (60..280).chain(320..540) {
        let level = if k >= 300 { 0.9 } else { 1.0 };
        assert!((v[k] - level).abs() < 1e-5, "sample {k}: {}", v[k]);
    }
    for k in 299..=300 {
        assert_eq!(v[k], ev.record.v_mag_pu[k], "step sample {k}");
    }
    // The angle's ramp (an off-nominal frequency) passes.
    for k in 0..n {
        assert!(
            (a[k] - ev.record.v_ang_rad[k]).abs() < 1e-7,
            "angle sample {k}"
        );
    }

    for (bad, needle) in [("40.0", "Nyquist"), ("-1.0", "invalid"), ("0.0", "invalid")] {
        let toml = dir.write(
            "bad.toml",
            &toml_text("d.csv", &format!("input_lowpass_hz = {bad}\n")),
        );
        let e = Event::from_toml_file(&toml).unwrap_err();
        assert_err(
            &e,
            "invalid_value",
            &[&ps(&toml), "input_lowpass_hz", needle],
        );
    }
    let toml = dir.write(
        "word.toml",
        &toml_text("d.csv", "input_lowpass_hz = \"off\"\n"),
    );
    let e = Event::from_toml_file(&toml).unwrap_err();
    assert_err(
        &e,
        "toml_value",
        &[&ps(&toml), "input_lowpass_hz = \"off\"", "\"none\""],
    );
}

/// The default cut-off is the same on every path, and only where the filter can run on a phasor
/// record: not on uneven stamps, not without an angle, not at or below the Nyquist frequency.
#[test]
fn the_default_input_lowpass_needs_a_uniform_phasor_record() {
    let n = 600;
    // `mem_record`'s samples (60/s) at the stamps `dt` gives.
    let rec = |dt: &dyn Fn(usize) -> f64| Record {
        time_s: (0..n).map(dt).collect(),
        ..mem_record(n)
    };
    let build = |r: Record, d: &Declaration| {
        Event::from_record_declared("e", r, 100.0, 60.0, None, None, d)
            .unwrap()
            .input_lowpass_hz
    };
    let phasor = Declaration::default();
    let uniform = |i: usize| i as f64 / 60.0;
    assert_eq!(
        build(rec(&uniform), &phasor),
        Some(smoothing::DEFAULT_CUTOFF_HZ)
    );
    // Stamps 1/60 s apart, then 1/30 s: not uniform within 1 %.
    let uneven = |i: usize| {
        if i < 300 {
            i as f64 / 60.0
        } else {
            5.0 + (i - 300) as f64 / 30.0
        }
    };
    assert_eq!(build(rec(&uneven), &phasor), None);
    // 8 samples/s: the Nyquist frequency is the default cut-off.
    assert_eq!(build(rec(&|i| i as f64 / 8.0), &phasor), None);
    let no_angle = Declaration {
        channels: Some(vec![Channel::V, Channel::P, Channel::Q]),
        ..Declaration::default()
    };
    assert_eq!(build(rec(&uniform), &no_angle), None);
}
