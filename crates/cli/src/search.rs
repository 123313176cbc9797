//! Swarm, local-method and thread options shared by `fit` and `diagnose`: their help text and
//! defaults come from the library ([`itaipu_calib::options::search_help`]).

use itaipu_calib::options::search_help;
use itaipu_calib::request::Search;

use crate::CliError;

/// Swarm, local-method and thread options shared by `fit` and `diagnose`.
#[derive(clap::Args, Debug)]
pub struct SearchArgs {
    #[arg(long, help = search_help("seed"))]
    pub seed: Option<u64>,
    #[arg(long, help = search_help("particles"))]
    pub particles: Option<usize>,
    #[arg(long, help = search_help("pso_iterations"))]
    pub pso_iterations: Option<usize>,
    /// (`--lbfgs-iterations`, the old spelling, is an alias: it caps Levenberg-Marquardt too.)
    #[arg(long, alias = "lbfgs-iterations", help = search_help("local_iterations"))]
    pub local_iterations: Option<u64>,
    #[arg(long, help = search_help("threads"))]
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
            local_iterations: self.local_iterations,
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
