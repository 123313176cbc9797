//! Model library: machines, exciters, stabilisers, governors, model extensions, the grid
//! equivalent of the closed-loop playback, and shared limiter logic.
pub mod exciter;
pub mod extensions;
pub mod governor;
pub mod grid;
pub mod limiter;
pub mod machine;
pub mod pss;
