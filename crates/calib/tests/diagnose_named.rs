//! The catalog's own recovery of a cause hidden by our engine (the protocol of
//! `itaipu_calib::diagnose::trial`, see `diagnose.rs`): each test fits and diagnoses a whole
//! 20 s event with the catalog, 10-30 s each on 2 cores, so they run in the slower tier
//! (`scripts/test-slow.sh`).

use itaipu_calib::diagnose::trial::{run, scenario};
use itaipu_calib::diagnose::DiagnoseOptions;
use itaipu_dynamics::synthetic::EventKind;

/// The catalog's own recovery of a cause hidden by our engine. The look-alikes outside the
/// catalog are left out here (they are scored after every catalog cause and leave their
/// scores as they are; what they do to right names is measured on the practice sets, where
/// `tests/practice.rs` runs them, and their verdict rule is `verdict.rs`'s unit test).
fn check(cause: &str, seed: u64, kind: Option<EventKind>) {
    check_with(cause, seed, kind, false);
}

/// [`check`], the re-fits' searches stepping over the smoothed input's samples or not
/// (`DiagnoseOptions::refit_over_samples`).
fn check_with(cause: &str, seed: u64, kind: Option<EventKind>, over_samples: bool) {
    let t = scenario(cause, seed, kind);
    let o = run(
        &t,
        &DiagnoseOptions {
            seed,
            look_alikes: false,
            refit_over_samples: over_samples,
            ..Default::default()
        },
    )
    .unwrap_or_else(|e| panic!("{cause}: {e}"));
    for c in &o.report.candidates {
        match &c.gains {
            Some(g) => println!(
                "{:<17} ΔBIC {:>9.1} fit {:>6.1} % held {:>6.1} % null {:>6.1} {}",
                c.cause,
                g.delta_bic,
                100.0 * g.fit_drop,
                100.0 * g.held_drop,
                g.null_gain_fit,
                if c.significant { "significant" } else { "" }
            ),
            None => println!("{:<17} {}", c.cause, c.note),
        }
    }
    println!("verdict: {}", o.report.verdict.statement);
    assert_eq!(
        o.named, t.cause,
        "{cause} hidden (seed {seed}): the verdict is {}",
        o.report.verdict.statement
    );
    if let Some((p, truth, got)) = &o.key {
        let got = got.unwrap_or_else(|| panic!("{cause}: the verdict does not report {p}"));
        println!("{p}: truth {truth:.5}, recovered {got:.5}");
        assert!(
            o.hit,
            "{cause}: {p} recovered {got:.5} for truth {truth:.5}, outside the tolerance"
        );
    }
    // The trial's phasor record is played back smoothed at the default cut-off; a cause whose
    // mode lies above it (the shaft's) is re-fitted on the record as recorded, every other on
    // the smoothed one.
    for c in o.report.candidates.iter().filter(|c| c.applicable) {
        assert_eq!(
            c.input_as_recorded,
            c.cause == "torsional_mode",
            "{}: input as recorded {}",
            c.cause,
            c.input_as_recorded
        );
    }
    // The first candidate of the ranked table is the named one.
    if cause != "none" {
        assert_eq!(o.report.candidates[0].cause, cause);
        assert!(o.report.candidates[0].significant);
    }
}

#[test]
fn hidden_torsional_mode_is_named_with_its_frequency() {
    check("torsional_mode", 101, None);
}

#[test]
fn hidden_pmu_skew_is_named_with_its_delay() {
    check("measurement_skew", 101, None);
}

#[test]
fn hidden_terminal_load_is_named() {
    check("terminal_load", 101, None);
}

#[test]
fn hidden_exciter_ceiling_is_named_with_its_limit() {
    check("exciter_limit", 101, None);
}

#[test]
fn hidden_saturation_is_named() {
    check("saturation", 101, None);
}

#[test]
fn a_hidden_over_excitation_limiter_is_named_with_its_pickup() {
    check("oel", 101, None);
}

#[test]
fn hidden_governor_deadband_and_rate_limit_are_named() {
    check("governor", 101, None);
}

/// The option that lets the re-fits' searches step over the smoothed samples names the same
/// hidden OEL with its pickup, and finds nothing on the clean dip.
#[test]
fn stepping_over_the_samples_in_the_refits_keeps_the_oel_and_the_clean_dip() {
    check_with("oel", 101, None, true);
    check_with("none", 101, None, true);
}

#[test]
fn a_pss_out_of_service_is_named() {
    check("pss_state", 101, None);
}

#[test]
fn a_clean_fault_dip_gives_none() {
    check("none", 101, None);
}

#[test]
fn a_clean_frequency_excursion_gives_none() {
    check("none", 102, Some(EventKind::FrequencyExcursion));
}
