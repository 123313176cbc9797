//! IEEEX1: IEEE type 1 DC-commutator exciter with a transient-gain-reduction lead-lag, as PSS/E's
//! `IEEEX1` (the 1979 IEEE type DC1, IEEE 421.5-2016 DC1C without its E_fd limits), cross-checked
//! against ANDES 2.0 `EXDC2` before its speed multiplier (`tests/andes_models.rs`). Its DC2A
//! sibling, PSS/E's `EXDC2` (`exdc2.rs`), is the same block with regulator limits proportional
//! to the terminal voltage ([`Ieeex1::variant`]): the equations live here once.
//!
//! States: transducer `v_m`, lead-lag `x_ll`, regulator output `v_r` (non-windup), exciter output
//! `e_fd`, rate feedback washout `x_f`.
//!
//! ```text
//! T_R dV_m/dt = E_comp − V_m                                (T_R = 0: V_m = E_comp)
//! V_F = (K_F/T_F1)(E_fd − x_f),   T_F1 dx_f/dt = E_fd − x_f  (rate feedback s K_F/(1 + sT_F1) on E_fd)
//! v_err = V_ref + ΔV_ref − V_m + V_S + V_UEL + V_OEL − V_F
//! y_ll = (1 + sT_C)/(1 + sT_B) v_err                         (T_B = 0: y_ll = v_err)
//! T_A dV_R/dt = K_A y_ll − V_R    non-windup in [V_RMIN, V_RMAX]           (IEEEX1)
//!                                 non-windup in [V_T·V_RMIN, V_T·V_RMAX]   (EXDC2)
//!                                 (T_A = 0: V_R = clamp(K_A y_ll))
//! T_E dE_fd/dt = V_R − (K_E + S_E(E_fd)) E_fd
//! S_E(E) = B (E − A)²/E for E > A, else 0   (PSS/E quadratic through (E_1, SE(E_1)), (E_2, SE(E_2)))
//! ```
//!
//! All in pu (E_fd on the machine's field base, V_T the terminal voltage magnitude, port
//! `v_supply`), times in s; nothing depends on the nominal frequency.
//!
//! **Limits.** IEEE 421.5-2016 (DC1C, DC2C) and PSS/E draw V_RMAX/V_RMIN on the regulator lag
//! `K_A/(1 + sT_A)` as a non-windup limit: V_R stops on the limit while its rate pushes outwards
//! and leaves when the rate reverses ([`NonWindup`]; EXDC2's limits move with V_T,
//! [`NonWindup::derivative_moving`]). E_fd itself is not limited (DC1C's optional E_fd ≥ 0
//! clamp, `exclim`, is not part of PSS/E's IEEEX1/EXDC2): its ceiling is where V_R = V_RMAX
//! holds it. ANDES's `EXDC2` and `IEEEX1` use the same non-windup lag (`LagAntiWindup`).
//!
//! **Initialisation** (exact, from E_fd0): `S_E0 = S_E(E_fd0)`, `V_R0 = (K_E + S_E0) E_fd0`,
//! `x_f = E_fd0` (`V_F = 0`), `x_ll = V_R0/K_A`, `V_m0 = E_comp0`, `V_ref = E_comp0 + V_R0/K_A −
//! V_S0 − V_UEL0 − V_OEL0`. An error, not a clip, when `V_R0` lies outside `[V_RMIN, V_RMAX]`
//! (EXDC2: `[V_T0·V_RMIN, V_T0·V_RMAX]`).
//!
//! **KE = 0** follows PSS/E's rule for IEEEX1 and EXDC2: the effective `K_E = −S_E(E_fd0)`, so
//! that the regulator starts at `V_R0 = 0` (a self-excited shunt field whose operator trims the
//! rheostat); the parameter stays 0 ([`Ieeex1::effective_ke`]). Unlike IEEET1, `VRMAX = 0` has
//! no automatic meaning here (refused: `VRMAX > VRMIN` is required).
//!
//! **Departures.** `SWITCH` (PSS/E CON 11) is read and written back but not used (PSS/E does not
//! use it either). ANDES's `EXDC2` multiplies E_fd by the speed (PSS/E's IEEEX1 does not); its
//! `IEEEX1` is PSS/E's EXDC2 (limits `V_T·V_RMAX`, no stabiliser input); its `ESDC1A` leaves its
//! regulator limits at 0.

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port, PortInit};
use crate::dyr::DyrRecord;
use crate::models::exciter::blocks::{Lag, LeadLag, QuadraticExciterSaturation, ZERO_T};
use crate::models::exciter::roles::{ExciterRoles, LeadLagRole, ParamRole};
use crate::models::exciter::sexs::{port, PORTS};
use crate::models::limiter::{clamp, NonWindup};
use crate::params::{ParamSet, ParamSpec};
use crate::registry::{ModelInfo, Role};
use crate::sens::{Scalar, D};
use crate::{block_common, param_set};

/// The registry entry ([`crate::registry`]): name, role, `.dyr` record.
pub const MODEL: ModelInfo = ModelInfo {
    name: "IEEEX1",
    role: Role::Exciter,
    summary: "IEEE type 1 (DC1) DC exciter with lead-lag, rate feedback and quadratic saturation",
    reference: "IEEE 1979 type DC1 as PSS/E IEEEX1, ANDES EXDC2 (no speed factor); non-windup V_R limits",
    make: || Box::new(Ieeex1::default()),
    dyr: Some(DyrRecord::cons(DYR_CONS)),
};

/// PSS/E's CON order of IEEEX1 and EXDC2 (the same record).
pub const DYR_CONS: &[&str] = &[
    "t_r", "k_a", "t_a", "t_b", "t_c", "vr_max", "vr_min", "k_e", "t_e", "k_f", "t_f1", "switch",
    "e1", "se1", "e2", "se2",
];

param_set! {
    /// IEEEX1 parameters (PSS/E CON order; EXDC2's `Exdc2Params` has the same fields). Typical
    /// values: IEEE 421.5-2005 Annex H sample data of DC1A; ranges from the PSS/E manual's
    /// typical data and the Annex's spread of DC exciters.
    pub struct Ieeex1Params {
        t_r: ("TR", "s", 0.0, (0.0, 0.06), "voltage transducer time constant T_R"),
        k_a: ("KA", "pu", 46.0, (10.0, 500.0), "regulator gain K_A"),
        t_a: ("TA", "s", 0.06, (0.0, 0.5), "regulator time constant T_A"),
        t_b: ("TB", "s", 0.0, (0.0, 20.0), "lead-lag lag time constant T_B (0: lead-lag bypassed)"),
        t_c: ("TC", "s", 0.0, (0.0, 10.0), "lead-lag lead time constant T_C"),
        vr_max: ("VRMAX", "pu", 1.0, (0.5, 10.0), "regulator maximum output V_RMAX (EXDC2: times V_T)"),
        vr_min: ("VRMIN", "pu", -0.9, (-10.0, 0.0), "regulator minimum output V_RMIN (EXDC2: times V_T)"),
        k_e: ("KE", "pu", 0.0, (-0.1, 1.0), "exciter field constant K_E (0: computed so that V_R0 = 0)"),
        t_e: ("TE", "s", 0.46, (0.2, 2.0), "exciter field time constant T_E"),
        k_f: ("KF", "pu", 0.1, (0.0, 0.3), "rate feedback gain K_F"),
        t_f1: ("TF1", "s", 1.0, (0.3, 3.0), "rate feedback time constant T_F1"),
        switch: ("SWITCH", "-", 0.0, (0.0, 1.0), "PSS/E SWITCH (read and written back, not used)"),
        e1: ("E1", "pu", 3.1, (1.0, 6.0), "exciter voltage E_1 of the first saturation point"),
        se1: ("SE1", "-", 0.33, (0.0, 1.0), "saturation factor S_E(E_1)"),
        e2: ("E2", "pu", 2.3, (1.0, 8.0), "exciter voltage E_2 of the second saturation point"),
        se2: ("SE2", "-", 0.1, (0.0, 2.0), "saturation factor S_E(E_2)"),
        v_ref_offset: ("dVref", "pu", 0.0, (-0.01, 0.01), "voltage reference offset added after initialisation (nuisance)"),
    }
}

/// Port of EXDC2's supply voltage V_T (after [`PORTS`]' five).
const V_SUPPLY: usize = 5;

/// EXDC2's ports: SEXS's five and the supply (terminal) voltage of its regulator limits.
pub const PORTS_VT: &[Port] = &[
    PORTS[0],
    PORTS[1],
    PORTS[2],
    PORTS[3],
    PORTS[4],
    Port::input(
        "v_supply",
        PortInit::Needs,
        "terminal voltage V_T scaling the regulator limits [pu]",
    )
    .wired("v_term"),
];

const V_M: usize = 0;
const X_LL: usize = 1;
const V_R: usize = 2;
const E_FD: usize = 3;
const X_F: usize = 4;

/// The block's parameters: the values, with the spec table (typical values, ranges) of the
/// model in use, IEEEX1's or EXDC2's (the same fields in the same order). Reads as
/// [`Ieeex1Params`].
#[derive(Debug, Clone)]
pub struct DcParams {
    pub v: Ieeex1Params,
    specs: &'static [ParamSpec],
}

impl Default for DcParams {
    fn default() -> Self {
        Self {
            v: Ieeex1Params::default(),
            specs: Ieeex1Params::SPECS,
        }
    }
}

impl std::ops::Deref for DcParams {
    type Target = Ieeex1Params;
    fn deref(&self) -> &Ieeex1Params {
        &self.v
    }
}

impl std::ops::DerefMut for DcParams {
    fn deref_mut(&mut self) -> &mut Ieeex1Params {
        &mut self.v
    }
}

impl ParamSet for DcParams {
    fn specs(&self) -> &'static [ParamSpec] {
        self.specs
    }
    fn get(&self, index: usize) -> f64 {
        self.v.get(index)
    }
    fn set(&mut self, index: usize, value: f64) {
        self.v.set(index, value)
    }
}

/// An IEEEX1 (or, with V_T-scaled limits, EXDC2) block. See the module documentation.
#[derive(Debug, Clone, Default)]
pub struct Ieeex1 {
    pub p: DcParams,
    /// EXDC2: the regulator limits are `V_T·[V_RMIN, V_RMAX]`.
    vt_limits: bool,
    /// The numbers the initialisation derives (built by [`Block::init`], read with `p`).
    k: Consts,
    limit: NonWindup,
    /// The parameters and the derived numbers on duals, after [`Block::seed_dual`].
    dual: Option<(Ieeex1Params<D>, Consts<D>)>,
}

/// The numbers the initialisation derives, on the number type `S`.
#[derive(Debug, Clone, Default)]
struct Consts<S = f64> {
    v_ref: S,
    /// K_E in use (after PSS/E's KE = 0 rule).
    ke: S,
    sat: QuadraticExciterSaturation<S>,
    transducer: Lag<S>,
    lead_lag: LeadLag<S>,
    inv_ta: S,
    inv_te: S,
    inv_tf: S,
    /// `T_A = 0`: V_R is algebraic.
    no_ta: bool,
    /// EXDC2's V_T-scaled limits.
    vt_limits: bool,
}

impl<S: Scalar> Consts<S> {
    /// The regulator limits `(lo, hi)` at the current point.
    #[inline(always)]
    fn limits(&self, p: &Ieeex1Params<S>, io: &Io<S>) -> (S, S) {
        if self.vt_limits {
            let vt = io.get(V_SUPPLY);
            (vt * p.vr_min, vt * p.vr_max)
        } else {
            (p.vr_min, p.vr_max)
        }
    }
    /// The lead-lag's input `v_err`.
    #[inline(always)]
    fn v_err(&self, p: &Ieeex1Params<S>, x: &[S], io: &Io<S>) -> S {
        let v_m = self.transducer.output(x[V_M], io.get(port::V_TERM));
        let v_f = p.k_f * self.inv_tf * (x[E_FD] - x[X_F]);
        self.v_ref + p.v_ref_offset - v_m + io.get(port::VS) + io.get(port::VUEL) + io.get(port::VOEL)
            - v_f
    }
    /// `K_A y_ll`, the unconstrained target of V_R.
    #[inline(always)]
    fn regulator_target(&self, p: &Ieeex1Params<S>, x: &[S], io: &Io<S>) -> S {
        p.k_a * self.lead_lag.output(x[X_LL], self.v_err(p, x, io))
    }
    /// The unconstrained rate of V_R at the regulator state `v_r`.
    #[inline(always)]
    fn rate(&self, p: &Ieeex1Params<S>, x: &[S], io: &Io<S>, v_r: S) -> S {
        (self.regulator_target(p, x, io) - v_r) * self.inv_ta
    }
    /// V_R as the exciter sees it.
    #[inline(always)]
    fn v_r(&self, p: &Ieeex1Params<S>, limit: &NonWindup, x: &[S], io: &Io<S>) -> S {
        let (lo, hi) = self.limits(p, io);
        if self.no_ta {
            clamp(self.regulator_target(p, x, io), lo, hi)
        } else if self.vt_limits {
            clamp(limit.effective(x[V_R], lo, hi), lo, hi)
        } else {
            limit.output(x[V_R], lo, hi)
        }
    }
    #[inline(always)]
    fn guards(&self, p: &Ieeex1Params<S>, limit: &NonWindup, x: &[S], io: &Io<S>, g: &mut [S]) {
        if self.no_ta {
            g[0] = S::cst(1.0);
            g[1] = S::cst(1.0);
            return;
        }
        let (lo, hi) = self.limits(p, io);
        if self.vt_limits {
            let f = self.rate(p, x, io, limit.effective(x[V_R], lo, hi));
            limit.events_moving(x[V_R], f, lo, hi, g);
        } else {
            limit.events(x[V_R], self.rate(p, x, io, x[V_R]), lo, hi, g);
        }
    }
    #[inline(always)]
    fn derivatives(
        &self,
        p: &Ieeex1Params<S>,
        limit: &NonWindup,
        x: &[S],
        io: &Io<S>,
        dx: &mut [S],
    ) {
        dx[V_M] = self.transducer.derivative(x[V_M], io.get(port::V_TERM));
        dx[X_LL] = self.lead_lag.derivative(x[X_LL], self.v_err(p, x, io));
        dx[V_R] = if self.no_ta {
            S::cst(0.0)
        } else if self.vt_limits {
            let (lo, hi) = self.limits(p, io);
            let f = self.rate(p, x, io, limit.effective(x[V_R], lo, hi));
            limit.derivative_moving(f, x[V_R], lo, hi, self.inv_ta)
        } else {
            limit.derivative(self.rate(p, x, io, x[V_R]))
        };
        let e = x[E_FD];
        dx[E_FD] = (self.v_r(p, limit, x, io) - self.ke * e - self.sat.times_e(e)) * self.inv_te;
        dx[X_F] = (e - x[X_F]) * self.inv_tf;
    }
}

impl Ieeex1 {
    pub fn new(p: Ieeex1Params) -> Self {
        Self {
            p: DcParams {
                v: p,
                specs: Ieeex1Params::SPECS,
            },
            ..Default::default()
        }
    }
    /// A variant of the block: `typical`'s values and spec table (same fields in the same
    /// order as [`Ieeex1Params`]), with V_T-scaled regulator limits when `vt_limits` (EXDC2).
    pub fn variant(typical: &dyn ParamSet, vt_limits: bool) -> Self {
        let mut v = Ieeex1Params::default();
        for i in 0..typical.specs().len() {
            v.set(i, typical.get(i));
        }
        Self {
            p: DcParams {
                v,
                specs: typical.specs(),
            },
            vt_limits,
            ..Default::default()
        }
    }
    fn name(&self) -> &'static str {
        if self.vt_limits {
            "EXDC2"
        } else {
            MODEL.name
        }
    }
    /// Voltage reference found at initialisation [pu].
    pub fn v_ref(&self) -> f64 {
        self.k.v_ref
    }
    /// K_E in use after initialisation (computed when the parameter is 0).
    pub fn effective_ke(&self) -> f64 {
        self.k.ke
    }
}

impl Block for Ieeex1 {
    block_common!();

    fn model(&self) -> &'static str {
        self.name()
    }
    fn ports(&self) -> &'static [Port] {
        if self.vt_limits {
            PORTS_VT
        } else {
            PORTS
        }
    }
    fn state_names(&self) -> &'static [&'static str] {
        &["v_m", "x_ll", "v_r", "e_fd", "x_f"]
    }
    fn validate(&self) -> Result<(), ModelError> {
        let p = &self.p;
        guard::non_negative("t_r", p.t_r)?;
        guard::positive("k_a", p.k_a)?;
        guard::non_negative("t_a", p.t_a)?;
        guard::non_negative("t_b", p.t_b)?;
        guard::non_negative("t_c", p.t_c)?;
        guard::finite("k_e", p.k_e)?;
        guard::positive("t_e", p.t_e)?;
        guard::non_negative("k_f", p.k_f)?;
        guard::positive("t_f1", p.t_f1)?;
        guard::finite("switch", p.switch)?;
        guard::finite("v_ref_offset", p.v_ref_offset)?;
        guard::finite("vr_min", p.vr_min)?;
        guard::greater("vr_max", p.vr_max, "vr_min", p.vr_min)?;
        QuadraticExciterSaturation::new(p.e1, p.se1, p.e2, p.se2)
            .map(|_| ())
            .map_err(|(n, m)| ModelError::param(n, m))
    }

    fn init(&mut self, _op: &InitPoint, x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        self.validate()?;
        let p = self.p.clone();
        let name = self.name();
        self.k.vt_limits = self.vt_limits;
        self.k.sat = QuadraticExciterSaturation::new(p.e1, p.se1, p.e2, p.se2)
            .map_err(|(n, m)| ModelError::param(n, m))?;
        let efd0 = io.get(port::EFD);
        let se0 = self.k.sat.factor(efd0);
        self.k.ke = if p.k_e == 0.0 { -se0 } else { p.k_e };
        let vr0 = (self.k.ke + se0) * efd0;
        let (lo, hi) = self.k.limits(&p, io);
        if !(vr0 >= lo && vr0 <= hi) {
            let which = if self.vt_limits {
                format!(
                    "[V_T·VRMIN, V_T·VRMAX] = [{lo:.4}, {hi:.4}] (V_T = {:.4})",
                    io.get(V_SUPPLY)
                )
            } else {
                format!("[VRMIN, VRMAX] = [{lo}, {hi}]")
            };
            return Err(ModelError::Init(format!(
                "{name}: the regulator output needed to hold E_fd0 = {efd0:.4} pu, V_R0 = (KE + SE(E_fd0))·E_fd0 = {vr0:.4} pu, lies outside {which}"
            )));
        }
        self.k.transducer = Lag::new(p.t_r);
        self.k.lead_lag = LeadLag::new(p.t_c, p.t_b);
        self.k.inv_ta = if p.t_a < ZERO_T { 0.0 } else { 1.0 / p.t_a };
        self.k.no_ta = self.k.inv_ta == 0.0;
        self.k.inv_te = 1.0 / p.t_e;
        self.k.inv_tf = 1.0 / p.t_f1;
        let ecomp0 = io.get(port::V_TERM);
        self.k.v_ref =
            ecomp0 + vr0 / p.k_a - io.get(port::VS) - io.get(port::VUEL) - io.get(port::VOEL);
        x[V_M] = ecomp0;
        x[X_LL] = vr0 / p.k_a;
        x[V_R] = vr0;
        x[E_FD] = efd0;
        x[X_F] = efd0;
        self.limit = NonWindup::default();
        Ok(())
    }

    #[inline]
    fn outputs(&self, _t: f64, x: &[f64], io: &mut Io) {
        io.set(port::EFD, x[E_FD]);
    }

    #[inline]
    fn derivatives(&self, _t: f64, x: &[f64], io: &Io, dx: &mut [f64]) {
        self.k.derivatives(&self.p, &self.limit, x, io, dx);
    }

    fn init_constants(&self) -> Vec<f64> {
        vec![self.k.v_ref, self.k.ke]
    }

    fn seed_dual(&mut self, lanes: &[Option<usize>], consts: &[D]) -> bool {
        let p = self.p.lift_dual(lanes);
        let c = |i: usize, v: f64| consts.get(i).copied().unwrap_or(D::cst(v));
        let Ok(sat) = QuadraticExciterSaturation::new(p.e1, p.se1, p.e2, p.se2) else {
            return false;
        };
        let k = &self.k;
        let kd = Consts {
            v_ref: c(0, k.v_ref),
            ke: c(1, k.ke),
            sat,
            transducer: Lag::new(p.t_r),
            lead_lag: LeadLag::new(p.t_c, p.t_b),
            inv_ta: if k.no_ta { D::cst(0.0) } else { p.t_a.recip() },
            inv_te: p.t_e.recip(),
            inv_tf: p.t_f1.recip(),
            no_ta: k.no_ta,
            vt_limits: k.vt_limits,
        };
        self.dual = Some((p, kd));
        true
    }

    fn outputs_dual(&self, _t: f64, x: &[D], io: &mut Io<D>) {
        io.set(port::EFD, x[E_FD]);
    }

    fn derivatives_dual(&self, _t: f64, x: &[D], io: &Io<D>, dx: &mut [D]) {
        if let Some((p, k)) = &self.dual {
            k.derivatives(p, &self.limit, x, io, dx);
        }
    }

    fn pin_dual(&self, x: &mut [D], io: &Io<D>) {
        if let Some((p, k)) = &self.dual {
            if !k.no_ta {
                let (lo, hi) = k.limits(p, io);
                self.limit.pin(&mut x[V_R], lo, hi);
            }
        }
    }

    fn moving_pins(&self, _x: &[f64], io: &Io, out: &mut Vec<(usize, f64)>) {
        if self.vt_limits && !self.k.no_ta {
            let (lo, hi) = self.k.limits(&self.p, io);
            out.extend(self.limit.pinned_to(lo, hi).map(|v| (V_R, v)));
        }
    }

    fn moving_pins_dual(&self, _x: &[D], io: &Io<D>, out: &mut Vec<(usize, D)>) {
        if let (true, Some((p, k))) = (self.vt_limits, &self.dual) {
            if !k.no_ta {
                let (lo, hi) = k.limits(p, io);
                out.extend(self.limit.pinned_to(lo, hi).map(|v| (V_R, v)));
            }
        }
    }

    fn n_events(&self) -> usize {
        2
    }
    fn events(&self, x: &[f64], io: &Io, g: &mut [f64]) {
        self.k.guards(&self.p, &self.limit, x, io, g);
    }
    fn events_dual(&self, x: &[D], io: &Io<D>, g: &mut [D]) -> bool {
        match &self.dual {
            Some((p, k)) => {
                k.guards(p, &self.limit, x, io, g);
                true
            }
            None => false,
        }
    }
    fn update_modes(&mut self, x: &mut [f64], io: &Io) -> bool {
        if self.k.no_ta {
            return false;
        }
        let (lo, hi) = self.k.limits(&self.p, io);
        if self.vt_limits {
            let mut limit = self.limit;
            let mut v_r = x[V_R];
            // The regulator's target does not depend on V_R itself.
            let target = self.k.regulator_target(&self.p, x, io);
            let inv_ta = self.k.inv_ta;
            let changed = limit.update_moving(&mut v_r, |v| (target - v) * inv_ta, lo, hi);
            self.limit = limit;
            x[V_R] = v_r;
            changed
        } else {
            let f = self.k.rate(&self.p, x, io, x[V_R]);
            self.limit.update(&mut x[V_R], f, lo, hi)
        }
    }

    fn exciter_roles(&self) -> Option<ExciterRoles> {
        let name = self.name();
        let mut r = ExciterRoles::none(&format!("not applicable to {name}"));
        r.gain = ParamRole::param("k_a");
        r.field_time_constant = ParamRole::param("t_e");
        r.v_ref_offset = ParamRole::param("v_ref_offset");
        let not_efd = format!("{name} limits the regulator output V_R, not E_fd: E_fd's limit is where (KE + SE(E_fd))·E_fd = V_R's limit (see regulator_ceiling, regulator_floor)");
        r.ceiling = ParamRole::none(not_efd.clone());
        r.floor = ParamRole::none(not_efd);
        r.regulator_ceiling = ParamRole::param("vr_max");
        r.regulator_floor = ParamRole::param("vr_min");
        r.transient_gain_reduction = LeadLagRole::LeadLag {
            lead: "t_c".into(),
            lag: "t_b".into(),
        };
        let supply = if self.vt_limits {
            "EXDC2 scales its regulator limits (not an E_fd limit) by V_T: see regulator_ceiling"
                .to_string()
        } else {
            format!("{name} is a DC exciter: its limits do not scale with the terminal voltage")
        };
        r.supply_ceiling = ParamRole::none(supply.clone());
        r.supply_floor = ParamRole::none(supply);
        r.commutation = ParamRole::none(format!("{name} has no rectifier commutation term K_C"));
        Some(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MAP: [usize; 6] = [0, 1, 2, 3, 4, 5];
    const OP: InitPoint = InitPoint {
        v_mag: 1.0,
        v_ang: 0.0,
        p: 0.8,
        q: 0.2,
        speed_dev: 0.0,
    };

    /// The bus of ports E_comp, V_S, V_OEL, V_UEL, E_fd, V_T at an operating point.
    fn bus_at(vt: f64, efd: f64) -> [f64; 6] {
        [vt, 0.0, 0.0, 0.0, efd, vt]
    }

    /// Initialises `b` at the bus `bus`; the states, or the refusal's message.
    fn init_at(b: &mut Ieeex1, bus: &mut [f64; 6]) -> Result<Vec<f64>, String> {
        let mut x = vec![0.0; 5];
        b.init(&OP, &mut x, &mut Io::new(bus, &MAP))
            .map_err(|e| e.to_string())?;
        Ok(x)
    }

    fn derivative_norm(b: &Ieeex1, x: &[f64], bus: &mut [f64; 6]) -> f64 {
        let mut dx = vec![0.0; 5];
        b.derivatives(0.0, x, &Io::new(bus, &MAP), &mut dx);
        dx.iter().fold(0.0f64, |a, d| a.max(d.abs()))
    }

    #[test]
    fn ke_zero_starts_the_regulator_at_zero_in_saturation() {
        let mut b = Ieeex1::default();
        b.p.t_b = 10.0;
        b.p.t_c = 1.0;
        let mut bus = bus_at(1.02, 3.4);
        let x = init_at(&mut b, &mut bus).unwrap();
        // E_fd0 = 3.4 > E_1: saturated, so K_E = −S_E(E_fd0) < 0 and V_R0 = 0.
        assert!(b.effective_ke() < -0.3, "{}", b.effective_ke());
        assert!(x[V_R].abs() < 1e-15);
        assert!(derivative_norm(&b, &x, &mut bus) < 1e-12);
    }

    #[test]
    fn exdc2_limits_scale_with_the_terminal_voltage() {
        let mut b = crate::models::exciter::exdc2::exdc2();
        b.p.vr_max = 3.0;
        // V_R0 = (1 + S_E(2.5))·2.5 ≈ 2.9: inside 3·V_T at V_T = 1, outside at V_T = 0.9.
        let mut bus = bus_at(1.0, 2.5);
        let x = init_at(&mut b, &mut bus).unwrap();
        assert!(x[V_R] > 2.85 && x[V_R] < 2.95, "{}", x[V_R]);
        assert!(derivative_norm(&b, &x, &mut bus) < 1e-12);
        let mut low = bus_at(0.9, 2.5);
        let msg = init_at(&mut b, &mut low).unwrap_err();
        assert!(msg.contains("EXDC2") && msg.contains("V_T·VRMAX"), "{msg}");
        // IEEEX1 with the same data does not scale: it starts at V_T = 0.9.
        init_at(&mut Ieeex1::new(b.p.v.clone()), &mut low).unwrap();
    }

    #[test]
    fn an_impossible_regulator_output_is_refused_naming_the_limit() {
        let mut b = Ieeex1::default();
        b.p.k_e = 1.0;
        let msg = init_at(&mut b, &mut bus_at(1.0, 2.0)).unwrap_err();
        assert!(
            msg.contains("IEEEX1") && msg.contains("[VRMIN, VRMAX] = [-0.9, 1]"),
            "{msg}"
        );
    }

    #[test]
    fn roles_name_ieeex1_and_exdc2_parameters() {
        for b in [Ieeex1::default(), crate::models::exciter::exdc2::exdc2()] {
            let r = b.exciter_roles().unwrap();
            r.check(b.params()).unwrap();
            assert_eq!(r.gain.name(), Some("k_a"));
            assert_eq!(r.field_time_constant.name(), Some("t_e"));
            assert_eq!(r.regulator_ceiling.name(), Some("vr_max"));
            assert_eq!(r.regulator_floor.name(), Some("vr_min"));
            assert!(r.ceiling.reason().unwrap().contains("regulator output"));
            assert_eq!(r.transient_gain_reduction.names(), Some(("t_c", "t_b")));
            assert_eq!(
                r.identifiable(),
                vec!["k_a", "t_e", "t_c", "t_b"]
            );
        }
    }
}
