//! Helpers shared by the playback integration tests (`soft_knots.rs`, `watched_playback.rs`):
//! the bundled synthetic unit and a fault dip synthesised into it.

use itaipu_dynamics::event::Event;
use itaipu_dynamics::simulate::SimOptions;
use itaipu_dynamics::synthetic::{synthesize, PmuNoise, VoltageProfile};
use itaipu_dynamics::unit::Unit;
use itaipu_dynamics::unit_file::read_unit;

/// GENSAE + SEXS + STAB3 + HYGOV (`data/synthetic/unit_gensae_sexs_stab3_hygov.toml`).
pub fn synthetic_unit() -> Unit {
    let path = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../data/synthetic/unit_gensae_sexs_stab3_hygov.toml");
    read_unit(&path).unwrap()
}

/// A fault dip of `duration_s` into [`synthetic_unit`] at 60 samples/s with typical PMU noise
/// (`seed`), as the synthetic path makes it (played back smoothed at its default cut-off).
pub fn synthetic_dip(duration_s: f64, seed: u64) -> Event {
    let profile = VoltageProfile {
        duration_s,
        ..VoltageProfile::default()
    };
    synthesize(
        "dip",
        &synthetic_unit(),
        &profile,
        60.0,
        &PmuNoise::typical(seed),
        &SimOptions::default(),
    )
    .unwrap()
}
