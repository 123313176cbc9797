//! What a cause is: the [`Cause`] trait every cause implements, the built-in ones (one file per
//! cause in `causes/`) and those read from cause files ([`super::user_cause`]) alike; the
//! extension a cause builds ([`Extension`]) and how it is built from a unit ([`extend_cause`]);
//! why one cannot be ([`CauseError`], [`HideError`]).
//!
//! One definition serves two uses: [`extend_cause`] builds the extended unit that `diagnose`
//! re-fits, and [`hidden_unit`] the same extension with chosen values, so that `synth` can hide
//! a cause in the truth of a synthetic event.

use itaipu_dynamics::block::Block;
use itaipu_dynamics::registry::{self, Role};
use itaipu_dynamics::unit::Unit;
use serde::Serialize;

use crate::bounds::FreeBound;

pub use super::context::{Acts, Context};
pub use super::not_applicable::NotApplicable;
use super::report::EventEvidence;

/// What a cause is called and how it is described.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct CauseInfo<'a> {
    /// Identifier (`torsional_mode`, …), as written in verdicts and on the command line.
    pub id: &'a str,
    /// A short title for tables.
    pub title: &'a str,
    /// What the cause looks like in the residual evidence.
    pub signature: &'a str,
    /// The model extension fitted for it.
    pub extension: &'a str,
    /// The parameters that characterise it (reported in the verdict), extension-relative
    /// (`block.param` inside the extended unit).
    pub key_params: &'a [&'a str],
}

/// A cause of the diagnosis. Implemented once per built-in cause, in
/// `diagnose/causes/<cause>.rs` and listed in [`super::catalog::CAUSES`], and by every cause
/// file ([`super::user_cause::UserCause`]); the diagnosis, `synth --hide`, the CLI, Python and
/// the self-tests all go through it.
pub trait Cause: Sync {
    /// Its id, title and descriptions.
    fn info(&self) -> CauseInfo<'_>;

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
    fn signature(&self, _ev: &[EventEvidence], _ctx: &Context) -> Vec<String> {
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

    /// The cause's canonical self-test, when it has one (the built-in causes do): values hidden
    /// in a synthetic truth (`spread(salt)` is a seeded number in [-1, 1]), the parameter whose
    /// recovery is scored and the event that drives the unit into the cause's regime (see
    /// [`super::trial::scenario`]).
    fn scenario(&self, _spread: &dyn Fn(u64) -> f64) -> Option<Scenario> {
        None
    }
}

/// A cause's self-test scenario ([`Cause::scenario`]).
#[derive(Debug, Clone)]
pub struct Scenario {
    /// `(path, value)` of the extension's parameters in the truth.
    pub values: Vec<(&'static str, f64)>,
    /// The parameter whose recovery is scored, with its tolerance.
    pub key: Option<(&'static str, Tolerance)>,
    /// The event that shows the cause.
    pub kind: itaipu_dynamics::synthetic::EventKind,
}

/// Tolerance on a recovered parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Tolerance {
    /// `|x − truth| ≤ r·|truth|`.
    Rel(f64),
    /// `|x − truth| ≤ a`.
    Abs(f64),
}

/// The instances of the unit's machine, exciter, PSS and governor.
#[derive(Debug, Clone)]
pub struct Roles {
    pub machine: String,
    pub exciter: Option<String>,
    pub pss: Option<String>,
    pub governor: Option<String>,
}

impl Roles {
    /// The roles' instances in `unit`; a unit without a machine has none.
    fn of(unit: &Unit) -> Result<Self, CauseError> {
        Ok(Roles {
            machine: instance_with_role(unit, Role::Machine)
                .ok_or_else(|| CauseError::build("the unit has no machine"))?,
            exciter: instance_with_role(unit, Role::Exciter),
            pss: instance_with_role(unit, Role::Pss),
            governor: instance_with_role(unit, Role::Governor),
        })
    }
}

/// Why a cause's extension was not built. Its message is written beside the registry
/// (`catalog.rs`), which an unknown id's message lists.
#[derive(Debug, Clone, PartialEq)]
pub enum CauseError {
    /// No such cause (the id asked for).
    Unknown(String),
    /// The cause cannot apply to this unit, this playback or these events.
    NotApplicable(NotApplicable),
    /// The extension could not be built (a parameter, a block or a wiring the unit refused).
    Build(String),
}

impl std::error::Error for CauseError {}

impl CauseError {
    /// Short stable identifier of the variant (`"unknown"`, `"not_applicable"`, `"build"`).
    pub fn kind(&self) -> &'static str {
        match self {
            CauseError::Unknown(_) => "unknown",
            CauseError::NotApplicable(_) => "not_applicable",
            CauseError::Build(_) => "build",
        }
    }

    pub fn build(why: impl std::fmt::Display) -> Self {
        Self::Build(why.to_string())
    }
}

impl From<NotApplicable> for CauseError {
    fn from(why: NotApplicable) -> Self {
        CauseError::NotApplicable(why)
    }
}

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
    /// its calibrated one, the better kept (the extension's re-fit, `steps::fit_extension`).
    /// Limits: a calibration that mimicked a limit bent the unit so that it never reaches the
    /// limit, and there the limit's parameters have no gradient to follow. A measurement skew:
    /// the delay belongs to the PMU, not to the unit, and a calibration that mimicked it bent the
    /// unit's fast dynamics to lag; from the bent unit the delay's re-fit stops in the nearest
    /// valley, at a fraction of the skew, with the bent values still paying their prior.
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

/// The extension of variant `variant` of `cause` on `unit` ([`Cause::extend_variant`]), with
/// the set-point offsets (nuisance parameters) freed in every re-fit.
pub fn extend_cause(
    cause: &dyn Cause,
    unit: &Unit,
    ctx: &Context,
    variant: usize,
) -> Result<Extension, CauseError> {
    let info = cause.info();
    let mut u = unit.clone();
    u.ensure_finished().map_err(CauseError::build)?;
    let roles = Roles::of(&u)?;
    let mut ext = Extension {
        cause: itaipu_dynamics::diagram::intern::str(info.id),
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
    cause.extend_variant(&mut ext, &roles, ctx, variant)?;
    ext.unit.ensure_finished().map_err(CauseError::build)?;
    free_nuisance(&mut ext);
    Ok(ext)
}

/// The extensions of every variant of `cause` ([`Cause::variants`]): variant 0's error is the
/// cause's; a later variant that cannot be built is left out.
pub fn extend_every_variant(
    cause: &dyn Cause,
    unit: &Unit,
    ctx: &Context,
) -> Result<Vec<Extension>, CauseError> {
    let first = extend_cause(cause, unit, ctx, 0)?;
    let mut all = vec![first];
    all.extend((1..cause.variants()).filter_map(|v| extend_cause(cause, unit, ctx, v).ok()));
    if all.len() > 1 {
        // Choosing among the structures is one more (discrete) parameter.
        for e in &mut all {
            e.discrete_params += 1;
        }
    }
    Ok(all)
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
        why: NotApplicable,
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
