//! Model-extension blocks (`models.md` §12) inside the full synthetic unit (GENSAE + SEXS +
//! STAB3 + HYGOV, `data/synthetic/unit_gensae_sexs_stab3_hygov.toml`), each wired in through
//! unit-file text:
//!
//! * every extension starts in exact steady state (max |dx/dt| < 1e-9), also off nominal;
//! * with inert parameters (zero deadband, very stiff and light shaft, OEL pickup far above,
//!   ceiling far above) P and Q equal the base unit's within 1e-6 on the synthetic 20 s event;
//! * the two-mass shaft's torsional mode shows in Δω_t − Δω_g after a dip at the designed
//!   frequency (zero crossings, within 3 %);
//! * the deadband removes governor action for small frequency deviations, not for large ones;
//! * the OEL activates only when X_adI_fd stays above the pickup long enough, and pulls it back
//!   toward the limit;
//! * the bus-fed ceiling clips E_fd during a dip where the constant-ceiling SEXS does not.

use std::path::Path;

use itaipu_dynamics::block::InitPoint;
use itaipu_dynamics::event::Event;
use itaipu_dynamics::integrate::{Dopri5Options, Method, OdeSystem};
use itaipu_dynamics::simulate::{simulate, SimOptions, Traces};
use itaipu_dynamics::synthetic::{synthesize, PmuNoise, VoltageProfile};
use itaipu_dynamics::unit::{Playback, PlaybackInput, Unit};
use itaipu_dynamics::unit_file::parse_unit;

const BASE: &str = include_str!("../../../data/synthetic/unit_gensae_sexs_stab3_hygov.toml");

/// Replaces exactly one occurrence of `from` in `text`.
fn edit(text: &str, from: &str, to: &str) -> String {
    assert_eq!(
        text.matches(from).count(),
        1,
        "'{from}' must occur once in the unit text"
    );
    text.replacen(from, to, 1)
}

fn unit(text: &str) -> Unit {
    parse_unit(text, Path::new("extensions-test.toml")).unwrap_or_else(|e| panic!("{e}\n{text}"))
}

/// The base unit with the machine inertia split: machine.h = H_g, plus the shaft block.
fn shaft_text(h_t: f64, f_hz: f64, zeta: f64, d_t: f64) -> String {
    let h_g = 4.5 - h_t;
    let t = edit(
        BASE,
        "h = 4.5\n",
        &format!("h = {h_g}\nwiring = {{ pm = \"p_shaft\" }}\n"),
    );
    format!(
        "{t}\n[[block]]\nname = \"shaft\"\nmodel = \"two_mass_shaft\"\nh_turbine = {h_t}\nh_generator = {h_g}\n\
         f_torsion_hz = {f_hz}\nzeta = {zeta}\nd_turbine = {d_t}\n"
    )
}

fn deadband_text(db: f64) -> String {
    let t = edit(
        BASE,
        "model = \"HYGOV\"\n",
        "model = \"HYGOV\"\nwiring = { speed = \"speed_db\" }\n",
    );
    format!("{t}\n[[block]]\nname = \"deadband\"\nmodel = \"speed_deadband\"\ndb = {db}\n")
}

#[allow(clippy::too_many_arguments)]
fn oel_text(
    ifd_rated: f64,
    i_pickup: f64,
    i_limit: f64,
    a_max: f64,
    k_cool: f64,
    k_i: f64,
    voel_min: f64,
) -> String {
    format!(
        "{BASE}\n[[block]]\nname = \"oel\"\nmodel = \"oel\"\nifd_rated = {ifd_rated}\ni_pickup = {i_pickup}\n\
         i_limit = {i_limit}\na_max = {a_max}\nk_cool = {k_cool}\nk_i = {k_i}\nvoel_min = {voel_min}\n"
    )
}

/// The base unit with SEXS's constant limits replaced.
fn sexs_text(e_min: f64, e_max: f64) -> String {
    edit(
        BASE,
        "e_min = 0.0\ne_max = 4.5\n",
        &format!("e_min = {e_min}\ne_max = {e_max}\n"),
    )
}

fn bus_fed_text(vr_min: f64, vr_max: f64, k_c: f64) -> String {
    let t = edit(BASE, "model = \"SEXS\"\n", "model = \"SEXS_bus_fed\"\n");
    edit(
        &t,
        "e_min = 0.0\ne_max = 4.5\n",
        &format!("vr_min = {vr_min}\nvr_max = {vr_max}\nk_c = {k_c}\n"),
    )
}

fn op(p: f64, q: f64, v: f64, ang_deg: f64, f_hz: f64) -> InitPoint {
    InitPoint {
        v_mag: v,
        v_ang: ang_deg.to_radians(),
        p,
        q,
        speed_dev: (f_hz - 60.0) / 60.0,
    }
}

fn operating_points() -> Vec<(&'static str, InitPoint)> {
    vec![
        ("lagging", op(0.8, 0.2, 1.0, 17.0, 60.0)),
        ("leading", op(0.9, -0.25, 1.02, -30.0, 60.0)),
        ("off-nominal 60.012 Hz", op(0.84, 0.03, 0.986, 4.0, 60.012)),
        ("off-nominal 59.6 Hz", op(0.7, 0.1, 1.0, -40.0, 59.6)),
    ]
}

/// Max |dx/dt| at t = 0 (δ: minus its exact ramp ω_b Δω0) and the worst state.
fn worst_derivative(u: &mut Unit, op: &InitPoint) -> (f64, String) {
    let x = u
        .initialise(op)
        .unwrap_or_else(|e| panic!("init failed: {e}"));
    let w_b = 2.0 * std::f64::consts::PI * 60.0;
    let input = PlaybackInput::linear(
        vec![0.0, 1.0],
        vec![op.v_mag, op.v_mag],
        vec![op.v_ang, op.v_ang + w_b * op.speed_dev],
    );
    let names = u.state_names();
    let mut sys = Playback::new(u, &input);
    let mut dx = vec![0.0; x.len()];
    sys.rhs(0.0, &x, &mut dx);
    let mut worst = (0.0, String::new());
    for (k, d) in dx.iter().enumerate() {
        let d = if names[k] == "machine.delta" {
            d - w_b * op.speed_dev
        } else {
            *d
        };
        assert!(d.is_finite(), "{} derivative is not finite", names[k]);
        if d.abs() > worst.0 {
            worst = (d.abs(), names[k].clone());
        }
    }
    worst
}

fn rk4() -> SimOptions {
    SimOptions {
        method: Method::Rk4 { h: 1e-3 },
    }
}

fn tight() -> SimOptions {
    SimOptions {
        method: Method::Dopri5(Dopri5Options {
            rtol: 1e-9,
            atol: 1e-11,
            h_max: 0.01,
            ..Default::default()
        }),
    }
}

/// An event made by playing `profile` into the base unit (no noise).
fn event(profile: &VoltageProfile) -> Event {
    synthesize(
        "ext",
        &unit(BASE),
        profile,
        1000.0,
        &PmuNoise::none(),
        &SimOptions::default(),
    )
    .unwrap()
}

fn sim(text: &str, ev: &Event, opts: &SimOptions) -> Traces {
    simulate(&unit(text), ev, opts).unwrap_or_else(|e| panic!("simulation failed: {e}"))
}

fn col<'a>(tr: &'a Traces, name: &str) -> &'a [f64] {
    tr.get(name).unwrap_or_else(|| panic!("no column {name}"))
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// Max |ΔP|, |ΔQ| (system base) between two trace sets.
fn pq_diff(a: &Traces, b: &Traces) -> f64 {
    max_abs_diff(col(a, "p_pu"), col(b, "p_pu")).max(max_abs_diff(col(a, "q_pu"), col(b, "q_pu")))
}

// ---------------------------------------------------------------------------------------------
// Steady state

#[test]
fn every_extension_starts_in_exact_steady_state() {
    let cases: Vec<(&str, String)> = vec![
        ("base", BASE.to_string()),
        ("two_mass_shaft", shaft_text(0.45, 8.0, 0.05, 0.3)),
        ("speed_deadband", deadband_text(0.0003)),
        ("speed_deadband db = 0", deadband_text(0.0)),
        ("oel", oel_text(2.6, 1.05, 1.02, 0.7, 0.05, 0.02, -0.3)),
        ("SEXS_bus_fed", bus_fed_text(-1.0, 6.0, 0.15)),
    ];
    for (label, text) in &cases {
        let mut u = unit(text);
        for (at, op) in operating_points() {
            let (d, state) = worst_derivative(&mut u, &op);
            assert!(d < 1e-9, "{label} at {at}: |d{state}/dt| = {d:e}");
        }
    }
}

#[test]
fn extension_outputs_start_at_their_steady_values() {
    let (_, op0) = operating_points()[3]; // 59.6 Hz: speed deviation beyond the deadband
    let mut u = unit(&deadband_text(0.0003));
    u.initialise(&op0).unwrap();
    let sig = |u: &Unit, n: &str| u.bus()[u.signal_index(n).unwrap()];
    assert!((sig(&u, "speed_db") - (op0.speed_dev + 0.0003)).abs() < 1e-15);

    let mut u = unit(&shaft_text(0.45, 8.0, 0.05, 0.3));
    u.initialise(&op0).unwrap();
    let w0 = op0.speed_dev;
    assert_eq!(sig(&u, "speed_turbine"), w0);
    // pm0 = (T_s0 + D_t Δω0)(1 + Δω0) with T_s0 = p_shaft0/(1 + Δω0).
    let ts0 = sig(&u, "p_shaft") / (1.0 + w0);
    assert!((sig(&u, "pm") - (ts0 + 0.3 * w0) * (1.0 + w0)).abs() < 1e-14);

    let mut u = unit(&oel_text(2.6, 1.05, 1.02, 0.7, 0.05, 0.02, -0.3));
    u.initialise(&op0).unwrap();
    assert_eq!(sig(&u, "voel"), 0.0);
}

#[test]
fn an_oel_already_above_pickup_or_an_unreachable_ceiling_is_an_init_error() {
    let (_, op0) = operating_points()[0];
    let err = unit(&oel_text(1.0, 1.05, 1.02, 0.7, 0.05, 0.02, -0.3))
        .initialise(&op0)
        .unwrap_err()
        .to_string();
    assert!(err.contains("oel") && err.contains("pickup"), "{err}");
    let err = unit(&bus_fed_text(0.0, 1.5, 0.15))
        .initialise(&op0)
        .unwrap_err()
        .to_string();
    assert!(err.contains("exciter") && err.contains("VRMAX"), "{err}");
}

// ---------------------------------------------------------------------------------------------
// Inert parameters reproduce the base unit

#[test]
fn inert_extensions_reproduce_the_base_unit() {
    let ev = event(&VoltageProfile::default());
    let opts = rk4();
    let base = sim(BASE, &ev, &opts);

    let d = pq_diff(&sim(&deadband_text(0.0), &ev, &opts), &base);
    eprintln!("speed_deadband db = 0: max |ΔP|, |ΔQ| = {d:.2e}");
    assert!(d < 1e-6, "deadband {d:e}");

    let d = pq_diff(
        &sim(
            &oel_text(2.6, 3.0, 2.9, 100.0, 0.05, 0.02, -0.3),
            &ev,
            &opts,
        ),
        &base,
    );
    eprintln!("oel, pickup far above: max |ΔP|, |ΔQ| = {d:.2e}");
    assert!(d < 1e-6, "oel {d:e}");

    // The base unit with its ceiling far away too, and the bus-fed one with K_C = 0.
    let far = sim(&sexs_text(-100.0, 100.0), &ev, &opts);
    let d = pq_diff(&sim(&bus_fed_text(-100.0, 100.0, 0.0), &ev, &opts), &far);
    eprintln!("SEXS_bus_fed, ceiling far above: max |ΔP|, |ΔQ| = {d:.2e}");
    assert!(d < 1e-6, "bus-fed {d:e}");
    // And the base unit does reach its ceiling on this event, so the comparison above is the
    // honest one (a constant E_MAX = 4.5 clips).
    assert!(
        col(&base, "efd").iter().any(|&e| e >= 4.5 - 1e-9),
        "base unit never reaches E_MAX"
    );

    // A light, very stiff shaft (H_t = 0.01 s of the 4.5 s, ζ = 0.7): the two masses move as one.
    // Stiffness is what makes it inert, not lightness: the turbine's own self-regulation
    // ∂(P_m/(1 + Δω_t))/∂Δω_t ≈ −P_m must be small against the shaft's K_s and D_s, which
    // shrink with H_t at a given frequency. An adaptive integrator resolves the fast mode; the
    // base unit is run with the same settings.
    let opts = tight();
    let base = sim(BASE, &ev, &opts);
    let d200 = pq_diff(&sim(&shaft_text(0.01, 200.0, 0.7, 0.0), &ev, &opts), &base);
    let d400 = pq_diff(&sim(&shaft_text(0.01, 400.0, 0.7, 0.0), &ev, &opts), &base);
    eprintln!(
        "two_mass_shaft, H_t = 0.01 s: max |ΔP|, |ΔQ| = {d200:.2e} at 200 Hz, {d400:.2e} at 400 Hz"
    );
    assert!(d400 < 1e-6, "shaft {d400:e}");
    assert!(
        d400 < d200 / 3.0,
        "the difference must vanish as the shaft stiffens (∝ 1/f²)"
    );
}

// ---------------------------------------------------------------------------------------------
// Two-mass shaft: the torsional mode

/// Frequency [Hz] of `y(t)` from its upward zero crossings in `[t0, t1]` (linear interpolation
/// between samples): (number of full cycles)/(time between the first and last crossing).
fn zero_crossing_frequency(t: &[f64], y: &[f64], t0: f64, t1: f64) -> (f64, usize) {
    let mut ups = vec![];
    for k in 1..t.len() {
        if t[k - 1] < t0 || t[k] > t1 {
            continue;
        }
        if y[k - 1] < 0.0 && y[k] >= 0.0 {
            ups.push(t[k - 1] + (t[k] - t[k - 1]) * (-y[k - 1]) / (y[k] - y[k - 1]));
        }
    }
    assert!(ups.len() >= 3, "too few zero crossings: {}", ups.len());
    let cycles = ups.len() - 1;
    (cycles as f64 / (ups[cycles] - ups[0]), cycles)
}

#[test]
fn torsional_mode_appears_at_the_designed_frequency() {
    // A dip without grid swing or frequency drift, sampled at 1 kHz so that an 8 Hz mode is
    // resolved by the recorded traces.
    let profile = VoltageProfile {
        duration_s: 4.0,
        rate_hz: 1000.0,
        dip_start_s: 1.0,
        dip_duration_s: 0.1,
        dip_v: 0.6,
        angle_step: 0.0,
        swing_amp: 0.0,
        freq_dev_hz: 0.0,
        ..VoltageProfile::default()
    };
    let ev = event(&profile);
    for (f_tor, zeta) in [(8.0, 0.02), (5.0, 0.03)] {
        let tr = sim(&shaft_text(0.45, f_tor, zeta, 0.0), &ev, &tight());
        let wt = col(&tr, "speed_turbine");
        let wg = col(&tr, "speed");
        let rel: Vec<f64> = wt.iter().zip(wg).map(|(a, b)| a - b).collect();
        let amp = rel.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let (f, cycles) = zero_crossing_frequency(&tr.time_s, &rel, 1.15, 3.5);
        let err = (f - f_tor) / f_tor;
        eprintln!(
            "two_mass_shaft f_tor = {f_tor} Hz, ζ = {zeta}: measured {f:.4} Hz over {cycles} cycles \
             (error {:+.2} %), max |Δω_t − Δω_g| = {amp:.2e} pu",
            100.0 * err
        );
        assert!(
            err.abs() < 0.03,
            "torsional frequency {f} Hz vs designed {f_tor} Hz"
        );
        assert!(amp > 1e-6, "the dip must excite the mode");
        // The mode is damped: the late oscillation is smaller than the early one.
        let window_max = |a: f64, b: f64| {
            tr.time_s
                .iter()
                .zip(&rel)
                .filter(|(t, _)| **t >= a && **t < b)
                .fold(0.0f64, |m, (_, v)| m.max(v.abs()))
        };
        assert!(
            window_max(3.0, 3.5) < window_max(1.2, 1.7),
            "torsional oscillation must decay"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Speed deadband

/// Change of the governor's P_m from start to end of a pure frequency ramp (no dip, no swing).
fn pm_change(text: &str, freq_dev_hz: f64) -> f64 {
    let profile = VoltageProfile {
        duration_s: 60.0,
        rate_hz: 30.0,
        dip_v: 1.0,
        angle_step: 0.0,
        swing_amp: 0.0,
        freq_dev_hz,
        freq_tau_s: 2.0,
        ..VoltageProfile::default()
    };
    let tr = sim(text, &event(&profile), &SimOptions::default());
    let pm = col(&tr, "pm");
    pm[pm.len() - 1] - pm[0]
}

#[test]
fn deadband_removes_governor_action_for_small_deviations_only() {
    let db = 0.0003; // 0.018 Hz at 60 Hz
                     // Small: −0.01 Hz (Δω = −1.7e-4 pu, inside the band).
    let (free, banded) = (pm_change(BASE, -0.01), pm_change(&deadband_text(db), -0.01));
    eprintln!("speed_deadband, −0.01 Hz: ΔP_m without {free:.3e}, with {banded:.3e}");
    assert!(
        free > 2e-3,
        "the governor must respond without a deadband ({free:e})"
    );
    assert!(
        banded.abs() < 1e-9,
        "inside the band the governor must not act ({banded:e})"
    );
    // Large: −0.2 Hz (Δω = −3.3e-3 pu): the response shrinks only by the band's share.
    let dw: f64 = 0.2 / 60.0;
    let (free, banded) = (pm_change(BASE, -0.2), pm_change(&deadband_text(db), -0.2));
    let ratio = banded / free;
    let expected = (dw - db) / dw;
    eprintln!("speed_deadband, −0.2 Hz: ΔP_m without {free:.4e}, with {banded:.4e}, ratio {ratio:.4} (expected {expected:.4})");
    assert!(free > 0.04, "{free:e}");
    assert!(
        (ratio - expected).abs() < 0.02,
        "ratio {ratio} vs {expected}"
    );
}

// ---------------------------------------------------------------------------------------------
// Over-excitation limiter

/// X_adI_fd at the event's operating point (base unit).
fn xadifd0(ev: &Event) -> f64 {
    let mut u = unit(BASE);
    let op = itaipu_dynamics::simulate::PreparedEvent::new(ev).init_point(&u);
    u.initialise(&op).unwrap();
    u.bus()[u.signal_index("xadifd").unwrap()]
}

/// Integral gain of the OEL in the dynamic tests. The loop gain is about K_i·K/I_fd,rated
/// (SEXS K = 100, rated ≈ 1.5): 0.002 keeps it near 0.1/s, well inside the AVR's lead-lag and
/// the field's T'_d.
const K_I: f64 = 0.002;

#[test]
fn oel_acts_only_on_a_sustained_overload_and_pulls_the_field_current_back() {
    let (i_pu, i_lim, a_max) = (1.05, 1.02, 2.0);
    // Short: the default event's 0.1 s dip to 0.7 pu drives the field current above the pickup,
    // but not for long enough to use up A_max.
    let ev = event(&VoltageProfile::default());
    let rated = xadifd0(&ev); // rated = the initial field current (I0 = 1 pu of rated)
    let text = oel_text(rated, i_pu, i_lim, a_max, 0.05, K_I, -0.3);
    let tr = sim(&text, &ev, &SimOptions::default());
    let i_max = col(&tr, "xadifd").iter().fold(0.0f64, |m, v| m.max(*v)) / rated;
    let a_peak = col(&tr, "oel.a").iter().fold(0.0f64, |m, v| m.max(*v));
    eprintln!(
        "oel, short dip: max I = {i_max:.3} pu of rated, peak A = {a_peak:.3} (A_max {a_max})"
    );
    assert!(
        i_max > i_pu,
        "the short dip must cross the pickup ({i_max})"
    );
    assert!(a_peak > 0.0 && a_peak < a_max);
    assert!(
        col(&tr, "voel").iter().all(|&v| v == 0.0),
        "a short overload must not activate the OEL"
    );
    // Only the heating/cooling events (extra step ends) distinguish it from the base unit.
    let d = pq_diff(&sim(&text, &ev, &rk4()), &sim(BASE, &ev, &rk4()));
    eprintln!("oel, short dip: max |ΔP|, |ΔQ| against the base unit = {d:.2e}");
    assert!(d < 1e-6, "{d:e}");

    // Sustained: |V| held at 0.9 pu for 40 s; the AVR drives the field current far above rated.
    let profile = VoltageProfile {
        duration_s: 41.0,
        rate_hz: 30.0,
        dip_start_s: 1.0,
        dip_duration_s: 40.0,
        dip_v: 0.9,
        angle_step: 0.0,
        swing_amp: 0.0,
        freq_dev_hz: 0.0,
        ..VoltageProfile::default()
    };
    let ev = event(&profile);
    let rated = xadifd0(&ev);
    let text = oel_text(rated, i_pu, i_lim, a_max, 0.05, K_I, -0.3);
    let with = sim(&text, &ev, &SimOptions::default());
    let without = sim(BASE, &ev, &SimOptions::default());
    let t = &with.time_s;
    let i_with: Vec<f64> = col(&with, "xadifd").iter().map(|v| v / rated).collect();
    let i_without: Vec<f64> = col(&without, "xadifd").iter().map(|v| v / rated).collect();
    let voel = col(&with, "voel");
    let k_pick = i_with
        .iter()
        .position(|&i| i > i_pu)
        .expect("overload must cross the pickup");
    let k_act = voel
        .iter()
        .position(|&v| v < 0.0)
        .expect("the OEL must activate");
    // I²t between pickup and activation: A_max (the accumulator starts at 0).
    let mut a = 0.0;
    for k in k_pick..k_act {
        a += 0.5
            * (t[k + 1] - t[k])
            * (i_with[k].powi(2) + i_with[k + 1].powi(2) - 2.0 * i_pu * i_pu).max(0.0);
    }
    let k_end = t.iter().position(|&s| s >= 40.9).unwrap();
    eprintln!(
        "oel, sustained: pickup at {:.2} s, active at {:.2} s (∫(I²−I_pu²)dt ≈ {a:.3}, A_max {a_max}); \
         at {:.1} s I = {:.4} with OEL, {:.4} without (I_lim {i_lim}); min V_OEL = {:.4}",
        t[k_pick],
        t[k_act],
        t[k_end],
        i_with[k_end],
        i_without[k_end],
        voel.iter().fold(0.0f64, |m, v| m.min(*v))
    );
    assert!(
        t[k_act] > t[k_pick] + 0.1,
        "activation must wait for the I²t capacity"
    );
    assert!(
        (a - a_max).abs() < 0.1 * a_max,
        "activated after ∫ = {a}, A_max = {a_max}"
    );
    assert!(
        i_without[k_end] > i_lim + 0.1,
        "without the OEL the overload persists"
    );
    assert!(
        (i_with[k_end] - i_lim).abs() < 0.1,
        "the OEL must pull I back to I_lim ({})",
        i_with[k_end]
    );
    let k_mid = t.iter().position(|&s| s >= 30.0).unwrap();
    assert!(
        i_with[k_mid] > i_with[k_end] && i_with[k_mid] < i_without[k_mid],
        "I must fall toward I_lim"
    );
    assert!(
        voel.iter().all(|&v| (-0.3..=0.0).contains(&v)),
        "V_OEL must stay in [V_OEL,min, 0]"
    );
}

// ---------------------------------------------------------------------------------------------
// Bus-fed ceiling

#[test]
fn bus_fed_ceiling_clips_efd_in_a_dip_where_the_constant_ceiling_does_not() {
    let profile = VoltageProfile {
        duration_s: 5.0,
        rate_hz: 240.0,
        dip_start_s: 1.0,
        dip_duration_s: 0.3,
        dip_v: 0.8,
        angle_step: 0.0,
        swing_amp: 0.0,
        freq_dev_hz: 0.0,
        ..VoltageProfile::default()
    };
    let ev = event(&profile);
    let (vr_max, k_c) = (6.0, 0.15);
    let constant = sim(&sexs_text(0.0, vr_max), &ev, &SimOptions::default());
    let bus_fed = sim(&bus_fed_text(0.0, vr_max, k_c), &ev, &SimOptions::default());
    let efd_c = col(&constant, "efd");
    let efd_b = col(&bus_fed, "efd");
    let ceiling: Vec<f64> = col(&bus_fed, "v_term")
        .iter()
        .zip(col(&bus_fed, "xadifd"))
        .map(|(v, i)| v * vr_max - k_c * i)
        .collect();
    let max_c = efd_c.iter().fold(0.0f64, |m, v| m.max(*v));
    let max_b = efd_b.iter().fold(0.0f64, |m, v| m.max(*v));
    let on_ceiling = efd_b
        .iter()
        .zip(&ceiling)
        .filter(|(e, c)| (*e - *c).abs() < 1e-9)
        .count();
    let above = efd_b
        .iter()
        .zip(&ceiling)
        .map(|(e, c)| e - c)
        .fold(f64::MIN, f64::max);
    let ceiling_min = ceiling.iter().fold(f64::MAX, |m, v| m.min(*v));
    eprintln!(
        "SEXS_bus_fed, dip to {}: max E_fd {max_b:.4} (bus-fed) vs {max_c:.4} (constant E_MAX {vr_max}); \
         {on_ceiling} samples on the ceiling (lowest {ceiling_min:.4}); max E_fd − ceiling {above:.2e}",
        profile.dip_v
    );
    assert!(
        max_c < vr_max - 0.05,
        "the constant ceiling must not clip ({max_c})"
    );
    assert!(
        max_c > ceiling_min + 0.1,
        "the dip must ask for more than the bus-fed ceiling"
    );
    assert!(
        on_ceiling >= 5,
        "the bus-fed exciter must sit on its ceiling during the dip"
    );
    assert!(
        above <= 1e-9,
        "E_fd must never exceed the bus-fed ceiling ({above:e})"
    );
    assert!(max_b < max_c - 0.1);
}

/// Issue 25: in a deep dip with a high field current the commutation drop takes the bus-fed
/// ceiling `V_t·V_RMAX − K_C·X_adI_fd` below the floor `V_t·V_RMIN` (here a floor just under
/// E_fd0, as a diagnosis's search may try). The simulation used to panic there (`f64::clamp`
/// with min > max, from `diagnose` through Python); the bridge delivers the ceiling.
#[test]
fn a_bus_fed_ceiling_below_its_floor_in_a_deep_dip_gives_the_ceiling() {
    let profile = VoltageProfile {
        duration_s: 3.0,
        rate_hz: 240.0,
        dip_start_s: 1.0,
        dip_duration_s: 0.2,
        dip_v: 0.3,
        angle_step: 0.0,
        swing_amp: 0.0,
        freq_dev_hz: 0.0,
        ..VoltageProfile::default()
    };
    let ev = event(&profile);
    let base = sim(BASE, &ev, &SimOptions::default());
    let (efd0, i0, v0) = (
        col(&base, "efd")[0],
        col(&base, "xadifd")[0],
        col(&base, "v_term")[0],
    );
    // Feasible at the operating point: floor 0.1 below E_fd0, ceiling 0.1 above it.
    let k_c = 0.2;
    let vr_min = (efd0 - 0.1) / v0;
    let vr_max = (efd0 + 0.1 + k_c * i0) / v0;
    let tr = sim(
        &bus_fed_text(vr_min, vr_max, k_c),
        &ev,
        &SimOptions::default(),
    );
    let (efd, v, i) = (col(&tr, "efd"), col(&tr, "v_term"), col(&tr, "xadifd"));
    let mut crossed = 0;
    for k in 0..efd.len() {
        let (floor, ceiling) = (v[k] * vr_min, v[k] * vr_max - k_c * i[k]);
        assert!(
            efd[k] <= ceiling + 1e-9,
            "E_fd {} above the ceiling {ceiling} at sample {k}",
            efd[k]
        );
        if ceiling < floor {
            crossed += 1;
            assert!(
                (efd[k] - ceiling).abs() < 1e-9,
                "ceiling {ceiling} below the floor {floor}: E_fd {} must be the ceiling",
                efd[k]
            );
        }
    }
    assert!(
        crossed >= 5,
        "the dip must take the ceiling below the floor ({crossed} samples)"
    );
}

/// `base` with a `pmu_measurement` block named "measurement" at its defaults.
fn with_measurement(base: &Unit) -> Unit {
    let mut with = base.clone();
    with.put(
        "measurement",
        itaipu_dynamics::registry::find("pmu_measurement")
            .unwrap()
            .create(),
        &[],
    )
    .unwrap();
    with
}

/// `pmu_measurement`: neutral by default; otherwise skew, phase and ratio as documented.
#[test]
fn pmu_measurement_applies_skew_phase_and_ratio() {
    use itaipu_dynamics::simulate::{simulate_pq, PreparedEvent, SimOptions};
    use itaipu_dynamics::synthetic::{delayed, synthesize, PmuNoise, VoltageProfile};
    let path = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../data/synthetic/unit_gensae_sexs_stab3_hygov.toml");
    let base = itaipu_dynamics::unit_file::read_unit(&path).unwrap();
    let profile = VoltageProfile {
        duration_s: 5.0,
        ..Default::default()
    };
    let ev = synthesize(
        "m",
        &base,
        &profile,
        737.0,
        &PmuNoise::none(),
        &SimOptions::default(),
    )
    .unwrap();
    let prep = PreparedEvent::new(&ev);
    let (p0, q0) = simulate_pq(&mut base.clone(), &prep, &SimOptions::default()).unwrap();
    let mut with = with_measurement(&base);
    let (p1, q1) = simulate_pq(&mut with.clone(), &prep, &SimOptions::default()).unwrap();
    assert_eq!((&p0, &q0), (&p1, &q1), "defaults change nothing");
    let set = |u: &mut itaipu_dynamics::unit::Unit, name: &str, v: f64| {
        let r = u.param(&format!("measurement.{name}")).unwrap();
        u.set(r, v);
    };
    set(&mut with, "pq_delay_s", 0.012);
    set(&mut with, "phase_deg", 0.5);
    set(&mut with, "p_ratio", 1.01);
    set(&mut with, "q_ratio", 0.99);
    let (p2, q2) = simulate_pq(&mut with.clone(), &prep, &SimOptions::default()).unwrap();
    let t = &prep.input.time_s;
    let (pd, qd) = (delayed(t, &p0, 0.012), delayed(t, &q0, 0.012));
    let (s, c) = 0.5f64.to_radians().sin_cos();
    for k in 0..t.len() {
        assert!((p2[k] - 1.01 * (pd[k] * c + qd[k] * s)).abs() < 1e-12);
        assert!((q2[k] - 0.99 * (qd[k] * c - pd[k] * s)).abs() < 1e-12);
    }
    // The skew is visible after the dip: a 12 ms delay of a fast power swing.
    let worst = p0
        .iter()
        .zip(&pd)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(worst > 0.01, "skew effect {worst}");
}

#[test]
fn terminal_load_is_delivered_by_the_machine_and_missing_from_the_recording() {
    // A 4 % P, 2 % Q constant-impedance load between the machine and the PMU.
    let text = format!("{BASE}\n[[block]]\nname = \"load\"\nmodel = \"terminal_load\"\np_load = 0.04\nq_load = 0.02\nn_p = 2.0\nn_q = 2.0\n");
    let ev = event(&VoltageProfile::preset(
        itaipu_dynamics::synthetic::EventKind::FaultDip,
        5.0,
        60.0,
        1,
    ));
    let tr = sim(&text, &ev, &tight());
    let (p, pe, qe, q, v) = (
        col(&tr, "p_mach_pu"),
        col(&tr, "pe"),
        col(&tr, "qe"),
        col(&tr, "q_mach_pu"),
        col(&tr, "v_term"),
    );
    // The recording is the machine's output minus the load at the played-back voltage, exactly.
    for k in 0..p.len() {
        assert!(
            (pe[k] - p[k] - 0.04 * v[k] * v[k]).abs() < 1e-12,
            "P at sample {k}"
        );
        assert!(
            (qe[k] - q[k] - 0.02 * v[k] * v[k]).abs() < 1e-12,
            "Q at sample {k}"
        );
    }
    // It starts at the measured operating point (the machine delivers P0 + P_L(V0)).
    let op = ev.operating_point();
    let to_mach = ev.system_mva / 737.0;
    assert!((p[0] - op.p_pu * to_mach).abs() < 1e-9 && (q[0] - op.q_pu * to_mach).abs() < 1e-9);
    // In the dip the load falls with V²: the recording differs from the base unit's.
    let base = sim(BASE, &ev, &tight());
    assert!(
        pq_diff(&tr, &base) > 0.01,
        "the load must change what the PMU sees in a dip"
    );
    // And the unit with the load starts in exact steady state at any operating point.
    let mut u = unit(&text);
    for (at, op) in operating_points() {
        let (d, state) = worst_derivative(&mut u, &op);
        assert!(d < 1e-9, "terminal_load at {at}: |d{state}/dt| = {d:e}");
    }
}

/// `pmu_measurement`'s delay on a record without skew, the voltage channel's PMU noise played
/// back into the simulation: χ² over delays of 0 to 2 sample intervals is lowest within a tenth
/// of a sample of zero on every event kind and seed. With linear interpolation of the fraction it
/// was lowest near half a sample (the interpolation smooths the noise the playback carries from
/// the measured voltage into P and Q, most at half a sample), a skew where there is none.
#[test]
fn a_delay_fitted_to_a_record_without_skew_finds_none() {
    use itaipu_dynamics::simulate::{simulate_pq, PreparedEvent, SimOptions};
    use itaipu_dynamics::synthetic::EventKind;
    let base = unit(BASE);
    let rate = 60.0;
    for (kind, seed) in [
        (EventKind::FaultDip, 3),
        (EventKind::Ambient, 4),
        (EventKind::FrequencyExcursion, 5),
    ] {
        let profile = VoltageProfile::preset(kind, 12.0, rate, seed);
        let ev = synthesize(
            "no skew",
            &base,
            &profile,
            737.0,
            &PmuNoise::typical(seed),
            &SimOptions::default(),
        )
        .unwrap();
        let prep = PreparedEvent::new(&ev);
        let with = with_measurement(&base);
        let r = with.param("measurement.pq_delay_s").unwrap();
        let chi2: Vec<(f64, f64)> = (0..=20)
            .map(|i| {
                let samples = i as f64 / 10.0;
                let mut u = with.clone();
                u.set(r, samples / rate);
                let (p, q) = simulate_pq(&mut u, &prep, &SimOptions::default()).unwrap();
                let rec = &ev.record;
                let s: f64 = (0..p.len())
                    .map(|k| (p[k] - rec.p_pu[k]).powi(2) + (q[k] - rec.q_pu[k]).powi(2))
                    .sum();
                (samples, s)
            })
            .collect();
        let best = chi2.iter().min_by(|a, b| a.1.total_cmp(&b.1)).unwrap();
        assert!(
            best.0 <= 0.1,
            "{kind:?}: χ² lowest at {} samples of delay: {chi2:?}",
            best.0
        );
    }
}
