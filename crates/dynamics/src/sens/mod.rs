//! Forward sensitivities: the derivatives of a playback's states and of P and Q with respect to
//! the unit's parameters, integrated with the states.
//!
//! Every block with dual equations ([`crate::Block::seed_dual`]) evaluates its outputs and
//! derivatives on [`Dual`] numbers; the unit's right-hand side then gives, with `ẋ = f(t, x, p)`,
//! the sensitivity equations `Ṡ = ∂f/∂x S + ∂f/∂p` exactly (forward-mode automatic
//! differentiation, `LANES` parameters per pass).

mod dual;
mod playback;

pub use dual::{Dual, Scalar};
pub use playback::{simulate_pq_sensitivities, PqSensitivities, SensError};

/// Tangent lanes per sensitivity pass: parameters beyond it take further passes.
pub const LANES: usize = 8;

/// The dual number of a sensitivity pass.
pub type D = Dual<LANES>;

/// A parameter value as a dual: seeded on `lane` when it has one, a constant otherwise.
#[inline]
pub fn seeded(v: f64, lane: Option<usize>) -> D {
    match lane {
        Some(k) => D::var(v, k),
        None => <D as Scalar>::cst(v),
    }
}
