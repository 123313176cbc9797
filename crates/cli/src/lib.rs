//! The `itaipu-calib` command line. `main.rs` only calls [`run`]; tests call it in-process.
//!
//! Exit codes (also in `--help`): 0 success, 2 usage error, 3 bad event data (event TOML or
//! CSV), 4 bad unit model, 5 the model cannot initialise at the measured operating point,
//! 6 the simulation failed, 7 output could not be written (or would overwrite), 130/143 a fit
//! interrupted by SIGINT/SIGTERM (partial folder kept; `--resume` goes on).

// Checks are written `!(x > 0.0)` on purpose: that form also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::{Parser, Subcommand, ValueEnum};
use itaipu_dynamics::event::Event;
use itaipu_dynamics::integrate::{Dopri5Options, Method};
use itaipu_dynamics::plausibility::{self, Finding, Severity};
use itaipu_dynamics::registry;
use itaipu_dynamics::simulate::{simulate, SimError, SimOptions, Traces};
use itaipu_dynamics::unit::Unit;
use itaipu_dynamics::unit_file::read_unit;

use report::svg as plot;

pub mod diagnose_cmd;
pub mod dyr_cmd;
pub mod fit_cmd;
pub mod import_cmd;
pub mod output;
pub mod report;
pub mod synth_cmd;

pub const EXIT_CODES: &str =
    "Exit codes: 0 success, 2 usage error, 3 bad event data (event TOML or CSV), \
4 bad unit model or calibration spec, 5 model cannot initialise at the measured operating point, \
6 simulation or fit failed, 7 output could not be written (or would overwrite an existing folder), \
130/143 fit interrupted by SIGINT/SIGTERM (finished stages kept in a folder marked by partial.json; \
rerun with --resume). A complete output folder holds manifest.json (written last).";

#[derive(Parser, Debug)]
#[command(
    name = "itaipu-calib",
    version,
    about = "Play back PMU recordings into generating-unit models, calibrate and diagnose them",
    after_help = EXIT_CODES
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Play the measured terminal voltage of an event into a unit model and compare simulated
    /// P and Q with the measured ones. With no arguments: the bundled Itaipu event and unit.
    #[command(after_help = EXIT_CODES)]
    Simulate(SimulateArgs),
    /// Calibrate a unit model against one or more events, stage by stage (generator, AVR, PSS,
    /// governor), each by a particle swarm then L-BFGS. With no arguments: the bundled Itaipu
    /// record, unit and calibration spec (RaPId's problem).
    Fit(fit_cmd::FitArgs),
    /// Diagnose what a (calibrated) unit still gets wrong on events: residual evidence, each
    /// cause of the catalog tried as a model extension and re-fitted, the gain judged by ΔBIC
    /// and on held-out data, a verdict, the extended unit, plots and an HTML report. With no
    /// arguments: the bundled Itaipu record and unit.
    Diagnose(diagnose_cmd::DiagnoseArgs),
    /// Make a realistic synthetic event from the engine: a fault dip, frequency excursion,
    /// voltage step or ambient record played into a true unit, PMU sampling, noise and
    /// quantisation, optionally a hidden effect; writes the event, its CSV and the truth.
    Synth(synth_cmd::SynthArgs),
    /// Import a PMU recording (C37.118-style CSV, COMTRADE .cfg/.dat) into an event folder:
    /// P and Q from the voltage and current phasors with named bases, gaps and dropouts
    /// reported.
    #[command(after_help = EXIT_CODES)]
    Import(import_cmd::ImportArgs),
    /// Read a unit from a PSS/E .dyr into a unit file, or write a unit file as .dyr.
    #[command(after_help = EXIT_CODES)]
    Dyr(dyr_cmd::DyrArgs),
    /// List the model library: models, their parameters (name, PSS/E alias, unit, meaning,
    /// typical value and range) and ports, then the primitives of user-defined diagrams.
    Models {
        /// Show one model only (e.g. GENSAE), or `diagram` for the diagram primitives.
        name: Option<String>,
    },
    /// Draw a user-defined diagram as Graphviz dot text (render with `dot -Tsvg`), to check
    /// the wiring. FILE is a diagram definition or a unit file (every diagram block in it, or
    /// the one named by --block).
    Diagram(DiagramArgs),
}

#[derive(clap::Args, Debug)]
struct DiagramArgs {
    /// A diagram definition (TOML with [[block]] entries) or a unit file.
    file: PathBuf,
    /// In a unit file: the block (section) to draw, e.g. exciter.
    #[arg(long)]
    block: Option<String>,
    /// Write the dot text here instead of the standard output.
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
}

#[derive(clap::Args, Debug)]
struct SimulateArgs {
    /// Event file (TOML naming the CSV, system base, nominal frequency and windows).
    /// Default: the bundled Itaipu record, data/itaipu/event.toml.
    #[arg(long, value_name = "FILE")]
    event: Option<PathBuf>,
    /// Unit model file (TOML). Default: the bundled Itaipu unit, data/itaipu/unit.toml.
    #[arg(long, value_name = "FILE")]
    unit: Option<PathBuf>,
    /// Output folder for traces.csv and plot.svg. Default: out/simulate-<event>, or a new
    /// numbered folder beside it if that exists. An existing --out folder is never overwritten
    /// unless --force is given.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Allow writing into an existing, non-empty --out folder.
    #[arg(long)]
    force: bool,
    /// Integrator.
    #[arg(long, value_enum, default_value_t = MethodArg::Dopri5)]
    method: MethodArg,
    /// RK4 step [s] (with --method rk4).
    #[arg(long, default_value_t = 0.001, value_name = "SECONDS")]
    step: f64,
    /// Relative tolerance (with --method dopri5).
    #[arg(long, default_value_t = 1e-6)]
    rtol: f64,
    /// Absolute tolerance (with --method dopri5).
    #[arg(long, default_value_t = 1e-7)]
    atol: f64,
    /// Do not draw plot.svg.
    #[arg(long)]
    no_plot: bool,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
enum MethodArg {
    /// Adaptive Dormand-Prince 5(4) with event location.
    Dopri5,
    /// Fixed-step classical Runge-Kutta 4.
    Rk4,
}

/// An error with its exit code.
#[derive(Debug)]
pub struct CliError {
    pub code: u8,
    pub msg: String,
}

impl CliError {
    pub fn new(code: u8, msg: impl Into<String>) -> Self {
        Self {
            code,
            msg: msg.into(),
        }
    }
}

impl From<SimError> for CliError {
    fn from(e: SimError) -> Self {
        let code = match e {
            SimError::Init(_) | SimError::Frequency { .. } => 5,
            SimError::Solve(_) => 6,
        };
        CliError::new(code, e.to_string())
    }
}

/// Parses `args` (including the program name) and runs the command; returns the exit code.
pub fn run<I, T>(args: I) -> u8
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let args: Vec<OsString> = args.into_iter().map(Into::into).collect();
    output::set_command(
        args.iter()
            .map(|a| a.to_string_lossy().into_owned())
            .collect(),
    );
    let cli = match Cli::try_parse_from(args) {
        Ok(c) => c,
        Err(e) => {
            let code = if e.use_stderr() { 2 } else { 0 };
            let _ = e.print();
            return code;
        }
    };
    if !matches!(cli.cmd, Cmd::Fit(_) | Cmd::Models { .. }) {
        output::remove_partial_on_signal();
    }
    let result = match cli.cmd {
        Cmd::Simulate(a) => cmd_simulate(&a),
        Cmd::Models { name } => cmd_models(name.as_deref()),
        Cmd::Diagram(a) => cmd_diagram(&a),
        Cmd::Fit(a) => fit_cmd::cmd_fit(&a),
        Cmd::Diagnose(a) => diagnose_cmd::cmd_diagnose(&a),
        Cmd::Synth(a) => synth_cmd::cmd_synth(&a),
        Cmd::Import(a) => import_cmd::cmd_import(&a),
        Cmd::Dyr(a) => dyr_cmd::cmd_dyr(&a),
    };
    match result {
        Ok(()) => 0,
        Err(e) => {
            eprintln!("error: {}", e.msg);
            e.code
        }
    }
}

/// Locates a bundled data file: `./data/…`, then next to the executable's repository
/// (`target/<profile>/../../data/…`), then `$ITAIPU_CALIB_DATA/…`.
pub fn bundled(rel: &str) -> Result<PathBuf, CliError> {
    let mut candidates = vec![PathBuf::from("data").join(rel)];
    if let Ok(exe) = std::env::current_exe() {
        if let Some(dir) = exe.parent() {
            candidates.push(dir.join("../../data").join(rel));
            candidates.push(dir.join("../data").join(rel));
        }
    }
    if let Some(d) = std::env::var_os("ITAIPU_CALIB_DATA") {
        candidates.push(PathBuf::from(d).join(rel));
    }
    candidates.iter().find(|p| p.is_file()).cloned().ok_or_else(|| {
        CliError::new(3, format!("bundled data file data/{rel} not found (run from the repository root, or set ITAIPU_CALIB_DATA)"))
    })
}

/// Reads an event file (exit code 3 on error).
pub fn load_event(path: &Path) -> Result<Event, CliError> {
    Event::from_toml_file(path).map_err(|e| CliError::new(3, e.to_string()))
}

/// Reads a unit file (exit code 4 on error). A `.dyr` is read with the bases of
/// `<stem>.bases.toml` beside it (its warnings printed).
pub fn load_unit(path: &Path) -> Result<Unit, CliError> {
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("dyr"))
    {
        let d = dyr_cmd::load_dyr(path, None, None, &dyr_cmd::BasesArgs::default())?;
        for w in &d.warnings {
            eprintln!("warning: {w}");
        }
        return Ok(d.unit);
    }
    read_unit(path).map_err(|e| CliError::new(4, e.to_string()))
}

/// The plausibility layer ([`itaipu_dynamics::plausibility`]) on events (against the unit's
/// rating) and on the unit's parameters: an error stops the run (exit 3, every error listed
/// with file, line, column and fix); warnings are printed and returned, for the outputs.
pub fn plausibility(
    events: &[&Event],
    unit: &Unit,
    unit_path: &Path,
) -> Result<Vec<Finding>, CliError> {
    let mut all = vec![];
    for e in events {
        all.extend(plausibility::check_event(e, Some(unit.machine_mva)));
    }
    all.extend(plausibility::check_unit(unit, unit_path));
    let errors: Vec<String> = all
        .iter()
        .filter(|f| f.severity == Severity::Error)
        .map(|f| f.to_string())
        .collect();
    if !errors.is_empty() {
        return Err(CliError::new(
            3,
            format!("implausible data:\n  {}", errors.join("\n  ")),
        ));
    }
    for f in &all {
        eprintln!("warning: {f}");
    }
    Ok(all)
}

/// Writes `warnings.json` into `dir` when there are warnings.
pub fn write_warnings(dir: &Path, warnings: &[Finding]) -> Result<(), CliError> {
    if warnings.is_empty() {
        return Ok(());
    }
    let text =
        serde_json::to_string_pretty(warnings).map_err(|e| CliError::new(7, e.to_string()))?;
    output::write_synced(&dir.join("warnings.json"), text.as_bytes())
}

/// Largest number of fixed RK4 steps a playback may take (`--step` too small for the record
/// is refused rather than run for hours).
pub const RK4_MAX_STEPS: f64 = 1e7;

/// A simulation error traced back to the data: an integration failure at time t names the
/// samples around t, an initialisation failure the operating point it was given.
pub fn explain_sim_error(e: SimError, event: &Event, unit: &Unit) -> CliError {
    use itaipu_dynamics::integrate::SolveError;
    let mut err = CliError::from(e.clone());
    let t = match &e {
        SimError::Solve(
            SolveError::NonFinite { t, .. }
            | SolveError::StepUnderflow { t, .. }
            | SolveError::TooManySteps { t, .. }
            | SolveError::EventLoop { t },
        ) => Some(*t),
        _ => None,
    };
    match (&e, t) {
        (_, Some(t)) => {
            err.msg = format!("{}; {}", err.msg, plausibility::locate_time(event, t));
        }
        (SimError::Init(_), None) => {
            err.msg = format!(
                "{}; {}",
                err.msg,
                plausibility::describe_operating_point(event, unit.machine_mva)
            );
        }
        _ => {}
    }
    err
}

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
    /// Overrides the given search settings with the options given on the command line.
    /// `--particles` below 2 is a usage error (exit 2; it used to become 2 in silence).
    pub fn apply(
        &self,
        seed: &mut u64,
        particles: &mut usize,
        pso: &mut usize,
        lbfgs: &mut u64,
    ) -> Result<(), CliError> {
        if let Some(s) = self.seed {
            *seed = s;
        }
        if let Some(n) = self.particles {
            if n < 2 {
                return Err(CliError::new(
                    2,
                    format!("--particles {n}: a swarm needs at least 2 particles"),
                ));
            }
            *particles = n;
        }
        if let Some(n) = self.pso_iterations {
            *pso = n;
        }
        if let Some(n) = self.lbfgs_iterations {
            *lbfgs = n;
        }
        Ok(())
    }

    /// A worker pool of its own with `--threads` workers (all cores by default), so that the
    /// option holds on every call, also in-process. `--threads 0` is a usage error (exit 2).
    pub fn pool(&self) -> Result<rayon::ThreadPool, CliError> {
        let threads = match self.threads {
            Some(0) => return Err(CliError::new(2, "--threads must be at least 1")),
            Some(t) => t,
            None => rayon::current_num_threads(),
        };
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .map_err(|e| CliError::new(6, format!("cannot start {threads} worker threads: {e}")))
    }
}

/// Refuses an explicit `--out` that is not a folder, a non-empty folder without `force`, and
/// with `force` a non-empty folder that is not an output of this tool (exit 7). Called before a
/// long run, so that it fails before the work, not after.
pub fn check_out(out: Option<&Path>, force: bool) -> Result<(), CliError> {
    let Some(d) = out else {
        return Ok(());
    };
    if d.exists() && !d.is_dir() {
        return Err(CliError::new(
            7,
            format!("{} exists and is not a folder", d.display()),
        ));
    }
    let nonempty = d.is_dir()
        && std::fs::read_dir(d)
            .map(|mut r| r.next().is_some())
            .unwrap_or(false);
    if nonempty && !force {
        return Err(CliError::new(
            7,
            format!(
                "{} exists and is not empty; refusing to overwrite (use --force, or another --out)",
                d.display()
            ),
        ));
    }
    if nonempty && !looks_like_output(d) {
        return Err(CliError::new(
            7,
            format!(
                "{} is not an output folder of itaipu-calib (none of {}); --force replaces a folder whole, so it only replaces one of ours: give another --out, or empty the folder first",
                d.display(),
                OUTPUT_MARKERS.join(", ")
            ),
        ));
    }
    if nonempty {
        let foreign = foreign_files(d);
        if !foreign.is_empty() {
            let shown: Vec<&str> = foreign.iter().take(5).map(String::as_str).collect();
            return Err(CliError::new(
                7,
                format!(
                    "{} holds {} file(s) that its manifest.json does not list ({}{}): --force replaces the folder whole and would delete them; move them out first, or give another --out",
                    d.display(),
                    foreign.len(),
                    shown.join(", "),
                    if foreign.len() > 5 { ", ..." } else { "" }
                ),
            ));
        }
    }
    Ok(())
}

/// Files of a complete output folder that its manifest does not list (put there after the
/// run); empty when there is no readable manifest.
fn foreign_files(dir: &Path) -> Vec<String> {
    let Ok(text) = std::fs::read_to_string(dir.join(output::MANIFEST)) else {
        return vec![];
    };
    let Ok(m) = serde_json::from_str::<output::Manifest>(&text) else {
        return vec![];
    };
    let Ok(now) = output::list_files(dir) else {
        return vec![];
    };
    now.into_iter()
        .map(|f| f.path)
        .filter(|p| p != output::MANIFEST && !m.files.iter().any(|f| &f.path == p))
        .collect()
}

/// Files at the top of a folder that mark it as an output of this tool (the manifest, the
/// partial marker, and the main result of each command, as written before manifests existed).
pub const OUTPUT_MARKERS: &[&str] = &[
    output::MANIFEST,
    output::PARTIAL,
    "report.json",
    "traces.csv",
    "diagnosis.json",
    "truth.json",
];

/// Whether `--force` may replace `dir` whole: it holds one of [`OUTPUT_MARKERS`]. A folder of
/// the user's own (say the one holding the event files) is never deleted by a mistyped `--out`.
pub fn looks_like_output(dir: &Path) -> bool {
    OUTPUT_MARKERS.iter().any(|m| dir.join(m).is_file())
}

/// Chooses the output folder and starts writing it ([`output::Staging`]: a temporary folder
/// beside it, renamed into place when complete). With an explicit `--out`, an existing
/// non-empty folder is refused unless `force` ([`check_out`]), and then replaced whole; by
/// default `out/<name>` or the first free `out/<name>-N`. Call it before the computation: it
/// is the writability check.
pub fn prepare_out(
    out: Option<&Path>,
    name: &str,
    force: bool,
) -> Result<output::Staging, CliError> {
    check_out(out, force)?;
    let dir = match out {
        Some(d) => d.to_path_buf(),
        None => {
            let base = PathBuf::from("out").join(name);
            let mut d = base.clone();
            let mut k = 2;
            while d.exists() {
                d = PathBuf::from(format!("{}-{k}", base.display()));
                k += 1;
            }
            d
        }
    };
    output::Staging::begin(&dir)
}

fn sim_options(a: &SimulateArgs) -> Result<SimOptions, CliError> {
    let method = match a.method {
        MethodArg::Rk4 => {
            if !(a.step > 0.0 && a.step.is_finite()) {
                return Err(CliError::new(
                    2,
                    format!("--step must be > 0 (got {})", a.step),
                ));
            }
            Method::Rk4 { h: a.step }
        }
        MethodArg::Dopri5 => {
            if !(a.rtol > 0.0 && a.atol >= 0.0) {
                return Err(CliError::new(2, "--rtol must be > 0 and --atol >= 0"));
            }
            Method::Dopri5(Dopri5Options {
                rtol: a.rtol,
                atol: a.atol,
                h_max: 0.05,
                ..Default::default()
            })
        }
    };
    Ok(SimOptions { method })
}

/// Sum over the fit-window samples of squared P and Q errors (paper 000 eq. 3, RaPId's J),
/// and the RMS errors of P and Q, all on the system base.
pub fn misfit(event: &Event, traces: &Traces) -> (f64, f64, f64, usize) {
    let (p, q) = (traces.get("p_pu").unwrap(), traces.get("q_pu").unwrap());
    let r = &event.record;
    let (mut sp, mut sq, mut n) = (0.0, 0.0, 0usize);
    for k in 0..r.time_s.len() {
        let t = r.time_s[k];
        if t >= event.fit.start_s - 1e-9 && t <= event.fit.end_s + 1e-9 {
            sp += (p[k] - r.p_pu[k]).powi(2);
            sq += (q[k] - r.q_pu[k]).powi(2);
            n += 1;
        }
    }
    let nn = n.max(1) as f64;
    (sp + sq, (sp / nn).sqrt(), (sq / nn).sqrt(), n)
}

fn describe_unit(u: &Unit) -> String {
    u.instances()
        .iter()
        .map(|i| i.block.model())
        .collect::<Vec<_>>()
        .join(" + ")
}

fn cmd_simulate(a: &SimulateArgs) -> Result<(), CliError> {
    let event_path = match &a.event {
        Some(p) => p.clone(),
        None => bundled("itaipu/event.toml")?,
    };
    let unit_path = match &a.unit {
        Some(p) => p.clone(),
        None => bundled("itaipu/unit.toml")?,
    };
    let opts = sim_options(a)?;
    let event = load_event(&event_path)?;
    let unit = load_unit(&unit_path)?;
    if let Method::Rk4 { h } = opts.method {
        let steps = event.playback.duration_s() / h;
        if steps > RK4_MAX_STEPS {
            return Err(CliError::new(
                2,
                format!(
                    "--step {h}: {steps:.3e} RK4 steps over the {:.3} s playback of {}; the cap is {RK4_MAX_STEPS:e} (use --step {:.1e} or larger, or --method dopri5)",
                    event.playback.duration_s(),
                    event_path.display(),
                    event.playback.duration_s() / RK4_MAX_STEPS
                ),
            ));
        }
    }
    let warnings = plausibility(&[&event], &unit, &unit_path)?;
    let staging = prepare_out(
        a.out.as_deref(),
        &format!("simulate-{}", event.name),
        a.force,
    )?;
    let out = staging.path().to_path_buf();
    let t0 = Instant::now();
    let traces = simulate(&unit, &event, &opts).map_err(|e| explain_sim_error(e, &event, &unit))?;
    let wall = t0.elapsed();
    let csv_path = out.join("traces.csv");
    traces
        .write_csv(&csv_path)
        .map_err(|e| CliError::new(7, format!("cannot write {}: {e}", csv_path.display())))?;

    let op = event.operating_point();
    let r = &event.record;
    let (j, rms_p, rms_q, n_fit) = misfit(&event, &traces);
    let col = |n: &str| traces.get(n).map(|c| c[0]).unwrap_or(f64::NAN);
    println!(
        "event  {} ({}): {} samples, {:.3}-{:.3} s, system base {} MVA, {} Hz",
        event.name,
        event_path.display(),
        r.time_s.len(),
        r.time_s[0],
        r.time_s[r.time_s.len() - 1],
        event.system_mva,
        event.nominal_hz
    );
    println!(
        "unit   {} ({}): {}, machine base {} MVA",
        unit.name,
        unit_path.display(),
        describe_unit(&unit),
        unit.machine_mva
    );
    println!(
        "init   from {:.2}-{:.2} s: |V| {:.5} pu, P {:.5} pu, Q {:.5} pu (system base), f {:.4} Hz; E_fd0 {:.4} pu, δ0 {:.2}°, P_m0 {:.4} pu (machine base)",
        event.init.start_s,
        event.init.end_s,
        op.v_mag_pu,
        op.p_pu,
        op.q_pu,
        op.freq_hz,
        col("efd"),
        col("delta").to_degrees(),
        col("pm")
    );
    let s = traces.stats;
    println!(
        "run    {}: {} steps ({} rejected), {} RHS evaluations, {} limiter events, {:.2} ms",
        opts.method,
        s.steps_accepted,
        s.steps_rejected,
        s.rhs_evals,
        s.events,
        wall.as_secs_f64() * 1e3
    );
    println!(
        "misfit fit window {:.2}-{:.2} s ({n_fit} samples): RMS P {rms_p:.4} pu, RMS Q {rms_q:.4} pu, J = sum(dP^2 + dQ^2) = {j:.4}",
        event.fit.start_s, event.fit.end_s
    );
    let mut written = vec!["traces.csv".to_string()];
    if !a.no_plot {
        let plot_path = out.join("plot.svg");
        let t = &traces.time_s;
        let get = |n: &str| traces.get(n).unwrap();
        let panels = vec![
            plot::Panel {
                y_label: "|V| [pu] (played back)".into(),
                series: vec![plot::Series {
                    label: "measured |V|".into(),
                    x: t,
                    y: get("v_term"),
                    color: plot::MEASURED,
                    thin: false,
                }],
            },
            plot::Panel {
                y_label: format!("P [pu on {} MVA]", event.system_mva),
                series: vec![
                    plot::Series {
                        label: "measured".into(),
                        x: t,
                        y: get("p_meas_pu"),
                        color: plot::MEASURED,
                        thin: true,
                    },
                    plot::Series {
                        label: "simulated".into(),
                        x: t,
                        y: get("p_pu"),
                        color: plot::SIMULATED,
                        thin: false,
                    },
                ],
            },
            plot::Panel {
                y_label: format!("Q [pu on {} MVA]", event.system_mva),
                series: vec![
                    plot::Series {
                        label: "measured".into(),
                        x: t,
                        y: get("q_meas_pu"),
                        color: plot::MEASURED,
                        thin: true,
                    },
                    plot::Series {
                        label: "simulated".into(),
                        x: t,
                        y: get("q_pu"),
                        color: plot::SIMULATED,
                        thin: false,
                    },
                ],
            },
        ];
        let title = format!("{}: {} playback, J = {j:.3}", event.name, unit.name);
        plot::draw(&plot_path, &title, "time [s]", &panels).map_err(|e| CliError::new(7, e))?;
        written.push("plot.svg".to_string());
    }
    write_warnings(&out, &warnings)?;
    if !warnings.is_empty() {
        written.push("warnings.json".to_string());
    }
    let target = staging.commit(None)?;
    written.push(output::MANIFEST.to_string());
    println!("wrote  {}/{{{}}}", target.display(), written.join(", "));
    Ok(())
}

/// `itaipu-calib diagram`: the dot text of a diagram file or of a unit's diagram blocks.
fn cmd_diagram(a: &DiagramArgs) -> Result<(), CliError> {
    use itaipu_dynamics::unit_file::{read_diagram_or_unit, DiagramFile};
    let mut dots = vec![];
    match read_diagram_or_unit(&a.file).map_err(|e| CliError::new(4, e.to_string()))? {
        DiagramFile::Unit(unit) => {
            for inst in unit.instances() {
                if a.block.as_deref().is_some_and(|b| b != inst.name) {
                    continue;
                }
                if let Some(d) = inst.block.diagram() {
                    dots.push(d.to_dot().replacen(
                        "digraph diagram",
                        &format!("digraph {}", inst.name),
                        1,
                    ));
                }
            }
            if dots.is_empty() {
                return Err(CliError::new(
                    2,
                    match &a.block {
                        Some(b) => format!("{}: no diagram block named '{b}'", a.file.display()),
                        None => format!("{}: the unit has no diagram block", a.file.display()),
                    },
                ));
            }
        }
        DiagramFile::Definition(d) => dots.push(d.to_dot()),
    }
    let out = dots.join("\n");
    match &a.out {
        Some(p) => {
            std::fs::write(p, out).map_err(|e| CliError::new(7, format!("{}: {e}", p.display())))?
        }
        None => print!("{out}"),
    }
    Ok(())
}

fn cmd_models(name: Option<&str>) -> Result<(), CliError> {
    if name.is_some_and(|n| n.eq_ignore_ascii_case("diagram")) {
        print!("{}", itaipu_dynamics::diagram::describe_primitives());
        return Ok(());
    }
    let models: Vec<_> = match name {
        Some(n) => vec![registry::find(n).ok_or_else(|| {
            CliError::new(
                2,
                format!(
                    "unknown model '{n}' (known: {}, diagram)",
                    registry::names()
                ),
            )
        })?],
        None => registry::MODELS.iter().collect(),
    };
    for m in models {
        let b = m.create();
        println!("{} [{}]: {}", m.name, m.role.section(), m.summary);
        println!("  states: {}", b.state_names().join(", "));
        let ports: Vec<String> = b
            .ports()
            .iter()
            .map(|p| {
                format!(
                    "{}{}",
                    p.name,
                    if p.dir == itaipu_dynamics::block::Dir::In {
                        "(in)"
                    } else {
                        "(out)"
                    }
                )
            })
            .collect();
        println!("  ports:  {}", ports.join(", "));
        for s in b.params().specs() {
            println!(
                "  {:<14} {:<8} {:>6}  typical {:<8} range {:>7}-{:<7} {}",
                s.name, s.alias, s.unit, s.typical, s.range.0, s.range.1, s.doc
            );
        }
        println!();
    }
    if name.is_none() {
        print!("{}", itaipu_dynamics::diagram::describe_primitives());
    }
    Ok(())
}
