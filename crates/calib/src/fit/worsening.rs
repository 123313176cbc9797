//! A pass that makes a channel an earlier pass compared far worse: measured after every pass
//! (stage, simultaneous or joint) from the fitness rows before and after it, and said in the
//! pass's report, on the terminal and among the fit's warnings. Nothing is undone: a pass keeps
//! what its own objective chose (a joint table that names fewer channels than its stages is
//! the user's word), but it is never accepted silently.
//!
//! **The rule.** For each channel (in its playback mode) that an earlier pass compared, over the
//! fitted events: its noise-weighted sum of squares `χ² = Σ_e Σ_k Δ²/σ_e²` (σ_e² the robust
//! noise variance of the measured channel over event `e`'s window,
//! [`EventData::channel_noise_variance`]) over its `n` samples, before and after the pass. The
//! pass made it **far worse** when `χ²_after / s² > max(2 n, χ²_{n, 0.999})`, with
//! `s² = max(χ²_before / n, 1)` the channel's reduced χ² before the pass: its residual variance
//! in units of the noise, at least the noise (lmfit scales its covariance by the same number).
//! In words: in units of what the channel's residual was before, the pass added more than a
//! whole noise of `n` samples, which a χ² with `n` degrees of freedom exceeds with probability
//! below 0.1 % from n = 30 on (Wilson-Hilferty; below n = 30 the 0.1 % quantile itself, which
//! is larger than 2n, is the bar). A channel at its noise before must end above twice its noise
//! variance (RMS √2 σ, more than the ≈ 25 % an estimated σ may be off); a channel already
//! off by model error must double its sum of squares, whatever σ is, since `s²` cancels σ.
//! A pass that trades a little of one channel for another (a joint pass balancing P against
//! Q) stays far below that; a joint pass on P and Q alone after stages that fitted E_fd is not.

use serde::{Deserialize, Serialize};

use itaipu_dynamics::event::{Channel, Event};
use itaipu_dynamics::mode::PlaybackMode;

use crate::problem::{objective_weights, EventData};
use crate::spec::StageSpec;

use super::report::EventFitness;

/// The bar on `χ²_after / s²` in units of the channel's samples `n` (see the module
/// documentation): the pass added at least a whole noise of `n` samples.
pub const WORSENING_FACTOR: f64 = 2.0;

/// The standard normal's upper 0.1 % quantile: the one-sided tail whose χ² quantile bars a
/// worsening of few samples.
const Z_TAIL: f64 = 3.090_232;

/// One channel a pass made far worse ([`super::worsening`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChannelWorsening {
    /// The pass that made it worse (`joint`, `avr`, …).
    pub pass: String,
    /// The last earlier pass that compared the channel.
    pub compared_by: String,
    pub mode: PlaybackMode,
    pub channel: Channel,
    /// Σ Δ² over the fitted events' windows before and after the pass (pu²).
    pub sse_before: f64,
    pub sse_after: f64,
    /// The same in units of the channel's noise variance.
    pub chi2_before: f64,
    pub chi2_after: f64,
    /// Samples summed (the fitted events' windows).
    pub samples: usize,
}

impl ChannelWorsening {
    /// The warning, naming the pass, the channel and both numbers.
    pub fn sentence(&self) -> String {
        format!(
            "pass {} made {} ({} playback), which pass {} compared, far worse: sum of squares \
             {:.4e} -> {:.4e} (chi-square {:.1} -> {:.1} over {} samples: {:.1} x)",
            self.pass,
            self.channel,
            self.mode,
            self.compared_by,
            self.sse_before,
            self.sse_after,
            self.chi2_before,
            self.chi2_after,
            self.samples,
            self.sse_after / self.sse_before.max(f64::MIN_POSITIVE)
        )
    }
}

/// Whether a channel's χ² going from `before` to `after` over `n` samples is far worse (see the
/// module documentation).
pub fn far_worse(before: f64, after: f64, n: usize) -> bool {
    if n == 0 || !before.is_finite() {
        return false;
    }
    if !after.is_finite() {
        return true;
    }
    let nf = n as f64;
    let s2 = (before / nf).max(1.0);
    after / s2 > (WORSENING_FACTOR * nf).max(chi2_quantile(nf, Z_TAIL))
}

/// The χ² quantile with `k` degrees of freedom at the standard normal quantile `z`
/// (Wilson-Hilferty's cube approximation, within 1 % from k = 3 on at the 0.1 % tail).
fn chi2_quantile(k: f64, z: f64) -> f64 {
    let c = 2.0 / (9.0 * k);
    k * (1.0 - c + z * c.sqrt()).powi(3)
}

/// What the passes of a fit compared so far, and each channel's noise per fitted event.
pub(super) struct Watch {
    /// `(mode, channel)` → the last pass that compared it.
    compared: Vec<((PlaybackMode, Channel), String)>,
    /// Per fitted event: its name and each recorded channel's noise variance.
    noise: Vec<(String, Vec<(Channel, f64)>)>,
}

impl Watch {
    pub(super) fn new(events: &[Event]) -> Self {
        let noise = events
            .iter()
            .filter_map(|e| {
                let d = EventData::new(e, None, None).ok()?;
                let vars = Channel::ALL
                    .into_iter()
                    .map(|c| (c, d.channel_noise_variance(c)))
                    .filter(|(_, v)| *v > 0.0 && v.is_finite())
                    .collect();
                Some((e.name.clone(), vars))
            })
            .collect();
        Self {
            compared: vec![],
            noise,
        }
    }

    /// After pass `label` (with stage spec `spec`): the channels earlier passes compared that it
    /// made far worse, from the fitness rows `before` (the previous pass's, `None` when unknown)
    /// and `after`; then the pass's own channels join the compared ones.
    pub(super) fn after_pass(
        &mut self,
        label: &str,
        spec: &StageSpec,
        before: Option<&[EventFitness]>,
        after: &[EventFitness],
    ) -> Vec<ChannelWorsening> {
        let mut out = vec![];
        if let Some(before) = before {
            for ((mode, channel), by) in &self.compared {
                let (Some(b), Some(a)) = (
                    self.sums(before, *mode, *channel),
                    self.sums(after, *mode, *channel),
                ) else {
                    continue;
                };
                if far_worse(b.1, a.1, a.2) {
                    out.push(ChannelWorsening {
                        pass: label.to_string(),
                        compared_by: by.clone(),
                        mode: *mode,
                        channel: *channel,
                        sse_before: b.0,
                        sse_after: a.0,
                        chi2_before: b.1,
                        chi2_after: a.1,
                        samples: a.2,
                    });
                }
            }
        }
        for key in compared_channels(spec) {
            match self.compared.iter_mut().find(|(k, _)| *k == key) {
                Some((_, by)) => *by = label.to_string(),
                None => self.compared.push((key, label.to_string())),
            }
        }
        out
    }

    /// `(Σ Δ², χ², samples)` of `channel` in `mode` over the fitted events of `rows`; `None`
    /// when a row lacks it or an event's noise is unknown.
    fn sums(
        &self,
        rows: &[EventFitness],
        mode: PlaybackMode,
        channel: Channel,
    ) -> Option<(f64, f64, usize)> {
        let (mut sse, mut chi2, mut n) = (0.0, 0.0, 0usize);
        for r in rows.iter().filter(|r| !r.held_out) {
            let var = self
                .noise
                .iter()
                .find(|(e, _)| *e == r.event)?
                .1
                .iter()
                .find(|(c, _)| *c == channel)?
                .1;
            let (s, k) = if r.modes.is_empty() {
                // A fit without playback modes: its rows are the phasor P+Q ones.
                let rms = match (mode, channel) {
                    (PlaybackMode::Phasor, Channel::P) => r.rms_p,
                    (PlaybackMode::Phasor, Channel::Q) => r.rms_q,
                    _ => return None,
                };
                (rms * rms * r.samples as f64, r.samples)
            } else {
                let c = r
                    .modes
                    .iter()
                    .find(|m| m.mode == mode)?
                    .channels
                    .iter()
                    .find(|c| c.channel == channel)?;
                (c.sse, c.samples)
            };
            sse += s;
            chi2 += s / var;
            n += k;
        }
        (n > 0).then_some((sse, chi2, n))
    }
}

/// The `(mode, channel)` pairs a pass with stage spec `spec` compares (weight above 0).
fn compared_channels(spec: &StageSpec) -> Vec<(PlaybackMode, Channel)> {
    match spec.compare() {
        Some(c) => c.weights.iter().map(|(ch, _)| (c.mode, *ch)).collect(),
        None => {
            let (wp, wq) = objective_weights(spec.objective, spec.weights);
            [(Channel::P, wp), (Channel::Q, wq)]
                .into_iter()
                .filter(|(_, w)| *w > 0.0)
                .map(|(c, _)| (PlaybackMode::Phasor, c))
                .collect()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bar: a channel at its noise must end above twice its noise variance; one off by
    /// model error must double its sum of squares; few samples need the χ² quantile.
    #[test]
    fn far_worse_is_a_doubling_beyond_the_noise() {
        let n = 600;
        // At the noise (χ² ≈ n): 1.9 n is not far worse, 2.1 n is.
        assert!(!far_worse(600.0, 1140.0, n));
        assert!(far_worse(600.0, 1260.0, n));
        // Below the noise (σ over-estimated): still twice the noise.
        assert!(!far_worse(300.0, 1100.0, n));
        // Off by model error: doubling whatever σ.
        assert!(!far_worse(6000.0, 11000.0, n));
        assert!(far_worse(6000.0, 12100.0, n));
        // Few samples: the 0.1 % quantile of χ²(10) is 29.6, above 2n = 20.
        assert!(!far_worse(10.0, 28.0, 10));
        assert!(far_worse(10.0, 31.0, 10));
        assert!((chi2_quantile(10.0, Z_TAIL) / 29.59 - 1.0).abs() < 0.01);
    }
}
