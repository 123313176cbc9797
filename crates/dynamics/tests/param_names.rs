//! Parameters by PSS/E alias in a unit file: an alias that differs from another only in case
//! (HYGOV's `R`, permanent droop, and `r`, temporary droop) names its own parameter; other
//! aliases and names still match whatever their case.

use std::path::Path;

use itaipu_dynamics::unit_file::parse_unit;

const UNIT: &str = include_str!("../../../data/synthetic/unit_gensae_sexs_stab3_hygov.toml");

fn with_governor(lines: &str) -> String {
    UNIT.replace("r_perm = 0.05\nr_temp = 0.3\n", lines)
}

fn value(text: &str, path: &str) -> f64 {
    let u = parse_unit(text, Path::new("unit.toml")).unwrap();
    u.get(u.param(path).unwrap())
}

#[test]
fn hygov_r_and_r_are_the_two_droops() {
    assert!(UNIT.contains("r_perm = 0.05\nr_temp = 0.3\n"));
    let text = with_governor("R = 0.04\nr = 0.45\n");
    assert_eq!(value(&text, "governor.r_perm"), 0.04);
    assert_eq!(value(&text, "governor.r_temp"), 0.45);
    // Either order.
    let text = with_governor("r = 0.45\nR = 0.04\n");
    assert_eq!(value(&text, "governor.r_perm"), 0.04);
    assert_eq!(value(&text, "governor.r_temp"), 0.45);
    // By path too.
    let u = parse_unit(&text, Path::new("unit.toml")).unwrap();
    assert_eq!(u.get(u.param("governor.r").unwrap()), 0.45);
    assert_eq!(u.get(u.param("governor.R").unwrap()), 0.04);
}

#[test]
fn unambiguous_aliases_and_names_match_in_any_case() {
    let u = parse_unit(UNIT, Path::new("unit.toml")).unwrap();
    let xpd = u.get(u.param("machine.x_d_prime").unwrap());
    assert_eq!(u.get(u.param("machine.Xpd").unwrap()), xpd);
    assert_eq!(u.get(u.param("machine.XPD").unwrap()), xpd);
    assert_eq!(u.get(u.param("machine.X_D_PRIME").unwrap()), xpd);
    assert_eq!(u.get(u.param("governor.R_PERM").unwrap()), 0.05);
}
