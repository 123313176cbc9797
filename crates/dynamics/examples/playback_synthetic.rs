//! Plays a 20 s synthetic event (dip, grid swing, frequency fall, PMU noise) into the generic
//! GENSAE + SEXS + STAB3 + HYGOV unit and prints integrator statistics and timing.
//!
//! `cargo run --release -p itaipu-dynamics --example playback_synthetic [repeats]`

use std::path::PathBuf;
use std::time::Instant;

use itaipu_dynamics::simulate::{run_playback, PreparedEvent, SimOptions};
use itaipu_dynamics::synthetic::{synthesize, PmuNoise, VoltageProfile};
use itaipu_dynamics::unit_file::read_unit;

fn main() {
    let repeats: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(20);
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../data/synthetic/unit_gensae_sexs_stab3_hygov.toml");
    let unit = read_unit(&path).expect("unit file");
    let opts = SimOptions::default();
    let event = synthesize(
        "synthetic-20s",
        &unit,
        &VoltageProfile::default(),
        737.0,
        &PmuNoise::typical(1),
        &opts,
    )
    .expect("synthetic event");
    let ev = PreparedEvent::new(&event);
    let mut u = unit.clone();
    let t0 = Instant::now();
    let mut stats = Default::default();
    for _ in 0..repeats {
        stats = run_playback(&mut u, &ev, &opts, |_, _, _| {}).expect("playback");
    }
    let per = t0.elapsed().as_secs_f64() / repeats as f64;
    println!(
        "{}: {} samples, {}: {stats:?}",
        event.name,
        ev.input.time_s.len(),
        opts.method
    );
    println!("{:.3} ms per playback ({repeats} repeats)", per * 1e3);
}
