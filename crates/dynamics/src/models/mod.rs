//! Model library: machines, exciters, stabilisers, governors, model extensions, and shared
//! limiter logic.
pub mod exciter;
pub mod extensions;
pub mod governor;
pub mod limiter;
pub mod machine;
pub mod pss;
