//! [`diagnose`]: the steps of a diagnosis in order (see the module documentation of
//! [`super`]): the request checked, the noise floors and the split, the reference and its
//! evidence, the candidates scored, the verdict, the report.

use std::collections::BTreeMap;
use std::time::Instant;

use itaipu_dynamics::event::{Channel, Event};
use itaipu_dynamics::unit::Unit;

use crate::fit::Progress;
use crate::spec::Compare;

use super::calibrated::check_refit;
use super::candidates::{Candidates, RecordedInput};
use super::catalog::CAUSES;
use super::cause::Cause;
use super::error::DiagnoseError;
use super::fold_check;
use super::look_alike;
use super::options::DiagnoseOptions;
use super::playback::{signal_name, Playback};
use super::profile::Profile;
use super::reference::{self, Reference};
use super::refit::{RefitEnv, RefitRecord};
use super::report::{CandidateReport, DiagnoseResult, Diagnosis, NoiseModel};
use super::split::{split, Split, SEGMENT_S};
use super::user_cause::{self, UserCause};
use super::verdict;

/// Diagnoses `unit` (normally already calibrated) on `events`, judging candidates on `held_out`
/// events when given (see the module documentation).
pub fn diagnose(
    unit: &Unit,
    events: &[Event],
    held_out: &[Event],
    opts: &DiagnoseOptions,
    progress: &dyn Progress,
) -> Result<DiagnoseResult, DiagnoseError> {
    let result = diagnose_run(unit, events, held_out, opts, progress).and_then(|r| {
        fold_check::check(r, held_out, opts, progress, |o| {
            diagnose_run(unit, events, held_out, o, progress)
        })
    });
    // A re-fit cut short reads as a failed candidate: never hand out a verdict built on one.
    match result {
        Ok(r) => {
            interrupted(opts, &r.report.candidates)?;
            Ok(r)
        }
        Err(_) if opts.cancelled() => Err(DiagnoseError::Interrupted { tried: vec![] }),
        Err(e) => Err(e),
    }
}

/// [`DiagnoseError::Interrupted`] when [`DiagnoseOptions::cancel`] is set, naming the causes
/// tried (`done`).
fn interrupted(opts: &DiagnoseOptions, done: &[CandidateReport]) -> Result<(), DiagnoseError> {
    if !opts.cancelled() {
        return Ok(());
    }
    Err(DiagnoseError::Interrupted {
        tried: done.iter().map(|c| c.cause.clone()).collect(),
    })
}

/// The noise floors of the compared channels, the χ² weights and the splits every re-fit
/// reads.
struct Noise {
    pb: Playback,
    /// The noise floor of each compared channel, in the order of [`Playback::channels`].
    sigmas: Vec<f64>,
    sigma_p: f64,
    sigma_q: f64,
    /// The phasor playback's `(w_P, w_Q)` (1 in a playback that compares through `compare`).
    weights: (f64, f64),
    compare: Option<Compare>,
    sp: Split,
    /// The contiguous segments of the second held-out test (without held-out events).
    sp_segments: Option<Split>,
    /// Per event the floors and the residual of the unit as given ([`crate::noise::assess`]).
    rows: Vec<crate::noise::NoiseRow>,
    /// The residual of the unit as given against the noise, in one sentence.
    headline: crate::noise::Headline,
}

/// What the candidates' scoring produced: every report (the catalog's and the user's causes,
/// then the look-alikes when they ran) and each scored cause's re-fit by id.
struct Scored {
    reports: Vec<CandidateReport>,
    refits: BTreeMap<String, RefitRecord>,
}

fn diagnose_run(
    unit: &Unit,
    events: &[Event],
    held_out: &[Event],
    opts: &DiagnoseOptions,
    progress: &dyn Progress,
) -> Result<DiagnoseResult, DiagnoseError> {
    let t_start = Instant::now();
    let causes = check_request(unit, events, opts)?;
    let profile = Profile::default();
    let noise = noise(unit, events, held_out, opts, &profile)?;
    let scoring = (&noise.pb, noise.weights, noise.compare.as_ref());
    let mut reference = reference::reference(
        unit, events, held_out, &noise.sp, scoring, opts, progress, &profile,
    )?;
    // The evidence against the one noise floor of each event and channel (the unit as given's,
    // as the noise table and the χ² weights), not the reference's own pre-event residual.
    super::noise::against_noise(&mut reference.evidence, &noise.rows);
    let ctx = reference::catalog_context(events, &reference.before, &reference.evidence, &noise.pb);
    let band_top = causes
        .iter()
        .filter_map(|c| c.band_top_hz(&ctx))
        .reduce(f64::max);
    let recorded = recorded_input(events, held_out, &reference, band_top, &noise, opts)?;
    let env = noise.env(opts, progress, &profile);
    let segments = noise.sp_segments.as_ref();
    let mut candidates = Candidates::new(&reference, &ctx, env, segments, recorded.as_ref());
    let Scored {
        mut reports,
        refits,
    } = score_candidates(&mut candidates, &causes, opts)?;
    let t_verdict = Instant::now();
    let absorbed = super::absorbed::absorbed(&reference.refit.unit, &opts.refit);
    let decision = verdict::decide(
        &mut reports,
        refits,
        events,
        recorded.as_ref().map(|r| r.events.as_slice()),
        scoring,
        &reference.evidence,
        &absorbed,
        opts,
    );
    let t = t_verdict.elapsed().as_secs_f64();
    profile.add("diagnosis", VERDICT_PHASE, t, 0, 0);
    let Reference {
        refit,
        before,
        evidence,
        note,
        ..
    } = reference;
    let mut evidence_after = decision.evidence_after;
    super::noise::against_noise(&mut evidence_after, &noise.rows);
    let report = Diagnosis {
        unit: refit.unit.name.clone(),
        events: events.iter().map(|e| e.name.clone()).collect(),
        held_out: held_out.iter().map(|e| e.name.clone()).collect(),
        verdict: decision.verdict,
        candidates: reports,
        evidence,
        evidence_after,
        noise: noise.model(),
        headline: noise.headline.clone(),
        warnings: vec![],
        refit: opts.refit.clone(),
        profile: profile.rows(),
        seed: opts.seed,
        threads: rayon::current_num_threads(),
        wall_s: t_start.elapsed().as_secs_f64(),
        reference: note,
    };
    Ok(DiagnoseResult {
        report,
        extended_unit: decision.extended_unit,
        before,
        after: decision.after,
    })
}

/// The record played back as recorded ([`RecordedInput::new`]), when some cause's band
/// (`band_top`) reaches above the events' input cut-off.
fn recorded_input(
    events: &[Event],
    held_out: &[Event],
    reference: &Reference,
    band_top: Option<f64>,
    noise: &Noise,
    opts: &DiagnoseOptions,
) -> Result<Option<RecordedInput>, DiagnoseError> {
    RecordedInput::new(
        events,
        held_out,
        &reference.surrogates,
        band_top,
        (&reference.refit.unit, &noise.pb),
        noise.sp_segments.is_some(),
        (opts.block_s, opts.fold),
    )
}

/// Checks the request (events, causes, re-fit bounds, search settings) and returns the causes
/// to try: the catalog's then the user's, or those named (in the order given).
fn check_request<'o>(
    unit: &Unit,
    events: &[Event],
    opts: &'o DiagnoseOptions,
) -> Result<Vec<&'o dyn Cause>, DiagnoseError> {
    if events.is_empty() {
        return Err(DiagnoseError::Setup("no event to diagnose".into()));
    }
    let mut causes: Vec<&'o dyn Cause> = vec![];
    for c in &opts.causes {
        let Some(cause) = user_cause::lookup(c, &opts.user_causes) else {
            return Err(DiagnoseError::Setup(format!(
                "unknown cause '{c}' (known: {})",
                user_cause::ids(&opts.user_causes)
            )));
        };
        causes.push(cause);
    }
    check_refit(unit, &opts.refit)?;
    if opts.particles == 0 && opts.pso_iterations > 0 {
        return Err(DiagnoseError::Setup(
            "particles must be at least 1 (or pso_iterations 0)".into(),
        ));
    }
    if !(opts.block_s > 0.0) {
        return Err(DiagnoseError::Setup(format!(
            "block length must be > 0 s (got {})",
            opts.block_s
        )));
    }
    if opts.causes.is_empty() {
        let users = opts.user_causes.iter().map(|u| u as &dyn Cause);
        causes = CAUSES.iter().copied().chain(users).collect();
    }
    Ok(causes)
}

/// The noise floor of each compared channel, from the pre-event residual of the unit as given
/// ([`super::noise::assess`]), the χ² weights, and the fitted/held-out split.
fn noise(
    unit: &Unit,
    events: &[Event],
    held_out: &[Event],
    opts: &DiagnoseOptions,
    profile: &Profile,
) -> Result<Noise, DiagnoseError> {
    let t_noise = Instant::now();
    let all: Vec<&Event> = events.iter().chain(held_out).collect();
    let pb = Playback::for_events(opts.mode, &all)?;
    let (sigmas, noise_rows, headline) = super::noise::assess(unit, events, held_out, &pb)?;
    let t = t_noise.elapsed().as_secs_f64();
    profile.add("diagnosis", "noise floor", t, 0, 0);
    let sigma_of = |c: Channel| {
        pb.channels
            .iter()
            .position(|k| *k == c)
            .map_or(f64::NAN, |j| sigmas[j])
    };
    let (sigma_p, sigma_q) = (sigma_of(Channel::P), sigma_of(Channel::Q));
    let weights = if pb.is_pq_phasor() {
        (1.0 / sigma_p.powi(2), 1.0 / sigma_q.powi(2))
    } else {
        (1.0, 1.0)
    };
    let compare = pb.compare(&sigmas);
    let sp = split(events, held_out, opts.block_s, opts.fold)?;
    let sp_segments = if sp.blocks {
        Some(split(events, held_out, SEGMENT_S, opts.fold)?)
    } else {
        None
    };
    Ok(Noise {
        pb,
        sigmas,
        sigma_p,
        sigma_q,
        weights,
        compare,
        sp,
        sp_segments,
        rows: noise_rows,
        headline,
    })
}

/// The profile's row of the verdict's own work.
const VERDICT_PHASE: &str = "verdict: standard errors, evidence after";

impl Noise {
    /// Every re-fit's environment on the record's split.
    fn env<'a>(
        &'a self,
        opts: &'a DiagnoseOptions,
        progress: &'a dyn Progress,
        profile: &'a Profile,
    ) -> RefitEnv<'a> {
        RefitEnv {
            sp: &self.sp,
            weights: self.weights,
            compare: self.compare.as_ref(),
            opts,
            progress,
            profile: Some(profile),
        }
    }

    /// The report's noise model.
    fn model(&self) -> NoiseModel {
        let pb = &self.pb;
        NoiseModel {
            playback: pb.describe(),
            sigmas: pb
                .channels
                .iter()
                .zip(&self.sigmas)
                .map(|(c, s)| (signal_name(*c).to_string(), *s))
                .collect(),
            sigma_p: self.sigma_p,
            sigma_q: self.sigma_q,
            split: self.sp.description.clone(),
            n_fit: self.sp.fit.iter().map(|d| d.n_window()).sum(),
            n_held: self.sp.held.iter().map(|d| d.n_window()).sum(),
            events: self.rows.clone(),
        }
    }
}

/// Scores `causes` side by side, then, in a full diagnosis where one of them passed its test
/// (significant, or refused by its physical checks: then the verdict is `unexplained` and a
/// look-alike may say what the residual looks like), the look-alikes outside the catalog
/// ([`look_alike`]), after every cause that can be named (whose scores they leave as they
/// are): otherwise they could only turn `none` into `unexplained`.
fn score_candidates<'a>(
    candidates: &mut Candidates<'a>,
    causes: &[&'a dyn Cause],
    opts: &'a DiagnoseOptions,
) -> Result<Scored, DiagnoseError> {
    let mut reports = vec![];
    let mut refits = BTreeMap::new();
    interrupted(opts, &reports)?;
    for (cause, (rep, refit)) in causes.iter().zip(candidates.score_all(causes)) {
        if let Some(r) = refit {
            refits.insert(cause.info().id.to_string(), r);
        }
        reports.push(rep);
    }
    // A batch cancelled part-way names every cause it started (its re-fits stop at the flag).
    interrupted(opts, &reports)?;
    if reports.iter().any(|r| r.significant || r.passed_test) {
        let look_alikes = look_alikes(opts);
        interrupted(opts, &reports)?;
        for (mut rep, _) in candidates.score_all(&look_alikes) {
            rep.look_alike = true;
            reports.push(rep);
        }
        interrupted(opts, &reports)?;
    }
    Ok(Scored { reports, refits })
}

/// The look-alikes a full diagnosis tries: the bundled ones whose id is no catalog cause's nor
/// the user's (a user's file of the same id is a candidate that can be named).
fn look_alikes(opts: &DiagnoseOptions) -> Vec<&dyn Cause> {
    if !opts.look_alikes || !opts.causes.is_empty() {
        return vec![];
    }
    look_alike::bundled()
        .iter()
        .filter(|l| !user_cause::known(&l.id, &opts.user_causes))
        .map(|l: &'static UserCause| l as &dyn Cause)
        .collect()
}
