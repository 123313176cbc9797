//! The statistics a candidate's gain is judged by: the significance tests (the fitted and
//! held-out floors, ΔBIC, the whole record's evidence), the share of a misfit an extension
//! explains, and the calibrated values it un-bends.

use itaipu_dynamics::unit::Unit;

use crate::bounds::FreeBound;

use super::options::DiagnoseOptions;
use super::report::{Distortion, Gains};

/// The distortion a cause removes: for every re-freed parameter with a prior, its baseline and
/// extension values, kept where either lies more than one prior spread from the datasheet.
pub(super) fn distortion(refit: &[FreeBound], base: &Unit, ext: &Unit) -> Vec<Distortion> {
    refit
        .iter()
        .filter_map(|b| {
            let p = b.prior?;
            let get = |u: &Unit| u.param(&b.param).ok().map(|r| u.get(r));
            let (vb, ve) = (get(base)?, get(ext)?);
            let (zb, ze) = (p.z(vb)?, p.z(ve)?);
            (zb.abs() > 1.0 || ze.abs() > 1.0).then(|| Distortion {
                param: b.param.clone(),
                datasheet: p.center,
                base: vb,
                extended: ve,
                z_base: zb,
                z_extended: ze,
            })
        })
        .collect()
}

/// The χ²₁ quantile at 95 %: the likelihood-ratio test of one parameter. Relaxing an upper end
/// that gains less than this (in independent samples, VIF-deflated) is a bound the data do not
/// push against.
pub(super) const BINDING_CHI2: f64 = 3.841;

/// Whether an upper end binds, given the relaxed re-fit's gain (`None`: not measured).
pub(super) fn binds(relaxed_gain: Option<f64>) -> bool {
    relaxed_gain.is_none_or(|g| g >= BINDING_CHI2)
}

/// The fitted blocks' floor: a relative χ² drop `rel` (net of noise fitting) of at least
/// `min_fit_drop`. The one definition of the floors and of the ΔBIC threshold, which the
/// significance test ([`GainTest`]), the grade and a `none` verdict's statement all read.
pub(super) fn fit_floor_met(rel: f64, opts: &DiagnoseOptions) -> bool {
    rel >= opts.min_fit_drop
}

/// The held-out blocks' floor: a relative χ² drop `rel` of at least `min_held_drop`.
pub(super) fn held_floor_met(rel: f64, opts: &DiagnoseOptions) -> bool {
    rel >= opts.min_held_drop
}

/// A ΔBIC (or the record's evidence `2 ln B`, on the same scale) above `bic_threshold`.
pub(super) fn bic_met(delta_bic: f64, opts: &DiagnoseOptions) -> bool {
    delta_bic > opts.bic_threshold
}

/// A χ² drop `d` relative to the baseline's `chi2`.
pub(super) fn relative(d: f64, chi2: f64) -> f64 {
    d / chi2.max(1e-300)
}

/// The evidence for an extension over its baseline from the whole record, `2 ln B`: the fitted
/// blocks' marginal likelihood ratio by Schwarz's approximation (`delta_bic`, the parameters'
/// Occam penalty in it) plus the held-out blocks' predictive likelihood ratio at the values
/// fitted without them, `Δχ²_held/VIF` (no penalty: nothing was fitted to those samples; the
/// same variance inflation as the fitted part, the residuals' colour being the record's). The
/// two factors of `p(D_fit, D_held | M) = p(D_fit | M) · p(D_held | D_fit, M)`, so the sum is on
/// the scale the threshold is (10: "very strong" on Kass and Raftery's), with the same
/// threshold. `d_held` is net of noise fitting (the surrogate's gain). The fitted ΔBIC alone
/// discards half the record: an exciter ceiling reached in one short window of the dip gains
/// little on the fitted blocks (a few per cent, a ΔBIC under the threshold with its three
/// parameters) and is then unnameable, however well it predicts the held-out samples it never
/// saw. A held-out loss counts as no gain here (the held-out floor `min_held_drop` already
/// refuses such a candidate).
pub(super) fn record_evidence(delta_bic: f64, d_held: f64, vif: f64) -> f64 {
    delta_bic + d_held.max(0.0) / vif.max(1.0)
}

/// A candidate's gains over its baseline as the significance tests read them
/// ([`DiagnoseOptions`]: `bic_threshold`, `min_fit_drop`, `min_held_drop`): the fitted and
/// held-out χ² drops `d_fit`, `d_held` (net of noise fitting, or raw where the question is
/// whether they could pass), the baseline's χ² on each half and its variance inflation, the
/// extension's added parameters `k` and the fitted samples `n`.
#[derive(Debug, Clone, Copy)]
pub(super) struct GainTest {
    pub d_fit: f64,
    pub d_held: f64,
    pub chi2_fit: f64,
    pub chi2_held: f64,
    pub vif: f64,
    pub k: usize,
    pub n: f64,
}

impl GainTest {
    /// ΔBIC on the fitted blocks: `Δχ²/VIF − k ln(N/VIF)`.
    pub fn delta_bic(&self) -> f64 {
        self.d_fit / self.vif - self.k as f64 * (self.n / self.vif).max(1.0).ln()
    }

    /// The whole record's evidence `2 ln B` ([`record_evidence`]).
    pub fn evidence(&self) -> f64 {
        record_evidence(self.delta_bic(), self.d_held, self.vif)
    }

    /// The fitted blocks' gain passes: ΔBIC above the threshold and the fitted χ² down by
    /// `min_fit_drop` at least.
    pub fn fits(&self, opts: &DiagnoseOptions) -> bool {
        bic_met(self.delta_bic(), opts) && self.fitted_floor(opts)
    }

    /// The held-out blocks' χ² down by `min_held_drop` at least.
    pub fn held(&self, opts: &DiagnoseOptions) -> bool {
        held_floor_met(relative(self.d_held, self.chi2_held), opts)
    }

    fn fitted_floor(&self, opts: &DiagnoseOptions) -> bool {
        fit_floor_met(relative(self.d_fit, self.chi2_fit), opts)
    }

    /// Significant: the fitted χ² down by its floor, and either the held-out χ² down by its
    /// floor with the whole record's evidence above the threshold, or (the held-out blocks not
    /// confirming) the fitted ΔBIC above it and the segments' second test passed
    /// (`segments_pass`).
    pub fn passes(&self, segments_pass: bool, opts: &DiagnoseOptions) -> bool {
        self.fitted_floor(opts)
            && ((self.held(opts) && bic_met(self.evidence(), opts))
                || (segments_pass && self.fits(opts)))
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

#[cfg(test)]
mod tests {
    use super::*;

    /// An upper end binds when relaxing it gains the one-parameter test's quantile or more, or
    /// when the relaxed re-fit could not say (the veto stays).
    #[test]
    fn an_upper_end_binds_unless_relaxing_it_gains_little() {
        assert!(binds(None));
        assert!(binds(Some(BINDING_CHI2)));
        assert!(binds(Some(40.0)));
        assert!(!binds(Some(0.4)));
    }

    /// The significance tests on a candidate's gains. A governor deadband the re-fitted
    /// baseline absorbed on the fitted blocks: Δχ² 12.8 of 1585 fitted (0.8 %, ΔBIC −3.1 with 2
    /// parameters) and 59.5 of 1696 held out (3.5 %), the record's evidence 51.7: significant
    /// by default, refused by a 2 % floor on the fitted drop. An extension that fits worse than
    /// its baseline, one whose
    /// held-out blocks lose, and one whose evidence stays under 10 are not; one whose held-out
    /// blocks do not confirm it is, by a fitted ΔBIC above 10 and the segments' second test.
    #[test]
    fn a_gain_is_significant_by_the_held_out_floor_and_the_record_evidence() {
        let opts = DiagnoseOptions::default();
        let deadband = GainTest {
            d_fit: 12.78,
            d_held: 59.55,
            chi2_fit: 1585.4,
            chi2_held: 1696.3,
            vif: 1.087,
            k: 2,
            n: 1820.0,
        };
        assert!(
            (deadband.delta_bic() + 3.1).abs() < 0.1,
            "{}",
            deadband.delta_bic()
        );
        assert!(
            (deadband.evidence() - 51.7).abs() < 0.2,
            "{}",
            deadband.evidence()
        );
        assert!(deadband.held(&opts) && !deadband.fits(&opts));
        assert!(deadband.passes(false, &opts));
        let floor = DiagnoseOptions {
            min_fit_drop: 0.02,
            ..DiagnoseOptions::default()
        };
        assert!(!deadband.passes(false, &floor) && !deadband.passes(true, &floor));
        let worse_fit = GainTest {
            d_fit: -5.0,
            ..deadband
        };
        assert!(worse_fit.held(&opts) && !worse_fit.passes(true, &opts));
        let held_loss = GainTest {
            d_held: -10.0,
            ..deadband
        };
        assert!(!held_loss.passes(false, &opts));
        let weak = GainTest {
            d_fit: 5.0,
            d_held: 20.0,
            ..deadband
        };
        assert!(weak.held(&opts) && weak.evidence() < 10.0 && !weak.passes(false, &opts));
        let unconfirmed = GainTest {
            d_fit: 40.0,
            d_held: 5.0,
            ..deadband
        };
        assert!(unconfirmed.fits(&opts) && !unconfirmed.held(&opts));
        assert!(!unconfirmed.passes(false, &opts) && unconfirmed.passes(true, &opts));
    }

    /// The held-out samples' predictive gain adds to the fitted ΔBIC, deflated by the same
    /// variance inflation; a held-out loss adds nothing (the held-out floor refuses it).
    #[test]
    fn the_held_out_prediction_adds_to_the_fitted_evidence() {
        // An exciter ceiling reached in the dip: ΔBIC 4.5 on the fitted blocks, Δχ² 92.8 held
        // out.
        assert!(record_evidence(4.5, 92.8, 1.0) > 10.0);
        assert_eq!(record_evidence(4.5, 20.0, 4.0), 9.5);
        assert_eq!(record_evidence(4.5, -30.0, 1.0), 4.5);
        // A VIF below 1 (anti-correlated residual) does not inflate the held-out part.
        assert_eq!(record_evidence(0.0, 8.0, 0.5), 8.0);
    }
}
