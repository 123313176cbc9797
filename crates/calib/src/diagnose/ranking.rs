//! How candidates compare with each other: their extended models' BIC on the common fitted
//! samples, their predictions of the held-out samples, the named cause's posterior
//! probability and its grade.

use super::gain::{bic_met, held_floor_met};
use super::options::DiagnoseOptions;
use super::report::{
    fmt_num, CandidateParam, CandidateReport, Confidence, Gains, STRONG_PROBABILITY,
};

/// Sorts `reports` as the diagnosis lists them ([`super::Diagnosis::candidates`]): the
/// significant candidates first, by their extended model's BIC on the common fitted samples,
/// `χ²_ext + k ln N` with k every parameter the candidate re-fitted (lowest first: each passed
/// the test against its own baseline, the same interacting parameters re-fitted without it, and
/// among them the extended model that explains the data best wins; a cause whose extension is
/// only significant because its baseline stayed bent does not beat one that fits); the others
/// by decreasing ΔBIC.
pub(super) fn rank(reports: &mut [CandidateReport]) {
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
}

/// A candidate's fitted χ² as candidates are compared with each other: without the echo of
/// the voltage's noise that a re-fit on the record as recorded carries ([`Gains::input_echo`]).
pub(super) fn comparable_chi2(g: &Gains) -> f64 {
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

/// Prior odds of "an effect outside the catalog" against the named cause, before the record is
/// read. The catalog holds the effects that plant experience finds most often in unit model
/// validation, never all of them: the prior says that, of the effects a catalog extension can
/// mimic, about one in five is another effect's (limiters and controllers the catalog lacks, a
/// plant-level controller, a transducer error). An assumption stated so a reviewer can change
/// it; the record then moves the odds by [`misfit_left`] and [`data_evidence`].
pub(super) const OUTSIDE_PRIOR_ODDS: f64 = 0.25;

/// The share of the misfit above the noise a right catalog block may leave: its model-form
/// difference from the plant's device. A catalog block represents its device's dominant
/// dynamics (a limiter's pickup and pull-back, a ceiling, a delay), and what its form misses is
/// a second-order part of the effect: a tenth of the misfit. More left over is the mark of an
/// effect the block only partly mimics.
pub(super) const FORM_TOLERANCE: f64 = 0.1;

/// Parameters an effect outside the catalog needs beyond the named extension's to explain the
/// same residual: at least a gain and a time constant of its own (Schwarz's penalty
/// `k ln(N/VIF)` on each). The data's evidence beyond the threshold counts against the outside
/// hypothesis up to this penalty: a record fitted to the noise by the named block leaves an
/// unknown effect only its extra parameters' Occam factor to lose.
pub(super) const OUTSIDE_PARAMS: f64 = 2.0;

/// The evidence, on the `2 ln B` scale, of a name by the cause's signature
/// ([`CandidateReport::by_evidence`]: a spectral peak at p < 1e-6 standing out of its
/// neighbourhood): the largest Bayes factor a p-value of 1e-6 can carry,
/// `1/(−e·p·ln p)` (Sellke, Bayarri and Berger's bound), is about 2.7e4, `2 ln B` ≈ 20.
pub(super) const SIGNATURE_EVIDENCE: f64 = 20.0;

/// The data's own evidence for an extension over its baseline, `2 ln B` as
/// [`super::gain::record_evidence`] computes it, with the priors' rows left out of both halves'
/// χ² drops: what the extension gains on the record. The priors' part of a gain is calibrated
/// values returning to their datasheet (un-bending): evidence that something acts where the
/// re-freed parameters act, not evidence for one cause.
pub(super) fn data_evidence(g: &Gains) -> f64 {
    let un_bent = g.chi2_prior_base - g.chi2_prior_ext;
    let v = g.vif.max(1.0);
    let n = (g.n_fit.max(1) as f64 / v).max(1.0);
    let d_fit = g.chi2_fit_base - g.chi2_fit_ext - g.null_gain_fit - un_bent;
    let d_held = g.chi2_held_base - g.chi2_held_ext - g.null_gain_held - un_bent;
    d_fit / v - g.k as f64 * n.ln() + d_held.max(0.0) / v
}

/// The fitted χ² the extension leaves beyond what a right block may leave, in independent
/// samples (deflated by the variance inflation): above the noise floor
/// (`noise_factor² · N`, the RMS the verdicts call "at the noise level") by more than
/// [`FORM_TOLERANCE`] of the baseline's misfit above that floor. Zero when the extension brings
/// the residual to the floor or leaves only its model-form share. Both χ² without the echo of a
/// record played as recorded ([`comparable_chi2`]).
pub(super) fn misfit_left(g: &Gains, noise_factor: f64) -> f64 {
    let floor = noise_factor * noise_factor * g.n_fit.max(1) as f64;
    let base = g.chi2_fit_base - g.input_echo;
    let ext = comparable_chi2(g);
    let allowed = floor + FORM_TOLERANCE * (base - floor).max(0.0);
    (ext - allowed).max(0.0) / g.vif.max(1.0)
}

/// The named candidate's confidence in an open world (see [`Confidence`]): its posterior
/// probability among its re-fitted baseline, the other significant candidates' extended models
/// and an effect outside the catalog, `1 / (1 + o_base + Σ o_rival + o_outside)`, each `o` the
/// alternative's odds against it by Schwarz's approximation of the marginal likelihood:
///
/// - baseline: `e^{−2lnB/2}`, the record's evidence that the significance test read (the
///   naming rule and the probability are one computation);
/// - rival: `e^{−G/2}`, `G` its extended model's VIF-deflated BIC above the named one's on the
///   fitted samples ([`bic_gap`]) less how much better it predicts the held-out samples
///   ([`held_out_gap`]). A candidate that failed its own test is no rival: its extension gained
///   nothing over its baseline;
/// - outside: [`OUTSIDE_PRIOR_ODDS`] `· e^{(L − S)/2}`, `L` the misfit the extension leaves
///   ([`misfit_left`]: what an effect it only mimics leaves and a right block does not), `S` the
///   data's own evidence above the threshold ([`data_evidence`]), between zero and the outside
///   effect's extra parameters' penalty ([`OUTSIDE_PARAMS`]). A gain made of un-bending alone
///   (`S` = 0) leaves the prior odds: something acts there, and an effect outside the catalog
///   would un-bend the same values; only the data can say it is this cause.
///
/// A name by the cause's signature counts at least [`SIGNATURE_EVIDENCE`] against its
/// baseline and as the data's own.
///
/// The grade's other conditions are the caller's ([`strong_or_why_not`]). The figure is an
/// approximation a reviewer weighs, not an exact Bayes factor.
pub(super) fn confidence(
    named: &CandidateReport,
    reports: &[CandidateReport],
    opts: &DiagnoseOptions,
) -> Confidence {
    let Some(g) = &named.gains else {
        return Confidence {
            probability: 0.0,
            odds_baseline: f64::INFINITY,
            odds_rivals: 0.0,
            odds_outside: 0.0,
            data_evidence: f64::NAN,
            misfit_left: f64::NAN,
            not_strong: vec!["no gains".into()],
        };
    };
    let odds_rivals: f64 = reports
        .iter()
        .filter(|r| r.cause != named.cause && r.significant)
        .map(|r| bic_gap(named, r) - held_out_gap(named, r))
        .filter(|gap| gap.is_finite())
        .map(|gap| (-gap / 2.0).exp())
        .sum();
    // A name by the cause's signature rests on a test of the record's own (a spectral peak
    // at p < 1e-6): its evidence is at least that test's, on the data alone.
    let (record, data) = if named.by_evidence {
        (
            g.record_evidence.max(SIGNATURE_EVIDENCE),
            data_evidence(g).max(SIGNATURE_EVIDENCE),
        )
    } else {
        (g.record_evidence, data_evidence(g))
    };
    let odds_baseline = (-record / 2.0).exp();
    let left = misfit_left(g, opts.noise_factor);
    let n = (g.n_fit.max(1) as f64 / g.vif.max(1.0)).max(1.0);
    let specific = (data - opts.bic_threshold).clamp(0.0, OUTSIDE_PARAMS * n.ln());
    let odds_outside = OUTSIDE_PRIOR_ODDS * ((left - specific) / 2.0).exp();
    let probability = 1.0 / (1.0 + odds_baseline + odds_rivals + odds_outside);
    Confidence {
        probability: if probability.is_finite() {
            probability
        } else {
            0.0
        },
        odds_baseline,
        odds_rivals,
        odds_outside,
        data_evidence: data,
        misfit_left: left,
        not_strong: vec![],
    }
}

/// Whether the alternative that most undermines a confidence is an effect outside the catalog
/// (rather than the baseline or a rival).
pub(super) fn outside_dominates(c: &Confidence) -> bool {
    c.odds_outside >= c.odds_baseline && c.odds_outside >= c.odds_rivals
}

/// The reasons a named cause `rep` (its gains `g`, its confidence `c`) is not `strong`, empty
/// when it is: a probability under [`STRONG_PROBABILITY`]; the gain not confirmed on the
/// held-out blocks or not above the threshold on the fitted ones; named by its signature
/// alone; its acting parameters not identified (a parameter acts when its standard error is
/// finite; identified when the estimate is at least twice its standard error from zero, the
/// two-sided 95 % test, and not resting on a bound); the misfit it was named for not gone; its
/// evidence made of un-bending (the data's own evidence under the threshold).
pub(super) fn strong_or_why_not(
    rep: &CandidateReport,
    g: &Gains,
    c: &Confidence,
    opts: &DiagnoseOptions,
) -> Vec<String> {
    let mut why = vec![];
    if c.probability < STRONG_PROBABILITY {
        why.push(format!(
            "posterior probability {:.3} under {STRONG_PROBABILITY}",
            c.probability
        ));
    }
    if rep.by_evidence {
        why.push("named by its signature in the evidence, not by the test".into());
    }
    if !held_floor_met(g.held_drop, opts) {
        why.push(format!(
            "the held-out χ² down {:.1} %, under {:.1} %",
            100.0 * g.held_drop,
            100.0 * opts.min_held_drop
        ));
    }
    if !bic_met(g.delta_bic, opts) {
        why.push(format!(
            "ΔBIC on the fitted samples {:.1}, not above {}",
            g.delta_bic, opts.bic_threshold
        ));
    }
    let acting: Vec<&CandidateParam> = rep
        .parameters
        .iter()
        .filter(|p| p.extension && p.std_error.is_some_and(f64::is_finite))
        .collect();
    if acting.is_empty() && !rep.parameters.iter().all(|p| !p.extension) {
        why.push("no parameter of its extension identified (no finite standard error)".into());
    }
    for p in acting {
        let se = p.std_error.unwrap_or(f64::INFINITY);
        if p.at_bound {
            why.push(format!(
                "{} rests on a bound of its range ({})",
                p.param,
                fmt_num(p.result)
            ));
        } else if p.result.abs() < 2.0 * se {
            why.push(format!(
                "{} not identified ({} ± {})",
                p.param,
                fmt_num(p.result),
                fmt_num(se)
            ));
        }
    }
    if c.misfit_left > 0.0 {
        why.push(format!(
            "the misfit it was named for not gone (fitted χ² {:.0} -> {:.0}, {:.1} times the noise variance left)",
            g.chi2_fit_base,
            g.chi2_fit_ext,
            g.chi2_fit_ext / g.n_fit.max(1) as f64
        ));
    }
    if !bic_met(c.data_evidence, opts) {
        why.push(format!(
            "the data's own evidence 2 ln B = {:.1} (the rest of its gain is calibrated values returning to their datasheet)",
            c.data_evidence
        ));
    }
    why
}
