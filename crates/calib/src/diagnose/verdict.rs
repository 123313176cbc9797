//! The verdict: the candidates ranked ([`rank`]), the rivals that leave no name (several
//! explaining the residual about equally, the held-out samples contradicting the fitted
//! ranking, a look-alike outside the catalog explaining it best), the named cause with its
//! standard errors, its evidence after, its posterior probability and grade, or `none` /
//! `unexplained` with where the residual lives ([`undecided`]).

use std::collections::BTreeMap;

use itaipu_dynamics::event::Event;
use itaipu_dynamics::simulate::Traces;
use itaipu_dynamics::unit::Unit;

use super::catalog;
use super::options::DiagnoseOptions;
use super::playback::{signal_name, Scoring};
use super::ranking::{
    bic_gap, confidence, held_out_gap, outside_dominates, rank, strong_or_why_not,
};
use super::refit::{std_errors, RefitRecord};
use super::report::{
    fmt_num, CandidateReport, Confidence, EventEvidence, Gains, Grade, Verdict, VerdictCause,
    NAME_PROBABILITY,
};
use super::statements::{
    contradicted, inconclusive, key_parameters, named, outside_catalog, undecided,
};

/// The verdict of a diagnosis, with the named cause's extended unit and its traces and
/// evidence (empty when none is named).
pub(super) struct Decision {
    pub verdict: Verdict,
    pub extended_unit: Option<Unit>,
    pub after: Vec<(String, Traces)>,
    pub evidence_after: Vec<EventEvidence>,
}

impl Decision {
    /// A verdict that names no cause: no extended unit, no evidence after.
    fn unnamed(verdict: Verdict) -> Self {
        Decision {
            verdict,
            extended_unit: None,
            after: vec![],
            evidence_after: vec![],
        }
    }
}

/// Ranks `reports` (see [`super::Diagnosis::candidates`]) and decides: the first significant
/// candidate is named (with the standard errors of its re-fit in `refits`) unless a rival
/// leaves no name ([`rivals`]), else [`undecided`]. A named cause whose re-fits played the
/// record as recorded ([`CandidateReport::input_as_recorded`]) gets its standard errors and its
/// evidence after on `recorded` (the events played back so).
#[allow(clippy::too_many_arguments)]
pub(super) fn decide(
    reports: &mut [CandidateReport],
    mut refits: BTreeMap<String, RefitRecord>,
    events: &[Event],
    recorded: Option<&[Event]>,
    scoring: Scoring,
    evidence_before: &[EventEvidence],
    absorbed: &[String],
    opts: &DiagnoseOptions,
) -> Decision {
    let compared: Vec<&str> = scoring.0.channels.iter().map(|c| signal_name(*c)).collect();
    rank(reports);
    if let Some(verdict) = rivals(reports, evidence_before, &compared, opts) {
        return Decision::unnamed(verdict);
    }
    // A significant candidate has its re-fit and its gains (the scoring returns them with
    // every report it scores); one without them could not be named, and is not.
    let best = reports
        .iter()
        .find(|r| r.significant)
        .cloned()
        .and_then(|rep| {
            let g = rep.gains.clone()?;
            let refit = refits.remove(&rep.cause)?;
            Some((rep, g, refit))
        });
    if let Some((rep, g, refit)) = best {
        let events = match recorded {
            Some(raw) if rep.input_as_recorded => raw,
            _ => events,
        };
        let id = rep.cause.clone();
        match name(rep, g, refit, reports, events, scoring, opts) {
            Ok(d) => return d,
            // Refused for its probability: it passed the test and stays on record as refused,
            // so that the residual is `unexplained` (an effect is there), never `none`.
            Err(why) => {
                if let Some(c) = reports.iter_mut().find(|c| c.cause == id) {
                    c.significant = false;
                    c.passed_test = true;
                    c.note = why;
                }
            }
        }
    }
    Decision::unnamed(undecided(
        evidence_before,
        &compared,
        reports,
        absorbed,
        opts,
    ))
}

/// The verdict when the best significant candidate (the first of the ranked `reports`) is not
/// named for its rivals: two or more whose extended models explain the fitted samples about
/// equally (a wrong name is worse than none: `inconclusive`, with the competitors); a rival
/// whose extended model predicts the held-out samples decisively better (`inconclusive`); or a
/// look-alike outside the catalog explaining the residual best (`unexplained`). `None` when
/// the best stands.
fn rivals(
    reports: &[CandidateReport],
    ev: &[EventEvidence],
    compared: &[&str],
    opts: &DiagnoseOptions,
) -> Option<Verdict> {
    let significant: Vec<&CandidateReport> = reports
        .iter()
        .filter(|r| r.significant && r.gains.is_some())
        .collect();
    let [best, rivals @ ..] = significant.as_slice() else {
        return None;
    };
    let competing: Vec<(String, f64)> = rivals
        .iter()
        .map(|r| (r.cause.clone(), bic_gap(best, r)))
        .filter(|(_, gap)| *gap < opts.bic_threshold)
        .collect();
    if !competing.is_empty() {
        return Some(inconclusive(best, &competing, reports, ev, compared, opts));
    }
    let contradicting: Vec<(&CandidateReport, f64)> = rivals
        .iter()
        .map(|r| (*r, held_out_gap(best, r)))
        .filter(|(_, gap)| *gap > opts.bic_threshold)
        .collect();
    if !contradicting.is_empty() {
        return Some(contradicted(best, &contradicting, ev, compared, opts));
    }
    best.look_alike
        .then(|| outside_catalog(best, reports, ev, compared))
}

/// The named cause `rep` (its gains `g`, its re-fit): the standard errors of its re-fitted
/// parameters (every sample of `events`, with the priors), its confidence in the open world
/// ([`confidence`]) and grade ([`strong_or_why_not`]), its traces and evidence after, its
/// statement. `Err` with the candidate's refusal when its posterior probability is under
/// [`NAME_PROBABILITY`]: the alternatives together are likelier, and a wrong name is worse
/// than none.
fn name(
    mut rep: CandidateReport,
    g: Gains,
    (r, bounds, ties): RefitRecord,
    reports: &mut [CandidateReport],
    events: &[Event],
    (pb, weights, compare): Scoring,
    opts: &DiagnoseOptions,
) -> Result<Decision, String> {
    if let Some(se) = std_errors(&r.unit, &bounds, &ties, &r.values, events, weights, compare) {
        for (p, e) in rep.parameters.iter_mut().zip(se) {
            p.std_error = Some(e);
        }
        if let Some(c) = reports.iter_mut().find(|c| c.cause == rep.cause) {
            c.parameters = rep.parameters.clone();
        }
    }
    let mut conf = confidence(&rep, reports, opts);
    if conf.probability < NAME_PROBABILITY {
        return Err(unnamed_for(&conf));
    }
    conf.not_strong = strong_or_why_not(&rep, &g, &conf, opts);
    let grade = if conf.not_strong.is_empty() {
        Grade::Strong
    } else {
        Grade::Moderate
    };
    let (mut after, mut evidence_after) = (vec![], vec![]);
    for e in events {
        if let Ok((tr, ev, _)) = pb.evidence(&r.unit, e) {
            evidence_after.push(ev);
            after.push((e.name.clone(), tr));
        }
    }
    let rivals = reports
        .iter()
        .filter(|c| c.significant && c.cause != rep.cause)
        .count();
    let key = key_parameters(&rep);
    let statement = named(&rep, &g, &key, (&conf, grade, rivals));
    let verdict = Verdict {
        cause: named_cause(&rep.cause),
        title: rep.title.clone(),
        statement,
        key_parameters: key,
        gains: Some(g),
        where_: None,
        grade: Some(grade),
        probability: Some(conf.probability),
        confidence: Some(conf),
        competing: vec![],
    };
    Ok(Decision {
        verdict,
        extended_unit: Some(r.unit),
        after,
        evidence_after,
    })
}

/// Why a candidate is not named for its posterior probability `c` (under
/// [`NAME_PROBABILITY`]): the alternative that weighs most against it.
fn unnamed_for(c: &Confidence) -> String {
    let what = if outside_dominates(c) && c.misfit_left > 0.0 {
        format!(
            "it mimics part of another effect: its extension leaves {:.0} independent χ² of the misfit \
             beyond the noise and its form's tolerance",
            c.misfit_left
        )
    } else if outside_dominates(c) {
        "an effect outside the catalog acting where it acts is as likely".to_string()
    } else if c.odds_rivals >= c.odds_baseline {
        "other significant candidates explain the record about as well".to_string()
    } else {
        "its baseline without the extension explains the record about as well".to_string()
    };
    format!(
        "not named: its posterior probability {:.3} is under {NAME_PROBABILITY} (odds against it: baseline {}, rivals {}, \
         an effect outside the catalog {}); {what}",
        c.probability,
        fmt_num(c.odds_baseline),
        fmt_num(c.odds_rivals),
        fmt_num(c.odds_outside)
    )
}

/// The verdict's cause for the named candidate `id`: the catalog's when it has one of that id,
/// else a cause file's.
fn named_cause(id: &str) -> VerdictCause {
    match catalog::find(id) {
        Some(info) => VerdictCause::Catalog(info.id),
        None => VerdictCause::User(id.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::gain::explains_too_little;
    use crate::diagnose::playback::Playback;
    use crate::diagnose::ranking::{OUTSIDE_PRIOR_ODDS, SIGNATURE_EVIDENCE};
    use crate::diagnose::report::{CandidateParam, STRONG_PROBABILITY};
    use crate::evidence::{analyse, EvidenceOptions};

    /// A residual far above the noise whose evidence has no window (the windows are the
    /// caller's; none may fit a short record) is `unexplained` as a whole, never a panic.
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
        let v = undecided(&ev, &["P", "Q"], &[], &[], &DiagnoseOptions::default());
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
        let v = undecided(
            &ev,
            &["P", "Q"],
            &[quiet.clone(), refused.clone()],
            &[],
            &opts,
        );
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
        let v = undecided(&ev, &["P", "Q"], &[quiet.clone(), untested], &[], &opts);
        assert_eq!(v.cause, "none", "{}", v.statement);
        // Above the floor the residual's verdict, with its window, is unchanged.
        ev[0].signals[0].rms_over_noise = 3.0;
        let v = undecided(&ev, &["P", "Q"], &[refused, quiet], &[], &opts);
        assert_eq!(v.cause, "unexplained");
        says(&v.statement, "Unexplained residual at P");
    }

    /// At the noise floor with no significant gain the verdict is `none`; re-freed values far
    /// outside their typical ranges are named in it (weakly determined or absorbing: the
    /// record cannot tell when no extension gains), not raised as an alarm.
    #[test]
    fn values_pressed_far_outside_their_ranges_are_no_clean_bill() {
        let mut ev = evidence();
        ev[0].signals[0].rms_over_noise = 1.1;
        let opts = DiagnoseOptions::default();
        let quiet = candidate("governor", 380.0, 2, -3.0, false);
        let v = undecided(&ev, &["P", "Q"], std::slice::from_ref(&quiet), &[], &opts);
        assert_eq!(v.cause, "none", "{}", v.statement);
        let absorbed =
            ["machine.x_d = 1.8300 pu (typical 0.8000-1.2000, datasheet 0.9200)".to_string()];
        let v = undecided(&ev, &["P", "Q"], &[quiet], &absorbed, &opts);
        assert_eq!(v.cause, "none", "{}", v.statement);
        says(&v.statement, "machine.x_d = 1.8300 pu");
        says(&v.statement, "absorb an effect the model lacks");
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
        let v = undecided(&ev, &["P", "Q"], &[with(0.016, 0.009, 26.4)], &[], &opts);
        assert_eq!(v.cause, "none", "{}", v.statement);
        says(
            &v.statement,
            "not significant (the held-out χ² down 0.9 %, under 1.0 %)",
        );
        let v = undecided(&ev, &["P", "Q"], &[with(-0.003, -0.004, 0.5)], &[], &opts);
        says(
            &v.statement,
            "not significant (the fitted χ² up 0.3 %; the held-out χ² up 0.4 %; 2 ln B 0.5, not \
             above 10)",
        );
        let v = undecided(&ev, &["P", "Q"], &[with(-0.0002, 0.02, 5.0)], &[], &opts);
        says(
            &v.statement,
            "not significant (the fitted χ² unchanged; 2 ln B 5.0, not above 10)",
        );
        let floor = DiagnoseOptions {
            min_fit_drop: 0.02,
            ..DiagnoseOptions::default()
        };
        let v = undecided(&ev, &["P", "Q"], &[with(0.016, 0.02, 37.0)], &[], &floor);
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
        let v = undecided(&ev("Ifd"), &["P", "Q", "Efd", "Ifd"], &[], &[], &opts);
        assert_eq!(v.cause, "unexplained");
        says(&v.statement, "channels = \"recorded\"");
        let v = undecided(&ev("Efd"), &["|V|", "Q", "Efd"], &[], &[], &opts);
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
                chi2_prior_base: 0.0,
                chi2_prior_ext: 0.0,
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
            &[],
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

    /// The open-world confidence: one clear winner whose extension leaves the residual at the
    /// noise has odds above 99:1 against its baseline, its rivals and an effect outside the
    /// catalog together; a close rival lowers it; a rival that failed its own test is none.
    #[test]
    fn the_confidence_weighs_the_baseline_the_rivals_and_the_outside() {
        let opts = DiagnoseOptions::default();
        let mut best = candidate("saturation", 300.0, 3, 40.0, true);
        best.parameters[0].std_error = Some(0.1);
        let far = candidate("governor", 360.0, 3, 12.0, true);
        let c = confidence(&best, &[best.clone(), far.clone()], &opts);
        // Record evidence 90; the rival 60/2 behind on the fitted samples and level held out;
        // the data's evidence 100/2 − ln 500 + 100/2 (no prior rows), beyond the threshold by
        // more than two parameters' penalty 2 ln 500: the outside odds 0.25 e^{−ln 500}.
        let n = 500f64;
        assert!((c.data_evidence - (100.0 - n.ln())).abs() < 1e-9, "{c:?}");
        assert_eq!(c.misfit_left, 0.0);
        assert!((c.odds_outside - 0.25 / n).abs() < 1e-12, "{c:?}");
        let expected = 1.0 / (1.0 + (-45.0f64).exp() + (-15.0f64).exp() + 0.25 / n);
        assert!((c.probability - expected).abs() < 1e-12, "{c:?}");
        let g = best.gains.clone().unwrap();
        assert!(strong_or_why_not(&best, &g, &c, &opts).is_empty());
        // A rival 4 χ² behind (deflated gap 2): odds e^-1, probability ≈ 0.73, moderate.
        let near = candidate("governor", 304.0, 3, 12.0, true);
        let c2 = confidence(&best, &[best.clone(), near.clone()], &opts);
        assert!((c2.odds_rivals - (-1.0f64).exp()).abs() < 1e-12);
        let why = strong_or_why_not(&best, &g, &c2, &opts);
        assert!(why[0].starts_with("posterior probability 0.73"), "{why:?}");
        // The same rival without a significant gain over its own baseline is no rival.
        let failed = CandidateReport {
            significant: false,
            ..near.clone()
        };
        assert_eq!(
            confidence(&best, &[best.clone(), failed], &opts).odds_rivals,
            0.0
        );
        // A rival that predicts the held-out samples 8 χ² better (4 deflated) closes the gap.
        let mut predicts = near;
        predicts.gains.as_mut().unwrap().chi2_held_ext = 392.0;
        let c3 = confidence(&best, &[best.clone(), predicts], &opts);
        assert!((c3.odds_rivals - (1.0f64).exp()).abs() < 1e-9, "{c3:?}");
        // Clear odds but a held-out drop below the threshold: not strong, and said so.
        let mut g2 = g.clone();
        g2.held_drop = 0.0;
        let why = strong_or_why_not(&best, &g2, &c, &opts);
        assert_eq!(why.len(), 1, "{why:?}");
        assert!(why[0].contains("held-out χ² down 0.0 %"), "{why:?}");
        // A rival with more parameters pays ln(N/VIF) each.
        let bigger = candidate("oel", 300.0, 5, 40.0, true);
        assert!((bic_gap(&best, &bigger) - 2.0 * (500.0f64).ln()).abs() < 1e-12);
    }

    /// A gain made of calibrated values returning to their datasheet (the priors' rows) is no
    /// evidence that it is this cause rather than an effect outside the catalog acting in the
    /// same place: the outside keeps its prior odds (a probability of 0.8 at most) and the
    /// grade says the data's own evidence is missing; the same gain on the data takes the
    /// outside odds down by two parameters' penalty, and a record-evidence name by its
    /// signature counts at least the signature's test.
    #[test]
    fn a_gain_of_un_bending_alone_is_no_strong_name() {
        let opts = DiagnoseOptions::default();
        let mut bent = candidate("saturation", 300.0, 3, 40.0, true);
        bent.parameters[0].std_error = Some(0.1);
        if let Some(g) = bent.gains.as_mut() {
            (g.chi2_prior_base, g.chi2_prior_ext) = (120.0, 20.0);
        }
        let c = confidence(&bent, std::slice::from_ref(&bent), &opts);
        assert!(c.data_evidence < 0.0, "{c:?}");
        assert!((c.odds_outside - OUTSIDE_PRIOR_ODDS).abs() < 1e-12, "{c:?}");
        assert!(
            c.probability < 0.81 && c.probability > NAME_PROBABILITY,
            "{c:?}"
        );
        let why = strong_or_why_not(&bent, bent.gains.as_ref().unwrap(), &c, &opts);
        assert!(
            why.iter()
                .any(|w| w.contains("returning to their datasheet")),
            "{why:?}"
        );
        let clean = candidate("saturation", 300.0, 3, 40.0, true);
        let c = confidence(&clean, std::slice::from_ref(&clean), &opts);
        assert!(c.probability > STRONG_PROBABILITY, "{c:?}");
        // Named by its signature with no gain in the re-fit: the signature's evidence.
        let mut ringing = candidate("torsional_mode", 300.0, 3, -13.7, true);
        ringing.by_evidence = true;
        if let Some(g) = ringing.gains.as_mut() {
            (g.chi2_fit_base, g.chi2_held_ext, g.record_evidence) = (300.0, 500.0, 8.1);
        }
        let c = confidence(&ringing, std::slice::from_ref(&ringing), &opts);
        assert!((c.odds_baseline - (-SIGNATURE_EVIDENCE / 2.0).exp()).abs() < 1e-12);
        assert!(c.probability > 0.95, "{c:?}");
    }

    /// An extension that takes half of a misfit far above the noise leaves what a right block
    /// does not: the outside odds are overwhelming and it is not named; one that leaves only its
    /// form's tolerance (a tenth) keeps its name, graded moderate for what it leaves.
    #[test]
    fn a_block_that_leaves_most_of_its_misfit_is_not_named() {
        let opts = DiagnoseOptions::default();
        let with = |base: f64, ext: f64| {
            let mut c = candidate("oel", ext, 3, 40.0, true);
            if let Some(g) = c.gains.as_mut() {
                g.chi2_fit_base = base;
                g.chi2_held_base = base;
                g.chi2_held_ext = ext;
                g.record_evidence = 5000.0;
            }
            c
        };
        // N = 1000, floor 2250: 10000 -> 5000 leaves 5000 − (2250 + 775) = 1975, 988 deflated.
        let half = with(10_000.0, 5_000.0);
        let c = confidence(&half, std::slice::from_ref(&half), &opts);
        assert!((c.misfit_left - 987.5).abs() < 1e-9, "{c:?}");
        assert!(c.probability < 1e-6, "{c:?}");
        assert!(unnamed_for(&c).contains("mimics part of another effect"));
        // 10000 -> 3000: within the tolerance (3025), named.
        let most = with(10_000.0, 3_000.0);
        let c = confidence(&most, std::slice::from_ref(&most), &opts);
        assert_eq!(c.misfit_left, 0.0);
        assert!(c.probability > STRONG_PROBABILITY, "{c:?}");
    }

    /// The grade needs the acting parameters identified: an estimate within two standard errors
    /// of zero, or resting on a bound, is named moderate with the reason; a parameter with an
    /// infinite standard error does not act and is not held against it.
    #[test]
    fn a_strong_grade_needs_identified_parameters() {
        let opts = DiagnoseOptions::default();
        let mut rep = candidate("terminal_load", 300.0, 2, 40.0, true);
        let g = rep.gains.clone().unwrap();
        let c = confidence(&rep, std::slice::from_ref(&rep), &opts);
        rep.parameters[0].std_error = Some(0.1);
        assert!(strong_or_why_not(&rep, &g, &c, &opts).is_empty());
        rep.parameters[0].std_error = Some(22.5);
        let why = strong_or_why_not(&rep, &g, &c, &opts);
        assert!(
            why.iter()
                .any(|w| w.contains("p0 not identified (1.0000 ± 22.5000)")),
            "{why:?}"
        );
        rep.parameters[0].std_error = Some(0.1);
        rep.parameters[0].at_bound = true;
        let why = strong_or_why_not(&rep, &g, &c, &opts);
        assert!(
            why.iter().any(|w| w.contains("rests on a bound")),
            "{why:?}"
        );
        rep.parameters[0].std_error = Some(f64::INFINITY);
        let why = strong_or_why_not(&rep, &g, &c, &opts);
        assert!(
            why.iter()
                .any(|w| w.contains("no parameter of its extension identified")),
            "{why:?}"
        );
    }
}
