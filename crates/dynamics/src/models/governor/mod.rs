//! Turbine-governors.
pub mod constant_pm;
pub mod hygov;
