//! Power system stabilisers.
pub mod ieeest;
pub mod stab3;
