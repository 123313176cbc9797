//! The tests of an extension's gain on samples its re-fit did not fit: the second held-out test
//! on contiguous segments, and the gain the same re-fits achieve on surrogate records where
//! only noise can be fitted.

use itaipu_dynamics::unit::Unit;

use crate::bounds::FreeBound;

use super::baseline_cache::{BaselineCache, BaselineKey};
use super::cause::Extension;
use super::extension_fit::{baseline_from, fit_extension};
use super::gain::held_floor_met;
use super::options::DiagnoseOptions;
use super::profile::{Label, RefitKind};
use super::refit::{refit, Refit, RefitEnv};
use super::split::{SEGMENT_OVERFIT, SEGMENT_S};

/// The second held-out test's outcome: the baseline's and the extension's χ² on the held-out
/// segments, and how much worse per sample the baseline re-fitted on the segments predicts them
/// than the baseline re-fitted on the blocks predicts the held-out blocks.
pub(super) struct SegmentsTest {
    base_held: f64,
    ext_held: f64,
    overfit: f64,
    pub(super) simulations: usize,
}

impl SegmentsTest {
    /// The relative held-out drop on the segments.
    pub(super) fn drop(&self) -> f64 {
        (self.base_held - self.ext_held) / self.base_held.max(1e-300)
    }

    /// Informative ([`SEGMENT_OVERFIT`]) and the held-out drop at least the threshold.
    pub(super) fn passes(&self, opts: &DiagnoseOptions) -> bool {
        self.overfit <= SEGMENT_OVERFIT && held_floor_met(self.drop(), opts)
    }

    pub(super) fn note(&self) -> String {
        format!(
            "held out on {SEGMENT_S} s segments: χ² {:.1} -> {:.1} ({:+.1} %){}",
            self.base_held,
            self.ext_held,
            100.0 * self.drop(),
            if self.overfit <= SEGMENT_OVERFIT {
                String::new()
            } else {
                format!(
                    ", not counted: the baseline re-fitted on the segments predicts the others \
                     {:.1} × worse per sample than the blocks",
                    self.overfit
                )
            }
        )
    }
}

/// The second held-out test, on contiguous segments (`env` on the segments' split): the
/// extension and its baseline (cached in `baselines` beside the blocks' one, `key`) re-fitted on
/// the fitted segments and judged on the others. For an extension whose fitted gain passes but
/// whose interleaved held-out blocks do not confirm it: interleaved 0.5 s blocks test that the
/// gain is not noise, but a model that absorbed the cause by bending its parameters predicts
/// them about as well as the fitted ones, and an effect confined to the disturbance (a terminal
/// load acts in the dip, which a fitted block holds) leaves them nothing to predict. Longer
/// segments hold out whole phases of the response (the recovery after the dip), which a bent
/// model predicts worse. `None` when a re-fit fails.
pub(super) fn segments_test(
    env: &RefitEnv,
    unit: &Unit,
    base_bounds: &[FreeBound],
    ext: &Extension,
    baselines: &mut BaselineCache,
    key: &BaselineKey,
    id: &str,
) -> Option<SegmentsTest> {
    let lkey = key.on_segments();
    if !baselines.contains_key(&lkey) {
        let label = Label::new(RefitKind::Segments, format!("{id} baseline on segments"));
        let b = refit(env, unit, base_bounds, &[], &label).ok()?;
        baselines.insert(lkey.clone(), b);
    }
    let bl = baselines.at(&lkey);
    let label = Label::new(RefitKind::Segments, format!("{id} on segments"));
    let rl = fit_extension(env, ext, bl, !base_bounds.is_empty(), &label).ok()?;
    // Per held-out sample, against the baseline re-fitted on the blocks: a baseline that
    // predicts the held-out segments far worse has over-fitted the segments it saw, and two
    // such predictions say nothing of structure.
    let per = |r: &Refit| r.chi2_held / r.n_held.max(1) as f64;
    Some(SegmentsTest {
        base_held: bl.chi2_held,
        ext_held: rl.chi2_held,
        overfit: per(bl) / per(baselines.at(key)).max(1e-300),
        simulations: rl.simulations,
    })
}

/// The noise-fitting gain of an extension ([`noise_fitting_gain`]): per surrogate draw whose
/// re-fits ran, the residuals' χ² drop on the fitted and on the held-out samples.
#[derive(Default)]
pub(super) struct NoiseFitting {
    pub(super) fits: Vec<f64>,
    pub(super) helds: Vec<f64>,
    pub(super) simulations: usize,
    /// A draw's re-fits did not run.
    pub(super) failed: bool,
}

impl NoiseFitting {
    fn mean(v: &[f64]) -> f64 {
        if v.is_empty() {
            0.0
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    }
    pub(super) fn mean_fit(&self) -> f64 {
        Self::mean(&self.fits)
    }
    pub(super) fn mean_held(&self) -> f64 {
        Self::mean(&self.helds)
    }
}

/// The gain the same re-fits (the baseline's over `base_bounds`, the extension's over
/// `bounds`) achieve on each surrogate record of `envs_null` (the reference's own simulation
/// with the noise drawn again, where only noise can be fitted). Each draw's baseline is cached
/// in `baselines` under its own key ([`BaselineKey::on_surrogate`]).
#[allow(clippy::too_many_arguments)]
pub(super) fn noise_fitting_gain(
    envs_null: &[RefitEnv],
    baselines: &mut BaselineCache,
    unit: &Unit,
    base_bounds: &[FreeBound],
    ext: &Extension,
    bounds: &[FreeBound],
    key: &BaselineKey,
    id: &str,
) -> NoiseFitting {
    let mut out = NoiseFitting::default();
    for (draw, env_null) in envs_null.iter().enumerate() {
        let nkey = key.on_surrogate(draw);
        if !baselines.contains_key(&nkey) {
            let label = Label::new(RefitKind::Surrogate, format!("{id} null baseline"));
            if let Ok(b) = refit(env_null, unit, base_bounds, &[], &label) {
                baselines.insert(nkey.clone(), b);
            }
        }
        // The standard search budget: on the surrogate the reference is exact and the start is
        // its optimum, so the longer search a bent calibration needs buys nothing.
        let label = Label::new(RefitKind::Surrogate, format!("{id} null"));
        let (Some(b0), Ok(r0)) = (
            baselines.get(&nkey),
            refit(env_null, &ext.unit, bounds, &ext.ties, &label),
        ) else {
            out.failed = true;
            continue;
        };
        // The null baseline again from where the extension's null re-fit ended, as on the
        // record: the noise-fitting gain is the extension's, not a luckier search.
        let mut b0 = b0.clone_scores();
        if b0.chi2_fit > r0.chi2_fit && !base_bounds.is_empty() {
            let label = Label::new(RefitKind::Surrogate, format!("{id} null baseline again"));
            if let Some(b2) = baseline_from(env_null, unit, base_bounds, &r0, &label) {
                if b2.chi2_fit < b0.chi2_fit {
                    b0 = b2.clone_scores();
                }
            }
        }
        // Only the residuals' part of the surrogate's gain is noise fitting. Its priors' part
        // is not: the surrogate was made by the reference, whose calibration may have bent
        // datasheet values to absorb the cause, so an extension that returns them gains that
        // part there as on the record, and netting it out would make an absorbed cause
        // unnameable by construction.
        let (b_fit, b_held) = b0.residuals_chi2();
        let (e_fit, e_held) = r0.clone_scores().residuals_chi2();
        out.fits.push((b_fit - e_fit).max(0.0));
        out.helds.push((b_held - e_held).max(0.0));
        out.simulations += r0.simulations;
    }
    out
}
