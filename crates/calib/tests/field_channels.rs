//! The record's own channels, whatever the calibration compared (issue 63, item 3).
//!
//! The calibration: a joint pass without channels of its own compares what its stages compared
//! (a spec with `channels = "recorded"` in every stage fits E_fd in the joint pass too), and a
//! pass that makes a channel an earlier pass compared far worse says so. The diagnosis: when the
//! record holds the field, its reference re-fits the calibrated set on every compared channel
//! with a global search, so that a unit calibrated on P and Q alone, whose field is far off, is
//! judged against a reference fitted to the record's own channels, and gets the same verdict as
//! the unit calibrated on the field too.
//!
//! The record: a 20 s fault dip at 60 samples/s into the bundled synthetic hydro unit (GENSAE,
//! SEXS, STAB3, HYGOV), PMU noise on P, Q and the phasor, E_fd and X_ad I_fd recorded with white
//! noise of 0.01 and 0.005 pu; clean (no cause hidden). The nominal unit starts with X_d 30 %
//! high (E_fd, not P and Q, pins it: the phasor playback starts from the measured operating
//! point), H, X'_d, K and T_E off as in the diagnosis trials.

use itaipu_calib::diagnose::trial::{base_unit, dip_event_with_field};
use itaipu_calib::diagnose::{calibrated_set, diagnose, DiagnoseOptions};
use itaipu_calib::fit::{fit, quick_options, FitOptions, Silent};
use itaipu_calib::spec::CalibSpec;
use itaipu_dynamics::event::{Channel, Event};
use itaipu_dynamics::mode::PlaybackMode;
use itaipu_dynamics::unit::Unit;

/// The clean record with its field (fixed seeds).
fn record() -> Event {
    dip_event_with_field(&base_unit(), 20.0, 3, 4)
}

/// The nominal unit: the truth with X_d 30 % high, H 30 % high, X'_d 25 % low, K 30 % low and
/// T_E 50 % high.
fn nominal() -> Unit {
    let mut u = base_unit();
    for (p, f) in [
        ("machine.x_d", 1.3),
        ("machine.h", 1.3),
        ("machine.x_d_prime", 0.75),
        ("exciter.k", 0.7),
        ("exciter.te", 1.5),
    ] {
        let r = u.param(p).unwrap();
        let v = u.get(r);
        u.set(r, v * f);
    }
    u
}

/// Two stages (generator, then AVR) that compare `compare` (a spec line, or nothing: P and Q),
/// then `extra` (a joint table, say).
fn spec(compare: &str, extra: &str) -> CalibSpec {
    let text = format!(
        r#"[calibration]
[[calibration.stage]]
name = "gen"
{compare}
free = [
  {{ param = "machine.x_d", min = 0.6, max = 1.6 }},
  {{ param = "machine.h", min = 2.0, max = 9.0 }},
  {{ param = "machine.x_d_prime", min = 0.15, max = 0.6 }},
]
[[calibration.stage]]
name = "avr"
{compare}
free = [
  {{ param = "exciter.k", min = 30.0, max = 300.0 }},
  {{ param = "exciter.te", min = 0.02, max = 0.2 }},
]
{extra}"#
    );
    CalibSpec::parse(&text, std::path::Path::new("field-spec.toml")).unwrap()
}

/// A quick fit of both stages, with the joint pass.
fn options() -> FitOptions {
    FitOptions {
        polish: true,
        ..quick_options(&["gen", "avr"], 5)
    }
}

/// The E_fd sum of squares of a pass's fitness rows in the phasor playback (fitted events).
fn efd_sse(rows: &[itaipu_calib::fit::EventFitness]) -> f64 {
    rows.iter()
        .filter(|r| !r.held_out)
        .flat_map(|r| &r.modes)
        .filter(|m| m.mode == PlaybackMode::Phasor)
        .flat_map(|m| &m.channels)
        .filter(|c| c.channel == Channel::Efd)
        .map(|c| c.sse)
        .sum()
}

/// `channels = "recorded"` in every stage and no `[calibration.joint]`: the joint pass compares
/// P, Q and the recorded field at the stages' weights, keeps the field the stages fitted, and
/// no pass is reported as making a channel far worse. (Before, the joint pass compared P and Q
/// alone.)
#[test]
fn a_joint_pass_without_a_table_compares_what_its_stages_compared() {
    let ev = record();
    let s = spec("channels = \"recorded\"", "");
    let stages = ["gen".to_string(), "avr".to_string()];
    let resolved = s.resolve_recorded(&[&ev], &[]);
    let joint = resolved
        .joint_compare_of(&stages)
        .expect("the joint pass compares the field");
    let weight = |c: Channel| joint.weights.iter().find(|(x, _)| *x == c).map(|(_, w)| *w);
    assert_eq!(joint.mode, PlaybackMode::Phasor);
    assert_eq!(
        (weight(Channel::P), weight(Channel::Q)),
        (Some(1.0), Some(1.0))
    );
    assert!(weight(Channel::Efd).is_some() && weight(Channel::Ifd).is_some());

    let r = fit(
        &nominal(),
        &s,
        std::slice::from_ref(&ev),
        &[],
        &options(),
        &Silent,
    )
    .unwrap();
    let labels: Vec<&str> = r.report.stages.iter().map(|s| s.stage.as_str()).collect();
    assert_eq!(labels, ["gen", "avr", "joint"]);
    let joint = &r.report.stages[2];
    let compared = joint.compare.as_deref().unwrap_or("");
    assert!(
        compared.starts_with("phasor:") && compared.contains("efd") && compared.contains("ifd"),
        "the joint pass compares {compared:?}"
    );
    let (avr, after) = (
        efd_sse(&r.report.stages[1].fitness),
        efd_sse(&joint.fitness),
    );
    println!("E_fd sum of squares after the AVR stage {avr:.4}, after the joint pass {after:.4}");
    assert!(
        after <= 1.5 * avr,
        "the joint pass keeps the field fit: {avr} -> {after}"
    );
    assert!(r.report.stages.iter().all(|s| s.worsened.is_empty()));
}

/// Stages weighing a channel differently: the joint pass takes the largest weight (a channel's
/// trust is its noise, the same in every pass); a stage without channels counts as P and Q at 1;
/// a joint table with channels decides; stages on P and Q alone keep the historical joint pass.
#[test]
fn the_joint_pass_takes_each_channels_largest_stage_weight() {
    let stages = ["gen".to_string(), "avr".to_string()];
    let two = |gen: &str, avr: &str, extra: &str| {
        let text = format!(
            "[calibration]\n[[calibration.stage]]\nname = \"gen\"\n{gen}\nfree = [ {{ param = \"machine.h\", min = 2.0, max = 9.0 }} ]\n[[calibration.stage]]\nname = \"avr\"\n{avr}\nfree = [ {{ param = \"exciter.k\", min = 30.0, max = 300.0 }} ]\n{extra}"
        );
        CalibSpec::parse(&text, std::path::Path::new("w.toml")).unwrap()
    };
    let s = two(
        "channels = { p = 1.0, q = 1.0, efd = 0.04 }",
        "channels = { p = 1.0, q = 2.0, efd = 1.0 }",
        "",
    );
    assert_eq!(
        s.joint_compare_of(&stages).unwrap().describe(),
        "phasor: p 1, q 2, efd 1"
    );
    // Only the generator stage runs: its weights.
    assert_eq!(
        s.joint_compare_of(&stages[..1]).unwrap().describe(),
        "phasor: p 1, q 1, efd 0.04"
    );
    // A stage without channels: P and Q at 1; an exciter-alone stage's E_fd joins.
    let s = two("", "mode = \"exciter_alone\"\nchannels = { efd = 0.5 }", "");
    assert_eq!(
        s.joint_compare_of(&stages).unwrap().describe(),
        "phasor: p 1, q 1, efd 0.5"
    );
    // The joint table's channels decide.
    let s = two(
        "channels = { p = 1.0, q = 1.0, efd = 0.04 }",
        "",
        "[calibration.joint]\nchannels = { p = 1.0, q = 1.0 }\n",
    );
    assert_eq!(
        s.joint_compare_of(&stages).unwrap().describe(),
        "phasor: p 1, q 1"
    );
    // A joint table freeing a parameter but naming no channels: the stages' union.
    let s = two(
        "channels = { p = 1.0, q = 1.0, efd = 0.04 }",
        "",
        "[calibration.joint]\nfree = [ { param = \"machine.d\", min = 0.0, max = 2.0 } ]\n",
    );
    assert_eq!(
        s.joint_compare_of(&stages).unwrap().describe(),
        "phasor: p 1, q 1, efd 0.04"
    );
    // P and Q alone in every stage: the historical joint pass (no comparison of its own).
    assert!(two("", "objective = \"pq\"", "")
        .joint_compare_of(&stages)
        .is_none());
}

/// A pass that makes a channel an earlier pass compared far worse is said: the generator stage
/// fits X_d on P, Q and the field; the AVR stage, on P and Q alone, sets X_d 40 % high, which
/// P and Q barely see and the field does (its E_fd sum of squares many times what the generator
/// stage left). The warning names the pass, the channel, the pass that compared it and both
/// numbers, in the stage's report and its text.
#[test]
fn a_pass_that_makes_a_compared_channel_far_worse_warns() {
    let ev = record();
    let text = r#"[calibration]
[[calibration.stage]]
name = "gen"
channels = "recorded"
free = [
  { param = "machine.x_d", min = 0.6, max = 1.6 },
  { param = "machine.h", min = 2.0, max = 9.0 },
]
[[calibration.stage]]
name = "avr"
set = { "machine.x_d" = 1.33 }
free = [ { param = "exciter.k", min = 30.0, max = 300.0 } ]
"#;
    let s = CalibSpec::parse(text, std::path::Path::new("worse.toml")).unwrap();
    let opts = quick_options(&["gen", "avr"], 5);
    let r = fit(
        &nominal(),
        &s,
        std::slice::from_ref(&ev),
        &[],
        &opts,
        &Silent,
    )
    .unwrap();
    let (gen, avr) = (&r.report.stages[0], &r.report.stages[1]);
    assert!(gen.worsened.is_empty());
    let w = avr
        .worsened
        .iter()
        .find(|w| w.channel == Channel::Efd)
        .unwrap_or_else(|| panic!("E_fd made far worse is said: {:?}", avr.worsened));
    assert_eq!((w.pass.as_str(), w.compared_by.as_str()), ("avr", "gen"));
    assert_eq!(w.mode, PlaybackMode::Phasor);
    assert_eq!(w.sse_before, efd_sse(&gen.fitness));
    assert_eq!(w.sse_after, efd_sse(&avr.fitness));
    assert!(w.sse_after > 2.0 * w.sse_before);
    // P and Q, which the AVR stage re-fitted, are not made far worse.
    assert!(avr
        .worsened
        .iter()
        .all(|w| w.channel != Channel::P && w.channel != Channel::Q));
    let text = r.report.to_text();
    assert!(
        text.contains("warning: pass avr made efd (phasor playback), which pass gen compared"),
        "{text}"
    );
}

/// The diagnosis of a clean record with the field after a calibration on P and Q alone (its
/// E_fd far off: X_d stays near its wrong datasheet value, which P and Q do not pin) and after
/// one on the field too: the reference re-fits the calibrated set on every channel with a
/// global search, brings the field to the noise, says so, and both verdicts are `none`. (Before,
/// every baseline re-freed the set by local steps from the P+Q valley.)
#[test]
fn the_reference_refits_the_calibrated_set_on_the_records_own_channels() {
    let ev = record();
    let events = std::slice::from_ref(&ev);
    let opts = FitOptions {
        polish: false,
        ..options()
    };
    let stages = opts.stages.clone();
    let datasheet = nominal();
    let diagnose_after = |compare: &str| {
        let s = spec(compare, "");
        let fitted = fit(&datasheet, &s, events, &[], &opts, &Silent).unwrap();
        let d = diagnose(
            &fitted.unit,
            events,
            &[],
            &DiagnoseOptions {
                refit: calibrated_set(&s, &stages, &datasheet, &fitted.unit),
                causes: vec![
                    "exciter_limit".into(),
                    "saturation".into(),
                    "terminal_load".into(),
                ],
                look_alikes: false,
                particles: 8,
                pso_iterations: 8,
                lbfgs_iterations: 15,
                seed: 2,
                ..Default::default()
            },
            &Silent,
        )
        .unwrap();
        (fitted, d)
    };
    let efd_over_noise = |d: &itaipu_calib::diagnose::DiagnoseResult| {
        let note = d.report.reference.as_ref().expect("the reference says so");
        let c = note.channels.iter().find(|c| c.signal == "Efd").unwrap();
        (c.rms_offsets / c.sigma, c.rms_reference / c.sigma)
    };

    let (pq_fit, pq) = diagnose_after("objective = \"pq\"");
    let xd = |u: &Unit| u.get(u.param("machine.x_d").unwrap());
    let (before, after) = efd_over_noise(&pq);
    println!(
        "P+Q calibration: X_d {:.3} (truth 0.95); E_fd RMS {before:.1} -> {after:.1} x σ; verdict {} ({})",
        xd(&pq_fit.unit),
        pq.report.verdict.cause,
        pq.report.reference.as_ref().unwrap().sentence
    );
    assert!(before > 5.0, "the P+Q calibration leaves the field far off");
    assert!(after < 1.5, "the reference brings E_fd to the noise");
    let note = pq.report.reference.as_ref().unwrap();
    assert!(note.failed.is_none() && note.freed.contains(&"machine.x_d".to_string()));
    assert!(note.sentence.contains("global search") && note.sentence.contains("Efd"));
    assert_eq!(pq.report.verdict.cause.to_string(), "none");

    let (_, rec) = diagnose_after("channels = \"recorded\"");
    let (before, after) = efd_over_noise(&rec);
    println!(
        "field calibration: E_fd RMS {before:.1} -> {after:.1} x σ; verdict {}",
        rec.report.verdict.cause
    );
    assert!(after < 1.5);
    assert_eq!(
        rec.report.verdict.cause.to_string(),
        pq.report.verdict.cause.to_string()
    );
}
