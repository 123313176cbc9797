//! Hit rate of `diagnose` over a sweep of hidden causes, seeds and event types, and the false
//! alarm rate on clean events, with the protocol of the tests (`diagnose::trial`): truth with the
//! cause hidden, typical PMU noise, nominal unit 20-50 % off and calibrated first.
//!
//! `[FIRST_SEED=102] cargo run --release -p itaipu-calib --example diagnose_sweep -- [SEEDS] [CAUSE ...]`
//! (default 3 seeds from 101, every cause and `none`; clean events on all four event types).

use itaipu_calib::diagnose::trial::{run, scenario};
use itaipu_calib::diagnose::{catalog, DiagnoseOptions};
use itaipu_dynamics::synthetic::EventKind;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let seeds: u64 = args.first().and_then(|s| s.parse().ok()).unwrap_or(3);
    // Seeds 101.. are the tests' (seed 101); FIRST_SEED=102 sweeps beyond them.
    let first: u64 = std::env::var("FIRST_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(101);
    let mut causes: Vec<String> = args.iter().skip(1).cloned().collect();
    if causes.is_empty() {
        causes = catalog::CAUSES
            .iter()
            .map(|c| c.info().id.to_string())
            .collect();
        causes.push("none".into());
    }
    let mut rows = vec![];
    for cause in &causes {
        for seed in first..first + seeds {
            // The canonical event, and for the clean case every event type.
            let kinds: Vec<Option<EventKind>> = if cause == "none" {
                vec![
                    None,
                    Some(EventKind::FrequencyExcursion),
                    Some(EventKind::VoltageStep),
                    Some(EventKind::Ambient),
                ]
            } else {
                vec![None]
            };
            for kind in kinds {
                let t = scenario(cause, seed, kind);
                let t0 = std::time::Instant::now();
                match run(
                    &t,
                    &DiagnoseOptions {
                        seed: t.seed,
                        // DIAG_CAUSES=a,b restricts the catalog tried (for quick experiments).
                        causes: std::env::var("DIAG_CAUSES")
                            .ok()
                            .map(|v| v.split(',').map(str::to_string).collect())
                            .unwrap_or_default(),
                        lbfgs_iterations: std::env::var("LBFGS")
                            .ok()
                            .and_then(|v| v.parse().ok())
                            .unwrap_or(15),
                        ..Default::default()
                    },
                ) {
                    Ok(o) => {
                        let key = o
                            .key
                            .as_ref()
                            .map(|(p, tv, got)| {
                                format!(
                                    "{p}: truth {tv:.5} got {}",
                                    got.map_or("-".into(), |g| format!("{g:.5}"))
                                )
                            })
                            .unwrap_or_default();
                        let second = o
                            .report
                            .candidates
                            .get(1)
                            .map(|c| c.cause.clone())
                            .unwrap_or_default();
                        let top = o.report.candidates.first().and_then(|c| c.gains.as_ref());
                        let top_bic = top.map_or(f64::NAN, |g| g.delta_bic);
                        let chi2n = top.map_or(f64::NAN, |g| g.chi2_fit_base / g.n_fit as f64);
                        println!(
                            "{:<17} {:<10} seed {:>3}: named {:<17} {} (top ΔBIC {:.0}, χ²/N {chi2n:.2}, next {second}) {key} [{:.0} s]",
                            cause,
                            format!("{:?}", t.kind),
                            t.seed,
                            o.named,
                            if o.hit { "HIT " } else { "MISS" },
                            top_bic,
                            t0.elapsed().as_secs_f64()
                        );
                        if std::env::var("VERBOSE").is_ok() {
                            let cal: Vec<String> = [
                                "machine.h",
                                "machine.x_d_prime",
                                "machine.t_d0_prime",
                                "exciter.k",
                                "exciter.te",
                            ]
                            .iter()
                            .map(|p| {
                                format!(
                                    "{p}={:.4}",
                                    o.calibrated.get(o.calibrated.param(p).unwrap())
                                )
                            })
                            .collect();
                            println!("    calibrated: {}", cal.join(" "));
                            for c in &o.report.candidates {
                                if let Some(g) = &c.gains {
                                    println!(
                                        "    {:<17} {:>5.1} s ΔBIC {:>9.1} fit {:>6.1} % held {:>6.1} % null {:>6.1} {} [{}] {}",
                                        c.cause,
                                        c.wall_s,
                                        g.delta_bic,
                                        100.0 * g.fit_drop,
                                        100.0 * g.held_drop,
                                        g.null_gain_fit,
                                        if c.significant { "*" } else { " " },
                                        c.parameters.iter().filter(|p| p.extension || std::env::var("VERBOSE").as_deref() == Ok("2")).map(|p| format!("{}={:.4}", p.param, p.result)).collect::<Vec<_>>().join(" "),
                                        c.note
                                    );
                                } else {
                                    println!("    {:<17} {}", c.cause, c.note);
                                }
                            }
                        }
                        rows.push((cause.clone(), o.hit));
                    }
                    Err(e) => {
                        println!("{cause:<17} seed {}: failed: {e}", t.seed);
                        rows.push((cause.clone(), false));
                    }
                }
            }
        }
    }
    let effect: Vec<bool> = rows
        .iter()
        .filter(|(c, _)| c != "none")
        .map(|(_, h)| *h)
        .collect();
    let clean: Vec<bool> = rows
        .iter()
        .filter(|(c, _)| c == "none")
        .map(|(_, h)| *h)
        .collect();
    println!(
        "hit rate {}/{} on hidden causes; false alarms {}/{} on clean events",
        effect.iter().filter(|h| **h).count(),
        effect.len(),
        clean.iter().filter(|h| !**h).count(),
        clean.len()
    );
}
