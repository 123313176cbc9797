//! The options of a diagnosis and their defaults, declared here once: the library's
//! [`DiagnoseOptions::default`], the command line, Python and the request layer's
//! `DIAGNOSE_SEARCH` all read them.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use crate::bounds::FreeBound;

pub use super::split::Fold;
use super::user_cause::UserCause;

/// Seed of the re-fits' swarms.
pub const DEFAULT_SEED: u64 = 1;
/// Particles of each re-fit's swarm.
pub const DEFAULT_PARTICLES: usize = 16;
/// Iterations of each re-fit's swarm.
pub const DEFAULT_PSO_ITERATIONS: usize = 20;
/// Iterations of each re-fit's local method.
pub const DEFAULT_LOCAL_ITERATIONS: u64 = 15;

/// Options of a diagnosis.
#[derive(Debug, Clone)]
pub struct DiagnoseOptions {
    /// Causes to try (ids from [`super::catalog::CAUSES`]); empty = the whole catalog.
    pub causes: Vec<String>,
    /// Causes written by the user ([`super::user_cause`]), tried after the catalog's (or named
    /// in `causes`).
    pub user_causes: Vec<UserCause>,
    /// Calibrated parameters to free again in every re-fit (baselines and extensions alike),
    /// with their bounds: the parameters a calibration without the cause may have bent to make
    /// up for it (typically the stage parameters of the preceding fit). Empty = only each
    /// cause's own interacting parameters.
    pub refit: Vec<FreeBound>,
    pub seed: u64,
    pub particles: usize,
    pub pso_iterations: usize,
    pub lbfgs_iterations: u64,
    pub lbfgs_memory: usize,
    /// Block length of the fit/held-out split of an event [s].
    pub block_s: f64,
    /// ΔBIC above which a gain counts (10 = "very strong" on the Kass-Raftery scale).
    pub bic_threshold: f64,
    /// Smallest relative drop of the fitted χ² (net of noise fitting) for a cause to be named.
    /// Default 0: the extension fits the fitted blocks at least as well as its baseline. That
    /// gain is tested by its ΔBIC inside the record's evidence (`bic_threshold`); a floor on
    /// its relative size would measure an effect's share of the misfit on the half where the
    /// share is biased low: the baseline is re-fitted on the same blocks and bends its free
    /// values to absorb what it can of the effect there, and it is the held-out blocks, which
    /// the bent values predict worse, that show the share (`min_held_drop` is that floor). A
    /// rival that fits part of another cause's misfit is told apart by the ranking (the BIC and
    /// held-out gaps between significant candidates), not by a floor.
    pub min_fit_drop: f64,
    /// Smallest relative drop of the held-out χ² (net of noise fitting): the share of the
    /// misfit an extension predicts on samples its re-fit did not see, for it to be named.
    pub min_held_drop: f64,
    /// Residual RMS up to this multiple of the noise floor counts as "at the noise floor".
    pub noise_factor: f64,
    /// How the events are played back ([`super::Playback`]): `None` = the phasor playback (P
    /// and Q compared), which needs a voltage angle; a record without one is diagnosed in the
    /// mode named here, on that mode's compared channels.
    pub mode: Option<itaipu_dynamics::mode::PlaybackMode>,
    /// Let the re-fits' searches (swarms and grid scans) step over the samples inside a
    /// smoothed input's spline ([`crate::problem::refit_search_integrator`]) instead of landing
    /// on every sample ([`crate::problem::search_integrator`]); the local method, every χ²
    /// and every reported number are unchanged in kind. Off by default: the search would rank
    /// on the spline what the local method polishes on the line, two inputs whose J differ
    /// after a fault by more than the gains a re-fit compares, so a search may hand the local
    /// method another valley than it would on the line. It can be the default once every
    /// playback of a smoothed record plays one input.
    pub refit_over_samples: bool,
    /// Surrogate records a candidate's noise-fitting gain is measured on (at least 1; default
    /// 1): the gain it nets out is their mean. The rule (a statistic): one draw's noise-fitting
    /// gain is a random variable whose spread is several χ² units, as large as the margin by
    /// which a net gain may clear `min_fit_drop` or `bic_threshold`, so such a verdict follows
    /// the draw; the mean of n draws spreads √n less, for n times the surrogate re-fits.
    pub null_draws: usize,
    /// Also try the bundled effects outside the catalog ([`super::look_alike`]) in a full
    /// diagnosis (`causes` empty) where a candidate passed its test: a residual one of them
    /// explains better is then `unexplained` (or `inconclusive`), not the nearest catalog
    /// cause.
    pub look_alikes: bool,
    /// Which alternate blocks the re-fits fit ([`Fold`]): the even ones by default; the
    /// diagnosis sets the swapped fold itself to check a named cause ([`Self::other_fold`]).
    pub fold: Fold,
    /// Check a named cause on the other fold with another seed: the cause alone diagnosed again
    /// with the fitted and held-out blocks swapped and the seed after this one. A cause whose
    /// gain does not hold there is `inconclusive`, with both folds' numbers: a verdict that
    /// follows the split or the seed is no verdict. Default on.
    pub other_fold: bool,
    /// When set (by a signal handler, say), every later candidate evaluation of the re-fits
    /// fails at once and the diagnosis returns [`super::DiagnoseError::Interrupted`] with the
    /// causes it finished.
    pub cancel: Option<Arc<AtomicBool>>,
}

impl DiagnoseOptions {
    /// Whether [`DiagnoseOptions::cancel`] is set.
    pub(super) fn cancelled(&self) -> bool {
        self.cancel
            .as_ref()
            .is_some_and(|c| c.load(Ordering::Relaxed))
    }
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        Self {
            causes: vec![],
            user_causes: vec![],
            refit: vec![],
            seed: DEFAULT_SEED,
            particles: DEFAULT_PARTICLES,
            pso_iterations: DEFAULT_PSO_ITERATIONS,
            lbfgs_iterations: DEFAULT_LOCAL_ITERATIONS,
            lbfgs_memory: 7,
            block_s: 0.5,
            bic_threshold: 10.0,
            min_fit_drop: 0.0,
            min_held_drop: 0.01,
            noise_factor: 1.5,
            mode: None,
            refit_over_samples: false,
            null_draws: 1,
            look_alikes: true,
            fold: Fold::Even,
            other_fold: true,
            cancel: None,
        }
    }
}
