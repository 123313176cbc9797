//! The one bound type and its resolver (issue 11 step 3): the errors name the parameter, a
//! start outside the bounds is clamped, the prior comes from the datasheet or is given, the
//! spec's `[[stage.free]]` tables refuse unknown keys, and `--refit` requests become bounds.

use std::path::Path;

use itaipu_calib::bounds::{resolve, BoundProblem, FreeBound, PriorSource};
use itaipu_calib::diagnose::refit_bounds;
use itaipu_calib::diagnose::trial::base_unit;
use itaipu_calib::problem::Prior;
use itaipu_calib::spec::CalibSpec;

#[test]
fn unknown_parameter_is_named() {
    let unit = base_unit();
    let e = resolve(
        &unit,
        &[FreeBound::new("machine.h_bar", 1.0, 2.0)],
        PriorSource::Given,
    )
    .unwrap_err();
    assert_eq!(e.param, "machine.h_bar");
    assert_eq!(e.kind(), "unknown");
    assert!(e.to_string().contains("machine.h_bar"), "{e}");
}

#[test]
fn empty_or_non_finite_bounds_are_refused() {
    let unit = base_unit();
    for (min, max, kind) in [
        (5.0, 2.0, "empty"),
        (2.0, 2.0, "empty"),
        (f64::NAN, 2.0, "empty"),
        (1.0, f64::INFINITY, "non_finite"),
    ] {
        let e = resolve(
            &unit,
            &[FreeBound::new("machine.h", min, max)],
            PriorSource::Given,
        )
        .unwrap_err();
        assert_eq!(e.kind(), kind, "[{min}, {max}]: {e}");
        assert_eq!(e.param, "machine.h");
        assert!(
            e.to_string().starts_with("free parameter machine.h: "),
            "{e}"
        );
        if kind == "empty" {
            assert!(matches!(e.problem, BoundProblem::Empty { .. }));
            assert!(e.to_string().contains("upside down"), "{e}");
        }
    }
}

#[test]
fn start_is_the_unit_value_or_the_given_one_clamped() {
    let unit = base_unit();
    let h = unit.get(unit.param("machine.h").unwrap());
    let free = resolve(
        &unit,
        &[
            FreeBound::new("machine.h", h + 1.0, h + 2.0),
            FreeBound {
                start: Some(h - 0.5),
                ..FreeBound::new("machine.h", 0.5 * h, 2.0 * h)
            },
            FreeBound {
                start: Some(-1.0),
                ..FreeBound::new("machine.h", 0.5 * h, 2.0 * h)
            },
        ],
        PriorSource::Given,
    )
    .unwrap();
    assert_eq!(free[0].start, h + 1.0, "the unit's value, clamped up");
    assert_eq!(free[1].start, h - 0.5, "the given start");
    assert_eq!(free[2].start, 0.5 * h, "the given start, clamped");
    assert_eq!(free[0].path, "machine.h");
}

#[test]
fn priors_from_the_datasheet_or_given() {
    let unit = base_unit();
    let mut datasheet = unit.clone();
    let r = datasheet.param("machine.h").unwrap();
    datasheet.set(r, 4.0);
    let b = |spread| FreeBound {
        spread,
        ..FreeBound::new("machine.h", 1.0, 10.0)
    };
    let priors = PriorSource::Datasheet {
        datasheet: &datasheet,
        default_spread: 0.2,
    };
    let free = resolve(&unit, &[b(None), b(Some(0.5)), b(Some(0.0))], priors).unwrap();
    assert_eq!(
        free[0].prior,
        Some(Prior {
            center: 4.0,
            spread: 0.2
        })
    );
    assert_eq!(free[1].prior.map(|p| p.spread), Some(0.5));
    assert_eq!(free[2].prior, None, "a spread of 0: no prior");
    let given = Prior {
        center: 3.0,
        spread: 0.1,
    };
    let free = resolve(
        &unit,
        &[FreeBound {
            prior: Some(given),
            ..b(Some(0.5))
        }],
        PriorSource::Given,
    )
    .unwrap();
    assert_eq!(free[0].prior, Some(given));
}

#[test]
fn refit_requests_become_bounds() {
    let unit = base_unit();
    let h = unit.get(unit.param("machine.h").unwrap());
    let b = refit_bounds(&unit, &[("machine.h".into(), None)]).unwrap();
    let declared = FreeBound::requested(&unit, "machine.h", None).unwrap();
    assert_eq!(b.len(), 1);
    assert!(b[0].polish_only);
    assert_eq!((b[0].min, b[0].max), (declared.min, declared.max));
    assert!(b[0].min <= h && h <= b[0].max);
    assert_eq!(b[0].start, Some(h));
    let e = refit_bounds(&unit, &[("machine.h".into(), Some((5.0, 2.0)))]).unwrap_err();
    assert!(e.to_string().contains("machine.h") && e.to_string().contains("upside down"));
    let e = refit_bounds(&unit, &[("machine.nope".into(), None)]).unwrap_err();
    assert!(e.to_string().contains("machine.nope"), "{e}");
}

fn spec_with_free(entry: &str) -> Result<CalibSpec, itaipu_calib::spec::SpecError> {
    let text =
        format!("[calibration]\n[[calibration.stage]]\nname = \"gen\"\nfree = [ {entry} ]\n");
    CalibSpec::parse(&text, Path::new("spec.toml"))
}

#[test]
fn spec_free_tables_accept_their_keys_and_refuse_others() {
    let s = spec_with_free(
        "{ param = \"machine.h\", min = 2.0, max = 8.0, start = 4.0, spread = 0.3 }",
    )
    .unwrap();
    let f = &s.stages[0].free[0];
    assert_eq!(
        (f.param.as_str(), f.min, f.max, f.start, f.spread),
        ("machine.h", 2.0, 8.0, Some(4.0), Some(0.3))
    );
    assert_eq!((f.scan, f.polish_only, f.prior), (0, false, None));
    let s = spec_with_free("{ param = \"machine.h\", min = 2.0, max = 8.0 }").unwrap();
    assert_eq!(
        (s.stages[0].free[0].start, s.stages[0].free[0].spread),
        (None, None)
    );
    // The diagnosis' settings are not spec keys, nor is anything else.
    for bad in [
        "scan = 3",
        "polish_only = true",
        "prior = 0.2",
        "factor = 2.0",
        "stat = 1.0",
    ] {
        let e = spec_with_free(&format!(
            "{{ param = \"machine.h\", min = 2.0, max = 8.0, {bad} }}"
        ))
        .unwrap_err();
        let key = bad.split(' ').next().unwrap();
        assert_eq!(e.kind(), "syntax", "{bad}: {e}");
        assert!(
            e.to_string().contains("unknown field") && e.to_string().contains(key),
            "{bad}: {e}"
        );
    }
}

/// The catalog's search ranges that do not depend on the operating point, the evidence or the
/// PMU rate are the parameters' declared ranges.
#[test]
fn catalog_search_ranges_are_the_declared_ranges() {
    use itaipu_calib::diagnose::catalog;
    let base = base_unit();
    let t = itaipu_calib::diagnose::trial::scenario("none", 1, None);
    let (_, ev) = itaipu_calib::diagnose::trial::truth_and_event(&t).unwrap();
    let ctx = itaipu_calib::diagnose::context(&base, &ev).unwrap();
    let no_pss = base.without(&["pss"]).unwrap();
    let mut expected: Vec<&str> = vec![
        "deadband.db",
        "governor.velm",
        "governor.r_perm",
        "governor.t_w",
        "load.p_load",
        "load.q_load",
        // (oel.ifd_rated's range is computed by the cause: it is read against the calibrated
        // unit's pre-event field current, which a re-fit from the datasheet may leave.)
        "oel.a_max",
        "oel.k_i",
        "pss.k_x",
        "pss.t_x2",
        "machine.s10",
        "machine.s12",
        "shaft.zeta",
    ];
    let mut seen: Vec<String> = vec![];
    for c in catalog::CAUSES.iter().map(|c| c.info()) {
        for unit in [&base, &no_pss] {
            let Ok(ext) = catalog::extend(c.id, unit, &ctx) else {
                continue;
            };
            for b in ext.extension_free.iter().chain(&ext.interacting_free) {
                if !expected.contains(&b.param.as_str()) {
                    continue;
                }
                let r = ext.unit.param(&b.param).unwrap();
                assert_eq!(
                    (b.min, b.max),
                    ext.unit.param_spec(r).range,
                    "{}: {}",
                    c.id,
                    b.param
                );
                seen.push(b.param.clone());
            }
        }
    }
    expected.retain(|p| !seen.iter().any(|s| s == p));
    assert!(expected.is_empty(), "not freed by any cause: {expected:?}");
}

#[test]
fn a_bound_continues_from_a_units_value_or_keeps_its_start() {
    let mut unit = base_unit();
    let r = unit.param("machine.h").unwrap();
    unit.set(r, 4.0);
    let b = FreeBound::new("machine.h", 1.0, 3.0).starting_at(2.0);
    // The unit's value, clamped into the bounds.
    assert_eq!(b.starting_in(&unit).start, Some(3.0));
    unit.set(r, 1.5);
    assert_eq!(b.starting_in(&unit).start, Some(1.5));
    // A unit without the parameter: the bound's own start.
    let other = FreeBound::new("oel.i_pickup", 1.0, 1.5).starting_at(1.2);
    assert_eq!(other.starting_in(&unit).start, Some(1.2));
}
