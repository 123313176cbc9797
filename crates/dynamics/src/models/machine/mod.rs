//! Synchronous machines (PSS/E GENSAE, GENSAL, GENROU, GENCLS as implemented by OpenIPSL).
//!
//! What all machines share lives here, once: the ports, the Park transform, the stator
//! algebraic solve and the swing equation. Each model file (`gensae.rs`, …) holds only its
//! electrical (rotor circuit) equations, behind the [`Electrical`] trait.
//!
//! Conventions (reference `models.md` §0–§3): per unit on the machine base, generator sign,
//! `Δω` per-unit speed deviation, `δ` in electrical radians in the PMU's nominal-frequency frame,
//! q-axis along δ, d-axis lagging by 90°:
//!
//! ```text
//! v_d = |V| sin(δ − θ),   v_q = |V| cos(δ − θ)
//! v_d = E''_d + X''_q i_q − R_a i_d,   v_q = E''_q − X''_d i_d − R_a i_q        (ω = 1 in the stator)
//! ψ_d = E''_q − X''_d i_d,   ψ_q = −E''_d − X''_q i_q,   T_e = ψ_d i_q − ψ_q i_d
//! P = v_d i_d + v_q i_q,   Q = v_q i_d − v_d i_q
//! 2H dΔω/dt = (P_m − D Δω)/(1 + Δω) − T_e        (PSS/E / OpenIPSL; `swing = "pm_over_speed"`)
//! 2H dΔω/dt = P_m − D Δω − T_e                    (ANDES; `swing = "pm_is_torque"`)
//! dδ/dt = ω_b Δω
//! ```

pub mod saturation;

crate::library! {
    gensae,
    gensal,
    genrou,
    gencls,
}

use gensae::GensaeParams;
use gensal::GensalParams;

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port, PortInit};
use crate::params::ParamSet;
use crate::sens::{Scalar, D};

/// Minimal complex number for the phasor algebra of initialisation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Phasor {
    pub re: f64,
    pub im: f64,
}

impl Phasor {
    pub fn new(re: f64, im: f64) -> Self {
        Self { re, im }
    }
    pub fn polar(mag: f64, ang: f64) -> Self {
        Self {
            re: mag * ang.cos(),
            im: mag * ang.sin(),
        }
    }
    pub fn abs(self) -> f64 {
        self.re.hypot(self.im)
    }
    pub fn arg(self) -> f64 {
        self.im.atan2(self.re)
    }
    pub fn conj(self) -> Self {
        Self {
            re: self.re,
            im: -self.im,
        }
    }
    /// Park transform at rotor angle δ: returns `(d, q)` components.
    pub fn to_dq(self, delta: f64) -> (f64, f64) {
        let (s, c) = delta.sin_cos();
        (self.re * s - self.im * c, self.re * c + self.im * s)
    }
}

impl std::ops::Mul for Phasor {
    type Output = Phasor;
    fn mul(self, o: Self) -> Self {
        Self {
            re: self.re * o.re - self.im * o.im,
            im: self.re * o.im + self.im * o.re,
        }
    }
}

impl std::ops::Div for Phasor {
    type Output = Phasor;
    fn div(self, o: Self) -> Self {
        let d = o.re * o.re + o.im * o.im;
        Self {
            re: (self.re * o.re + self.im * o.im) / d,
            im: (self.im * o.re - self.re * o.im) / d,
        }
    }
}

impl std::ops::Add for Phasor {
    type Output = Phasor;
    fn add(self, o: Self) -> Self {
        Self {
            re: self.re + o.re,
            im: self.im + o.im,
        }
    }
}

/// Stator quantities in the dq frame.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Stator<S = f64> {
    pub vd: S,
    pub vq: S,
    pub id: S,
    pub iq: S,
    pub psi_d: S,
    pub psi_q: S,
}

/// Stator impedance with the inverse determinant of the 2×2 solve, computed once per
/// initialisation.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StatorImpedance<S = f64> {
    pub r_a: S,
    pub x_d_pp: S,
    pub x_q_pp: S,
    /// 1/(R_a² + X''_d X''_q).
    pub inv_det: S,
}

impl<S: Scalar> StatorImpedance<S> {
    pub fn new(r_a: S, x_d_pp: S, x_q_pp: S) -> Self {
        Self {
            r_a,
            x_d_pp,
            x_q_pp,
            inv_det: (r_a * r_a + x_d_pp * x_q_pp).recip(),
        }
    }
}

impl<S: Scalar> Stator<S> {
    /// Solves the stator algebraic equations (§1.2) for the currents given the subtransient
    /// voltages `E''_d`, `E''_q` and the terminal voltage in dq:
    /// `Δ = R_a² + X''_d X''_q`,
    /// `i_d = [R_a (E''_d − v_d) + X''_q (E''_q − v_q)]/Δ`,
    /// `i_q = [X''_d (v_d − E''_d) + R_a (E''_q − v_q)]/Δ`.
    #[inline(always)]
    pub fn solve(e_d_pp: S, e_q_pp: S, vd: S, vq: S, z: &StatorImpedance<S>) -> Self {
        let dd = e_d_pp - vd;
        let dq = e_q_pp - vq;
        let id = (z.r_a * dd + z.x_q_pp * dq) * z.inv_det;
        let iq = (z.r_a * dq - z.x_d_pp * dd) * z.inv_det;
        Self {
            vd,
            vq,
            id,
            iq,
            psi_d: e_q_pp - z.x_d_pp * id,
            psi_q: -e_d_pp - z.x_q_pp * iq,
        }
    }
    #[inline(always)]
    pub fn torque(&self) -> S {
        self.psi_d * self.iq - self.psi_q * self.id
    }
    #[inline(always)]
    pub fn p(&self) -> S {
        self.vd * self.id + self.vq * self.iq
    }
    #[inline(always)]
    pub fn q(&self) -> S {
        self.vq * self.id - self.vd * self.iq
    }
}

/// Field current and saturation factor at one point.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Field<S = f64> {
    /// X_ad I_fd [pu].
    pub xadifd: S,
    /// Saturation factor Se (0 when unsaturated or not modelled).
    pub sat: S,
}

/// Magnitude of (a, b) without `hypot`'s overflow guards (arguments are O(1) pu).
#[inline(always)]
pub fn norm2<S: Scalar>(a: S, b: S) -> S {
    (a * a + b * b).sqrt()
}

/// Steady-state electrical quantities found by [`Electrical::init_electrical`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ElectricalInit {
    /// Rotor angle δ0 [rad].
    pub delta: f64,
    /// Field voltage that holds the steady state, E_fd0 [pu].
    pub efd: f64,
}

/// The rotor-circuit equations of a machine model on the number type `S` (`f64`, or [`D`] for
/// forward sensitivities: one implementation serves both).
pub trait ElectricalEq<S: Scalar> {
    /// Inertia constant H [s] and damping D [pu P / pu speed].
    fn inertia_damping(&self) -> (S, S);
    /// Stator solution for electrical states `x_el` and terminal voltage `(v_d, v_q)`.
    fn stator(&self, x_el: &[S], vd: S, vq: S) -> Stator<S>;
    /// Field current X_ad I_fd [pu, non-reciprocal] and the saturation factor Se at this point.
    fn field(&self, x_el: &[S], st: &Stator<S>) -> Field<S>;
    /// Electrical state derivatives; `field` is what [`ElectricalEq::field`] returned at this
    /// point (read back from the bus, so saturation is evaluated once per right-hand side).
    fn derivatives(&self, x_el: &[S], efd: S, field: Field<S>, st: &Stator<S>, dx_el: &mut [S]);
}

/// The rotor-circuit part of a machine model. States after `δ` and `Δω`.
pub trait Electrical: ElectricalEq<f64> + Clone + Send + Sync + 'static {
    const MODEL: &'static str;
    /// All state names, starting with `delta`, `speed`.
    const STATE_NAMES: &'static [&'static str];
    /// The model on dual numbers ([`Electrical::lift`]).
    type Lifted: ElectricalEq<D> + Clone + std::fmt::Debug + Send + Sync + 'static;
    fn params(&self) -> &dyn ParamSet;
    fn params_mut(&mut self) -> &mut dyn ParamSet;
    fn armature_resistance(&self) -> f64;
    fn validate(&self) -> Result<(), ModelError>;
    /// Recomputes derived constants from the parameters (called before every initialisation).
    fn prepare(&mut self) -> Result<(), ModelError>;
    /// Steady state for terminal voltage `v` and current `i` (system frame, machine base):
    /// writes the electrical states `x_el` and returns δ0 and E_fd0.
    fn init_electrical(
        &mut self,
        v: Phasor,
        i: Phasor,
        x_el: &mut [f64],
    ) -> Result<ElectricalInit, ModelError>;
    /// Constants the initialisation computed from the operating point (GENCLS's E'), which
    /// the equations hold fixed; a sensitivity pass differentiates them with the initial state.
    fn init_constants(&self) -> Vec<f64> {
        Vec::new()
    }
    /// The model on dual numbers after [`Electrical::prepare`] and the initialisation:
    /// parameter `i` seeded on `lanes[i]`, the [`Electrical::init_constants`] as `consts`.
    /// `None` if the derived constants cannot be formed (they could for the `f64` values).
    fn lift(&self, lanes: &[Option<usize>], consts: &[D]) -> Option<Self::Lifted>;
}

/// Which mechanical-torque convention the swing equation uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Swing {
    /// `T_m = (P_m − D Δω)/(1 + Δω)` (PSS/E, OpenIPSL). Default.
    #[default]
    PmOverSpeed,
    /// `T_m = P_m − D Δω` (ANDES: no division by speed).
    PmIsTorque,
}

/// Port indices shared by all machines.
pub mod port {
    pub const V_TERM: usize = 0;
    pub const THETA_TERM: usize = 1;
    pub const EFD: usize = 2;
    pub const PM: usize = 3;
    pub const DELTA: usize = 4;
    pub const SPEED: usize = 5;
    pub const PE: usize = 6;
    pub const QE: usize = 7;
    pub const TE: usize = 8;
    pub const XADIFD: usize = 9;
    pub const ID: usize = 10;
    pub const IQ: usize = 11;
    pub const SAT: usize = 12;
}

const PORTS: &[Port] = &[
    Port::input_ft(
        "v_term",
        PortInit::Needs,
        "terminal voltage magnitude |V| [pu], from playback",
    ),
    Port::input_ft(
        "theta_term",
        PortInit::Needs,
        "terminal voltage angle θ [rad], from playback",
    ),
    Port::input("efd", PortInit::Gives, "field voltage E_fd [pu]"),
    Port::input(
        "pm",
        PortInit::Gives,
        "mechanical power P_m [pu machine base]",
    ),
    Port::output("delta", PortInit::Gives, "rotor angle δ [rad]"),
    Port::output("speed", PortInit::Gives, "speed deviation Δω [pu]"),
    Port::output(
        "pe",
        PortInit::Gives,
        "terminal active power P [pu machine base]",
    ),
    Port::output(
        "qe",
        PortInit::Gives,
        "terminal reactive power Q [pu machine base]",
    ),
    Port::output("te", PortInit::Gives, "air-gap torque T_e [pu]"),
    Port::output("xadifd", PortInit::Gives, "field current X_ad I_fd [pu]"),
    Port::output("id", PortInit::Gives, "d-axis stator current [pu]"),
    Port::output("iq", PortInit::Gives, "q-axis stator current [pu]"),
    Port::output("sat", PortInit::Gives, "saturation factor Se [-]"),
];

/// A machine block: swing equation + stator + the electrical model `E`.
#[derive(Debug, Clone)]
pub struct Machine<E: Electrical> {
    pub el: E,
    pub swing: Swing,
    /// Base angular frequency ω_b = 2π f_n [rad/s] (set by the unit).
    pub omega_b: f64,
    /// 1/(2H) and D, refreshed at every initialisation.
    inv_2h: f64,
    damping: f64,
    /// The model on dual numbers, 1/(2H) and D, after [`Block::seed_dual`].
    dual: Option<(E::Lifted, D, D)>,
}

impl<E: Electrical> Machine<E> {
    pub fn new(el: E) -> Self {
        Self {
            el,
            swing: Swing::default(),
            omega_b: 2.0 * std::f64::consts::PI * 60.0,
            inv_2h: 0.0,
            damping: 0.0,
            dual: None,
        }
    }
}

/// The stator at the terminal voltage on the bus (the Park transform at δ).
#[inline(always)]
fn stator_at<S: Scalar, M: ElectricalEq<S>>(el: &M, x: &[S], io: &Io<S>) -> Stator<S> {
    let (s, c) = (x[0] - io.get(port::THETA_TERM)).sin_cos();
    let v = io.get(port::V_TERM);
    el.stator(&x[2..], v * s, v * c)
}

/// Every output port at `x` with the stator solved there.
#[inline(always)]
fn write_outputs<S: Scalar, M: ElectricalEq<S>>(el: &M, x: &[S], st: &Stator<S>, io: &mut Io<S>) {
    io.set(port::DELTA, x[0]);
    io.set(port::SPEED, x[1]);
    io.set(port::PE, st.p());
    io.set(port::QE, st.q());
    io.set(port::TE, st.torque());
    let field = el.field(&x[2..], st);
    io.set(port::XADIFD, field.xadifd);
    io.set(port::SAT, field.sat);
    io.set(port::ID, st.id);
    io.set(port::IQ, st.iq);
}

/// The swing equation and the electrical derivatives (after [`write_outputs`] at this point:
/// the currents, torque and field are read back from the bus).
#[inline(always)]
fn derivatives_at<S: Scalar, M: ElectricalEq<S>>(
    el: &M,
    swing: Swing,
    omega_b: f64,
    (inv_2h, damping): (S, S),
    x: &[S],
    io: &Io<S>,
    dx: &mut [S],
) {
    let st = Stator {
        id: io.get(port::ID),
        iq: io.get(port::IQ),
        ..Stator::default()
    };
    let w = x[1];
    let pm = io.get(port::PM);
    let tm = match swing {
        Swing::PmOverSpeed => (pm - damping * w) / (w + 1.0),
        Swing::PmIsTorque => pm - damping * w,
    };
    dx[0] = w * omega_b;
    dx[1] = (tm - io.get(port::TE)) * inv_2h;
    let field = Field {
        xadifd: io.get(port::XADIFD),
        sat: io.get(port::SAT),
    };
    el.derivatives(&x[2..], io.get(port::EFD), field, &st, &mut dx[2..]);
}

impl<E: Electrical> Block for Machine<E> {
    fn model(&self) -> &'static str {
        E::MODEL
    }
    fn ports(&self) -> &'static [Port] {
        PORTS
    }
    fn state_names(&self) -> &'static [&'static str] {
        E::STATE_NAMES
    }
    fn params(&self) -> &dyn ParamSet {
        self.el.params()
    }
    fn params_mut(&mut self) -> &mut dyn ParamSet {
        self.el.params_mut()
    }
    fn validate(&self) -> Result<(), ModelError> {
        let (h, d) = ElectricalEq::<f64>::inertia_damping(&self.el);
        guard::positive("h", h)?;
        guard::non_negative("d", d)?;
        guard::non_negative("r_a", self.el.armature_resistance())?;
        self.el.validate()
    }

    fn init(&mut self, op: &InitPoint, x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        self.validate()?;
        self.el.prepare()?;
        let (h, d) = ElectricalEq::<f64>::inertia_damping(&self.el);
        self.inv_2h = 1.0 / (2.0 * h);
        self.damping = d;
        if !(op.v_mag > 0.0) || !op.p.is_finite() || !op.q.is_finite() {
            return Err(ModelError::Init(format!(
                "operating point is not usable (|V| = {}, P = {}, Q = {})",
                op.v_mag, op.p, op.q
            )));
        }
        let v = Phasor::polar(op.v_mag, op.v_ang);
        let i = (Phasor::new(op.p, op.q) / v).conj();
        let ei = self.el.init_electrical(v, i, &mut x[2..])?;
        x[0] = ei.delta;
        x[1] = op.speed_dev;
        let (vd, vq) = v.to_dq(ei.delta);
        let st = ElectricalEq::<f64>::stator(&self.el, &x[2..], vd, vq);
        // Self-check: the electrical steady state must reproduce the measured P and Q.
        let (dp, dq) = (st.p() - op.p, st.q() - op.q);
        if !(dp.abs() < 1e-8 && dq.abs() < 1e-8) {
            return Err(ModelError::Init(format!(
                "{} steady state does not reproduce P, Q (errors {dp:.3e}, {dq:.3e}); check the reactances",
                E::MODEL
            )));
        }
        let (_, d) = ElectricalEq::<f64>::inertia_damping(&self.el);
        let te = st.torque();
        let w0 = op.speed_dev;
        let pm = match self.swing {
            Swing::PmOverSpeed => (1.0 + w0) * te + d * w0,
            Swing::PmIsTorque => te + d * w0,
        };
        io.set(port::EFD, ei.efd);
        io.set(port::PM, pm);
        write_outputs(&self.el, x, &st, io);
        if !ei.efd.is_finite() || !pm.is_finite() || x.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::Init(format!(
                "{} initial state is not finite",
                E::MODEL
            )));
        }
        Ok(())
    }

    #[inline]
    fn outputs(&self, _t: f64, x: &[f64], io: &mut Io) {
        let st = stator_at(&self.el, x, io);
        write_outputs(&self.el, x, &st, io);
    }

    #[inline]
    fn derivatives(&self, _t: f64, x: &[f64], io: &Io, dx: &mut [f64]) {
        // `outputs` has just solved the stator at this (t, x): reuse its currents and torque.
        let hd = (self.inv_2h, self.damping);
        derivatives_at(&self.el, self.swing, self.omega_b, hd, x, io, dx);
    }

    fn init_constants(&self) -> Vec<f64> {
        self.el.init_constants()
    }

    fn seed_dual(&mut self, lanes: &[Option<usize>], consts: &[D]) -> bool {
        self.dual = self.el.lift(lanes, consts).map(|el| {
            let (h, d) = el.inertia_damping();
            (el, (h * 2.0).recip(), d)
        });
        self.dual.is_some()
    }

    fn outputs_dual(&self, _t: f64, x: &[D], io: &mut Io<D>) {
        if let Some((el, _, _)) = &self.dual {
            let st = stator_at(el, x, io);
            write_outputs(el, x, &st, io);
        }
    }

    fn derivatives_dual(&self, _t: f64, x: &[D], io: &Io<D>, dx: &mut [D]) {
        if let Some((el, inv_2h, d)) = &self.dual {
            derivatives_at(el, self.swing, self.omega_b, (*inv_2h, *d), x, io, dx);
        }
    }

    fn set_nominal_frequency(&mut self, hz: f64) {
        self.omega_b = 2.0 * std::f64::consts::PI * hz;
    }

    fn set_option(&mut self, key: &str, value: &str) -> Result<(), ModelError> {
        match (key, value) {
            ("swing", "pm_over_speed") => self.swing = Swing::PmOverSpeed,
            ("swing", "pm_is_torque") => self.swing = Swing::PmIsTorque,
            ("swing", v) => {
                return Err(ModelError::param(
                    "swing",
                    format!("'{v}' is not one of: pm_over_speed, pm_is_torque"),
                ))
            }
            (k, _) => {
                return Err(ModelError::param(
                    k,
                    "unknown option (machines accept: swing)",
                ))
            }
        }
        Ok(())
    }

    fn options(&self) -> Vec<(&'static str, String)> {
        let s = match self.swing {
            Swing::PmOverSpeed => "pm_over_speed",
            Swing::PmIsTorque => "pm_is_torque",
        };
        vec![("swing", s.to_string())]
    }

    fn clone_box(&self) -> Box<dyn Block> {
        Box::new(self.clone())
    }
}

/// The d-axis constants shared by GENSAL, GENSAE and GENROU (`models.md` §4.2):
/// `K3d = (X''d − Xl)/(X'd − Xl)`, `K4d = (X'd − X''d)/(X'd − Xl)` (K3d + K4d = 1),
/// `K1d = (X'd − X''d)(Xd − X'd)/(X'd − Xl)²`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct DAxis<S = f64> {
    pub k1d: S,
    pub k3d: S,
    pub k4d: S,
}

impl<S: Scalar> DAxis<S> {
    pub fn new(x_d: S, x_d_prime: S, x_d_pp: S, x_l: S) -> Self {
        let xdl = x_d_prime - x_l;
        Self {
            k1d: (x_d_prime - x_d_pp) * (x_d - x_d_prime) / (xdl * xdl),
            k3d: (x_d_pp - x_l) / xdl,
            k4d: (x_d_prime - x_d_pp) / xdl,
        }
    }
}

/// The parameters GENSAL and GENSAE share, by name: their parameter sets have the same fields
/// (`From` implemented for both below), which [`SalientConsts::of`] reads.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SalientPole<S> {
    pub r_a: S,
    pub x_d: S,
    pub x_d_prime: S,
    pub x_d_pp: S,
    pub x_q_pp: S,
    pub x_l: S,
    pub t_d0_prime: S,
    pub t_d0_pp: S,
    pub t_q0_pp: S,
}

macro_rules! salient_pole_from {
    ($($params:ident),*) => {$(
        impl<S: Copy> From<&$params<S>> for SalientPole<S> {
            fn from(p: &$params<S>) -> Self {
                Self {
                    r_a: p.r_a,
                    x_d: p.x_d,
                    x_d_prime: p.x_d_prime,
                    x_d_pp: p.x_d_pp,
                    x_q_pp: p.x_q_pp,
                    x_l: p.x_l,
                    t_d0_prime: p.t_d0_prime,
                    t_d0_pp: p.t_d0_pp,
                    t_q0_pp: p.t_q0_pp,
                }
            }
        }
    )*};
}
salient_pole_from!(GensaeParams, GensalParams);

/// The stator and d-axis constants of the salient-pole models GENSAL and GENSAE, built once
/// for both (each keeps its own saturation and q-axis terms): the stator impedance with X''_d
/// and X''_q, the reciprocal open-circuit time constants and the [`DAxis`] constants.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct SalientConsts<S = f64> {
    pub z: StatorImpedance<S>,
    pub inv_t_d0_prime: S,
    pub inv_t_d0_pp: S,
    pub inv_t_q0_pp: S,
    pub d: DAxis<S>,
}

impl<S: Scalar> SalientConsts<S> {
    pub fn of(p: SalientPole<S>) -> Self {
        Self {
            z: StatorImpedance::new(p.r_a, p.x_d_pp, p.x_q_pp),
            inv_t_d0_prime: p.t_d0_prime.recip(),
            inv_t_d0_pp: p.t_d0_pp.recip(),
            inv_t_q0_pp: p.t_q0_pp.recip(),
            d: DAxis::new(p.x_d, p.x_d_prime, p.x_d_pp, p.x_l),
        }
    }
}

/// Common reactance guards of the salient-pole and round-rotor models:
/// `X_d > X'_d > X''_d > X_l > 0`, `X_q > X''_q > X_l`, `X_d >= X_q` is *not* enforced (a
/// round rotor may have X_q close to X_d), all time constants > 0.
pub(crate) fn check_d_axis(x_d: f64, x_d_p: f64, x_d_pp: f64, x_l: f64) -> Result<(), ModelError> {
    guard::positive("x_l", x_l)?;
    guard::greater("x_d_pp", x_d_pp, "x_l", x_l)?;
    guard::greater("x_d_prime", x_d_p, "x_d_pp", x_d_pp)?;
    guard::greater("x_d", x_d, "x_d_prime", x_d_p)
}
