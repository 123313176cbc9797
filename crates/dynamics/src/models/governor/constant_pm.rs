//! Constant mechanical power: no governor action (what RaPId's Itaipu model uses).
//!
//! `P_m = P_m0 + ΔP_m`, where `P_m0` is the value the machine needs for steady state and
//! `ΔP_m` (`pm_offset`, default 0) is a nuisance parameter a fit may free.

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port, PortInit};
use crate::models::exciter::roles::ParamRole;
use crate::models::governor::roles::GovernorRoles;
use crate::sens::{seeded, D};
use crate::{block_common, param_set};
use crate::registry::{ModelInfo, Role};

/// The registry entry ([`crate::registry`]): name, role, `.dyr` record.
pub const MODEL: ModelInfo = ModelInfo {
    name: "constant_pm",
    role: Role::Governor,
    summary: "constant mechanical power (no governor action)",
    reference: "P_m held at its initial value (written as no governor record)",
    make: || Box::new(ConstantPm::default()),
    dyr: None,
};

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
    /// P_m0 + ΔP_m on dual numbers, after [`Block::seed_dual`].
    dual: Option<D>,
}

impl ConstantPm {
    pub fn new(p: ConstantPmParams) -> Self {
        Self {
            p,
            pm0: 0.0,
            dual: None,
        }
    }
}

impl Block for ConstantPm {
    block_common!();

    fn governor_roles(&self) -> Option<GovernorRoles> {
        let mut r = GovernorRoles::none("constant_pm has no governor action");
        r.reference_offset = ParamRole::param("pm_offset");
        Some(r)
    }
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

    fn init_constants(&self) -> Vec<f64> {
        vec![self.pm0]
    }
    fn seed_dual(&mut self, lanes: &[Option<usize>], consts: &[D]) -> bool {
        let pm0 = consts.first().copied().unwrap_or(seeded(self.pm0, None));
        self.dual = Some(pm0 + self.p.lift_dual(lanes).pm_offset);
        true
    }
    fn outputs_dual(&self, _t: f64, _x: &[D], io: &mut Io<D>) {
        if let Some(pm) = self.dual {
            io.set(0, pm);
        }
    }
}
