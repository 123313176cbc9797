//! Where in time the error lives: bias, RMS and share of the squared error per window.

use serde::{Deserialize, Serialize};

use super::*;

/// Bias, RMS and share of the error of the residual inside one time window.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WindowStats {
    /// Window name (e.g. `pre-event`, `dip`, `recovery`, `tail`).
    pub label: String,
    /// Window start in s (inclusive).
    pub start_s: f64,
    /// Window end in s (exclusive, except that the record's last sample belongs to a window
    /// ending at or after it).
    pub end_s: f64,
    /// Number of samples in the window.
    pub samples: usize,
    /// Mean residual in the window, `Σ r_k / n`.
    pub bias: f64,
    /// Root-mean-square residual in the window, `√(Σ r_k² / n)`.
    pub rms: f64,
    /// Window's share of the record's sum of squared errors, `Σ_window r_k² / Σ_all r_k²`.
    pub share_of_sse: f64,
}

/// [`WindowStats`] of `residual` (at the times `t`) for each `(label, start, end)` window, with
/// the membership `start − eps ≤ t_k < end − eps` (the last sample also in windows that close
/// at the record's end) and the share of `sse`, the record's sum of squared errors.
pub(super) fn window_stats(
    t: &[f64],
    residual: &[f64],
    windows: &[(String, f64, f64)],
    eps: f64,
    sse: f64,
) -> Vec<WindowStats> {
    let n = t.len();
    let t_last = t.last().copied().unwrap_or(0.0);
    windows
        .iter()
        .map(|(label, a, b)| {
            let closes = *b >= t_last - eps;
            let sel: Vec<f64> = t
                .iter()
                .zip(residual)
                .enumerate()
                .filter(|&(k, (&tk, _))| {
                    (tk >= a - eps && tk < b - eps) || (k + 1 == n && closes && tk >= a - eps)
                })
                .map(|(_, (_, &r))| r)
                .collect();
            let (wb, wr) = bias_rms(&sel);
            let wsse: f64 = sel.iter().map(|r| r * r).sum();
            WindowStats {
                label: label.clone(),
                start_s: *a,
                end_s: *b,
                samples: sel.len(),
                bias: wb,
                rms: wr,
                share_of_sse: if sse > 0.0 { wsse / sse } else { 0.0 },
            }
        })
        .collect()
}
