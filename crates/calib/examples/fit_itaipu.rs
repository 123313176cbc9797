//! Calibrates the bundled Itaipu unit on the bundled record with the bundled spec (RaPId's
//! problem) and prints the fitness per stage.
//!
//! `cargo run --release -p itaipu-calib --example fit_itaipu [stage ...]`

use std::path::PathBuf;

use itaipu_calib::fit::{fit, FitOptions, Progress};
use itaipu_calib::spec::CalibSpec;
use itaipu_dynamics::event::Event;
use itaipu_dynamics::unit_file::read_unit;

struct Lines;

impl Progress for Lines {
    fn phase(&self, stage: &str, phase: &str, total: u64) {
        println!("[{stage}] {phase} ({total} iterations max)");
    }
    fn iteration(&self, i: u64, best: f64) {
        if i.is_multiple_of(10) {
            println!("    iteration {i}: best {best:.5}");
        }
    }
    fn message(&self, text: &str) {
        println!("{text}");
    }
}

fn main() {
    let data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/itaipu");
    let unit = read_unit(&data.join("unit.toml")).expect("unit");
    let event = Event::from_toml_file(&data.join("event.toml")).expect("event");
    let spec = CalibSpec::from_file(&data.join("calibration.toml")).expect("spec");
    let mut opts = FitOptions::from_spec(&spec);
    let stages: Vec<String> = std::env::args().skip(1).collect();
    if !stages.is_empty() {
        opts.stages = stages;
    }
    let res = fit(&unit, &spec, &[event], &[], &opts, &Lines).expect("fit");
    println!("start: J = {:.4}", res.report.start_fitness[0].j_pq);
    for s in &res.report.stages {
        println!(
            "{}: objective {:.4} -> {:.4}, J_pq = {:.4}, {} simulations, {} failed, {:.1} s",
            s.stage,
            s.objective_before,
            s.objective_after,
            s.fitness[0].j_pq,
            s.simulations,
            s.failed_candidates,
            s.wall_s
        );
        for p in &s.parameters {
            println!(
                "    {:<22} {:>10.4} -> {:>10.4}  [{}, {}]{}",
                p.param,
                p.start,
                p.result,
                p.min,
                p.max,
                if p.at_bound { "  AT BOUND" } else { "" }
            );
        }
    }
    println!(
        "total {:.1} s on {} threads",
        res.report.wall_s, res.report.threads
    );
}
