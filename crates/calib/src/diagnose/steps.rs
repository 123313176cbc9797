//! The steps that score one candidate, each returning what the next reads:
//!
//! 1. set up the playback and the extensions ([`Candidates::score_all`]'s [`Setup`]);
//! 2. re-fit the baseline ([`Candidate::baseline`]) unless the batch did;
//! 3. re-fit the extension, every structure of the cause, the best kept
//!    ([`Candidate::fit_structures`] → [`Fitted`]);
//! 4. test the gain on samples the re-fit did not fit: the segments' second held-out test, and
//!    the baseline again from the extension's values ([`Candidate::held_out`] → [`HeldOut`]);
//! 5. compare the extension with its baseline, net of what the same re-fits gain on surrogate
//!    records ([`Candidate::compare`] → [`Compared`]);
//! 6. judge: the significance test, then the physical checks that may refuse a significant
//!    candidate, or the evidence that names one by itself ([`Candidate::judge`] → [`Judged`]);
//!
//! and the candidate's report ([`Candidate::report`]). The verdict ranks the reports
//! ([`super::verdict`]).

use std::time::Instant;

use itaipu_dynamics::unit::Unit;

use crate::bounds::FreeBound;
use crate::problem::FreeParam;

use super::baseline_cache::{BaselineCache, BaselineKey};
use super::candidates::{Candidates, NotScored, Played, Scored, Setup};
use super::cause::{Cause, Extension};
use super::extension_fit::{baseline_from, fit_extension, Pressed};
use super::gain::{distortion, explains_too_little, relative, GainTest, BINDING_CHI2};
use super::held_out::{noise_fitting_gain, segments_test, NoiseFitting, SegmentsTest};
use super::options::DiagnoseOptions;
use super::playback::signal_name;
use super::profile::{Label, RefitKind};
use super::refit::{resolve, Refit, RefitEnv, Scores};
use super::report::{fmt_num, CandidateParam, CandidateReport, Gains};

/// Step 3's result: the structure kept, its re-fit, the bounds it re-fitted over and those
/// resolved in its unit (the extension's first).
pub(super) struct Fitted {
    ext: Extension,
    refit: Refit,
    bounds: Vec<FreeBound>,
    free: Vec<FreeParam>,
}

/// Step 4's result: the segments' second held-out test, when it ran, and the baseline again
/// from the extension's values, when it ran and fits better.
pub(super) struct HeldOut {
    segments: Option<SegmentsTest>,
    segments_pass: bool,
    base_again: Option<Refit>,
}

/// Step 5's result: the gains net of noise fitting and the test they are judged by.
pub(super) struct Compared {
    gains: Gains,
    net: GainTest,
    null: NoiseFitting,
}

/// Step 6's result: the candidate's standing and the note that says why.
pub(super) struct Judged {
    significant: bool,
    passed_test: bool,
    by_evidence: bool,
    note: String,
    /// Simulations of the re-fits the checks ran.
    simulations: usize,
}

/// One candidate being scored: its cause on its playback, its baseline's bounds and key.
pub(super) struct Candidate<'s> {
    unit: &'s Unit,
    cause: &'s dyn Cause,
    id: &'s str,
    played: &'s Played<'s>,
    env: RefitEnv<'s>,
    opts: &'s DiagnoseOptions,
    base_bounds: &'s [FreeBound],
    key: &'s BaselineKey,
}

impl<'a> Candidates<'a> {
    /// Scores one candidate set up by [`Candidates::score_all`]: its report, and its re-fit when
    /// it has one (for the standard errors of a named cause).
    pub(super) fn score(&self, setup: Setup<'a>, cache: &mut BaselineCache) -> Scored {
        let t0 = Instant::now();
        let Setup {
            cause,
            played,
            extended,
        } = setup;
        let mut rep = blank_report(cause, &played);
        let x = match extended {
            Ok(x) => x,
            Err(why) => {
                rep.note = why.to_string();
                return (rep, None);
            }
        };
        let s = Candidate {
            unit: self.unit,
            cause,
            id: cause.info().id,
            played: &played,
            env: played.env,
            opts: played.env.opts,
            base_bounds: &x.base_bounds,
            key: &x.key,
        };
        rep.applicable = true;
        rep.extension = x.exts[0].description.clone();
        rep.fixed = x.exts[0].fixed.clone();
        let progress = s.env.progress;
        progress.message(&format!("diagnose: {}: {}", s.id, x.exts[0].description));
        if let Err(why) = s.baseline(cache) {
            rep.note = why.to_string();
            return (rep, None);
        }
        let fitted = match s.fit_structures(x.exts, cache.at(s.key)) {
            Ok(f) => f,
            Err(why) => {
                rep.note = why.to_string();
                rep.wall_s = t0.elapsed().as_secs_f64();
                return (rep, None);
            }
        };
        let held = s.held_out(&fitted, cache);
        let input_echo = match played.recorded {
            None => 0.0,
            Some(_) => self.input_echo.expect("measured before the batch"),
        };
        let compared = s.compare(&fitted, &held, cache, input_echo);
        let judged = s.judge(&fitted, &held, &compared);
        let mut rep = s.report(rep, &fitted, &held, compared, judged, cache);
        rep.wall_s = t0.elapsed().as_secs_f64();
        let Fitted {
            refit, bounds, ext, ..
        } = fitted;
        (rep, Some((refit, bounds, ext.ties)))
    }
}

/// A candidate's report before it is scored: not applicable, no gains, its signature in the
/// evidence of its playback.
fn blank_report(cause: &dyn Cause, played: &Played) -> CandidateReport {
    let info = cause.info();
    CandidateReport {
        cause: info.id.to_string(),
        title: info.title.to_string(),
        applicable: false,
        note: String::new(),
        extension: info.extension.to_string(),
        parameters: vec![],
        fixed: vec![],
        gains: None,
        significant: false,
        passed_test: false,
        look_alike: false,
        by_evidence: false,
        signature: cause.signature(played.evidence, played.ctx),
        simulations: 0,
        failed_candidates: 0,
        wall_s: 0.0,
        distortion: vec![],
        input_as_recorded: played.recorded.is_some(),
    }
}

impl Candidate<'_> {
    /// The significance test of gains `d_fit`, `d_held` over a baseline with scores `base`.
    fn test(&self, f: &Fitted, d_fit: f64, d_held: f64, base: &Scores) -> GainTest {
        GainTest {
            d_fit,
            d_held,
            chi2_fit: base.chi2_fit,
            chi2_held: base.chi2_held,
            vif: base.vif,
            k: f.ext.extension_free.len() + f.ext.discrete_params,
            n: f.refit.n_fit.max(1) as f64,
        }
    }

    /// Step 2: the baseline, the unit as given re-fitted over the same interacting parameters
    /// (unless the batch or another cause re-fitted it already).
    fn baseline(&self, cache: &mut BaselineCache) -> Result<(), NotScored> {
        if cache.contains_key(self.key) {
            return Ok(());
        }
        let label = Label::new(RefitKind::Baseline, format!("{} baseline", self.id));
        let r = super::refit::refit(&self.env, self.unit, self.base_bounds, &[], &label)
            .map_err(NotScored::Baseline)?;
        cache.insert(self.key.clone(), r);
        Ok(())
    }

    /// Step 3: the extension re-fitted, then the cause's other structures, the one with the
    /// best information criterion kept (χ² plus ln n per parameter: structures with more
    /// parameters fit at least as well). They are refinements of the first, which can mimic
    /// them in part (a constant ceiling at the level a terminal-fed one falls to in the dip):
    /// they are tried only when the first gains on the fitted samples more than its own
    /// penalty.
    fn fit_structures(&self, mut exts: Vec<Extension>, base: &Refit) -> Result<Fitted, NotScored> {
        let has_base = !self.base_bounds.is_empty();
        let mut ext = exts.remove(0);
        let label = Label::new(RefitKind::Extension, self.id);
        let mut r =
            fit_extension(&self.env, &ext, base, has_base, &label).map_err(NotScored::Extension)?;
        let ic = |r: &Refit, x: &Extension| {
            r.chi2_fit + x.extension_free.len() as f64 * (r.n_fit.max(1) as f64).ln()
        };
        if ic(&r, &ext) >= base.chi2_fit {
            exts.clear();
        }
        for alt in exts {
            let label = Label::new(
                RefitKind::Extension,
                format!("{} ({})", self.id, alt.description),
            );
            if let Ok(r2) = fit_extension(&self.env, &alt, base, has_base, &label) {
                if ic(&r2, &alt) < ic(&r, &ext) {
                    r = r.replaced_by(r2);
                    ext = alt;
                } else {
                    r.simulations += r2.simulations;
                }
            }
        }
        let bounds: Vec<FreeBound> = ext.free().cloned().collect();
        let free = resolve(&ext.unit, &bounds).unwrap_or_default();
        Ok(Fitted {
            ext,
            refit: r,
            bounds,
            free,
        })
    }

    /// Step 4: the segments' second held-out test, for an extension whose fitted gain passes
    /// but whose held-out blocks do not confirm it; then the baseline again from the
    /// interacting values the extension's re-fit found (its search may have found a better
    /// set-point than the baseline's own), so that no gain comes from optimisation luck. The
    /// baseline again only for a gain that could pass (a better baseline only lowers it), kept
    /// for this cause alone: the shared cache holds each baseline as its own search found it,
    /// so that a cause's gain does not depend on which causes were tried before it.
    fn held_out(&self, f: &Fitted, cache: &mut BaselineCache) -> HeldOut {
        let r = &f.refit;
        let b = cache.at(self.key).clone_scores();
        let t = self.test(f, b.chi2_fit - r.chi2_fit, b.chi2_held - r.chi2_held, &b);
        let segments = self
            .played
            .sp_segments
            .filter(|_| t.fits(self.opts) && !t.held(self.opts))
            .and_then(|sp_segments| {
                segments_test(
                    &self.env.on(sp_segments),
                    self.unit,
                    self.base_bounds,
                    &f.ext,
                    cache,
                    self.key,
                    self.id,
                )
            });
        let segments_pass = segments.as_ref().is_some_and(|t| t.passes(self.opts));
        let b = cache.at(self.key);
        let could_pass = self
            .test(
                f,
                b.chi2_fit - r.chi2_fit,
                b.chi2_held - r.chi2_held,
                &b.clone_scores(),
            )
            .passes(segments_pass, self.opts);
        let mut base_again = None;
        if !self.base_bounds.is_empty() && could_pass {
            let label = Label::new(
                RefitKind::BaselineAgain,
                format!("{} baseline again", self.id),
            );
            if let Some(b2) = baseline_from(&self.env, self.unit, self.base_bounds, r, &label) {
                if b2.chi2_fit < cache.at(self.key).chi2_fit {
                    base_again = Some(b2);
                }
            }
        }
        HeldOut {
            segments,
            segments_pass,
            base_again,
        }
    }

    /// Step 5: the extension against its baseline (the baseline again when it ran): the raw
    /// gains, the noise-fitting part of them measured on the surrogate records (only for a
    /// candidate whose raw gain could pass: the correction only lowers it), the net gains and
    /// the RMS of each compared channel.
    fn compare(
        &self,
        f: &Fitted,
        h: &HeldOut,
        cache: &mut BaselineCache,
        input_echo: f64,
    ) -> Compared {
        let r = &f.refit;
        let (base, base_rms) = {
            let b: &Refit = h.base_again.as_ref().unwrap_or(cache.at(self.key));
            (b.clone_scores(), b.rms.clone())
        };
        let raw_fit = base.chi2_fit - r.chi2_fit;
        let raw_held = base.chi2_held - r.chi2_held;
        let passes = |d_fit: f64, d_held: f64| {
            self.test(f, d_fit, d_held, &base)
                .passes(h.segments_pass, self.opts)
        };
        let null = if passes(raw_fit, raw_held) {
            let envs_null: Vec<RefitEnv> =
                self.played.sp_null.iter().map(|s| self.env.on(s)).collect();
            noise_fitting_gain(
                &envs_null,
                cache,
                self.unit,
                self.base_bounds,
                &f.ext,
                &f.bounds,
                self.key,
                self.id,
            )
        } else {
            NoiseFitting::default()
        };
        let (null_fit, null_held) = (null.mean_fit(), null.mean_held());
        let (net_fit, net_held) = (raw_fit - null_fit, raw_held - null_held);
        let net = self.test(f, net_fit, net_held, &base);
        let rms = self.rms(&base_rms, &r.rms);
        let of = |name: &str| {
            rms.iter()
                .find(|(s, _, _)| s == name)
                .map_or((f64::NAN, f64::NAN), |(_, b, e)| (*b, *e))
        };
        let ((rms_p_base, rms_p_ext), (rms_q_base, rms_q_ext)) = (of("P"), of("Q"));
        let gains = Gains {
            chi2_fit_base: base.chi2_fit,
            chi2_fit_ext: r.chi2_fit,
            input_echo,
            chi2_held_base: base.chi2_held,
            chi2_held_ext: r.chi2_held,
            chi2_prior_base: base.chi2_prior,
            chi2_prior_ext: r.chi2_prior,
            null_gain_fit: null_fit,
            null_gain_held: null_held,
            null_gains_fit: null.fits.clone(),
            null_gains_held: null.helds.clone(),
            fit_drop: relative(net_fit, base.chi2_fit),
            held_drop: relative(net_held, base.chi2_held),
            held_drop_segments: h.segments.as_ref().map(SegmentsTest::drop),
            delta_bic: net.delta_bic(),
            record_evidence: net.evidence(),
            vif: base.vif,
            k: net.k,
            n_fit: r.n_fit,
            n_held: r.n_held,
            rms,
            rms_p_base,
            rms_q_base,
            rms_p_ext,
            rms_q_ext,
        };
        Compared { gains, net, null }
    }

    /// The RMS of each compared channel (P and Q first in the phasor playback), `(signal,
    /// baseline, extended)`.
    fn rms(&self, base: &[f64], ext: &[f64]) -> Vec<(String, f64, f64)> {
        let signals: Vec<&str> = match self.env.compare {
            None => vec!["P", "Q"],
            Some(c) => c.weights.iter().map(|(c, _)| signal_name(*c)).collect(),
        };
        signals
            .iter()
            .zip(base.iter().zip(ext))
            .map(|(s, (b, e))| (s.to_string(), *b, *e))
            .collect()
    }

    /// Step 6: significant by the test on the net gains; then not named when the cause's
    /// fitted values are no unit of it or below what the data resolve ([`Cause::vetoed`]), when
    /// it leaves most of a misfit far above the noise ([`explains_too_little`]), or when its
    /// extension presses against the upper end of its range where that end binds
    /// ([`Candidate::pressed`]); named by the evidence alone where the cause says so
    /// ([`Cause::named_by_evidence`]).
    fn judge(&self, f: &Fitted, h: &HeldOut, c: &Compared) -> Judged {
        let significant = c.net.passes(h.segments_pass, self.opts);
        let mut j = Judged {
            significant,
            passed_test: significant,
            by_evidence: false,
            note: match (&h.segments, c.null.failed) {
                (_, true) => "the surrogate (noise-only) re-fit failed: the gain is not \
                              corrected for noise fitting"
                    .into(),
                (Some(t), false) => t.note(),
                (None, false) => String::new(),
            },
            simulations: 0,
        };
        let fitted: Vec<(String, f64)> = f
            .free
            .iter()
            .zip(&f.refit.values)
            .map(|(p, v)| (p.path.clone(), *v))
            .collect();
        if let Some(why) = self.cause.vetoed(&fitted, self.played.ctx) {
            j.refuse(why);
        }
        if j.significant {
            if let Some(why) = explains_too_little(&c.gains, self.opts.noise_factor) {
                j.refuse(why);
            }
        }
        if j.significant {
            self.pressed(f, c, &mut j);
        }
        if !j.significant {
            if let Some(why) = self.cause.named_by_evidence(self.played.ctx) {
                j.significant = true;
                j.by_evidence = true;
                j.note = format!("named by the evidence: {why}");
            }
        }
        j
    }

    /// An extension pressed against the upper end of its declared range (the largest
    /// saturation, load, delay, limiter setting the cause can physically be), where that end
    /// binds ([`Pressed::binds`]): the residual asks for more of the effect than the cause can
    /// be, so what it gained is a part of another misfit it bent to follow (an effect outside
    /// the catalog, or the named cause's, which a rival follows as far as its range lets it).
    /// Not named by the statistical test; the evidence rule may still name it. An end that does
    /// not bind is where a flat valley ran out: the cause stands, and the note says so.
    fn pressed(&self, f: &Fitted, c: &Compared, j: &mut Judged) {
        let (ext, r) = (&f.ext, &f.refit);
        let pressed =
            Pressed::measured(&self.env, &f.free, ext, r, c.gains.vif, &mut j.simulations);
        if let Some(p) = pressed.as_ref().filter(|p| !p.binds()) {
            if !j.note.is_empty() {
                j.note.push_str("; ");
            }
            j.note += &format!(
                "{} rests at the upper end of its range, which does not bind: moved out by the \
                 range's width it gains Δχ² {:.1} (independent samples), below the one-parameter \
                 test's {BINDING_CHI2}",
                p.param.path,
                p.relaxed_gain.unwrap_or(0.0)
            );
        }
        if let Some(p) = pressed.filter(Pressed::binds) {
            let (q, v) = (&p.param, p.value);
            j.significant = false;
            j.note = format!(
                "not named: its extension presses against the upper end of its range ({} = {} in [{}, {}]{}): the \
                 residual asks for more of this effect than the cause can be, so it does not explain it (another \
                 effect may be at work)",
                q.path,
                fmt_num(v),
                fmt_num(q.lo),
                fmt_num(q.hi),
                p.relaxed_gain.map_or(String::new(), |g| format!(
                    "; moved out by the range's width it gains Δχ² {g:.1}"
                ))
            );
        }
    }

    /// The candidate's report: its standing, parameters, gains, the calibrated values it
    /// un-bends and the simulations of its re-fits.
    fn report(
        &self,
        rep: CandidateReport,
        f: &Fitted,
        h: &HeldOut,
        c: Compared,
        j: Judged,
        cache: &BaselineCache,
    ) -> CandidateReport {
        let r = &f.refit;
        let base_ref: &Refit = h.base_again.as_ref().unwrap_or(cache.at(self.key));
        let parameters = f
            .free
            .iter()
            .zip(&r.values)
            .enumerate()
            .map(|(i, (p, v))| CandidateParam {
                param: p.path.clone(),
                unit: p.unit.to_string(),
                start: p.start,
                min: p.lo,
                max: p.hi,
                result: *v,
                extension: i < f.ext.extension_free.len(),
                at_bound: p.at_bound(*v),
                std_error: None,
            })
            .collect();
        let g = &c.gains;
        self.env.progress.message(&format!(
            "diagnose: {}: χ² {:.1} -> {:.1} (fit), {:.1} -> {:.1} (held out), ΔBIC {:.1}{}",
            self.id,
            g.chi2_fit_base,
            g.chi2_fit_ext,
            g.chi2_held_base,
            g.chi2_held_ext,
            g.delta_bic,
            if j.significant { ", significant" } else { "" }
        ));
        let segments_simulations = h.segments.as_ref().map_or(0, |t| t.simulations);
        CandidateReport {
            extension: f.ext.description.clone(),
            fixed: f.ext.fixed.clone(),
            note: j.note,
            significant: j.significant,
            passed_test: j.passed_test,
            by_evidence: j.by_evidence,
            distortion: distortion(&self.opts.refit, &base_ref.unit, &r.unit),
            parameters,
            gains: Some(c.gains),
            simulations: segments_simulations
                + c.null.simulations
                + j.simulations
                + r.simulations
                + base_ref.simulations,
            failed_candidates: r.failures,
            ..rep
        }
    }
}

impl Judged {
    /// Not named: the test passed, a check refuses it (`why`).
    fn refuse(&mut self, why: String) {
        if self.significant {
            self.significant = false;
            self.note = format!("not named: {why}");
        }
    }
}
