//! Forward sensitivities (`itaipu_dynamics::sens`) against central differences of the same
//! discretised playback: for every machine model and every one of its parameters, `∂P/∂p` and
//! `∂Q/∂p` at every sample agree to 1e-5 of the column's largest value. The event is the
//! synthetic fault dip with M-class PMU noise on the played-back voltage (fixed seed).
//!
//! The differences are taken on the steps of the unperturbed adaptive playback (a replay), so
//! both sides differentiate the same discrete map and step-size noise does not enter.

use itaipu_dynamics::event::Event;
use itaipu_dynamics::integrate::{Method, StepLog};
use itaipu_dynamics::registry;
use itaipu_dynamics::sens::{simulate_pq_sensitivities, SensError};
use itaipu_dynamics::simulate::{simulate_pq, PreparedEvent, SimOptions};
use itaipu_dynamics::synthetic::{synthesize, PmuNoise, VoltageProfile};
use itaipu_dynamics::unit::{ParamRef, Unit};

fn unit(blocks: &[(&str, &str)]) -> Unit {
    let mut u = Unit::new("sens", 737.0, 60.0);
    for (name, model) in blocks {
        u.add(name, registry::find(model).unwrap().create(), &[])
            .unwrap();
    }
    u.finish().unwrap();
    // Damping inside its domain: at D = 0 the differences would be one-sided and their
    // rounding error (1e-13 / h) of the order of the tolerance.
    let d = u.param("machine.d").unwrap();
    u.set(d, 0.5);
    u
}

/// A 10 s dip to `dip_v` with PMU noise on |V| and the angle, made by `truth`.
fn event_to(truth: &Unit, dip_v: f64) -> Event {
    let profile = VoltageProfile {
        duration_s: 10.0,
        dip_v,
        ..Default::default()
    };
    let opts = SimOptions::default();
    synthesize("dip", truth, &profile, 737.0, &PmuNoise::typical(7), &opts).unwrap()
}

/// The synthetic fault dip (to 0.7 pu): SEXS reaches its ceiling.
fn event(truth: &Unit) -> Event {
    event_to(truth, 0.7)
}

/// The default adaptive method's step schedule for `u` on `ev`.
fn steps(u: &Unit, ev: &PreparedEvent) -> Method {
    let Method::Dopri5(o) = SimOptions::default().method else {
        unreachable!()
    };
    let log = StepLog::default();
    let logged = SimOptions {
        method: Method::Dopri5Logged(o, log.clone()),
    };
    simulate_pq(&mut u.clone(), ev, &logged).unwrap();
    Method::Replay(log.times())
}

/// `(∂P/∂p, ∂Q/∂p)` by central differences of the replayed playback (second-order one-sided
/// where the lower point is outside the parameter's domain, as for D = 0).
fn differences(u: &Unit, ev: &PreparedEvent, r: ParamRef, m: &Method) -> (Vec<f64>, Vec<f64>, f64) {
    let opts = SimOptions { method: m.clone() };
    let p0 = u.get(r);
    // A step the parameter's plausible range measures (D's value is 0).
    let (lo, hi) = u.param_spec(r).range;
    let h = 1e-5 * p0.abs().max(0.1 * (hi - lo));
    let at = |v: f64| {
        let mut w = u.clone();
        w.set(r, v);
        simulate_pq(&mut w, ev, &opts).ok()
    };
    let (up, dn) = (at(p0 + h).unwrap(), at(p0 - h));
    let col = |f: &dyn Fn(usize) -> f64, n: usize| (0..n).map(f).collect::<Vec<_>>();
    let n = up.0.len();
    match dn {
        Some(dn) => (
            col(&|k| (up.0[k] - dn.0[k]) / (2.0 * h), n),
            col(&|k| (up.1[k] - dn.1[k]) / (2.0 * h), n),
            h,
        ),
        None => {
            let (f0, f2) = (at(p0).unwrap(), at(p0 + 2.0 * h).unwrap());
            (
                col(
                    &|k| (4.0 * (up.0[k] - f0.0[k]) - (f2.0[k] - f0.0[k])) / (2.0 * h),
                    n,
                ),
                col(
                    &|k| (4.0 * (up.1[k] - f0.1[k]) - (f2.1[k] - f0.1[k])) / (2.0 * h),
                    n,
                ),
                h,
            )
        }
    }
}

/// Whether a sensitivity column matches the differences: within 1e-5 of the column's largest
/// value, plus the differences' own rounding floor (a playback's values carry ~1e-14 of
/// accumulated rounding, divided by the step `h`), which decides only for near-zero columns.
fn mismatch(s: &[f64], fd: &[f64], h: f64) -> f64 {
    let scale = fd.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let err = s
        .iter()
        .zip(fd)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    err / (1e-5 * scale + 1e-13 / h)
}

/// Every parameter of `u`: the sensitivities against the differences, and most of them
/// moving P or Q on the event.
fn check_every_parameter(label: &str, u: &Unit, dip_v: f64) {
    let ev = PreparedEvent::new(&event_to(u, dip_v));
    let m = steps(u, &ev);
    let refs: Vec<ParamRef> = u
        .params()
        .iter()
        .map(|(path, _, _)| u.param(path).unwrap())
        .collect();
    let s = simulate_pq_sensitivities(u, &ev, &refs, &SimOptions { method: m.clone() })
        .unwrap_or_else(|e| panic!("{label}: {e}"));
    // The values are the replayed playback's.
    let (p, q) = simulate_pq(&mut u.clone(), &ev, &SimOptions { method: m.clone() }).unwrap();
    let dv = p.iter().zip(&s.p).chain(q.iter().zip(&s.q));
    assert!(
        dv.fold(0.0f64, |a, (x, y)| a.max((x - y).abs())) < 1e-12,
        "{label}: values"
    );
    let mut moved = 0;
    let mut worst = (0.0f64, String::new());
    for (j, &r) in refs.iter().enumerate() {
        let (fp, fq, h) = differences(u, &ev, r, &m);
        let (ep, eq) = (mismatch(&s.dp[j], &fp, h), mismatch(&s.dq[j], &fq, h));
        let name = u.param_path(r);
        if ep.max(eq) > worst.0 {
            worst = (ep.max(eq), name.clone());
        }
        assert!(
            ep < 1.0 && eq < 1.0,
            "{label} {name}: ∂P/∂p off by {ep:.2} × the tolerance, ∂Q/∂p by {eq:.2}"
        );
        let big = |c: &[f64]| c.iter().any(|v| v.abs() > 1e-4);
        moved += usize::from(big(&fp) || big(&fq));
    }
    eprintln!(
        "{label}: worst {:.3} × the tolerance ({})",
        worst.0, worst.1
    );
    // Most parameters move P or Q on this event: the comparison is not of zeros.
    assert!(
        moved * 2 > refs.len(),
        "{label}: only {moved} of {} parameters move P or Q",
        refs.len()
    );
}

#[test]
fn every_machine_parameter_s_sensitivity_matches_differences() {
    for machine in ["GENROU", "GENSAL", "GENSAE", "GENCLS"] {
        check_every_parameter(machine, &unit(&[("machine", machine)]), 0.7);
    }
}

/// The practice units (GENSAE, SEXS, STAB3, HYGOV) and the Itaipu one (constant P_m): the dip
/// drives SEXS onto its ceiling, so the pinned state's sensitivity is exercised.
#[test]
fn every_parameter_of_a_whole_unit_matches_differences() {
    let practice = unit(&[
        ("machine", "GENSAE"),
        ("exciter", "SEXS"),
        ("pss", "STAB3"),
        ("governor", "HYGOV"),
    ]);
    check_every_parameter("GENSAE+SEXS+STAB3+HYGOV", &practice, 0.9);
    let itaipu = unit(&[
        ("machine", "GENSAE"),
        ("exciter", "SEXS"),
        ("pss", "STAB3"),
        ("governor", "constant_pm"),
    ]);
    check_every_parameter("GENSAE+SEXS+STAB3+constant_pm", &itaipu, 0.9);
    // IEEET1 (rate feedback, quadratic exciter saturation, the regulator's non-windup limit).
    let ieeet1 = unit(&[
        ("machine", "GENROU"),
        ("exciter", "IEEET1"),
        ("governor", "HYGOV"),
    ]);
    check_every_parameter("GENROU+IEEET1+HYGOV", &ieeet1, 0.9);
    // IEEEST with its notch filter of order 4 (A1..A4 and A5 non-zero: the canonical form's
    // coefficients move with them) reading the speed.
    let mut ieeest = unit(&[
        ("machine", "GENSAE"),
        ("exciter", "SEXS"),
        ("pss", "IEEEST"),
        ("governor", "HYGOV"),
    ]);
    for (p, v) in [
        ("pss.a1", 0.05),
        ("pss.a2", 0.002),
        ("pss.a3", 0.04),
        ("pss.a4", 0.001),
        ("pss.a5", 0.02),
    ] {
        let r = ieeest.param(p).unwrap();
        ieeest.set(r, v);
    }
    check_every_parameter("GENSAE+SEXS+IEEEST+HYGOV", &ieeest, 0.9);
    // ESST1A (two lead-lags, the rate feedback, the field current limiter and the bus-fed
    // ceiling with its commutation term).
    let mut esst1a = unit(&[
        ("machine", "GENROU"),
        ("exciter", "ESST1A"),
        ("governor", "HYGOV"),
    ]);
    for (p, v) in [
        ("exciter.k_f", 0.02),
        ("exciter.k_lr", 1.0),
        ("exciter.i_lr", 2.0),
        ("exciter.t_c1", 0.5),
        ("exciter.t_b1", 1.0),
    ] {
        let r = esst1a.param(p).unwrap();
        esst1a.set(r, v);
    }
    check_every_parameter("GENROU+ESST1A+HYGOV", &esst1a, 0.9);
    // ST5B: the transducer, both lead-lags of the main path (T_C1/T_B1 and T_C2/T_B2, their
    // outputs limited to V_R/K_R), the bridge lag T_1 and a large commutation term K_C. With
    // K_C = 0.3 and V_RMAX = 4 the K_C-reduced ceiling V_RMAX − K_C·X_adI_fd stays below the
    // supply ceiling V_T·V_RMAX on this dip, so the bridge never pins (at the defaults it does:
    // see `st5b_through_its_supply_ceiling`). The alternate UEL/OEL pairs stay inactive
    // without their gates (zero columns). Measured: ST5B's parameters within 0.074 of the
    // tolerance (T_1), the unit's within 0.27 (the machine's R_a).
    let mut st5b = unit(&[
        ("machine", "GENROU"),
        ("exciter", "ST5B"),
        ("governor", "HYGOV"),
    ]);
    for (p, v) in [("exciter.k_c", 0.3), ("exciter.vr_max", 4.0)] {
        let r = st5b.param(p).unwrap();
        st5b.set(r, v);
    }
    check_every_parameter("GENROU+ST5B+HYGOV", &st5b, 0.9);
}

#[test]
fn a_block_without_dual_equations_is_refused_so_the_caller_falls_back() {
    // `grid_equivalent` has none (it holds only X_e and R_e for the closed-loop playback and is
    // inert in this one, but it does not opt in with `Block::seed_dual`): the unit holding it
    // is refused, naming the block. Every other registry model has dual equations; should this
    // one get them, put a test-only block without them here.
    let u = unit(&[
        ("machine", "GENROU"),
        ("exciter", "SEXS"),
        ("grid", "grid_equivalent"),
    ]);
    let ev = PreparedEvent::new(&event(&u));
    let r = u.param("machine.x_d").unwrap();
    match simulate_pq_sensitivities(&u, &ev, &[r], &SimOptions::default()) {
        Err(SensError::Unsupported(why)) => assert!(why.contains("grid_equivalent"), "{why}"),
        other => panic!("expected Unsupported, got {other:?}"),
    }
}

/// Through a limit: the 0.7 pu dip drives SEXS onto its ceiling (pinned, then released). The
/// replayed map is not smooth there (the located crossing moves against the fixed step ends), so
/// the reference is the converged derivative: central differences of adaptive playbacks at
/// rtol 1e-11 with a step of 1e-3 of the parameter's scale (truncation ~1e-6, integration noise
/// ~1e-11/h). The sensitivities on the default steps agree with it to 1e-5 of each column's
/// largest value (measured: 1e-7 to 2e-6); before the limit's output took the derivative of
/// its mode rather than of the clamp, 1e-2. The same for IEEET1, whose regulator output reaches
/// V_RMAX (measured 4e-8 to 1e-6).
#[test]
fn sensitivities_through_a_ceiling_match_the_converged_derivative() {
    let sexs = unit(&[
        ("machine", "GENSAE"),
        ("exciter", "SEXS"),
        ("pss", "STAB3"),
        ("governor", "HYGOV"),
    ]);
    let names = [
        "machine.x_d",
        "machine.t_d0_prime",
        "exciter.k",
        "exciter.te",
        "exciter.e_max",
        "exciter.ta_tb",
        "pss.k_x",
        "governor.t_w",
    ];
    through_a_limit(&sexs, &names);
    // IEEET1's regulator reaches V_RMAX.
    let ieeet1 = unit(&[("machine", "GENROU"), ("exciter", "IEEET1")]);
    let names = [
        "machine.x_d",
        "exciter.k_a",
        "exciter.t_a",
        "exciter.vr_max",
        "exciter.t_e",
        "exciter.k_f",
        "exciter.t_f",
    ];
    through_a_limit(&ieeet1, &names);
}

/// ST5B through its bridge's supply ceiling: on the 0.7 pu dip E_fd reaches V_T·V_RMAX (3.50 pu
/// at V_T = 0.70, the bridge input V_R − K_C·X_adI_fd being 4.90; checked on the traces) and is
/// pinned on it until the voltage recovers, when the ceiling rises past the bridge input and
/// releases it. Not yet within the tolerance: measured 3e-4 to 8e-2 of each column's largest
/// value (T_1 worst: while pinned the stored state only tracks the moving ceiling with T_1, and
/// at the release it is projected onto the ceiling, a reset whose derivative, the ceiling's plus
/// its rate times the release time's shift, the sensitivity pass does not apply; the other
/// columns' 3e-4 to 1e-2 are not explained yet). SEXS_bus_fed's moving limit is handled the
/// same way and not tested through its ceiling. Ignored until then.
#[test]
#[ignore = "known gap: the moving bridge ceiling's release (see the comment)"]
fn st5b_through_its_supply_ceiling() {
    let u = unit(&[("machine", "GENROU"), ("exciter", "ST5B")]);
    let names = [
        "machine.x_d",
        "exciter.k_r",
        "exciter.t_1",
        "exciter.vr_max",
        "exciter.k_c",
        "exciter.t_c2",
        "exciter.t_b2",
        "exciter.t_r",
    ];
    through_a_limit(&u, &names);
}

fn through_a_limit(u: &Unit, names: &[&str]) {
    through_a_limit_on(u, &PreparedEvent::new(&event(u)), names, 1e-3, 1e-5);
}

/// The sensitivities of `names` on `ev` against the converged derivative (see
/// [`sensitivities_through_a_ceiling_match_the_converged_derivative`]): differences with a step
/// of `h_rel` of each parameter's scale, every column within `tol` of its largest value.
fn through_a_limit_on(u: &Unit, ev: &PreparedEvent, names: &[&str], h_rel: f64, tol: f64) {
    let u = u.clone();
    let ev = ev.clone();
    let tight = SimOptions {
        method: Method::Dopri5(itaipu_dynamics::Dopri5Options {
            rtol: 1e-11,
            atol: 1e-12,
            h_max: 0.01,
            ..Default::default()
        }),
    };
    let refs: Vec<ParamRef> = names.iter().map(|n| u.param(n).unwrap()).collect();
    let s = simulate_pq_sensitivities(&u, &ev, &refs, &SimOptions::default()).unwrap();
    let mut worst = 0.0f64;
    for (j, &r) in refs.iter().enumerate() {
        let p0 = u.get(r);
        let (lo, hi) = u.param_spec(r).range;
        let h = h_rel * p0.abs().max(0.1 * (hi - lo));
        let at = |v: f64| {
            let mut w = u.clone();
            w.set(r, v);
            simulate_pq(&mut w, &ev, &tight).unwrap()
        };
        let (up, dn) = (at(p0 + h), at(p0 - h));
        for (sc, (a, b)) in [(&s.dp[j], (&up.0, &dn.0)), (&s.dq[j], (&up.1, &dn.1))] {
            let fd: Vec<f64> = a
                .iter()
                .zip(b.iter())
                .map(|(x, y)| (x - y) / (2.0 * h))
                .collect();
            let scale = fd.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let err = sc
                .iter()
                .zip(&fd)
                .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
            // A column the event does not move must be zero; no column may be NaN.
            assert!(
                scale > 0.0 || err == 0.0,
                "{}: {err:e} for a zero column",
                names[j]
            );
            let rel = if scale > 0.0 { err / scale } else { 0.0 };
            assert!(rel.is_finite(), "{}: {rel}", names[j]);
            worst = worst.max(rel);
        }
    }
    eprintln!(
        "{}: worst column off by {worst:.2e} of its largest value",
        u.name
    );
    assert!(
        worst < tol,
        "{}: worst column off by {worst:.2e} of its largest value",
        u.name
    );
}

/// The diagnosis's extension blocks: a speed deadband in front of the governor, a two-mass
/// shaft between it and the machine, a terminal load and the PMU's skew, phase and ratio
/// errors on the recorded P and Q. Every parameter of the extended unit within 1e-5 of the
/// replayed differences on the smooth dip (the skew's delay at 12 ms, a fraction of a sample,
/// and at 0; the deadband narrower than the event's speed swing, so both of its pieces are
/// crossed).
#[test]
fn the_extension_blocks_sensitivities_match_differences() {
    let base = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../data/synthetic/unit_gensae_sexs_stab3_hygov.toml");
    let text = std::fs::read_to_string(&base)
        .unwrap()
        .replacen(
            "[governor]\nmodel = \"HYGOV\"",
            "[governor]\nmodel = \"HYGOV\"\nwiring = { speed = \"speed_db\" }",
            1,
        )
        .replacen(
            "[machine]\nmodel = \"GENSAE\"",
            "[machine]\nmodel = \"GENSAE\"\nwiring = { pm = \"p_shaft\" }",
            1,
        )
        + r#"
[[block]]
name = "deadband"
model = "speed_deadband"
db = 0.0002
[[block]]
name = "shaft"
model = "two_mass_shaft"
h_turbine = 0.4
h_generator = 4.5
f_torsion_hz = 6.0
zeta = 0.05
d_turbine = 0.1
[[block]]
name = "load"
model = "terminal_load"
p_load = 0.03
q_load = 0.02
n_p = 1.5
n_q = 2.0
[[block]]
name = "measurement"
model = "pmu_measurement"
pq_delay_s = 0.012
phase_deg = 0.3
p_ratio = 1.004
q_ratio = 0.997
"#;
    let mut u = itaipu_dynamics::unit_file::parse_unit(&text, &base).unwrap();
    let d = u.param("machine.d").unwrap();
    u.set(d, 0.5);
    check_every_parameter("extended", &u, 0.9);
    // At no skew (where a delay's re-fit may start) the delay's derivative is the band-limited
    // signal's slope, against one-sided differences (the delay cannot be negative).
    let tau = u.param("measurement.pq_delay_s").unwrap();
    u.set(tau, 0.0);
    check_every_parameter("extended, no skew", &u, 0.9);
}

/// The over-excitation limiter across its switches: |V| held at 0.9 pu from 1 to 9 s drives the
/// field current above the pickup (heating), the I²t accumulator reaches A_max (activation:
/// V_OEL starts integrating), the voltage recovers and V_OEL winds back to 0 (release). Each
/// switch moves in time with the parameters, and where a right-hand side jumps there (the
/// accumulator's at heating/cooling, V_OEL's at activation) the sensitivities jump by
/// `(f⁻ − f⁺) ∂t*/∂p` (the saltation). Against the converged derivative (as for a ceiling, with
/// a step of 1e-4 of each parameter's scale): within 2e-4 of each column's largest value for
/// every OEL parameter and two of the unit's. Measured: Q's columns 4e-7 to 2.3e-6, P's 2e-5 to
/// 5.2e-5, the reference's own floor (P moves 1/50 as much as Q here, and the rtol-1e-11
/// differences carry ~1e-11/h; at a step of 1e-3 their truncation gives 2e-4 to 5e-4, at 3e-4
/// 4e-5 to 7e-5). Without the saltation (the pins alone), 0.07 to 1.0: the activation time's
/// dependence on A_max, I_pu and the field current would be lost.
#[test]
fn sensitivities_across_the_oel_s_switches_match_the_converged_derivative() {
    let base = unit(&[
        ("machine", "GENSAE"),
        ("exciter", "SEXS"),
        ("governor", "HYGOV"),
    ]);
    let profile = VoltageProfile {
        duration_s: 14.0,
        rate_hz: 30.0,
        dip_start_s: 1.0,
        dip_duration_s: 2.0,
        dip_v: 0.95,
        angle_step: 0.0,
        swing_amp: 0.0,
        freq_dev_hz: 0.0,
        ..VoltageProfile::default()
    };
    let ev = synthesize(
        "overload",
        &base,
        &profile,
        737.0,
        &PmuNoise::typical(7),
        &SimOptions::default(),
    )
    .unwrap();
    let pev = PreparedEvent::new(&ev);
    // Rated field current: the initial one (I0 = 1 pu of rated).
    let mut b = base.clone();
    b.initialise(&pev.machine_point(&base)).unwrap();
    let rated = b.bus()[b.signal_index("xadifd").unwrap()];
    let mut u = Unit::new("oel", 737.0, 60.0);
    for (name, model) in [
        ("machine", "GENSAE"),
        ("exciter", "SEXS"),
        ("governor", "HYGOV"),
        ("oel", "oel"),
    ] {
        u.add(name, registry::find(model).unwrap().create(), &[])
            .unwrap();
    }
    u.finish().unwrap();
    for (name, v) in [
        ("machine.d", 0.5),
        ("oel.ifd_rated", rated),
        ("oel.i_pickup", 1.05),
        ("oel.i_limit", 1.0),
        ("oel.a_max", 0.3),
        ("oel.k_cool", 0.05),
        ("oel.k_i", 0.03),
        ("oel.voel_min", -0.3),
    ] {
        let r = u.param(name).unwrap();
        u.set(r, v);
    }
    // The scenario: every switch is crossed.
    let tr = itaipu_dynamics::simulate::simulate(&u, &ev, &SimOptions::default()).unwrap();
    let voel = tr.get("voel").unwrap();
    let t = &tr.time_s;
    let k_act = voel
        .iter()
        .position(|&v| v < 0.0)
        .expect("the OEL activates");
    let k_rel = (k_act..voel.len())
        .rev()
        .find(|&k| voel[k] < 0.0)
        .map(|k| k + 1)
        .filter(|&k| k < voel.len())
        .expect("the OEL releases before the end");
    eprintln!(
        "oel: active from {:.2} s to {:.2} s, min V_OEL {:.4}",
        t[k_act],
        t[k_rel],
        voel.iter().fold(0.0f64, |m, v| m.min(*v))
    );
    through_a_limit_on(
        &u,
        &pev,
        &[
            "oel.ifd_rated",
            "oel.i_pickup",
            "oel.i_limit",
            "oel.a_max",
            "oel.k_cool",
            "oel.k_i",
            "exciter.k",
            "machine.x_d",
        ],
        1e-4,
        2e-4,
    );
}
