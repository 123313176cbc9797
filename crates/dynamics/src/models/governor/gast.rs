//! GAST: gas turbine-governor (PSS/E `GAST`, PSS/E Model Library; cross-checked against ANDES
//! 2.0 `GAST`, `tests/andes_models.rs`).
//!
//! States: fuel valve `x1` (non-windup in [V_MIN, V_MAX]), turbine (fuel flow) lag `x2`, load
//! limit (exhaust temperature) lag `x3`.
//!
//! ```text
//! u_s = (P_ref + ΔP_ref − Δω)/R                      the droop's demand
//! u_t = A_T + K_T (A_T − x3)                          the load limit's demand
//! T1 dx1/dt = min(u_s, u_t) − x1                      low-value gate; non-windup in [V_MIN, V_MAX]
//! T2 dx2/dt = x1 − x2                                 (T2 = 0: passes x1, state held)
//! T3 dx3/dt = x2 − x3                                 (T3 = 0: passes x2, state held)
//! P_m = x2 − D_turb Δω
//! ```
//!
//! Units: R in pu speed per pu power, A_T, V_MAX, V_MIN and P_m in pu power on the machine
//! base, K_T in pu per pu, D_turb in pu power per pu speed, Δω in pu, times in s. `P_ref` is a
//! speed reference (pu, as TGOV1's); the offset `ΔP_ref` (nuisance) moves the droop's demand by
//! `ΔP_ref/R`.
//!
//! **Limits.** The valve limit is a non-windup limit on the lag's state (IEEE 421.5-2016 Annex E
//! "non-windup lag"; PSS/E's GAST draws V_MAX/V_MIN on the `1/(1 + sT1)` block, ANDES's
//! `LagAntiWindup`): the valve stops on a limit while its input pushes outwards and leaves as soon
//! as it pulls back, located by events ([`NonWindup`]). The low-value gate is algebraic (the
//! smaller demand drives the valve, the other has no state to wind up); the load limit
//! `A_T + K_T (A_T − x3)` takes over when the fuel flow, seen through the temperature lag T3,
//! exceeds A_T, and holds x2 at A_T in steady state.
//!
//! **Initialisation** (exact at the measured speed deviation Δω0): `x1 = x2 = x3 = P_m0 +
//! D_turb Δω0`, `P_ref = R x1 + Δω0` (the droop's demand equal to x1). Refused, naming the limit,
//! when x1 lies outside [V_MIN, V_MAX], or above the ambient temperature load limit A_T (the load
//! limit's demand would then be below x1 and close the valve). T1 must be positive.

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port, PortInit};
use crate::dyr::DyrRecord;
use crate::models::exciter::blocks::Lag;
use crate::models::exciter::roles::ParamRole;
use crate::models::governor::roles::GovernorRoles;
use crate::models::limiter::NonWindup;
use crate::registry::{ModelInfo, Role};
use crate::sens::{Scalar, D};
use crate::{block_common, param_set};

/// The registry entry ([`crate::registry`]): name, role, `.dyr` record (PSS/E's CON order).
pub const MODEL: ModelInfo = ModelInfo {
    name: "GAST",
    role: Role::Governor,
    summary: "gas turbine-governor: droop, low-value gate with the temperature load limit, fuel valve and turbine lags",
    reference: "PSS/E GAST, ANDES GAST; non-windup valve limit, algebraic low-value gate",
    make: || Box::new(Gast::default()),
    dyr: Some(DyrRecord::cons(&[
        "r", "t1", "t2", "t3", "a_t", "k_t", "v_max", "v_min", "d_turb",
    ])),
};

param_set! {
    /// GAST parameters (PSS/E CON order; machine base). Typical values: the PSS/E manual's
    /// typical GAST data (R 0.05, T1 0.4 s, T2 0.1 s, T3 3 s, A_T 1, K_T 2, V_MAX 1, V_MIN 0).
    pub struct GastParams {
        r: ("R", "pu", 0.05, (0.03, 0.1), "permanent droop R"),
        t1: ("T1", "s", 0.4, (0.05, 1.0), "fuel valve time constant T1"),
        t2: ("T2", "s", 0.1, (0.05, 0.5), "turbine (fuel flow) time constant T2"),
        t3: ("T3", "s", 3.0, (1.0, 5.0), "load limit (exhaust temperature) time constant T3"),
        a_t: ("AT", "pu", 1.0, (0.8, 1.1), "ambient temperature load limit A_T"),
        k_t: ("KT", "pu", 2.0, (1.0, 4.0), "load limit feedback gain K_T"),
        v_max: ("VMAX", "pu", 1.0, (0.9, 1.2), "maximum fuel valve position V_MAX"),
        v_min: ("VMIN", "pu", 0.0, (-0.1, 0.3), "minimum fuel valve position V_MIN"),
        d_turb: ("Dt", "pu", 0.0, (0.0, 0.5), "turbine damping D_turb (PSS/E DTURB)"),
        p_ref_offset: ("dPref", "pu", 0.0, (-0.005, 0.005), "speed reference offset added after initialisation (nuisance; moves the droop's demand by dPref/R)"),
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
const X3: usize = 2;

/// The numbers the initialisation derives, on the number type `S`.
#[derive(Debug, Clone, Copy, Default)]
struct Consts<S = f64> {
    p_ref: S,
    inv_r: S,
    inv_t1: S,
    turbine: Lag<S>,
    load_limit: Lag<S>,
}

impl<S: Scalar> Consts<S> {
    fn new(p: &GastParams<S>, p_ref: S) -> Self {
        Self {
            p_ref,
            inv_r: p.r.recip(),
            inv_t1: p.t1.recip(),
            turbine: Lag::new(p.t2),
            load_limit: Lag::new(p.t3),
        }
    }
}

/// A GAST block. See the module documentation.
#[derive(Debug, Clone, Default)]
pub struct Gast {
    pub p: GastParams,
    k: Consts,
    valve: NonWindup,
    /// The parameters and derived numbers on dual numbers, after [`Block::seed_dual`].
    dual: Option<(GastParams<D>, Consts<D>)>,
}

/// The turbine's output x2 (the fuel flow) from the limited valve.
#[inline(always)]
fn flow<S: Scalar>(p: &GastParams<S>, k: &Consts<S>, valve: &NonWindup, x: &[S]) -> S {
    let x1 = valve.output(x[X1], p.v_min, p.v_max);
    k.turbine.output(x[X2], x1)
}

/// The valve's unconstrained rate: the low-value gate of the droop's and the load limit's
/// demands, through the valve lag.
#[inline(always)]
fn valve_rate<S: Scalar>(p: &GastParams<S>, k: &Consts<S>, valve: &NonWindup, x: &[S], speed: S) -> S {
    let droop = (k.p_ref + p.p_ref_offset - speed) * k.inv_r;
    let temp = flow(p, k, valve, x);
    let limit = p.a_t + p.k_t * (p.a_t - k.load_limit.output(x[X3], temp));
    (droop.min_s(limit) - x[X1]) * k.inv_t1
}

#[inline(always)]
fn outputs<S: Scalar>(p: &GastParams<S>, k: &Consts<S>, valve: &NonWindup, x: &[S], io: &mut Io<S>) {
    let speed = io.get(port::SPEED);
    io.set(port::PM, flow(p, k, valve, x) - p.d_turb * speed);
}

#[inline(always)]
fn derivatives<S: Scalar>(
    p: &GastParams<S>,
    k: &Consts<S>,
    valve: &NonWindup,
    x: &[S],
    io: &Io<S>,
    dx: &mut [S],
) {
    let speed = io.get(port::SPEED);
    dx[X1] = valve.derivative(valve_rate(p, k, valve, x, speed));
    let x1 = valve.output(x[X1], p.v_min, p.v_max);
    dx[X2] = k.turbine.derivative(x[X2], x1);
    let x2 = k.turbine.output(x[X2], x1);
    dx[X3] = k.load_limit.derivative(x[X3], x2);
}

impl Gast {
    pub fn new(p: GastParams) -> Self {
        Self {
            p,
            ..Default::default()
        }
    }
}

impl Block for Gast {
    block_common!();

    fn model(&self) -> &'static str {
        MODEL.name
    }
    fn ports(&self) -> &'static [Port] {
        PORTS
    }
    fn state_names(&self) -> &'static [&'static str] {
        &["x1", "x2", "x3"]
    }
    fn validate(&self) -> Result<(), ModelError> {
        let p = &self.p;
        guard::positive("r", p.r)?;
        guard::positive("t1", p.t1)?;
        guard::non_negative("t2", p.t2)?;
        guard::non_negative("t3", p.t3)?;
        guard::finite("a_t", p.a_t)?;
        guard::non_negative("k_t", p.k_t)?;
        guard::non_negative("d_turb", p.d_turb)?;
        guard::finite("p_ref_offset", p.p_ref_offset)?;
        guard::greater("v_max", p.v_max, "v_min", p.v_min)
    }

    fn init(&mut self, _op: &InitPoint, x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        self.validate()?;
        let p = &self.p;
        let pm0 = io.get(port::PM);
        let w0 = io.get(port::SPEED);
        let x1 = pm0 + p.d_turb * w0;
        if !(x1 >= p.v_min && x1 <= p.v_max) {
            return Err(ModelError::Init(format!(
                "GAST: the fuel valve position needed at t = 0, x1 = P_m0 + Dturb·Δω0 = {x1:.4} pu, lies outside [VMIN, VMAX] = [{}, {}]",
                p.v_min, p.v_max
            )));
        }
        if !(x1 <= p.a_t) {
            return Err(ModelError::Init(format!(
                "GAST: the fuel flow needed at t = 0, x2 = P_m0 + Dturb·Δω0 = {x1:.4} pu, exceeds the ambient temperature load limit AT = {} (the load limit would close the valve)",
                p.a_t
            )));
        }
        x[X1] = x1;
        x[X2] = x1;
        x[X3] = x1;
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
        let f = valve_rate(&self.p, &self.k, &self.valve, x, io.get(port::SPEED));
        self.valve.events(x[X1], f, self.p.v_min, self.p.v_max, g);
    }
    fn events_dual(&self, x: &[D], io: &Io<D>, g: &mut [D]) -> bool {
        match &self.dual {
            Some((p, k)) => {
                let f = valve_rate(p, k, &self.valve, x, io.get(port::SPEED));
                self.valve.events(x[X1], f, p.v_min, p.v_max, g);
                true
            }
            None => false,
        }
    }
    fn update_modes(&mut self, x: &mut [f64], io: &Io) -> bool {
        let f = valve_rate(&self.p, &self.k, &self.valve, x, io.get(port::SPEED));
        let (lo, hi) = (self.p.v_min, self.p.v_max);
        self.valve.update(&mut x[X1], f, lo, hi)
    }

    fn governor_roles(&self) -> Option<GovernorRoles> {
        let mut r = GovernorRoles::none("not applicable to GAST");
        r.droop = ParamRole::param("r");
        r.servo_time_constant = ParamRole::param("t1");
        r.turbine_time_constant = ParamRole::param("t2");
        r.output_max = ParamRole::param("v_max");
        r.output_min = ParamRole::param("v_min");
        r.damping = ParamRole::param("d_turb");
        r.reference_offset = ParamRole::param("p_ref_offset");
        Some(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn init_with(p: GastParams, pm0: f64, w0: f64) -> Result<(Gast, [f64; 3]), ModelError> {
        let mut b = Gast::new(p);
        let mut bus = [w0, pm0];
        let map = [0, 1];
        let mut x = [0.0; 3];
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

    fn rates(b: &Gast, x: &[f64], w: f64) -> (f64, [f64; 3]) {
        let mut bus = [w, 0.0];
        let map = [0, 1];
        let mut io = Io::new(&mut bus, &map);
        b.outputs(0.0, x, &mut io);
        let mut dx = [1.0; 3];
        b.derivatives(0.0, x, &io, &mut dx);
        (io.get(port::PM), dx)
    }

    #[test]
    fn starts_in_steady_state_on_the_load_limit_at_an_off_nominal_speed() {
        // x1 = P_m0 + D_turb Δω0 = A_T: both demands of the gate equal.
        let p = GastParams {
            d_turb: 0.3,
            a_t: 0.8 + 0.3 * 0.002,
            ..Default::default()
        };
        let (b, x) = init_with(p, 0.8, 0.002).unwrap();
        let (pm, dx) = rates(&b, &x, 0.002);
        assert!((pm - 0.8).abs() < 1e-15);
        assert!(dx.iter().all(|d| d.abs() < 1e-15), "{dx:?}");
    }

    #[test]
    fn the_load_limit_takes_over_from_the_droop() {
        // A speed fall asks the droop for more than the temperature limit allows once the
        // flow passes A_T: the gate follows the limit, x1 is driven back towards A_T.
        let p = GastParams {
            a_t: 0.82,
            ..Default::default()
        };
        let (b, mut x) = init_with(p, 0.8, 0.0).unwrap();
        x[X3] = 0.9; // hot exhaust: u_t = 0.82 + 2 (0.82 − 0.9) = 0.66
        let (_, dx) = rates(&b, &x, -0.01);
        assert!((dx[X1] - (0.66 - 0.8) / 0.4).abs() < 1e-12, "{dx:?}");
    }

    #[test]
    fn impossible_operating_points_are_refused_naming_the_limit() {
        let p = GastParams {
            v_max: 0.7,
            ..Default::default()
        };
        let e = init_with(p, 0.8, 0.0).unwrap_err().to_string();
        assert!(e.contains("GAST") && e.contains("VMAX") && e.contains("0.8000"), "{e}");
        let p = GastParams {
            a_t: 0.75,
            ..Default::default()
        };
        let e = init_with(p, 0.8, 0.0).unwrap_err().to_string();
        assert!(e.contains("GAST") && e.contains("AT = 0.75") && e.contains("0.8000"), "{e}");
    }

    #[test]
    fn roles_name_gast_parameters() {
        let b = Gast::default();
        let r = b.governor_roles().unwrap();
        r.check(b.params()).unwrap();
        assert_eq!(r.identifiable(), vec!["r", "t1", "t2"]);
    }
}
