//! Constant mechanical power: no governor action (what RaPId's Itaipu model uses).
//!
//! `P_m = P_m0 + ΔP_m`, where `P_m0` is the value the machine needs for steady state and
//! `ΔP_m` (`pm_offset`, default 0) is a nuisance parameter a fit may free.

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port, PortInit};
use crate::{block_common, param_set};

param_set! {
    /// Constant-P_m parameters.
    pub struct ConstantPmParams {
        pm_offset: ("dPm", "pu", 0.0, (-0.01, 0.01), "mechanical power offset added after initialisation (nuisance)"),
    }
}

const PORTS: &[Port] = &[Port::output(
    "pm",
    PortInit::Needs,
    "mechanical power P_m [pu machine base]",
)];

/// Constant mechanical power block.
#[derive(Debug, Clone, Default)]
pub struct ConstantPm {
    pub p: ConstantPmParams,
    pm0: f64,
}

impl ConstantPm {
    pub fn new(p: ConstantPmParams) -> Self {
        Self { p, pm0: 0.0 }
    }
}

impl Block for ConstantPm {
    block_common!();
    fn model(&self) -> &'static str {
        "constant_pm"
    }
    fn ports(&self) -> &'static [Port] {
        PORTS
    }
    fn state_names(&self) -> &'static [&'static str] {
        &[]
    }
    fn validate(&self) -> Result<(), ModelError> {
        guard::finite("pm_offset", self.p.pm_offset)
    }
    fn init(&mut self, _op: &InitPoint, _x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        self.validate()?;
        self.pm0 = io.get(0);
        Ok(())
    }
    fn outputs(&self, _t: f64, _x: &[f64], io: &mut Io) {
        io.set(0, self.pm0 + self.p.pm_offset);
    }
    fn derivatives(&self, _t: f64, _x: &[f64], _io: &Io, _dx: &mut [f64]) {}
}
