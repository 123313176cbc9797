//! Power system stabilisers, one file each (docs/model-library.md), and the stabiliser roles
//! they declare ([`roles`]).
pub mod roles;

crate::library! {
    stab3,
    ieeest,
    pss2a,
}
