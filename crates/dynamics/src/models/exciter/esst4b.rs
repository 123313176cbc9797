//! ESST4B: IEEE 421.5-2005 type ST4B potential- or compound-source controlled-rectifier
//! exciter, as PSS/E's `ESST4B` (cross-checked against ANDES 2.0 `ESST4B`,
//! `tests/andes_models.rs`).
//!
//! States: transducer `v_c`, outer PI integrator `x_r`, regulator lag `v_a`, inner PI integrator
//! `x_m`. E_fd is algebraic.
//!
//! ```text
//! T_R dV_C/dt = E_C − V_C                                        (T_R = 0: V_C = E_C)
//! e   = V_ref + ΔV_ref − V_C + V_S + V_UEL [+ V_OEL with oel = "summing"]
//! V_R = clamp(K_PR e + x_r, V_RMIN, V_RMAX),   dx_r/dt = K_IR e     x_r non-windup in [V_RMIN, V_RMAX]
//! T_A dV_A/dt = V_R − V_A                                        (T_A = 0: V_A = V_R)
//! V_M = clamp(K_PM (V_A − V_G) + x_m, V_MMIN, V_MMAX),  dx_m/dt = K_IM (V_A − V_G)   x_m non-windup in [V_MMIN, V_MMAX]
//! V_M ← min(V_M, V_OEL) with oel = "gate"                         (LV gate)
//! V_E = |K_P∠θ_P · V_T + j (K_I + K_P∠θ_P · X_L) I_T|,   I_N = K_C X_adI_fd / V_E
//! F_EX = 1 − 0.577 I_N (I_N ≤ 0.433), √(0.75 − I_N²) (≤ 0.75), 1.732 (1 − I_N) (≤ 1), 0 (> 1)
//! V_B = min(V_E F_EX, V_BMAX),   E_fd = V_B V_M,   V_G = K_G E_fd
//! ```
//!
//! V_G = K_G E_fd closes an algebraic loop through the inner PI; it is solved exactly:
//! `V_M = clamp((K_PM V_A + x_m)/(1 + K_PM K_G V_B), V_MMIN, V_MMAX)` (the clamp of a decreasing
//! map has that unique fixed point). The terminal current `I_T` comes from the terminal P and Q
//! (`I_T = (P − jQ)/V_T` with V_T the angle reference, the magnitude V_E being invariant to the
//! frame). All in pu (E_fd on the machine's field base, X_adI_fd non-reciprocal pu, K_P, K_I, X_L
//! pu), times in s, θ_P in degrees (PSS/E's unit). Ports `v_supply` (default the played-back
//! |V_t|), `pe` and `qe` feed V_E.
//!
//! **Limits.** The two PI blocks have non-windup limits on their integrator states (PSS/E's
//! reading of IEEE 421.5's non-windup PI: the state stops on a limit while its input pushes
//! outwards and leaves when the input reverses, located by events, [`NonWindup`]); their outputs
//! are clamped algebraically. IEEE 421.5-2016 Annex E's conditional form stops the integrator
//! when the *output* is on a limit instead; it differs only while the proportional path alone
//! holds the output on a limit, and can chatter there (Cui et al., on the 2016 form). ANDES uses
//! a tracking anti-windup (`PITrackAW`, gain 2); the reference case of `tests/andes_models.rs`
//! is chosen so that no PI state meets a limit, where the three forms agree. V_BMAX and the
//! F_EX curve are algebraic.
//!
//! **Initialisation** (exact, from E_fd0, X_adI_fd0 and the measured P, Q, V_T):
//! `V_B0`, then `V_M0 = E_fd0/V_B0`; the inner PI holds it with zero input when K_IM > 0
//! (`x_m = V_M0`, `V_A0 = K_G E_fd0`), else it is proportional only (`x_m = 0`,
//! `V_A0 = V_M0/K_PM + K_G E_fd0`, as the block diagram with K_IM = 0 is); `V_R0 = V_A0 = x_r`
//! with zero error (K_IR = 0 gives the same trajectory as a proportional regulator with its
//! reference shifted); `V_ref = V_C0 − V_S0 − V_UEL0 [− V_OEL0]`. Refused, naming the limit, when
//! the bridge cannot supply E_fd0 (`V_B0 = 0`), when V_M0 lies outside [V_MMIN, V_MMAX], V_R0
//! outside [V_RMIN, V_RMAX], or the OEL gate selects its limiter at t = 0.

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port, PortInit};
use crate::dyr::DyrRecord;
use crate::models::exciter::blocks::Lag;
use crate::models::exciter::roles::{ExciterRoles, LeadLagRole, ParamRole};
use crate::models::limiter::{clamp, NonWindup};
use crate::registry::{ModelInfo, Role};
use crate::sens::{Scalar, D};
use crate::{block_common, param_set};

/// The registry entry ([`crate::registry`]): name, role, `.dyr` record (PSS/E's CON order; no
/// ICON).
pub const MODEL: ModelInfo = ModelInfo {
    name: "ESST4B",
    role: Role::Exciter,
    summary: "IEEE 421.5-2005 ST4B potential/compound-source rectifier exciter: PI voltage and field regulators, V_E·F_EX bridge",
    reference: "IEEE 421.5-2005 ST4B as PSS/E's ESST4B, ANDES ESST4B; non-windup PI states, algebraic V_BMAX and F_EX",
    make: || Box::new(Esst4b::default()),
    dyr: Some(DyrRecord::cons(&[
        "t_r", "k_pr", "k_ir", "vr_max", "vr_min", "t_a", "k_pm", "k_im", "vm_max", "vm_min",
        "k_g", "k_p", "k_i", "vb_max", "k_c", "x_l", "theta_p",
    ])),
};

param_set! {
    /// ESST4B parameters (PSS/E CON order). Typical values: IEEE 421.5-2005 sample data
    /// (Annex H, ST4B).
    pub struct Esst4bParams {
        t_r: ("TR", "s", 0.02, (0.0, 0.05), "voltage transducer time constant T_R"),
        k_pr: ("KPR", "pu", 10.75, (1.0, 50.0), "voltage regulator proportional gain K_PR"),
        k_ir: ("KIR", "pu/s", 10.75, (0.0, 50.0), "voltage regulator integral gain K_IR"),
        vr_max: ("VRMAX", "pu", 1.0, (0.5, 2.0), "voltage regulator maximum output V_RMAX"),
        vr_min: ("VRMIN", "pu", -0.87, (-2.0, 0.0), "voltage regulator minimum output V_RMIN"),
        t_a: ("TA", "s", 0.02, (0.0, 0.1), "voltage regulator (firing circuit) time constant T_A"),
        k_pm: ("KPM", "pu", 1.0, (0.5, 10.0), "field current regulator proportional gain K_PM"),
        k_im: ("KIM", "pu/s", 0.0, (0.0, 10.0), "field current regulator integral gain K_IM"),
        vm_max: ("VMMAX", "pu", 99.0, (1.0, 99.0), "field current regulator maximum output V_MMAX"),
        vm_min: ("VMMIN", "pu", -99.0, (-99.0, 0.0), "field current regulator minimum output V_MMIN"),
        k_g: ("KG", "pu", 0.0, (0.0, 1.1), "feedback gain of the field current regulator K_G"),
        k_p: ("KP", "pu", 9.3, (1.0, 10.0), "potential circuit gain K_P"),
        k_i: ("KI", "pu", 0.0, (0.0, 1.1), "compound (current) circuit gain K_I"),
        vb_max: ("VBMAX", "pu", 11.63, (1.0, 20.0), "maximum bridge voltage V_BMAX"),
        k_c: ("KC", "pu", 0.113, (0.0, 1.0), "rectifier loading factor proportional to the commutating reactance K_C"),
        x_l: ("XL", "pu", 0.124, (0.0, 0.5), "reactance of the potential source X_L"),
        theta_p: ("THETAP", "deg", 0.0, (0.0, 90.0), "potential circuit phase angle θ_P"),
        v_ref_offset: ("dVref", "pu", 0.0, (-0.01, 0.01), "voltage reference offset added after initialisation (nuisance)"),
    }
}

/// Port indices (the first five as SEXS's).
pub mod port {
    pub const V_TERM: usize = 0;
    pub const VS: usize = 1;
    pub const VOEL: usize = 2;
    pub const VUEL: usize = 3;
    pub const EFD: usize = 4;
    pub const V_SUPPLY: usize = 5;
    pub const XADIFD: usize = 6;
    pub const PE: usize = 7;
    pub const QE: usize = 8;
}

const PORTS: &[Port] = &[
    Port::input_ft(
        "v_term",
        PortInit::Needs,
        "compensated terminal voltage E_C [pu]",
    ),
    Port::input_ft("vs", PortInit::Needs, "stabiliser signal V_S [pu]").optional(),
    Port::input_ft(
        "voel",
        PortInit::Needs,
        "over-excitation limiter signal [pu] (summed, or LV gate with oel = \"gate\")",
    )
    .optional(),
    Port::input_ft(
        "vuel",
        PortInit::Needs,
        "under-excitation limiter signal [pu] (summed at the error)",
    )
    .optional(),
    Port::output("efd", PortInit::Needs, "field voltage E_fd [pu]"),
    Port::input_ft(
        "v_supply",
        PortInit::Needs,
        "terminal voltage V_T feeding the potential source [pu]",
    )
    .wired("v_term"),
    Port::input_ft("xadifd", PortInit::Needs, "field current X_ad I_fd [pu]"),
    Port::input_ft(
        "pe",
        PortInit::Needs,
        "terminal active power P [pu machine base] (for the terminal current I_T)",
    ),
    Port::input_ft(
        "qe",
        PortInit::Needs,
        "terminal reactive power Q [pu machine base] (for the terminal current I_T)",
    ),
];

const V_C: usize = 0;
const X_R: usize = 1;
const V_A: usize = 2;
const X_M: usize = 3;

/// The numbers the initialisation derives, on the number type `S`.
#[derive(Debug, Clone, Copy, Default)]
struct Consts<S = f64> {
    v_ref: S,
    transducer: Lag<S>,
    regulator: Lag<S>,
    /// `K_P cos θ_P`, `K_P sin θ_P`, and the current circuit `K_I + K_P X_L cos θ_P`,
    /// `K_P X_L sin θ_P`.
    kp_re: S,
    kp_im: S,
    ki_re: S,
    ki_im: S,
}

impl<S: Scalar> Consts<S> {
    fn new(p: &Esst4bParams<S>, v_ref: S) -> Self {
        let (s, c) = (p.theta_p * (std::f64::consts::PI / 180.0)).sin_cos();
        Self {
            v_ref,
            transducer: Lag::new(p.t_r),
            regulator: Lag::new(p.t_a),
            kp_re: p.k_p * c,
            kp_im: p.k_p * s,
            ki_re: p.k_i + p.k_p * p.x_l * c,
            ki_im: p.k_p * p.x_l * s,
        }
    }
}

/// The options and modes of the evaluation (no number in them).
#[derive(Debug, Clone, Copy, Default)]
struct Modes {
    oel_gate: bool,
    oel_undriven: bool,
    outer: NonWindup,
    inner: NonWindup,
    /// K_IR > 0, K_IM > 0: the integrators move (else their states are constants).
    outer_integrates: bool,
    inner_integrates: bool,
}

/// An ESST4B block. See the module documentation.
#[derive(Debug, Clone, Default)]
pub struct Esst4b {
    pub p: Esst4bParams,
    k: Consts,
    m: Modes,
    /// The parameters and derived numbers on duals, after [`Block::seed_dual`].
    dual: Option<(Esst4bParams<D>, Consts<D>)>,
}

/// The rectifier loading factor F_EX(I_N) of IEEE 421.5 (Annex D).
#[inline(always)]
pub fn fex<S: Scalar>(i_n: S) -> S {
    let v = i_n.val();
    if v <= 0.0 {
        S::cst(1.0)
    } else if v <= 0.433 {
        (i_n * -0.577) + 1.0
    } else if v < 0.75 {
        (i_n * i_n).rsub(0.75).sqrt()
    } else if v <= 1.0 {
        i_n.rsub(1.0) * 1.732
    } else {
        S::cst(0.0)
    }
}

/// The bridge voltage `V_B = min(V_E F_EX(I_N), V_BMAX)`.
#[inline(always)]
fn bridge<S: Scalar>(p: &Esst4bParams<S>, k: &Consts<S>, io: &Io<S>) -> S {
    let v = io.get(port::V_SUPPLY);
    let (pe, qe) = (io.get(port::PE), io.get(port::QE));
    // K_P∠θ·V + j(K_I + K_P∠θ X_L)·(P − jQ)/V, V the angle reference.
    let inv_v = v.recip();
    let re = k.kp_re * v + (k.ki_re * qe - k.ki_im * pe) * inv_v;
    let im = k.kp_im * v + (k.ki_re * pe + k.ki_im * qe) * inv_v;
    let v_e = (re * re + im * im).sqrt();
    if !(v_e.val() > 1e-9) {
        return S::cst(0.0);
    }
    let i_n = p.k_c * io.get(port::XADIFD) / v_e;
    (v_e * fex(i_n)).min_s(p.vb_max)
}

/// The signals of one evaluation.
struct Eval<S> {
    /// The voltage error and the field regulator's input V_A − V_G.
    e: S,
    u_m: S,
    v_r: S,
    efd: S,
}

#[inline(always)]
fn eval<S: Scalar>(p: &Esst4bParams<S>, k: &Consts<S>, m: &Modes, x: &[S], io: &Io<S>) -> Eval<S> {
    let v_c = k.transducer.output(x[V_C], io.get(port::V_TERM));
    let mut e = k.v_ref + p.v_ref_offset - v_c + io.get(port::VS) + io.get(port::VUEL);
    if !m.oel_gate {
        e += io.get(port::VOEL);
    }
    let x_r = if m.outer_integrates {
        m.outer.output(x[X_R], p.vr_min, p.vr_max)
    } else {
        x[X_R]
    };
    let v_r = clamp(p.k_pr * e + x_r, p.vr_min, p.vr_max);
    let v_a = k.regulator.output(x[V_A], v_r);
    let v_b = bridge(p, k, io);
    let x_m = if m.inner_integrates {
        m.inner.output(x[X_M], p.vm_min, p.vm_max)
    } else {
        x[X_M]
    };
    let v_m_free = (p.k_pm * v_a + x_m) / ((p.k_pm * p.k_g * v_b) + 1.0);
    let mut v_m = clamp(v_m_free, p.vm_min, p.vm_max);
    if m.oel_gate && !m.oel_undriven {
        v_m = v_m.min_s(io.get(port::VOEL));
    }
    let efd = v_b * v_m;
    Eval {
        e,
        u_m: v_a - p.k_g * efd,
        v_r,
        efd,
    }
}

/// The integrators' unconstrained rates `(K_IR e, K_IM (V_A − V_G))`.
#[inline(always)]
fn rates<S: Scalar>(p: &Esst4bParams<S>, m: &Modes, e: &Eval<S>) -> (S, S) {
    let r = if m.outer_integrates {
        p.k_ir * e.e
    } else {
        S::cst(0.0)
    };
    let i = if m.inner_integrates {
        p.k_im * e.u_m
    } else {
        S::cst(0.0)
    };
    (r, i)
}

#[inline(always)]
fn derivatives<S: Scalar>(
    p: &Esst4bParams<S>,
    k: &Consts<S>,
    m: &Modes,
    x: &[S],
    io: &Io<S>,
    dx: &mut [S],
) {
    let e = eval(p, k, m, x, io);
    let (fr, fm) = rates(p, m, &e);
    dx[V_C] = k.transducer.derivative(x[V_C], io.get(port::V_TERM));
    dx[X_R] = m.outer.derivative(fr);
    dx[V_A] = k.regulator.derivative(x[V_A], e.v_r);
    dx[X_M] = m.inner.derivative(fm);
}

/// The two PI states' limit guards (positive constants for an integrator that does not move).
#[inline(always)]
fn guards<S: Scalar>(p: &Esst4bParams<S>, k: &Consts<S>, m: &Modes, x: &[S], io: &Io<S>, g: &mut [S]) {
    let (fr, fm) = rates(p, m, &eval(p, k, m, x, io));
    if m.outer_integrates {
        m.outer.events(x[X_R], fr, p.vr_min, p.vr_max, &mut g[0..2]);
    } else {
        g[0..2].fill(S::cst(1.0));
    }
    if m.inner_integrates {
        m.inner.events(x[X_M], fm, p.vm_min, p.vm_max, &mut g[2..4]);
    } else {
        g[2..4].fill(S::cst(1.0));
    }
}

impl Esst4b {
    pub fn new(p: Esst4bParams) -> Self {
        Self {
            p,
            ..Default::default()
        }
    }
    /// Voltage reference found at initialisation [pu].
    pub fn v_ref(&self) -> f64 {
        self.k.v_ref
    }
}

impl Block for Esst4b {
    block_common!();

    fn model(&self) -> &'static str {
        MODEL.name
    }
    fn ports(&self) -> &'static [Port] {
        PORTS
    }
    fn state_names(&self) -> &'static [&'static str] {
        &["v_c", "x_r", "v_a", "x_m"]
    }
    fn validate(&self) -> Result<(), ModelError> {
        let p = &self.p;
        for (n, v) in [
            ("t_r", p.t_r),
            ("t_a", p.t_a),
            ("k_pr", p.k_pr),
            ("k_ir", p.k_ir),
            ("k_pm", p.k_pm),
            ("k_im", p.k_im),
            ("k_g", p.k_g),
            ("k_i", p.k_i),
            ("k_c", p.k_c),
            ("x_l", p.x_l),
        ] {
            guard::non_negative(n, v)?;
        }
        guard::positive("k_p", p.k_p)?;
        guard::positive("vb_max", p.vb_max)?;
        guard::finite("theta_p", p.theta_p)?;
        guard::finite("v_ref_offset", p.v_ref_offset)?;
        guard::greater("vr_max", p.vr_max, "vr_min", p.vr_min)?;
        guard::greater("vm_max", p.vm_max, "vm_min", p.vm_min)?;
        if !(p.k_pr > 0.0 || p.k_ir > 0.0) {
            return Err(ModelError::param(
                "k_pr",
                "K_PR = K_IR = 0: the voltage regulator does not act on the voltage error",
            ));
        }
        if !(p.k_pm > 0.0 || p.k_im > 0.0) {
            return Err(ModelError::param(
                "k_pm",
                "K_PM = K_IM = 0: the field regulator does not pass the voltage regulator's output",
            ));
        }
        Ok(())
    }

    fn init(&mut self, _op: &InitPoint, x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        self.validate()?;
        let p = self.p.clone();
        self.k = Consts::new(&p, 0.0);
        self.m.outer = NonWindup::default();
        self.m.inner = NonWindup::default();
        self.m.outer_integrates = p.k_ir > 0.0;
        self.m.inner_integrates = p.k_im > 0.0;
        let efd0 = io.get(port::EFD);
        let v_b = bridge(&p, &self.k, io);
        if !(v_b > 0.0) {
            return Err(ModelError::Init(format!(
                "ESST4B: the bridge cannot supply E_fd0 = {efd0:.4} pu: V_B = V_E·F_EX(I_N) = 0 at t = 0 (V_T = {:.4}, X_adI_fd = {:.4}, KC = {}: I_N ≥ 1)",
                io.get(port::V_SUPPLY),
                io.get(port::XADIFD),
                p.k_c
            )));
        }
        let v_m0 = efd0 / v_b;
        if !(v_m0 >= p.vm_min && v_m0 <= p.vm_max) {
            return Err(ModelError::Init(format!(
                "ESST4B: the field regulator output needed at t = 0, V_M0 = E_fd0/V_B = {efd0:.4}/{v_b:.4} = {v_m0:.4} pu, lies outside [VMMIN, VMMAX] = [{}, {}]",
                p.vm_min, p.vm_max
            )));
        }
        let oel_gate = self.m.oel_gate && !self.m.oel_undriven;
        let voel = io.get(port::VOEL);
        if oel_gate && voel < v_m0 {
            return Err(ModelError::Init(format!(
                "ESST4B: the OEL gate selects V_OEL = {voel:.4} below V_M0 = {v_m0:.4} at t = 0"
            )));
        }
        let v_g0 = p.k_g * efd0;
        let (x_m, v_a0) = if self.m.inner_integrates {
            (v_m0, v_g0)
        } else {
            (0.0, v_m0 / p.k_pm + v_g0)
        };
        if !(v_a0 >= p.vr_min && v_a0 <= p.vr_max) {
            return Err(ModelError::Init(format!(
                "ESST4B: the voltage regulator output needed at t = 0, V_R0 = {v_a0:.4} pu, lies outside [VRMIN, VRMAX] = [{}, {}]",
                p.vr_min, p.vr_max
            )));
        }
        let e_c0 = io.get(port::V_TERM);
        let mut v_ref = e_c0 - io.get(port::VS) - io.get(port::VUEL);
        if !self.m.oel_gate {
            v_ref -= voel;
        }
        self.k.v_ref = v_ref;
        x[V_C] = e_c0;
        x[X_R] = v_a0;
        x[V_A] = v_a0;
        x[X_M] = x_m;
        Ok(())
    }

    #[inline]
    fn outputs(&self, _t: f64, x: &[f64], io: &mut Io) {
        let e = eval(&self.p, &self.k, &self.m, x, io);
        io.set(port::EFD, e.efd);
    }

    #[inline]
    fn derivatives(&self, _t: f64, x: &[f64], io: &Io, dx: &mut [f64]) {
        derivatives(&self.p, &self.k, &self.m, x, io, dx);
    }

    fn init_constants(&self) -> Vec<f64> {
        vec![self.k.v_ref]
    }

    fn seed_dual(&mut self, lanes: &[Option<usize>], consts: &[D]) -> bool {
        let p = self.p.lift_dual(lanes);
        let v_ref = consts.first().copied().unwrap_or(D::cst(self.k.v_ref));
        let k = Consts::new(&p, v_ref);
        self.dual = Some((p, k));
        true
    }

    fn outputs_dual(&self, _t: f64, x: &[D], io: &mut Io<D>) {
        if let Some((p, k)) = &self.dual {
            io.set(port::EFD, eval(p, k, &self.m, x, io).efd);
        }
    }

    fn derivatives_dual(&self, _t: f64, x: &[D], io: &Io<D>, dx: &mut [D]) {
        if let Some((p, k)) = &self.dual {
            derivatives(p, k, &self.m, x, io, dx);
        }
    }

    fn pin_dual(&self, x: &mut [D], _io: &Io<D>) {
        if let Some((p, _)) = &self.dual {
            self.m.outer.pin(&mut x[X_R], p.vr_min, p.vr_max);
            self.m.inner.pin(&mut x[X_M], p.vm_min, p.vm_max);
        }
    }

    fn n_events(&self) -> usize {
        4
    }
    fn events(&self, x: &[f64], io: &Io, g: &mut [f64]) {
        guards(&self.p, &self.k, &self.m, x, io, g);
    }
    fn events_dual(&self, x: &[D], io: &Io<D>, g: &mut [D]) -> bool {
        match &self.dual {
            Some((p, k)) => {
                guards(p, k, &self.m, x, io, g);
                true
            }
            None => false,
        }
    }
    fn update_modes(&mut self, x: &mut [f64], io: &Io) -> bool {
        let (fr, fm) = rates(&self.p, &self.m, &eval(&self.p, &self.k, &self.m, x, io));
        let p = &self.p;
        let mut changed = false;
        if self.m.outer_integrates {
            changed |= self.m.outer.update(&mut x[X_R], fr, p.vr_min, p.vr_max);
        }
        if self.m.inner_integrates {
            changed |= self.m.inner.update(&mut x[X_M], fm, p.vm_min, p.vm_max);
        }
        changed
    }

    fn set_undriven_inputs(&mut self, ports: &[usize]) {
        self.m.oel_undriven = ports.contains(&port::VOEL);
    }

    fn set_option(&mut self, key: &str, value: &str) -> Result<(), ModelError> {
        match (key, value) {
            ("oel", "summing") => self.m.oel_gate = false,
            ("oel", "gate") => self.m.oel_gate = true,
            ("oel", _) => {
                return Err(ModelError::param(
                    key,
                    format!("'{value}': expected \"summing\" or \"gate\""),
                ))
            }
            _ => {
                return Err(ModelError::param(
                    key,
                    "unknown option (ESST4B options: oel)",
                ))
            }
        }
        Ok(())
    }
    fn options(&self) -> Vec<(&'static str, String)> {
        if self.m.oel_gate {
            vec![("oel", "gate".to_string())]
        } else {
            vec![]
        }
    }

    fn exciter_roles(&self) -> Option<ExciterRoles> {
        let mut r = ExciterRoles::none("not applicable to ESST4B");
        r.gain = ParamRole::param("k_pr");
        r.integral_gain = ParamRole::param("k_ir");
        r.field_time_constant = ParamRole::param("t_a");
        r.v_ref_offset = ParamRole::param("v_ref_offset");
        r.ceiling = ParamRole::none(
            "ESST4B's E_fd ceiling is V_B·V_M, the bridge voltage times the field regulator's output, not one parameter (see regulator_ceiling)",
        );
        r.floor = ParamRole::none(
            "ESST4B's E_fd floor is V_B·V_M, not one parameter (see regulator_floor)",
        );
        r.transient_gain_reduction = LeadLagRole::NotApplicable(
            "ESST4B regulates with PI blocks, without a transient gain reduction lead-lag".into(),
        );
        r.supply_ceiling = ParamRole::none(
            "ESST4B's bridge voltage V_E·F_EX scales its whole gain (K_P), not a ceiling alone",
        );
        r.supply_floor = ParamRole::none("ESST4B's floor follows V_B·V_RMIN, not one parameter");
        r.commutation = ParamRole::param("k_c");
        r.regulator_ceiling = ParamRole::param("vr_max");
        r.regulator_floor = ParamRole::param("vr_min");
        Some(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Initialises an ESST4B at `(V_T, P, Q, X_adI_fd, E_fd0)` and returns it with its state.
    fn init_at(p: Esst4bParams, op: [f64; 5]) -> Result<(Esst4b, Vec<f64>, [f64; 9]), ModelError> {
        let [v, pe, qe, ifd, efd] = op;
        let mut b = Esst4b::new(p);
        b.set_undriven_inputs(&[port::VS, port::VOEL, port::VUEL]);
        let mut bus = [v, 0.0, 0.0, 0.0, efd, v, ifd, pe, qe];
        let map: Vec<usize> = (0..9).collect();
        let mut x = vec![0.0; 4];
        let ip = InitPoint {
            v_mag: v,
            v_ang: 0.0,
            p: pe,
            q: qe,
            speed_dev: 0.0,
        };
        b.init(&ip, &mut x, &mut Io::new(&mut bus, &map))?;
        Ok((b, x, bus))
    }

    #[test]
    fn starts_in_steady_state_with_either_field_regulator_and_the_bridge_on_vbmax() {
        // VBMAX 5 is below V_E F_EX ≈ 9.6 at this point: the bridge starts on its limit.
        for (k_im, vb_max) in [(0.0, 11.63), (2.0, 11.63), (0.0, 5.0), (2.0, 5.0)] {
            let p = Esst4bParams {
                k_im,
                vb_max,
                k_g: 0.1,
                k_i: 0.2,
                theta_p: 15.0,
                ..Default::default()
            };
            let (b, x, mut bus) = init_at(p, [1.02, 0.8, 0.3, 2.1, 2.3]).unwrap();
            let map: Vec<usize> = (0..9).collect();
            let mut io = Io::new(&mut bus, &map);
            b.outputs(0.0, &x, &mut io);
            assert!(
                (io.get(port::EFD) - 2.3).abs() < 1e-14,
                "K_IM {k_im}, VBMAX {vb_max}: {}",
                io.get(port::EFD)
            );
            let mut dx = [1.0; 4];
            b.derivatives(0.0, &x, &io, &mut dx);
            assert!(
                dx.iter().all(|d| d.abs() < 1e-13),
                "K_IM {k_im}, VBMAX {vb_max}: {dx:?}"
            );
        }
    }

    #[test]
    fn the_bridge_follows_ieee_421_5_s_loading_curve() {
        // F_EX is continuous at its knots and falls to 0 at I_N = 1.
        for knot in [0.433, 0.75, 1.0] {
            let (a, b) = (fex(knot - 1e-9_f64), fex(knot + 1e-9_f64));
            assert!((a - b).abs() < 1e-3, "F_EX jumps at {knot}: {a} {b}");
        }
        assert_eq!(fex(0.0_f64), 1.0);
        assert_eq!(fex(1.2_f64), 0.0);
        // K_I = X_L = θ_P = 0: V_E = K_P V_T.
        let p = Esst4bParams {
            k_i: 0.0,
            x_l: 0.0,
            k_c: 0.0,
            ..Default::default()
        };
        let k = Consts::new(&p, 0.0);
        let mut bus = [1.0, 0.0, 0.0, 0.0, 0.0, 1.05, 2.0, 0.8, 0.3];
        let map: Vec<usize> = (0..9).collect();
        let io = Io::new(&mut bus, &map);
        assert!((bridge(&p, &k, &io) - 9.3 * 1.05).abs() < 1e-12);
    }

    #[test]
    fn impossible_operating_points_are_refused_naming_the_limit() {
        let e = init_at(
            Esst4bParams {
                vr_max: 0.1,
                ..Default::default()
            },
            [1.0, 0.8, 0.3, 2.0, 2.2],
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("ESST4B") && e.contains("VRMAX"), "{e}");
        let e = init_at(
            Esst4bParams {
                vm_max: 0.1,
                ..Default::default()
            },
            [1.0, 0.8, 0.3, 2.0, 2.2],
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("VMMAX") && e.contains("V_M0"), "{e}");
        let e = init_at(
            Esst4bParams {
                k_c: 6.0,
                ..Default::default()
            },
            [1.0, 0.8, 0.3, 2.0, 2.2],
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("cannot supply"), "{e}");
    }

    #[test]
    fn roles_name_esst4b_parameters() {
        let b = Esst4b::default();
        let r = b.exciter_roles().unwrap();
        r.check(b.params()).unwrap();
        assert_eq!(r.identifiable(), vec!["k_pr", "k_ir", "t_a"]);
    }
}
