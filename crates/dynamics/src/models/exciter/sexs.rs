//! SEXS: simplified excitation system (`models.md` §9.1; OpenIPSL `ES/SEXS.mo`, ANDES `sexs.py`).
//!
//! States: lead-lag state `x_ll` and exciter state `x_e` (non-windup in [E_MIN, E_MAX]).
//!
//! ```text
//! v_err = V_ref + ΔV_ref − E_comp + V_S + V_UEL + V_OEL          (E_comp = |V_t|)
//! T_B dx_ll/dt = v_err − x_ll,     y_ll = (T_A/T_B) v_err + (1 − T_A/T_B) x_ll
//! T_E dx_e/dt  = K y_ll − x_e      (derivative frozen at a limit while pushing outwards)
//! E_fd = clamp(x_e, E_MIN, E_MAX)
//! ```
//!
//! Initialisation: `x_e = E_fd0`, `x_ll = E_fd0/K`, `V_ref = E_comp0 − V_S0 − V_UEL0 − V_OEL0 +
//! E_fd0/K`; infeasible (an error, not a clip) when `E_fd0 ∉ [E_MIN, E_MAX]`. `ΔV_ref`
//! (`v_ref_offset`, default 0) is a nuisance parameter a fit may free to absorb a set-point
//! mismatch between model and measurement.
//!
//! The equations live once, in [`SexsModel`], generic over a [`SexsVariant`] that supplies the
//! parameter set and the field-voltage limits: [`Sexs`] (constant `E_MIN`, `E_MAX`) and the
//! bus-fed variant `SEXS_bus_fed` (`models::extensions::sexs_bus_fed`, limits that follow the
//! terminal voltage and the field current, `models.md` §12.3).

use crate::block::{guard, Block, InitPoint, Io, ModelError, Port, PortInit};
use crate::models::exciter::roles::{ExciterRoles, LeadLagRole, ParamRole};
use crate::models::limiter::{clamp, NonWindup};
use crate::params::ParamSet;
use crate::sens::{seeded, Scalar, D};
use crate::{block_common, param_set};

param_set! {
    /// SEXS parameters.
    pub struct SexsParams {
        ta_tb: ("T_AT_B", "-", 0.2, (0.1, 0.3), "ratio of lead to lag time constant T_A/T_B"),
        tb: ("T_B", "s", 10.0, (5.0, 15.0), "lag time constant T_B"),
        k: ("K", "pu", 100.0, (30.0, 400.0), "gain"),
        te: ("T_E", "s", 0.05, (0.02, 0.1), "exciter (bridge) time constant"),
        e_min: ("E_MIN", "pu", 0.0, (-4.0, 0.0), "minimum field voltage"),
        e_max: ("E_MAX", "pu", 4.0, (4.0, 6.0), "maximum field voltage"),
        v_ref_offset: ("dVref", "pu", 0.0, (-0.01, 0.01), "voltage reference offset added after initialisation (nuisance)"),
    }
}

/// Port indices shared by every SEXS variant (a variant may append ports after `EFD`).
pub mod port {
    pub const V_TERM: usize = 0;
    pub const VS: usize = 1;
    pub const VOEL: usize = 2;
    pub const VUEL: usize = 3;
    pub const EFD: usize = 4;
}

/// Ports of SEXS; variants start with the same five.
pub const PORTS: &[Port] = &[
    Port::input(
        "v_term",
        PortInit::Needs,
        "compensated terminal voltage E_comp [pu]",
    ),
    Port::input("vs", PortInit::Needs, "stabiliser signal V_S [pu]").optional(),
    Port::input(
        "voel",
        PortInit::Needs,
        "over-excitation limiter signal (<= 0) [pu]",
    )
    .optional(),
    Port::input(
        "vuel",
        PortInit::Needs,
        "under-excitation limiter signal [pu]",
    )
    .optional(),
    Port::output("efd", PortInit::Needs, "field voltage E_fd [pu]"),
];

/// The parameters every SEXS variant shares, read from its parameter set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SexsGains<S = f64> {
    pub ta_tb: S,
    pub tb: S,
    pub k: S,
    pub te: S,
    pub v_ref_offset: S,
}

/// A SEXS variant's gains and E_fd limits on the number type `S` (`f64`, or [`D`] for
/// forward sensitivities).
pub trait SexsEq<S: Scalar> {
    fn gains(&self) -> SexsGains<S>;
    /// `(E_fd,min, E_fd,max)` at the current point.
    fn limits(&self, io: &Io<S>) -> (S, S);
}

/// What distinguishes one SEXS variant from another: its parameters, ports and E_fd limits.
pub trait SexsVariant:
    SexsEq<f64> + ParamSet + Clone + Default + std::fmt::Debug + Send + Sync + 'static
{
    /// Model name in unit files.
    const MODEL: &'static str;
    /// Ports; the first five are [`PORTS`] (same indices, see [`port`]).
    const PORTS: &'static [Port];
    /// `true` when the limits depend on signals (then the moving-limit logic of
    /// [`NonWindup::derivative_moving`] applies); `false` keeps the plain non-windup logic.
    const MOVING_LIMITS: bool;
    /// The parameters on dual numbers.
    type Lifted: SexsEq<D> + Clone + std::fmt::Debug + Send + Sync + 'static;
    /// Parameter `i` seeded on `lanes[i]`.
    fn lift_dual(&self, lanes: &[Option<usize>]) -> Self::Lifted;
    /// Guards on the limit parameters.
    fn validate_limits(&self) -> Result<(), ModelError>;
    /// How the limits read in an error message, e.g. `[E_MIN, E_MAX] = [0, 4]`.
    fn describe_limits(&self, io: &Io) -> String;
    /// Which parameter plays each exciter role ([`Block::exciter_roles`]).
    fn roles() -> ExciterRoles;
}

/// The roles every SEXS variant shares: `K`, `T_E`, `T_A/T_B` with `T_B`, the offset; the limits
/// are the variant's.
pub fn sexs_roles(model: &str) -> ExciterRoles {
    let mut r = ExciterRoles::none(&format!("not applicable to {model}"));
    r.gain = ParamRole::param("k");
    r.field_time_constant = ParamRole::param("te");
    r.v_ref_offset = ParamRole::param("v_ref_offset");
    r.transient_gain_reduction = LeadLagRole::RatioLag {
        ratio: "ta_tb".into(),
        lag: "tb".into(),
    };
    let no_regulator_limit =
        format!("{model} has no regulator limit: its limits act on the exciter state E_fd");
    r.regulator_ceiling = ParamRole::none(&no_regulator_limit);
    r.regulator_floor = ParamRole::none(no_regulator_limit);
    r
}

impl<S: Scalar> SexsEq<S> for SexsParams<S> {
    #[inline(always)]
    fn gains(&self) -> SexsGains<S> {
        SexsGains {
            ta_tb: self.ta_tb,
            tb: self.tb,
            k: self.k,
            te: self.te,
            v_ref_offset: self.v_ref_offset,
        }
    }
    #[inline(always)]
    fn limits(&self, _io: &Io<S>) -> (S, S) {
        (self.e_min, self.e_max)
    }
}

impl SexsVariant for SexsParams {
    const MODEL: &'static str = "SEXS";
    const PORTS: &'static [Port] = PORTS;
    const MOVING_LIMITS: bool = false;
    type Lifted = SexsParams<D>;
    fn lift_dual(&self, lanes: &[Option<usize>]) -> SexsParams<D> {
        self.lift(|i, v| seeded(v, lanes.get(i).copied().flatten()))
    }
    fn validate_limits(&self) -> Result<(), ModelError> {
        guard::greater("e_max", self.e_max, "e_min", self.e_min)
    }
    fn describe_limits(&self, _io: &Io) -> String {
        format!("[E_MIN, E_MAX] = [{}, {}]", self.e_min, self.e_max)
    }
    fn roles() -> ExciterRoles {
        let mut r = sexs_roles("SEXS");
        r.ceiling = ParamRole::param("e_max");
        r.floor = ParamRole::param("e_min");
        let constant = "SEXS's limits are constant, not fed from the terminal voltage";
        r.supply_ceiling = ParamRole::none(constant);
        r.supply_floor = ParamRole::none(constant);
        r.commutation = ParamRole::none("SEXS has no rectifier commutation term K_C");
        r
    }
}

/// A SEXS exciter block with the limits of variant `V`.
#[derive(Debug, Clone)]
pub struct SexsModel<V: SexsVariant> {
    pub p: V,
    v_ref: f64,
    limit: NonWindup,
    /// 1/T_B and 1/T_E (refreshed at initialisation).
    inv_tb: f64,
    inv_te: f64,
    /// The parameters on dual numbers with V_ref, 1/T_B, 1/T_E, after [`Block::seed_dual`].
    dual: Option<(V::Lifted, [D; 3])>,
}

impl<V: SexsVariant> Default for SexsModel<V> {
    fn default() -> Self {
        Self::new(V::default())
    }
}

/// SEXS with constant limits `[E_MIN, E_MAX]`.
pub type Sexs = SexsModel<SexsParams>;

impl<V: SexsVariant> SexsModel<V> {
    pub fn new(p: V) -> Self {
        Self {
            p,
            v_ref: 0.0,
            limit: NonWindup::default(),
            inv_tb: 0.0,
            inv_te: 0.0,
            dual: None,
        }
    }

    /// Voltage reference found at initialisation [pu].
    pub fn v_ref(&self) -> f64 {
        self.v_ref
    }

    /// `(v_err, y_ll)` at the current point.
    #[inline(always)]
    fn lead_lag(&self, g: &SexsGains, x: &[f64], io: &Io) -> (f64, f64) {
        lead_lag(g, self.v_ref, x, io)
    }

    /// Unconstrained `dx_e/dt` with the exciter state at `x_e`.
    #[inline(always)]
    fn exciter_rate(&self, g: &SexsGains, x: &[f64], io: &Io, x_e: f64) -> f64 {
        (g.k * self.lead_lag(g, x, io).1 - x_e) * self.inv_te
    }
}

/// `(v_err, y_ll)` at the current point.
#[inline(always)]
fn lead_lag<S: Scalar>(g: &SexsGains<S>, v_ref: S, x: &[S], io: &Io<S>) -> (S, S) {
    let v_err = v_ref + g.v_ref_offset - io.get(port::V_TERM)
        + io.get(port::VS)
        + io.get(port::VOEL)
        + io.get(port::VUEL);
    (v_err, g.ta_tb * v_err + g.ta_tb.rsub(1.0) * x[0])
}

/// E_fd at the current point.
#[inline(always)]
fn outputs<S: Scalar>(
    p: &impl SexsEq<S>,
    moving: bool,
    limit: &NonWindup,
    x: &[S],
    io: &mut Io<S>,
) {
    let (lo, hi) = p.limits(io);
    // Never panics (unlike `f64::clamp`): a trial stage of the integrator may compute the
    // moving limits from non-finite signals; the step is then rejected, not the process.
    let efd = if moving {
        clamp(limit.effective(x[1], lo, hi), lo, hi)
    } else {
        limit.output(x[1], lo, hi)
    };
    io.set(port::EFD, efd);
}

/// The state derivatives; `[v_ref, 1/T_B, 1/T_E]`.
#[inline(always)]
fn derivatives<S: Scalar>(
    p: &impl SexsEq<S>,
    moving: bool,
    limit: &NonWindup,
    [v_ref, inv_tb, inv_te]: [S; 3],
    x: &[S],
    io: &Io<S>,
    dx: &mut [S],
) {
    let g = p.gains();
    let (v_err, y_ll) = lead_lag(&g, v_ref, x, io);
    dx[0] = (v_err - x[0]) * inv_tb;
    if moving {
        let (lo, hi) = p.limits(io);
        let f = (g.k * y_ll - limit.effective(x[1], lo, hi)) * inv_te;
        dx[1] = limit.derivative_moving(f, x[1], lo, hi, inv_te);
    } else {
        dx[1] = limit.derivative((g.k * y_ll - x[1]) * inv_te);
    }
}

impl<V: SexsVariant> Block for SexsModel<V> {
    block_common!();

    fn model(&self) -> &'static str {
        V::MODEL
    }
    fn exciter_roles(&self) -> Option<ExciterRoles> {
        Some(V::roles())
    }
    fn ports(&self) -> &'static [Port] {
        V::PORTS
    }
    fn state_names(&self) -> &'static [&'static str] {
        &["x_ll", "x_e"]
    }
    fn validate(&self) -> Result<(), ModelError> {
        let g = self.p.gains();
        guard::non_negative("ta_tb", g.ta_tb)?;
        guard::positive("tb", g.tb)?;
        guard::positive("k", g.k)?;
        guard::positive("te", g.te)?;
        guard::finite("v_ref_offset", g.v_ref_offset)?;
        self.p.validate_limits()
    }

    fn init(&mut self, _op: &InitPoint, x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        self.validate()?;
        let g = self.p.gains();
        let efd0 = io.get(port::EFD);
        let (lo, hi) = self.p.limits(io);
        if !(efd0 >= lo && efd0 <= hi) {
            return Err(ModelError::Init(format!(
                "{}: initial field voltage E_fd0 = {efd0:.4} pu lies outside {}",
                V::MODEL,
                self.p.describe_limits(io)
            )));
        }
        x[1] = efd0;
        x[0] = efd0 / g.k;
        self.v_ref =
            io.get(port::V_TERM) - io.get(port::VS) - io.get(port::VOEL) - io.get(port::VUEL)
                + efd0 / g.k;
        self.limit = NonWindup::default();
        self.inv_tb = 1.0 / g.tb;
        self.inv_te = 1.0 / g.te;
        Ok(())
    }

    #[inline]
    fn outputs(&self, _t: f64, x: &[f64], io: &mut Io) {
        outputs(&self.p, V::MOVING_LIMITS, &self.limit, x, io);
    }

    #[inline]
    fn derivatives(&self, _t: f64, x: &[f64], io: &Io, dx: &mut [f64]) {
        let c = [self.v_ref, self.inv_tb, self.inv_te];
        derivatives(&self.p, V::MOVING_LIMITS, &self.limit, c, x, io, dx);
    }

    fn init_constants(&self) -> Vec<f64> {
        vec![self.v_ref]
    }

    fn seed_dual(&mut self, lanes: &[Option<usize>], consts: &[D]) -> bool {
        let p = self.p.lift_dual(lanes);
        let g = p.gains();
        let v_ref = consts.first().copied().unwrap_or(D::cst(self.v_ref));
        self.dual = Some((p, [v_ref, g.tb.recip(), g.te.recip()]));
        true
    }

    fn outputs_dual(&self, _t: f64, x: &[D], io: &mut Io<D>) {
        if let Some((p, _)) = &self.dual {
            outputs(p, V::MOVING_LIMITS, &self.limit, x, io);
        }
    }

    fn derivatives_dual(&self, _t: f64, x: &[D], io: &Io<D>, dx: &mut [D]) {
        if let Some((p, c)) = &self.dual {
            derivatives(p, V::MOVING_LIMITS, &self.limit, *c, x, io, dx);
        }
    }

    fn pin_dual(&self, x: &mut [D], io: &Io<D>) {
        if let Some((p, _)) = &self.dual {
            let (lo, hi) = p.limits(io);
            self.limit.pin(&mut x[1], lo, hi);
        }
    }

    fn n_events(&self) -> usize {
        2
    }
    fn events(&self, x: &[f64], io: &Io, g: &mut [f64]) {
        let gains = self.p.gains();
        let (lo, hi) = self.p.limits(io);
        if V::MOVING_LIMITS {
            let f = self.exciter_rate(&gains, x, io, self.limit.effective(x[1], lo, hi));
            self.limit.events_moving(x[1], f, lo, hi, g);
        } else {
            self.limit
                .events(x[1], self.exciter_rate(&gains, x, io, x[1]), lo, hi, g);
        }
    }
    fn update_modes(&mut self, x: &mut [f64], io: &Io) -> bool {
        let gains = self.p.gains();
        let (lo, hi) = self.p.limits(io);
        if V::MOVING_LIMITS {
            let mut limit = self.limit;
            let (x_ll, mut x_e) = (x[0], x[1]);
            let changed = limit.update_moving(
                &mut x_e,
                |xe| self.exciter_rate(&gains, &[x_ll, xe], io, xe),
                lo,
                hi,
            );
            self.limit = limit;
            x[1] = x_e;
            changed
        } else {
            let f = self.exciter_rate(&gains, x, io, x[1]);
            self.limit.update(&mut x[1], f, lo, hi)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::exciter::roles::LeadLagRole;

    #[test]
    fn roles_name_sexs_parameters() {
        let b = Sexs::default();
        let r = b.exciter_roles().unwrap();
        r.check(b.params()).unwrap();
        assert_eq!(r.gain.name(), Some("k"));
        assert_eq!(r.field_time_constant.name(), Some("te"));
        assert_eq!(r.ceiling.name(), Some("e_max"));
        assert_eq!(r.floor.name(), Some("e_min"));
        assert_eq!(r.v_ref_offset.name(), Some("v_ref_offset"));
        assert_eq!(
            r.transient_gain_reduction,
            LeadLagRole::RatioLag {
                ratio: "ta_tb".into(),
                lag: "tb".into()
            }
        );
        assert!(r.supply_ceiling.reason().unwrap().contains("constant"));
        assert!(r.regulator_ceiling.name().is_none());
    }
}
