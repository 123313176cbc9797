//! `Unit::with_params`: a copy with some parameters changed, checked as a unit file is.

use itaipu_dynamics::unit::UnitError;
use itaipu_dynamics::unit_file::parse_unit;

const BASE: &str = include_str!("../../../data/synthetic/unit_gensae_sexs_stab3_hygov.toml");

fn base() -> itaipu_dynamics::unit::Unit {
    parse_unit(BASE, std::path::Path::new("synthetic.toml")).expect("bundled synthetic unit")
}

fn refused(r: Result<itaipu_dynamics::unit::Unit, UnitError>) -> UnitError {
    match r {
        Ok(_) => panic!("accepted"),
        Err(e) => e,
    }
}

fn value(u: &itaipu_dynamics::unit::Unit, path: &str) -> f64 {
    u.get(u.param(path).unwrap())
}

#[test]
fn sets_values_by_name_and_alias_and_leaves_the_original() {
    let u = base();
    let h0 = value(&u, "machine.h");
    let k0 = value(&u, "exciter.k");
    let e = u
        .with_params(&[("machine.h", h0 + 1.25), ("exciter.K", k0 * 2.0)])
        .expect("valid values");
    assert_eq!(value(&e, "machine.h"), h0 + 1.25);
    assert_eq!(value(&e, "exciter.k"), k0 * 2.0);
    assert_eq!(value(&u, "machine.h"), h0, "the original is unchanged");
    // Every other parameter is untouched.
    for ((p, _, a), (_, _, b)) in u.params().iter().zip(e.params().iter()) {
        if p != "machine.h" && p != "exciter.k" {
            assert_eq!(a, b, "{p}");
        }
    }
}

#[test]
fn unknown_parameter_is_named() {
    let err = refused(base().with_params(&[("machine.hh", 3.0)]));
    assert!(
        matches!(err, UnitError::UnknownParam(ref p) if p == "machine.hh"),
        "{err}"
    );
    assert!(err.to_string().contains("machine.hh"), "{err}");
}

#[test]
fn out_of_domain_value_names_block_and_parameter() {
    let err = refused(base().with_params(&[("machine.h", -1.0)]));
    assert_eq!(err.kind(), "bad_param");
    let msg = err.to_string();
    assert!(msg.starts_with("machine (GENSAE): parameter h"), "{msg}");
    // A relation between parameters: X'd above Xd.
    let u = base();
    let xd = value(&u, "machine.x_d");
    let err = refused(u.with_params(&[("machine.x_d_prime", xd * 1.5)]));
    assert_eq!(err.kind(), "bad_param", "{err}");
    assert!(err.to_string().contains("x_d"), "{err}");
    let err = refused(u.with_params(&[("exciter.k", f64::NAN)]));
    assert!(
        err.to_string().contains("parameter k: must be finite"),
        "{err}"
    );
}
