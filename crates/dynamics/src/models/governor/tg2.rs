//! TG2: simple turbine-governor, droop through a lead-lag and an output limit (ANDES 2.0 `TG2`,
//! the "turbine governor type II" of F. Milano's PSAT, *Power System Modelling and Scripting*,
//! 2010; cross-checked against ANDES 2.0 `TG2`, `tests/andes_models.rs`).
//!
//! State: the lead-lag's `x_ll`.
//!
//! ```text
//! u = −Δω/R                                                 (positive for an under-speed)
//! T2 dx_ll/dt = u − x_ll,   y_ll = x_ll + (T1/T2)(u − x_ll)     (T2 = 0: y_ll = u, state held)
//! P_m = clamp(P_ref + ΔP_ref + y_ll, P_MIN, P_MAX)
//! ```
//!
//! Units: R in pu speed per pu power, P_MAX/P_MIN, P_ref and P_m in pu power on the machine
//! base, Δω in pu, times in s. T1 is the lead (ANDES's "transient gain time"), T2 the lag (its
//! "governor time constant"): the transient droop is R·T2/T1. `P_ref` is a power reference
//! (ANDES's `pref0`), the offset `ΔP_ref` (nuisance) moves P_m by ΔP_ref in steady state.
//!
//! **Convention.** ANDES's and PSAT's: the lead-lag `(1 + sT1)/(1 + sT2)` on `−Δω/R`, added to
//! the power reference, then limited. ANDES's optional speed deadband (`dbl`, `dbu`, `dbc`, off
//! by default: `deadband = 0`) is left out: the droop is deadband-free (the library's
//! `speed_deadband` block puts one in front of any governor). PSS/E has no TG2 record and no
//! model of this structure (the nearest, IEEEG1 with K = 1/R, its lead-lag and one stage, adds
//! a rate-limited integrating valve), so TG2 has no `.dyr` layout: `dyr write` leaves it out
//! with a warning.
//!
//! **Limits.** P_MAX/P_MIN clamp the output (ANDES's `HardLimiter`, on by default): there is no
//! state behind the limit, so nothing winds up; the lead-lag keeps following the speed and the
//! output leaves the limit as soon as the unclamped sum returns inside.
//!
//! **Initialisation** (exact at the measured speed deviation Δω0): `x_ll = −Δω0/R`, `P_ref = P_m0
//! + Δω0/R`. Refused, naming the limit, when P_m0 lies outside [P_MIN, P_MAX].

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port, PortInit};
use crate::models::exciter::blocks::LeadLag;
use crate::models::exciter::roles::{LeadLagRole, ParamRole};
use crate::models::governor::roles::GovernorRoles;
use crate::models::limiter::clamp;
use crate::registry::{ModelInfo, Role};
use crate::sens::{Scalar, D};
use crate::{block_common, param_set};

/// The registry entry ([`crate::registry`]): name, role, no `.dyr` record (PSS/E has none).
pub const MODEL: ModelInfo = ModelInfo {
    name: "TG2",
    role: Role::Governor,
    summary: "simple turbine-governor: droop through a lead-lag, output limits",
    reference: "ANDES TG2 (PSAT turbine governor type II), deadband-free; output clamp",
    make: || Box::new(Tg2::default()),
    dyr: None,
};

param_set! {
    /// TG2 parameters (ANDES's order without its deadband; machine base). Typical values:
    /// ANDES's defaults (R 0.05, T1 0.2 s, T2 10 s, P_MIN 0) with P_MAX at the rating (ANDES
    /// leaves it open at 999).
    pub struct Tg2Params {
        r: ("R", "pu", 0.05, (0.03, 0.1), "permanent droop R"),
        p_max: ("pmax", "pu", 1.0, (0.9, 1.2), "maximum mechanical power P_MAX"),
        p_min: ("pmin", "pu", 0.0, (0.0, 0.4), "minimum mechanical power P_MIN"),
        t1: ("T1", "s", 0.2, (0.0, 5.0), "lead time constant T1 (transient gain time)"),
        t2: ("T2", "s", 10.0, (1.0, 20.0), "lag time constant T2 (governor time constant)"),
        p_ref_offset: ("dPref", "pu", 0.0, (-0.01, 0.01), "power reference offset added after initialisation (nuisance; moves P_m by dPref)"),
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

const X_LL: usize = 0;

/// The numbers the initialisation derives, on the number type `S`.
#[derive(Debug, Clone, Copy, Default)]
struct Consts<S = f64> {
    p_ref: S,
    inv_r: S,
    ll: LeadLag<S>,
}

impl<S: Scalar> Consts<S> {
    fn new(p: &Tg2Params<S>, p_ref: S) -> Self {
        Self {
            p_ref,
            inv_r: p.r.recip(),
            ll: LeadLag::new(p.t1, p.t2),
        }
    }
}

/// A TG2 block. See the module documentation.
#[derive(Debug, Clone, Default)]
pub struct Tg2 {
    pub p: Tg2Params,
    k: Consts,
    /// The parameters and derived numbers on dual numbers, after [`Block::seed_dual`].
    dual: Option<(Tg2Params<D>, Consts<D>)>,
}

#[inline(always)]
fn outputs<S: Scalar>(p: &Tg2Params<S>, k: &Consts<S>, x: &[S], io: &mut Io<S>) {
    let u = -io.get(port::SPEED) * k.inv_r;
    let pm = k.p_ref + p.p_ref_offset + k.ll.output(x[X_LL], u);
    io.set(port::PM, clamp(pm, p.p_min, p.p_max));
}

#[inline(always)]
fn derivatives<S: Scalar>(k: &Consts<S>, x: &[S], io: &Io<S>, dx: &mut [S]) {
    let u = -io.get(port::SPEED) * k.inv_r;
    dx[X_LL] = k.ll.derivative(x[X_LL], u);
}

impl Tg2 {
    pub fn new(p: Tg2Params) -> Self {
        Self {
            p,
            ..Default::default()
        }
    }
}

impl Block for Tg2 {
    block_common!();

    fn model(&self) -> &'static str {
        MODEL.name
    }
    fn ports(&self) -> &'static [Port] {
        PORTS
    }
    fn state_names(&self) -> &'static [&'static str] {
        &["x_ll"]
    }
    fn validate(&self) -> Result<(), ModelError> {
        let p = &self.p;
        guard::positive("r", p.r)?;
        guard::non_negative("t1", p.t1)?;
        guard::non_negative("t2", p.t2)?;
        guard::finite("p_ref_offset", p.p_ref_offset)?;
        guard::greater("p_max", p.p_max, "p_min", p.p_min)
    }

    fn init(&mut self, _op: &InitPoint, x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        self.validate()?;
        let p = &self.p;
        let pm0 = io.get(port::PM);
        let w0 = io.get(port::SPEED);
        if !(pm0 >= p.p_min && pm0 <= p.p_max) {
            return Err(ModelError::Init(format!(
                "TG2: the mechanical power at t = 0, P_m0 = {pm0:.4} pu, lies outside [PMIN, PMAX] = [{}, {}]",
                p.p_min, p.p_max
            )));
        }
        x[X_LL] = -w0 / p.r;
        self.k = Consts::new(p, pm0 + w0 / p.r);
        Ok(())
    }

    #[inline]
    fn outputs(&self, _t: f64, x: &[f64], io: &mut Io) {
        outputs(&self.p, &self.k, x, io);
    }

    #[inline]
    fn derivatives(&self, _t: f64, x: &[f64], io: &Io, dx: &mut [f64]) {
        derivatives(&self.k, x, io, dx);
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
            outputs(p, k, x, io);
        }
    }

    fn derivatives_dual(&self, _t: f64, x: &[D], io: &Io<D>, dx: &mut [D]) {
        if let Some((_, k)) = &self.dual {
            derivatives(k, x, io, dx);
        }
    }

    fn governor_roles(&self) -> Option<GovernorRoles> {
        let mut r = GovernorRoles::none("not applicable to TG2");
        r.droop = ParamRole::param("r");
        r.governor_lead_lag = LeadLagRole::LeadLag {
            lead: "t1".into(),
            lag: "t2".into(),
        };
        r.output_max = ParamRole::param("p_max");
        r.output_min = ParamRole::param("p_min");
        r.reference_offset = ParamRole::param("p_ref_offset");
        Some(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn init_with(p: Tg2Params, pm0: f64, w0: f64) -> Result<(Tg2, [f64; 1]), ModelError> {
        let mut b = Tg2::new(p);
        let mut bus = [w0, pm0];
        let map = [0, 1];
        let mut x = [0.0; 1];
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

    fn pm_and_rate(b: &Tg2, x: &[f64], w: f64) -> (f64, f64) {
        let mut bus = [w, 0.0];
        let map = [0, 1];
        let mut io = Io::new(&mut bus, &map);
        b.outputs(0.0, x, &mut io);
        let mut dx = [1.0];
        b.derivatives(0.0, x, &io, &mut dx);
        (io.get(port::PM), dx[0])
    }

    #[test]
    fn starts_in_steady_state_at_an_off_nominal_speed() {
        let (b, x) = init_with(Tg2Params::default(), 0.8, 0.002).unwrap();
        let (pm, dx) = pm_and_rate(&b, &x, 0.002);
        assert!((pm - 0.8).abs() < 1e-15 && dx.abs() < 1e-15, "{pm} {dx}");
    }

    #[test]
    fn a_speed_step_moves_p_m_by_the_transient_then_the_permanent_droop_within_the_limits() {
        let p = Tg2Params {
            t1: 2.0,
            t2: 4.0,
            p_max: 0.9,
            ..Default::default()
        };
        let (b, x) = init_with(p, 0.8, 0.0).unwrap();
        // A 0.1 % under-speed: at once (T1/T2)·0.001/R = 0.01, in steady state 0.001/R = 0.02.
        let (pm, _) = pm_and_rate(&b, &x, -0.001);
        assert!((pm - 0.81).abs() < 1e-12, "{pm}");
        let (pm, dx) = pm_and_rate(&b, &[0.02], -0.001);
        assert!((pm - 0.82).abs() < 1e-12 && dx.abs() < 1e-15, "{pm} {dx}");
        // A 1 % under-speed asks for 0.8 + 0.2: clamped at P_MAX.
        let (pm, _) = pm_and_rate(&b, &[0.2], -0.01);
        assert_eq!(pm, 0.9);
    }

    #[test]
    fn an_operating_point_outside_the_limits_is_refused_naming_it() {
        let p = Tg2Params {
            p_max: 0.7,
            ..Default::default()
        };
        let e = init_with(p, 0.8, 0.0).unwrap_err().to_string();
        assert!(e.contains("TG2") && e.contains("PMAX") && e.contains("0.8000"), "{e}");
        let p = Tg2Params {
            p_min: 0.85,
            ..Default::default()
        };
        let e = init_with(p, 0.8, 0.0).unwrap_err().to_string();
        assert!(e.contains("PMIN") && e.contains("0.85"), "{e}");
    }

    #[test]
    fn roles_name_tg2_parameters() {
        let b = Tg2::default();
        let r = b.governor_roles().unwrap();
        r.check(b.params()).unwrap();
        assert_eq!(r.identifiable(), vec!["r", "t1", "t2"]);
    }
}
