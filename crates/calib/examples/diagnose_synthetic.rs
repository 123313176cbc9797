//! Hides a catalog cause in a synthetic event and diagnoses the nominal unit on it.
//!
//! `cargo run --release -p itaipu-calib --example diagnose_synthetic -- CAUSE [dip|frequency|step|ambient] [SEED] [param=value ...]`
//! (CAUSE `none` for a clean event).

use std::collections::BTreeMap;
use std::path::PathBuf;

use itaipu_calib::diagnose::{catalog, diagnose, trial, DiagnoseOptions};
use itaipu_calib::fit::Progress;
use itaipu_dynamics::simulate::SimOptions;
use itaipu_dynamics::synthetic::{synthesize, EventKind, PmuNoise, VoltageProfile};
use itaipu_dynamics::unit_file::read_unit;

struct Print;
impl Progress for Print {
    fn phase(&self, _: &str, _: &str, _: u64) {}
    fn iteration(&self, _: u64, _: f64) {}
    fn message(&self, text: &str) {
        eprintln!("{text}");
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let cause = args.first().cloned().unwrap_or_else(|| "none".into());
    let kind = match args.get(1).map(String::as_str).unwrap_or("dip") {
        "frequency" => EventKind::FrequencyExcursion,
        "step" => EventKind::VoltageStep,
        "ambient" => EventKind::Ambient,
        _ => EventKind::FaultDip,
    };
    let seed: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1);
    let values: BTreeMap<String, f64> = args
        .iter()
        .skip(3)
        .map(|kv| {
            let (k, v) = kv.split_once('=').expect("param=value");
            (k.to_string(), v.parse().expect("number"))
        })
        .collect();
    let data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data");
    let base = read_unit(&data.join("synthetic/unit_gensae_sexs_stab3_hygov.toml")).unwrap();
    let profile = VoltageProfile::preset(kind, 20.0, 60.0, seed);
    let truth = if cause == "none" {
        base.clone()
    } else {
        let (_, ctx) = trial::probe(&base, &profile).unwrap();
        catalog::hide(&cause, &base, &ctx, &values)
            .map_err(|e| e.to_string())
            .unwrap()
            .0
    };
    let mut noise = PmuNoise::typical(seed);
    if let Ok(scale) = std::env::var("NOISE_SCALE") {
        let k: f64 = scale.parse().expect("NOISE_SCALE is a number");
        noise.pq_sigma *= k;
        noise.v_sigma *= k;
        noise.angle_sigma *= k;
        noise.pq_quantum *= k;
    }
    if let Ok(scale) = std::env::var("V_NOISE_SCALE") {
        let k: f64 = scale.parse().expect("V_NOISE_SCALE is a number");
        noise.v_sigma *= k;
        noise.angle_sigma *= k;
    }
    let event = synthesize(
        "synthetic",
        &truth,
        &profile,
        737.0,
        &noise,
        &SimOptions::default(),
    )
    .unwrap();
    let causes: Vec<String> = std::env::var("CAUSES")
        .map(|c| c.split(',').map(String::from).collect())
        .unwrap_or_default();
    let t0 = std::time::Instant::now();
    let res = diagnose(
        &base,
        &[event],
        &[],
        &DiagnoseOptions {
            seed,
            causes,
            ..Default::default()
        },
        &Print,
    )
    .unwrap();
    let r = &res.report;
    println!(
        "noise σP {:.5} σQ {:.5}; {}",
        r.noise.sigma_p, r.noise.sigma_q, r.noise.split
    );
    for c in &r.candidates {
        match &c.gains {
            Some(g) => println!(
                "{:<17} null {:>7.1} ΔBIC {:>10.1}  fit {:>6.1} %  held {:>6.1} %  {}  {:>5.1} s {:>6} sims [{}]",
                c.cause,
                g.null_gain_fit,
                g.delta_bic,
                100.0 * g.fit_drop,
                100.0 * g.held_drop,
                if c.significant { "*" } else { " " },
                c.wall_s,
                c.simulations,
                c.parameters.iter().filter(|p| p.extension).map(|p| format!("{}={:.4}", p.param, p.result)).collect::<Vec<_>>().join(" ")
            ),
            None => println!("{:<17} {}", c.cause, c.note),
        }
    }
    println!("verdict: {} — {}", r.verdict.cause, r.verdict.statement);
    println!("wall {:.1} s", t0.elapsed().as_secs_f64());
}
