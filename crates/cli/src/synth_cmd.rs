//! `itaipu-calib synth`: realistic synthetic events from the engine, with a separate truth file.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use clap::ValueEnum;
use itaipu_calib::diagnose::{self, catalog};
use itaipu_dynamics::event::Event;
use itaipu_dynamics::simulate::{SimError, SimOptions};
use itaipu_dynamics::synthetic::{synthesize, EventKind, PmuNoise, SynthError, VoltageProfile};
use itaipu_dynamics::unit::Unit;
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
    /// Hidden effect: the power channels lag the voltage channel by this much [ms] (applied by
    /// the PMU noise model, not by a block in the truth).
    #[arg(long, default_value_t = 0.0)]
    skew_ms: f64,
    /// Hide a cause of the diagnosis catalog in the truth (repeatable, applied in order): the
    /// catalog's model extension with the given values, e.g.
    /// `torsional_mode:shaft.f_torsion_hz=5,shaft.zeta=0.05`, `exciter_limit:exciter.e_max=2.8`,
    /// `terminal_load:load.p_load=0.04,load.q_load=0.03`,
    /// `measurement_skew:measurement.pq_delay_s=0.012`. Parameters not given keep the
    /// extension's starting values. truth.toml is then the extended unit.
    #[arg(long, value_name = "CAUSE[:PARAM=VALUE,...]")]
    hide: Vec<String>,
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
        return Err(CliError::new(
            2,
            format!("--duration must exceed 1.5 s (got {})", a.duration),
        ));
    }
    if !(a.rate >= 10.0 && a.rate <= 1000.0) {
        return Err(CliError::new(
            2,
            format!("--rate must lie in 10-1000 samples/s (got {})", a.rate),
        ));
    }
    for (name, v) in [
        ("--pq-sigma", a.pq_sigma),
        ("--v-sigma", a.v_sigma),
        ("--quantum", a.quantum),
        ("--skew-ms", a.skew_ms),
    ] {
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
    let name = a
        .name
        .clone()
        .unwrap_or_else(|| format!("synthetic-{kind_name}-{}", a.seed));
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
    let hides = a
        .hide
        .iter()
        .map(|h| parse_hide(h))
        .collect::<Result<Vec<_>, _>>()?;
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
    let truth = if hides.is_empty() {
        truth
    } else {
        // The catalog's context (operating-point field voltage and current, PMU rate) comes from
        // the truth as given on a noise-free run of the same profile.
        let probe = synthesize(
            &name,
            &truth,
            &profile,
            system_mva,
            &PmuNoise::none(),
            &SimOptions::default(),
        )
        .map_err(|e| synth_error(&unit_path, e))?;
        let (extended, entries) = hide_all(&truth, &probe, &hides, &unit_path)?;
        hidden.extend(entries);
        extended
    };
    let event = synthesize(
        &name,
        &truth,
        &profile,
        system_mva,
        &noise,
        &SimOptions::default(),
    )
    .map_err(|e| {
        let e = synth_error(&unit_path, e);
        if hides.is_empty() {
            e
        } else {
            CliError::new(
                e.code,
                format!("{} (with the hidden cause(s) {})", e.msg, a.hide.join(" ")),
            )
        }
    })?;
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
    let target = staging.commit(Some(a.seed))?;
    println!(
        "wrote  {}/event.toml, {csv_name}, truth.toml, truth.json, manifest.json",
        target.display()
    );
    Ok(())
}

/// A `--hide` option: the spec as written, the cause, and the values in the order given.
type Hide = (String, String, Vec<(String, f64)>);

/// Parses `CAUSE[:PARAM=VALUE,PARAM=VALUE...]`; every error is a usage error (exit 2) naming
/// the bad piece.
fn parse_hide(spec: &str) -> Result<Hide, CliError> {
    let usage = |msg: String| CliError::new(2, format!("--hide {spec}: {msg}"));
    let (cause, rest) = match spec.split_once(':') {
        Some((c, r)) => (c.trim(), Some(r)),
        None => (spec.trim(), None),
    };
    if cause.is_empty() {
        return Err(usage(format!(
            "no cause before ':' (known: {})",
            catalog::ids()
        )));
    }
    if catalog::find(cause).is_none() {
        return Err(usage(format!(
            "unknown cause '{cause}' (known: {})",
            catalog::ids()
        )));
    }
    let mut values: Vec<(String, f64)> = vec![];
    if let Some(rest) = rest {
        if rest.trim().is_empty() {
            return Err(usage(
                "nothing after ':' (expected PARAM=VALUE[,PARAM=VALUE...])".into(),
            ));
        }
        for item in rest.split(',') {
            let (k, v) = item
                .split_once('=')
                .ok_or_else(|| usage(format!("'{}' is not PARAM=VALUE", item.trim())))?;
            let (k, v) = (k.trim(), v.trim());
            if k.is_empty() {
                return Err(usage(format!("'{}' has no parameter name", item.trim())));
            }
            let x: f64 = v
                .parse()
                .map_err(|_| usage(format!("{k}: '{v}' is not a number")))?;
            if !x.is_finite() {
                return Err(usage(format!("{k}: '{v}' is not a finite number")));
            }
            if values.iter().any(|(p, _)| p == k) {
                return Err(usage(format!("{k} is given twice")));
            }
            values.push((k.to_string(), x));
        }
    }
    Ok((spec.to_string(), cause.to_string(), values))
}

/// The exit code of a failure to synthesise: 5 when the unit cannot initialise, 6 when the
/// integration fails.
fn synth_error(unit_path: &Path, e: SynthError) -> CliError {
    let code = match &e {
        SynthError::Sim(SimError::Solve(_)) => 6,
        _ => 5,
    };
    CliError::new(code, format!("{}: {e}", unit_path.display()))
}

/// Hides each cause in turn in `truth` ([`catalog::hide`], the catalog's context taken from the
/// truth as given on `probe`); returns the extended unit and one `hidden_effects` entry per cause
/// (its parameters with their values in the extended unit).
fn hide_all(
    truth: &Unit,
    probe: &Event,
    hides: &[Hide],
    unit_path: &Path,
) -> Result<(Unit, Vec<serde_json::Value>), CliError> {
    let ctx = diagnose::context(truth, probe).map_err(|e| {
        CliError::new(
            5,
            format!(
                "{}: the true unit does not simulate on the synthetic profile: {e}",
                unit_path.display()
            ),
        )
    })?;
    let mut unit = truth.clone();
    let mut entries = vec![];
    for (spec, cause, values) in hides {
        let map: BTreeMap<String, f64> = values.iter().cloned().collect();
        let (extended, ext) = catalog::hide(cause, &unit, &ctx, &map).map_err(|e| match e {
            catalog::HideError::Build(msg) => {
                CliError::new(4, format!("{}: --hide {spec}: {msg}", unit_path.display()))
            }
            other => CliError::new(2, format!("--hide {spec}: {other}")),
        })?;
        unit = extended;
        let mut shown: Vec<&str> = ext
            .extension_free
            .iter()
            .map(|f| f.param.as_str())
            .collect();
        shown.extend(ext.ties.iter().map(|(_, to)| to.as_str()));
        shown.extend(values.iter().map(|(p, _)| p.as_str()));
        let mut params = serde_json::Map::new();
        for p in shown {
            if let Ok(r) = unit.param(p) {
                params
                    .entry(p.to_string())
                    .or_insert(serde_json::json!(unit.get(r)));
            }
        }
        let info = catalog::find(cause).expect("checked by parse_hide");
        entries.push(serde_json::json!({
            "cause": cause,
            "source": format!("--hide {spec}"),
            "title": info.title,
            "extension": ext.description,
            "parameters": params,
        }));
    }
    let causes: Vec<&str> = hides.iter().map(|(_, c, _)| c.as_str()).collect();
    unit.description = format!(
        "{} (hidden by itaipu-calib synth: {})",
        unit.description,
        causes.join(", ")
    );
    Ok((unit, entries))
}
