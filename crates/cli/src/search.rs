//! Swarm, L-BFGS and thread options shared by `fit` and `diagnose`.

use itaipu_calib::request::Search;

use crate::CliError;

/// Swarm, L-BFGS and thread options shared by `fit` and `diagnose`.
#[derive(clap::Args, Debug)]
pub struct SearchArgs {
    /// Random seed of the swarms (fit: the spec's; diagnose: 1). Same seed, same numbers, on
    /// any number of threads.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Swarm size (fit: the spec's, else 40; diagnose: 16 per candidate re-fit).
    #[arg(long)]
    pub particles: Option<usize>,
    /// Maximum swarm iterations (fit: per stage, the spec's, else 100; diagnose: 20 per re-fit).
    #[arg(long)]
    pub pso_iterations: Option<usize>,
    /// Maximum L-BFGS iterations (fit: per stage, the spec's, else 100; diagnose: 15 per
    /// re-fit).
    #[arg(long)]
    pub lbfgs_iterations: Option<u64>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
}

impl SearchArgs {
    /// The settings as a library request (checked by [`Search::validate`]: `--particles` below
    /// 2 and `--threads 0` are usage errors, exit 2).
    pub fn request(&self) -> Search {
        Search {
            seed: self.seed,
            particles: self.particles,
            pso_iterations: self.pso_iterations,
            lbfgs_iterations: self.lbfgs_iterations,
            threads: self.threads,
        }
    }

    /// A worker pool of its own with `--threads` workers (all cores by default), so that the
    /// option holds on every call, also in-process. `--threads 0` is a usage error (exit 2).
    pub fn pool(&self) -> Result<rayon::ThreadPool, CliError> {
        self.request().validate()?;
        let threads = self.threads.unwrap_or_else(rayon::current_num_threads);
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .map_err(|e| CliError::new(6, format!("cannot start {threads} worker threads: {e}")))
    }
}
