//! Excitation systems (AVRs), one file each (docs/model-library.md), the blocks they share and
//! the exciter roles every exciter declares ([`roles`]).
pub mod blocks;
pub mod roles;

crate::library! {
    sexs,
    st5b,
    ieeet1,
    ieeex1,
    exdc2,
    esst1a,
    esst4b,
}
