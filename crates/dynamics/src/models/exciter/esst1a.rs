//! ESST1A: IEEE 421.5-2005 type ST1A static (bus-fed thyristor) excitation system, as PSS/E's
//! `ESST1A` and OpenIPSL's `Electrical.Controls.PSSE.ES.ESST1A` (cross-checked against ANDES
//! 2.0 `ESST1A`, `tests/andes_exciters.rs`).
//!
//! States: transducer `v_m`, lead-lags `x_ll1` (T_C, T_B) and `x_ll2` (T_C1, T_B1), regulator
//! output `v_a` (non-windup), rate feedback washout `x_f`. E_fd is algebraic (no bridge lag).
//!
//! ```text
//! T_R dV_m/dt = E_comp − V_m                                        (T_R = 0: V_m = E_comp)
//! V_F = (K_F/T_F)(V_X − x_f),   T_F dx_f/dt = V_X − x_f             (rate feedback on V_X)
//! V_I = clamp(V_ref + ΔV_ref − V_m − V_F [+ V_S if VOS = 1] [+ V_UEL if UEL = 1] [+ V_OEL, summing], V_IMIN, V_IMAX)
//! V_1 = max(V_I, V_UEL) if UEL = 2, else V_I                          (HV gate)
//! V_2 = (1 + sT_C)/(1 + sT_B) · (1 + sT_C1)/(1 + sT_B1) · V_1        (T_B = 0: bypassed)
//! T_A dV_A/dt = K_A V_2 − V_A    non-windup in [V_AMIN, V_AMAX]       (T_A = 0: V_A = clamp(K_A V_2), K_F = 0)
//! V_X = V_A − max(0, K_LR (X_adI_fd − I_LR)) [+ V_S if VOS = 2]       (field current limiter)
//! V_3 = max(V_X, V_UEL) if UEL = 3, else V_X                          (HV gate)
//! V_4 = min(V_3, V_OEL) with oel = "gate", else V_3                   (LV gate)
//! E_fd = clamp(V_4, V_T·V_RMIN, V_T·V_RMAX − K_C·X_adI_fd)
//! ```
//!
//! All in pu (E_fd on the machine's field base, X_adI_fd non-reciprocal pu), times in s; nothing
//! depends on the nominal frequency. `V_T` is port `v_supply` (default the played-back |V_t|).
//! The options `uel = "1" | "2" | "3"` and `vos = "1" | "2"` are PSS/E's ICONs (where V_UEL and
//! V_S enter; read from and written to `.dyr`). `oel = "summing"` (default: `voel` added to the
//! error, as SEXS and the summing-point `oel` extension expect) or `"gate"` (PSS/E's LV gate). A
//! gate whose input no block drives stays inactive, as in PSS/E without a limiter model.
//!
//! **Initialisation** (exact, from E_fd0 and X_adI_fd0): `V_X0 = E_fd0`, `x_f = V_X0`,
//! `V_A0 = V_X0 + max(0, K_LR (X_adI_fd0 − I_LR)) [− V_S0 if VOS = 2]`, lead-lag states
//! `= V_A0/K_A`, `V_m0 = E_comp0`, `V_ref = E_comp0 + V_A0/K_A − …` (the summed inputs at t = 0).
//! An error, not a clip, when E_fd0 lies outside `[V_T·V_RMIN, V_T·V_RMAX − K_C·X_adI_fd]`, V_A0
//! outside `[V_AMIN, V_AMAX]`, `V_A0/K_A` outside `[V_IMIN, V_IMAX]`, or a gate selects its
//! limiter at t = 0.
//!
//! **Departures.** The rate feedback is taken on V_X, before the UEL/OEL gates, as OpenIPSL
//! does (ANDES takes it after the gates; the same while the gates are inactive). Lead-lags with
//! `T_B = 0` are bypassed as in PSS/E; OpenIPSL's `LeadLag` requires T_B > 0 unless T_C = T_B.

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port, PortInit};
use crate::models::exciter::blocks::{Lag, LeadLag, ZERO_T};
use crate::models::exciter::roles::{ExciterRoles, LeadLagRole, ParamRole};
use crate::models::limiter::{clamp, NonWindup};
use crate::sens::{Scalar, D};
use crate::{block_common, param_set};
use crate::dyr::{DyrRecord, Icon};
use crate::registry::{ModelInfo, Role};

/// The registry entry ([`crate::registry`]): name, role, `.dyr` record.
pub const MODEL: ModelInfo = ModelInfo {
    name: "ESST1A",
    role: Role::Exciter,
    summary: "IEEE 421.5-2005 ST1A static exciter: bus-fed ceiling with K_C, field current limiter, UEL/VOS input codes",
    reference: "IEEE 421.5-2005 ST1A as PSS/E's ESST1A and OpenIPSL; non-windup V_A, algebraic E_fd limits",
    make: || Box::new(Esst1a::default()),
    dyr: Some(DyrRecord {
        icons: &[
            Icon::Option {
                name: "UEL",
                key: "uel",
                default: "1",
            },
            Icon::Option {
                name: "VOS",
                key: "vos",
                default: "1",
            },
        ],
        cons: &[
            "t_r", "vi_max", "vi_min", "t_c", "t_b", "t_c1", "t_b1", "k_a", "t_a", "va_max",
            "va_min", "vr_max", "vr_min", "k_c", "k_f", "t_f", "k_lr", "i_lr",
        ],
        machine: None,
    }),
};

param_set! {
    /// ESST1A parameters (PSS/E CON order).
    pub struct Esst1aParams {
        t_r: ("TR", "s", 0.02, (0.0, 0.05), "voltage transducer time constant T_R"),
        vi_max: ("VIMAX", "pu", 0.3, (0.1, 1.0), "maximum voltage error (regulator input) V_IMAX"),
        vi_min: ("VIMIN", "pu", -0.3, (-1.0, -0.1), "minimum voltage error (regulator input) V_IMIN"),
        t_c: ("TC", "s", 1.0, (0.0, 5.0), "lead time constant of the first lead-lag T_C"),
        t_b: ("TB", "s", 10.0, (0.0, 20.0), "lag time constant of the first lead-lag T_B"),
        t_c1: ("TC1", "s", 0.0, (0.0, 2.0), "lead time constant of the second lead-lag T_C1"),
        t_b1: ("TB1", "s", 0.0, (0.0, 2.0), "lag time constant of the second lead-lag T_B1"),
        k_a: ("KA", "pu", 200.0, (50.0, 500.0), "regulator gain K_A"),
        t_a: ("TA", "s", 0.02, (0.0, 0.1), "regulator (bridge) time constant T_A"),
        va_max: ("VAMAX", "pu", 7.0, (3.0, 10.0), "regulator maximum output V_AMAX"),
        va_min: ("VAMIN", "pu", -6.0, (-10.0, 0.0), "regulator minimum output V_AMIN"),
        vr_max: ("VRMAX", "pu", 6.0, (3.0, 8.0), "E_fd ceiling per pu supply voltage V_RMAX"),
        vr_min: ("VRMIN", "pu", -5.0, (-7.0, 0.0), "E_fd floor per pu supply voltage V_RMIN"),
        k_c: ("KC", "pu", 0.05, (0.0, 0.3), "rectifier loading factor proportional to the commutating reactance K_C"),
        k_f: ("KF", "pu", 0.0, (0.0, 0.1), "rate feedback gain K_F"),
        t_f: ("TF", "s", 1.0, (0.1, 3.0), "rate feedback time constant T_F"),
        k_lr: ("KLR", "pu", 0.0, (0.0, 10.0), "field current limiter gain K_LR"),
        i_lr: ("ILR", "pu", 4.0, (2.0, 6.0), "field current limiter reference I_LR"),
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
}

const PORTS: &[Port] = &[
    Port::input_ft(
        "v_term",
        PortInit::Needs,
        "compensated terminal voltage E_comp [pu]",
    ),
    Port::input_ft(
        "vs",
        PortInit::Needs,
        "stabiliser signal V_S [pu] (at the error, VOS = 1, or after V_A, VOS = 2)",
    )
    .optional(),
    Port::input_ft(
        "voel",
        PortInit::Needs,
        "over-excitation limiter signal [pu] (summed, or LV gate with oel = \"gate\")",
    )
    .optional(),
    Port::input_ft(
        "vuel",
        PortInit::Needs,
        "under-excitation limiter signal [pu] (summed, UEL = 1, or HV gate, UEL = 2 or 3)",
    )
    .optional(),
    Port::output("efd", PortInit::Needs, "field voltage E_fd [pu]"),
    Port::input_ft(
        "v_supply",
        PortInit::Needs,
        "supply (terminal) voltage V_T of the bridge [pu]",
    )
    .wired("v_term"),
    Port::input_ft("xadifd", PortInit::Needs, "field current X_ad I_fd [pu]"),
];

const V_M: usize = 0;
const X_LL1: usize = 1;
const X_LL2: usize = 2;
const V_A: usize = 3;
const X_F: usize = 4;

/// An ESST1A block. See the module documentation.
#[derive(Debug, Clone)]
pub struct Esst1a {
    pub p: Esst1aParams,
    /// PSS/E ICONs: where V_UEL (1, 2, 3) and V_S (1, 2) enter.
    uel: u8,
    vos: u8,
    oel_gate: bool,
    uel_undriven: bool,
    oel_undriven: bool,
    /// The numbers the initialisation derives (built by [`Block::init`], read with `p`).
    k: Consts,
    limit: NonWindup,
    /// The parameters and the derived numbers on duals, after [`Block::seed_dual`].
    dual: Option<(Esst1aParams<D>, Consts<D>)>,
}

/// The numbers the initialisation derives, on the number type `S`.
#[derive(Debug, Clone, Copy, Default)]
struct Consts<S = f64> {
    v_ref: S,
    transducer: Lag<S>,
    ll1: LeadLag<S>,
    ll2: LeadLag<S>,
    inv_ta: S,
    inv_tf: S,
}

/// The options and the modes of the evaluation (no number in them).
#[derive(Debug, Clone, Copy)]
struct Opts {
    uel: u8,
    vos: u8,
    oel_gate: bool,
    uel_undriven: bool,
    oel_undriven: bool,
    /// `T_A = 0`: V_A is algebraic.
    no_ta: bool,
}

impl Default for Esst1a {
    fn default() -> Self {
        Self::new(Esst1aParams::default())
    }
}

/// The signals of one evaluation.
struct Eval<S> {
    /// Lead-lag inputs and the regulator's input K_A·V_2 target.
    v1: S,
    y1: S,
    v2: S,
    /// V_X (rate feedback input) and E_fd.
    v_x: S,
    efd: S,
}

/// `(E_fd,min, E_fd,max)`.
#[inline(always)]
fn limits<S: Scalar>(p: &Esst1aParams<S>, io: &Io<S>) -> (S, S) {
    let v = io.get(port::V_SUPPLY);
    (v * p.vr_min, v * p.vr_max - p.k_c * io.get(port::XADIFD))
}

/// Field current limiter term `max(0, K_LR (X_adI_fd − I_LR))`.
#[inline(always)]
fn current_limit<S: Scalar>(p: &Esst1aParams<S>, io: &Io<S>) -> S {
    (p.k_lr * (io.get(port::XADIFD) - p.i_lr)).max_s(S::cst(0.0))
}

#[inline(always)]
fn eval<S: Scalar>(p: &Esst1aParams<S>, k: &Consts<S>, o: &Opts, x: &[S], io: &Io<S>) -> Eval<S> {
    let (vs, vuel, voel) = (io.get(port::VS), io.get(port::VUEL), io.get(port::VOEL));
    let uel_gate = o.uel != 1 && !o.uel_undriven;
    let oel_gate = o.oel_gate && !o.oel_undriven;
    let v_m = k.transducer.output(x[V_M], io.get(port::V_TERM));
    // V_X from the states (V_A held by its state unless T_A = 0, handled below).
    let v_f_of = |v_x: S| p.k_f * k.inv_tf * (v_x - x[X_F]);
    let mut v_i = k.v_ref + p.v_ref_offset - v_m;
    if o.vos == 1 {
        v_i += vs;
    }
    if o.uel == 1 {
        v_i += vuel;
    }
    if !o.oel_gate {
        v_i += voel;
    }
    let after_va = |v_a: S| {
        let mut v_x = v_a - current_limit(p, io);
        if o.vos == 2 {
            v_x += vs;
        }
        v_x
    };
    let lead_lags = |v_i: S| {
        let v_i = clamp(v_i, p.vi_min, p.vi_max);
        let v1 = if uel_gate && o.uel == 2 {
            v_i.max_s(vuel)
        } else {
            v_i
        };
        let y1 = k.ll1.output(x[X_LL1], v1);
        (v1, y1, k.ll2.output(x[X_LL2], y1))
    };
    let (v1, y1, v2, v_x) = if o.no_ta {
        // V_A algebraic; no rate feedback then (validated), so no loop through V_F.
        let (v1, y1, v2) = lead_lags(v_i);
        (v1, y1, v2, after_va(clamp(p.k_a * v2, p.va_min, p.va_max)))
    } else {
        let v_x = after_va(x[V_A]);
        let (v1, y1, v2) = lead_lags(v_i - v_f_of(v_x));
        (v1, y1, v2, v_x)
    };
    let mut v = v_x;
    if uel_gate && o.uel == 3 {
        v = v.max_s(vuel);
    }
    if oel_gate {
        v = v.min_s(voel);
    }
    let (lo, hi) = limits(p, io);
    Eval {
        v1,
        y1,
        v2,
        v_x,
        efd: clamp(v, lo, hi),
    }
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn derivatives<S: Scalar>(
    p: &Esst1aParams<S>,
    k: &Consts<S>,
    o: &Opts,
    limit: &NonWindup,
    x: &[S],
    io: &Io<S>,
    dx: &mut [S],
) {
    let e = eval(p, k, o, x, io);
    dx[V_M] = k.transducer.derivative(x[V_M], io.get(port::V_TERM));
    dx[X_LL1] = k.ll1.derivative(x[X_LL1], e.v1);
    dx[X_LL2] = k.ll2.derivative(x[X_LL2], e.y1);
    dx[V_A] = if o.no_ta {
        S::cst(0.0)
    } else {
        limit.derivative(va_rate(p, k, &e, x))
    };
    dx[X_F] = (e.v_x - x[X_F]) * k.inv_tf;
}

/// V_A's unconstrained rate `(K_A v2 − V_A)/T_A` at the evaluated point `e`.
#[inline(always)]
fn va_rate<S: Scalar>(p: &Esst1aParams<S>, k: &Consts<S>, e: &Eval<S>, x: &[S]) -> S {
    (p.k_a * e.v2 - x[V_A]) * k.inv_ta
}

/// V_A's limit guards (none with `T_A = 0`: positive constants).
#[inline(always)]
fn guards<S: Scalar>(
    p: &Esst1aParams<S>,
    k: &Consts<S>,
    o: &Opts,
    limit: &NonWindup,
    x: &[S],
    io: &Io<S>,
    g: &mut [S],
) {
    if o.no_ta {
        g[0] = S::cst(1.0);
        g[1] = S::cst(1.0);
    } else {
        let f = va_rate(p, k, &eval(p, k, o, x, io), x);
        limit.events(x[V_A], f, p.va_min, p.va_max, g);
    }
}

impl Esst1a {
    pub fn new(p: Esst1aParams) -> Self {
        Self {
            p,
            uel: 1,
            vos: 1,
            oel_gate: false,
            uel_undriven: false,
            oel_undriven: false,
            k: Consts::default(),
            limit: NonWindup::default(),
            dual: None,
        }
    }
    /// Voltage reference found at initialisation [pu].
    pub fn v_ref(&self) -> f64 {
        self.k.v_ref
    }

    /// `(E_fd,min, E_fd,max)`.
    #[inline(always)]
    fn limits(&self, io: &Io) -> (f64, f64) {
        limits(&self.p, io)
    }

    /// Field current limiter term `max(0, K_LR (X_adI_fd − I_LR))`.
    #[inline(always)]
    fn current_limit(&self, io: &Io) -> f64 {
        current_limit(&self.p, io)
    }

    #[inline(always)]
    fn opts(&self) -> Opts {
        Opts {
            uel: self.uel,
            vos: self.vos,
            oel_gate: self.oel_gate,
            uel_undriven: self.uel_undriven,
            oel_undriven: self.oel_undriven,
            no_ta: self.k.inv_ta == 0.0,
        }
    }

    #[inline(always)]
    fn eval(&self, x: &[f64], io: &Io) -> Eval<f64> {
        eval(&self.p, &self.k, &self.opts(), x, io)
    }
}

impl Block for Esst1a {
    block_common!();

    fn model(&self) -> &'static str {
        "ESST1A"
    }
    fn ports(&self) -> &'static [Port] {
        PORTS
    }
    fn state_names(&self) -> &'static [&'static str] {
        &["v_m", "x_ll1", "x_ll2", "v_a", "x_f"]
    }
    fn validate(&self) -> Result<(), ModelError> {
        let p = &self.p;
        for (n, v) in [
            ("t_r", p.t_r),
            ("t_c", p.t_c),
            ("t_b", p.t_b),
            ("t_c1", p.t_c1),
            ("t_b1", p.t_b1),
            ("t_a", p.t_a),
            ("k_c", p.k_c),
            ("k_f", p.k_f),
            ("k_lr", p.k_lr),
        ] {
            guard::non_negative(n, v)?;
        }
        guard::positive("k_a", p.k_a)?;
        guard::positive("t_f", p.t_f)?;
        guard::finite("i_lr", p.i_lr)?;
        guard::finite("v_ref_offset", p.v_ref_offset)?;
        guard::greater("vi_max", p.vi_max, "vi_min", p.vi_min)?;
        guard::greater("va_max", p.va_max, "va_min", p.va_min)?;
        guard::greater("vr_max", p.vr_max, "vr_min", p.vr_min)?;
        if p.t_a < ZERO_T && p.k_f > 0.0 {
            // An algebraic regulator closes an algebraic loop through the rate feedback.
            return Err(ModelError::param(
                "t_a",
                format!("T_A = 0 with a rate feedback (K_F = {}) is an algebraic loop: give T_A > 0 or K_F = 0", p.k_f),
            ));
        }
        Ok(())
    }

    fn init(&mut self, _op: &InitPoint, x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        self.validate()?;
        let p = self.p.clone();
        self.k.transducer = Lag::new(p.t_r);
        self.k.ll1 = LeadLag::new(p.t_c, p.t_b);
        self.k.ll2 = LeadLag::new(p.t_c1, p.t_b1);
        self.k.inv_ta = if p.t_a < ZERO_T { 0.0 } else { 1.0 / p.t_a };
        self.k.inv_tf = 1.0 / p.t_f;
        self.limit = NonWindup::default();
        let efd0 = io.get(port::EFD);
        let (lo, hi) = self.limits(io);
        if !(efd0 >= lo && efd0 <= hi) {
            return Err(ModelError::Init(format!(
                "ESST1A: initial field voltage E_fd0 = {efd0:.4} pu lies outside [V_T·VRMIN, V_T·VRMAX − KC·X_adI_fd] = [{lo:.4}, {hi:.4}] (V_T = {:.4}, X_adI_fd = {:.4})",
                io.get(port::V_SUPPLY),
                io.get(port::XADIFD)
            )));
        }
        let (vs, vuel, voel) = (io.get(port::VS), io.get(port::VUEL), io.get(port::VOEL));
        let uel_gate = self.uel != 1 && !self.uel_undriven;
        let oel_gate = self.oel_gate && !self.oel_undriven;
        if oel_gate && voel < efd0 {
            return Err(ModelError::Init(format!(
                "ESST1A: the OEL gate selects V_OEL = {voel:.4} below E_fd0 = {efd0:.4} at t = 0"
            )));
        }
        if uel_gate && self.uel == 3 && vuel > efd0 {
            return Err(ModelError::Init(format!(
                "ESST1A: the UEL gate (UEL = 3) selects V_UEL = {vuel:.4} above E_fd0 = {efd0:.4} at t = 0"
            )));
        }
        let v_x0 = efd0;
        let mut v_a0 = v_x0 + self.current_limit(io);
        if self.vos == 2 {
            v_a0 -= vs;
        }
        if !(v_a0 >= p.va_min && v_a0 <= p.va_max) {
            return Err(ModelError::Init(format!(
                "ESST1A: the regulator output needed at t = 0, V_A0 = {v_a0:.4} pu, lies outside [VAMIN, VAMAX] = [{}, {}]",
                p.va_min, p.va_max
            )));
        }
        let u0 = v_a0 / p.k_a;
        if !(u0 >= p.vi_min && u0 <= p.vi_max) {
            return Err(ModelError::Init(format!(
                "ESST1A: the regulator input needed at t = 0, V_A0/KA = {u0:.4} pu, lies outside [VIMIN, VIMAX] = [{}, {}]",
                p.vi_min, p.vi_max
            )));
        }
        if uel_gate && self.uel == 2 && vuel > u0 {
            return Err(ModelError::Init(format!(
                "ESST1A: the UEL gate (UEL = 2) selects V_UEL = {vuel:.4} above the regulator input {u0:.4} at t = 0"
            )));
        }
        let ecomp0 = io.get(port::V_TERM);
        let mut v_ref = ecomp0 + u0;
        if self.vos == 1 {
            v_ref -= vs;
        }
        if self.uel == 1 {
            v_ref -= vuel;
        }
        if !self.oel_gate {
            v_ref -= voel;
        }
        self.k.v_ref = v_ref;
        x[V_M] = ecomp0;
        x[X_LL1] = u0;
        x[X_LL2] = u0;
        x[V_A] = v_a0;
        x[X_F] = v_x0;
        Ok(())
    }

    #[inline]
    fn outputs(&self, _t: f64, x: &[f64], io: &mut Io) {
        let e = self.eval(x, io);
        io.set(port::EFD, e.efd);
    }

    #[inline]
    fn derivatives(&self, _t: f64, x: &[f64], io: &Io, dx: &mut [f64]) {
        derivatives(&self.p, &self.k, &self.opts(), &self.limit, x, io, dx);
    }

    fn init_constants(&self) -> Vec<f64> {
        vec![self.k.v_ref]
    }

    fn seed_dual(&mut self, lanes: &[Option<usize>], consts: &[D]) -> bool {
        let p = self.p.lift_dual(lanes);
        let k = Consts {
            v_ref: consts.first().copied().unwrap_or(D::cst(self.k.v_ref)),
            transducer: Lag::new(p.t_r),
            ll1: LeadLag::new(p.t_c, p.t_b),
            ll2: LeadLag::new(p.t_c1, p.t_b1),
            inv_ta: if self.k.inv_ta == 0.0 {
                D::cst(0.0)
            } else {
                p.t_a.recip()
            },
            inv_tf: p.t_f.recip(),
        };
        self.dual = Some((p, k));
        true
    }

    fn outputs_dual(&self, _t: f64, x: &[D], io: &mut Io<D>) {
        if let Some((p, k)) = &self.dual {
            io.set(port::EFD, eval(p, k, &self.opts(), x, io).efd);
        }
    }

    fn derivatives_dual(&self, _t: f64, x: &[D], io: &Io<D>, dx: &mut [D]) {
        if let Some((p, k)) = &self.dual {
            derivatives(p, k, &self.opts(), &self.limit, x, io, dx);
        }
    }

    fn pin_dual(&self, x: &mut [D], _io: &Io<D>) {
        if let Some((p, _)) = &self.dual {
            if self.k.inv_ta != 0.0 {
                self.limit.pin(&mut x[V_A], p.va_min, p.va_max);
            }
        }
    }

    fn n_events(&self) -> usize {
        2
    }
    fn events(&self, x: &[f64], io: &Io, g: &mut [f64]) {
        guards(&self.p, &self.k, &self.opts(), &self.limit, x, io, g);
    }
    fn events_dual(&self, x: &[D], io: &Io<D>, g: &mut [D]) -> bool {
        match &self.dual {
            Some((p, k)) => {
                guards(p, k, &self.opts(), &self.limit, x, io, g);
                true
            }
            None => false,
        }
    }
    fn update_modes(&mut self, x: &mut [f64], io: &Io) -> bool {
        if self.k.inv_ta == 0.0 {
            return false;
        }
        let f = va_rate(&self.p, &self.k, &self.eval(x, io), x);
        let (lo, hi) = (self.p.va_min, self.p.va_max);
        self.limit.update(&mut x[V_A], f, lo, hi)
    }

    fn set_undriven_inputs(&mut self, ports: &[usize]) {
        self.uel_undriven = ports.contains(&port::VUEL);
        self.oel_undriven = ports.contains(&port::VOEL);
    }

    fn set_option(&mut self, key: &str, value: &str) -> Result<(), ModelError> {
        match (key, value) {
            ("uel", "1" | "2" | "3") => self.uel = value.parse().expect("digit"),
            ("vos", "1" | "2") => self.vos = value.parse().expect("digit"),
            ("oel", "summing") => self.oel_gate = false,
            ("oel", "gate") => self.oel_gate = true,
            ("uel", _) => {
                return Err(ModelError::param(
                    key,
                    format!("'{value}': PSS/E's UEL code is 1 (summed at the error), 2 (HV gate before the lead-lags) or 3 (HV gate after the regulator)"),
                ))
            }
            ("vos", _) => {
                return Err(ModelError::param(
                    key,
                    format!("'{value}': PSS/E's VOS code is 1 (at the error) or 2 (after the regulator)"),
                ))
            }
            ("oel", _) => {
                return Err(ModelError::param(
                    key,
                    format!("'{value}': expected \"summing\" or \"gate\""),
                ))
            }
            _ => {
                return Err(ModelError::param(
                    key,
                    "unknown option (ESST1A options: uel, vos, oel)",
                ))
            }
        }
        Ok(())
    }
    fn options(&self) -> Vec<(&'static str, String)> {
        let mut o = vec![];
        if self.uel != 1 {
            o.push(("uel", self.uel.to_string()));
        }
        if self.vos != 1 {
            o.push(("vos", self.vos.to_string()));
        }
        if self.oel_gate {
            o.push(("oel", "gate".to_string()));
        }
        o
    }

    fn exciter_roles(&self) -> Option<ExciterRoles> {
        let mut r = ExciterRoles::none("not applicable to ESST1A");
        r.gain = ParamRole::param("k_a");
        r.field_time_constant = ParamRole::param("t_a");
        r.v_ref_offset = ParamRole::param("v_ref_offset");
        r.ceiling = ParamRole::none(
            "ESST1A's ceiling is V_T·VRMAX − KC·X_adI_fd, not one parameter (see supply_ceiling)",
        );
        r.floor =
            ParamRole::none("ESST1A's floor is V_T·VRMIN, not one parameter (see supply_floor)");
        r.transient_gain_reduction = LeadLagRole::LeadLag {
            lead: "t_c".into(),
            lag: "t_b".into(),
        };
        r.supply_ceiling = ParamRole::param("vr_max");
        r.supply_floor = ParamRole::param("vr_min");
        r.commutation = ParamRole::param("k_c");
        r.regulator_ceiling = ParamRole::param("va_max");
        r.regulator_floor = ParamRole::param("va_min");
        Some(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roles_name_esst1a_parameters() {
        let b = Esst1a::default();
        let r = b.exciter_roles().unwrap();
        r.check(b.params()).unwrap();
        assert_eq!(r.gain.name(), Some("k_a"));
        assert_eq!(r.field_time_constant.name(), Some("t_a"));
        assert_eq!(r.transient_gain_reduction.names(), Some(("t_c", "t_b")));
        assert_eq!(r.supply_ceiling.name(), Some("vr_max"));
        assert_eq!(r.commutation.name(), Some("k_c"));
        assert_eq!(r.regulator_ceiling.name(), Some("va_max"));
        assert!(r.ceiling.reason().unwrap().contains("V_T·VRMAX"));
    }

    #[test]
    fn options_are_the_pss_e_icons() {
        let mut b = Esst1a::default();
        assert!(b.options().is_empty());
        b.set_option("uel", "3").unwrap();
        b.set_option("vos", "2").unwrap();
        assert_eq!(
            b.options(),
            vec![("uel", "3".to_string()), ("vos", "2".to_string())]
        );
        assert!(b.set_option("uel", "4").is_err());
        assert!(b.set_option("vos", "0").is_err());
        assert!(b.set_option("gain", "1").is_err());
    }
}
