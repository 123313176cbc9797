//! The `itaipu-calib` command line. `main.rs` only calls [`run`]; tests call it in-process.
//!
//! Exit codes (also in `--help`): 0 success, 2 usage error, 3 bad event data (event TOML or
//! CSV), 4 bad unit model, 5 the model cannot initialise at the measured operating point,
//! 6 the simulation failed, 7 output could not be written (or would overwrite).

// Checks are written `!(x > 0.0)` on purpose: that form also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::{Parser, Subcommand, ValueEnum};
use itaipu_dynamics::event::Event;
use itaipu_dynamics::integrate::{Dopri5Options, Method};
use itaipu_dynamics::registry;
use itaipu_dynamics::simulate::{simulate, SimError, SimOptions, Traces};
use itaipu_dynamics::unit::Unit;
use itaipu_dynamics::unit_file::read_unit;

pub mod diagnose_cmd;
pub mod dyr_cmd;
pub mod fit_cmd;
pub mod import_cmd;
pub mod plot;
pub mod synth_cmd;

pub const EXIT_CODES: &str =
    "Exit codes: 0 success, 2 usage error, 3 bad event data (event TOML or CSV), \
4 bad unit model or calibration spec, 5 model cannot initialise at the measured operating point, \
6 simulation or fit failed, 7 output could not be written (or would overwrite an existing folder).";

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
    /// typical value and range) and ports.
    Models {
        /// Show one model only (e.g. GENSAE).
        name: Option<String>,
    },
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
    let cli = match Cli::try_parse_from(args) {
        Ok(c) => c,
        Err(e) => {
            let code = if e.use_stderr() { 2 } else { 0 };
            let _ = e.print();
            return code;
        }
    };
    let result = match cli.cmd {
        Cmd::Simulate(a) => cmd_simulate(&a),
        Cmd::Models { name } => cmd_models(name.as_deref()),
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
    pub fn apply(&self, seed: &mut u64, particles: &mut usize, pso: &mut usize, lbfgs: &mut u64) {
        if let Some(s) = self.seed {
            *seed = s;
        }
        if let Some(n) = self.particles {
            *particles = n.max(2);
        }
        if let Some(n) = self.pso_iterations {
            *pso = n;
        }
        if let Some(n) = self.lbfgs_iterations {
            *lbfgs = n;
        }
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

/// Refuses an explicit `--out` that is not a folder, or a non-empty folder without `force`
/// (exit 7). Called before a long run, so that it fails before the work, not after.
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
    Ok(())
}

/// Chooses and creates the output folder. With an explicit `--out`, an existing non-empty
/// folder is refused unless `force` ([`check_out`]); by default `out/<name>` or the first free
/// `out/<name>-N`.
pub fn prepare_out(out: Option<&Path>, name: &str, force: bool) -> Result<PathBuf, CliError> {
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
    std::fs::create_dir_all(&dir)
        .map_err(|e| CliError::new(7, format!("cannot create {}: {e}", dir.display())))?;
    Ok(dir)
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
    let t0 = Instant::now();
    let traces = simulate(&unit, &event, &opts)?;
    let wall = t0.elapsed();
    let out = prepare_out(
        a.out.as_deref(),
        &format!("simulate-{}", event.name),
        a.force,
    )?;
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
    let mut written = vec![csv_path.display().to_string()];
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
        written.push(plot_path.display().to_string());
    }
    println!("wrote  {}", written.join(", "));
    Ok(())
}

fn cmd_models(name: Option<&str>) -> Result<(), CliError> {
    let models: Vec<_> = match name {
        Some(n) => vec![registry::find(n).ok_or_else(|| {
            CliError::new(
                2,
                format!("unknown model '{n}' (known: {})", registry::names()),
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
    Ok(())
}
