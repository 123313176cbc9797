//! IEEEG1: IEEE type 1 steam turbine-governor (PSS/E `IEEEG1`; `models.md` §9.3.3; IEEE
//! Committee report "Dynamic models for steam and hydro turbines", 1973; cross-checked against
//! ANDES 2.0 `IEEEG1`, `tests/andes_models.rs`).
//!
//! States: speed lead-lag `x_ll`, valve position `GV` (rate limited, non-windup in
//! [P_MIN, P_MAX]), the four turbine stages `x4` … `x7`.
//!
//! ```text
//! T1 dx_ll/dt = Δω − x_ll,   y_ll = K (x_ll + (T2/T1)(Δω − x_ll))      (T1 = 0: y_ll = K Δω)
//! dGV/dt = clamp((P0 + ΔP0 − y_ll − GV)/T3, U_C, U_O)                   non-windup in [P_MIN, P_MAX]
//! T4 dx4/dt = GV − x4,  T5 dx5/dt = x4 − x5,  T6 dx6/dt = x5 − x6,  T7 dx7/dt = x6 − x7
//!                                                  (T = 0: the stage passes its input, state held)
//! P_m = (K1 + K2) x4 + (K3 + K4) x5 + (K5 + K6) x6 + (K7 + K8) x7
//! ```
//!
//! Units: K in pu power per pu speed (= 1/R), U_O/U_C in pu/s, P_MAX/P_MIN and P_m in pu power on
//! the machine base, times in s. The unit is one machine: the high-pressure (K1, K3, K5, K7) and
//! low-pressure (K2, K4, K6, K8) shares drive the same shaft (a tandem-compound unit, PSS/E with
//! `JBUS = 0`); a cross-compound second machine (`JBUS ≠ 0`) is refused by the `.dyr` reader. The
//! fractions are used as given (PSS/E; ANDES normalises them to sum 1, the same when they do).
//!
//! **Limits.** The valve rate limit `[U_C, U_O]` is a clamp on the integrator's input; the
//! position limit is a non-windup limit on the integrator's state (IEEE 421.5-2016 Annex E
//! "non-windup integrator", as PSS/E and ANDES's `IntegratorAntiWindup`): the valve stops on a
//! limit while its rate pushes outwards and leaves as soon as the rate reverses, located by
//! events ([`NonWindup`]).
//!
//! **Initialisation** (exact at the measured speed deviation Δω0): `GV = x4 … x7 = P_m0/ΣK`,
//! `x_ll = Δω0`, `P0 = GV + K Δω0` (the valve's input zero). Refused, naming the limit, when GV
//! lies outside [P_MIN, P_MAX]; the fractions must sum to more than 0 and the rate limits must
//! hold 0 (U_C ≤ 0 ≤ U_O), else no steady state exists.

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port, PortInit};
use crate::dyr::{DyrRecord, Icon};
use crate::models::exciter::blocks::{Lag, LeadLag};
use crate::models::exciter::roles::{LeadLagRole, ParamRole};
use crate::models::governor::roles::GovernorRoles;
use crate::models::limiter::{clamp, NonWindup};
use crate::registry::{ModelInfo, Role};
use crate::sens::{Scalar, D};
use crate::{block_common, param_set};

/// The registry entry ([`crate::registry`]): name, role, `.dyr` record (PSS/E's ICON and CON
/// order).
pub const MODEL: ModelInfo = ModelInfo {
    name: "IEEEG1",
    role: Role::Governor,
    summary: "IEEE type 1 steam turbine-governor: speed lead-lag, rate-limited valve, four turbine stages",
    reference: "IEEE 1973 type 1 as PSS/E IEEEG1 (models.md §9.3.3), ANDES IEEEG1; non-windup valve, rate clamp",
    make: || Box::new(Ieeeg1::default()),
    dyr: Some(DyrRecord {
        icons: &[
            Icon::Zero {
                name: "JBUS",
                meaning: "bus of a second (low-pressure) machine",
            },
            Icon::Ignored {
                name: "M",
                meaning: "machine id of the second machine (unused with JBUS = 0)",
            },
        ],
        cons: &[
            "k", "t1", "t2", "t3", "u_o", "u_c", "p_max", "p_min", "t4", "k1", "k2", "t5", "k3",
            "k4", "t6", "k5", "k6", "t7", "k7", "k8",
        ],
        machine: None,
    }),
};

param_set! {
    /// IEEEG1 parameters (PSS/E CON order; machine base). Typical values: the IEEE committee
    /// report's tandem-compound single-reheat unit (T4 0.3 s, T5 7 s, T6 0.5 s, shares 0.3,
    /// 0.4, 0.3) with a 5 % droop.
    pub struct Ieeeg1Params {
        k: ("K", "pu", 20.0, (10.0, 33.0), "governor gain K = 1/R"),
        t1: ("T1", "s", 0.1, (0.0, 1.0), "speed lead-lag lag time constant T1"),
        t2: ("T2", "s", 0.0, (0.0, 1.0), "speed lead-lag lead time constant T2"),
        t3: ("T3", "s", 0.1, (0.04, 1.0), "valve servo time constant T3"),
        u_o: ("Uo", "pu/s", 0.5, (0.05, 1.0), "maximum valve opening rate U_O"),
        u_c: ("Uc", "pu/s", -0.5, (-1.0, -0.05), "maximum valve closing rate U_C (negative)"),
        p_max: ("PMAX", "pu", 1.0, (0.9, 1.2), "maximum valve position P_MAX"),
        p_min: ("PMIN", "pu", 0.0, (0.0, 0.5), "minimum valve position P_MIN"),
        t4: ("T4", "s", 0.3, (0.1, 0.6), "steam chest time constant T4"),
        k1: ("K1", "-", 0.3, (0.0, 1.0), "high-pressure share after T4"),
        k2: ("K2", "-", 0.0, (0.0, 1.0), "low-pressure share after T4"),
        t5: ("T5", "s", 7.0, (3.0, 12.0), "reheater time constant T5"),
        k3: ("K3", "-", 0.4, (0.0, 0.6), "high-pressure share after T5"),
        k4: ("K4", "-", 0.0, (0.0, 1.0), "low-pressure share after T5"),
        t6: ("T6", "s", 0.5, (0.0, 1.0), "crossover time constant T6"),
        k5: ("K5", "-", 0.3, (0.0, 0.6), "high-pressure share after T6"),
        k6: ("K6", "-", 0.0, (0.0, 1.0), "low-pressure share after T6"),
        t7: ("T7", "s", 0.0, (0.0, 1.0), "second reheater (or double crossover) time constant T7"),
        k7: ("K7", "-", 0.0, (0.0, 0.3), "high-pressure share after T7"),
        k8: ("K8", "-", 0.0, (0.0, 0.3), "low-pressure share after T7"),
        p0_offset: ("dP0", "pu", 0.0, (-0.01, 0.01), "load reference offset added after initialisation (nuisance)"),
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
const GV: usize = 1;
/// The first of the four turbine stages (x4 … x7).
const X4: usize = 2;

/// The numbers the initialisation derives, on the number type `S`.
#[derive(Debug, Clone, Copy, Default)]
struct Consts<S = f64> {
    p0: S,
    speed_ll: LeadLag<S>,
    inv_t3: S,
    stages: [Lag<S>; 4],
}

impl<S: Scalar> Consts<S> {
    fn new(p: &Ieeeg1Params<S>, p0: S) -> Self {
        Self {
            p0,
            speed_ll: LeadLag::new(p.t2, p.t1),
            inv_t3: p.t3.recip(),
            stages: [Lag::new(p.t4), Lag::new(p.t5), Lag::new(p.t6), Lag::new(p.t7)],
        }
    }
}

/// An IEEEG1 block. See the module documentation.
#[derive(Debug, Clone, Default)]
pub struct Ieeeg1 {
    pub p: Ieeeg1Params,
    k: Consts,
    valve: NonWindup,
    /// The parameters and derived numbers on dual numbers, after [`Block::seed_dual`].
    dual: Option<(Ieeeg1Params<D>, Consts<D>)>,
}

/// The valve's rate-limited velocity (before the position limit).
#[inline(always)]
fn valve_rate<S: Scalar>(p: &Ieeeg1Params<S>, k: &Consts<S>, x: &[S], speed: S) -> S {
    let y_ll = k.speed_ll.output(x[X_LL], speed) * p.k;
    let u = (k.p0 + p.p0_offset - y_ll - x[GV]) * k.inv_t3;
    clamp(u, p.u_c, p.u_o)
}

/// The four stages' outputs (a stage with T = 0 passes its input).
#[inline(always)]
fn stage_outputs<S: Scalar>(k: &Consts<S>, valve: &NonWindup, p: &Ieeeg1Params<S>, x: &[S]) -> [S; 4] {
    let mut y = [S::cst(0.0); 4];
    let mut u = valve.output(x[GV], p.p_min, p.p_max);
    for i in 0..4 {
        y[i] = k.stages[i].output(x[X4 + i], u);
        u = y[i];
    }
    y
}

#[inline(always)]
fn outputs<S: Scalar>(p: &Ieeeg1Params<S>, k: &Consts<S>, valve: &NonWindup, x: &[S], io: &mut Io<S>) {
    let y = stage_outputs(k, valve, p, x);
    let pm = (p.k1 + p.k2) * y[0] + (p.k3 + p.k4) * y[1] + (p.k5 + p.k6) * y[2] + (p.k7 + p.k8) * y[3];
    io.set(port::PM, pm);
}

#[inline(always)]
fn derivatives<S: Scalar>(
    p: &Ieeeg1Params<S>,
    k: &Consts<S>,
    valve: &NonWindup,
    x: &[S],
    io: &Io<S>,
    dx: &mut [S],
) {
    let speed = io.get(port::SPEED);
    dx[X_LL] = k.speed_ll.derivative(x[X_LL], speed);
    dx[GV] = valve.derivative(valve_rate(p, k, x, speed));
    let mut u = valve.output(x[GV], p.p_min, p.p_max);
    for i in 0..4 {
        dx[X4 + i] = k.stages[i].derivative(x[X4 + i], u);
        u = k.stages[i].output(x[X4 + i], u);
    }
}

impl Ieeeg1 {
    pub fn new(p: Ieeeg1Params) -> Self {
        Self {
            p,
            ..Default::default()
        }
    }
}

impl Block for Ieeeg1 {
    block_common!();

    fn model(&self) -> &'static str {
        MODEL.name
    }
    fn ports(&self) -> &'static [Port] {
        PORTS
    }
    fn state_names(&self) -> &'static [&'static str] {
        &["x_ll", "gv", "x4", "x5", "x6", "x7"]
    }
    fn validate(&self) -> Result<(), ModelError> {
        let p = &self.p;
        guard::finite("k", p.k)?;
        for (n, v) in [
            ("t1", p.t1),
            ("t2", p.t2),
            ("t4", p.t4),
            ("t5", p.t5),
            ("t6", p.t6),
            ("t7", p.t7),
        ] {
            guard::non_negative(n, v)?;
        }
        guard::positive("t3", p.t3)?;
        guard::non_negative("u_o", p.u_o)?;
        if !(p.u_c <= 0.0) {
            return Err(ModelError::param(
                "u_c",
                format!(
                    "the closing rate must be <= 0 (got {}): no steady state otherwise",
                    p.u_c
                ),
            ));
        }
        guard::greater("u_o", p.u_o, "u_c", p.u_c)?;
        guard::greater("p_max", p.p_max, "p_min", p.p_min)?;
        for (n, v) in [
            ("k1", p.k1),
            ("k2", p.k2),
            ("k3", p.k3),
            ("k4", p.k4),
            ("k5", p.k5),
            ("k6", p.k6),
            ("k7", p.k7),
            ("k8", p.k8),
        ] {
            guard::finite(n, v)?;
        }
        guard::finite("p0_offset", p.p0_offset)?;
        let sum = p.k1 + p.k2 + p.k3 + p.k4 + p.k5 + p.k6 + p.k7 + p.k8;
        if !(sum > 0.0) {
            return Err(ModelError::param(
                "k1",
                format!("the turbine shares K1 … K8 sum to {sum}: P_m could not follow the valve"),
            ));
        }
        Ok(())
    }

    fn init(&mut self, _op: &InitPoint, x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        self.validate()?;
        let p = &self.p;
        let pm0 = io.get(port::PM);
        let w0 = io.get(port::SPEED);
        let sum = p.k1 + p.k2 + p.k3 + p.k4 + p.k5 + p.k6 + p.k7 + p.k8;
        let gv = pm0 / sum;
        if !(gv >= p.p_min && gv <= p.p_max) {
            return Err(ModelError::Init(format!(
                "IEEEG1: the valve position needed at t = 0, GV = P_m0/ΣK = {gv:.4} pu (P_m0 = {pm0:.4}, ΣK = {sum}), lies outside [PMIN, PMAX] = [{}, {}]",
                p.p_min, p.p_max
            )));
        }
        x[X_LL] = w0;
        x[GV] = gv;
        x[X4..X4 + 4].fill(gv);
        self.k = Consts::new(p, gv + p.k * w0);
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
        vec![self.k.p0]
    }

    fn seed_dual(&mut self, lanes: &[Option<usize>], consts: &[D]) -> bool {
        let p = self.p.lift_dual(lanes);
        let p0 = consts.first().copied().unwrap_or(D::cst(self.k.p0));
        let k = Consts::new(&p, p0);
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
            self.valve.pin(&mut x[GV], p.p_min, p.p_max);
        }
    }

    fn n_events(&self) -> usize {
        2
    }
    fn events(&self, x: &[f64], io: &Io, g: &mut [f64]) {
        let f = valve_rate(&self.p, &self.k, x, io.get(port::SPEED));
        self.valve.events(x[GV], f, self.p.p_min, self.p.p_max, g);
    }
    fn events_dual(&self, x: &[D], io: &Io<D>, g: &mut [D]) -> bool {
        match &self.dual {
            Some((p, k)) => {
                let f = valve_rate(p, k, x, io.get(port::SPEED));
                self.valve.events(x[GV], f, p.p_min, p.p_max, g);
                true
            }
            None => false,
        }
    }
    fn update_modes(&mut self, x: &mut [f64], io: &Io) -> bool {
        let f = valve_rate(&self.p, &self.k, x, io.get(port::SPEED));
        let (lo, hi) = (self.p.p_min, self.p.p_max);
        self.valve.update(&mut x[GV], f, lo, hi)
    }

    fn governor_roles(&self) -> Option<GovernorRoles> {
        let mut r = GovernorRoles::none("not applicable to IEEEG1");
        r.speed_gain = ParamRole::param("k");
        r.droop = ParamRole::none("IEEEG1 gives the droop as its gain K = 1/R (speed_gain)");
        r.governor_lead_lag = LeadLagRole::LeadLag {
            lead: "t2".into(),
            lag: "t1".into(),
        };
        r.servo_time_constant = ParamRole::param("t3");
        r.turbine_time_constant = ParamRole::param("t4");
        r.reheat_time_constant = ParamRole::param("t5");
        r.output_max = ParamRole::param("p_max");
        r.output_min = ParamRole::param("p_min");
        r.rate_max = ParamRole::param("u_o");
        r.rate_min = ParamRole::param("u_c");
        r.reference_offset = ParamRole::param("p0_offset");
        Some(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn init_with(p: Ieeeg1Params, pm0: f64, w0: f64) -> Result<(Ieeeg1, [f64; 6]), ModelError> {
        let mut b = Ieeeg1::new(p);
        let mut bus = [w0, pm0];
        let map = [0, 1];
        let mut x = [0.0; 6];
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
    fn starts_in_steady_state_with_shares_not_summing_to_one() {
        let p = Ieeeg1Params {
            k2: 0.1,
            t2: 0.3,
            t7: 0.2,
            k8: 0.05,
            ..Default::default()
        };
        let (b, x) = init_with(p, 0.8, -0.001).unwrap();
        let mut bus = [-0.001, 0.0];
        let map = [0, 1];
        let mut io = Io::new(&mut bus, &map);
        b.outputs(0.0, &x, &mut io);
        assert!((io.get(port::PM) - 0.8).abs() < 1e-15, "{}", io.get(port::PM));
        let mut dx = [1.0; 6];
        b.derivatives(0.0, &x, &io, &mut dx);
        assert!(dx.iter().all(|d| d.abs() < 1e-15), "{dx:?}");
        // ΣK = 1.15: the valve sits at P_m0/1.15.
        assert!((x[GV] - 0.8 / 1.15).abs() < 1e-15);
    }

    #[test]
    fn impossible_operating_points_are_refused_naming_the_cause() {
        let p = Ieeeg1Params {
            p_max: 0.7,
            ..Default::default()
        };
        let e = init_with(p, 0.8, 0.0).unwrap_err().to_string();
        assert!(e.contains("IEEEG1") && e.contains("PMAX") && e.contains("0.8000"), "{e}");
        let p = Ieeeg1Params {
            u_c: 0.1,
            ..Default::default()
        };
        let e = init_with(p, 0.8, 0.0).unwrap_err().to_string();
        assert!(e.contains("u_c") && e.contains("steady state"), "{e}");
    }

    #[test]
    fn roles_name_ieeeg1_parameters() {
        let b = Ieeeg1::default();
        let r = b.governor_roles().unwrap();
        r.check(b.params()).unwrap();
        assert_eq!(r.identifiable(), vec!["k", "t3", "t4", "t5", "t2", "t1"]);
    }
}
