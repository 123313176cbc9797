//! Excitation systems (AVRs): SEXS, ST5B, IEEET1, ESST1A, the blocks they share and the
//! exciter roles every exciter declares ([`roles`]).
pub mod blocks;
pub mod roles;

crate::library! {
    sexs,
    st5b,
    ieeet1,
    esst1a,
}
