//! TGOV1: steam turbine-governor (PSS/E `TGOV1`; `models.md` §9.3.2; OpenIPSL `TG/TGOV1.mo`;
//! cross-checked against ANDES 2.0 `TGOV1`, `tests/andes_models.rs`).
//!
//! States: valve position `x1` (non-windup in [V_MIN, V_MAX]), reheater lead-lag state `x2`.
//!
//! ```text
//! T1 dx1/dt = (P_ref + ΔP_ref − Δω)/R − x1        non-windup in [V_MIN, V_MAX]
//! T3 dx2/dt = x1 − x2                              (T3 = 0: lead-lag bypassed, T2 ignored)
//! P_m = x2 + (T2/T3)(x1 − x2) − D_t Δω             (the reheater (1 + sT2)/(1 + sT3) on x1)
//! ```
//!
//! Units: R in pu speed per pu power, V_MAX/V_MIN and P_m in pu power on the machine base, Δω in
//! pu, times in s. `P_ref` is a speed reference (pu); the offset `ΔP_ref` (nuisance) moves P_m by
//! `ΔP_ref/R` in steady state.
//!
//! **Limits.** The valve limit is a non-windup limit on the lag's state (IEEE 421.5-2016 Annex E
//! "non-windup lag"; PSS/E's TGOV1 draws the same): the state stops on the limit while its input
//! pushes outwards and leaves it as soon as the input pulls back, located by events
//! ([`NonWindup`]). ANDES's `LagAntiWindup` is the same.
//!
//! **Initialisation** (exact at the measured speed deviation Δω0): `x1 = x2 = P_m0 + D_t Δω0`,
//! `P_ref = R x1 + Δω0`. Refused, naming the limit, when `x1` lies outside [V_MIN, V_MAX]. T1 must
//! be positive (an algebraic valve has nothing for its limit to act on).

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port, PortInit};
use crate::dyr::DyrRecord;
use crate::models::exciter::blocks::LeadLag;
use crate::models::exciter::roles::ParamRole;
use crate::models::governor::roles::GovernorRoles;
use crate::models::limiter::NonWindup;
use crate::registry::{ModelInfo, Role};
use crate::sens::{Scalar, D};
use crate::{block_common, param_set};

/// The registry entry ([`crate::registry`]): name, role, `.dyr` record (PSS/E's CON order).
pub const MODEL: ModelInfo = ModelInfo {
    name: "TGOV1",
    role: Role::Governor,
    summary: "steam turbine-governor: droop, valve lag with limits, reheater lead-lag",
    reference: "PSS/E TGOV1 (models.md §9.3.2), ANDES TGOV1; non-windup valve limit",
    make: || Box::new(Tgov1::default()),
    dyr: Some(DyrRecord::cons(&["r", "t1", "v_max", "v_min", "t2", "t3", "dt"])),
};

param_set! {
    /// TGOV1 parameters (PSS/E CON order; machine base). Typical values: PSS/E's manual and
    /// the WECC model library's reheat steam unit.
    pub struct Tgov1Params {
        r: ("R", "pu", 0.05, (0.03, 0.1), "permanent droop R"),
        t1: ("T1", "s", 0.5, (0.05, 1.0), "valve (governor) time constant T1"),
        v_max: ("VMAX", "pu", 1.0, (0.9, 1.2), "maximum valve position V_MAX"),
        v_min: ("VMIN", "pu", 0.0, (0.0, 0.4), "minimum valve position V_MIN"),
        t2: ("T2", "s", 2.1, (0.0, 5.0), "reheater lead time constant T2"),
        t3: ("T3", "s", 7.0, (3.0, 12.0), "reheater lag time constant T3"),
        dt: ("Dt", "pu", 0.0, (0.0, 0.5), "turbine damping D_t"),
        p_ref_offset: ("dPref", "pu", 0.0, (-0.005, 0.005), "speed reference offset added after initialisation (nuisance; moves P_m by dPref/R)"),
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

const X1: usize = 0;
const X2: usize = 1;

/// The numbers the initialisation derives, on the number type `S`.
#[derive(Debug, Clone, Copy, Default)]
struct Consts<S = f64> {
    p_ref: S,
    inv_r: S,
    inv_t1: S,
    reheat: LeadLag<S>,
}

impl<S: Scalar> Consts<S> {
    fn new(p: &Tgov1Params<S>, p_ref: S) -> Self {
        Self {
            p_ref,
            inv_r: p.r.recip(),
            inv_t1: p.t1.recip(),
            reheat: LeadLag::new(p.t2, p.t3),
        }
    }
}

/// A TGOV1 block. See the module documentation.
#[derive(Debug, Clone, Default)]
pub struct Tgov1 {
    pub p: Tgov1Params,
    k: Consts,
    valve: NonWindup,
    /// The parameters and derived numbers on dual numbers, after [`Block::seed_dual`].
    dual: Option<(Tgov1Params<D>, Consts<D>)>,
}

/// The valve's unconstrained rate.
#[inline(always)]
fn valve_rate<S: Scalar>(p: &Tgov1Params<S>, k: &Consts<S>, x: &[S], speed: S) -> S {
    ((k.p_ref + p.p_ref_offset - speed) * k.inv_r - x[X1]) * k.inv_t1
}

#[inline(always)]
fn outputs<S: Scalar>(p: &Tgov1Params<S>, k: &Consts<S>, valve: &NonWindup, x: &[S], io: &mut Io<S>) {
    let x1 = valve.output(x[X1], p.v_min, p.v_max);
    let speed = io.get(port::SPEED);
    io.set(port::PM, k.reheat.output(x[X2], x1) - p.dt * speed);
}

#[inline(always)]
fn derivatives<S: Scalar>(
    p: &Tgov1Params<S>,
    k: &Consts<S>,
    valve: &NonWindup,
    x: &[S],
    io: &Io<S>,
    dx: &mut [S],
) {
    let speed = io.get(port::SPEED);
    dx[X1] = valve.derivative(valve_rate(p, k, x, speed));
    let x1 = valve.output(x[X1], p.v_min, p.v_max);
    dx[X2] = k.reheat.derivative(x[X2], x1);
}

impl Tgov1 {
    pub fn new(p: Tgov1Params) -> Self {
        Self {
            p,
            ..Default::default()
        }
    }
}

impl Block for Tgov1 {
    block_common!();

    fn model(&self) -> &'static str {
        MODEL.name
    }
    fn ports(&self) -> &'static [Port] {
        PORTS
    }
    fn state_names(&self) -> &'static [&'static str] {
        &["x1", "x2"]
    }
    fn validate(&self) -> Result<(), ModelError> {
        let p = &self.p;
        guard::positive("r", p.r)?;
        guard::positive("t1", p.t1)?;
        guard::non_negative("t2", p.t2)?;
        guard::non_negative("t3", p.t3)?;
        guard::non_negative("dt", p.dt)?;
        guard::finite("p_ref_offset", p.p_ref_offset)?;
        guard::greater("v_max", p.v_max, "v_min", p.v_min)
    }

    fn init(&mut self, _op: &InitPoint, x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        self.validate()?;
        let p = &self.p;
        let pm0 = io.get(port::PM);
        let w0 = io.get(port::SPEED);
        let x1 = pm0 + p.dt * w0;
        if !(x1 >= p.v_min && x1 <= p.v_max) {
            return Err(ModelError::Init(format!(
                "TGOV1: the valve position needed at t = 0, x1 = P_m0 + Dt·Δω0 = {x1:.4} pu, lies outside [VMIN, VMAX] = [{}, {}]",
                p.v_min, p.v_max
            )));
        }
        x[X1] = x1;
        x[X2] = x1;
        self.k = Consts::new(p, p.r * x1 + w0);
        self.valve = NonWindup::default();
        Ok(())
    }

    #[inline]
    fn outputs(&self, _t: f64, x: &[f64], io: &mut Io) {
        outputs(&self.p, &self.k, &self.valve, x, io);
    }

    #[inline]
    fn derivatives(&self, _t: f64, x: &[f64], io: &Io, dx: &mut [f64]) {
        derivatives(&self.p, &self.k, &self.valve, x, io, dx);
    }

    fn init_constants(&self) -> Vec<f64> {
        vec![self.k.p_ref]
    }

    fn seed_dual(&mut self, lanes: &[Option<usize>], consts: &[D]) -> bool {
        let p = self.p.lift_dual(lanes);
        let p_ref = consts.first().copied().unwrap_or(D::cst(self.k.p_ref));
        let k = Consts::new(&p, p_ref);
        self.dual = Some((p, k));
        true
    }

    fn outputs_dual(&self, _t: f64, x: &[D], io: &mut Io<D>) {
        if let Some((p, k)) = &self.dual {
            outputs(p, k, &self.valve, x, io);
        }
    }

    fn derivatives_dual(&self, _t: f64, x: &[D], io: &Io<D>, dx: &mut [D]) {
        if let Some((p, k)) = &self.dual {
            derivatives(p, k, &self.valve, x, io, dx);
        }
    }

    fn pin_dual(&self, x: &mut [D], _io: &Io<D>) {
        if let Some((p, _)) = &self.dual {
            self.valve.pin(&mut x[X1], p.v_min, p.v_max);
        }
    }

    fn n_events(&self) -> usize {
        2
    }
    fn events(&self, x: &[f64], io: &Io, g: &mut [f64]) {
        let f = valve_rate(&self.p, &self.k, x, io.get(port::SPEED));
        self.valve.events(x[X1], f, self.p.v_min, self.p.v_max, g);
    }
    fn events_dual(&self, x: &[D], io: &Io<D>, g: &mut [D]) -> bool {
        match &self.dual {
            Some((p, k)) => {
                let f = valve_rate(p, k, x, io.get(port::SPEED));
                self.valve.events(x[X1], f, p.v_min, p.v_max, g);
                true
            }
            None => false,
        }
    }
    fn update_modes(&mut self, x: &mut [f64], io: &Io) -> bool {
        let f = valve_rate(&self.p, &self.k, x, io.get(port::SPEED));
        let (lo, hi) = (self.p.v_min, self.p.v_max);
        self.valve.update(&mut x[X1], f, lo, hi)
    }

    fn governor_roles(&self) -> Option<GovernorRoles> {
        let mut r = GovernorRoles::none("not applicable to TGOV1");
        r.droop = ParamRole::param("r");
        r.servo_time_constant = ParamRole::param("t1");
        r.reheat_time_constant = ParamRole::param("t3");
        r.reheat_lead = ParamRole::param("t2");
        r.output_max = ParamRole::param("v_max");
        r.output_min = ParamRole::param("v_min");
        r.damping = ParamRole::param("dt");
        r.reference_offset = ParamRole::param("p_ref_offset");
        Some(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn init_with(p: Tgov1Params, pm0: f64, w0: f64) -> Result<(Tgov1, [f64; 2]), ModelError> {
        let mut b = Tgov1::new(p);
        let mut bus = [w0, pm0];
        let map = [0, 1];
        let mut x = [0.0; 2];
        let op = InitPoint {
            v_mag: 1.0,
            v_ang: 0.0,
            p: pm0,
            q: 0.0,
            speed_dev: w0,
        };
        b.init(&op, &mut x, &mut Io::new(&mut bus, &map))?;
        Ok((b, x))
    }

    #[test]
    fn starts_in_steady_state_at_an_off_nominal_speed() {
        let p = Tgov1Params {
            dt: 0.3,
            ..Default::default()
        };
        let (b, x) = init_with(p, 0.8, 0.002).unwrap();
        let mut bus = [0.002, 0.0];
        let map = [0, 1];
        let mut io = Io::new(&mut bus, &map);
        b.outputs(0.0, &x, &mut io);
        assert!((io.get(port::PM) - 0.8).abs() < 1e-15);
        let mut dx = [1.0; 2];
        b.derivatives(0.0, &x, &io, &mut dx);
        assert!(dx.iter().all(|d| d.abs() < 1e-15), "{dx:?}");
    }

    #[test]
    fn a_valve_limit_below_the_operating_point_is_refused_naming_it() {
        let p = Tgov1Params {
            v_max: 0.7,
            ..Default::default()
        };
        let e = init_with(p, 0.8, 0.0).unwrap_err().to_string();
        assert!(e.contains("TGOV1") && e.contains("VMAX") && e.contains("0.8000"), "{e}");
    }

    #[test]
    fn roles_name_tgov1_parameters() {
        let b = Tgov1::default();
        let r = b.governor_roles().unwrap();
        r.check(b.params()).unwrap();
        assert_eq!(r.identifiable(), vec!["r", "t1", "t3", "t2"]);
    }
}
