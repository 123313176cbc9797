//! Step 6, the verdict: the candidates ranked, the named cause with its statement, or `none` /
//! `unexplained` with where the residual lives.

use std::collections::BTreeMap;

use crate::evidence::SignalEvidence;
use crate::fit::fitness;
use itaipu_dynamics::event::Event;
use itaipu_dynamics::simulate::Traces;
use itaipu_dynamics::unit::Unit;

use super::*;

pub(super) fn fmt_num(v: f64) -> String {
    if v != 0.0 && (v.abs() < 1e-2 || v.abs() >= 1e4) {
        format!("{v:.4e}")
    } else {
        format!("{v:.4}")
    }
}

/// The verdict when no cause is significant: `none` at the noise floor, else `unexplained`
/// with where the residual lives.
pub(super) fn undecided(
    ev: &[EventEvidence],
    reports: &[CandidateReport],
    opts: &DiagnoseOptions,
    sigma_p: f64,
    sigma_q: f64,
) -> Verdict {
    // The signal with the largest residual RMS relative to its noise floor (the evidence's
    // `rms_over_noise`: the event's own floor, [`crate::noise::noise_floor`], as the report
    // shows it).
    let ratio = |s: &SignalEvidence| s.rms_over_noise;
    let _ = (sigma_p, sigma_q);
    let mut worst: Option<(&str, &SignalEvidence)> = None;
    for e in ev {
        for s in e
            .signals
            .iter()
            .filter(|s| s.signal == "P" || s.signal == "Q")
        {
            if worst.is_none_or(|(_, w)| ratio(s) > ratio(w)) {
                worst = Some((&e.event, s));
            }
        }
    }
    let best_try = reports
        .iter()
        .filter_map(|r| r.gains.as_ref().map(|g| (r, g)))
        .next()
        .map(|(r, g)| {
            format!(
                " The best candidate, {}, gained ΔBIC {:.1} ({:.1} % of χ²), below the threshold.",
                r.cause,
                g.delta_bic,
                100.0 * g.fit_drop
            )
        })
        .unwrap_or_default();
    let Some((event, s)) = worst else {
        return Verdict {
            cause: "none".into(),
            title: "no residual to explain".into(),
            statement: "No P or Q residual.".into(),
            key_parameters: vec![],
            gains: None,
            where_: None,
        };
    };
    let top = s
        .windows
        .iter()
        .max_by(|a, b| a.share_of_sse.total_cmp(&b.share_of_sse));
    let where_ = top.map(|w| (s.signal.clone(), w.label.clone(), w.start_s, w.end_s));
    let over = ratio(s);
    if over <= opts.noise_factor {
        Verdict {
            cause: "none".into(),
            title: "residual at the noise floor".into(),
            statement: format!(
                "No cause named: the residuals are at the noise level (largest: {} on {event}, RMS {:.2} × the pre-event \
                 residual σ; Ljung-Box p = {:.2}) and no extension gains significantly.{best_try} The model needs no extension \
                 for these data.",
                s.signal, over, s.whiteness.p_value
            ),
            key_parameters: vec![],
            gains: None,
            where_,
        }
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
        Verdict {
            cause: "unexplained".into(),
            title: format!("unexplained residual at {} ({}, {:.2}-{:.2} s)", s.signal, w.label, w.start_s, w.end_s),
            statement: format!(
                "Unexplained residual at {} in the {} window ({:.2}-{:.2} s, {:.0} % of its squared error) on {event}: RMS {:.2} × \
                 the pre-event residual σ, Ljung-Box p = {:.2}{mode}. No catalog extension explains it significantly.{best_try}",
                s.signal,
                w.label,
                w.start_s,
                w.end_s,
                100.0 * w.share_of_sse,
                over,
                s.whiteness.p_value
            ),
            key_parameters: vec![],
            gains: None,
            where_,
        }
    } else {
        // No window (a record too short to cut into any): the residual as a whole.
        Verdict {
            cause: "unexplained".into(),
            title: format!("unexplained residual at {}", s.signal),
            statement: format!(
                "Unexplained residual at {} on {event}: RMS {:.2} × the pre-event residual σ, \
                 Ljung-Box p = {:.2}. No catalog extension explains it significantly.{best_try}",
                s.signal, over, s.whiteness.p_value
            ),
            key_parameters: vec![],
            gains: None,
            where_: None,
        }
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
/// [`undecided`].
#[allow(clippy::too_many_arguments)]
pub(super) fn decide(
    reports: &mut [CandidateReport],
    mut refits: BTreeMap<String, RefitRecord>,
    events: &[Event],
    weights: (f64, f64),
    evidence_before: &[EventEvidence],
    opts: &DiagnoseOptions,
    sigma_p: f64,
    sigma_q: f64,
) -> Decision {
    // 5. Rank and decide.
    // Significant candidates first. Each passed the test against its own baseline (the same
    // interacting parameters re-fitted without it); among them, the extended model that
    // explains the data best wins: lowest BIC on the common fitted samples,
    // χ²_ext + k ln N with k every parameter the candidate re-fitted (a cause whose extension
    // is only significant because its baseline stayed bent does not beat one that fits). The
    // others follow by ΔBIC.
    let bic_ext = |r: &CandidateReport| {
        r.gains.as_ref().map_or(f64::INFINITY, |g| {
            g.chi2_fit_ext + r.parameters.len() as f64 * (g.n_fit.max(1) as f64).ln()
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
    // A significant candidate has its re-fit and its gains (`Candidates::score` returns them
    // with every report it scores); one without them could not be named, and is not.
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
            // Uncertainty of the re-fitted parameters (all samples, with the priors).
            if let Some(se) = std_errors(&r.unit, &bounds, &ties, &r.values, events, weights) {
                for (p, e) in rep.parameters.iter_mut().zip(se) {
                    p.std_error = Some(e);
                }
                if let Some(c) = reports.iter_mut().find(|c| c.cause == rep.cause) {
                    c.parameters = rep.parameters.clone();
                }
            }
            for e in events {
                if let Ok((_, tr)) = fitness(&r.unit, e, false) {
                    evidence_after.push(event_evidence(e, &tr));
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
                 samples by {:.0} %{}; ΔBIC = {:.1} with {} added parameter(s). Fitted values: {}.",
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
            extended_unit = Some(r.unit);
            Verdict {
                cause: rep.cause.clone(),
                title: rep.title.clone(),
                statement,
                key_parameters: key,
                gains: Some(g),
                where_: None,
            }
        }
        None => undecided(evidence_before, reports, opts, sigma_p, sigma_q),
    };

    Decision {
        verdict,
        extended_unit,
        after,
        evidence_after,
    }
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
        let v = undecided(&ev, &[], &DiagnoseOptions::default(), 0.002, 0.002);
        assert_eq!(v.cause, "unexplained");
        assert!(
            v.statement.contains("Unexplained residual at Q on e"),
            "{}",
            v.statement
        );
        assert!(v.where_.is_none());
    }
}
