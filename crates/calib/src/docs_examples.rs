//! The Rust examples of the documentation, compiled inside this crate as the code they show
//! would be (a test of the documentation checks that each example's Markdown block is the file
//! compiled here), and exercised: an example that no longer compiles, or no longer does what
//! its chapter says, fails the build or a test.

/// `docs/extending.md`: a cause added to the catalog.
#[path = "../../../docs/examples/generator_damping.rs"]
mod generator_damping;

use crate::diagnose::catalog::{instance_with_role, Cause, Context, Extension, Roles};
use itaipu_dynamics::registry::Role;

/// The extension of `cause` for `unit`, built as the catalog builds a registered cause's.
fn extension(cause: &'static dyn Cause, unit: &itaipu_dynamics::unit::Unit) -> Extension {
    let roles = Roles {
        machine: instance_with_role(unit, Role::Machine).expect("a machine"),
        exciter: instance_with_role(unit, Role::Exciter),
        pss: instance_with_role(unit, Role::Pss),
        governor: instance_with_role(unit, Role::Governor),
    };
    let mut x = Extension {
        cause: cause.info().id,
        unit: unit.clone(),
        extension_free: vec![],
        interacting_free: vec![],
        discrete_params: 0,
        ties: vec![],
        description: cause.info().extension.to_string(),
        fixed: vec![],
        search_factor: 1,
        from_datasheet: false,
    };
    cause
        .extend(&mut x, &roles, &Context::default())
        .expect("the documented cause applies to the synthetic unit");
    x
}

#[test]
fn the_documented_cause_frees_its_key_parameter_within_its_declared_range() {
    let cause: &'static dyn Cause = &generator_damping::GeneratorDamping;
    let unit = crate::diagnose::trial::base_unit();
    let x = extension(cause, &unit);
    let key = cause.info().key_params[0];
    assert_eq!(x.extension_free.len(), 1);
    let d = &x.extension_free[0];
    assert_eq!(d.param, key);
    // The machine's declared plausible range for D (`param_set!`), the unit's value inside it.
    assert!(
        d.min <= 0.0 && d.max >= 2.0,
        "{} in [{}, {}]",
        d.param,
        d.min,
        d.max
    );
    assert_eq!(cause.acts(), crate::diagnose::catalog::Acts::Mechanical);
    // Its self-test scenario sets the key parameter to a value the range holds.
    let sc = cause
        .scenario(&|_| 1.0)
        .expect("the documented cause has a self-test");
    let (p, v) = sc.values[0];
    assert_eq!(p, key);
    assert!(v > d.min && v < d.max);
}
