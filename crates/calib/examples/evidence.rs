//! Residual evidence of a unit on an event: where the error lives, how it compares with the
//! noise floor, whether it is white, whether it follows the played-back voltage, and which
//! oscillations it contains.
//!
//! `cargo run --release -p itaipu-calib --example evidence [UNIT.toml] [EVENT.toml]`
//! (defaults: the bundled Itaipu unit and record; pass `out/fit-…/calibrated.toml` to look at
//! what a calibration left).

use std::path::PathBuf;

use itaipu_calib::evidence::{analyse, EvidenceOptions};
use itaipu_dynamics::event::Event;
use itaipu_dynamics::simulate::{simulate, SimOptions};
use itaipu_dynamics::unit_file::read_unit;

fn main() {
    let data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/itaipu");
    let args: Vec<String> = std::env::args().skip(1).collect();
    let unit_path = args
        .first()
        .map(PathBuf::from)
        .unwrap_or_else(|| data.join("unit.toml"));
    let event_path = args
        .get(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| data.join("event.toml"));
    let unit = read_unit(&unit_path).expect("unit");
    let event = Event::from_toml_file(&event_path).expect("event");
    let tr = simulate(&unit, &event, &SimOptions::default()).expect("simulation");
    let t = &tr.time_s;
    let r = &event.record;
    let t_end = t[t.len() - 1];
    let opts = EvidenceOptions {
        windows: vec![
            ("pre-event".into(), event.init.start_s, event.init.end_s),
            ("dip".into(), event.init.end_s, event.init.end_s + 0.25),
            (
                "recovery".into(),
                event.init.end_s + 0.25,
                event.init.end_s + 2.0,
            ),
            ("tail".into(), event.init.end_s + 2.0, t_end),
        ],
        noise_window: (event.init.start_s, event.init.end_s),
        ..Default::default()
    };
    let inputs = [
        ("|V|", r.v_mag_pu.as_slice()),
        ("angle", r.v_ang_rad.as_slice()),
    ];
    for (name, sim, meas) in [("P", "p_pu", &r.p_pu), ("Q", "q_pu", &r.q_pu)] {
        let res: Vec<f64> = tr
            .get(sim)
            .unwrap()
            .iter()
            .zip(meas.iter())
            .map(|(s, m)| s - m)
            .collect();
        let ev = analyse(name, t, &res, meas, &inputs, &opts);
        println!(
            "{name}: RMS {:.4} pu = {:.1} x noise floor {:.4}; bias {:+.4}; white: {} (Ljung-Box p = {:.2e})",
            ev.rms, ev.rms_over_noise, ev.noise_floor_rms, ev.bias, ev.whiteness.white, ev.whiteness.p_value
        );
        for w in &ev.windows {
            println!(
                "   {:<10} {:>5.2}-{:<5.2} s  bias {:+.4}  RMS {:.4}  share of SSE {:.0} %",
                w.label,
                w.start_s,
                w.end_s,
                w.bias,
                w.rms,
                100.0 * w.share_of_sse
            );
        }
        for c in &ev.cross {
            println!(
                "   follows {:<6}: lag {:+} samples, correlation {:+.2} (band {:.2}){}",
                c.input,
                c.best_lag_samples,
                c.correlation,
                c.band,
                if c.significant { "  significant" } else { "" }
            );
        }
        if let Some(f) = ev.spectrum.peak_hz {
            println!(
                "   spectrum peak {:.2} Hz (x{:.0} the median)",
                f, ev.spectrum.peak_significance
            );
        }
        for m in ev.modes.iter().take(4) {
            println!(
                "   mode {:.2} Hz, damping {:.2}, amplitude {:.4}, energy {:.0} %",
                m.freq_hz,
                m.damping_ratio,
                m.amplitude,
                100.0 * m.energy_share
            );
        }
    }
}
