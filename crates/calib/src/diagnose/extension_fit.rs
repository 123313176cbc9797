//! The extension's re-fit (from the calibrated values, and for a limit or a skew from the
//! datasheet values too), the local re-fits that polish a baseline or test a bound, and the
//! calibrated set re-freed in every extension.

use itaipu_dynamics::unit::Unit;

use crate::bounds::FreeBound;
use crate::problem::FreeParam;

use super::cause::Extension;
use super::error::RefitError;
use super::gain::binds;
use super::options::DiagnoseOptions;
use super::profile::{Label, RefitKind};
use super::refit::{refit, Refit, RefitEnv};

/// The extension's re-fit. It starts from the calibrated values (the extension may need the
/// interacting parameters back where the calibration found them), or for a limit or a skew
/// ([`Extension::from_datasheet`]) from the datasheet values and from the calibrated ones, the
/// better kept ([`several_starts`]); when it ends worse than the baseline, it is polished again
/// from where the baseline ended, so that with the extension at its neutral start it is at
/// least the baseline. A datasheet start is not given to every cause: from it a flexible
/// extension (a deadband) can un-bend a clean record's calibration and gain what the calibrated
/// values already had, a false alarm.
pub(super) fn fit_extension(
    env: &RefitEnv,
    ext: &Extension,
    baseline: &Refit,
    has_base: bool,
    label: &Label,
) -> Result<Refit, RefitError> {
    let deep = DiagnoseOptions {
        pso_iterations: env.opts.pso_iterations * ext.search_factor.max(1),
        ..env.opts.clone()
    };
    let deep_env = env.with(&deep);
    let r = if ext.from_datasheet {
        several_starts(env, &deep_env, ext, label)?
    } else {
        from_calibrated(&deep_env, ext, label)?
    };
    if r.chi2_fit > baseline.chi2_fit && has_base {
        Ok(polished_from_baseline(env, ext, baseline, label, r))
    } else {
        Ok(r)
    }
}

/// The extension's search from the calibrated values (the longer search of `deep_env`).
fn from_calibrated(
    deep_env: &RefitEnv,
    ext: &Extension,
    label: &Label,
) -> Result<Refit, RefitError> {
    let calibrated: Vec<FreeBound> = ext.free().cloned().collect();
    refit(deep_env, &ext.unit, &calibrated, &ext.ties, label)
}

/// A limit's or a skew's re-fit from more than one start, the best (χ² with the priors) kept.
///
/// Its re-fit is a search over a multimodal objective (a limiter that acts too early, too late
/// or never gives separate valleys), and a gain that depends on which single start the search
/// was given measures the search, not the cause. The datasheet start gives the limit a gradient
/// where a calibration that mimicked it bent the unit so far that it never reaches it; the
/// calibrated start is where the rest of the unit fits the record. When the calibrated start
/// wins, its limit settings are read against the bent unit (an OEL's current against a field
/// current that a bent X_d raised), so a third start, the limit where it ended and the rest at
/// the datasheet, polished, is kept if it fits better. A skew's delay gets the same starts: from
/// the calibrated unit, bent to lag like the skew, its re-fit stops at a fraction of it. The
/// datasheet values together with the calibrated ones may break a physical relation (a
/// datasheet X_d below a calibrated X'_d held by its own bounds): then from the calibrated
/// values alone.
fn several_starts(
    env: &RefitEnv,
    deep_env: &RefitEnv,
    ext: &Extension,
    label: &Label,
) -> Result<Refit, RefitError> {
    let datasheet: Vec<FreeBound> = ext
        .extension_free
        .iter()
        .cloned()
        .chain(ext.interacting_free.iter().map(|b| match b.prior {
            Some(p) => b.clone().starting_at(p.center),
            None => b.clone(),
        }))
        .collect();
    let second = label.then("from the calibrated values");
    let Ok(r) = refit(deep_env, &ext.unit, &datasheet, &ext.ties, label) else {
        return from_calibrated(deep_env, ext, &second);
    };
    let r2 = from_calibrated(deep_env, ext, &second);
    let calibrated_won = matches!(&r2, Ok(r2) if r2.chi2_fit < r.chi2_fit);
    let r = r.best_of(r2);
    if !calibrated_won {
        return Ok(r);
    }
    let third: Vec<FreeBound> = ext
        .extension_free
        .iter()
        .map(|b| b.starting_in(&r.unit))
        .chain(datasheet[ext.extension_free.len()..].iter().cloned())
        .collect();
    let polish = DiagnoseOptions {
        pso_iterations: 0,
        ..env.opts.clone()
    };
    let third_label =
        label.then("the extension from the calibrated start, the rest from the datasheet");
    Ok(r.best_of(refit(
        &env.with(&polish),
        &ext.unit,
        &third,
        &ext.ties,
        &third_label,
    )))
}

/// `r` or, when better, the extension polished from where the baseline ended with the
/// extension at its neutral start: a polish, not another search (its scans kept: they are cheap
/// and find a limit's valley from there), which only has to end at least as low as the
/// baseline.
fn polished_from_baseline(
    env: &RefitEnv,
    ext: &Extension,
    baseline: &Refit,
    label: &Label,
    r: Refit,
) -> Refit {
    let polish = DiagnoseOptions {
        pso_iterations: 0,
        ..env.opts.clone()
    };
    let env = env.with(&polish);
    let from_base: Vec<FreeBound> = ext
        .extension_free
        .iter()
        .cloned()
        .chain(
            ext.interacting_free
                .iter()
                .map(|b| b.starting_in(&baseline.unit)),
        )
        .collect();
    r.best_of(refit(
        &env,
        &ext.unit,
        &from_base,
        &ext.ties,
        &label.then("from the baseline"),
    ))
}

/// The baseline polished (no swarm, no scans) from the interacting values a re-fit `from`
/// ended at.
pub(super) fn baseline_from(
    env: &RefitEnv,
    unit: &Unit,
    base_bounds: &[FreeBound],
    from: &Refit,
    label: &Label,
) -> Option<Refit> {
    refit_locally(env, unit, base_bounds, &[], &from.unit, label).ok()
}

/// The re-fit of `unit` over `bounds` by the local method alone (no scan, no swarm), from the
/// values those parameters have in `from`.
pub(super) fn refit_locally(
    env: &RefitEnv,
    unit: &Unit,
    bounds: &[FreeBound],
    ties: &[(String, String)],
    from: &Unit,
    label: &Label,
) -> Result<Refit, RefitError> {
    let start: Vec<FreeBound> = bounds
        .iter()
        .map(|b| FreeBound {
            scan: 0,
            ..b.starting_in(from)
        })
        .collect();
    let local = DiagnoseOptions {
        pso_iterations: 0,
        ..env.opts.clone()
    };
    refit(&env.with(&local), unit, &start, ties, label)
}

/// An extension parameter that its re-fit left at the upper end of its declared range (the
/// largest saturation, load, delay, limiter setting the cause can physically be).
pub(super) struct Pressed {
    pub(super) param: FreeParam,
    pub(super) value: f64,
    /// The fitted χ² the re-fit gains when that end is moved out by the range's own width
    /// (`None`: not measured, or the relaxed re-fit failed: taken as binding).
    pub(super) relaxed_gain: Option<f64>,
    /// The relaxed re-fit's simulations.
    pub(super) simulations: usize,
}

impl Pressed {
    /// The first of `ext`'s own parameters at the upper end of its range in the re-fit `r`,
    /// `free` being the re-fit's free parameters resolved (the extension's first).
    fn find(free: &[FreeParam], ext: &Extension, r: &Refit) -> Option<Self> {
        free.iter()
            .zip(r.values.iter().copied())
            .take(ext.extension_free.len())
            .find(|(f, v)| f.at_upper_bound(*v))
            .map(|(param, value)| Self {
                param: param.clone(),
                value,
                relaxed_gain: None,
                simulations: 0,
            })
    }

    /// Whether the data push against that end: the re-fit from `r` with the range extended by
    /// its width (local method only, every other bound as it was) gains at least
    /// [`super::gain::BINDING_CHI2`] in independent samples. An end that does not bind is where a flat
    /// valley of the parameter ran out, not a residual asking for more of the effect.
    fn measure(mut self, env: &RefitEnv, ext: &Extension, r: &Refit, vif: f64) -> Self {
        let width = self.param.hi - self.param.lo;
        let bounds: Vec<FreeBound> = ext
            .free()
            .map(|b| {
                let mut b = FreeBound {
                    polish_only: false,
                    ..b.clone()
                };
                if b.param == self.param.path {
                    b.max += width;
                }
                b
            })
            .collect();
        let label = Label::new(
            RefitKind::Extension,
            format!("{} relaxed past its upper end", self.param.path),
        );
        if let Ok(r2) = refit_locally(env, &ext.unit, &bounds, &ext.ties, &r.unit, &label) {
            self.relaxed_gain = Some((r.chi2_fit - r2.chi2_fit).max(0.0) / vif.max(1.0));
            self.simulations = r2.simulations;
        }
        self
    }

    /// [`Self::find`] then [`Self::measure`], the relaxed re-fit's simulations added to
    /// `simulations`.
    pub(super) fn measured(
        env: &RefitEnv,
        free: &[FreeParam],
        ext: &Extension,
        r: &Refit,
        vif: f64,
        simulations: &mut usize,
    ) -> Option<Self> {
        let p = Self::find(free, ext, r)?.measure(env, ext, r, vif);
        *simulations += p.simulations;
        Some(p)
    }

    pub(super) fn binds(&self) -> bool {
        binds(self.relaxed_gain)
    }
}

/// The extension with the calibrated set of [`DiagnoseOptions::refit`] re-freed: a cause's own
/// interacting parameter keeps its bounds and takes the calibration's prior; the others join as
/// polish-only parameters at their value in the extended unit.
pub(super) fn with_calibrated_set(mut ext: Extension, opts: &DiagnoseOptions) -> Extension {
    for b in &opts.refit {
        let known = ext.free().any(|f| f.param == b.param);
        if known {
            for f in ext
                .interacting_free
                .iter_mut()
                .filter(|f| f.param == b.param)
            {
                f.prior = b.prior;
            }
        } else if ext.unit.param(&b.param).is_ok() {
            ext.interacting_free.push(FreeBound {
                polish_only: true,
                ..b.starting_in(&ext.unit)
            });
        }
    }
    ext
}
