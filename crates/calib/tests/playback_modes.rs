//! Calibration in the playback modes that need no angle: a fit of the exciter alone recovers
//! perturbed ST5B gains from a noisy synthetic step test; specs naming modes and channels are
//! checked field by field; events that lack what a stage plays back or compares are refused
//! before anything runs, naming the event file, the channel and the spec's field.

use crate::common;

use std::path::{Path, PathBuf};

use common::{mostar, noisy_step_test, truth};

use itaipu_calib::fit::{fit, quick_options, FitError, Silent};
use itaipu_calib::job::{prepare_fit, FitInputs};
use itaipu_calib::request::FitRequest;
use itaipu_calib::spec::CalibSpec;
use itaipu_dynamics::event::Event;
use itaipu_dynamics::mode::PlaybackMode;

fn spec(text: &str) -> Result<CalibSpec, itaipu_calib::spec::SpecError> {
    CalibSpec::parse(text, Path::new("cal.toml"))
}

/// The ST5B's regulator (K_R, T_C1, T_B1) and bridge (T_1) perturbed by 30-100 % are recovered
/// from a noisy step test by a fit of the exciter alone (open loop on the recorded |V|, compared
/// on E_fd), within 3 %.
#[test]
fn an_exciter_alone_fit_recovers_perturbed_st5b_gains_from_a_noisy_step() {
    let truth = truth();
    let ev = noisy_step_test(&truth, 7);
    let names = ["exciter.k_r", "exciter.t_c1", "exciter.t_b1", "exciter.t_1"];
    let true_values: Vec<f64> = names
        .iter()
        .map(|n| truth.get(truth.param(n).unwrap()))
        .collect();
    let start = truth
        .with_params(&[
            ("exciter.k_r", true_values[0] * 1.4),
            ("exciter.t_c1", true_values[1] * 0.7),
            ("exciter.t_b1", true_values[2] * 1.3),
            ("exciter.t_1", true_values[3] * 2.0),
        ])
        .unwrap();
    let s = spec(
        r#"
[calibration]
prior = 0
[[calibration.stage]]
name = "avr"
mode = "exciter_alone"
free = [
  { param = "exciter.k_r", min = 50.0, max = 2000.0 },
  { param = "exciter.t_c1", min = 0.1, max = 10.0 },
  { param = "exciter.t_b1", min = 1.0, max = 50.0 },
  { param = "exciter.t_1", min = 1e-4, max = 0.05 },
]
"#,
    )
    .unwrap();
    let r = fit(&start, &s, &[ev], &[], &quick_options(&["avr"], 1), &Silent).unwrap();
    let st = &r.report.stages[0];
    assert_eq!(st.compare.as_deref(), Some("exciter_alone: efd 1"));
    for (p, truth) in st.parameters.iter().zip(&true_values) {
        let rel = (p.result - truth).abs() / truth;
        eprintln!(
            "{}: start {:.5}, fit {:.5} ± {:.2e}, truth {truth:.5} ({:.2} %)",
            p.param,
            p.start,
            p.result,
            p.std_error,
            100.0 * rel
        );
        assert!(rel < 0.03, "{} = {} vs truth {truth}", p.param, p.result);
    }
    // The fitness row reports the mode, its E_fd misfit at about the noise: 2 401 samples of
    // σ = 0.01.
    let m = &st.fitness[0].modes[0];
    assert_eq!(m.mode, PlaybackMode::ExciterAlone);
    let sse = m.j.unwrap();
    assert!(sse < 2401.0 * 1e-4 * 1.5, "E_fd misfit {sse}");
}

#[test]
fn spec_modes_and_channels_are_checked_field_by_field() {
    let base =
        |stage: &str| format!("[calibration]\n[[calibration.stage]]\nname = \"avr\"\n{stage}");
    let cases: [(&str, &[&str]); 9] = [
        (
            "mode = \"exciter_alone\"\nchannels = { q = 1.0 }",
            &[
                "calibration.stage[0].channels (stage avr).q",
                "does not simulate q",
                "efd",
            ],
        ),
        (
            "mode = \"machine_from_efd\"\nchannels = { p = 1.0 }",
            &["channels (stage avr).p", "does not simulate p"],
        ),
        (
            "mode = \"closed_loop\"\nchannels = { volts = 1.0 }",
            &["unknown channel 'volts'"],
        ),
        (
            "mode = \"closed_loop\"\nchannels = { v = 0.0, q = 0.0 }",
            &["channels (stage avr)", "sum nothing"],
        ),
        (
            "mode = \"closed_loop\"\nchannels = { v = -1.0 }",
            &["channels (stage avr).v", "weight -1"],
        ),
        (
            "mode = \"exciter_alone\"\nobjective = \"q\"",
            &["calibration.stage[0].objective", "channels = {"],
        ),
        ("mode = \"open_loop\"", &["open_loop"]),
        (
            "mode = \"exciter_alone\"\nchannels = \"recorded\"",
            &[
                "calibration.stage[0].channels (stage avr)",
                "\"recorded\" goes with the phasor playback",
            ],
        ),
        ("channels = \"all\"", &["\"all\"", "or \"recorded\""]),
    ];
    for (stage, needles) in cases {
        let e = spec(&base(stage)).unwrap_err().to_string();
        assert!(e.contains("cal.toml"), "{e}");
        for n in needles {
            assert!(e.contains(n), "{n:?} not in: {e}");
        }
    }
    let e = spec("[calibration]\n[calibration.joint]\nmode = \"closed_loop\"\nchannels = { efd = 1.0, p = 1.0 }\nfree = [ { param = \"grid.x_e\", min = 0.5, max = 0.1 } ]\n")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("calibration.joint.free[0] (grid.x_e)") && e.contains("upside down"),
        "{e}"
    );
    // A phasor stage's "recorded" reads as P and Q until the events resolve it.
    let s = spec("[calibration]\n[[calibration.stage]]\nname = \"gen\"\nchannels = \"recorded\"\n")
        .unwrap();
    assert!(s.compares_recorded() && s.stages[0].compare().is_none());
    // A good one: the stage compares what it names, the joint its own channels.
    let s = spec("[calibration]\n[[calibration.stage]]\nname = \"gen\"\nmode = \"machine_from_efd\"\n[calibration.joint]\nmode = \"closed_loop\"\nchannels = { v = 400.0, q = 6.0, efd = 2.0 }\n").unwrap();
    assert_eq!(
        s.stages[0].compare().unwrap().describe(),
        "machine_from_efd: q 1"
    );
    assert_eq!(
        s.joint_compare().unwrap().describe(),
        "closed_loop: v 400, q 6, efd 2"
    );
}

fn inputs(spec_text: &str) -> FitInputs {
    FitInputs {
        unit: truth(),
        unit_path: Some(mostar("unit.toml")),
        spec: spec(spec_text).unwrap(),
        spec_path: Some(PathBuf::from("cal.toml")),
        spec_text: Some(spec_text.into()),
        events: vec![Event::from_toml_file(&mostar("event.toml")).unwrap()],
        held_out: vec![],
    }
}

/// A record without an angle in a phasor stage, and a compared channel the record lacks, stop
/// the fit before it runs (`prepare_fit`, what every front end calls first), naming the event
/// file, what is missing and the stage's field; the class is bad event data (exit 3).
#[test]
fn events_lacking_what_a_stage_needs_are_refused_before_the_fit() {
    let event_file = mostar("event.toml").display().to_string();
    let free = "free = [ { param = \"machine.x_d\", min = 0.6, max = 2.0 } ]";
    let cases: [(String, &[&str]); 3] = [
        (
            format!("[calibration]\n[[calibration.stage]]\nname = \"gen\"\n{free}\n"),
            &[
                "no voltage angle",
                "calibration.stage[0] (stage gen, phasor playback)",
            ],
        ),
        (
            format!(
                "[calibration]\n[[calibration.stage]]\nname = \"gen\"\nmode = \"machine_from_efd\"\nchannels = {{ q = 1.0, ifd = 1.0 }}\n{free}\n"
            ),
            &[
                "no ifd channel (column ifd_pu)",
                "calibration.stage[0] (stage gen, mode machine_from_efd, channels)",
            ],
        ),
        (
            format!(
                "[calibration]\n[[calibration.stage]]\nname = \"gen\"\nmode = \"machine_from_efd\"\n{free}\n[[calibration.stage]]\nname = \"avr\"\nmode = \"exciter_alone\"\nfree = [ {{ param = \"exciter.k_r\", min = 1.0, max = 1000.0 }} ]\n[calibration.joint]\nmode = \"phasor\"\nchannels = {{ p = 1.0, q = 1.0 }}\n"
            ),
            &["no voltage angle", "calibration.joint (mode phasor, channels)"],
        ),
    ];
    for (text, needles) in cases {
        let e = prepare_fit(&inputs(&text), &FitRequest::default()).expect_err("refused");
        assert_eq!(e.class(), itaipu_calib::error::ErrorClass::EventData, "{e}");
        assert!(
            matches!(e, itaipu_calib::Error::Fit(FitError::Event(_))),
            "{e}"
        );
        let msg = e.to_string();
        assert!(
            msg.contains(&event_file) && msg.contains("of cal.toml"),
            "{msg}"
        );
        for n in needles {
            assert!(msg.contains(n), "{n:?} not in: {msg}");
        }
    }
}
