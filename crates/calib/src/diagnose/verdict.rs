//! Step 6, the verdict: the candidates ranked, the named cause with its statement, or `none` /
//! `unexplained` with where the residual lives.

use std::collections::BTreeMap;

use crate::evidence::SignalEvidence;
use itaipu_dynamics::event::Event;
use itaipu_dynamics::simulate::Traces;
use itaipu_dynamics::unit::Unit;

use super::candidates::{bic_met, fit_floor_met, held_floor_met};
use super::*;

pub(super) fn fmt_num(v: f64) -> String {
    if v != 0.0 && (v.abs() < 1e-2 || v.abs() >= 1e4) {
        format!("{v:.4e}")
    } else {
        format!("{v:.4}")
    }
}

/// The event and P or Q signal with the largest residual RMS relative to its noise floor (the
/// evidence's `rms_over_noise`: the event's own floor, [`crate::noise::noise_floor`], as the
/// report shows it).
fn worst_residual<'a>(
    ev: &'a [EventEvidence],
    compared: &[&str],
) -> Option<(&'a str, &'a SignalEvidence)> {
    let mut worst: Option<(&str, &SignalEvidence)> = None;
    for e in ev {
        for s in e
            .signals
            .iter()
            .filter(|s| compared.contains(&s.signal.as_str()))
        {
            if worst.is_none_or(|(_, w)| s.rms_over_noise > w.rms_over_noise) {
                worst = Some((&e.event, s));
            }
        }
    }
    worst
}

/// The window holding the largest share of a signal's squared residual.
fn top_window(s: &SignalEvidence) -> Option<&crate::evidence::WindowStats> {
    s.windows
        .iter()
        .max_by(|a, b| a.share_of_sse.total_cmp(&b.share_of_sse))
}

/// A verdict that names no cause and carries no gains, grade or competitors: its id, title,
/// statement and where the residual lives.
fn unnamed(
    cause: &str,
    title: String,
    statement: String,
    where_: Option<(String, String, f64, f64)>,
) -> Verdict {
    Verdict {
        cause: cause.into(),
        title,
        statement,
        key_parameters: vec![],
        gains: None,
        where_,
        grade: None,
        probability: None,
        competing: vec![],
    }
}

/// The tests of a candidate's significance ([`DiagnoseOptions`]: `min_fit_drop`,
/// `min_held_drop`, `bic_threshold`) that its net gains `g` fall short of, as the verdict's
/// statement gives them, so that an engineer reading `none` sees which test an effect missed
/// and by how much. (A held-out blocks' shortfall is forgiven by the segments' second test,
/// reported apart in the candidate's note.)
pub(super) fn short_of(g: &Gains, opts: &DiagnoseOptions) -> Vec<String> {
    let mut out = vec![];
    if !fit_floor_met(g.fit_drop, opts) {
        out.push(shortfall("fitted", g.fit_drop, opts.min_fit_drop));
    }
    if !held_floor_met(g.held_drop, opts) {
        out.push(shortfall("held-out", g.held_drop, opts.min_held_drop));
    }
    if !bic_met(g.record_evidence, opts) {
        out.push(format!(
            "2 ln B {:.1}, not above {:.0}",
            g.record_evidence, opts.bic_threshold
        ));
    }
    if out.is_empty() {
        out.push("its held-out blocks and segments do not confirm it".into());
    }
    out
}

/// A relative χ² change short of its floor, as a statement gives it: "the fitted χ² down 1.6 %,
/// under 2.0 %", "the held-out χ² up 0.4 %" (a rise is short of any floor), "the fitted χ²
/// unchanged" (below the 0.05 % the statement prints).
fn shortfall(half: &str, drop: f64, floor: f64) -> String {
    let pct = 100.0 * drop;
    if pct.abs() < 0.05 {
        format!("the {half} χ² unchanged")
    } else if pct < 0.0 {
        format!("the {half} χ² up {:.1} %", -pct)
    } else {
        format!(
            "the {half} χ² down {pct:.1} %, under {:.1} %",
            100.0 * floor
        )
    }
}

/// The verdict when no cause is significant: `none` at the noise floor, else `unexplained`
/// with where the residual lives. A candidate whose gain passed the statistical test and was
/// refused by its physical checks ([`CandidateReport::passed_test`]) makes it `unexplained` at
/// the noise floor too: the test that would have named a cause says an effect is there (its
/// false-alarm rate is the naming's own, whatever refused the name), and the check says it is
/// not that cause, so "the model needs no extension" would be false.
pub(super) fn undecided(
    ev: &[EventEvidence],
    compared: &[&str],
    reports: &[CandidateReport],
    opts: &DiagnoseOptions,
) -> Verdict {
    let ratio = |s: &SignalEvidence| s.rms_over_noise;
    let worst = worst_residual(ev, compared);
    let best_try = reports
        .iter()
        .filter_map(|r| r.gains.as_ref().map(|g| (r, g)))
        .next()
        .map(|(r, g)| {
            format!(
                " The best candidate, {}, gained ΔBIC {:.1} ({:.1} % of χ²; the record's evidence \
                 with its held-out prediction 2 ln B = {:.1}){}.",
                r.cause,
                g.delta_bic,
                100.0 * g.fit_drop,
                g.record_evidence,
                if r.note.starts_with("not named") {
                    format!(", {}", r.note)
                } else {
                    format!(", not significant ({})", short_of(g, opts).join("; "))
                }
            )
        })
        .unwrap_or_default();
    let Some((event, s)) = worst else {
        return unnamed(
            "none",
            "no residual to explain".into(),
            format!(
                "No residual of the compared signals ({}).",
                compared.join(", ")
            ),
            None,
        );
    };
    let top = top_window(s);
    let where_ = top.map(|w| (s.signal.clone(), w.label.clone(), w.start_s, w.end_s));
    let over = ratio(s);
    // The largest residual in the recorded field of a phasor playback (P and Q compared too):
    // what a calibration on P and Q alone can leave, X_d and the exciter's gain bent until the
    // simulated field runs off the recorded one. The condition is structural (which compared
    // signal holds the largest residual), no threshold: the verdict is already `unexplained`,
    // the residual above the noise floor by `noise_factor`.
    let field_hint = if compared.contains(&"P")
        && compared.contains(&"Q")
        && super::playback::signal_channel(&s.signal)
            .is_some_and(|c| super::playback::FIELD_CHANNELS.contains(&c))
    {
        " If the calibration compared P and Q alone, it may have bent X_d and the exciter's gain \
         until the simulated field ran off the recorded one: calibrate with channels = \"recorded\" \
         (P, Q and the recorded field, each weighted by its noise) and diagnose again."
    } else {
        ""
    };
    // The refused candidate with the largest evidence for the record.
    let refused = reports
        .iter()
        .filter(|r| r.passed_test && !r.significant)
        .filter_map(|r| r.gains.as_ref().map(|g| (r, g)))
        .max_by(|(_, a), (_, b)| a.record_evidence.total_cmp(&b.record_evidence));
    if let Some((r, g)) = refused.filter(|_| over <= opts.noise_factor) {
        let why = r.note.strip_prefix("not named: ").unwrap_or(&r.note);
        let place = top.map_or(String::new(), |w| {
            format!(
                "; the largest residual is {} in the {} window ({:.2}-{:.2} s) on {event}",
                s.signal, w.label, w.start_s, w.end_s
            )
        });
        unnamed(
            "unexplained",
            format!(
                "unexplained: a significant gain that {} cannot be",
                r.cause
            ),
            format!(
                "Unexplained by the catalog. The residuals are near the noise level (largest: {} on {event}, the reference's RMS \
                 over the whole record {:.2} × the noise σ), yet the extension of {} ({}) lowers χ² on the fitted samples by {:.1} % and on the \
                 held-out samples by {:.1} % (the record's evidence 2 ln B = {:.1}), a gain the test names a cause on; it is \
                 not named: {why}. An effect the catalog does not hold is at work where {} acts{place}. If you know the \
                 unit's setting that makes it, write a cause file for it and diagnose again with --user-cause.",
                s.signal,
                over,
                r.cause,
                r.extension,
                100.0 * g.fit_drop,
                100.0 * g.held_drop,
                g.record_evidence,
                r.cause
            ),
            where_,
        )
    } else if over <= opts.noise_factor {
        unnamed(
            "none",
            "residual at the noise floor".into(),
            format!(
                "No cause named: the residuals are at the noise level (largest: {} on {event}, the reference's RMS over \
                 the whole record {:.2} × the noise σ; Ljung-Box p = {:.2}) and no extension gains significantly.{best_try} The model needs no extension \
                 for these data.",
                s.signal, over, s.whiteness.p_value
            ),
            where_,
        )
    } else if let Some(w) = top {
        let mode = s
            .modes
            .iter()
            .filter(|m| m.is_finding())
            .max_by(|a, b| a.energy_share.total_cmp(&b.energy_share))
            .map(|m| {
                format!(
                    ", dominant residual mode {:.2} Hz (ζ = {:.2})",
                    m.freq_hz, m.damping_ratio
                )
            })
            .unwrap_or_default();
        unnamed(
            "unexplained",
            format!("unexplained residual at {} ({}, {:.2}-{:.2} s)", s.signal, w.label, w.start_s, w.end_s),
            format!(
                "Unexplained residual at {} in the {} window ({:.2}-{:.2} s, {:.0} % of its squared error) on {event}: the reference's RMS \
                 over the whole record {:.2} × the noise σ, Ljung-Box p = {:.2}{mode}. No catalog extension explains it significantly.{best_try}{field_hint}",
                s.signal,
                w.label,
                w.start_s,
                w.end_s,
                100.0 * w.share_of_sse,
                over,
                s.whiteness.p_value
            ),
            where_,
        )
    } else {
        // No window (a record too short to cut into any): the residual as a whole.
        unnamed(
            "unexplained",
            format!("unexplained residual at {}", s.signal),
            format!(
                "Unexplained residual at {} on {event}: the reference's RMS over the whole record \
                 {:.2} × the noise σ, Ljung-Box p = {:.2}. No catalog extension explains it significantly.{best_try}{field_hint}",
                s.signal, over, s.whiteness.p_value
            ),
            None,
        )
    }
}

/// The verdict of a diagnosis, with the named cause's extended unit and its traces and
/// evidence (empty when none is named).
pub(super) struct Decision {
    pub verdict: Verdict,
    pub extended_unit: Option<Unit>,
    pub after: Vec<(String, Traces)>,
    pub evidence_after: Vec<EventEvidence>,
}

/// Ranks `reports` (see [`Diagnosis::candidates`]) and decides: the first significant
/// candidate is named (with the standard errors of its re-fit in `refits`), else
/// [`undecided`]. A named cause whose re-fits played the record as recorded
/// ([`CandidateReport::input_as_recorded`]) gets its standard errors and its evidence after on
/// `recorded` (the events played back so).
#[allow(clippy::too_many_arguments)]
pub(super) fn decide(
    reports: &mut [CandidateReport],
    mut refits: BTreeMap<String, RefitRecord>,
    events: &[Event],
    recorded: Option<&[Event]>,
    (pb, weights, compare): super::playback::Scoring,
    evidence_before: &[EventEvidence],
    opts: &DiagnoseOptions,
) -> Decision {
    // 5. Rank and decide.
    let compared: Vec<&str> = pb
        .channels
        .iter()
        .map(|c| super::playback::signal_name(*c))
        .collect();
    // Significant candidates first. Each passed the test against its own baseline (the same
    // interacting parameters re-fitted without it); among them, the extended model that
    // explains the data best wins: lowest BIC on the common fitted samples,
    // χ²_ext + k ln N with k every parameter the candidate re-fitted (a cause whose extension
    // is only significant because its baseline stayed bent does not beat one that fits). The
    // others follow by ΔBIC.
    let bic_ext = |r: &CandidateReport| {
        r.gains.as_ref().map_or(f64::INFINITY, |g| {
            comparable_chi2(g) + r.parameters.len() as f64 * (g.n_fit.max(1) as f64).ln()
        })
    };
    reports.sort_by(|a, b| {
        let s = |r: &CandidateReport| r.gains.as_ref().map_or(f64::NEG_INFINITY, |g| g.delta_bic);
        b.significant.cmp(&a.significant).then(if a.significant {
            bic_ext(a).total_cmp(&bic_ext(b))
        } else {
            s(b).total_cmp(&s(a))
        })
    });
    // Two significant candidates whose extended models explain the fitted samples about
    // equally: no name (a wrong name is worse than none), the verdict says which compete.
    let significant: Vec<&CandidateReport> = reports
        .iter()
        .filter(|r| r.significant && r.gains.is_some())
        .collect();
    if let [best, rivals @ ..] = significant.as_slice() {
        let competing: Vec<(String, f64)> = rivals
            .iter()
            .map(|r| (r.cause.clone(), bic_gap(best, r)))
            .filter(|(_, gap)| *gap < opts.bic_threshold)
            .collect();
        if !competing.is_empty() {
            let verdict = inconclusive(best, &competing, reports, evidence_before, &compared, opts);
            return Decision {
                verdict,
                extended_unit: None,
                after: vec![],
                evidence_after: vec![],
            };
        }
    }
    // The held-out samples contradict the fitted ranking: a rival's extended model predicts
    // them decisively better than the best's. No name either.
    if let [best, rivals @ ..] = significant.as_slice() {
        let contradicting: Vec<(&CandidateReport, f64)> = rivals
            .iter()
            .map(|r| (*r, held_out_gap(best, r)))
            .filter(|(_, gap)| *gap > opts.bic_threshold)
            .collect();
        if !contradicting.is_empty() {
            let verdict = contradicted(best, &contradicting, evidence_before, &compared, opts);
            return Decision {
                verdict,
                extended_unit: None,
                after: vec![],
                evidence_after: vec![],
            };
        }
    }
    // A significant candidate has its re-fit and its gains (`Candidates::score` returns them
    // with every report it scores); one without them could not be named, and is not.
    // A look-alike outside the catalog explains the residual best: no catalog name.
    if let Some(best) = significant.first().filter(|r| r.look_alike) {
        let verdict = outside_catalog(best, reports, evidence_before, &compared);
        return Decision {
            verdict,
            extended_unit: None,
            after: vec![],
            evidence_after: vec![],
        };
    }
    let named = reports
        .iter()
        .find(|r| r.significant)
        .cloned()
        .and_then(|rep| {
            let g = rep.gains.clone()?;
            let refit = refits.remove(&rep.cause)?;
            Some((rep, g, refit))
        });
    let mut extended_unit = None;
    let mut after = vec![];
    let mut evidence_after = vec![];
    let verdict = match named {
        Some((mut rep, g, (r, bounds, ties))) => {
            let events = match recorded {
                Some(raw) if rep.input_as_recorded => raw,
                _ => events,
            };
            // Uncertainty of the re-fitted parameters (all samples, with the priors).
            if let Some(se) =
                std_errors(&r.unit, &bounds, &ties, &r.values, events, weights, compare)
            {
                for (p, e) in rep.parameters.iter_mut().zip(se) {
                    p.std_error = Some(e);
                }
                if let Some(c) = reports.iter_mut().find(|c| c.cause == rep.cause) {
                    c.parameters = rep.parameters.clone();
                }
            }
            for e in events {
                if let Ok((tr, ev, _)) = pb.evidence(&r.unit, e) {
                    evidence_after.push(ev);
                    after.push((e.name.clone(), tr));
                }
            }
            let mut key: Vec<(String, f64, String)> = rep
                .parameters
                .iter()
                .filter(|p| p.extension)
                .map(|p| (p.param.clone(), p.result, p.unit.clone()))
                .collect();
            key.extend(
                rep.fixed
                    .iter()
                    .map(|(p, v)| (p.clone(), *v, "-".to_string())),
            );
            let params: Vec<String> = key
                .iter()
                .map(|(p, v, u)| {
                    let se = rep
                        .parameters
                        .iter()
                        .find(|c| &c.param == p)
                        .and_then(|c| c.std_error)
                        .filter(|e| e.is_finite())
                        .map_or(String::new(), |e| format!(" ± {}", fmt_num(e)));
                    format!("{p} = {}{se} {u}", fmt_num(*v))
                })
                .collect();
            let statement = format!(
                "{}: {}. The extension ({}) lowers χ² on the fitted samples by {:.0} % ({:.1} -> {:.1}) and on the held-out \
                 samples by {:.0} %{}; ΔBIC = {:.1} with {} added parameter(s), and with the held-out samples' \
                 predictive gain the record's evidence 2 ln B = {:.1}. Fitted values: {}.",
                rep.cause,
                rep.title,
                rep.extension,
                100.0 * g.fit_drop,
                g.chi2_fit_base,
                g.chi2_fit_ext,
                100.0 * g.held_drop,
                g.held_drop_segments.map_or(String::new(), |d| format!(
                    " (on the held-out {SEGMENT_S} s segments of the second test by {:.0} %)",
                    100.0 * d
                )),
                g.delta_bic,
                g.k,
                g.record_evidence,
                params.join(", ")
            );
            // Which calibrated values become plausible again with it.
            let back: Vec<String> = rep
                .distortion
                .iter()
                .filter(|d| d.z_base.abs() > 1.0 && d.z_extended.abs() < d.z_base.abs())
                .map(|d| {
                    format!(
                        "{} {} -> {} (datasheet {})",
                        d.param,
                        fmt_num(d.base),
                        fmt_num(d.extended),
                        fmt_num(d.datasheet)
                    )
                })
                .collect();
            let statement = if back.is_empty() {
                statement
            } else {
                format!(
                    "{statement} Without it the re-fitted unit bends calibrated values away from their datasheet; with it they come back: {}.",
                    back.join(", ")
                )
            };
            let probability = posterior(&rep, reports);
            // Strong: odds of 99:1 or better, and the held-out blocks confirm the gain by the
            // same test that made it significant (not only the segments' second test, not only
            // the cause's signature in the evidence).
            let grade = if rep.by_evidence {
                Grade::Moderate
            } else {
                grade(probability, &g, opts)
            };
            let statement = format!(
                "{statement} Confidence: {} (posterior probability {:.3} against its re-fitted baseline and the {} other significant candidate(s)).",
                grade.as_str(),
                probability,
                reports.iter().filter(|c| c.significant && c.cause != rep.cause).count()
            );
            extended_unit = Some(r.unit);
            Verdict {
                cause: rep.cause.clone(),
                title: rep.title.clone(),
                statement,
                key_parameters: key,
                gains: Some(g),
                where_: None,
                grade: Some(grade),
                probability: Some(probability),
                competing: vec![],
            }
        }
        None => undecided(evidence_before, &compared, reports, opts),
    };

    Decision {
        verdict,
        extended_unit,
        after,
        evidence_after,
    }
}

/// A candidate's fitted χ² as candidates are compared with each other: without the echo of
/// the voltage's noise that a re-fit on the record as recorded carries ([`Gains::input_echo`]).
fn comparable_chi2(g: &Gains) -> f64 {
    g.chi2_fit_ext - g.input_echo
}

/// The VIF-deflated BIC of `other`'s extended model above `best`'s, on the common fitted
/// samples: `(χ²_other − χ²_best)/v + (k_other − k_best) ln(N/v)`, k every parameter each
/// re-fitted and `v` the larger of the two baselines' variance inflation (the conservative
/// choice: a coloured residual counts as fewer independent samples, which narrows the gap).
/// Positive favours `best`. Infinite when either has no gains.
pub(super) fn bic_gap(best: &CandidateReport, other: &CandidateReport) -> f64 {
    let (Some(a), Some(b)) = (&best.gains, &other.gains) else {
        return f64::INFINITY;
    };
    let v = a.vif.max(b.vif).max(1.0);
    let n = (a.n_fit.max(1) as f64 / v).max(1.0);
    (comparable_chi2(b) - comparable_chi2(a)) / v
        + (other.parameters.len() as f64 - best.parameters.len() as f64) * n.ln()
}

/// How much better `other`'s extended model predicts the held-out samples than `best`'s: the
/// difference of their held-out χ² deflated by the larger variance inflation, as [`bic_gap`]
/// (no parameter term: neither re-fit saw those samples, so the difference is twice the log
/// likelihood ratio of two predictions). Positive favours `other`. Zero when either has no
/// gains or when one of them was played back as recorded and the other smoothed (their held-out
/// χ² then hold different echoes of the voltage's noise, measured on the fitted samples only).
pub(super) fn held_out_gap(best: &CandidateReport, other: &CandidateReport) -> f64 {
    let (Some(a), Some(b)) = (&best.gains, &other.gains) else {
        return 0.0;
    };
    if best.input_as_recorded != other.input_as_recorded {
        return 0.0;
    }
    (a.chi2_held_ext - b.chi2_held_ext) / a.vif.max(b.vif).max(1.0)
}

/// The named candidate's approximate posterior probability (equal prior odds) among its
/// re-fitted baseline (`ΔBIC` below it) and the other significant candidates' extensions
/// ([`bic_gap`] above it): `1 / (1 + e^{−ΔBIC/2} + Σ e^{−gap/2})`, Schwarz's approximation of
/// the marginal likelihood. A candidate that failed its own test is no rival explanation: its
/// extension gained nothing over its baseline, and its extended model's χ² differs from the
/// named one's by what the two baselines' searches found (each re-fits other interacting
/// parameters), not by the cause. The figure is an approximation a reviewer weighs, not an
/// exact Bayes factor.
pub(super) fn posterior(named: &CandidateReport, reports: &[CandidateReport]) -> f64 {
    let Some(g) = &named.gains else {
        return 0.0;
    };
    let mut odds_against = (-g.delta_bic / 2.0).exp();
    for r in reports
        .iter()
        .filter(|r| r.cause != named.cause && r.significant)
    {
        let gap = bic_gap(named, r);
        if gap.is_finite() {
            odds_against += (-gap / 2.0).exp();
        }
    }
    1.0 / (1.0 + odds_against)
}

/// A named cause's grade: `strong` with a posterior probability of at least
/// [`STRONG_PROBABILITY`], a ΔBIC against its baseline above the threshold and a held-out drop
/// of at least `min_held_drop` on the interleaved blocks (the gain predicted, not only fitted);
/// `moderate` otherwise (named by the segments' second test or by its signature, or a rival
/// close behind).
pub(super) fn grade(probability: f64, g: &Gains, opts: &DiagnoseOptions) -> Grade {
    if probability >= STRONG_PROBABILITY
        && held_floor_met(g.held_drop, opts)
        && bic_met(g.delta_bic, opts)
    {
        Grade::Strong
    } else {
        Grade::Moderate
    }
}

/// Why a candidate that passed its test against its baseline still does not explain the misfit
/// it was tried on: with its extension the fitted residual is still above the noise floor
/// (`χ²_ext > noise_factor² · N`, N fitted residuals, each of noise variance 1 by the weights:
/// the RMS `undecided` calls the floor), and the extension took away less of the misfit above
/// the noise than it left (`χ²_base − χ²_ext < χ²_ext − N`). A cause is named as *the* cause of
/// a misfit; one that removes a minority of it while most stays has fitted a part of another
/// effect's (an effect outside the catalog, or a catalog cause whose own re-fit failed to find
/// it), and naming it would send an engineer after the smaller part. "Most" is the majority
/// of the excess over the noise's χ². The floor gate keeps the rule off residuals at the noise
/// level, where `N` as the noise's χ² is only as exact as the pre-event σ; above the floor the
/// excess is far larger than that uncertainty.
pub(super) fn explains_too_little(g: &Gains, noise_factor: f64) -> Option<String> {
    let n = g.n_fit.max(1) as f64;
    let (base, ext) = (g.chi2_fit_base, g.chi2_fit_ext);
    let floor = noise_factor * noise_factor * n;
    (ext > floor && base - ext < ext - n).then(|| {
        format!(
            "it explains {:.0} % of the misfit above the noise (fitted χ² {:.0} -> {:.0}, {:.0} at the noise level) and \
             leaves {:.1} times the noise variance: most of the misfit is another effect's",
            100.0 * (base - ext) / (base - n),
            base,
            ext,
            n,
            ext / n
        )
    })
}

/// A verdict that names no cause but lists the candidates behind it (`inconclusive`, or
/// `unexplained` by a look-alike): `best` first, then `others` with their BIC gaps above it,
/// and where the residual lives as `undecided` finds it.
fn listing(
    cause: &str,
    title: String,
    statement: String,
    (ev, compared): (&[EventEvidence], &[&str]),
    best: &CandidateReport,
    others: Vec<(String, f64)>,
) -> Verdict {
    let where_ = worst_residual(ev, compared).and_then(|(_, s)| {
        top_window(s).map(|w| (s.signal.clone(), w.label.clone(), w.start_s, w.end_s))
    });
    Verdict {
        competing: std::iter::once((best.cause.clone(), 0.0))
            .chain(others)
            .collect(),
        ..unnamed(cause, title, statement, where_)
    }
}

/// The verdict when a look-alike outside the catalog ([`super::look_alike`]) is the best
/// significant candidate: `unexplained`, saying what the residual looks like, which catalog
/// causes it beats and how to name it; `competing` holds the look-alike, then those causes
/// with their extended models' BIC above it.
fn outside_catalog(
    best: &CandidateReport,
    reports: &[CandidateReport],
    ev: &[EventEvidence],
    compared: &[&str],
) -> Verdict {
    let beaten: Vec<(String, f64)> = reports
        .iter()
        .filter(|r| r.significant && !r.look_alike && r.gains.is_some())
        .map(|r| (r.cause.clone(), bic_gap(best, r)))
        .collect();
    let gains = best.gains.as_ref().map_or(String::new(), |g| {
        format!(
            ": its extension ({}) lowers χ² on the fitted samples by {:.0} % and on the held-out samples by {:.0} %, \
             the record's evidence 2 ln B = {:.1}",
            best.extension,
            100.0 * g.fit_drop,
            100.0 * g.held_drop,
            g.record_evidence
        )
    });
    let catalog = if beaten.is_empty() {
        String::new()
    } else {
        let list: Vec<String> = beaten
            .iter()
            .map(|(c, gap)| format!("{c} (its extended model's BIC {gap:.1} above)"))
            .collect();
        let verbs = if list.len() == 1 {
            "also passes its own test but explains the data less well; it is"
        } else {
            "also pass their own tests but explain the data less well; they are"
        };
        format!(
            " {} {verbs} not named, as the nearest catalog cause to an effect outside the catalog \
             would be a wrong name.",
            list.join(" and ")
        )
    };
    let file = super::look_alike::file_of(&best.cause);
    listing(
        "unexplained",
        format!(
            "unexplained by the catalog: looks like {} ({})",
            best.title, best.cause
        ),
        format!(
            "Unexplained by the catalog. The residual is explained best by an effect outside the catalog that the \
             diagnosis tries as a look-alike, {} ({}){gains}.{catalog} If the unit has this setting, diagnose again \
             with --user-cause {file} to name it and re-fit with it; if not, write a cause file for the effect it has.",
            best.title, best.cause
        ),
        (ev, compared),
        best,
        beaten,
    )
}

/// A candidate as the verdicts that list it name it: its id, and for a look-alike the bundled
/// file that models it.
fn display_name(c: &CandidateReport) -> String {
    if c.look_alike {
        format!(
            "{} (outside the catalog: {})",
            c.cause,
            super::look_alike::file_of(&c.cause)
        )
    } else {
        c.cause.clone()
    }
}

/// The verdict when two or more significant candidates explain the residual within the BIC
/// threshold of each other: `inconclusive`, with the competitors and where the residual lives.
fn inconclusive(
    best: &CandidateReport,
    competing: &[(String, f64)],
    reports: &[CandidateReport],
    ev: &[EventEvidence],
    compared: &[&str],
    opts: &DiagnoseOptions,
) -> Verdict {
    let describe = |c: &CandidateReport| {
        let name = display_name(c);
        c.gains.as_ref().map_or(name.clone(), |g| {
            format!(
                "{name} (ΔBIC {:.1} against its baseline, fitted χ² −{:.0} %, held out −{:.0} %)",
                g.delta_bic,
                100.0 * g.fit_drop,
                100.0 * g.held_drop
            )
        })
    };
    let rivals: Vec<String> = competing
        .iter()
        .filter_map(|(c, gap)| {
            reports.iter().find(|r| &r.cause == c).map(|r| {
                format!(
                    "{}, whose extended model's BIC is {gap:.1} above",
                    describe(r)
                )
            })
        })
        .collect();
    let names: Vec<&str> = std::iter::once(best.cause.as_str())
        .chain(competing.iter().map(|(c, _)| c.as_str()))
        .collect();
    listing(
        "inconclusive",
        format!("inconclusive: {}", names.join(" or ")),
        format!(
            "Inconclusive: more than one cause explains the residual about equally. {} passes its test, and so does {}: a              BIC difference below {:.0} (Kass and Raftery's \"very strong\" level, the one each cause had to pass against its              baseline) does not decide between them, so none is named. Test them apart with another event (a step of the              other sign or size, a different operating point) or hold one of them out by knowledge of the unit.",
            describe(best),
            rivals.join("; and "),
            opts.bic_threshold
        ),
        (ev, compared),
        best,
        competing.to_vec(),
    )
}

/// The verdict when the fitted and the held-out samples disagree: `best` explains the fitted
/// samples best (lowest BIC of the significant candidates' extended models), but each of
/// `contradicting` (candidate, [`held_out_gap`]) predicts the held-out samples better by more than
/// the BIC threshold, the "very strong" level each cause had to pass against its baseline. A
/// cause is named for what it predicts, not only for what it fits: a model that fits the
/// samples it saw better and predicts the others worse has absorbed some of another effect's
/// misfit. `inconclusive`, listing both.
fn contradicted(
    best: &CandidateReport,
    contradicting: &[(&CandidateReport, f64)],
    ev: &[EventEvidence],
    compared: &[&str],
    opts: &DiagnoseOptions,
) -> Verdict {
    let rivals: Vec<String> = contradicting
        .iter()
        .map(|(r, gap)| {
            format!(
                "{}, whose extended model predicts the held-out samples better by Δχ² = {gap:.1} (deflated by the \
                 residual's variance inflation) although its BIC on the fitted samples is {:.1} above",
                display_name(r),
                bic_gap(best, r)
            )
        })
        .collect();
    let names: Vec<&str> = std::iter::once(best.cause.as_str())
        .chain(contradicting.iter().map(|(r, _)| r.cause.as_str()))
        .collect();
    listing(
        "inconclusive",
        format!("inconclusive: {}", names.join(" or ")),
        format!(
            "Inconclusive: the fitted and the held-out samples disagree. {} passes its test and explains the fitted \
             samples best, but so does {}: more than {:.0} (Kass and Raftery's \"very strong\" level) on samples neither \
             re-fit saw. A cause that fits better what it saw and predicts worse what it did not has absorbed part of \
             another effect's misfit, so none is named. Test them apart with another event, or hold one of them out by \
             knowledge of the unit.",
            display_name(best),
            rivals.join("; and "),
            opts.bic_threshold
        ),
        (ev, compared),
        best,
        contradicting
            .iter()
            .map(|(r, _)| (r.cause.clone(), bic_gap(best, r)))
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::evidence::{analyse, EvidenceOptions};

    /// A residual far above the noise whose evidence has no window (the windows are the
    /// caller's; none may fit a short record) is `unexplained` as a whole: it used to be an
    /// `expect("windows exist")`.
    #[test]
    fn an_unexplained_residual_without_windows_gives_a_verdict() {
        let t: Vec<f64> = (0..200).map(|k| k as f64 / 60.0).collect();
        let r: Vec<f64> = t.iter().map(|x| 0.05 * (3.0 * x).sin()).collect();
        let s = analyse("Q", &t, &r, &r, &[], &EvidenceOptions::default());
        assert!(s.windows.is_empty());
        let ev = [EventEvidence {
            event: "e".into(),
            onset_s: 1.0,
            signals: vec![s],
            p_peak: None,
        }];
        let v = undecided(&ev, &["P", "Q"], &[], &DiagnoseOptions::default());
        assert_eq!(v.cause, "unexplained");
        says(&v.statement, "Unexplained residual at Q on e");
        assert!(v.where_.is_none());
        assert!(!v.statement.contains("recorded"), "{}", v.statement);
    }

    /// A candidate whose gain passed the test and was refused by its physical checks makes a
    /// residual near the noise floor `unexplained` (where it lives and why the cause was
    /// refused); the same candidate without a passed test leaves it `none`, and above the
    /// floor the residual's own verdict stands.
    #[test]
    fn a_refused_significant_gain_is_unexplained_not_none() {
        let t: Vec<f64> = (0..600).map(|k| k as f64 / 60.0).collect();
        let r: Vec<f64> = t.iter().map(|x| 0.05 * (3.0 * x).sin()).collect();
        let eopts = EvidenceOptions {
            windows: vec![("dip".into(), 1.0, 2.0), ("tail".into(), 2.0, 10.0)],
            ..EvidenceOptions::default()
        };
        let mut ev = vec![EventEvidence {
            event: "e".into(),
            onset_s: 1.0,
            signals: vec![analyse("P", &t, &r, &r, &[], &eopts)],
            p_peak: None,
        }];
        ev[0].signals[0].rms_over_noise = 1.1;
        let opts = DiagnoseOptions::default();
        let why = "its extension presses against the upper end of its range (x = 2 in [0, 2])";
        let mut refused = candidate("saturation", 300.0, 2, 40.0, false);
        refused.passed_test = true;
        refused.note = format!("not named: {why}");
        let quiet = candidate("governor", 380.0, 2, -3.0, false);
        let v = undecided(&ev, &["P", "Q"], &[quiet.clone(), refused.clone()], &opts);
        assert_eq!(v.cause, "unexplained", "{}", v.statement);
        says(&v.statement, why);
        says(&v.statement, "extension of saturation");
        says(&v.statement, "tail window (2.00-10.00 s) on e");
        assert!(v.where_.is_some());
        assert!(v.competing.is_empty());
        // Through the ranking too: nothing significant, the refused gain decides.
        let d = decide_on(vec![quiet.clone(), refused.clone()]);
        assert_eq!(d.verdict.cause, "unexplained", "{}", d.verdict.statement);
        // Without a passed test the same reports are `none`.
        let untested = CandidateReport {
            passed_test: false,
            ..refused.clone()
        };
        let v = undecided(&ev, &["P", "Q"], &[quiet.clone(), untested], &opts);
        assert_eq!(v.cause, "none", "{}", v.statement);
        // Above the floor the residual's verdict, with its window, is unchanged.
        ev[0].signals[0].rms_over_noise = 3.0;
        let v = undecided(&ev, &["P", "Q"], &[refused, quiet], &opts);
        assert_eq!(v.cause, "unexplained");
        says(&v.statement, "Unexplained residual at P");
    }

    /// A `none` verdict says which significance tests its best candidate fell short of, and by
    /// how much: a candidate short of the held-out floor alone names that floor only; one short
    /// of every test names all three, a rise as a rise; a change under what the statement
    /// prints as unchanged (not "-0.0 %"); a fitted floor set by the user is named too.
    #[test]
    fn a_none_verdict_names_the_tests_its_best_candidate_missed() {
        let mut ev = evidence();
        ev[0].signals[0].rms_over_noise = 1.1;
        let opts = DiagnoseOptions::default();
        let with = |fit: f64, held: f64, evidence: f64| {
            let mut c = candidate("governor", 380.0, 2, 12.0, false);
            if let Some(g) = c.gains.as_mut() {
                (g.fit_drop, g.held_drop, g.record_evidence) = (fit, held, evidence);
            }
            c
        };
        let v = undecided(&ev, &["P", "Q"], &[with(0.016, 0.009, 26.4)], &opts);
        assert_eq!(v.cause, "none", "{}", v.statement);
        says(
            &v.statement,
            "not significant (the held-out χ² down 0.9 %, under 1.0 %)",
        );
        let v = undecided(&ev, &["P", "Q"], &[with(-0.003, -0.004, 0.5)], &opts);
        says(
            &v.statement,
            "not significant (the fitted χ² up 0.3 %; the held-out χ² up 0.4 %; 2 ln B 0.5, not \
             above 10)",
        );
        let v = undecided(&ev, &["P", "Q"], &[with(-0.0002, 0.02, 5.0)], &opts);
        says(
            &v.statement,
            "not significant (the fitted χ² unchanged; 2 ln B 5.0, not above 10)",
        );
        let floor = DiagnoseOptions {
            min_fit_drop: 0.02,
            ..DiagnoseOptions::default()
        };
        let v = undecided(&ev, &["P", "Q"], &[with(0.016, 0.02, 37.0)], &floor);
        says(
            &v.statement,
            "not significant (the fitted χ² down 1.6 %, under 2.0 %)",
        );
    }

    /// An unexplained residual in the recorded field of a phasor playback says how the
    /// calibration may have left it (P and Q alone) and what to do; in a playback mode that
    /// compares E_fd without P it does not.
    #[test]
    fn an_unexplained_field_residual_points_to_the_recorded_channels() {
        let t: Vec<f64> = (0..200).map(|k| k as f64 / 60.0).collect();
        let r: Vec<f64> = t.iter().map(|x| 0.05 * (3.0 * x).sin()).collect();
        let ev = |signal: &str| {
            [EventEvidence {
                event: "e".into(),
                onset_s: 1.0,
                signals: vec![analyse(
                    signal,
                    &t,
                    &r,
                    &r,
                    &[],
                    &EvidenceOptions::default(),
                )],
                p_peak: None,
            }]
        };
        let opts = DiagnoseOptions::default();
        let v = undecided(&ev("Ifd"), &["P", "Q", "Efd", "Ifd"], &[], &opts);
        assert_eq!(v.cause, "unexplained");
        says(&v.statement, "channels = \"recorded\"");
        let v = undecided(&ev("Efd"), &["|V|", "Q", "Efd"], &[], &opts);
        assert!(!v.statement.contains("recorded"), "{}", v.statement);
    }

    /// Asserts that a verdict's text holds `part`, printing the text when it does not.
    fn says(text: &str, part: &str) {
        assert!(text.contains(part), "expected {part:?} in: {text}");
    }

    /// The causes a verdict lists as competing, in order.
    fn competitors(v: &Verdict) -> Vec<&str> {
        v.competing.iter().map(|(c, _)| c.as_str()).collect()
    }

    fn candidate(
        cause: &str,
        chi2_ext: f64,
        k: usize,
        delta_bic: f64,
        significant: bool,
    ) -> CandidateReport {
        CandidateReport {
            cause: cause.into(),
            title: cause.into(),
            applicable: true,
            note: String::new(),
            extension: String::new(),
            parameters: (0..k)
                .map(|i| CandidateParam {
                    param: format!("{cause}.p{i}"),
                    unit: "pu".into(),
                    start: 1.0,
                    min: 0.0,
                    max: 2.0,
                    result: 1.0,
                    extension: i == 0,
                    at_bound: false,
                    std_error: None,
                })
                .collect(),
            fixed: vec![],
            gains: Some(Gains {
                chi2_fit_base: chi2_ext + 100.0,
                chi2_fit_ext: chi2_ext,
                input_echo: 0.0,
                chi2_held_base: 500.0,
                chi2_held_ext: 400.0,
                null_gain_fit: 0.0,
                null_gain_held: 0.0,
                null_gains_fit: vec![],
                null_gains_held: vec![],
                fit_drop: 0.1,
                held_drop: 0.2,
                held_drop_segments: None,
                delta_bic,
                record_evidence: delta_bic + 50.0,
                vif: 2.0,
                k: 1,
                n_fit: 1000,
                n_held: 1000,
                rms: vec![],
                rms_p_base: 0.01,
                rms_q_base: 0.01,
                rms_p_ext: 0.005,
                rms_q_ext: 0.005,
            }),
            significant,
            passed_test: significant,
            look_alike: false,
            by_evidence: false,
            signature: vec![],
            simulations: 0,
            failed_candidates: 0,
            wall_s: 0.0,
            distortion: vec![],
            input_as_recorded: false,
        }
    }

    fn evidence() -> Vec<EventEvidence> {
        let t: Vec<f64> = (0..600).map(|k| k as f64 / 60.0).collect();
        let r: Vec<f64> = t.iter().map(|x| 0.05 * (3.0 * x).sin()).collect();
        vec![EventEvidence {
            event: "e".into(),
            onset_s: 1.0,
            signals: vec![analyse("P", &t, &r, &r, &[], &EvidenceOptions::default())],
            p_peak: None,
        }]
    }

    /// `decide` on the reports alone (no re-fit records: a name falls back to undecided).
    fn decide_on(mut reports: Vec<CandidateReport>) -> Decision {
        decide(
            &mut reports,
            BTreeMap::new(),
            &[],
            None,
            (&Playback::phasor(), (1.0, 1.0), None),
            &evidence(),
            &DiagnoseOptions::default(),
        )
    }

    /// A cause that removes a minority of a misfit far above the noise is turned away; one that
    /// removes most of it, or leaves the residual at the noise floor, is not.
    #[test]
    fn a_cause_that_leaves_most_of_a_large_misfit_does_not_explain_it() {
        let with = |base: f64, ext: f64| {
            let mut g = candidate("c", ext, 1, 50.0, true).gains.unwrap();
            g.chi2_fit_base = base;
            g
        };
        // N = 1000: the noise's χ²; the floor at noise_factor 1.5 is 2250.
        // 143 N -> 131 N: 8 % of the excess taken, 130 N left.
        let why = explains_too_little(&with(143_000.0, 131_000.0), 1.5).expect("too little");
        assert!(why.contains("8 % of the misfit above the noise"), "{why}");
        // 97 N -> 12.4 N: 88 % taken, the rest above the floor (a cause whose model differs a
        // little from the recording's).
        assert!(explains_too_little(&with(97_000.0, 12_400.0), 1.5).is_none());
        // Exactly half of the excess taken and half left: named (the majority is not less).
        assert!(explains_too_little(&with(9_000.0, 5_000.0), 1.5).is_none());
        assert!(explains_too_little(&with(9_000.0, 5_100.0), 1.5).is_some());
        // At the noise floor with the extension: no judgement, whatever share it took.
        assert!(explains_too_little(&with(2_400.0, 2_200.0), 1.5).is_none());
        assert!(explains_too_little(&with(1_120.0, 1_080.0), 1.5).is_none());
        // A stricter floor makes the same residual "above the noise".
        assert!(explains_too_little(&with(2_400.0, 2_200.0), 1.0).is_some());
    }

    /// A look-alike outside the catalog whose extended model is decisively better than the
    /// significant catalog cause's takes the name away: `unexplained`, with the look-alike, its
    /// file and the cause it beats. About as good: `inconclusive`, the look-alike among the
    /// competitors. Decisively worse, or not significant: the catalog cause stays the best.
    #[test]
    fn a_better_look_alike_outside_the_catalog_takes_the_name_away() {
        let look_alike = |chi2: f64, significant: bool| {
            let mut c = candidate("reactive_droop", chi2, 2, 60.0, significant);
            c.look_alike = true;
            c
        };
        let saturation = || candidate("saturation", 340.0, 3, 40.0, true);
        // VIF 2, N = 1000: a gap of 40/2 + (3 − 2) ln 500 = 26.2.
        let d = decide_on(vec![saturation(), look_alike(300.0, true)]);
        assert_eq!(d.verdict.cause, "unexplained", "{}", d.verdict.statement);
        assert!(!d.verdict.names_a_cause());
        assert!(d.extended_unit.is_none());
        assert_eq!(d.verdict.competing[0], ("reactive_droop".to_string(), 0.0));
        assert_eq!(d.verdict.competing[1].0, "saturation");
        assert!((d.verdict.competing[1].1 - (20.0 + 500f64.ln())).abs() < 1e-9);
        for s in [
            "--user-cause data/causes/reactive_droop.toml",
            "saturation (its extended model's BIC 26.2 above)",
        ] {
            says(&d.verdict.statement, s);
        }
        says(&d.verdict.title, "looks like");
        // A gap of 5/2 + ln 500 = 8.7: not decided either way.
        let d = decide_on(vec![saturation(), look_alike(335.0, true)]);
        assert_eq!(d.verdict.cause, "inconclusive", "{}", d.verdict.statement);
        assert_eq!(competitors(&d.verdict), ["reactive_droop", "saturation"]);
        says(
            &d.verdict.statement,
            "outside the catalog: data/causes/reactive_droop.toml",
        );
        // Decisively worse, or not significant: the catalog cause is the best (named when its
        // re-fit is on record; here `decide` falls back to undecided without the look-alike).
        for l in [look_alike(400.0, true), look_alike(300.0, false)] {
            let d = decide_on(vec![saturation(), l]);
            assert!(
                !d.verdict.title.contains("looks like"),
                "{}",
                d.verdict.title
            );
            assert_ne!(d.verdict.cause, "inconclusive");
        }
    }

    /// The held-out samples can overrule the fitted ranking: a significant rival whose extended
    /// model predicts them better by more than the threshold (VIF-deflated) makes the verdict
    /// `inconclusive` though the best fits decisively better; a smaller margin, or a rival
    /// played back otherwise (as recorded against smoothed), does not.
    #[test]
    fn a_rival_that_predicts_the_held_out_samples_better_blocks_the_name() {
        let held = |mut c: CandidateReport, chi2_held: f64| {
            c.gains.as_mut().unwrap().chi2_held_ext = chi2_held;
            c
        };
        let saturation = || held(candidate("saturation", 300.0, 3, 40.0, true), 400.0);
        let lead = |chi2_held: f64| {
            let mut c = held(candidate("pss_lead_lag", 340.0, 2, 40.0, true), chi2_held);
            c.look_alike = true;
            c
        };
        // On the fitted samples saturation is 40/2 − ln 500 = 13.8 ahead: decisive.
        assert!((bic_gap(&saturation(), &lead(300.0)) - (20.0 - 500f64.ln())).abs() < 1e-9);
        // Held out, the lead predicts 100 χ² better: 50 after deflation.
        assert!((held_out_gap(&saturation(), &lead(300.0)) - 50.0).abs() < 1e-9);
        let d = decide_on(vec![saturation(), lead(300.0)]);
        assert_eq!(d.verdict.cause, "inconclusive", "{}", d.verdict.statement);
        assert!(d.extended_unit.is_none());
        assert_eq!(competitors(&d.verdict), ["saturation", "pss_lead_lag"]);
        for s in [
            "the fitted and the held-out samples disagree",
            "Δχ² = 50.0",
            "outside the catalog: data/causes/pss_lead_lag.toml",
        ] {
            says(&d.verdict.statement, s);
        }
        // 19 χ² better, 9.5 deflated: below the threshold, no contradiction.
        let d = decide_on(vec![saturation(), lead(381.0)]);
        assert_ne!(d.verdict.cause, "inconclusive", "{}", d.verdict.statement);
        // Played back otherwise: the held-out χ² are not compared.
        let mut recorded = lead(300.0);
        recorded.input_as_recorded = true;
        assert_eq!(held_out_gap(&saturation(), &recorded), 0.0);
        let d = decide_on(vec![saturation(), recorded]);
        assert_ne!(d.verdict.cause, "inconclusive", "{}", d.verdict.statement);
    }

    /// A candidate re-fitted on the record as recorded is compared with the others without its
    /// input's echo: 70 χ² of echo on a raw 340 puts its extended model 30 below a smoothed 300
    /// (VIF 2, equal k: a deflated gap of 15), so its rival is decisively behind; without the
    /// echo taken off, the smoothed rival would be 40 χ² ahead of it.
    #[test]
    fn a_candidate_played_as_recorded_is_compared_without_its_input_echo() {
        let smoothed = candidate("saturation", 300.0, 3, 40.0, true);
        let mut recorded = candidate("torsional_mode", 340.0, 3, 40.0, true);
        recorded.input_as_recorded = true;
        assert!((bic_gap(&smoothed, &recorded) - 20.0).abs() < 1e-9);
        recorded.gains.as_mut().unwrap().input_echo = 70.0;
        assert!((bic_gap(&recorded, &smoothed) - 15.0).abs() < 1e-9);
        assert!((bic_gap(&smoothed, &recorded) + 15.0).abs() < 1e-9);
        let d = decide_on(vec![smoothed.clone(), recorded.clone()]);
        assert_ne!(d.verdict.cause, "inconclusive", "{}", d.verdict.statement);
        assert!(d.verdict.competing.is_empty(), "{:?}", d.verdict.competing);
        // A smaller echo (25): 15 χ² behind, a deflated gap of 7.5 < 10: inconclusive, the
        // smoothed candidate first.
        recorded.gains.as_mut().unwrap().input_echo = 25.0;
        let d = decide_on(vec![recorded, smoothed]);
        assert_eq!(d.verdict.cause, "inconclusive", "{}", d.verdict.statement);
        assert_eq!(competitors(&d.verdict), ["saturation", "torsional_mode"]);
    }

    /// Two causes that pass their tests and whose extended models are within the BIC threshold
    /// of each other: no name, both listed, no extended unit; the same pair far apart names the
    /// better one (here without its re-fit record, so it falls back to undecided: the name needs
    /// the re-fit, which `decide` never invents).
    #[test]
    fn two_causes_explaining_the_residual_about_equally_are_inconclusive() {
        // VIF 2: a χ² difference of 12 is a deflated gap of 6 < 10.
        let d = decide_on(vec![
            candidate("saturation", 300.0, 3, 40.0, true),
            candidate("torsional_mode", 312.0, 3, 30.0, true),
            candidate("governor", 350.0, 2, 2.0, false),
        ]);
        assert_eq!(d.verdict.cause, "inconclusive", "{}", d.verdict.statement);
        assert!(!d.verdict.names_a_cause());
        assert!(d.extended_unit.is_none());
        assert_eq!(competitors(&d.verdict), ["saturation", "torsional_mode"]);
        assert!(
            (d.verdict.competing[1].1 - 6.0).abs() < 1e-9,
            "{:?}",
            d.verdict.competing
        );
        says(&d.verdict.statement, "torsional_mode");
        // The rival 40 χ² behind (deflated gap 20): not inconclusive.
        let d = decide_on(vec![
            candidate("saturation", 300.0, 3, 40.0, true),
            candidate("torsional_mode", 340.0, 3, 30.0, true),
        ]);
        assert_ne!(d.verdict.cause, "inconclusive");
        // A non-significant rival close behind does not make it inconclusive either.
        let d = decide_on(vec![
            candidate("saturation", 300.0, 3, 40.0, true),
            candidate("torsional_mode", 301.0, 3, 5.0, false),
        ]);
        assert_ne!(d.verdict.cause, "inconclusive");
    }

    /// The posterior: one clear winner has odds above 99:1 and is graded strong; a close rival
    /// or a weak gain over the baseline lowers it to moderate; the held-out drop is required.
    #[test]
    fn the_posterior_and_the_grade_follow_the_bic_margins() {
        let opts = DiagnoseOptions::default();
        let best = candidate("saturation", 300.0, 3, 40.0, true);
        let far = candidate("governor", 360.0, 3, 12.0, true);
        let p = posterior(&best, &[best.clone(), far.clone()]);
        // exp(−20) against the baseline, exp(−15) against the rival (gap 60/2 = 30).
        let expected = 1.0 / (1.0 + (-20.0f64).exp() + (-15.0f64).exp());
        assert!((p - expected).abs() < 1e-12, "{p}");
        assert_eq!(grade(p, best.gains.as_ref().unwrap(), &opts), Grade::Strong);
        // A rival 4 χ² behind (deflated gap 2): odds e^-1, probability ≈ 0.73.
        let near = candidate("governor", 304.0, 3, 12.0, true);
        let p2 = posterior(&best, &[best.clone(), near.clone()]);
        assert!((p2 - 1.0 / (1.0 + (-20.0f64).exp() + (-1.0f64).exp())).abs() < 1e-12);
        assert_eq!(
            grade(p2, best.gains.as_ref().unwrap(), &opts),
            Grade::Moderate
        );
        // The same rival without a significant gain over its own baseline is no rival.
        let failed = CandidateReport {
            significant: false,
            ..near
        };
        let p3 = posterior(&best, &[best.clone(), failed]);
        assert!((p3 - 1.0 / (1.0 + (-20.0f64).exp())).abs() < 1e-12);
        // Clear odds but a held-out drop below the threshold: moderate.
        let mut g = best.gains.clone().unwrap();
        g.held_drop = 0.0;
        assert_eq!(grade(p, &g, &opts), Grade::Moderate);
        // A rival with more parameters pays ln(N/VIF) each.
        let bigger = candidate("oel", 300.0, 5, 40.0, true);
        assert!((bic_gap(&best, &bigger) - 2.0 * (500.0f64).ln()).abs() < 1e-12);
    }
}
