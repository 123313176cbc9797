//! Signature lines the causes read from the residual evidence (shown in the candidates' table,
//! not used to rank).

use super::super::report::EventEvidence;

/// The dominant oscillatory mode of each event's P residual (matrix pencil), as signature lines.
pub(crate) fn dominant_p_mode(ev: &[EventEvidence]) -> Vec<String> {
    ev.iter()
        .flat_map(|e| e.signals.iter().map(move |s| (e, s)))
        .filter(|(_, s)| s.signal == "P")
        .filter_map(|(e, s)| {
            let m = s
                .modes
                .iter()
                .filter(|m| m.freq_hz > 0.1)
                .max_by(|a, b| a.energy_share.total_cmp(&b.energy_share))?;
            Some(format!(
                "{}: P residual mode {:.2} Hz, ζ = {:.3}, amplitude {:.4} pu",
                e.event, m.freq_hz, m.damping_ratio, m.amplitude
            ))
        })
        .collect()
}

/// The residuals (of `signal`, or every signal) whose cross-correlation with `input` (`|V|`,
/// `frequency`) is significant, as signature lines.
pub(crate) fn correlates_with(
    ev: &[EventEvidence],
    input: &str,
    signal: Option<&str>,
) -> Vec<String> {
    ev.iter()
        .flat_map(|e| e.signals.iter().map(move |s| (e, s)))
        .filter(|(_, s)| signal.is_none_or(|x| s.signal == x))
        .filter_map(|(e, s)| {
            let x = s.cross.iter().find(|x| x.input == input && x.significant)?;
            Some(format!(
                "{}: {} residual correlates with {input} (ρ = {:.2} at lag {})",
                e.event, s.signal, x.correlation, x.best_lag_samples
            ))
        })
        .collect()
}

/// The window holding most of each event's Q residual, as signature lines.
pub(crate) fn q_window(ev: &[EventEvidence]) -> Vec<String> {
    ev.iter()
        .flat_map(|e| e.signals.iter().map(move |s| (e, s)))
        .filter(|(_, s)| s.signal == "Q")
        .filter_map(|(e, s)| {
            let w = s
                .windows
                .iter()
                .max_by(|a, b| a.share_of_sse.total_cmp(&b.share_of_sse))?;
            Some(format!(
                "{}: Q residual mostly in the {} window ({:.0} % of SSE)",
                e.event,
                w.label,
                100.0 * w.share_of_sse
            ))
        })
        .collect()
}
