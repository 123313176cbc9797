//! `itaipu-calib simulate`: play the measured terminal voltage of an event into a unit model and
//! compare simulated P and Q with the measured ones.

use std::path::PathBuf;
use std::time::Instant;

use clap::ValueEnum;
use itaipu_calib::options::{cli_help, Command::Simulate, SIMULATE};
use itaipu_calib::request::SimulateRequest;
use itaipu_dynamics::event::{Channel, Event};
use itaipu_dynamics::integrate::Method;
use itaipu_dynamics::mode::{simulate_mode_traces, PlaybackMode};
use itaipu_dynamics::simulate::{trace_columns, Traces};
use itaipu_dynamics::unit::Unit;

use crate::report::svg as plot;
use crate::{
    bundled, explain_sim_error, load_event, load_unit, output, plausibility, prepare_out,
    write_warnings, CliError,
};

#[derive(clap::Args, Debug)]
pub struct SimulateArgs {
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
    #[arg(long, value_enum, default_value = SIMULATE.method, help = cli_help(Simulate, "method"))]
    method: MethodArg,
    #[arg(long, default_value_t = SIMULATE.step, value_name = "SECONDS", help = cli_help(Simulate, "step"))]
    step: f64,
    #[arg(long, default_value_t = SIMULATE.rtol, help = cli_help(Simulate, "rtol"))]
    rtol: f64,
    #[arg(long, default_value_t = SIMULATE.atol, help = cli_help(Simulate, "atol"))]
    atol: f64,
    /// Do not draw plot.svg.
    #[arg(long)]
    no_plot: bool,
    #[arg(long, default_value = SIMULATE.mode, value_parser = mode_parser(), help = cli_help(Simulate, "mode"))]
    mode: PlaybackMode,
}

/// `--mode`: the library's mode names ([`PlaybackMode::NAMES`]).
pub(crate) fn mode_parser() -> impl clap::builder::TypedValueParser<Value = PlaybackMode> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(PlaybackMode::NAMES)
        .map(|s| PlaybackMode::parse(&s).expect("a mode name"))
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum MethodArg {
    /// Adaptive Dormand-Prince 5(4) with event location.
    Dopri5,
    /// Fixed-step classical Runge-Kutta 4.
    Rk4,
}

/// Largest number of fixed RK4 steps a playback may take (`--step` too small for the record
/// is refused rather than run for hours).
pub const RK4_MAX_STEPS: f64 = 1e7;

fn sim_options(a: &SimulateArgs) -> Result<itaipu_dynamics::simulate::SimOptions, CliError> {
    let method = a.method.to_possible_value().expect("no skipped values");
    let request = SimulateRequest {
        method: method.get_name().to_string(),
        rtol: a.rtol,
        atol: a.atol,
        step: a.step,
    };
    Ok(request.options()?)
}

/// Sum over the fit-window samples of squared P and Q errors (paper 000 eq. 3, RaPId's J),
/// and the RMS errors of P and Q, all on the system base.
pub fn misfit(event: &Event, traces: &Traces) -> (f64, f64, f64, usize) {
    let col = |c: Channel| {
        let (sim, _) = trace_columns(c).expect("P and Q have trace columns");
        traces.get(sim).expect("a playback's traces carry P and Q")
    };
    let (p, q) = (col(Channel::P), col(Channel::Q));
    let r = &event.record;
    let (mut sp, mut sq, mut n) = (0.0, 0.0, 0usize);
    for k in 0..r.time_s.len() {
        if event.fit.contains(r.time_s[k]) {
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

pub fn cmd_simulate(a: &SimulateArgs) -> Result<(), CliError> {
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
    if let Some(why) = a.mode.missing(&event, &[]) {
        return Err(CliError::new(
            3,
            format!(
                "{}: event '{}' {why} (--mode {})",
                event_path.display(),
                event.name,
                a.mode
            ),
        ));
    }
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
    let traces = simulate_mode_traces(&unit, &event, a.mode, &opts)
        .map_err(|e| explain_sim_error(e, &event, &unit))?;
    let wall = t0.elapsed();
    let csv_path = out.join("traces.csv");
    traces
        .write_csv(&csv_path)
        .map_err(|e| CliError::new(7, format!("cannot write {}: {e}", csv_path.display())))?;

    let op = event.operating_point();
    let r = &event.record;
    let (j, rms_p, rms_q, n_fit) = misfit(&event, &traces);
    let col = |n: &str| {
        // A machine driven by the measured E_fd reads it as efd_meas.
        let alias = if n == "efd" { "efd_meas" } else { n };
        traces
            .get(n)
            .or_else(|| traces.get(alias))
            .map(|c| c[0])
            .unwrap_or(f64::NAN)
    };
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
    if a.mode == PlaybackMode::Phasor {
        println!(
            "misfit fit window {:.2}-{:.2} s ({n_fit} samples): RMS P {rms_p:.4} pu, RMS Q {rms_q:.4} pu, J = sum(dP^2 + dQ^2) = {j:.4}",
            event.fit.start_s, event.fit.end_s
        );
    } else {
        // The headline is what the mode compares (its default channels the record holds), not
        // P and Q: a mode that imposes P or Q has no misfit in it to speak of.
        let compared: Vec<Channel> = a
            .mode
            .default_channels()
            .iter()
            .copied()
            .filter(|c| event.has(*c))
            .collect();
        let sums: Vec<(Channel, f64, usize)> = a
            .mode
            .outputs()
            .iter()
            .filter(|c| event.has(**c))
            .filter_map(|c| {
                let (sim, meas) = trace_columns(*c)?;
                let (s, m) = (traces.get(sim)?, traces.get(meas)?);
                let (mut sse, mut n) = (0.0, 0usize);
                for k in (0..s.len()).filter(|&k| event.fit.contains(r.time_s[k])) {
                    sse += (s[k] - m[k]).powi(2);
                    n += 1;
                }
                Some((*c, sse, n))
            })
            .collect();
        let head: Vec<String> = sums
            .iter()
            .filter(|(c, _, _)| compared.contains(c))
            .map(|(c, sse, n)| format!("RMS {c} {:.4} pu", (sse / (*n).max(1) as f64).sqrt()))
            .collect();
        let j: f64 = sums
            .iter()
            .filter(|(c, _, _)| compared.contains(c))
            .map(|(_, sse, _)| sse)
            .sum();
        println!(
            "misfit {} compares {}: fit window {:.2}-{:.2} s ({n_fit} samples): {}, J = sum over {} of sum(d^2) = {j:.4}",
            a.mode,
            compared.iter().map(|c| c.name()).collect::<Vec<_>>().join(", "),
            event.fit.start_s,
            event.fit.end_s,
            head.join(", "),
            compared.iter().map(|c| c.name()).collect::<Vec<_>>().join(", ")
        );
        println!(
            "mode   {}: sum of squared differences per channel over the fit window: {}",
            a.mode,
            sums.iter()
                .map(|(c, sse, _)| format!("{c} {sse:.5}"))
                .collect::<Vec<_>>()
                .join(", ")
        );
        if matches!(
            a.mode,
            PlaybackMode::ExciterAlone | PlaybackMode::MachineFromEfd
        ) {
            println!(
                "mode   the machine starts at Q {:.5} pu (machine base), where its steady E_fd is the measured E_fd0 {:.5} pu; the load angle is held by the measured P",
                col("q_mach_pu"),
                col("efd_meas")
            );
        }
        for note in event.declaration_notes() {
            println!("event  {note}");
        }
    }
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
        let mut panels = panels;
        // A phasor record played back smoothed: the played-back |V| over the recorded one.
        if let (PlaybackMode::Phasor, Some(fc)) = (a.mode, event.input_lowpass_hz) {
            if event.record.v_mag_pu.len() == t.len() {
                panels[0].series[0].label = format!("played-back |V| (low-passed at {fc} Hz)");
                panels[0].series[0].color = plot::PLAYED;
                panels[0].series.insert(
                    0,
                    plot::Series {
                        label: "measured |V|".into(),
                        x: t,
                        y: &event.record.v_mag_pu,
                        color: plot::MEASURED,
                        thin: true,
                    },
                );
            }
        }
        if a.mode != PlaybackMode::Phasor {
            panels[0].y_label = "|V| [pu]".into();
            if a.mode == PlaybackMode::ClosedLoop {
                panels[0].series[0].label = "simulated |V|".into();
                panels[0].series[0].color = plot::SIMULATED;
                panels[0].series.insert(
                    0,
                    plot::Series {
                        label: "measured |V|".into(),
                        x: t,
                        y: get("v_meas_pu"),
                        color: plot::MEASURED,
                        thin: true,
                    },
                );
            }
            if let (Some(m), Some(s)) = (traces.get("efd_meas_pu"), traces.get("efd")) {
                panels.push(plot::Panel {
                    y_label: "E_fd [pu]".into(),
                    series: vec![
                        plot::Series {
                            label: "measured".into(),
                            x: t,
                            y: m,
                            color: plot::MEASURED,
                            thin: true,
                        },
                        plot::Series {
                            label: if a.mode == PlaybackMode::MachineFromEfd {
                                "played back".into()
                            } else {
                                "simulated".into()
                            },
                            x: t,
                            y: s,
                            color: plot::SIMULATED,
                            thin: false,
                        },
                    ],
                });
            }
        }
        let title = format!(
            "{}: {} playback ({}), J = {j:.3}",
            event.name, unit.name, a.mode
        );
        plot::draw(&plot_path, &title, "time [s]", &panels).map_err(|e| CliError::new(7, e))?;
        written.push("plot.svg".to_string());
    }
    write_warnings(&out, &warnings)?;
    if !warnings.is_empty() {
        written.push("warnings.json".to_string());
    }
    let target = crate::output::commit(staging, None)?;
    written.push(output::MANIFEST.to_string());
    println!("wrote  {}/{{{}}}", target.display(), written.join(", "));
    Ok(())
}
