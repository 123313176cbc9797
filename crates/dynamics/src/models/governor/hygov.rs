//! HYGOV: hydro turbine-governor (`models.md` §9.3.1; OpenIPSL `TG/HYGOV.mo`).
//!
//! States: filter output `e`, desired gate `c` (non-windup in [G_MIN, G_MAX], rate-limited by
//! VELM), gate `g`, turbine flow `q`.
//!
//! ```text
//! T_f de/dt = n_ref + Δn_ref − Δω − R c − e
//! v = e/(r T_r) + (1/r) de/dt                        ((1 + sT_r)/(r T_r) acting on e)
//! dc/dt = clamp(v, −VELM, +VELM)                     (frozen at a gate limit while pushing outwards)
//! T_g dg/dt = c − g
//! h = (q/g)²,   T_w dq/dt = 1 − h                    (static head h0 = 1, as in PSS/E)
//! P_m = A_t h (q − q_NL) − D_turb g Δω
//! ```
//!
//! Initialisation at `Δω0` (§10.2): `q0 = (P_m0 + A_t q_NL)/(A_t − D_turb Δω0)`, `g0 = c0 = q0`,
//! `e0 = 0`, `n_ref = R c0 + Δω0`; infeasible when `g0 ∉ [G_MIN, G_MAX]`. The droop feeds back
//! the desired gate `c`, not the servo output `g`. `g` is floored at 1e-6 inside `h` so that a
//! wild calibration candidate produces a large but finite head rather than a division by zero.

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port, PortInit};
use crate::models::exciter::roles::ParamRole;
use crate::models::governor::roles::GovernorRoles;
use crate::models::limiter::{clamp, NonWindup};
use crate::sens::{Scalar, D};
use crate::{block_common, param_set};
use crate::dyr::DyrRecord;
use crate::registry::{ModelInfo, Role};

/// The registry entry ([`crate::registry`]): name, role, `.dyr` record.
pub const MODEL: ModelInfo = ModelInfo {
    name: "HYGOV",
    role: Role::Governor,
    summary: "hydro turbine-governor",
    reference: "PSS/E HYGOV as OpenIPSL, OPAL-RT and ANDES (models.md §9.3.1); non-windup gate, rate limit VELM",
    make: || Box::new(Hygov::default()),
    dyr: Some(DyrRecord::cons(&[
        "r_perm", "r_temp", "t_r", "t_f", "t_g", "velm", "g_max", "g_min", "t_w", "a_t", "d_turb",
        "q_nl",
    ])),
};

param_set! {
    /// HYGOV parameters (machine base).
    pub struct HygovParams {
        r_perm: ("R", "pu", 0.05, (0.01, 0.15), "permanent droop"),
        r_temp: ("r", "pu", 0.3, (0.2, 0.8), "temporary droop"),
        t_r: ("T_r", "s", 5.0, (3.0, 10.0), "governor (dashpot reset) time constant"),
        t_f: ("T_f", "s", 0.05, (0.03, 0.1), "filter time constant"),
        t_g: ("T_g", "s", 0.5, (0.2, 0.5), "gate servo time constant"),
        velm: ("VELM", "pu/s", 0.2, (0.005, 0.5), "gate velocity limit"),
        g_max: ("G_MAX", "pu", 1.0, (0.9, 1.0), "maximum gate opening"),
        g_min: ("G_MIN", "pu", 0.0, (0.0, 0.1), "minimum gate opening"),
        t_w: ("T_w", "s", 1.2, (0.3, 4.0), "water inertia time constant at rated flow"),
        a_t: ("A_t", "-", 1.2, (1.1, 1.3), "turbine gain 1/(g_FL − g_NL)"),
        d_turb: ("D_turb", "pu", 0.5, (0.0, 0.5), "turbine damping"),
        q_nl: ("q_NL", "pu", 0.08, (0.05, 0.15), "no-load flow"),
        n_ref_offset: ("dnref", "pu", 0.0, (-0.005, 0.005), "speed reference offset added after initialisation (nuisance)"),
    }
}

mod port {
    pub const SPEED: usize = 0;
    pub const PM: usize = 1;
}

const PORTS: &[Port] = &[
    Port::input_ft("speed", PortInit::Needs, "speed deviation Δω [pu]"),
    Port::output(
        "pm",
        PortInit::Needs,
        "mechanical power P_m [pu machine base]",
    ),
];

/// HYGOV block.
#[derive(Debug, Clone, Default)]
pub struct Hygov {
    pub p: HygovParams,
    n_ref: f64,
    gate_limit: NonWindup,
    /// 1/T_f, 1/(r T_r), 1/r, 1/T_g, 1/T_w (refreshed at initialisation).
    inv: [f64; 5],
    /// The parameters, n_ref and the inverses on dual numbers, after [`Block::seed_dual`].
    dual: Option<(HygovParams<D>, D, [D; 5])>,
}

/// 1/T_f, 1/(r T_r), 1/r, 1/T_g, 1/T_w.
fn inverses<S: Scalar>(p: &HygovParams<S>) -> [S; 5] {
    [
        p.t_f.recip(),
        (p.r_temp * p.t_r).recip(),
        p.r_temp.recip(),
        p.t_g.recip(),
        p.t_w.recip(),
    ]
}

/// `(de/dt, rate-limited dc/dt before the gate limit)`.
#[inline(always)]
fn rates<S: Scalar>(p: &HygovParams<S>, n_ref: S, inv: &[S; 5], x: &[S], speed: S) -> (S, S) {
    let [inv_tf, inv_rtr, inv_r, _, _] = *inv;
    let de = (n_ref + p.n_ref_offset - speed - p.r_perm * x[1] - x[0]) * inv_tf;
    let v = x[0] * inv_rtr + de * inv_r;
    (de, clamp(v, -p.velm, p.velm))
}

/// Turbine head for flow `q` and gate `g`.
#[inline(always)]
fn head<S: Scalar>(q: S, g: S) -> S {
    let r = q / g.max_s(S::cst(1e-6));
    r * r
}

#[inline(always)]
fn outputs<S: Scalar>(p: &HygovParams<S>, x: &[S], io: &mut Io<S>) {
    let h = head(x[3], x[2]);
    io.set(
        port::PM,
        p.a_t * h * (x[3] - p.q_nl) - p.d_turb * x[2] * io.get(port::SPEED),
    );
}

#[inline(always)]
fn derivatives<S: Scalar>(
    p: &HygovParams<S>,
    (n_ref, inv): (S, &[S; 5]),
    gate: &NonWindup,
    x: &[S],
    io: &Io<S>,
    dx: &mut [S],
) {
    let (de, dc) = rates(p, n_ref, inv, x, io.get(port::SPEED));
    dx[0] = de;
    dx[1] = gate.derivative(dc);
    dx[2] = (x[1] - x[2]) * inv[3];
    dx[3] = head(x[3], x[2]).rsub(1.0) * inv[4];
}

/// The gate limit's guards.
#[inline(always)]
fn guards<S: Scalar>(
    p: &HygovParams<S>,
    (n_ref, inv): (S, &[S; 5]),
    gate: &NonWindup,
    x: &[S],
    io: &Io<S>,
    g: &mut [S],
) {
    let (_, dc) = rates(p, n_ref, inv, x, io.get(port::SPEED));
    gate.events(x[1], dc, p.g_min, p.g_max, g);
}

impl Hygov {
    pub fn new(p: HygovParams) -> Self {
        Self {
            p,
            ..Default::default()
        }
    }

    /// `(de/dt, rate-limited dc/dt before the gate limit)`.
    #[inline(always)]
    fn rates(&self, x: &[f64], speed: f64) -> (f64, f64) {
        rates(&self.p, self.n_ref, &self.inv, x, speed)
    }
}

impl Block for Hygov {
    block_common!();

    fn model(&self) -> &'static str {
        "HYGOV"
    }
    fn ports(&self) -> &'static [Port] {
        PORTS
    }
    fn state_names(&self) -> &'static [&'static str] {
        &["e", "c", "g", "q"]
    }
    fn validate(&self) -> Result<(), ModelError> {
        let p = &self.p;
        guard::non_negative("r_perm", p.r_perm)?;
        guard::positive("r_temp", p.r_temp)?;
        guard::positive("t_r", p.t_r)?;
        guard::positive("t_f", p.t_f)?;
        guard::positive("t_g", p.t_g)?;
        guard::positive("velm", p.velm)?;
        guard::positive("t_w", p.t_w)?;
        guard::positive("a_t", p.a_t)?;
        guard::non_negative("d_turb", p.d_turb)?;
        guard::non_negative("q_nl", p.q_nl)?;
        guard::finite("n_ref_offset", p.n_ref_offset)?;
        guard::greater("g_max", p.g_max, "g_min", p.g_min)
    }

    fn init(&mut self, _op: &InitPoint, x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        self.validate()?;
        let p = &self.p;
        let pm0 = io.get(port::PM);
        let w0 = io.get(port::SPEED);
        let q0 = (pm0 + p.a_t * p.q_nl) / (p.a_t - p.d_turb * w0);
        if !(q0 > 0.0 && q0 >= p.g_min && q0 <= p.g_max) {
            return Err(ModelError::Init(format!(
                "HYGOV: initial gate g0 = {q0:.4} pu (for P_m0 = {pm0:.4} pu) lies outside [G_MIN, G_MAX] = [{}, {}]",
                p.g_min, p.g_max
            )));
        }
        x[0] = 0.0;
        x[1] = q0;
        x[2] = q0;
        x[3] = q0;
        self.n_ref = p.r_perm * q0 + w0;
        self.inv = inverses(p);
        self.gate_limit = NonWindup::default();
        Ok(())
    }

    #[inline]
    fn outputs(&self, _t: f64, x: &[f64], io: &mut Io) {
        outputs(&self.p, x, io);
    }

    #[inline]
    fn derivatives(&self, _t: f64, x: &[f64], io: &Io, dx: &mut [f64]) {
        let c = (self.n_ref, &self.inv);
        derivatives(&self.p, c, &self.gate_limit, x, io, dx);
    }

    fn init_constants(&self) -> Vec<f64> {
        vec![self.n_ref]
    }

    fn seed_dual(&mut self, lanes: &[Option<usize>], consts: &[D]) -> bool {
        let p = self.p.lift_dual(lanes);
        let n_ref = consts.first().copied().unwrap_or(D::cst(self.n_ref));
        let inv = inverses(&p);
        self.dual = Some((p, n_ref, inv));
        true
    }

    fn outputs_dual(&self, _t: f64, x: &[D], io: &mut Io<D>) {
        if let Some((p, _, _)) = &self.dual {
            outputs(p, x, io);
        }
    }

    fn derivatives_dual(&self, _t: f64, x: &[D], io: &Io<D>, dx: &mut [D]) {
        if let Some((p, n_ref, inv)) = &self.dual {
            derivatives(p, (*n_ref, inv), &self.gate_limit, x, io, dx);
        }
    }

    fn pin_dual(&self, x: &mut [D], _io: &Io<D>) {
        if let Some((p, _, _)) = &self.dual {
            self.gate_limit.pin(&mut x[1], p.g_min, p.g_max);
        }
    }

    fn n_events(&self) -> usize {
        2
    }
    fn events(&self, x: &[f64], io: &Io, g: &mut [f64]) {
        guards(&self.p, (self.n_ref, &self.inv), &self.gate_limit, x, io, g);
    }
    fn events_dual(&self, x: &[D], io: &Io<D>, g: &mut [D]) -> bool {
        match &self.dual {
            Some((p, n_ref, inv)) => {
                guards(p, (*n_ref, inv), &self.gate_limit, x, io, g);
                true
            }
            None => false,
        }
    }
    fn update_modes(&mut self, x: &mut [f64], io: &Io) -> bool {
        let (_, dc) = self.rates(x, io.get(port::SPEED));
        let (lo, hi) = (self.p.g_min, self.p.g_max);
        self.gate_limit.update(&mut x[1], dc, lo, hi)
    }

    fn governor_roles(&self) -> Option<GovernorRoles> {
        let mut r = GovernorRoles::none("not applicable to HYGOV");
        r.droop = ParamRole::param("r_perm");
        r.transient_droop = ParamRole::param("r_temp");
        r.reset_time_constant = ParamRole::param("t_r");
        r.servo_time_constant = ParamRole::param("t_g");
        r.turbine_time_constant = ParamRole::param("t_w");
        r.output_max = ParamRole::param("g_max");
        r.output_min = ParamRole::param("g_min");
        r.rate_max = ParamRole::param("velm");
        r.rate_min = ParamRole::param("velm");
        r.damping = ParamRole::param("d_turb");
        r.reference_offset = ParamRole::param("n_ref_offset");
        Some(r)
    }
}
