//! `grid_equivalent`: the network seen from the unit's terminal during a test, a Thévenin
//! equivalent `Z_e = R_e + j X_e` to an infinite bus (RaPId's Mostar model: X = 0.1169 pu to an
//! infinite bus).
//!
//! The block holds only the parameters (no ports, no states): the playback mode `closed_loop`
//! ([`crate::mode`]) solves the network equation `V_t = E_∞ + Z_e · I_t` with them at every
//! evaluation, `I_t` the current the unit delivers at its terminal. The infinite-bus voltage
//! `E_∞` is not a parameter: it is initialised from the pre-event operating point
//! (`E_∞ = V_t0 − Z_e · I_t0`), so that the unit starts in the measured steady state whatever
//! `Z_e`; its magnitude and angle then stay fixed (rotating at the pre-event frequency). In the
//! other playback modes the block is inert. Per unit on the **machine** base.

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port};
use crate::registry::{ModelInfo, Role};
use crate::{block_common, param_set};

/// The registry entry ([`crate::registry`]).
pub const MODEL: ModelInfo = ModelInfo {
    name: "grid_equivalent",
    role: Role::Other,
    summary: "network seen from the terminal: Z_e = R_e + jX_e to an infinite bus (closed_loop playback only)",
    reference: "a Thévenin equivalent (RaPId's Mostar model)",
    make: || Box::new(GridEquivalent::default()),
    dyr: None,
};

param_set! {
    /// Grid-equivalent parameters (machine base).
    pub struct GridEquivalentParams {
        x_e: ("XE", "pu", 0.1, (0.02, 0.5), "reactance from the terminal to the infinite bus X_e"),
        r_e: ("RE", "pu", 0.0, (0.0, 0.05), "resistance from the terminal to the infinite bus R_e"),
    }
}

/// The grid equivalent. See the module documentation.
#[derive(Debug, Clone, Default)]
pub struct GridEquivalent {
    pub p: GridEquivalentParams,
}

impl GridEquivalent {
    /// The impedance `(R_e, X_e)` [pu machine base].
    pub fn impedance(&self) -> (f64, f64) {
        (self.p.r_e, self.p.x_e)
    }
}

impl Block for GridEquivalent {
    block_common!();
    fn model(&self) -> &'static str {
        MODEL.name
    }
    fn ports(&self) -> &'static [Port] {
        &[]
    }
    fn state_names(&self) -> &'static [&'static str] {
        &[]
    }
    fn validate(&self) -> Result<(), ModelError> {
        guard::non_negative("x_e", self.p.x_e)?;
        guard::non_negative("r_e", self.p.r_e)
    }
    fn init(&mut self, _op: &InitPoint, _x: &mut [f64], _io: &mut Io) -> Result<(), ModelError> {
        self.validate()
    }
    fn outputs(&self, _t: f64, _x: &[f64], _io: &mut Io) {}
    fn derivatives(&self, _t: f64, _x: &[f64], _io: &Io, _dx: &mut [f64]) {}
}
