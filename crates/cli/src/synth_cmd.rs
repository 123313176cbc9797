//! `itaipu-calib synth`: realistic synthetic events from the engine, with a separate truth file.

use std::path::PathBuf;

use clap::ValueEnum;
use itaipu_dynamics::simulate::SimOptions;
use itaipu_dynamics::synthetic::{synthesize, EventKind, PmuNoise, VoltageProfile};
use itaipu_dynamics::unit_file::unit_to_toml;

use crate::{bundled, load_unit, prepare_out, CliError, EXIT_CODES};

#[derive(clap::Args, Debug)]
#[command(after_help = EXIT_CODES)]
pub struct SynthArgs {
    /// The true unit (default: the generic GENSAE + SEXS + STAB3 + HYGOV unit,
    /// data/synthetic/unit_gensae_sexs_stab3_hygov.toml).
    #[arg(long, value_name = "FILE")]
    unit: Option<PathBuf>,
    /// What happens on the grid side (the event is at 1 s).
    #[arg(long, value_enum, default_value_t = KindArg::Dip)]
    kind: KindArg,
    /// Record length [s].
    #[arg(long, default_value_t = 20.0)]
    duration: f64,
    /// PMU reporting rate [samples/s] (30 or 60).
    #[arg(long, default_value_t = 60.0)]
    rate: f64,
    /// System base of the written P and Q [MVA] (default: the unit's machine base).
    #[arg(long)]
    system_mva: Option<f64>,
    /// White noise on P and Q [pu] (default 0.002; 0 for none).
    #[arg(long, default_value_t = 0.002)]
    pq_sigma: f64,
    /// White noise on |V| [pu] and on the angle [rad] (default 0.0005 each).
    #[arg(long, default_value_t = 0.0005)]
    v_sigma: f64,
    /// Quantisation step of P and Q [pu] (default 0.0014, as in the Itaipu record; 0 for none).
    #[arg(long, default_value_t = 0.0014)]
    quantum: f64,
    /// Hidden effect: the power channels lag the voltage channel by this much [ms].
    #[arg(long, default_value_t = 0.0)]
    skew_ms: f64,
    /// Seed of the noise and of the ambient fluctuations.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Event name (default: synthetic-<kind>-<seed>).
    #[arg(long)]
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
    if !(a.duration > 1.5 && a.duration.is_finite()) {
        return Err(CliError::new(2, format!("--duration must exceed 1.5 s (got {})", a.duration)));
    }
    if !(a.rate >= 10.0 && a.rate <= 1000.0) {
        return Err(CliError::new(2, format!("--rate must lie in 10-1000 samples/s (got {})", a.rate)));
    }
    for (name, v) in [("--pq-sigma", a.pq_sigma), ("--v-sigma", a.v_sigma), ("--quantum", a.quantum), ("--skew-ms", a.skew_ms)] {
        if !(v >= 0.0 && v.is_finite()) {
            return Err(CliError::new(2, format!("{name} must be >= 0 (got {v})")));
        }
    }
    let kind = match a.kind {
        KindArg::Dip => EventKind::FaultDip,
        KindArg::Frequency => EventKind::FrequencyExcursion,
        KindArg::Step => EventKind::VoltageStep,
        KindArg::Ambient => EventKind::Ambient,
    };
    let kind_name = format!("{:?}", a.kind).to_lowercase();
    let name = a.name.clone().unwrap_or_else(|| format!("synthetic-{kind_name}-{}", a.seed));
    let profile = VoltageProfile::preset(kind, a.duration, a.rate, a.seed);
    let noise = PmuNoise {
        pq_sigma: a.pq_sigma,
        v_sigma: a.v_sigma,
        angle_sigma: a.v_sigma,
        pq_quantum: a.quantum,
        pq_delay_s: a.skew_ms * 1e-3,
        seed: a.seed,
    };
    let system_mva = a.system_mva.unwrap_or(truth.machine_mva);
    if !(system_mva > 0.0) {
        return Err(CliError::new(2, "--system-mva must be > 0"));
    }
    let event = synthesize(&name, &truth, &profile, system_mva, &noise, &SimOptions::default())
        .map_err(|e| CliError::new(5, format!("{}: {e}", unit_path.display())))?;
    let out = prepare_out(a.out.as_deref(), &format!("synth-{name}"), a.force)?;
    let csv_name = format!("{name}.csv");
    let csv_path = out.join(&csv_name);
    event.write_csv(&csv_path).map_err(|e| CliError::new(7, e.to_string()))?;
    let write = |p: PathBuf, text: String| std::fs::write(&p, text).map_err(|e| CliError::new(7, format!("cannot write {}: {e}", p.display())));
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
    let params: serde_json::Map<String, serde_json::Value> =
        truth.params().into_iter().map(|(p, _, v)| (p, serde_json::json!(v))).collect();
    let hidden = if a.skew_ms > 0.0 {
        serde_json::json!([{ "cause": "measurement_skew", "delay_s": a.skew_ms * 1e-3 }])
    } else {
        serde_json::json!([])
    };
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
    write(out.join("truth.json"), serde_json::to_string_pretty(&truth_json).expect("json"))?;
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
    println!("wrote  {}/event.toml, {csv_name}, truth.toml, truth.json", out.display());
    Ok(())
}
