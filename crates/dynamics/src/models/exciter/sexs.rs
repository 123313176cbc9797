//! SEXS: simplified excitation system (`models.md` §9.1; OpenIPSL `ES/SEXS.mo`, ANDES `sexs.py`).
//!
//! States: lead-lag state `x_ll` and exciter state `x_e` (non-windup in [E_MIN, E_MAX]).
//!
//! ```text
//! v_err = V_ref + ΔV_ref − E_comp + V_S + V_UEL + V_OEL          (E_comp = |V_t|)
//! T_B dx_ll/dt = v_err − x_ll,     y_ll = (T_A/T_B) v_err + (1 − T_A/T_B) x_ll
//! T_E dx_e/dt  = K y_ll − x_e      (derivative frozen at a limit while pushing outwards)
//! E_fd = clamp(x_e, E_MIN, E_MAX)
//! ```
//!
//! Initialisation: `x_e = E_fd0`, `x_ll = E_fd0/K`, `V_ref = E_comp0 − V_S0 − V_UEL0 − V_OEL0 +
//! E_fd0/K`; infeasible (an error, not a clip) when `E_fd0 ∉ [E_MIN, E_MAX]`. `ΔV_ref`
//! (`v_ref_offset`, default 0) is a nuisance parameter a fit may free to absorb a set-point
//! mismatch between model and measurement.

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port, PortInit};
use crate::models::limiter::NonWindup;
use crate::{block_common, param_set};

param_set! {
    /// SEXS parameters.
    pub struct SexsParams {
        ta_tb: ("T_AT_B", "-", 0.2, (0.1, 0.3), "ratio of lead to lag time constant T_A/T_B"),
        tb: ("T_B", "s", 10.0, (5.0, 15.0), "lag time constant T_B"),
        k: ("K", "pu", 100.0, (30.0, 400.0), "gain"),
        te: ("T_E", "s", 0.05, (0.02, 0.1), "exciter (bridge) time constant"),
        e_min: ("E_MIN", "pu", 0.0, (-4.0, 0.0), "minimum field voltage"),
        e_max: ("E_MAX", "pu", 4.0, (4.0, 6.0), "maximum field voltage"),
        v_ref_offset: ("dVref", "pu", 0.0, (-0.01, 0.01), "voltage reference offset added after initialisation (nuisance)"),
    }
}

mod port {
    pub const V_TERM: usize = 0;
    pub const VS: usize = 1;
    pub const VOEL: usize = 2;
    pub const VUEL: usize = 3;
    pub const EFD: usize = 4;
}

const PORTS: &[Port] = &[
    Port::input("v_term", PortInit::Needs, "compensated terminal voltage E_comp [pu]"),
    Port::input("vs", PortInit::Needs, "stabiliser signal V_S [pu]").optional(),
    Port::input("voel", PortInit::Needs, "over-excitation limiter signal (<= 0) [pu]").optional(),
    Port::input("vuel", PortInit::Needs, "under-excitation limiter signal [pu]").optional(),
    Port::output("efd", PortInit::Needs, "field voltage E_fd [pu]"),
];

/// SEXS exciter block.
#[derive(Debug, Clone, Default)]
pub struct Sexs {
    pub p: SexsParams,
    v_ref: f64,
    limit: NonWindup,
    /// 1/T_B and 1/T_E (refreshed at initialisation).
    inv_tb: f64,
    inv_te: f64,
}

impl Sexs {
    pub fn new(p: SexsParams) -> Self {
        Self { p, ..Default::default() }
    }

    /// Voltage reference found at initialisation [pu].
    pub fn v_ref(&self) -> f64 {
        self.v_ref
    }

    /// `(v_err, y_ll)` at the current point.
    #[inline(always)]
    fn lead_lag(&self, x: &[f64], io: &Io) -> (f64, f64) {
        let v_err = self.v_ref + self.p.v_ref_offset - io.get(port::V_TERM)
            + io.get(port::VS)
            + io.get(port::VOEL)
            + io.get(port::VUEL);
        (v_err, self.p.ta_tb * v_err + (1.0 - self.p.ta_tb) * x[0])
    }

    /// Unconstrained `dx_e/dt`.
    #[inline(always)]
    fn exciter_rate(&self, x: &[f64], io: &Io) -> f64 {
        (self.p.k * self.lead_lag(x, io).1 - x[1]) * self.inv_te
    }
}

impl Block for Sexs {
    block_common!();

    fn model(&self) -> &'static str {
        "SEXS"
    }
    fn ports(&self) -> &'static [Port] {
        PORTS
    }
    fn state_names(&self) -> &'static [&'static str] {
        &["x_ll", "x_e"]
    }
    fn validate(&self) -> Result<(), ModelError> {
        let p = &self.p;
        guard::non_negative("ta_tb", p.ta_tb)?;
        guard::positive("tb", p.tb)?;
        guard::positive("k", p.k)?;
        guard::positive("te", p.te)?;
        guard::finite("v_ref_offset", p.v_ref_offset)?;
        guard::greater("e_max", p.e_max, "e_min", p.e_min)
    }

    fn init(&mut self, _op: &InitPoint, x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        self.validate()?;
        let efd0 = io.get(port::EFD);
        if !(efd0 >= self.p.e_min && efd0 <= self.p.e_max) {
            return Err(ModelError::Init(format!(
                "SEXS: initial field voltage E_fd0 = {efd0:.4} pu lies outside [E_MIN, E_MAX] = [{}, {}]",
                self.p.e_min, self.p.e_max
            )));
        }
        x[1] = efd0;
        x[0] = efd0 / self.p.k;
        self.v_ref = io.get(port::V_TERM) - io.get(port::VS) - io.get(port::VOEL) - io.get(port::VUEL) + efd0 / self.p.k;
        self.limit = NonWindup::default();
        self.inv_tb = 1.0 / self.p.tb;
        self.inv_te = 1.0 / self.p.te;
        Ok(())
    }

    #[inline]
    fn outputs(&self, _t: f64, x: &[f64], io: &mut Io) {
        io.set(port::EFD, x[1].clamp(self.p.e_min, self.p.e_max));
    }

    #[inline]
    fn derivatives(&self, _t: f64, x: &[f64], io: &Io, dx: &mut [f64]) {
        let (v_err, y_ll) = self.lead_lag(x, io);
        dx[0] = (v_err - x[0]) * self.inv_tb;
        dx[1] = self.limit.derivative((self.p.k * y_ll - x[1]) * self.inv_te);
    }

    fn n_events(&self) -> usize {
        2
    }
    fn events(&self, x: &[f64], io: &Io, g: &mut [f64]) {
        self.limit.events(x[1], self.exciter_rate(x, io), self.p.e_min, self.p.e_max, g);
    }
    fn update_modes(&mut self, x: &mut [f64], io: &Io) -> bool {
        let f = self.exciter_rate(x, io);
        self.limit.update(&mut x[1], f, self.p.e_min, self.p.e_max)
    }
}
