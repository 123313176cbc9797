//! The candidates' batch: every cause set up on its playback (its extensions built, its
//! baseline's bounds and key), the batch's main baselines re-fitted once each, then each cause
//! scored side by side ([`super::steps`]), the reports in the order the causes were given.

use std::collections::BTreeMap;

use itaipu_dynamics::event::Event;
use itaipu_dynamics::unit::Unit;

use crate::bounds::FreeBound;

use super::baseline_cache::{BaselineCache, BaselineKey, Input};
use super::cause::{extend_every_variant, Cause, CauseError, Context, Extension, NotApplicable};
use super::error::{DiagnoseError, RefitError};
use super::extension_fit::with_calibrated_set;
use super::playback::Playback;
use super::profile::{Label, RefitKind};
use super::reference::Reference;
use super::refit::{refit, Refit, RefitEnv, RefitRecord};
use super::report::{CandidateReport, EventEvidence};
use super::split::{split, Fold, Split, SEGMENT_S};

/// What the scoring of every candidate shares: the reference unit and its context and evidence,
/// the fitted/held-out split and its surrogate, the noise weights, the options, and the
/// baselines re-fitted so far (by [`BaselineKey`], re-used across candidates).
pub(super) struct Candidates<'a> {
    pub unit: &'a Unit,
    pub ctx: &'a Context,
    pub evidence: &'a [EventEvidence],
    /// The re-fits on the record's split.
    pub env: RefitEnv<'a>,
    /// The surrogates' splits, one per draw.
    pub sp_null: &'a [Split],
    /// The split on contiguous segments for the second held-out test (without held-out events;
    /// [`SEGMENT_S`]).
    pub sp_segments: Option<&'a Split>,
    /// The same splits with the record played back as recorded, when the events' input is
    /// low-passed: for a cause whose extension adds a mode above the cut-off
    /// ([`Cause::band_top_hz`]).
    pub recorded: Option<&'a RecordedInput>,
    /// The voltage noise's echo ([`super::Gains::input_echo`]), once measured.
    pub input_echo: Option<f64>,
    pub baselines: BTreeMap<BaselineKey, Refit>,
}

/// The record's splits played back as recorded (the events' `input_lowpass_hz` cleared), for
/// the causes whose band reaches above the lowest cut-off of the events, `cutoff_hz`.
pub(super) struct RecordedInput {
    pub cutoff_hz: f64,
    pub events: Vec<Event>,
    /// The reference's evidence and the catalog's context on the events played so: what such a
    /// cause reads its signature and its search's start from (a shaft's resonance in the
    /// residual is the recorded input's).
    pub evidence: Vec<EventEvidence>,
    pub ctx: Context,
    pub sp: Split,
    pub sp_null: Vec<Split>,
    pub sp_segments: Option<Split>,
}

impl RecordedInput {
    /// `events`, `held_out` and their surrogates played back as recorded, with the evidence of
    /// the reference unit `reference` on them, when any of them is low-passed below `band_top`
    /// (the highest band a cause to try must reproduce); `None` otherwise (no cause needs it).
    pub(super) fn new(
        events: &[Event],
        held_out: &[Event],
        surrogates: &[(Vec<Event>, Vec<Event>)],
        band_top: Option<f64>,
        (reference, pb): (&Unit, &Playback),
        segments: bool,
        (block_s, fold): (f64, Fold),
    ) -> Result<Option<Self>, DiagnoseError> {
        let Some(cutoff_hz) = events
            .iter()
            .chain(held_out)
            .filter_map(|e| e.input_lowpass_hz)
            .reduce(f64::min)
            .filter(|fc| band_top.is_some_and(|top| *fc < top))
        else {
            return Ok(None);
        };
        let raw = |es: &[Event]| -> Vec<Event> {
            es.iter()
                .map(|e| {
                    let mut e = e.clone();
                    e.input_lowpass_hz = None;
                    e
                })
                .collect()
        };
        let (ev, ho) = (raw(events), raw(held_out));
        let sp = split(&ev, &ho, block_s, fold)?;
        let mut sp_null = Vec::with_capacity(surrogates.len());
        for (e, h) in surrogates {
            sp_null.push(split(&raw(e), &raw(h), block_s, fold)?);
        }
        let sp_segments = if segments {
            Some(split(&ev, &ho, SEGMENT_S, fold)?)
        } else {
            None
        };
        let mut before = vec![];
        let mut evidence = vec![];
        for e in &ev {
            let (tr, evd, _) = pb.evidence(reference, e)?;
            before.push((e.name.clone(), tr));
            evidence.push(evd);
        }
        let ctx = super::reference::catalog_context(&ev, &before, &evidence, pb);
        Ok(Some(Self {
            cutoff_hz,
            evidence,
            ctx,
            events: ev,
            sp,
            sp_null,
            sp_segments,
        }))
    }
}

/// The playback a candidate is scored on ([`Candidates::played_for`]): the record as the
/// other causes are, or as recorded.
pub(super) struct Played<'c> {
    pub recorded: Option<&'c RecordedInput>,
    pub env: RefitEnv<'c>,
    pub sp_null: &'c [Split],
    pub sp_segments: Option<&'c Split>,
    pub ctx: &'c Context,
    pub evidence: &'c [EventEvidence],
    /// How the re-fits play the record (the baselines' keys are apart for each).
    pub input: Input,
}

/// A cause's extensions (the first its main structure, the others its refinements), its
/// baseline's bounds and the baseline's key in the cache.
pub(super) struct Extended {
    pub exts: Vec<Extension>,
    pub base_bounds: Vec<FreeBound>,
    pub key: BaselineKey,
}

/// Why a candidate has no gains: the cause does not apply, its extension cannot be built, or a
/// re-fit it needs failed. Its text is the candidate's note.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum NotScored {
    NotApplicable(NotApplicable),
    /// The extension could not be built on this unit.
    Build(CauseError),
    /// The baseline's re-fit failed.
    Baseline(RefitError),
    /// The extended unit does not simulate at the re-fit's best candidate.
    Extension(RefitError),
}

impl std::fmt::Display for NotScored {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NotScored::NotApplicable(why) => write!(f, "not applicable: {why}"),
            NotScored::Build(e) => write!(f, "could not build the extension: {e}"),
            NotScored::Baseline(e) => write!(f, "the baseline re-fit failed: {e}"),
            NotScored::Extension(e) => write!(
                f,
                "the extended unit does not simulate at the best candidate: {e}"
            ),
        }
    }
}

/// Step 1 of a candidate: the cause, the playback it is scored on, and its extensions (or why
/// it is not scored).
pub(super) struct Setup<'c> {
    pub cause: &'c dyn Cause,
    pub played: Played<'c>,
    pub extended: Result<Extended, NotScored>,
}

/// A candidate's report and, when it was re-fitted, its re-fit (for the standard errors of a
/// named cause).
pub(super) type Scored = (CandidateReport, Option<RefitRecord>);

impl<'a> Candidates<'a> {
    /// The candidates of a diagnosis whose reference is `reference` (its unit, evidence and
    /// surrogate splits; its re-fit the first baseline of the cache, shared by a cause that
    /// re-frees the nuisance offsets alone), on the catalog's context `ctx`, the re-fits of
    /// `env`, the segments' split and the record played back as recorded.
    pub(super) fn new(
        reference: &'a Reference,
        ctx: &'a Context,
        env: RefitEnv<'a>,
        sp_segments: Option<&'a Split>,
        recorded: Option<&'a RecordedInput>,
    ) -> Self {
        Candidates {
            unit: &reference.refit.unit,
            ctx,
            evidence: &reference.evidence,
            env,
            sp_null: &reference.sp_null,
            sp_segments,
            recorded,
            input_echo: None,
            baselines: BTreeMap::from([(
                BaselineKey::new(Input::AsEvents, &reference.bounds),
                reference.refit.clone(),
            )]),
        }
    }

    /// Scores `causes` side by side (each candidate's re-fits in parallel with the others',
    /// their swarms on the same pool), in the order given: the same reports as scoring them
    /// one after another ([`BaselineCache`]), with the threads a candidate's own re-fit leaves
    /// idle (its local method's steps and its serial phases) used by the others.
    pub(super) fn score_all(&mut self, causes: &[&'a dyn Cause]) -> Vec<Scored> {
        use rayon::prelude::*;
        self.measure_input_echo(causes);
        // Each cause's playback and extensions, built once: the batch's baselines and the
        // cause's scoring read them.
        let setups: Vec<Setup<'a>> = causes.iter().map(|&c| self.set_up(c)).collect();
        self.refit_main_baselines(&setups);
        let this = &*self;
        let scored: Vec<_> = setups
            .into_par_iter()
            .with_max_len(1)
            .map(|setup| {
                let mut cache = BaselineCache::new(&this.baselines);
                let scored = this.score(setup, &mut cache);
                (scored, cache.into_own())
            })
            .collect();
        let mut out = Vec::with_capacity(scored.len());
        for (scored, own) in scored {
            for (k, r) in own {
                self.baselines.entry(k).or_insert(r);
            }
            out.push(scored);
        }
        out
    }

    /// The voltage noise's echo in the fitted χ² as recorded, measured once before the batch
    /// when a cause needs it: the reference unit (no parameter free) on both playbacks.
    fn measure_input_echo(&mut self, causes: &[&'a dyn Cause]) {
        if self.input_echo.is_some() {
            return;
        }
        if let Some(r) = causes.iter().find_map(|c| self.recorded_for(*c)) {
            let label = Label::new(RefitKind::Reference, "input echo");
            let echo = match (
                refit(&self.env.on(&r.sp), self.unit, &[], &[], &label),
                refit(&self.env, self.unit, &[], &[], &label),
            ) {
                (Ok(a), Ok(b)) => (a.chi2_fit - b.chi2_fit).max(0.0),
                _ => 0.0,
            };
            self.input_echo = Some(echo);
        }
    }

    /// The batch's main baselines not re-fitted yet, each once (causes that re-free the same
    /// parameters share one), side by side; each is the re-fit its first cause would have
    /// made, so no number changes. One that fails is left to its causes, whose reports say so.
    fn refit_main_baselines(&mut self, setups: &[Setup<'a>]) {
        use rayon::prelude::*;
        let mut todo: Vec<(&BaselineKey, &RefitEnv, &[FreeBound], &str)> = vec![];
        for s in setups {
            if let Ok(x) = &s.extended {
                if !self.baselines.contains_key(&x.key) && todo.iter().all(|t| t.0 != &x.key) {
                    todo.push((&x.key, &s.played.env, &x.base_bounds, s.cause.info().id));
                }
            }
        }
        let unit = self.unit;
        let fitted: Vec<_> = todo
            .par_iter()
            .with_max_len(1)
            .map(|&(key, env, base_bounds, id)| {
                let label = Label::new(RefitKind::Baseline, format!("{id} baseline"));
                (key.clone(), refit(env, unit, base_bounds, &[], &label))
            })
            .collect();
        for (key, r) in fitted {
            if let Ok(r) = r {
                self.baselines.insert(key, r);
            }
        }
    }

    /// Step 1: `cause` on its playback with its extensions.
    fn set_up(&self, cause: &'a dyn Cause) -> Setup<'a> {
        let played = self.played_for(cause);
        let extended = self.extensions(cause, &played);
        Setup {
            cause,
            played,
            extended,
        }
    }

    /// What `cause` is scored on: the record as the other causes are, or played back as
    /// recorded for a cause whose mode lies above the input's cut-off, with its baselines and
    /// surrogates played alike (cached apart from the others').
    fn played_for(&self, cause: &dyn Cause) -> Played<'a> {
        match self.recorded_for(cause) {
            Some(r) => Played {
                recorded: Some(r),
                env: self.env.on(&r.sp),
                sp_null: &r.sp_null,
                sp_segments: r.sp_segments.as_ref(),
                ctx: &r.ctx,
                evidence: &r.evidence,
                input: Input::AsRecorded,
            },
            None => Played {
                recorded: None,
                env: self.env,
                sp_null: self.sp_null,
                sp_segments: self.sp_segments,
                ctx: self.ctx,
                evidence: self.evidence,
                input: Input::AsEvents,
            },
        }
    }

    /// `cause`'s extensions of the unit (the first its main structure, the others its
    /// refinements; the calibration's set values applied), its baseline's bounds (the
    /// interacting parameters the unit as given has: a replaced block's parameters are the
    /// extension's) and the baseline's key in the cache; why not, when the cause does not apply
    /// to the record or its extension cannot be built.
    fn extensions(&self, cause: &dyn Cause, played: &Played) -> Result<Extended, NotScored> {
        let unit = self.unit;
        if let Some(why) = played.ctx.not_seen(cause.acts()) {
            return Err(NotScored::NotApplicable(why));
        }
        let opts = played.env.opts;
        let exts = match extend_every_variant(cause, unit, played.ctx) {
            Err(CauseError::NotApplicable(why)) => return Err(NotScored::NotApplicable(why)),
            Err(e) => return Err(NotScored::Build(e)),
            Ok(exts) => exts,
        };
        let exts: Vec<Extension> = exts
            .into_iter()
            .map(|e| with_calibrated_set(e, opts))
            .collect();
        let base_bounds: Vec<FreeBound> = exts[0]
            .interacting_free
            .iter()
            .filter(|b| unit.param(&b.param).is_ok())
            .map(|b| b.starting_in(unit))
            .collect();
        let key = BaselineKey::new(played.input, &base_bounds);
        Ok(Extended {
            exts,
            base_bounds,
            key,
        })
    }

    /// The record played back as recorded, for a cause whose mode lies above the input's
    /// cut-off (its baselines and surrogates played alike, cached apart from the others').
    fn recorded_for(&self, cause: &dyn Cause) -> Option<&'a RecordedInput> {
        self.recorded.filter(|r| {
            cause
                .band_top_hz(&r.ctx)
                .is_some_and(|top| r.cutoff_hz < top)
        })
    }
}
