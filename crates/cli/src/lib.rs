//! The `itaipu-calib` command line. `main.rs` only calls [`run`]; tests call it in-process.
//!
//! This file holds the clap definition and the dispatch only: one module per command
//! (`simulate_cmd`, `fit_cmd`, `diagnose_cmd`, `synth_cmd`, `import_cmd`, `dyr_cmd`,
//! `models_cmd`, `diagram_cmd`), reading inputs in [`inputs`], output folders in [`output`],
//! reports in [`report`], and every library error mapped to its exit code once, in [`error`].
//! Options are checked by the library's request layer (`itaipu_calib::request`), shared with
//! the Python module.
//!
//! Exit codes (also in `--help`): 0 success, 2 usage error, 3 bad event data (event TOML or
//! CSV), 4 bad unit model, 5 the model cannot initialise at the measured operating point,
//! 6 the simulation failed, 7 output could not be written (or would overwrite), 130/143 a fit
//! interrupted by SIGINT/SIGTERM (partial folder kept; `--resume` goes on).

// Checks are written `!(x > 0.0)` on purpose: that form also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use std::ffi::OsString;

use clap::{CommandFactory, Parser, Subcommand};

pub mod diagnose_cmd;
pub mod diagram_cmd;
pub mod dyr_cmd;
pub mod error;
pub mod fit_cmd;
pub mod import_cmd;
pub mod inputs;
pub mod models_cmd;
pub mod options_doc;
pub mod output;
pub mod report;
pub mod search;
pub mod simulate_cmd;
pub mod synth_cmd;

pub use error::{explain_sim_error, CliError};
pub use inputs::{bundled, load_event, load_unit, plausibility, write_warnings};
pub use output::{check_out, looks_like_output, prepare_out, OUTPUT_MARKERS};
pub use search::SearchArgs;
pub use simulate_cmd::{misfit, RK4_MAX_STEPS};

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
    Simulate(simulate_cmd::SimulateArgs),
    #[command(about = fit_about(), long_about = fit_about())]
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
        /// Print the library as the Markdown table of docs/model-library.md (model, role,
        /// standard, `.dyr` record, roles) instead.
        #[arg(long)]
        table: bool,
    },
    /// Draw a user-defined diagram as Graphviz dot text (render with `dot -Tsvg`), to check
    /// the wiring. FILE is a diagram definition or a unit file (every diagram block in it, or
    /// the one named by --block).
    Diagram(diagram_cmd::DiagramArgs),
}

/// The command line's definition (every command and option), for the option reference and the
/// documentation's tests.
pub fn command() -> clap::Command {
    Cli::command()
}

/// `fit`'s help: the search method in the library's words ([`itaipu_calib::spec::SEARCH_METHOD`]).
fn fit_about() -> String {
    format!(
        "Calibrate a unit model against one or more events, stage by stage (generator, AVR, PSS, \
         governor), each by {}. With no arguments: the bundled Itaipu record, unit and \
         calibration spec (RaPId's problem).",
        itaipu_calib::spec::SEARCH_METHOD
    )
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
        Cmd::Simulate(a) => simulate_cmd::cmd_simulate(&a),
        Cmd::Models { name, table } => models_cmd::cmd_models(name.as_deref(), table),
        Cmd::Diagram(a) => diagram_cmd::cmd_diagram(&a),
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
