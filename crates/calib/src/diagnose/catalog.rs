//! The catalog of causes: the [`Cause`] trait each cause implements (what it looks like in the
//! residual evidence, the extension block that models it, which parameters a re-fit frees — the
//! extension's own, then the unit's parameters it interacts with — and its self-test scenario),
//! the registry [`CAUSES`] (one file per cause in `causes/`), and what every cause shares.
//!
//! One definition serves two uses: [`extend`] builds the extended unit that `diagnose` re-fits,
//! and [`hide`] builds the same extension with chosen values, so that `synth` can hide a cause
//! in the truth of a synthetic event.

use itaipu_dynamics::models::exciter::roles::{ExciterRoles, ParamRole};
use std::collections::BTreeMap;

use itaipu_dynamics::block::Block;
use itaipu_dynamics::registry::{self, Role};
use itaipu_dynamics::unit::Unit;
use serde::Serialize;

use crate::bounds::FreeBound;

/// One entry of the catalog.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct CauseInfo {
    /// Identifier (`torsional_mode`, …), as written in verdicts and on the command line.
    pub id: &'static str,
    /// A short title for tables.
    pub title: &'static str,
    /// What the cause looks like in the residual evidence.
    pub signature: &'static str,
    /// The model extension fitted for it.
    pub extension: &'static str,
    /// The parameters that characterise it (reported in the verdict), extension-relative
    /// (`block.param` inside the extended unit).
    pub key_params: &'static [&'static str],
}

pub use super::causes::CAUSES;

/// A cause of the catalog. Implemented once per cause, in `diagnose/causes/<cause>.rs`, and
/// listed in [`CAUSES`]; the diagnosis, `synth --hide`, the CLI, Python and the self-tests all
/// go through it.
pub trait Cause: Sync {
    /// Its id, title and descriptions.
    fn info(&self) -> &'static CauseInfo;

    /// The part of the unit its extension acts through: where a playback mode cannot show it,
    /// the cause is not applicable ([`Context::not_seen`]).
    fn acts(&self) -> Acts;

    /// Extends `x.unit` (a copy of the unit as given, its machine, exciter, PSS and governor
    /// named in `roles`) with the cause's model and sets what a re-fit frees: the extension's
    /// own parameters, the unit parameters it interacts with, ties, fixed results, the search
    /// length. [`CauseError::NotApplicable`] when the cause cannot apply to this unit or these
    /// events (no exciter, no dip to reach a limit).
    fn extend(&self, x: &mut Extension, roles: &Roles, ctx: &Context) -> Result<(), CauseError>;

    /// How many alternative structures the cause has (e.g. an exciter ceiling that is constant
    /// or follows the supply voltage). Each is re-fitted and the best kept, with one more
    /// discrete parameter in the information criterion when there are several. Default: one.
    fn variants(&self) -> usize {
        1
    }

    /// The extension of variant `variant` (`0..variants()`); variant 0 is [`Cause::extend`].
    fn extend_variant(
        &self,
        x: &mut Extension,
        roles: &Roles,
        ctx: &Context,
        variant: usize,
    ) -> Result<(), CauseError> {
        debug_assert_eq!(variant, 0, "a cause with one structure has one variant");
        self.extend(x, roles, ctx)
    }

    /// The highest frequency the extension's dynamics must reproduce [Hz], when it adds a mode
    /// above the control band (`None`: the machine's, controls' and governor's band, below a few
    /// hertz). A playback whose input is low-passed below it
    /// ([`itaipu_dynamics::event::Event::input_lowpass_hz`]) would remove what drives the mode
    /// with the noise, so the cause's re-fits (its baseline too, and their surrogates) play the
    /// record back as recorded.
    fn band_top_hz(&self, _ctx: &Context) -> Option<f64> {
        None
    }

    /// Features of the evidence that point to the cause (shown in the candidates' table, not
    /// used to rank).
    fn signature(&self, _ev: &[super::EventEvidence], _ctx: &Context) -> Vec<String> {
        vec![]
    }

    /// Why the evidence names the cause by itself, when a re-fit cannot measure it (`None`:
    /// only its gain can name it).
    fn named_by_evidence(&self, _ctx: &Context) -> Option<String> {
        None
    }

    /// Why the fitted extension (its parameters `(path, value)`) is below what the data can
    /// resolve; then it is not named, whatever its gain.
    fn below_resolution(&self, _fitted: &[(String, f64)], _ctx: &Context) -> Option<String> {
        None
    }

    /// Why the fitted extension (its parameters `(path, value)`) is no unit that can exist (a
    /// saturation curve that falls with flux); then it is not named, whatever its gain: an
    /// engineer acts on a named cause's values.
    fn unphysical(&self, _fitted: &[(String, f64)], _ctx: &Context) -> Option<String> {
        None
    }

    /// Why a cause's fitted extension is not named whatever its gain: below what the data
    /// resolve ([`Cause::below_resolution`]) or no physical unit ([`Cause::unphysical`]).
    fn vetoed(&self, fitted: &[(String, f64)], ctx: &Context) -> Option<String> {
        self.below_resolution(fitted, ctx)
            .or_else(|| self.unphysical(fitted, ctx))
    }

    /// The cause's canonical self-test: values hidden in a synthetic truth (`spread(salt)` is a
    /// seeded number in [-1, 1]), the parameter whose recovery is scored and the event that
    /// drives the unit into the cause's regime (see [`super::trial::scenario`]).
    fn scenario(&self, spread: &dyn Fn(u64) -> f64) -> Scenario;
}

/// A cause's self-test scenario ([`Cause::scenario`]).
#[derive(Debug, Clone)]
pub struct Scenario {
    /// `(path, value)` of the extension's parameters in the truth.
    pub values: Vec<(&'static str, f64)>,
    /// The parameter whose recovery is scored, with its tolerance.
    pub key: Option<(&'static str, super::trial::Tolerance)>,
    /// The event that shows the cause.
    pub kind: itaipu_dynamics::synthetic::EventKind,
}

/// The instances of the unit's machine, exciter, PSS and governor.
#[derive(Debug, Clone)]
pub struct Roles {
    pub machine: String,
    pub exciter: Option<String>,
    pub pss: Option<String>,
    pub governor: Option<String>,
}

/// Why a cause's extension was not built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CauseError {
    /// No such cause in the catalog.
    #[error("unknown cause '{0}' (known: {known})", known = ids())]
    Unknown(String),
    /// The cause cannot apply to this unit or these events.
    #[error("{0}")]
    NotApplicable(String),
    /// The extension could not be built (a parameter, a block or a wiring the unit refused).
    #[error("{0}")]
    Build(String),
}

impl CauseError {
    /// Short stable identifier of the variant (`"unknown"`, `"not_applicable"`, `"build"`).
    pub fn kind(&self) -> &'static str {
        match self {
            CauseError::Unknown(_) => "unknown",
            CauseError::NotApplicable(_) => "not_applicable",
            CauseError::Build(_) => "build",
        }
    }

    pub fn not_applicable(why: impl Into<String>) -> Self {
        Self::NotApplicable(why.into())
    }

    pub fn build(why: impl std::fmt::Display) -> Self {
        Self::Build(why.to_string())
    }
}

/// The cause with id `id`.
pub fn cause(id: &str) -> Option<&'static dyn Cause> {
    CAUSES.iter().copied().find(|c| c.info().id == id)
}

/// Looks a cause up by id.
pub fn find(id: &str) -> Option<&'static CauseInfo> {
    cause(id).map(|c| c.info())
}

/// Ids of all causes, for messages.
pub fn ids() -> String {
    CAUSES
        .iter()
        .map(|c| c.info().id)
        .collect::<Vec<_>>()
        .join(", ")
}

/// What the operating point and the evidence tell the catalog about a unit on an event.
#[derive(Debug, Clone, Default)]
pub struct Context {
    /// Field voltage at the pre-event operating point [pu], if the unit has an exciter.
    pub efd0: Option<f64>,
    /// Field current X_adI_fd at the operating point [pu].
    pub xadifd0: Option<f64>,
    /// PMU reporting rate [samples/s].
    pub rate_hz: f64,
    /// Frequency of the dominant oscillation in the P residual above 1 Hz, if any [Hz].
    pub mode_hint_hz: Option<f64>,
    /// A resonance of the P residual in the shaft band that passes [`resonance_stands_out`]
    /// (the most significant over the events), if any.
    pub shaft_resonance: Option<crate::evidence::SpectralPeak>,
    /// Deepest voltage dip of the events after the onset, as a fraction of the pre-event |V|
    /// (`None`: unknown, e.g. when hiding a cause, and no regime is required).
    pub deepest_dip: Option<f64>,
    /// Largest sustained frequency change of the events (last quarter against pre-event) [Hz].
    pub sustained_df_hz: Option<f64>,
    /// Largest rise of the field current X_adI_fd of the unit as given over its pre-event value,
    /// as a fraction (`None`: unknown).
    pub field_current_rise: Option<f64>,
    /// Largest set-point step the events apply to the voltage regulator, as a fraction
    /// (`None`: no step, or a mode that does not play them). At the summing point a step of
    /// the reference by x drives the AVR as a dip of |V| by x does.
    pub setpoint_step: Option<f64>,
    /// How the events are played back ([`super::Playback`]): a cause whose extension does not
    /// act on what the mode compares is not applicable there ([`Context::not_seen`]).
    pub mode: itaipu_dynamics::mode::PlaybackMode,
    /// The compared channels (empty: the phasor playback's P and Q).
    pub compared: Vec<itaipu_dynamics::event::Channel>,
}

impl Context {
    /// Whether the events drive the AVR by at least `x` (a fraction): a dip of |V| or a
    /// set-point step of that size; `true` when the regime is unknown.
    pub fn drives_avr_by(&self, x: f64) -> bool {
        self.deepest_dip.is_none_or(|d| d >= x) || self.setpoint_step.is_some_and(|s| s >= x)
    }

    /// Whether the diagnosis compares channel `c`.
    pub fn compares(&self, c: itaipu_dynamics::event::Channel) -> bool {
        use itaipu_dynamics::event::Channel;
        if self.compared.is_empty() {
            matches!(c, Channel::P | Channel::Q)
        } else {
            self.compared.contains(&c)
        }
    }

    /// Why a cause acting through `acts` (the unit's parts its extension changes) cannot show in
    /// this playback: the part is not simulated in the mode, or nothing it drives is compared.
    /// `None` when it can show (always in the phasor playback, where every part is simulated
    /// and P and Q are compared).
    ///
    /// The machine in `exciter_alone` is driven by the measured E_fd: its magnetic state
    /// reaches the compared E_fd only through the field current of the exciter's commutation
    /// term (K_C·I_fd), a second-order path that cannot determine a machine parameter, so a
    /// machine cause is not tried there.
    pub fn not_seen(&self, acts: Acts) -> Option<String> {
        use itaipu_dynamics::event::Channel::{Efd, Ifd, P, Q, V};
        use itaipu_dynamics::mode::PlaybackMode::*;
        let m = self.mode;
        let any = |cs: &[itaipu_dynamics::event::Channel]| cs.iter().any(|c| self.compares(*c));
        match (acts, m) {
            (_, Phasor) => None,
            (Acts::Exciter, MachineFromEfd) => Some(format!(
                "in mode {m} the measured E_fd drives the machine: the exciter is not simulated"
            )),
            (Acts::Exciter, _) if !any(&[Efd, V, Q, P, Ifd]) => {
                Some(format!("mode {m} compares nothing the exciter drives"))
            }
            (Acts::Machine, ExciterAlone) => Some(format!(
                "in mode {m} the measured E_fd drives the machine, which reaches the compared \
                 E_fd only through the field current of the commutation term"
            )),
            (Acts::Terminal, ExciterAlone) => Some(format!(
                "in mode {m} the measured |V| is imposed and only E_fd is compared: a load at \
                 the terminal changes neither"
            )),
            (Acts::Terminal, _) if !any(&[P, Q, V]) => {
                Some(format!("mode {m} compares neither P, Q nor |V|"))
            }
            (Acts::PowerMeasurement, ClosedLoop) if !any(&[P, Q]) => {
                Some(format!("mode {m} compares neither P nor Q"))
            }
            (Acts::PowerMeasurement, ClosedLoop) => None,
            (Acts::PowerMeasurement, _) => Some(format!(
                "mode {m} does not model the measuring device's P and Q against its voltage"
            )),
            (Acts::Mechanical, _) => Some(format!(
                "in mode {m} the mechanical side is not exercised (P is imposed, or the grid \
                 equivalent's frequency is held)"
            )),
            (Acts::ActivePower, _) if !any(&[P]) => Some(format!(
                "mode {m} does not compare P, where the cause shows"
            )),
            _ => None,
        }
    }
}

/// The part of the unit a cause's extension acts through, for [`Context::not_seen`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Acts {
    /// The exciter (its limits, its limiters).
    Exciter,
    /// The machine's electrical equations (saturation).
    Machine,
    /// A load at the terminal bus, between the machine and the measurement.
    Terminal,
    /// The measuring device's P and Q channels.
    PowerMeasurement,
    /// The turbine and governor, the swing equation.
    Mechanical,
    /// Oscillations of the active power (a shaft's torsional mode, the PSS).
    ActivePower,
}

/// Largest chance that noise alone gives a resonance, for it to name a torsional mode: one in
/// a million (with the band's windows counted), the "very strong" end of the usual scales.
pub const RESONANCE_P: f64 = 1e-6;
/// Smallest prominence of a resonance over its neighbourhood (see
/// [`crate::evidence::SpectralPeak::prominence`]): twice its neighbours' power. The shoulder
/// of a low-frequency misfit leaking into the band has a prominence near or below 1.
pub const RESONANCE_PROMINENCE: f64 = 2.0;

/// Whether a resonance of the P residual is a mode the model lacks rather than noise or leakage.
pub fn resonance_stands_out(p: &crate::evidence::SpectralPeak) -> bool {
    p.p_value < RESONANCE_P && p.prominence >= RESONANCE_PROMINENCE
}

/// Dip from which a high-gain AVR is taken to run to its limits.
pub const LIMIT_DIP: f64 = 0.05;
/// Rise of the field current from which an over-excitation limiter can pick up: a voltage step
/// down that the AVR answers with a sustained field forcing reaches the limiter's pickup
/// (typically 1.05-1.1 × rated, a few percent above a loaded unit's field current) without any
/// dip. Below it, a limiter just above the operating point would only trim a bent AVR gain.
pub const OEL_IFD_RISE: f64 = 0.05;
/// Sustained frequency change from which a governor is taken to act [Hz].
pub const GOVERNOR_DF_HZ: f64 = 0.02;
/// Swarm-length factor of a candidate whose regime the events reach and that re-frees a
/// calibration's bent stage parameters (limits, governor, PSS).
pub const DEEP_SEARCH: usize = 5;

/// A unit extended for one cause, with what to free in the re-fit.
#[derive(Clone)]
pub struct Extension {
    pub cause: &'static str,
    pub unit: Unit,
    /// The extension's own parameters (counted in the information criterion).
    pub extension_free: Vec<FreeBound>,
    /// Parameters of the unit the extension interacts with (freed in the baseline re-fit too).
    pub interacting_free: Vec<FreeBound>,
    /// Structural parameters that are not continuous (e.g. a PSS switched out): counted in the
    /// information criterion on top of `extension_free`.
    pub discrete_params: usize,
    /// `(from, to)`: `to` follows `from` (paths in `unit`).
    pub ties: Vec<(String, String)>,
    /// Human-readable description of what was changed.
    pub description: String,
    /// Fixed results to report (e.g. `pss.in_service = 0`).
    pub fixed: Vec<(String, f64)>,
    /// Multiplier of the swarm's iterations for this candidate (a structural change that moves
    /// many interacting parameters at once needs a longer search).
    pub search_factor: usize,
    /// The re-fit also starts every parameter with a prior at its datasheet value, not only at
    /// its calibrated one, the better kept ([`super::candidates`]'s `fit_extension`). Limits: a
    /// calibration that mimicked a limit bent the unit so that it never reaches the limit, and
    /// there the limit's parameters have no gradient to follow. A measurement skew: the delay
    /// belongs to the PMU, not to the unit, and a calibration that mimicked it bent the unit's
    /// fast dynamics to lag; from the bent unit the delay's re-fit stops in the nearest valley,
    /// at a fraction of the skew, with the bent values still paying their prior.
    pub from_datasheet: bool,
}

impl Extension {
    /// Every parameter a re-fit of the extension frees: its own, then the interacting ones.
    pub fn free(&self) -> impl Iterator<Item = &FreeBound> {
        self.extension_free.iter().chain(&self.interacting_free)
    }
}

fn role_of(block: &dyn Block) -> Role {
    registry::find(block.model()).map_or(Role::Other, |m| m.role)
}

/// The instance name of the block with `role`.
pub fn instance_with_role(unit: &Unit, role: Role) -> Option<String> {
    unit.instances()
        .iter()
        .find(|i| role_of(i.block.as_ref()) == role)
        .map(|i| i.name.clone())
}

pub(crate) fn model_of(unit: &Unit, name: &str) -> String {
    unit.block(name)
        .map(|b| b.model().to_string())
        .unwrap_or_default()
}

pub(crate) fn new_block(model: &str, values: &[(&str, f64)]) -> Result<Box<dyn Block>, CauseError> {
    let info = registry::find(model)
        .ok_or_else(|| CauseError::build(format!("model {model} is not in the registry")))?;
    let mut b = info.create();
    for (name, v) in values {
        let ps = b.params_mut();
        let k = ps
            .index_of(name)
            .ok_or_else(|| CauseError::build(format!("{model} has no parameter {name}")))?;
        ps.set(k, *v);
    }
    Ok(b)
}

pub(crate) fn value(unit: &Unit, path: &str) -> Result<f64, CauseError> {
    unit.param(path)
        .map(|r| unit.get(r))
        .map_err(CauseError::build)
}

pub(crate) fn has_param(unit: &Unit, path: &str) -> bool {
    unit.param(path).is_ok()
}

/// `path` of `unit` (the extended unit) free within its declared range
/// ([`itaipu_dynamics::params::ParamSpec::range`], the plausible range), starting at `start`
/// (clamped): a cause's search range comes from the parameter's declaration. Only ranges that
/// depend on the operating point, the evidence or the PMU rate are computed in a cause's file
/// (with [`fb`]).
pub(crate) fn declared(unit: &Unit, path: &str, start: f64) -> Result<FreeBound, CauseError> {
    FreeBound::declared(unit, path)
        .map(|b| b.starting_at(start))
        .map_err(CauseError::build)
}

/// The declared range (`ParamSpec::range`) of parameter `param` of library model `model`: what
/// [`declared`] frees it within, for a rule that reads a fitted value against it.
pub(crate) fn declared_range(model: &str, param: &str) -> Option<(f64, f64)> {
    let block = itaipu_dynamics::registry::find(model)?.create();
    let p = block.params();
    let i = p.index_of(param)?;
    Some(p.specs()[i].range)
}

/// `param` free within `[min, max]` computed by the cause (from the operating point, the
/// evidence or the PMU rate), starting at `start` (clamped). A range that is empty, upside down
/// or not finite (an operating point that leaves the search no room, a NaN from a unit that
/// does not initialise) is never built: the cause is not applicable, and the note says why.
pub(crate) fn fb(param: &str, min: f64, max: f64, start: f64) -> Result<FreeBound, CauseError> {
    let b = FreeBound::new(param, min, max);
    b.check().map_err(|e| {
        CauseError::not_applicable(format!(
            "no search range for {param} at this operating point: {}",
            e.problem
        ))
    })?;
    Ok(b.starting_at(start))
}

pub(crate) fn scanned(b: FreeBound, points: usize) -> FreeBound {
    b.scanned(points)
}

/// Adds block `name` (the wiring is resolved once all edits are made).
pub(crate) fn add_block(
    unit: &mut Unit,
    name: &str,
    block: Box<dyn Block>,
) -> Result<(), CauseError> {
    unit.add(name, block, &[]).map_err(CauseError::build)
}

/// Rewires ports of the existing instance `name`, keeping its other connections.
pub(crate) fn rewire(
    unit: &mut Unit,
    name: &str,
    ports: &[(&str, &str)],
) -> Result<(), CauseError> {
    let rw: Vec<(String, String)> = ports
        .iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect();
    unit.rewire(name, &rw).map_err(CauseError::build)
}

/// Set-point offsets that every re-fit frees as nuisance parameters (`models.md`: a playback
/// is open loop, and a small error in the initial voltage or speed reference moves the response).
pub const NUISANCE: &[&str] = &["v_ref_offset", "n_ref_offset", "pm_offset"];

/// The unit's nuisance offsets, each within its declared range (widened to hold its value).
pub fn nuisance(unit: &Unit) -> Vec<FreeBound> {
    unit.params()
        .into_iter()
        .filter(|(path, _, _)| NUISANCE.iter().any(|n| path.rsplit('.').next() == Some(*n)))
        .filter_map(|(path, _, _)| FreeBound::requested(unit, &path, None).ok())
        .collect()
}

/// Frees the positive parameter `path` of `u` within `[v/factor, v·factor]` around its value
/// `v`, clipped to the model's declared range (a calibrated value may sit on the bound of the
/// calibration that bent it, so the band is wide). `None` if it does not exist, is not > 0, or
/// leaves no band (an infinite value, a factor of 1 or less): it is then not freed.
pub(crate) fn around(u: &Unit, path: &str, factor: f64) -> Option<FreeBound> {
    let (_, spec, v) = u.params().into_iter().find(|(p, _, _)| p == path)?;
    if !(v > 0.0) {
        return None;
    }
    let lo = (v / factor).max(spec.range.0).min(v);
    let hi = (v * factor).min(spec.range.1).max(v);
    fb(path, lo, hi, v).ok()
}

/// The roles the exciter block `exc` of `u` declares ([`ExciterRoles`]: its model's, or a
/// user diagram's `[exciter_roles]` table): the parameters a cause reasons about by role
/// (gain, field time constant, ceiling, ...), never by one model's names. A block that declares
/// none makes every role not applicable, with the reason.
pub fn exciter_roles(u: &Unit, exc: &str) -> ExciterRoles {
    match u.block(exc) {
        Some(b) => b.exciter_roles().unwrap_or_else(|| {
            ExciterRoles::none(&format!(
                "the exciter model {} declares no exciter roles",
                b.model()
            ))
        }),
        None => ExciterRoles::none("the unit has no exciter"),
    }
}

/// `{exc}.{parameter}` of `role`, or the role's reason as a "not applicable" error (`what`
/// names the role in it, e.g. "a ceiling").
pub(crate) fn role_path(
    u: &Unit,
    exc: &str,
    role: &ParamRole,
    what: &str,
) -> Result<String, CauseError> {
    match role {
        ParamRole::Param(p) => Ok(format!("{exc}.{p}")),
        ParamRole::NotApplicable(why) => Err(CauseError::not_applicable(format!(
            "exciter {} has no {what}: {why}",
            model_of(u, exc)
        ))),
    }
}

/// The exciter's gain and field time constant by role, each freed within `factor` of its value
/// ([`around`]) where the exciter has it: what a calibration without a field-side cause bends.
pub(crate) fn exciter_gain_and_time_constant(u: &Unit, exc: &str, factor: f64) -> Vec<FreeBound> {
    let r = exciter_roles(u, exc);
    [&r.gain, &r.field_time_constant]
        .into_iter()
        .filter_map(|role| role.name().map(|p| format!("{exc}.{p}")))
        .filter_map(|p| around(u, &p, factor))
        .collect()
}

/// The calibrated parameters a calibration without a field-side cause (an exciter limit, an
/// OEL, a saturation curve) bends to make up for it: the exciter's gain and field time constant
/// (by role: SEXS's K and T_E, ST5B's K_R and T_1, ...) within ×3 (a bent value may sit on its
/// calibration's bound), X'_d and H within ×1.6. T'_d0 stays as given (see
/// `trial::NOMINAL_OFFSETS`).
pub(crate) fn field_side(u: &Unit, exciter: Option<&str>, machine: &str) -> Vec<FreeBound> {
    let avr = exciter
        .into_iter()
        .flat_map(|x| exciter_gain_and_time_constant(u, x, 3.0));
    avr.chain(
        [
            around(u, &format!("{machine}.x_d_prime"), 1.6),
            around(u, &format!("{machine}.h"), 1.6),
        ]
        .into_iter()
        .flatten(),
    )
    .collect()
}

/// Builds the extension of `unit` for `cause` ([`Cause::extend`]), with the set-point offsets
/// (nuisance parameters) freed in every re-fit.
pub fn extend(cause_id: &str, unit: &Unit, ctx: &Context) -> Result<Extension, CauseError> {
    extend_variant(cause_id, unit, ctx, 0)
}

/// The extensions of every variant of a cause ([`Cause::variants`]): variant 0's error is the
/// cause's; a later variant that cannot be built is left out.
pub fn extend_all(
    cause_id: &str,
    unit: &Unit,
    ctx: &Context,
) -> Result<Vec<Extension>, CauseError> {
    let c = cause(cause_id).ok_or_else(|| CauseError::Unknown(cause_id.to_string()))?;
    let first = extend_variant(cause_id, unit, ctx, 0)?;
    let mut all = vec![first];
    all.extend((1..c.variants()).filter_map(|v| extend_variant(cause_id, unit, ctx, v).ok()));
    let n = all.len();
    if n > 1 {
        // Choosing among the structures is one more (discrete) parameter.
        for e in &mut all {
            e.discrete_params += 1;
        }
    }
    Ok(all)
}

/// The extension of variant `variant` of a cause.
pub fn extend_variant(
    cause_id: &str,
    unit: &Unit,
    ctx: &Context,
    variant: usize,
) -> Result<Extension, CauseError> {
    let c = cause(cause_id).ok_or_else(|| CauseError::Unknown(cause_id.to_string()))?;
    let info = c.info();
    let mut u = unit.clone();
    u.ensure_finished().map_err(CauseError::build)?;
    let roles = Roles {
        machine: instance_with_role(&u, Role::Machine)
            .ok_or_else(|| CauseError::build("the unit has no machine"))?,
        exciter: instance_with_role(&u, Role::Exciter),
        pss: instance_with_role(&u, Role::Pss),
        governor: instance_with_role(&u, Role::Governor),
    };
    let mut ext = Extension {
        cause: info.id,
        unit: u,
        extension_free: vec![],
        interacting_free: vec![],
        discrete_params: 0,
        ties: vec![],
        description: info.extension.to_string(),
        fixed: vec![],
        search_factor: 1,
        from_datasheet: false,
    };
    c.extend_variant(&mut ext, &roles, ctx, variant)?;
    ext.unit.ensure_finished().map_err(CauseError::build)?;
    free_nuisance(&mut ext);
    Ok(ext)
}

/// Every re-fit also frees the set-point offsets (nuisance parameters) the extension does not
/// free already.
pub(crate) fn free_nuisance(ext: &mut Extension) {
    for n in nuisance(&ext.unit) {
        let known = |v: &Vec<FreeBound>| v.iter().any(|f| f.param == n.param);
        if !known(&ext.extension_free) && !known(&ext.interacting_free) {
            ext.interacting_free.push(n);
        }
    }
}

/// Why a cause cannot be hidden.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HideError {
    /// Unknown cause, unknown or tied parameter: a bad request.
    #[error("{0}")]
    Request(String),
    /// The cause does not apply to this unit (e.g. no exciter for `exciter_limit`).
    #[error("cannot hide {cause} in unit '{unit}': {why}")]
    NotApplicable {
        cause: String,
        unit: String,
        why: String,
    },
    /// The extension could not be built on this unit.
    #[error("{0}")]
    Build(String),
}

impl HideError {
    /// Why `cause`'s extension could not be built on `unit`, as a reason it cannot be hidden.
    pub(crate) fn from_cause(cause: &str, unit: &Unit, e: CauseError) -> HideError {
        match e {
            CauseError::Unknown(_) => HideError::Request(e.to_string()),
            CauseError::NotApplicable(why) => HideError::NotApplicable {
                cause: cause.to_string(),
                unit: unit.name.clone(),
                why,
            },
            CauseError::Build(msg) => HideError::Build(msg),
        }
    }

    /// Short stable identifier of the variant (`"request"`, `"not_applicable"`, `"build"`).
    pub fn kind(&self) -> &'static str {
        match self {
            HideError::Request(_) => "request",
            HideError::NotApplicable { .. } => "not_applicable",
            HideError::Build(_) => "build",
        }
    }
}

/// The parameters a hide of `ext` (built on `unit`) may set: those the extension frees and
/// those of the blocks it adds, except the ones tied to another parameter.
pub fn hideable_params(unit: &Unit, ext: &Extension) -> Vec<String> {
    let old: Vec<&str> = unit.instances().iter().map(|i| i.name.as_str()).collect();
    let mut known: Vec<String> = vec![];
    let candidates = ext.free().map(|f| f.param.clone()).chain(
        ext.unit
            .params()
            .into_iter()
            .map(|(p, _, _)| p)
            .filter(|p| !old.contains(&p.split('.').next().unwrap_or(""))),
    );
    for p in candidates {
        if !known.contains(&p) && !ext.ties.iter().any(|(_, to)| *to == p) {
            known.push(p);
        }
    }
    known
}

/// The unit with `cause` hidden in it: the extension of [`extend`] with `values` set
/// (`block.param` paths among [`hideable_params`], e.g. `shaft.f_torsion_hz`), ties applied.
/// Returns the extension too (what was added, for reports).
pub fn hide(
    cause: &str,
    unit: &Unit,
    ctx: &Context,
    values: &BTreeMap<String, f64>,
) -> Result<(Unit, Extension), HideError> {
    let ext = extend(cause, unit, ctx).map_err(|e| HideError::from_cause(cause, unit, e))?;
    let known = hideable_params(unit, &ext);
    for path in values.keys() {
        if let Some((from, _)) = ext.ties.iter().find(|(_, to)| to == path) {
            return Err(HideError::Request(format!(
                "{cause}: {path} follows {from}; set {from} instead"
            )));
        }
        if !known.contains(path) {
            return Err(HideError::Request(format!(
                "{cause}: unknown parameter '{path}' (its parameters: {})",
                known.join(", ")
            )));
        }
    }
    let u = hidden_unit(&ext, values.iter().map(|(p, v)| (p.as_str(), *v)))?;
    Ok((u, ext))
}

/// The extended unit of `ext` with the cause hidden in it: the extension's parameters at their
/// search start, then `values` (`path`, value) set, then every tied parameter given its
/// leader's value. The paths are not checked against [`hideable_params`] here.
pub(crate) fn hidden_unit<'a>(
    ext: &Extension,
    values: impl IntoIterator<Item = (&'a str, f64)>,
) -> Result<Unit, HideError> {
    let mut u = ext.unit.clone();
    let set = |u: &mut Unit, path: &str, v: f64| -> Result<(), HideError> {
        let r = u.param(path).map_err(|e| HideError::Build(e.to_string()))?;
        u.set(r, v);
        Ok(())
    };
    // Extension parameters start at their search start unless given.
    for f in &ext.extension_free {
        let v = u.get(
            u.param(&f.param)
                .map_err(|e| HideError::Build(e.to_string()))?,
        );
        set(&mut u, &f.param, f.start_from(v))?;
    }
    for (path, v) in values {
        set(&mut u, path, v)?;
    }
    for (from, to) in &ext.ties {
        let v = u.get(u.param(from).map_err(|e| HideError::Build(e.to_string()))?);
        set(&mut u, to, v)?;
    }
    Ok(u)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::trial::base_unit;

    fn ctx(efd0: f64, rate_hz: f64) -> Context {
        Context {
            efd0: Some(efd0),
            xadifd0: Some(2.0),
            rate_hz,
            ..Default::default()
        }
    }

    fn not_applicable(cause: &str, c: &Context) -> String {
        match extend(cause, &base_unit(), c) {
            Err(CauseError::NotApplicable(why)) => why,
            Err(e) => panic!("{cause}: {e:?}"),
            Ok(x) => panic!(
                "{cause}: built with {:?}",
                x.free()
                    .map(|b| (&b.param, b.min, b.max))
                    .collect::<Vec<_>>()
            ),
        }
    }

    /// Issue 25: a range a cause computes from the operating point that leaves no room (an
    /// E_fd0 below the floor's range, a NaN E_fd0 from a unit that does not initialise, a PMU
    /// rate whose Nyquist frequency is below the shaft band) is never built as a bound with
    /// min >= max (`f64::clamp` panicked on some): the cause is not applicable, naming the
    /// parameter. An ordinary operating point builds proper bounds.
    #[test]
    fn a_range_with_no_room_makes_the_cause_not_applicable() {
        let why = not_applicable("exciter_limit", &ctx(f64::NAN, 60.0));
        assert!(why.contains("exciter.e_max"), "{why}");
        let why = not_applicable("exciter_limit", &ctx(-3.0, 60.0));
        assert!(why.contains("exciter.e_min"), "{why}");
        let why = not_applicable("torsional_mode", &ctx(2.0, 4.0));
        assert!(why.contains("shaft.f_torsion_hz"), "{why}");
        for cause in ["exciter_limit", "torsional_mode", "measurement_skew", "oel"] {
            for v in 0..extend_all(cause, &base_unit(), &ctx(2.0, 60.0))
                .unwrap()
                .len()
            {
                let x = extend_variant(cause, &base_unit(), &ctx(2.0, 60.0), v).unwrap();
                for b in x.free() {
                    assert!(b.check().is_ok(), "{cause} ({v}): {b:?}");
                }
            }
        }
    }
}
