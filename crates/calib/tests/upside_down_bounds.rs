//! Issue 25: a bound whose min exceeds max (or is NaN) can be built in code (the spec parser
//! and `--refit` refuse them, a `CalibSpec` or a `FreeBound` made by a program need not). Giving
//! it a start and taking a calibrated set from it used `f64::clamp`, which panics; now the start
//! is kept and the bound is refused by name where it is used: a typed error, not a panic.

use std::path::Path;

use itaipu_calib::bounds::{resolve, FreeBound, PriorSource};
use itaipu_calib::diagnose::trial::base_unit;
use itaipu_calib::diagnose::{calibrated_set, diagnose, DiagnoseError, DiagnoseOptions};
use itaipu_calib::fit::Silent;
use itaipu_calib::spec::CalibSpec;
use itaipu_dynamics::synthetic::{synthesize, PmuNoise, VoltageProfile};

#[test]
fn an_upside_down_bound_keeps_its_start_and_is_refused_by_name() {
    let unit = base_unit();
    for (min, max) in [(5.0, 2.0), (f64::NAN, 2.0), (1.0, f64::NAN)] {
        let b = FreeBound::new("machine.h", min, max).starting_at(3.0);
        assert_eq!(b.start, Some(3.0));
        assert_eq!(b.start_from(4.0), 3.0);
        let b = FreeBound::new("machine.h", min, max).starting_in(&unit);
        assert_eq!(b.start, Some(4.5), "the unit's H");
        let e = resolve(&unit, &[b], PriorSource::Given).unwrap_err();
        assert_eq!((e.param.as_str(), e.kind()), ("machine.h", "empty"), "{e}");
    }
}

#[test]
fn a_calibrated_set_from_an_upside_down_spec_bound_is_a_setup_error_of_diagnose() {
    let unit = base_unit();
    let text = "[calibration]\n[[calibration.stage]]\nname = \"gen\"\n\
                free = [ { param = \"machine.h\", min = 2.0, max = 8.0 } ]\n";
    let mut spec = CalibSpec::parse(text, Path::new("spec.toml")).unwrap();
    (spec.stages[0].free[0].min, spec.stages[0].free[0].max) = (8.0, 2.0);
    let set = calibrated_set(&spec, &["gen".to_string()], &unit, &unit);
    assert_eq!(set.len(), 1);
    assert_eq!(set[0].start, Some(4.5), "the calibrated value, not clamped");
    let profile = VoltageProfile {
        duration_s: 3.0,
        ..VoltageProfile::default()
    };
    let ev = synthesize(
        "dip",
        &unit,
        &profile,
        1000.0,
        &PmuNoise::typical(1),
        &Default::default(),
    )
    .unwrap();
    let opts = DiagnoseOptions {
        causes: vec!["terminal_load".into()],
        refit: set,
        ..Default::default()
    };
    match diagnose(&unit, &[ev], &[], &opts, &Silent) {
        Err(DiagnoseError::Setup(msg)) => {
            assert!(
                msg.contains("machine.h") && msg.contains("upside down"),
                "{msg}"
            )
        }
        Err(e) => panic!("{e:?}"),
        Ok(_) => panic!("an upside-down refit bound was used"),
    }
}
