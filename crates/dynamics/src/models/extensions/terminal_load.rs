//! `terminal_load`: an unmodelled load between the machine terminals and the measurement point
//! (station service, excitation transformer, a feeder tapped off the generator bus), as a static
//! voltage-dependent load (`models.md` §12, exponential load model).
//!
//! ```text
//! P_L(V) = P_L0 · V^{n_P},   Q_L(V) = Q_L0 · V^{n_Q}      (pu on the machine base, V in pu)
//! P_meas = P_e − P_L(V),     Q_meas = Q_e − Q_L(V)
//! ```
//!
//! `n = 2` is a constant impedance, `n = 1` a constant current, `n = 0` a constant power. The
//! load sits at the played-back bus, so it sees the measured |V| and adds no state. The machine
//! delivers the measured power plus the load: it initialises at `P0 + P_L(V0)`, `Q0 + Q_L(V0)`
//! ([`Block::terminal_load`] is read by the unit at initialisation and when it records P and Q).
//! With `P_L0 = Q_L0 = 0` (the defaults) it changes nothing.

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port};
use crate::sens::{Scalar, D};
use crate::{block_common, param_set};
use crate::registry::{ModelInfo, Role};

/// The registry entry ([`crate::registry`]): name, role, `.dyr` record.
pub const MODEL: ModelInfo = ModelInfo {
    name: "terminal_load",
    role: Role::Other,
    summary: "static voltage-dependent load between the machine and the measurement point (extension)",
    reference: "a static load model between the terminal and the measurement point",
    make: || Box::new(TerminalLoad::default()),
    dyr: None,
};

param_set! {
    /// Terminal-load parameters.
    pub struct TerminalLoadParams {
        p_load: ("PL", "pu", 0.0, (0.0, 0.15), "active power drawn at 1 pu voltage (machine base)"),
        q_load: ("QL", "pu", 0.0, (0.0, 0.15), "reactive power drawn at 1 pu voltage (machine base, > 0 inductive: an auxiliary load of motors and transformers draws reactive power)"),
        n_p: ("nP", "-", 2.0, (0.0, 2.0), "voltage exponent of P (2 = constant impedance)"),
        n_q: ("nQ", "-", 2.0, (0.0, 2.0), "voltage exponent of Q (2 = constant impedance)"),
    }
}

/// Static load between the machine and the PMU.
#[derive(Debug, Clone, Default)]
pub struct TerminalLoad {
    pub p: TerminalLoadParams,
    /// The parameters on dual numbers, after [`Block::seed_dual`].
    dual: Option<TerminalLoadParams<D>>,
}

/// `(P_L(V), Q_L(V))`; on duals `V^n = exp(n ln V)` carries `∂/∂n` (the value is `powf`'s, as
/// in the simulation).
fn load<S: Scalar>(p: &TerminalLoadParams<S>, v: f64) -> (S, S) {
    let v = v.max(0.0);
    let pow = |n: S| {
        let value = v.powf(n.val());
        if v > 0.0 {
            (n * v.ln()).exp().with_value(value)
        } else {
            S::cst(value)
        }
    };
    (p.p_load * pow(p.n_p), p.q_load * pow(p.n_q))
}

impl Block for TerminalLoad {
    block_common!();

    fn model(&self) -> &'static str {
        "terminal_load"
    }
    fn ports(&self) -> &'static [Port] {
        &[]
    }
    fn state_names(&self) -> &'static [&'static str] {
        &[]
    }
    fn validate(&self) -> Result<(), ModelError> {
        guard::finite("p_load", self.p.p_load)?;
        guard::finite("q_load", self.p.q_load)?;
        guard::finite("n_p", self.p.n_p)?;
        guard::finite("n_q", self.p.n_q)
    }
    fn init(&mut self, _op: &InitPoint, _x: &mut [f64], _io: &mut Io) -> Result<(), ModelError> {
        self.validate()
    }
    fn outputs(&self, _t: f64, _x: &[f64], _io: &mut Io) {}
    fn derivatives(&self, _t: f64, _x: &[f64], _io: &Io, _dx: &mut [f64]) {}

    fn terminal_load(&self, v: f64) -> (f64, f64) {
        load(&self.p, v)
    }
    fn seed_dual(&mut self, lanes: &[Option<usize>], _consts: &[D]) -> bool {
        self.dual = Some(self.p.lift_dual(lanes));
        true
    }
    fn terminal_load_dual(&self, v: f64) -> (D, D) {
        self.dual
            .as_ref()
            .map_or((D::cst(0.0), D::cst(0.0)), |p| load(p, v))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_impedance_scales_with_v_squared() {
        let mut b = TerminalLoad::default();
        b.p.p_load = 0.04;
        b.p.q_load = -0.02;
        let (p, q) = b.terminal_load(0.5);
        assert!((p - 0.01).abs() < 1e-15 && (q + 0.005).abs() < 1e-15);
        b.p.n_p = 0.0;
        assert!((b.terminal_load(0.5).0 - 0.04).abs() < 1e-15);
        assert_eq!(TerminalLoad::default().terminal_load(1.1), (0.0, 0.0));
    }
}
