//! `itaipu-calib synth`: realistic synthetic events from the engine, with a separate truth file.

use std::path::PathBuf;

use clap::ValueEnum;
use itaipu_calib::options::{cli_help, Command::Synth, SYNTH};
use itaipu_calib::request::{HideSpec, SynthRequest};
use itaipu_dynamics::unit_file::unit_to_toml;

use crate::error::synth_error;
use crate::{bundled, load_unit, prepare_out, CliError, EXIT_CODES};

#[derive(clap::Args, Debug)]
#[command(after_help = EXIT_CODES)]
pub struct SynthArgs {
    /// The true unit (default: the generic GENSAE + SEXS + STAB3 + HYGOV unit,
    /// data/synthetic/unit_gensae_sexs_stab3_hygov.toml).
    #[arg(long, value_name = "FILE")]
    unit: Option<PathBuf>,
    #[arg(long, value_enum, default_value = SYNTH.kind, help = cli_help(Synth, "kind"))]
    kind: KindArg,
    #[arg(long, default_value_t = SYNTH.duration, help = cli_help(Synth, "duration"))]
    duration: f64,
    #[arg(long, default_value_t = SYNTH.rate, help = cli_help(Synth, "rate"))]
    rate: f64,
    #[arg(long, help = cli_help(Synth, "system_mva"))]
    system_mva: Option<f64>,
    #[arg(long, default_value_t = SYNTH.pq_sigma, help = cli_help(Synth, "pq_sigma"))]
    pq_sigma: f64,
    #[arg(long, default_value_t = SYNTH.v_sigma, help = cli_help(Synth, "v_sigma"))]
    v_sigma: f64,
    #[arg(long, default_value_t = SYNTH.quantum, help = cli_help(Synth, "quantum"))]
    quantum: f64,
    #[arg(long, default_value_t = SYNTH.skew_ms, help = cli_help(Synth, "skew_ms"))]
    skew_ms: f64,
    #[arg(long, value_name = "CAUSE[:PARAM=VALUE,...]", help = cli_help(Synth, "hide"))]
    hide: Vec<String>,
    #[arg(long, default_value_t = SYNTH.seed, help = cli_help(Synth, "seed"))]
    seed: u64,
    #[arg(long, help = cli_help(Synth, "name"))]
    name: Option<String>,
    /// Output folder for event.toml, <name>.csv, truth.toml and truth.json (default:
    /// out/synth-<name>). An existing folder is never overwritten unless --force is given.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Allow writing into an existing, non-empty --out folder.
    #[arg(long)]
    force: bool,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
enum KindArg {
    /// Fault-like dip with angle swing and a frequency fall.
    Dip,
    /// Frequency excursion without a dip.
    Frequency,
    /// Grid voltage step.
    Step,
    /// Ambient fluctuations only.
    Ambient,
}

pub fn cmd_synth(a: &SynthArgs) -> Result<(), CliError> {
    let unit_path = match &a.unit {
        Some(p) => p.clone(),
        None => bundled("synthetic/unit_gensae_sexs_stab3_hygov.toml")?,
    };
    let truth = load_unit(&unit_path)?;
    let kind = a.kind.to_possible_value().expect("no skipped values");
    let mut request = SynthRequest {
        kind: kind.get_name().parse()?,
        duration: a.duration,
        rate: a.rate,
        system_mva: a.system_mva,
        pq_sigma: a.pq_sigma,
        v_sigma: a.v_sigma,
        quantum: a.quantum,
        skew_ms: a.skew_ms,
        seed: a.seed,
        name: a.name.clone(),
        hides: vec![],
    };
    request.validate()?;
    request.hides = a
        .hide
        .iter()
        .map(|h| HideSpec::parse(h))
        .collect::<Result<Vec<_>, _>>()?;
    let kind_name = request.kind.name();
    let name = request.event_name();
    let system_mva = a.system_mva.unwrap_or(truth.machine_mva);
    let mut hidden = if a.skew_ms > 0.0 {
        vec![serde_json::json!({
            "cause": "measurement_skew",
            "source": "noise model (--skew-ms)",
            "delay_s": a.skew_ms * 1e-3,
            "parameters": { "pq_delay_s": a.skew_ms * 1e-3 },
        })]
    } else {
        vec![]
    };
    let made = request
        .run(&truth, "itaipu-calib synth")
        .map_err(|e| synth_error(&unit_path, e, &a.hide))?;
    hidden.extend(made.hidden.iter().map(|h| {
        let params: serde_json::Map<String, serde_json::Value> = h
            .parameters
            .iter()
            .map(|(p, v)| (p.clone(), serde_json::json!(v)))
            .collect();
        serde_json::json!({
            "cause": h.cause,
            "source": format!("--hide {}", h.written),
            "title": h.title,
            "extension": h.extension,
            "parameters": params,
        })
    }));
    let (event, truth) = (made.event, made.truth);
    let staging = prepare_out(a.out.as_deref(), &format!("synth-{name}"), a.force)?;
    let out = staging.path().to_path_buf();
    let csv_name = format!("{name}.csv");
    let csv_path = out.join(&csv_name);
    event
        .write_csv(&csv_path)
        .map_err(|e| CliError::new(7, e.to_string()))?;
    let write = |p: PathBuf, text: String| {
        std::fs::write(&p, text)
            .map_err(|e| CliError::new(7, format!("cannot write {}: {e}", p.display())))
    };
    write(
        out.join("event.toml"),
        format!(
            "name = {name:?}\ndescription = \"synthetic {kind_name} event made by itaipu-calib synth from {} (seed {}); truth in truth.toml and truth.json\"\ncsv = {csv_name:?}\nsystem_mva = {system_mva:?}\nnominal_hz = {:?}\n\n[init]\nstart_s = {:?}\nend_s = {:?}\n",
            truth.name,
            a.seed,
            truth.nominal_hz,
            event.init.start_s,
            event.init.end_s
        ),
    )?;
    write(out.join("truth.toml"), unit_to_toml(&truth))?;
    let params: serde_json::Map<String, serde_json::Value> = truth
        .params()
        .into_iter()
        .map(|(p, _, v)| (p, serde_json::json!(v)))
        .collect();
    let truth_json = serde_json::json!({
        "event": name,
        "kind": kind_name,
        "duration_s": a.duration,
        "rate_hz": a.rate,
        "system_mva": system_mva,
        "seed": a.seed,
        "unit": truth.name,
        "unit_file": unit_path.display().to_string(),
        "noise": { "pq_sigma": a.pq_sigma, "v_sigma": a.v_sigma, "angle_sigma": a.v_sigma, "pq_quantum": a.quantum },
        "hidden_effects": hidden,
        "parameters": params,
    });
    write(
        out.join("truth.json"),
        serde_json::to_string_pretty(&truth_json).expect("json"),
    )?;
    println!(
        "synth  {name}: {kind_name}, {} samples at {} samples/s over {} s from {} ({}), noise P/Q {} pu, |V| {} pu, quantum {} pu{}",
        event.record.time_s.len(),
        a.rate,
        a.duration,
        truth.name,
        unit_path.display(),
        a.pq_sigma,
        a.v_sigma,
        a.quantum,
        if a.skew_ms > 0.0 { format!(", power channels delayed {} ms", a.skew_ms) } else { String::new() }
    );
    for h in &a.hide {
        println!("hidden {h}");
    }
    let target = crate::output::commit(staging, Some(a.seed))?;
    println!(
        "wrote  {}/event.toml, {csv_name}, truth.toml, truth.json, manifest.json",
        target.display()
    );
    Ok(())
}
