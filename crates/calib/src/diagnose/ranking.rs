//! How candidates compare with each other: their extended models' BIC on the common fitted
//! samples, their predictions of the held-out samples, the named cause's posterior
//! probability and its grade.

use super::gain::{bic_met, held_floor_met};
use super::options::DiagnoseOptions;
use super::report::{CandidateReport, Gains, Grade, STRONG_PROBABILITY};

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
