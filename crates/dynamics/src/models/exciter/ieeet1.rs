//! IEEET1: IEEE type 1 (1968) DC-commutator exciter with rate feedback, as PSS/E's `IEEET1`
//! and OpenIPSL's `Electrical.Controls.PSSE.ES.IEEET1` (cross-checked against ANDES 2.0
//! `IEEET1`, `tests/andes_reference.rs`).
//!
//! States: transducer `v_m`, regulator output `v_r` (non-windup), exciter output `e_fd`, rate
//! feedback washout `x_f`.
//!
//! ```text
//! T_R dV_m/dt = E_comp − V_m                               (T_R = 0: V_m = E_comp)
//! V_F = (K_F/T_F)(E_fd − x_f),   T_F dx_f/dt = E_fd − x_f   (rate feedback K_F s/(1 + sT_F) on E_fd)
//! v_err = V_ref + ΔV_ref − V_m + V_S + V_UEL + V_OEL − V_F
//! T_A dV_R/dt = K_A v_err − V_R     non-windup in [V_RMIN, V_RMAX]   (T_A = 0: V_R = clamp(K_A v_err))
//! T_E dE_fd/dt = V_R − (K_E + S_E(E_fd)) E_fd
//! S_E(E) = B (E − A)²/E for E > A, else 0   (PSS/E quadratic through (E_1, SE(E_1)), (E_2, SE(E_2)))
//! ```
//!
//! All in pu (E_fd on the machine's field base), times in s; nothing depends on the nominal
//! frequency. E_fd itself is not limited: its ceiling is where `V_R = V_RMAX` holds it,
//! `(K_E + S_E(E_fd)) E_fd = V_RMAX`.
//!
//! **Initialisation** (exact, from E_fd0): `S_E0 = S_E(E_fd0)`, `V_R0 = (K_E + S_E0) E_fd0`,
//! `x_f = E_fd0` (`V_F = 0`), `V_m0 = E_comp0`, `V_ref = E_comp0 + V_R0/K_A − V_S0 − V_UEL0 −
//! V_OEL0`; an error, not a clip, when `V_R0 ∉ [V_RMIN, V_RMAX]`.
//!
//! PSS/E's automatic DC-exciter parameters, as OpenIPSL's `calculate_dc_exciter_params` (and the
//! older iPSL it comes from) compute them at initialisation, are implemented:
//!
//! * **`KE = 0`**: `K_E` is computed so that the regulator starts at a tenth of its ceiling,
//!   `V_R0 = V_RMAX/10`, i.e. `K_E = V_RMAX/(10 E_fd0) − S_E(E_fd0)` (the effective value is
//!   [`Ieeet1::effective_ke`]; the parameter stays 0, as PSS/E keeps it). This is *not* the
//!   "V_R0 = 0" reading of a self-excited shunt field; OpenIPSL, iPSL and other PSS/E-compatible
//!   codes all use `V_RMAX/10`.
//! * **`VRMAX = 0`**: `V_RMAX = (K_E + SE(E_2)) E_2` (`SE(E_2) E_2` when `K_E ≤ 0`) and
//!   `V_RMIN = −V_RMAX`: the regulator output that holds E_fd at E_2. Current OpenIPSL writes
//!   `SE(E_2) + K_E` (the factor E_2 lost); the older iPSL has `(SE(E_2) + K_E) E_2`, kept here.
//!
//! `SWITCH` (PSS/E CON 10) is read and written back but not used (PSS/E does not use it either).
//! ANDES's IEEET1 differs: it ignores the stabiliser and limiter inputs, keeps `K_E = 0` as 0
//! and replaces `VRMAX = 0` by 999.

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port};
use crate::models::exciter::blocks::{Lag, QuadraticExciterSaturation, ZERO_T};
use crate::models::exciter::roles::{ExciterRoles, LeadLagRole, ParamRole};
use crate::models::exciter::sexs::{port, PORTS};
use crate::models::limiter::{clamp, NonWindup};
use crate::sens::{Scalar, D};
use crate::{block_common, param_set};
use crate::dyr::DyrRecord;
use crate::registry::{ModelInfo, Role};

/// The registry entry ([`crate::registry`]): name, role, `.dyr` record.
pub const MODEL: ModelInfo = ModelInfo {
    name: "IEEET1",
    role: Role::Exciter,
    summary: "IEEE type 1 DC exciter with rate feedback and quadratic saturation",
    reference: "IEEE 1968 type 1 as PSS/E IEEET1 and ANDES IEEET1; non-windup V_R limits",
    make: || Box::new(Ieeet1::default()),
    dyr: Some(DyrRecord::cons(&[
        "t_r", "k_a", "t_a", "vr_max", "vr_min", "k_e", "t_e", "k_f", "t_f", "switch", "e1",
        "se1", "e2", "se2",
    ])),
};

param_set! {
    /// IEEET1 parameters (PSS/E CON order).
    pub struct Ieeet1Params {
        t_r: ("TR", "s", 0.02, (0.0, 0.06), "voltage transducer time constant T_R"),
        k_a: ("KA", "pu", 50.0, (10.0, 400.0), "regulator gain K_A"),
        t_a: ("TA", "s", 0.05, (0.0, 0.5), "regulator time constant T_A"),
        vr_max: ("VRMAX", "pu", 3.5, (1.0, 10.0), "regulator maximum output V_RMAX (0: computed, see the model)"),
        vr_min: ("VRMIN", "pu", -3.5, (-10.0, 0.0), "regulator minimum output V_RMIN"),
        k_e: ("KE", "pu", 1.0, (-0.1, 1.0), "exciter field constant K_E (0: computed so that V_R0 = V_RMAX/10)"),
        t_e: ("TE", "s", 0.8, (0.2, 2.0), "exciter field time constant T_E"),
        k_f: ("KF", "pu", 0.05, (0.0, 0.2), "rate feedback gain K_F"),
        t_f: ("TF", "s", 1.0, (0.3, 3.0), "rate feedback time constant T_F"),
        switch: ("SWITCH", "-", 0.0, (0.0, 1.0), "PSS/E SWITCH (read and written back, not used)"),
        e1: ("E1", "pu", 2.8, (1.0, 6.0), "exciter voltage E_1 of the first saturation point"),
        se1: ("SE1", "-", 0.04, (0.0, 1.0), "saturation factor S_E(E_1)"),
        e2: ("E2", "pu", 3.7, (1.0, 8.0), "exciter voltage E_2 of the second saturation point"),
        se2: ("SE2", "-", 0.33, (0.0, 2.0), "saturation factor S_E(E_2)"),
        v_ref_offset: ("dVref", "pu", 0.0, (-0.01, 0.01), "voltage reference offset added after initialisation (nuisance)"),
    }
}

const V_M: usize = 0;
const V_R: usize = 1;
const E_FD: usize = 2;
const X_F: usize = 3;

/// An IEEET1 block. See the module documentation.
#[derive(Debug, Clone, Default)]
pub struct Ieeet1 {
    pub p: Ieeet1Params,
    /// The numbers the initialisation derives (built by [`Block::init`], read with `p`).
    k: Consts,
    limit: NonWindup,
    /// The parameters and the derived numbers on duals, after [`Block::seed_dual`].
    dual: Option<(Ieeet1Params<D>, Consts<D>)>,
}

/// The numbers the initialisation derives, on the number type `S` (the block's own on `f64`;
/// from the lifted parameters and the initialisation's constants on duals). The equations read
/// them with the parameters.
#[derive(Debug, Clone, Default)]
struct Consts<S = f64> {
    v_ref: S,
    /// K_E, V_RMAX, V_RMIN in use (after PSS/E's automatic rules).
    ke: S,
    vr_max: S,
    vr_min: S,
    sat: QuadraticExciterSaturation<S>,
    transducer: Lag<S>,
    inv_ta: S,
    inv_te: S,
    inv_tf: S,
    /// `T_A = 0`: V_R is algebraic.
    no_ta: bool,
}

impl<S: Scalar> Consts<S> {
    /// Regulator input `K_A v_err` (the unconstrained target of V_R).
    #[inline(always)]
    fn regulator_target(&self, p: &Ieeet1Params<S>, x: &[S], io: &Io<S>) -> S {
        let v_m = self.transducer.output(x[V_M], io.get(port::V_TERM));
        let v_f = p.k_f * self.inv_tf * (x[E_FD] - x[X_F]);
        let v_err = self.v_ref + p.v_ref_offset - v_m
            + io.get(port::VS)
            + io.get(port::VUEL)
            + io.get(port::VOEL)
            - v_f;
        p.k_a * v_err
    }
    /// The regulator limit's guards (none with `T_A = 0`: positive constants).
    #[inline(always)]
    fn guards(&self, p: &Ieeet1Params<S>, limit: &NonWindup, x: &[S], io: &Io<S>, g: &mut [S]) {
        if self.no_ta {
            g[0] = S::cst(1.0);
            g[1] = S::cst(1.0);
        } else {
            let f = (self.regulator_target(p, x, io) - x[V_R]) * self.inv_ta;
            limit.events(x[V_R], f, self.vr_min, self.vr_max, g);
        }
    }
    /// V_R at the current point.
    #[inline(always)]
    fn v_r(&self, p: &Ieeet1Params<S>, x: &[S], io: &Io<S>) -> S {
        if self.no_ta {
            clamp(self.regulator_target(p, x, io), self.vr_min, self.vr_max)
        } else {
            x[V_R]
        }
    }
    #[inline(always)]
    fn derivatives(
        &self,
        p: &Ieeet1Params<S>,
        limit: &NonWindup,
        x: &[S],
        io: &Io<S>,
        dx: &mut [S],
    ) {
        dx[V_M] = self.transducer.derivative(x[V_M], io.get(port::V_TERM));
        dx[V_R] = if self.no_ta {
            S::cst(0.0)
        } else {
            limit.derivative((self.regulator_target(p, x, io) - x[V_R]) * self.inv_ta)
        };
        let e = x[E_FD];
        dx[E_FD] = (self.v_r(p, x, io) - self.ke * e - self.sat.times_e(e)) * self.inv_te;
        dx[X_F] = (e - x[X_F]) * self.inv_tf;
    }
}

impl Ieeet1 {
    pub fn new(p: Ieeet1Params) -> Self {
        Self {
            p,
            ..Default::default()
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
    /// `(V_RMIN, V_RMAX)` in use after initialisation (computed when VRMAX is 0).
    pub fn effective_vr_limits(&self) -> (f64, f64) {
        (self.k.vr_min, self.k.vr_max)
    }

    /// Regulator input `K_A v_err` (the unconstrained target of V_R).
    #[inline(always)]
    fn regulator_target(&self, x: &[f64], io: &Io) -> f64 {
        self.k.regulator_target(&self.p, x, io)
    }
}

impl Block for Ieeet1 {
    block_common!();

    fn model(&self) -> &'static str {
        "IEEET1"
    }
    fn ports(&self) -> &'static [Port] {
        PORTS
    }
    fn state_names(&self) -> &'static [&'static str] {
        &["v_m", "v_r", "e_fd", "x_f"]
    }
    fn validate(&self) -> Result<(), ModelError> {
        let p = &self.p;
        guard::non_negative("t_r", p.t_r)?;
        guard::positive("k_a", p.k_a)?;
        guard::non_negative("t_a", p.t_a)?;
        guard::finite("k_e", p.k_e)?;
        guard::positive("t_e", p.t_e)?;
        guard::non_negative("k_f", p.k_f)?;
        guard::positive("t_f", p.t_f)?;
        guard::finite("switch", p.switch)?;
        guard::finite("v_ref_offset", p.v_ref_offset)?;
        guard::finite("vr_min", p.vr_min)?;
        guard::non_negative("vr_max", p.vr_max)?;
        if p.vr_max != 0.0 {
            guard::greater("vr_max", p.vr_max, "vr_min", p.vr_min)?;
        }
        QuadraticExciterSaturation::new(p.e1, p.se1, p.e2, p.se2)
            .map(|_| ())
            .map_err(|(n, m)| ModelError::param(n, m))
    }

    fn init(&mut self, _op: &InitPoint, x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        self.validate()?;
        let p = self.p.clone();
        self.k.sat = QuadraticExciterSaturation::new(p.e1, p.se1, p.e2, p.se2)
            .map_err(|(n, m)| ModelError::param(n, m))?;
        let efd0 = io.get(port::EFD);
        (self.k.vr_max, self.k.vr_min) = if p.vr_max == 0.0 {
            let se2 = p.se2;
            let vmax = if p.k_e > 0.0 {
                (p.k_e + se2) * p.e2
            } else {
                se2 * p.e2
            };
            (vmax, -vmax)
        } else {
            (p.vr_max, p.vr_min)
        };
        if !(self.k.vr_max > self.k.vr_min) {
            return Err(ModelError::Init(format!(
                "IEEET1: VRMAX = 0 computed from the saturation data gives V_RMAX = {:.4}, no range for the regulator",
                self.k.vr_max
            )));
        }
        let se0 = self.k.sat.factor(efd0);
        self.k.ke = if p.k_e == 0.0 {
            if !(efd0 > 0.0) {
                return Err(ModelError::Init(format!(
                    "IEEET1: KE = 0 asks for K_E = VRMAX/(10·E_fd0) − SE(E_fd0), undefined at E_fd0 = {efd0:.4}"
                )));
            }
            self.k.vr_max / (10.0 * efd0) - se0
        } else {
            p.k_e
        };
        let vr0 = (self.k.ke + se0) * efd0;
        if !(vr0 >= self.k.vr_min && vr0 <= self.k.vr_max) {
            return Err(ModelError::Init(format!(
                "IEEET1: the regulator output needed to hold E_fd0 = {efd0:.4} pu, V_R0 = (KE + SE)·E_fd0 = {vr0:.4} pu, lies outside [VRMIN, VRMAX] = [{}, {}]",
                self.k.vr_min, self.k.vr_max
            )));
        }
        self.k.transducer = Lag::new(p.t_r);
        self.k.inv_ta = if p.t_a < ZERO_T { 0.0 } else { 1.0 / p.t_a };
        self.k.no_ta = self.k.inv_ta == 0.0;
        self.k.inv_te = 1.0 / p.t_e;
        self.k.inv_tf = 1.0 / p.t_f;
        let ecomp0 = io.get(port::V_TERM);
        self.k.v_ref =
            ecomp0 + vr0 / p.k_a - io.get(port::VS) - io.get(port::VUEL) - io.get(port::VOEL);
        x[V_M] = ecomp0;
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
        let k = &self.k;
        vec![k.v_ref, k.ke, k.vr_max, k.vr_min]
    }

    fn seed_dual(&mut self, lanes: &[Option<usize>], consts: &[D]) -> bool {
        let p = self.p.lift_dual(lanes);
        let c = |i: usize, v: f64| consts.get(i).copied().unwrap_or(D::cst(v));
        let Ok(sat) = QuadraticExciterSaturation::new(p.e1, p.se1, p.e2, p.se2) else {
            return false;
        };
        let (k, no_ta) = (&self.k, self.k.no_ta);
        let kd = Consts {
            v_ref: c(0, k.v_ref),
            ke: c(1, k.ke),
            vr_max: c(2, k.vr_max),
            vr_min: c(3, k.vr_min),
            sat,
            transducer: Lag::new(p.t_r),
            inv_ta: if no_ta { D::cst(0.0) } else { p.t_a.recip() },
            inv_te: p.t_e.recip(),
            inv_tf: p.t_f.recip(),
            no_ta,
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

    fn pin_dual(&self, x: &mut [D], _io: &Io<D>) {
        if let Some((_, k)) = &self.dual {
            if !k.no_ta {
                self.limit.pin(&mut x[V_R], k.vr_min, k.vr_max);
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
        if self.k.inv_ta == 0.0 {
            return false;
        }
        let f = (self.regulator_target(x, io) - x[V_R]) * self.k.inv_ta;
        self.limit
            .update(&mut x[V_R], f, self.k.vr_min, self.k.vr_max)
    }

    fn exciter_roles(&self) -> Option<ExciterRoles> {
        let mut r = ExciterRoles::none("not applicable to IEEET1");
        r.gain = ParamRole::param("k_a");
        r.field_time_constant = ParamRole::param("t_e");
        r.v_ref_offset = ParamRole::param("v_ref_offset");
        let not_efd = "IEEET1 limits the regulator output V_R, not E_fd: E_fd's limit is where (KE + SE(E_fd))·E_fd = VRMAX (see regulator_ceiling)";
        r.ceiling = ParamRole::none(not_efd);
        r.floor = ParamRole::none(not_efd.replace(
            "VRMAX (see regulator_ceiling)",
            "VRMIN (see regulator_floor)",
        ));
        r.regulator_ceiling = ParamRole::param("vr_max");
        r.regulator_floor = ParamRole::param("vr_min");
        r.transient_gain_reduction = LeadLagRole::NotApplicable(
            "IEEET1 has no lead-lag: its transient gain reduction is the rate feedback K_F s/(1 + sT_F)"
                .into(),
        );
        let dc = "IEEET1 is a DC exciter: its limits do not scale with the terminal voltage";
        r.supply_ceiling = ParamRole::none(dc);
        r.supply_floor = ParamRole::none(dc);
        r.commutation = ParamRole::none("IEEET1 has no rectifier commutation term K_C");
        Some(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roles_name_ieeet1_parameters() {
        let b = Ieeet1::default();
        let r = b.exciter_roles().unwrap();
        r.check(b.params()).unwrap();
        assert_eq!(r.gain.name(), Some("k_a"));
        assert_eq!(r.field_time_constant.name(), Some("t_e"));
        assert_eq!(r.v_ref_offset.name(), Some("v_ref_offset"));
        assert!(r.ceiling.reason().unwrap().contains("regulator output"));
        assert!(r.floor.reason().unwrap().contains("VRMIN"));
        assert_eq!(r.regulator_ceiling.name(), Some("vr_max"));
        assert_eq!(r.regulator_floor.name(), Some("vr_min"));
        assert!(r
            .transient_gain_reduction
            .reason()
            .unwrap()
            .contains("rate feedback"));
        assert!(r.supply_ceiling.name().is_none() && r.commutation.name().is_none());
    }
}
