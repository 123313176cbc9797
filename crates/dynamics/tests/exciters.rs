//! The exciter library beyond SEXS (ST5B, IEEET1, ESST1A, IEEEX1, EXDC2) inside full units:
//!
//! * exact steady state: at several operating points (lagging, leading, light load, off-nominal
//!   frequency, a 50 Hz unit), with zero time constants and with E_fd0 a hair inside each limit,
//!   every state derivative at t = 0 is below 1e-10 and every signal stays within 1e-9 of its
//!   initial value over a 10 s playback of the constant operating point;
//! * an operating point the exciter cannot hold is an initialisation error naming the limit;
//! * PSS/E's automatic IEEET1 parameters (KE = 0, VRMAX = 0) give the documented V_R0;
//! * EXDC2's regulator is held at its limits times the terminal voltage;
//! * `.dyr` read → write → read keeps every parameter for each new record;
//! * every exciter declares its roles, each naming one of its parameters or saying why none.

use crate::exciter_support;

use std::path::Path;

use exciter_support::{Series, Source};

use itaipu_dynamics::block::{Block, InitPoint};
use itaipu_dynamics::dyr::{parse_dyr, write_dyr, DyrBases};
use itaipu_dynamics::integrate::{solve, Dopri5Options, Method, OdeSystem};
use itaipu_dynamics::models::exciter::roles::{ExciterRoles, ParamRole};
use itaipu_dynamics::registry::{self, Role};
use itaipu_dynamics::unit::{Playback, PlaybackInput, Unit};

fn op(p: f64, q: f64, v: f64, ang_deg: f64, f_hz: f64, f_n: f64) -> InitPoint {
    InitPoint {
        v_mag: v,
        v_ang: ang_deg.to_radians(),
        p,
        q,
        speed_dev: (f_hz - f_n) / f_n,
    }
}

/// Operating points for a unit of nominal frequency `f_n`.
fn operating_points(f_n: f64) -> Vec<(&'static str, InitPoint)> {
    vec![
        ("lagging", op(0.8, 0.2, 1.0, 17.0, f_n, f_n)),
        ("leading", op(0.9, -0.25, 1.02, -30.0, f_n, f_n)),
        ("light load", op(0.3, 0.05, 0.97, 0.0, f_n, f_n)),
        ("high Q", op(0.7, 0.55, 1.04, 60.0, f_n, f_n)),
        (
            "off-nominal +0.02 %",
            op(0.62, 0.03, 0.986, 4.0, f_n * 1.0002, f_n),
        ),
        (
            "off-nominal −0.7 %",
            op(0.7, 0.1, 1.0, -40.0, f_n * 0.993, f_n),
        ),
    ]
}

/// A unit `machine` + `exciter` (+ IEEEST on speed + HYGOV) at `f_n`, exciter parameters set;
/// with a gate option, limiter signals parked far away drive `vuel`, `voel` unless the option
/// list also holds `("limiters", "none")`.
fn build(
    machine: &str,
    exciter: &str,
    f_n: f64,
    set: &[(&str, f64)],
    options: &[(&str, &str)],
) -> Unit {
    let mut u = Unit::new("exc-test", 30.0, f_n);
    u.add("machine", registry::find(machine).unwrap().create(), &[])
        .unwrap();
    let mut e = registry::find(exciter).unwrap().create();
    for (k, v) in set {
        let i = e
            .params()
            .index_of(k)
            .unwrap_or_else(|| panic!("{exciter} has no {k}"));
        e.params_mut().set(i, *v);
    }
    for (k, v) in options.iter().filter(|(k, _)| *k != "limiters") {
        e.set_option(k, v).unwrap();
    }
    u.add("exciter", e, &[]).unwrap();
    u.add("pss", registry::find("IEEEST").unwrap().create(), &[])
        .unwrap();
    u.add("governor", registry::find("HYGOV").unwrap().create(), &[])
        .unwrap();
    let gated = options
        .iter()
        .any(|(k, m)| *m == "gate" || (*k == "uel" && *m != "1"));
    if gated && !options.contains(&("limiters", "none")) {
        // Gate inputs must be driven: limiter signals parked far outside the operating range.
        let limits = Source::new(
            vec![
                ("vuel", Series::constant(-5.0)),
                ("voel", Series::constant(5.0)),
            ],
            None,
        );
        u.add("limiters", Box::new(limits), &[]).unwrap();
    }
    u.finish().unwrap();
    u
}

fn tight() -> Method {
    Method::Dopri5(Dopri5Options {
        rtol: 1e-10,
        atol: 1e-12,
        h_max: 0.05,
        ..Default::default()
    })
}

/// Initialises at `op`, returns (max |dx/dt| at t = 0 with the worst state, max drift of any
/// bus signal over 10 s of constant playback with its signal name).
fn steady(u: &mut Unit, op: &InitPoint) -> ((f64, String), (f64, String)) {
    let x0 = u.initialise(op).unwrap_or_else(|e| panic!("init: {e}"));
    let w_b = 2.0 * std::f64::consts::PI * u.nominal_hz;
    let t_end = 10.0;
    let input = PlaybackInput::linear(
        vec![0.0, t_end],
        vec![op.v_mag, op.v_mag],
        vec![op.v_ang, op.v_ang + w_b * op.speed_dev * t_end],
    );
    let names = u.state_names();
    let signals = u.signal_names().to_vec();
    let theta = u.signal_index("theta_term").unwrap();
    let delta = u.signal_index("delta");
    let mut sys = Playback::new(u, &input);
    let mut dx = vec![0.0; x0.len()];
    sys.rhs(0.0, &x0, &mut dx);
    let mut worst_d = (0.0, String::new());
    for (k, d) in dx.iter().enumerate() {
        let d = if names[k] == "machine.delta" {
            d - w_b * op.speed_dev
        } else {
            *d
        };
        assert!(d.is_finite(), "{} derivative is not finite", names[k]);
        if d.abs() > worst_d.0 {
            worst_d = (d.abs(), names[k].clone());
        }
    }
    let bus0 = sys.unit.bus().to_vec();
    let knots: Vec<f64> = (0..=100).map(|k| k as f64 * t_end / 100.0).collect();
    let mut worst_s = (0.0, String::new());
    let mut x = x0.clone();
    solve(&tight(), &mut sys, &mut x, &knots, |_, t, x, s| {
        s.eval_signals(t, x);
        for (i, (v, v0)) in s.unit.bus().iter().zip(&bus0).enumerate() {
            // The angles ramp at an off-nominal frequency by design.
            let ramp = if i == theta || Some(i) == delta {
                w_b * op.speed_dev * t
            } else {
                0.0
            };
            let dev = (v - v0 - ramp).abs();
            if dev > worst_s.0 {
                worst_s = (dev, signals[i].clone());
            }
        }
    })
    .unwrap();
    (worst_d, worst_s)
}

/// `(E_fd0, X_adI_fd0, V_t0)` the machine asks of the exciter at `op`.
fn field_at(machine: &str, exciter: &str, f_n: f64, op: &InitPoint) -> (f64, f64, f64) {
    let mut u = build(machine, exciter, f_n, &[], &[]);
    u.initialise(op).unwrap();
    let s = |n: &str| u.bus()[u.signal_index(n).unwrap()];
    (s("efd"), s("xadifd"), s("v_term"))
}

struct Variant {
    label: String,
    set: Vec<(&'static str, f64)>,
    options: Vec<(&'static str, &'static str)>,
}

fn variant(label: &str, set: &[(&'static str, f64)]) -> Variant {
    Variant {
        label: label.into(),
        set: set.to_vec(),
        options: vec![],
    }
}

/// Parameter variants of `exciter` for the operating point `op` (some place a limit a hair
/// above what the operating point needs).
fn variants(machine: &str, exciter: &str, f_n: f64, op: &InitPoint) -> Vec<Variant> {
    let (efd0, ifd0, vt0) = field_at(machine, exciter, f_n, op);
    match exciter {
        "ST5B" => {
            let k_c = 0.3;
            let mut v = vec![
                variant("typical", &[]),
                variant(
                    "Mostar (RaPId) regulator, OpenIPSL K_C",
                    &[
                        ("t_r", 0.025),
                        ("t_c1", 1.071137),
                        ("t_b1", 10.7561),
                        ("t_c2", 3.414283),
                        ("t_b2", 1.701033),
                        ("k_r", 358.6086),
                        ("t_1", 0.004361481),
                        ("k_c", k_c),
                        ("vr_max", 10.0),
                        ("vr_min", -10.0),
                    ],
                ),
                variant(
                    "zero time constants (T_R, T_C1, T_B2, T_1 = 0)",
                    &[("t_r", 0.0), ("t_c1", 0.0), ("t_b2", 0.0), ("t_1", 0.0)],
                ),
                variant(
                    "E_fd0 a hair under the K_C-reduced ceiling",
                    &[("k_c", k_c), ("vr_max", (efd0 + k_c * ifd0) * (1.0 + 1e-6))],
                ),
                Variant {
                    label: "UEL and OEL gates, limiter signals far away".into(),
                    set: vec![],
                    options: vec![("uel", "gate"), ("oel", "gate")],
                },
                Variant {
                    label: "UEL and OEL gates, inputs undriven (inactive)".into(),
                    set: vec![],
                    options: vec![("uel", "gate"), ("oel", "gate"), ("limiters", "none")],
                },
            ];
            // With K_C = 0 the supply ceiling V_T·V_RMAX binds before V_R ≤ V_RMAX only when V_T < 1.
            if vt0 < 1.0 {
                v.push(variant(
                    "E_fd0 a hair under the supply ceiling V_T·V_RMAX",
                    &[("k_c", 0.0), ("vr_max", efd0 / vt0 * (1.0 + 1e-6))],
                ));
            }
            v
        }
        "ESST1A" => {
            let (k_c, i_lr, k_lr) = (0.2, 0.8 * ifd0, 2.0);
            // V_A0 = E_fd0 + K_LR (X_adI_fd0 − I_LR) with the limiter active at t = 0.
            let va0 = efd0 + k_lr * (ifd0 - i_lr);
            vec![
                variant("typical", &[]),
                variant(
                    "PSS/E example (rate feedback, second lead-lag)",
                    &[
                        ("t_r", 0.1),
                        ("vi_max", 0.3),
                        ("vi_min", -0.3),
                        ("t_c", 2.0),
                        ("t_b", 10.0),
                        ("t_c1", 0.08),
                        ("t_b1", 0.083),
                        ("k_a", 300.0),
                        ("t_a", 0.1),
                        ("va_max", 7.0),
                        ("va_min", -7.0),
                        ("vr_max", 5.2),
                        ("vr_min", -5.2),
                        ("k_c", 0.38),
                        ("k_f", 0.05),
                        ("t_f", 1.0),
                    ],
                ),
                variant(
                    "zero time constants (T_R, T_B, T_B1, T_A = 0)",
                    &[("t_r", 0.0), ("t_b", 0.0), ("t_b1", 0.0), ("t_a", 0.0)],
                ),
                variant(
                    "field current limiter active at t = 0",
                    &[("k_lr", k_lr), ("i_lr", i_lr), ("va_max", va0 + 1.0)],
                ),
                variant(
                    "E_fd0 a hair under the K_C-reduced supply ceiling",
                    &[
                        ("k_c", k_c),
                        ("vr_max", (efd0 + k_c * ifd0) / vt0 * (1.0 + 1e-6)),
                    ],
                ),
                variant(
                    "V_A0 a hair under VAMAX",
                    &[("va_max", efd0 * (1.0 + 1e-6)), ("k_lr", 0.0)],
                ),
                Variant {
                    label: "UEL = 2, VOS = 2, OEL gate, limiter inputs undriven".into(),
                    set: vec![],
                    options: vec![
                        ("uel", "2"),
                        ("vos", "2"),
                        ("oel", "gate"),
                        ("limiters", "none"),
                    ],
                },
                Variant {
                    label: "UEL = 3, OEL gate, limiter signals far away".into(),
                    set: vec![],
                    options: vec![("uel", "3"), ("oel", "gate")],
                },
            ]
        }
        "IEEET1" => {
            let p = registry::find("IEEET1").unwrap().create();
            let get = |n: &str| p.params().get(p.params().index_of(n).unwrap());
            // V_R0 = (K_E + S_E(E_fd0)) E_fd0 with the typical saturation: E_fd0 < A here.
            let vr0 =
                get("k_e") * efd0 + sat_times_e(get("e1"), get("se1"), get("e2"), get("se2"), efd0);
            vec![
                variant("typical", &[]),
                variant(
                    "zero time constants (T_R, T_A = 0)",
                    &[("t_r", 0.0), ("t_a", 0.0)],
                ),
                variant("KE = 0 (computed)", &[("k_e", 0.0)]),
                variant("VRMAX = 0 (computed)", &[("vr_max", 0.0)]),
                variant(
                    "saturated at E_fd0 (E_1 = 0.6 E_fd0)",
                    &[
                        ("e1", 0.6 * efd0),
                        ("se1", 0.05),
                        ("e2", 1.5 * efd0),
                        ("se2", 0.4),
                    ],
                ),
                variant("V_R0 a hair under VRMAX", &[("vr_max", vr0 * (1.0 + 1e-6))]),
            ]
        }
        "IEEEX1" | "EXDC2" => {
            let p = registry::find(exciter).unwrap().create();
            let get = |n: &str| p.params().get(p.params().index_of(n).unwrap());
            // K_E = 1 so that V_R0 = (K_E + S_E(E_fd0)) E_fd0 is not 0 (IEEEX1's typical K_E = 0).
            let vr0 = efd0 + sat_times_e(get("e1"), get("se1"), get("e2"), get("se2"), efd0);
            // EXDC2's ceiling is V_T0·V_RMAX: a hair above V_R0 at this V_T0 (IEEEX1 with the
            // same V_RMAX refuses the points where V_T0 > 1).
            let scale = if exciter == "EXDC2" { vt0 } else { 1.0 };
            vec![
                variant("typical", &[]),
                variant(
                    "zero time constants (T_R, T_A, T_B = 0)",
                    &[("t_r", 0.0), ("t_a", 0.0), ("t_b", 0.0)],
                ),
                variant("lead-lag on", &[("t_c", 0.5), ("t_b", 1.0)]),
                variant("KE = 0 (computed)", &[("k_e", 0.0)]),
                variant(
                    "saturated at E_fd0 (E_1 = 0.6 E_fd0)",
                    &[
                        ("e1", 0.6 * efd0),
                        ("se1", 0.05),
                        ("e2", 1.5 * efd0),
                        ("se2", 0.4),
                    ],
                ),
                variant(
                    "V_R0 a hair under the ceiling",
                    &[("k_e", 1.0), ("vr_max", vr0 / scale * (1.0 + 1e-6))],
                ),
            ]
        }
        _ => unreachable!(),
    }
}

/// PSS/E quadratic saturation `S_E(E)·E`, written out here from its definition.
fn sat_times_e(e1: f64, se1: f64, e2: f64, se2: f64, e: f64) -> f64 {
    if se1 == 0.0 || se2 == 0.0 {
        return 0.0;
    }
    let a = (se1 * e1 / (se2 * e2)).sqrt();
    let big_a = e2 - (e1 - e2) / (a - 1.0);
    let b = se2 * e2 * (a - 1.0).powi(2) / (e1 - e2).powi(2);
    if e > big_a {
        b * (e - big_a).powi(2)
    } else {
        0.0
    }
}

#[test]
fn new_exciters_start_in_exact_steady_state() {
    let mut checked = 0;
    for exciter in ["ST5B", "IEEET1", "ESST1A", "IEEEX1", "EXDC2"] {
        for (machine, f_n) in [("GENSAL", 50.0), ("GENSAE", 60.0), ("GENROU", 50.0)] {
            for (at, p) in operating_points(f_n) {
                for v in variants(machine, exciter, f_n, &p) {
                    let mut u = build(machine, exciter, f_n, &v.set, &v.options);
                    let ((d, ds), (s, ss)) = steady(&mut u, &p);
                    let what = format!("{machine}+{exciter} ({}) at {at}, {f_n} Hz", v.label);
                    assert!(d < 1e-10, "{what}: |d{ds}/dt| = {d:e}");
                    assert!(s < 1e-9, "{what}: signal {ss} drifts by {s:e} over 10 s");
                    checked += 1;
                }
            }
        }
    }
    // ST5B: 6 variants (7 where V_t < 1: light load, +0.02 %); IEEET1: 6; ESST1A: 8; IEEEX1,
    // EXDC2: 6.
    assert_eq!(
        checked,
        3 * (6 * 6 + 2) + 3 * 6 * 6 + 3 * 6 * 8 + 2 * 3 * 6 * 6
    );
}

// ---------------------------------------------------------------------------------------------
// Operating points an exciter cannot hold

fn init_error(exciter: &str, set: &[(&str, f64)], options: &[(&str, &str)]) -> String {
    init_error_with(exciter, set, options, None)
}

fn init_error_with(
    exciter: &str,
    set: &[(&str, f64)],
    options: &[(&str, &str)],
    limiters: Option<Source>,
) -> String {
    let p = operating_points(50.0)[2].1; // light load, V_t = 0.97
    let mut u = Unit::new("exc-test", 30.0, 50.0);
    u.add("machine", registry::find("GENSAL").unwrap().create(), &[])
        .unwrap();
    let mut e = registry::find(exciter).unwrap().create();
    for (k, v) in set {
        let i = e.params().index_of(k).unwrap();
        e.params_mut().set(i, *v);
    }
    for (k, v) in options {
        e.set_option(k, v).unwrap();
    }
    u.add("exciter", e, &[]).unwrap();
    if let Some(l) = limiters {
        u.add("limiters", Box::new(l), &[]).unwrap();
    }
    u.finish().unwrap();
    let err = u.initialise(&p).unwrap_err();
    assert_eq!(err.kind(), "init", "{err}");
    err.to_string()
}

#[test]
fn an_operating_point_outside_the_exciter_limits_is_an_init_error_not_a_clip() {
    let (efd0, ifd0, vt0) = field_at("GENSAL", "ST5B", 50.0, &operating_points(50.0)[2].1);
    assert!(vt0 < 1.0 && efd0 > 0.5 && ifd0 > 0.5);
    // Above the K_C-reduced ceiling: E_fd0 + K_C·I_fd0 > V_RMAX although V_T·V_RMAX > E_fd0.
    let e = init_error("ST5B", &[("k_c", 0.3), ("vr_max", efd0 + 0.2 * ifd0)], &[]);
    assert!(
        e.contains("exciter") && e.contains("KC-reduced ceiling"),
        "{e}"
    );
    // Above the supply ceiling: V_T·V_RMAX < E_fd0 although V_RMAX > E_fd0 (V_T < 1).
    let e = init_error("ST5B", &[("k_c", 0.0), ("vr_max", efd0 / vt0 * 0.999)], &[]);
    assert!(e.contains("V_T·VRMAX"), "{e}");
    // Below the floor.
    let e = init_error(
        "ST5B",
        &[("vr_min", 1.01 * efd0 / vt0), ("vr_max", 9.0)],
        &[],
    );
    assert!(e.contains("V_T·VRMIN"), "{e}");
    // An OEL signal at 0 on the LV gate is below the regulator error: the gate selects it.
    let oel0 = Source::new(vec![("voel", Series::constant(0.0))], None);
    let e = init_error_with("ST5B", &[], &[("oel", "gate")], Some(oel0));
    assert!(e.contains("OEL gate"), "{e}");
    // ESST1A: E_fd0 above V_T·V_RMAX − K_C·X_adI_fd; V_A0 above VAMAX; V_A0/K_A above VIMAX.
    let e = init_error(
        "ESST1A",
        &[("k_c", 0.2), ("vr_max", (efd0 + 0.1 * ifd0) / vt0)],
        &[],
    );
    assert!(e.contains("ESST1A") && e.contains("KC·X_adI_fd"), "{e}");
    let e = init_error("ESST1A", &[("va_max", 0.99 * efd0), ("k_lr", 0.0)], &[]);
    assert!(e.contains("VAMAX"), "{e}");
    let e = init_error(
        "ESST1A",
        &[("k_a", 2.0), ("vi_max", 0.4 * efd0), ("va_max", 9.0)],
        &[],
    );
    assert!(e.contains("VIMAX"), "{e}");
    // IEEET1: V_R0 = (K_E + S_E) E_fd0 above VRMAX.
    let e = init_error(
        "IEEET1",
        &[("vr_max", 0.9 * efd0), ("k_e", 1.0), ("se1", 0.0)],
        &[],
    );
    assert!(e.contains("IEEET1") && e.contains("VRMAX"), "{e}");
}

// ---------------------------------------------------------------------------------------------
// IEEET1: PSS/E's automatic parameters

/// Plays a 0.5 pu dip (1-2 s) and a 1.15 pu overvoltage into GENSAL + IEEET1 with `set` and
/// returns (V_R at t = 0, max V_R, min V_R) over the whole run ([`regulator_extremes`]).
fn ieeet1_dip(set: &[(&str, f64)]) -> (f64, f64, f64) {
    let mut e = registry::find("IEEET1").unwrap().create();
    for (k, v) in set {
        let i = e.params().index_of(k).unwrap();
        e.params_mut().set(i, *v);
    }
    regulator_extremes(e, 0.0)
}

/// Plays into GENSAL + the exciter `e` (at the first 50 Hz operating point) a dip to 0.5 pu
/// (1-2 s) then an overvoltage of 1.15 pu (2-4 s), 1 ms edges, and returns (V_R at t = 0, max
/// V_R in the dip from `settle_s` after its edge, min V_R from `settle_s` after the
/// overvoltage's edge; with `settle_s` = 0 the extremes over the whole run).
fn regulator_extremes(e: Box<dyn Block>, settle_s: f64) -> (f64, f64, f64) {
    let p = operating_points(50.0)[0].1;
    let mut u = Unit::new("exc-test", 30.0, 50.0);
    u.add("machine", registry::find("GENSAL").unwrap().create(), &[])
        .unwrap();
    u.add("exciter", e, &[]).unwrap();
    u.finish().unwrap();
    let mut x = u.initialise(&p).unwrap();
    let k_vr = u
        .state_names()
        .iter()
        .position(|n| n == "exciter.v_r")
        .unwrap();
    let vr0 = x[k_vr];
    let input = PlaybackInput::linear(
        vec![0.0, 1.0, 1.001, 2.0, 2.001, 4.0],
        vec![p.v_mag, p.v_mag, 0.5, 0.5, 1.15, 1.15],
        vec![p.v_ang; 6],
    );
    let knots: Vec<f64> = (0..=4000).map(|k| k as f64 * 1e-3).collect();
    let (mut hi, mut lo) = (f64::MIN, f64::MAX);
    let whole = settle_s == 0.0;
    let mut sys = Playback::new(&mut u, &input);
    solve(&tight(), &mut sys, &mut x, &knots, |_, t, x, _| {
        if whole || (1.0 + settle_s..2.0).contains(&t) {
            hi = hi.max(x[k_vr]);
        }
        if whole || t >= 2.0 + settle_s {
            lo = lo.min(x[k_vr]);
        }
    })
    .unwrap();
    (vr0, hi, lo)
}

#[test]
fn ieeet1_ke_zero_starts_the_regulator_at_a_tenth_of_its_ceiling() {
    let (vr0, hi, _) = ieeet1_dip(&[("k_e", 0.0), ("vr_max", 4.0), ("vr_min", -4.0)]);
    assert!((vr0 - 0.4).abs() < 1e-12, "V_R0 = {vr0}");
    assert!((hi - 4.0).abs() < 1e-9, "the dip drives V_R to VRMAX: {hi}");
    // With K_E given, V_R0 = K_E·E_fd0 (no saturation below A), not VRMAX/10.
    let (vr0, _, _) = ieeet1_dip(&[("k_e", 1.0), ("vr_max", 4.0), ("se1", 0.0)]);
    let (efd0, _, _) = field_at("GENSAL", "IEEET1", 50.0, &operating_points(50.0)[0].1);
    assert!((vr0 - efd0).abs() < 1e-12, "V_R0 = {vr0}, E_fd0 = {efd0}");
}

#[test]
fn ieeet1_vrmax_zero_takes_the_regulator_output_that_holds_e2() {
    // VRMAX = (K_E + SE(E_2))·E_2 = (0.8 + 0.5)·3.0 = 3.9, VRMIN = −3.9.
    let set = [
        ("vr_max", 0.0),
        ("vr_min", -1.0),
        ("k_e", 0.8),
        ("e1", 2.0),
        ("se1", 0.1),
        ("e2", 3.0),
        ("se2", 0.5),
        ("k_a", 200.0),
    ];
    let (_, hi, lo) = ieeet1_dip(&set);
    assert!((hi - 3.9).abs() < 1e-9, "max V_R = {hi}");
    assert!((lo + 3.9).abs() < 1e-9, "min V_R = {lo}");
}

// ---------------------------------------------------------------------------------------------
// EXDC2: regulator limits proportional to the terminal voltage

/// [`regulator_extremes`] of GENSAL + `model` (IEEEX1 or EXDC2, DC2A sample data with
/// V_RMAX = 6, V_RMIN = −4 and no rate feedback, which would hold V_R off its floor in the
/// overvoltage), each window starting 0.3 s after its edge: the stored state of a V_R pinned while its limit moves (the 1 ms edges)
/// tracks the limit with T_A = 0.01 s, within e^-30 of it after 30 T_A (the output is the
/// limit itself throughout).
fn dc_regulator_extremes(model: &str) -> (f64, f64, f64) {
    let mut e = registry::find("EXDC2").unwrap().create();
    let data: Vec<f64> = (0..e.params().specs().len())
        .map(|i| e.params().get(i))
        .collect();
    if model != "EXDC2" {
        e = registry::find(model).unwrap().create();
        for (i, v) in data.into_iter().enumerate() {
            e.params_mut().set(i, v);
        }
    }
    for (k, v) in [("vr_max", 6.0), ("vr_min", -4.0), ("k_f", 0.0)] {
        let i = e.params().index_of(k).unwrap();
        e.params_mut().set(i, v);
    }
    regulator_extremes(e, 0.3)
}

#[test]
fn exdc2_s_regulator_is_held_at_its_limits_times_the_terminal_voltage() {
    let (vr0, hi, lo) = dc_regulator_extremes("EXDC2");
    // V_R starts inside 0.5·V_RMAX = 3, so the dip drives it up onto the scaled ceiling.
    assert!(vr0 < 2.9, "V_R0 = {vr0}");
    assert!((hi - 0.5 * 6.0).abs() < 1e-9, "V_R in the dip: {hi}");
    assert!(
        (lo - 1.15 * -4.0).abs() < 1e-9,
        "V_R in the overvoltage: {lo}"
    );
    // The same data as IEEEX1 (constant limits, as ANDES 2.0's IEEEX1 in effect) reaches the
    // unscaled limits.
    let (_, hi, lo) = dc_regulator_extremes("IEEEX1");
    assert!(
        (hi - 6.0).abs() < 1e-9 && (lo + 4.0).abs() < 1e-9,
        "IEEEX1: {hi}, {lo}"
    );
}

// ---------------------------------------------------------------------------------------------
// .dyr

#[test]
fn dyr_read_write_read_keeps_every_parameter_of_the_new_exciters() {
    for exciter in ["ST5B", "IEEET1", "ESST1A", "IEEEX1", "EXDC2"] {
        let mut u = Unit::new("rt", 30.0, 50.0);
        for (k, (role, model)) in [("machine", "GENSAL"), ("exciter", exciter)]
            .iter()
            .enumerate()
        {
            let mut b = registry::find(model).unwrap().create();
            for i in 0..b.params().specs().len() {
                let s = b.params().specs()[i];
                if s.name.ends_with("_offset") {
                    continue;
                }
                // Off the typical values (zeros too), so that a dropped or swapped CON shows.
                let v = b.params().get(i) * (1.0 + 0.0137 * (((i + k) % 5) as f64 - 2.0))
                    + 0.001 * (i as f64 + 1.0);
                b.params_mut().set(i, v);
            }
            if *model == "ESST1A" {
                // The ICONs, off their defaults.
                b.set_option("uel", "3").unwrap();
                b.set_option("vos", "2").unwrap();
            }
            if *model == "GENSAL" {
                let xd = b.params().index_of("x_d_pp").unwrap();
                let xq = b.params().index_of("x_q_pp").unwrap();
                let v = b.params().get(xd);
                b.params_mut().set(xq, v);
            }
            b.validate().unwrap_or_else(|e| panic!("{model}: {e}"));
            u.add(role, b, &[]).unwrap();
        }
        u.finish().unwrap();
        let w = write_dyr(&u, 12, "M1");
        assert!(w.warnings.is_empty(), "{exciter}: {:?}", w.warnings);
        assert!(w.dyr.contains(&format!("'{exciter}'")), "{}", w.dyr);
        let b = DyrBases::parse(&w.bases, Path::new("rt.bases.toml"), None).unwrap();
        let d = parse_dyr(&w.dyr, Path::new("rt.dyr"), Some((12, "M1")), &b).unwrap();
        assert!(d.warnings.is_empty(), "{exciter}: {:?}", d.warnings);
        let params = |u: &Unit| -> Vec<(String, f64)> {
            u.params().into_iter().map(|(p, _, v)| (p, v)).collect()
        };
        assert_eq!(params(&d.unit), params(&u), "{exciter}\n{}", w.dyr);
        let opts = |u: &Unit| u.block("exciter").unwrap().options();
        assert_eq!(opts(&d.unit), opts(&u), "{exciter} options\n{}", w.dyr);
        assert_eq!(write_dyr(&d.unit, 12, "M1").dyr, w.dyr);
    }
}

#[test]
fn a_pss_e_record_reads_in_pss_e_con_order() {
    // The CONs of PSS/E's own example records (OpenIPSL's PSS/E validation cases).
    let text = "\
 5 'GENSAL' 1 5.0 0.07 0.09 4.28 0.0 1.84 1.75 0.41 0.2 0.12 0.11 0.39 /
 5 'ST5B' 1 0.0 0.8 6.0 0.08 0.01 200.0 5.0 -4.0 0.001 0.004 2.0 10.0 0.1 0.05 0.1 2.0 0.08 0.08 /
 6 'GENSAL' 1 5.0 0.07 0.09 4.28 0.0 1.84 1.75 0.41 0.2 0.12 0.11 0.39 /
 6 'IEEET1' 1 0.02 200.0 0.001 2.0 -2.0 0.1 0.55 0.06 1.0 0.0 2.85 0.3 3.8 0.6 /
 7 'GENSAL' 1 5.0 0.07 0.09 4.28 0.0 1.84 1.75 0.41 0.2 0.12 0.11 0.39 /
 7 'ESST1A' 1 1 2 0.1 0.3 -0.3 2.0 10.0 0.08 0.083 300.0 0.1 7.0 -7.0 5.2 -5.2 0.38 1.0 1.0 1.0 0.0 /
";
    let bases = DyrBases {
        mbase: 100.0,
        nominal_hz: 60.0,
        zr: Some(0.0),
        zx: None,
        name: None,
    };
    let get = |bus: i64, name: &str| {
        let d = parse_dyr(text, Path::new("ex.dyr"), Some((bus, "1")), &bases).unwrap();
        let r = d.unit.param(name).unwrap();
        d.unit.get(r)
    };
    for (name, want) in [
        ("exciter.t_r", 0.0),
        ("exciter.t_b1", 6.0),
        ("exciter.k_r", 200.0),
        ("exciter.vr_min", -4.0),
        ("exciter.t_1", 0.001),
        ("exciter.k_c", 0.004),
        ("exciter.t_uc1", 2.0),
        ("exciter.t_ob2", 0.08),
    ] {
        assert_eq!(get(5, name), want, "ST5B {name}");
    }
    for (name, want) in [
        ("exciter.k_a", 200.0),
        ("exciter.vr_max", 2.0),
        ("exciter.k_e", 0.1),
        ("exciter.t_f", 1.0),
        ("exciter.switch", 0.0),
        ("exciter.e1", 2.85),
        ("exciter.se2", 0.6),
    ] {
        assert_eq!(get(6, name), want, "IEEET1 {name}");
    }
    for (name, want) in [
        ("exciter.t_r", 0.1),
        ("exciter.vi_min", -0.3),
        ("exciter.t_b1", 0.083),
        ("exciter.k_a", 300.0),
        ("exciter.va_min", -7.0),
        ("exciter.vr_max", 5.2),
        ("exciter.k_c", 0.38),
        ("exciter.k_lr", 1.0),
        ("exciter.i_lr", 0.0),
    ] {
        assert_eq!(get(7, name), want, "ESST1A {name}");
    }
    let d = parse_dyr(text, Path::new("ex.dyr"), Some((7, "1")), &bases).unwrap();
    assert_eq!(
        d.unit.block("exciter").unwrap().options(),
        vec![("vos", "2".to_string())],
        "UEL = 1 (default), VOS = 2"
    );
}

// ---------------------------------------------------------------------------------------------
// Roles

#[test]
fn every_exciter_declares_its_roles() {
    let exciters: Vec<_> = registry::MODELS
        .iter()
        .filter(|m| m.role == Role::Exciter)
        .collect();
    assert!(exciters.len() >= 4);
    for m in exciters {
        let b = m.create();
        let r: ExciterRoles = b
            .exciter_roles()
            .unwrap_or_else(|| panic!("{} declares no roles", m.name));
        r.check(b.params())
            .unwrap_or_else(|e| panic!("{}: {e}", m.name));
        // Every exciter has a gain, a field time constant and the set-point offset.
        for (role, pr) in [
            ("gain", &r.gain),
            ("field_time_constant", &r.field_time_constant),
            ("v_ref_offset", &r.v_ref_offset),
        ] {
            assert!(
                matches!(pr, ParamRole::Param(_)),
                "{}: {role} must name a parameter",
                m.name
            );
        }
        for (role, pr) in r.params() {
            if let Some(reason) = pr.reason() {
                assert!(
                    reason.len() > 10 && !reason.contains("not declared"),
                    "{}: {role}: a reason the diagnosis can print, got '{reason}'",
                    m.name
                );
            }
        }
        // An E_fd ceiling is either a constant parameter or a supply-scaled one, never both.
        assert!(
            r.ceiling.name().is_some() != r.supply_ceiling.name().is_some()
                || r.regulator_ceiling.name().is_some(),
            "{}: no ceiling of any kind",
            m.name
        );
    }
    // Non-exciters declare none.
    for name in ["GENSAL", "IEEEST", "HYGOV", "oel"] {
        assert!(
            registry::find(name)
                .unwrap()
                .create()
                .exciter_roles()
                .is_none(),
            "{name}"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// The Mostar unit (RaPId's OpenIPSL model: GENSAL with X''q ≠ X''d and R_a > 0, ST5B, 50 Hz)

#[test]
fn the_mostar_gensal_st5b_unit_starts_in_exact_steady_state() {
    let mut u = Unit::new("mostar", 30.0, 50.0);
    let mut m = registry::find("GENSAL").unwrap().create();
    for (k, v) in [
        ("h", 2.137),
        ("d", 0.0),
        ("x_d", 1.183),
        ("x_q", 0.62),
        ("x_d_prime", 0.371),
        ("x_d_pp", 0.215),
        ("x_q_pp", 0.241),
        ("x_l", 0.1),
        ("t_d0_prime", 3.77),
        ("t_d0_pp", 0.0552),
        ("t_q0_pp", 0.0823),
        ("s10", 0.1),
        ("s12", 0.4),
        ("r_a", 0.017637 / (10.5 * 10.5 / 30.0)),
    ] {
        let i = m.params().index_of(k).unwrap();
        m.params_mut().set(i, v);
    }
    u.add("machine", m, &[]).unwrap();
    let mut e = registry::find("ST5B").unwrap().create();
    for (k, v) in [
        ("t_r", 0.025),
        ("t_c1", 1.071137),
        ("t_b1", 10.7561),
        ("t_c2", 3.414283),
        ("t_b2", 1.701033),
        ("k_r", 358.6086),
        ("vr_max", 10.0),
        ("vr_min", -10.0),
        ("t_1", 0.004361481),
        ("k_c", 0.3),
    ] {
        let i = e.params().index_of(k).unwrap();
        e.params_mut().set(i, v);
    }
    u.add("exciter", e, &[]).unwrap();
    u.finish().unwrap();
    // RaPId's operating point: P 5.19486 MW, Q 0.07332 pu on 30 MVA, |V| 0.9705 pu.
    let p = op(5.19486 / 30.0, 0.07332, 0.9705, 0.0, 50.0, 50.0);
    let ((d, ds), (s, ss)) = steady(&mut u, &p);
    assert!(d < 1e-10, "|d{ds}/dt| = {d:e}");
    assert!(s < 1e-9, "signal {ss} drifts by {s:e} over 10 s");
}

#[test]
fn a_user_diagram_declares_its_exciter_roles() {
    let sexs = include_str!("../../../data/diagrams/sexs.toml");
    let with_roles = format!(
        "{sexs}\n[exciter_roles]\ngain = \"k\"\nfield_time_constant = \"te\"\nceiling = \"e_max\"\n\
         floor = \"e_min\"\nv_ref_offset = \"v_ref_offset\"\n\
         transient_gain_reduction = {{ ratio = \"ta_tb\", lag = \"tb\" }}\n\
         supply_ceiling = {{ none = \"constant limits\" }}\n"
    );
    let table: toml::Table = toml::from_str(&with_roles).unwrap();
    let d = itaipu_dynamics::diagram::from_table(&table).unwrap();
    let b: &dyn itaipu_dynamics::block::Block = &d;
    let r = b.exciter_roles().expect("declared");
    r.check(b.params()).unwrap();
    assert_eq!(r.gain.name(), Some("k"));
    assert_eq!(r.ceiling.name(), Some("e_max"));
    assert_eq!(r.transient_gain_reduction.names(), Some(("ta_tb", "tb")));
    assert_eq!(r.supply_ceiling.reason(), Some("constant limits"));
    assert!(r.commutation.reason().unwrap().contains("not declared"));
    // The same SEXS diagram without the table declares nothing.
    let plain = itaipu_dynamics::diagram::from_table(&toml::from_str(sexs).unwrap()).unwrap();
    assert!(itaipu_dynamics::block::Block::exciter_roles(&plain).is_none());
    // A role naming an undeclared parameter is a definition error naming the field.
    let bad: toml::Table =
        toml::from_str(&format!("{sexs}\n[exciter_roles]\ngain = \"k_a\"\n")).unwrap();
    let e = itaipu_dynamics::diagram::from_table(&bad).unwrap_err();
    assert_eq!(e.field, "exciter_roles.gain", "{e:?}");
}
