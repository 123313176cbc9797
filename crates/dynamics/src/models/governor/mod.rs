//! Turbine-governors, one file each (docs/model-library.md), and the governor roles they declare
//! ([`roles`]).
pub mod roles;

crate::library! {
    hygov,
    tgov1,
    ieeeg1,
    gast,
    tg2,
    constant_pm,
}
