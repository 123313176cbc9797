//! Excitation systems (AVRs).
pub mod sexs;
