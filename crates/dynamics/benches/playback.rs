//! Playback benchmarks (divan): `cargo bench -p itaipu-dynamics`.
//!
//! * a 20 s synthetic event at 60 samples/s (dip, grid swing, 0.2 Hz frequency fall, PMU
//!   noise) into GENSAE + SEXS + STAB3 + HYGOV, with RK4 at 1 ms and Dormand-Prince at rtol 1e-6,
//!   and at the searches' rtol 1e-5 landing on every sample or stepping over the smoothed
//!   input's samples (`soft_knots`);
//! * the bundled Itaipu record (4.65 s, 280 samples) into its GENSAE + SEXS + STAB3 unit;
//! * the forward sensitivities of the synthetic event to eight parameters (one pass), and of
//!   the Itaipu record with its SEXS built in or as a user-defined diagram.
//!
//! Each iteration is one complete playback: initialisation, integration, P and Q at every sample.

use std::path::PathBuf;

use divan::Bencher;
use itaipu_dynamics::event::Event;
use itaipu_dynamics::integrate::{Dopri5Options, Method};
use itaipu_dynamics::simulate::{simulate_pq, PreparedEvent, SimOptions};
use itaipu_dynamics::synthetic::{synthesize, PmuNoise, VoltageProfile};
use itaipu_dynamics::unit::Unit;
use itaipu_dynamics::unit_file::read_unit;

fn main() {
    divan::main();
}

fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../data")
        .join(rel)
}

fn synthetic() -> (Unit, PreparedEvent) {
    let unit = read_unit(&data("synthetic/unit_gensae_sexs_stab3_hygov.toml")).unwrap();
    let event = synthesize(
        "bench",
        &unit,
        &VoltageProfile::default(),
        737.0,
        &PmuNoise::typical(1),
        &SimOptions::default(),
    )
    .unwrap();
    (unit, PreparedEvent::new(&event))
}

fn itaipu() -> (Unit, PreparedEvent) {
    let unit = read_unit(&data("itaipu/unit.toml")).unwrap();
    let event = Event::from_toml_file(&data("itaipu/event.toml")).unwrap();
    (unit, PreparedEvent::new(&event))
}

fn dopri5() -> SimOptions {
    SimOptions {
        method: Method::Dopri5(Dopri5Options {
            rtol: 1e-6,
            atol: 1e-7,
            h_max: 0.05,
            ..Default::default()
        }),
    }
}

fn bench(bencher: Bencher, (unit, ev): (Unit, PreparedEvent), opts: SimOptions) {
    let mut u = unit.clone();
    bencher.bench_local(|| simulate_pq(divan::black_box(&mut u), &ev, &opts).unwrap());
}

#[divan::bench(sample_count = 30)]
fn synthetic_20s_rk4_1ms(bencher: Bencher) {
    bench(
        bencher,
        synthetic(),
        SimOptions {
            method: Method::Rk4 { h: 1e-3 },
        },
    );
}

#[divan::bench(sample_count = 100)]
fn synthetic_20s_dopri5_rtol_1e6(bencher: Bencher) {
    bench(bencher, synthetic(), dopri5());
}

/// The searches' tolerances ([`Dopri5Options::search`]), `soft`: stepping over the samples
/// inside the smoothed input's spline.
fn search(soft_knots: bool) -> SimOptions {
    SimOptions {
        method: Method::Dopri5(Dopri5Options {
            soft_knots,
            ..Dopri5Options::search()
        }),
    }
}

#[divan::bench(args = [false, true], sample_count = 100)]
fn synthetic_20s_search_soft_knots(bencher: Bencher, soft: bool) {
    bench(bencher, synthetic(), search(soft));
}

#[divan::bench(sample_count = 100)]
fn itaipu_record_dopri5_rtol_1e6(bencher: Bencher) {
    bench(bencher, itaipu(), dopri5());
}

#[divan::bench(sample_count = 30)]
fn itaipu_record_rk4_1ms(bencher: Bencher) {
    bench(
        bencher,
        itaipu(),
        SimOptions {
            method: Method::Rk4 { h: 1e-3 },
        },
    );
}

/// The Itaipu unit with its SEXS as the user-defined diagram `data/diagrams/sexs.toml`.
fn itaipu_sexs_diagram() -> (Unit, PreparedEvent) {
    let text = std::fs::read_to_string(data("itaipu/unit.toml"))
        .unwrap()
        .replacen(
            "model = \"SEXS\"",
            "model = \"diagram\"\ndiagram = \"../diagrams/sexs.toml\"",
            1,
        );
    let unit =
        itaipu_dynamics::unit_file::parse_unit(&text, &data("itaipu/unit_sexs_diagram.toml"))
            .unwrap();
    let event = Event::from_toml_file(&data("itaipu/event.toml")).unwrap();
    (unit, PreparedEvent::new(&event))
}

/// Built-in SEXS against the same SEXS as a user-defined diagram, per playback of the Itaipu
/// record (RK4 at 1 ms: the same number of right-hand sides for both).
#[divan::bench(sample_count = 100)]
fn itaipu_rk4_1ms_builtin_sexs(bencher: Bencher) {
    bench(
        bencher,
        itaipu(),
        SimOptions {
            method: Method::Rk4 { h: 1e-3 },
        },
    );
}

#[divan::bench(sample_count = 100)]
fn itaipu_rk4_1ms_diagram_sexs(bencher: Bencher) {
    bench(
        bencher,
        itaipu_sexs_diagram(),
        SimOptions {
            method: Method::Rk4 { h: 1e-3 },
        },
    );
}

/// Forward sensitivities of P and Q to eight parameters of the synthetic unit (one pass of the
/// tangent lanes), on the steps of a Dormand-Prince rtol-1e-6 playback: the plain playback that
/// logs the steps, then the states and sensitivities together on them. Compare with
/// [`synthetic_20s_dopri5_rtol_1e6`] × 9 (forward differences) or × 17 (central).
#[divan::bench(sample_count = 30)]
fn synthetic_20s_sensitivities_8_parameters(bencher: Bencher) {
    let names = [
        "machine.h",
        "machine.x_d",
        "machine.t_d0_prime",
        "exciter.k",
        "exciter.te",
        "pss.k_x",
        "governor.t_w",
        "governor.r_temp",
    ];
    sensitivities(bencher, synthetic(), &names);
}

/// One sensitivity playback of `ev` through `unit` for the parameters `names`, on the steps of
/// a Dormand-Prince rtol-1e-6 playback.
fn sensitivities(bencher: Bencher, (unit, ev): (Unit, PreparedEvent), names: &[&str]) {
    let refs: Vec<_> = names.iter().map(|p| unit.param(p).unwrap()).collect();
    let opts = dopri5();
    bencher.bench_local(|| {
        itaipu_dynamics::sens::simulate_pq_sensitivities(divan::black_box(&unit), &ev, &refs, &opts)
            .unwrap()
    });
}

/// Forward sensitivities of the Itaipu record to eight parameters (machine and exciter), the
/// exciter built in or the user-defined SEXS diagram (its dual equations evaluate the compiled
/// nodes on dual numbers): one pass of the tangent lanes on the Dormand-Prince rtol-1e-6 steps.
/// Compare with [`itaipu_record_dopri5_rtol_1e6`] × 9 (forward differences).
fn itaipu_sensitivities(bencher: Bencher, unit_ev: (Unit, PreparedEvent)) {
    let names = [
        "machine.h",
        "machine.x_d",
        "machine.x_d_prime",
        "machine.t_d0_prime",
        "exciter.k",
        "exciter.te",
        "exciter.ta_tb",
        "exciter.tb",
    ];
    sensitivities(bencher, unit_ev, &names);
}

#[divan::bench(sample_count = 50)]
fn itaipu_sensitivities_8_parameters_builtin_sexs(bencher: Bencher) {
    itaipu_sensitivities(bencher, itaipu());
}

#[divan::bench(sample_count = 50)]
fn itaipu_sensitivities_8_parameters_diagram_sexs(bencher: Bencher) {
    itaipu_sensitivities(bencher, itaipu_sexs_diagram());
}

/// The thermal unit (GENROU, ESST4B, PSS2A, IEEEG1, `data/thermal/unit.dyr`) with both washouts
/// of PSS2A's power input and its speed transducer present, and the same unit with the PSS2A
/// written from diagram primitives (`data/diagrams/pss2a.toml`) in its place; on a 10 s fault
/// dip with a 0.2 Hz frequency fall.
fn thermal(pss_diagram: bool) -> (Unit, PreparedEvent) {
    use itaipu_dynamics::dyr::{parse_dyr, DyrBases};
    let path = data("thermal/unit.dyr");
    let bases = DyrBases {
        mbase: 700.0,
        nominal_hz: 60.0,
        zr: Some(0.0025),
        zx: None,
        name: None,
    };
    let text = std::fs::read_to_string(&path).unwrap();
    let mut u = parse_dyr(&text, &path, None, &bases).unwrap().unit;
    for (p, v) in [("pss.tw4", 5.0), ("pss.t6", 0.05)] {
        let r = u.param(p).unwrap();
        u.set(r, v);
    }
    let event = synthesize(
        "bench",
        &u,
        &VoltageProfile {
            duration_s: 10.0,
            ..Default::default()
        },
        700.0,
        &PmuNoise::typical(1),
        &SimOptions::default(),
    )
    .unwrap();
    if pss_diagram {
        let toml = itaipu_dynamics::unit_file::unit_to_toml(&u);
        let mut out = String::new();
        let mut in_pss = false;
        for line in toml.lines() {
            if line.starts_with('[') {
                in_pss = line == "[pss]";
            }
            if in_pss && line.starts_with("model = ") {
                out.push_str("model = \"diagram\"\ndiagram = \"../diagrams/pss2a.toml\"\n");
            } else if !(in_pss && (line.starts_with("m = ") || line.starts_with("n = "))) {
                out.push_str(line);
                out.push('\n');
            }
        }
        u = itaipu_dynamics::unit_file::parse_unit(&out, &data("thermal/pss2a_diagram.toml"))
            .unwrap();
    }
    (u, PreparedEvent::new(&event))
}

/// Built-in PSS2A against the same PSS2A from diagram primitives, per playback of the thermal
/// unit (RK4 at 1 ms: the same number of right-hand sides for both).
#[divan::bench(sample_count = 30)]
fn thermal_rk4_1ms_builtin_pss2a(bencher: Bencher) {
    bench(
        bencher,
        thermal(false),
        SimOptions {
            method: Method::Rk4 { h: 1e-3 },
        },
    );
}

#[divan::bench(sample_count = 30)]
fn thermal_rk4_1ms_diagram_pss2a(bencher: Bencher) {
    bench(
        bencher,
        thermal(true),
        SimOptions {
            method: Method::Rk4 { h: 1e-3 },
        },
    );
}

/// One right-hand side of the thermal unit at its initial state: with the built-in PSS2A, with
/// the diagram, and without a stabiliser (the difference is the stabiliser's own cost).
fn rhs(bencher: Bencher, pss: Option<bool>) {
    use itaipu_dynamics::integrate::OdeSystem;
    use itaipu_dynamics::unit::{Playback, PlaybackInput};
    let (mut u, _) = thermal(pss == Some(true));
    if pss.is_none() {
        u = u.without(&["pss"]).unwrap();
    }
    let op = itaipu_dynamics::block::InitPoint {
        v_mag: 1.0,
        v_ang: 0.3,
        p: 0.8,
        q: 0.2,
        speed_dev: 0.0,
    };
    let x = u.initialise(&op).unwrap();
    let input = PlaybackInput::linear(vec![0.0, 1.0], vec![1.0, 1.0], vec![0.3, 0.3]);
    let mut sys = Playback::new(&mut u, &input);
    let mut dx = vec![0.0; x.len()];
    let mut t = 0.0;
    bencher.bench_local(|| {
        // A new time each call, so that the bus is evaluated again.
        t += 1e-9;
        sys.rhs(divan::black_box(t), &x, &mut dx);
    });
}

#[divan::bench(sample_count = 200)]
fn thermal_rhs_without_pss(bencher: Bencher) {
    rhs(bencher, None);
}

#[divan::bench(sample_count = 200)]
fn thermal_rhs_builtin_pss2a(bencher: Bencher) {
    rhs(bencher, Some(false));
}

#[divan::bench(sample_count = 200)]
fn thermal_rhs_diagram_pss2a(bencher: Bencher) {
    rhs(bencher, Some(true));
}
