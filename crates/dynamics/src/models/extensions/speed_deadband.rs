//! `speed_deadband`: intentional governor deadband on the speed signal (`models.md` §12.2,
//! type 1, "no jump"; OpenIPSL `Nonlinear/Deadband1.mo` with err = 0, ANDES HYGOVDB).
//!
//! ```text
//! y = 0                   if |u| ≤ db
//! y = u − db·sign(u)      otherwise
//! ```
//!
//! `u` is the machine's speed deviation Δω (port `speed`), `y` the signal the governor sees (port
//! `speed_db`; rewire the governor with `wiring = { speed = "speed_db" }`). Stateless and
//! feed-through. The characteristic is continuous (only its slope jumps at ±db), so no discrete
//! mode is needed: the adaptive integrator's error control handles the kink. At
//! initialisation `y0 = f(Δω0)`, and the governor initialises on `y0` (its speed reference
//! absorbs it), so the unit starts in steady state at any frequency. `db = 0` is the identity.

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port, PortInit};
use crate::sens::{Scalar, D};
use crate::{block_common, param_set};
use crate::registry::{ModelInfo, Role};

/// The registry entry ([`crate::registry`]): name, role, `.dyr` record.
pub const MODEL: ModelInfo = ModelInfo {
    name: "speed_deadband",
    role: Role::Other,
    summary: "intentional governor speed deadband, no-jump type (extension, §12.2)",
    reference: "models.md §12.2",
    make: || Box::new(SpeedDeadband::default()),
    dyr: None,
};

param_set! {
    /// Speed-deadband parameters.
    pub struct SpeedDeadbandParams {
        db: ("db", "pu", 0.0003, (0.0, 0.004), "half-width of the speed deadband (0.0003 pu = ±0.018 Hz at 60 Hz)"),
    }
}

mod port {
    pub const SPEED: usize = 0;
    pub const SPEED_DB: usize = 1;
}

const PORTS: &[Port] = &[
    Port::input_ft("speed", PortInit::Needs, "speed deviation Δω [pu]"),
    Port::output(
        "speed_db",
        PortInit::Gives,
        "speed deviation after the deadband [pu]",
    ),
];

/// Speed deadband block.
#[derive(Debug, Clone, Default)]
pub struct SpeedDeadband {
    pub p: SpeedDeadbandParams,
    /// The half-width on dual numbers, after [`Block::seed_dual`].
    dual: Option<D>,
}

impl SpeedDeadband {
    /// The type-1 deadband characteristic (on duals: the derivative of the active piece).
    #[inline(always)]
    pub fn apply<S: Scalar>(u: S, db: S) -> S {
        if u.val() > db.val() {
            u - db
        } else if u.val() < -db.val() {
            u + db
        } else {
            S::cst(0.0)
        }
    }
}

impl Block for SpeedDeadband {
    block_common!();

    fn model(&self) -> &'static str {
        "speed_deadband"
    }
    fn ports(&self) -> &'static [Port] {
        PORTS
    }
    fn state_names(&self) -> &'static [&'static str] {
        &[]
    }
    fn validate(&self) -> Result<(), ModelError> {
        guard::non_negative("db", self.p.db)
    }
    fn init(&mut self, _op: &InitPoint, _x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        self.validate()?;
        io.set(port::SPEED_DB, Self::apply(io.get(port::SPEED), self.p.db));
        Ok(())
    }
    #[inline]
    fn outputs(&self, _t: f64, _x: &[f64], io: &mut Io) {
        io.set(port::SPEED_DB, Self::apply(io.get(port::SPEED), self.p.db));
    }
    fn derivatives(&self, _t: f64, _x: &[f64], _io: &Io, _dx: &mut [f64]) {}

    fn seed_dual(&mut self, lanes: &[Option<usize>], _consts: &[D]) -> bool {
        self.dual = Some(self.p.lift_dual(lanes).db);
        true
    }

    fn outputs_dual(&self, _t: f64, _x: &[D], io: &mut Io<D>) {
        if let Some(db) = self.dual {
            io.set(port::SPEED_DB, Self::apply(io.get(port::SPEED), db));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::SpeedDeadband;

    #[test]
    fn characteristic_is_continuous_and_shifted() {
        let db = 0.0003;
        assert_eq!(SpeedDeadband::apply(0.0002, db), 0.0);
        assert_eq!(SpeedDeadband::apply(-0.0003, db), 0.0);
        assert!((SpeedDeadband::apply(0.001, db) - 0.0007).abs() < 1e-18);
        assert!((SpeedDeadband::apply(-0.001, db) + 0.0007).abs() < 1e-18);
        assert_eq!(SpeedDeadband::apply(0.0123, 0.0), 0.0123);
    }
}
