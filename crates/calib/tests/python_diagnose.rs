//! Issue 25 item 3: Python's documented fit-then-diagnose on the bundled Itaipu unit
//!
//! ```python
//! u = ic.read_dyr("data/itaipu/unit.dyr")
//! r = ic.fit("out/ev/event.toml", u, calib="data/itaipu/calibration.toml")
//! ic.diagnose("out/ev/event.toml", u, fit=r)
//! ```
//!
//! ended after 21 s in `PanicException: min > max, or either was NaN`: the `exciter_limit`
//! cause's supply-fed ceiling (SEXS_bus_fed) fell below its floor in the dip and `f64::clamp`
//! panicked. The same calls through the library as the Python module makes them (the event
//! imported from the COMTRADE recording as `itaipu-calib import` does; the datasheet unit from
//! the `.dyr` with its bases; the calibrated set re-freed around it, `fit=r`; Python's default
//! budgets), with the exciter_limit cause alone to keep it short. About 40 s on 2 cores.

use std::path::PathBuf;

use itaipu_calib::diagnose::{calibrated_set, diagnose, DiagnoseOptions};
use itaipu_calib::fit::{fit, FitOptions, Silent};
use itaipu_calib::spec::CalibSpec;
use itaipu_dynamics::dyr;
use itaipu_dynamics::pmu_import::{import, ImportOptions};

fn data() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/itaipu")
}

#[test]
fn pythons_diagnose_with_fit_on_the_datasheet_unit_gives_a_verdict() {
    // `itaipu-calib import data/itaipu/pmu/itaipu.cfg --system-mva 1000 --nominal-hz 60
    // --v-base-kv 18`
    let (event, _) = import(
        &data().join("pmu/itaipu.cfg"),
        &ImportOptions {
            v_base_kv: Some(18.0),
            ..ImportOptions::new(1000.0, 60.0)
        },
    )
    .unwrap();
    let events = std::slice::from_ref(&event);
    // `ic.read_dyr("data/itaipu/unit.dyr")`: bases from unit.bases.toml beside it.
    let path = data().join("unit.dyr");
    let bases = dyr::resolve_bases(&path, None, &Default::default()).unwrap();
    let u = dyr::read_dyr(&path, None, &bases).unwrap().unit;
    // `ic.fit(event, u, calib=...)`: the spec's own budgets.
    let spec = CalibSpec::from_file(&data().join("calibration.toml")).unwrap();
    let opts = FitOptions::from_spec(&spec);
    let r = fit(&u, &spec, events, &[], &opts, &Silent).unwrap();
    // `FitResult.calibrated_set`, and `ic.diagnose(event, u, fit=r)` with Python's defaults
    // (crates/py/src/fit.rs and diagnose.rs): the set's parameters the unit has.
    let mut d = DiagnoseOptions {
        causes: vec!["exciter_limit".into()],
        ..Default::default()
    };
    for b in calibrated_set(&spec, &opts.stages, &u, &r.unit) {
        if u.param(&b.param).is_ok() {
            d.refit.push(b);
        }
    }
    assert!(d.refit.len() >= 18, "RaPId's 18 parameters re-freed");
    let out = diagnose(&u, events, &[], &d, &Silent).unwrap();
    let c = &out.report.candidates;
    println!("{}", out.report.verdict.statement);
    assert_eq!(c.len(), 1);
    assert_eq!(c[0].cause, "exciter_limit");
    assert!(c[0].applicable, "{}", c[0].note);
    assert!(c[0].gains.is_some(), "re-fitted: {}", c[0].note);
    assert!(
        ["exciter_limit", "none", "unexplained"].contains(&out.report.verdict.cause.as_str()),
        "{}",
        out.report.verdict.cause
    );
    assert!(!out.report.verdict.statement.is_empty());
}
