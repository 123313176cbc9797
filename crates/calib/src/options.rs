//! The user's options of `simulate`, `fit`, `diagnose` and `synth`, declared once: each
//! option's spelling on the command line and in Python, its default and its help. The command
//! line (clap) takes its help texts and defaults from [`OPTIONS`] and the typed defaults below,
//! the Python module its defaults (and `itaipu_calib.options()` returns the table), and the
//! option reference `docs/options.md` is rendered from it (a test fails when that file is not
//! current). The checks of the values live in [`crate::request`].
//!
//! Options only one front end has (the command line's `--out`, `--force`, input files; Python's
//! `return_truth`) are declared by that front end.

use crate::request::{SearchDefaults, Style, DIAGNOSE_SEARCH, FIT_SEARCH};

/// A command both front ends have.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    Simulate,
    Fit,
    Diagnose,
    Synth,
}

impl Command {
    /// Every command, in the reference's order.
    pub const ALL: [Command; 4] = [
        Command::Simulate,
        Command::Fit,
        Command::Diagnose,
        Command::Synth,
    ];

    /// The command's name (the command line's subcommand, the Python function).
    pub fn name(self) -> &'static str {
        match self {
            Command::Simulate => "simulate",
            Command::Fit => "fit",
            Command::Diagnose => "diagnose",
            Command::Synth => "synth",
        }
    }
}

/// The defaults of `simulate`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimulateDefaults {
    /// Integrator name (`itaipu_dynamics::integrate::Method`'s `FromStr`).
    pub method: &'static str,
    pub rtol: f64,
    pub atol: f64,
    /// RK4 step [s].
    pub step: f64,
    /// Playback mode name (`itaipu_dynamics::mode::PlaybackMode::NAMES`).
    pub mode: &'static str,
}

/// `simulate`'s defaults.
pub const SIMULATE: SimulateDefaults = SimulateDefaults {
    method: "dopri5",
    rtol: 1e-6,
    atol: 1e-7,
    step: 0.001,
    mode: "phasor",
};

/// The defaults of `synth`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SynthDefaults {
    /// Event kind name (`crate::request::SynthKind`'s `FromStr`).
    pub kind: &'static str,
    /// Record length [s].
    pub duration: f64,
    /// PMU reporting rate [samples/s].
    pub rate: f64,
    /// White noise on P and Q [pu].
    pub pq_sigma: f64,
    /// White noise on |V| [pu] and the angle [rad].
    pub v_sigma: f64,
    /// Quantisation step of P and Q [pu].
    pub quantum: f64,
    /// Delay of the power channels behind the voltage [ms].
    pub skew_ms: f64,
    pub seed: u64,
}

/// `synth`'s defaults: a 20 s fault dip at 60 samples/s with a PMU's noise (the P and Q quantum
/// is the bundled Itaipu record's).
pub const SYNTH: SynthDefaults = SynthDefaults {
    kind: "dip",
    duration: 20.0,
    rate: 60.0,
    pq_sigma: 0.002,
    v_sigma: 0.0005,
    quantum: 0.0014,
    skew_ms: 0.0,
    seed: 1,
};

/// A search setting whose default differs between `fit` and `diagnose` ([`FIT_SEARCH`],
/// [`DIAGNOSE_SEARCH`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SearchField {
    Seed,
    Particles,
    PsoIterations,
    LocalIterations,
}

impl SearchField {
    fn of(self, d: &SearchDefaults) -> u64 {
        match self {
            SearchField::Seed => d.seed,
            SearchField::Particles => d.particles as u64,
            SearchField::PsoIterations => d.pso_iterations as u64,
            SearchField::LocalIterations => d.local_iterations,
        }
    }
}

/// An option's default.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DefaultValue {
    /// A text both front ends use when the option is not given.
    Text(&'static str),
    /// A number both front ends use when the option is not given.
    Real(f64),
    /// An integer both front ends use when the option is not given.
    Int(u64),
    /// No value: the command decides (what it does is said here). Python's default is None.
    Unset(&'static str),
    /// A search setting: the spec's, else [`FIT_SEARCH`] (fit), or [`DIAGNOSE_SEARCH`]
    /// (diagnose). Python's default is None.
    Search(SearchField),
    /// A switch: the command line's flag (absent by default) turns off what Python's argument
    /// keeps on with its default (`Some(true)`, or None meaning on).
    Switch(Option<bool>),
}

/// One option of a command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OptionDecl {
    pub command: Command,
    /// The name the code looks the option up by (snake case).
    pub name: &'static str,
    /// The command line's long option, without `--` (None: Python only).
    pub cli: Option<&'static str>,
    /// Python's keyword argument (None: command line only).
    pub python: Option<&'static str>,
    pub default: DefaultValue,
    /// What it does. `{name}` (another option of the command) is spelled as the front end
    /// spells it ([`OptionDecl::help`]).
    pub help: &'static str,
}

impl OptionDecl {
    /// The help text with option names spelled in `style`: `{name}` names an option of the same
    /// command; braces around anything else (Python's `{param: value}`) are kept as written.
    pub fn help(&self, style: Style) -> String {
        let mut out = String::new();
        let mut rest = self.help;
        while let Some(open) = rest.find('{') {
            let Some(close) = rest[open..].find('}') else {
                break;
            };
            let name = &rest[open + 1..open + close];
            let declared = OPTIONS
                .iter()
                .any(|o| o.command == self.command && o.name == name);
            out.push_str(&rest[..open]);
            if declared {
                out.push_str(&spelling(self.command, name, style));
            } else {
                out.push_str(&rest[open..=open + close]);
            }
            rest = &rest[open + close + 1..];
        }
        out.push_str(rest);
        out
    }

    /// The default as the reference and `--help` describe it (None: a switch, off).
    pub fn default_text(&self) -> Option<String> {
        match self.default {
            DefaultValue::Text(t) => Some(t.to_string()),
            DefaultValue::Real(x) => Some(x.to_string()),
            DefaultValue::Int(n) => Some(n.to_string()),
            DefaultValue::Unset(what) => Some(what.to_string()),
            DefaultValue::Search(f) => Some(match self.command {
                Command::Diagnose => format!("{} (per candidate re-fit)", f.of(&DIAGNOSE_SEARCH)),
                _ => format!("the spec's, else {} (per stage)", f.of(&FIT_SEARCH)),
            }),
            DefaultValue::Switch(_) => None,
        }
    }
}

/// How the front end of `style` spells the declared option `name` of `command`.
fn spelling(command: Command, name: &str, style: Style) -> String {
    let decl = option(command, name);
    match (style, decl.cli, decl.python) {
        (Style::Cli, Some(c), _) => format!("--{c}"),
        (Style::Python, _, Some(p)) => p.to_string(),
        _ => style.option(name),
    }
}

/// The option `name` of `command`.
///
/// # Panics
/// If it is not declared: a front end names options that exist (checked by the tests).
pub fn option(command: Command, name: &str) -> &'static OptionDecl {
    OPTIONS
        .iter()
        .find(|o| o.command == command && o.name == name)
        .unwrap_or_else(|| panic!("option '{name}' of {} is not declared", command.name()))
}

/// The command line's help of option `name` of `command`: its text, then its default where
/// clap does not show one (an option without a value of its own).
pub fn cli_help(command: Command, name: &str) -> String {
    let o = option(command, name);
    let text = o.help(Style::Cli);
    match o.default {
        DefaultValue::Unset(_) | DefaultValue::Search(_) => {
            format!("{text} Default: {}.", o.default_text().unwrap_or_default())
        }
        _ => text,
    }
}

/// The help of a search option shared by `fit` and `diagnose` (the command line declares them
/// once for both): its text, then each command's default.
pub fn search_help(name: &str) -> String {
    let fit = option(Command::Fit, name);
    let text = fit.help(Style::Cli);
    match (fit.default, option(Command::Diagnose, name).default) {
        (DefaultValue::Search(f), DefaultValue::Search(_)) => format!(
            "{text} Default: fit, the spec's, else {} (per stage); diagnose, {} (per candidate \
             re-fit).",
            f.of(&FIT_SEARCH),
            f.of(&DIAGNOSE_SEARCH)
        ),
        _ => format!(
            "{text} Default: {}.",
            fit.default_text().unwrap_or_default()
        ),
    }
}

const SEED_HELP: &str =
    "Random seed of the swarms. Same seed, same numbers, on any number of threads.";
const PARTICLES_HELP: &str = "Swarm size (at least 2).";
const PSO_HELP: &str = "Maximum swarm iterations.";
const LOCAL_HELP: &str = "Maximum iterations of the local method after the swarm \
    (Levenberg-Marquardt steps, or L-BFGS iterations with `local = \"lbfgs\"` in the spec). The \
    old spelling `lbfgs_iterations` is still accepted.";
const THREADS_HELP: &str = "Worker threads (at least 1).";

/// The search settings of `command` (fit or diagnose).
macro_rules! search_options {
    ($command:expr) => {
        [
            OptionDecl {
                command: $command,
                name: "seed",
                cli: Some("seed"),
                python: Some("seed"),
                default: DefaultValue::Search(SearchField::Seed),
                help: SEED_HELP,
            },
            OptionDecl {
                command: $command,
                name: "particles",
                cli: Some("particles"),
                python: Some("particles"),
                default: DefaultValue::Search(SearchField::Particles),
                help: PARTICLES_HELP,
            },
            OptionDecl {
                command: $command,
                name: "pso_iterations",
                cli: Some("pso-iterations"),
                python: Some("pso_iterations"),
                default: DefaultValue::Search(SearchField::PsoIterations),
                help: PSO_HELP,
            },
            OptionDecl {
                command: $command,
                name: "local_iterations",
                cli: Some("local-iterations"),
                python: Some("local_iterations"),
                default: DefaultValue::Search(SearchField::LocalIterations),
                help: LOCAL_HELP,
            },
            OptionDecl {
                command: $command,
                name: "threads",
                cli: Some("threads"),
                python: Some("threads"),
                default: DefaultValue::Unset("all cores"),
                help: THREADS_HELP,
            },
        ]
    };
}

const FIT_SEARCH_OPTIONS: [OptionDecl; 5] = search_options!(Command::Fit);
const DIAGNOSE_SEARCH_OPTIONS: [OptionDecl; 5] = search_options!(Command::Diagnose);

/// An option both front ends spell as `name` (a single word).
const fn both(
    command: Command,
    name: &'static str,
    default: DefaultValue,
    help: &'static str,
) -> OptionDecl {
    OptionDecl {
        command,
        name,
        cli: Some(name),
        python: Some(name),
        default,
        help,
    }
}

const SIMULATE_OPTIONS: [OptionDecl; 5] = [
    both(
        Command::Simulate,
        "method",
        DefaultValue::Text(SIMULATE.method),
        "Integrator: dopri5 (adaptive Dormand-Prince 5(4) with event location, tolerances {rtol} \
         and {atol}) or rk4 (fixed-step classical Runge-Kutta 4, step {step}).",
    ),
    both(
        Command::Simulate,
        "step",
        DefaultValue::Real(SIMULATE.step),
        "RK4 step [s] (with {method} rk4).",
    ),
    both(
        Command::Simulate,
        "rtol",
        DefaultValue::Real(SIMULATE.rtol),
        "Relative tolerance (with {method} dopri5).",
    ),
    both(
        Command::Simulate,
        "atol",
        DefaultValue::Real(SIMULATE.atol),
        "Absolute tolerance (with {method} dopri5).",
    ),
    both(
        Command::Simulate,
        "mode",
        DefaultValue::Text(SIMULATE.mode),
        "Playback mode: phasor (the measured |V| and angle imposed), exciter_alone (the AVR open \
         loop on the measured |V|, compared on E_fd), machine_from_efd (the machine on the \
         measured E_fd, |V| and P, compared on Q) or closed_loop (the unit against its grid \
         equivalent). A record without an angle needs one of the last three.",
    ),
];

const FIT_OPTIONS: [OptionDecl; 3] = [
    OptionDecl {
        command: Command::Fit,
        name: "stages",
        cli: Some("stage"),
        python: Some("stages"),
        default: DefaultValue::Text("all"),
        help: "Stage(s) to run: gen (machine, E_fd and P_m held), avr, pss, tg, or all (every \
               stage the spec lists). Several stages (e.g. gen,avr,pss) run in the fixed order \
               gen, avr, pss, tg, each starting from the previous result.",
    },
    OptionDecl {
        command: Command::Fit,
        name: "strategy",
        cli: Some("strategy"),
        python: Some("strategy"),
        default: DefaultValue::Unset("the spec's, else sequential"),
        help: "How stages are combined: sequential, incremental or simultaneous-first.",
    },
    OptionDecl {
        command: Command::Fit,
        name: "polish",
        cli: Some("no-polish"),
        python: Some("polish"),
        default: DefaultValue::Switch(Some(true)),
        help: "Skip the final joint refinement of all stages' parameters on the full unit.",
    },
];

const DIAGNOSE_OPTIONS: [OptionDecl; 5] = [
    OptionDecl {
        command: Command::Diagnose,
        name: "causes",
        cli: Some("cause"),
        python: Some("causes"),
        default: DefaultValue::Unset("the whole catalog"),
        help: "Cause(s) to try, ids of the catalog or of the user causes (repeatable or \
               comma-separated), e.g. measurement_skew,saturation.",
    },
    OptionDecl {
        command: Command::Diagnose,
        name: "user_causes",
        cli: Some("user-cause"),
        python: Some("user_causes"),
        default: DefaultValue::Unset("none"),
        help: "A cause written by the user (repeatable): a TOML file declaring the blocks its \
               model extension adds (user-defined diagrams or library models), the ports of the \
               unit it rewires and the parameters the re-fit frees (see \
               data/causes/reactive_droop.toml). It is tried after the catalog's causes, or \
               alone with {causes} ITS_ID.",
    },
    OptionDecl {
        command: Command::Diagnose,
        name: "refit",
        cli: Some("refit"),
        python: Some("refit"),
        default: DefaultValue::Unset("none"),
        help: "Calibrated parameter(s) to free again in every re-fit, baselines and extensions \
               alike (repeatable or comma-separated): PARAM within the model's declared range, \
               or PARAM=MIN:MAX, e.g. machine.h,exciter.k=50:200. For the stage parameters a \
               calibration may have bent to make up for the missing cause: held during each \
               candidate's global search, freed in its local method.",
    },
    OptionDecl {
        command: Command::Diagnose,
        name: "mode",
        cli: Some("mode"),
        python: Some("mode"),
        default: DefaultValue::Unset("phasor"),
        help: "Playback of the events: phasor (the measured |V| and angle imposed, P and Q \
               compared) or, for a record without an angle (a staged test), exciter_alone (the \
               AVR open loop, compared on E_fd), machine_from_efd (compared on Q) or closed_loop \
               (the unit against its grid equivalent, compared on |V|, Q and E_fd). Each \
               compared channel is weighted by its own noise floor.",
    },
    OptionDecl {
        command: Command::Diagnose,
        name: "look_alikes",
        cli: Some("no-look-alikes"),
        python: Some("look_alikes"),
        default: DefaultValue::Switch(None),
        help: "Do not try the look-alikes outside the catalog (the bundled reactive droop, \
               transducer lag, speed filter, PSS lead-lag and UEL), which a full diagnosis with \
               a significant candidate scores so that a residual one of them explains better \
               gets no catalog name. Faster, and a wrong name is then more likely.",
    },
];

const SYNTH_OPTIONS: [OptionDecl; 11] = [
    both(
        Command::Synth,
        "kind",
        DefaultValue::Text(SYNTH.kind),
        "What happens on the grid side (the event is at 1 s): dip (a fault-like dip with angle \
         swing and a frequency fall), frequency (a frequency excursion without a dip), step (a \
         grid voltage step) or ambient (ambient fluctuations only).",
    ),
    both(
        Command::Synth,
        "duration",
        DefaultValue::Real(SYNTH.duration),
        "Record length [s] (above 1.5).",
    ),
    both(
        Command::Synth,
        "rate",
        DefaultValue::Real(SYNTH.rate),
        "PMU reporting rate [samples/s] (10 to 1000; PMUs report 30 or 60).",
    ),
    OptionDecl {
        command: Command::Synth,
        name: "system_mva",
        cli: Some("system-mva"),
        python: Some("system_mva"),
        default: DefaultValue::Unset("the unit's machine base"),
        help: "System base of the written P and Q [MVA].",
    },
    OptionDecl {
        command: Command::Synth,
        name: "pq_sigma",
        cli: Some("pq-sigma"),
        python: Some("pq_sigma"),
        default: DefaultValue::Real(SYNTH.pq_sigma),
        help: "White noise on P and Q [pu] (0 for none).",
    },
    OptionDecl {
        command: Command::Synth,
        name: "v_sigma",
        cli: Some("v-sigma"),
        python: Some("v_sigma"),
        default: DefaultValue::Real(SYNTH.v_sigma),
        help: "White noise on |V| [pu] and on the angle [rad] (0 for none).",
    },
    both(
        Command::Synth,
        "quantum",
        DefaultValue::Real(SYNTH.quantum),
        "Quantisation step of P and Q [pu] (the default is the Itaipu record's; 0 for none).",
    ),
    OptionDecl {
        command: Command::Synth,
        name: "skew_ms",
        cli: Some("skew-ms"),
        python: Some("skew_ms"),
        default: DefaultValue::Real(SYNTH.skew_ms),
        help: "Hidden effect: the power channels lag the voltage channel by this much [ms] \
               (applied by the PMU noise model, not by a block in the truth).",
    },
    both(
        Command::Synth,
        "hide",
        DefaultValue::Unset("none"),
        "Hide causes of the diagnosis catalog in the truth, in order: the catalog's model \
         extension with the given values (parameters not given keep the extension's starting \
         values); the truth is then the extended unit. Command line: CAUSE[:PARAM=VALUE,...], \
         repeatable, e.g. torsional_mode:shaft.f_torsion_hz=5,shaft.zeta=0.05, \
         exciter_limit:exciter.e_max=2.8, terminal_load:load.p_load=0.04,load.q_load=0.03, \
         measurement_skew:measurement.pq_delay_s=0.012. Python: [(cause, {param: value}), ...] \
         or {cause: {param: value}}.",
    ),
    both(
        Command::Synth,
        "seed",
        DefaultValue::Int(SYNTH.seed),
        "Seed of the noise and of the ambient fluctuations. Same seed, same bytes.",
    ),
    both(
        Command::Synth,
        "name",
        DefaultValue::Unset("synthetic-<kind>-<seed>"),
        "Event name.",
    ),
];

/// Every declared option, command by command.
pub static OPTIONS: &[OptionDecl] = &concat_options();

const N_OPTIONS: usize = SIMULATE_OPTIONS.len()
    + FIT_OPTIONS.len()
    + FIT_SEARCH_OPTIONS.len()
    + DIAGNOSE_OPTIONS.len()
    + DIAGNOSE_SEARCH_OPTIONS.len()
    + SYNTH_OPTIONS.len();

/// The tables above, one after the other.
const fn concat_options() -> [OptionDecl; N_OPTIONS] {
    let parts: [&[OptionDecl]; 6] = [
        &SIMULATE_OPTIONS,
        &FIT_OPTIONS,
        &FIT_SEARCH_OPTIONS,
        &DIAGNOSE_OPTIONS,
        &DIAGNOSE_SEARCH_OPTIONS,
        &SYNTH_OPTIONS,
    ];
    let mut out = [SIMULATE_OPTIONS[0]; N_OPTIONS];
    let (mut k, mut p) = (0, 0);
    while p < parts.len() {
        let mut i = 0;
        while i < parts[p].len() {
            out[k] = parts[p][i];
            k += 1;
            i += 1;
        }
        p += 1;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_option_is_declared_once_per_command() {
        for (i, a) in OPTIONS.iter().enumerate() {
            for b in &OPTIONS[i + 1..] {
                assert!(
                    !(a.command == b.command && a.name == b.name),
                    "{} declared twice for {}",
                    a.name,
                    a.command.name()
                );
            }
            assert!(a.cli.is_some() || a.python.is_some(), "{}", a.name);
        }
    }

    #[test]
    fn help_spells_the_other_options_as_the_front_end_does() {
        let step = option(Command::Simulate, "step");
        assert_eq!(step.help(Style::Cli), "RK4 step [s] (with --method rk4).");
        assert_eq!(step.help(Style::Python), "RK4 step [s] (with method rk4).");
        let user = option(Command::Diagnose, "user_causes");
        assert!(user
            .help(Style::Cli)
            .ends_with("alone with --cause ITS_ID."));
        assert!(user
            .help(Style::Python)
            .ends_with("alone with causes ITS_ID."));
        // A brace that names no option (Python's dict syntax) is kept as written.
        for style in [Style::Cli, Style::Python] {
            let hide = option(Command::Synth, "hide").help(style);
            assert!(hide.contains("[(cause, {param: value}), ...] or {cause: {param: value}}"));
        }
    }

    #[test]
    fn the_typed_defaults_are_the_requests_defaults() {
        let s = crate::request::SimulateRequest::default();
        assert_eq!(
            (s.method.as_str(), s.rtol, s.atol, s.step),
            (SIMULATE.method, SIMULATE.rtol, SIMULATE.atol, SIMULATE.step)
        );
        assert_eq!(
            SIMULATE.mode,
            itaipu_dynamics::mode::PlaybackMode::default().name()
        );
        let y = crate::request::SynthRequest::default();
        assert_eq!(y.kind.name(), SYNTH.kind);
        assert_eq!(
            (y.duration, y.rate, y.pq_sigma, y.v_sigma, y.quantum, y.skew_ms, y.seed),
            (
                SYNTH.duration,
                SYNTH.rate,
                SYNTH.pq_sigma,
                SYNTH.v_sigma,
                SYNTH.quantum,
                SYNTH.skew_ms,
                SYNTH.seed
            )
        );
    }

    #[test]
    fn search_defaults_are_shown_per_command() {
        let fit = option(Command::Fit, "particles").default_text().unwrap();
        assert_eq!(
            fit,
            format!("the spec's, else {} (per stage)", FIT_SEARCH.particles)
        );
        let diag = option(Command::Diagnose, "particles")
            .default_text()
            .unwrap();
        assert_eq!(
            diag,
            format!("{} (per candidate re-fit)", DIAGNOSE_SEARCH.particles)
        );
        assert!(search_help("particles").contains(&format!(
            "diagnose, {} (per candidate re-fit)",
            DIAGNOSE_SEARCH.particles
        )));
    }
}
