//! Excitation systems (AVRs): SEXS, ST5B, IEEET1, ESST1A, the blocks they share and the
//! exciter roles every exciter declares ([`roles`]).
pub mod blocks;
pub mod esst1a;
pub mod ieeet1;
pub mod roles;
pub mod sexs;
pub mod st5b;
