//! STAB3: power-sensitive stabiliser (`models.md` §9.2.1; OpenIPSL `PSS/STAB3.mo`).
//!
//! States: transducer `P_f`, low-pass `x2`, washout `x3`. `P_REF` is frozen at the initial
//! electrical power (as in OpenIPSL and OPAL-RT).
//!
//! ```text
//! T_t dP_f/dt = P_e − P_f                 (P_f = P_e algebraically when T_t = 0)
//! T_X1 dx2/dt = (P_f − P_REF) − x2
//! T_X2 dx3/dt = x2 − x3
//! V_S = clamp(−(K_X/T_X2)(x2 − x3), −V_LIM, +V_LIM)       (−K_X s/(1 + s T_X2) on the low-passed ΔP)
//! ```

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port, PortInit};
use crate::models::limiter::clamp;
use crate::models::exciter::roles::{LeadLagRole, ParamRole};
use crate::models::pss::roles::PssRoles;
use crate::sens::{Scalar, D};
use crate::{block_common, param_set};
use crate::dyr::DyrRecord;
use crate::registry::{ModelInfo, Role};

/// The registry entry ([`crate::registry`]): name, role, `.dyr` record.
pub const MODEL: ModelInfo = ModelInfo {
    name: "STAB3",
    role: Role::Pss,
    summary: "power-input stabiliser (PSS/E STAB3)",
    reference: "PSS/E STAB3 as OpenIPSL (models.md §9.2.1); P_REF frozen at the initial power",
    make: || Box::new(Stab3::default()),
    dyr: Some(DyrRecord::cons(&["t_t", "t_x1", "t_x2", "k_x", "v_lim"])),
};

param_set! {
    /// STAB3 parameters.
    pub struct Stab3Params {
        t_t: ("T_t", "s", 0.1, (0.0, 0.2), "power transducer time constant (0 = none)"),
        t_x1: ("T_X1", "s", 0.04, (0.03, 0.05), "low-pass time constant"),
        t_x2: ("T_X2", "s", 3.0, (0.5, 8.0), "washout time constant"),
        k_x: ("K_X", "s", 1.0, (0.2, 5.0), "derivative gain (washout numerator time constant)"),
        v_lim: ("V_LIM", "pu", 0.1, (0.05, 0.1), "symmetric output limit"),
    }
}

mod port {
    pub const PE: usize = 0;
    pub const VS: usize = 1;
}

const PORTS: &[Port] = &[
    Port::input(
        "pe",
        PortInit::Needs,
        "electrical power P_e [pu machine base]",
    ),
    Port::output("vs", PortInit::Gives, "stabiliser output V_S [pu]"),
];

/// Below this a transducer time constant counts as absent.
const T_MIN: f64 = 1e-9;

/// STAB3 block.
#[derive(Debug, Clone, Default)]
pub struct Stab3 {
    pub p: Stab3Params,
    p_ref: f64,
    /// The parameters and P_REF on dual numbers, after [`Block::seed_dual`].
    dual: Option<(Stab3Params<D>, D)>,
}

impl Stab3 {
    pub fn new(p: Stab3Params) -> Self {
        Self {
            p,
            p_ref: 0.0,
            dual: None,
        }
    }
}

#[inline(always)]
fn outputs<S: Scalar>(p: &Stab3Params<S>, x: &[S], io: &mut Io<S>) {
    let vs = -(p.k_x / p.t_x2) * (x[1] - x[2]);
    io.set(port::VS, clamp(vs, -p.v_lim, p.v_lim));
}

#[inline(always)]
fn derivatives<S: Scalar>(p: &Stab3Params<S>, p_ref: S, x: &[S], io: &Io<S>, dx: &mut [S]) {
    let pe = io.get(port::PE);
    let p_f = if p.t_t.val() > T_MIN {
        dx[0] = (pe - x[0]) / p.t_t;
        x[0]
    } else {
        dx[0] = S::cst(0.0);
        pe
    };
    dx[1] = (p_f - p_ref - x[1]) / p.t_x1;
    dx[2] = (x[1] - x[2]) / p.t_x2;
}

impl Block for Stab3 {
    block_common!();

    fn pss_roles(&self) -> Option<PssRoles> {
        let mut r = PssRoles::none("not applicable to STAB3");
        r.gain = ParamRole::param("k_x");
        r.washout = ParamRole::param("t_x2");
        r.input_filter = ParamRole::param("t_x1");
        r.output_max = ParamRole::param("v_lim");
        r.output_min = ParamRole::param("v_lim");
        r.lead_lag_1 = LeadLagRole::NotApplicable("STAB3 has no lead-lag".into());
        r.lead_lag_2 = LeadLagRole::NotApplicable("STAB3 has no lead-lag".into());
        Some(r)
    }

    fn model(&self) -> &'static str {
        "STAB3"
    }
    fn ports(&self) -> &'static [Port] {
        PORTS
    }
    fn state_names(&self) -> &'static [&'static str] {
        &["p_f", "x_lowpass", "x_washout"]
    }
    fn validate(&self) -> Result<(), ModelError> {
        guard::non_negative("t_t", self.p.t_t)?;
        guard::positive("t_x1", self.p.t_x1)?;
        guard::positive("t_x2", self.p.t_x2)?;
        guard::finite("k_x", self.p.k_x)?;
        guard::positive("v_lim", self.p.v_lim)
    }
    fn init(&mut self, _op: &InitPoint, x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        self.validate()?;
        let pe0 = io.get(port::PE);
        self.p_ref = pe0;
        x[0] = pe0;
        x[1] = 0.0;
        x[2] = 0.0;
        io.set(port::VS, 0.0);
        Ok(())
    }
    #[inline]
    fn outputs(&self, _t: f64, x: &[f64], io: &mut Io) {
        outputs(&self.p, x, io);
    }
    #[inline]
    fn derivatives(&self, _t: f64, x: &[f64], io: &Io, dx: &mut [f64]) {
        derivatives(&self.p, self.p_ref, x, io, dx);
    }
    fn init_constants(&self) -> Vec<f64> {
        vec![self.p_ref]
    }
    fn seed_dual(&mut self, lanes: &[Option<usize>], consts: &[D]) -> bool {
        let p = self.p.lift_dual(lanes);
        let p_ref = consts.first().copied().unwrap_or(D::cst(self.p_ref));
        self.dual = Some((p, p_ref));
        true
    }
    fn outputs_dual(&self, _t: f64, x: &[D], io: &mut Io<D>) {
        if let Some((p, _)) = &self.dual {
            outputs(p, x, io);
        }
    }
    fn derivatives_dual(&self, _t: f64, x: &[D], io: &Io<D>, dx: &mut [D]) {
        if let Some((p, p_ref)) = &self.dual {
            derivatives(p, *p_ref, x, io, dx);
        }
    }
}
