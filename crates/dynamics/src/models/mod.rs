//! Model library: machines, exciters, stabilisers, governors, and shared limiter logic.
pub mod exciter;
pub mod governor;
pub mod limiter;
pub mod machine;
pub mod pss;
