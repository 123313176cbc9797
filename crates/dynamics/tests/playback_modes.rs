//! The playback modes (`itaipu_dynamics::mode`): every mode starts in exact steady state, the
//! closed loop solves its network, and a closed-loop step simulated by the engine is reproduced
//! by the open-loop modes (the exciter alone recovers E_fd, the machine from E_fd recovers Q)
//! and by the phasor playback with the same steps.

use std::path::Path;

use itaipu_dynamics::event::{Channel, Declaration, Event, Record, SetpointStep, StepReference};
use itaipu_dynamics::mode::{
    initial_derivatives, simulate_mode, simulate_mode_both, simulate_mode_traces, ModeOutputs,
    PlaybackMode,
};
use itaipu_dynamics::registry;
use itaipu_dynamics::simulate::{simulate_pq, PreparedEvent, SimError, SimOptions};
use itaipu_dynamics::unit::Unit;
use itaipu_dynamics::unit_file::read_unit;

/// The bundled Mostar unit: GENSAL + ST5B (RaPId's values) + constant P_m + grid X = 0.1169.
fn mostar_unit() -> Unit {
    read_unit(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/mostar/unit.toml")).unwrap()
}

/// The Mostar unit with a STAB3 (P_e input) between the measured P and the AVR.
fn with_pss(model: &str) -> Unit {
    let mut u = mostar_unit();
    u.put("pss", registry::find(model).unwrap().create(), &[])
        .unwrap();
    u
}

fn tight() -> SimOptions {
    SimOptions {
        method: itaipu_dynamics::Method::Dopri5(itaipu_dynamics::Dopri5Options {
            rtol: 1e-10,
            atol: 1e-12,
            h_max: 0.01,
            ..Default::default()
        }),
    }
}

/// An event of `n` samples `dt` apart holding constant |V|, P, Q, E_fd (and I_fd), at Mostar's
/// operating point (30 MVA base, 50 Hz), declared without an angle unless `angle`.
#[allow(clippy::too_many_arguments)]
fn constant_event(
    n: usize,
    dt: f64,
    efd: f64,
    ifd: Option<f64>,
    angle: bool,
    steps: Vec<SetpointStep>,
) -> Event {
    let rec = Record {
        time_s: (0..n).map(|i| i as f64 * dt).collect(),
        v_mag_pu: vec![0.97043; n],
        v_ang_rad: vec![0.1; n],
        p_pu: vec![0.17153; n],
        q_pu: vec![0.07401; n],
        freq_hz: None,
        efd_pu: Some(vec![efd; n]),
        ifd_pu: ifd.map(|v| vec![v; n]),
    };
    let mut ch = vec![Channel::V, Channel::P, Channel::Q, Channel::Efd];
    if angle {
        ch.push(Channel::Angle);
    }
    if ifd.is_some() {
        ch.push(Channel::Ifd);
    }
    let decl = Declaration {
        channels: Some(ch),
        steps,
        ..Default::default()
    };
    Event::from_record_declared("constant", rec, 30.0, 50.0, None, None, &decl).unwrap()
}

fn max_dev(y: &[f64]) -> f64 {
    y.iter().map(|v| (v - y[0]).abs()).fold(0.0, f64::max)
}

/// Every mode's initialisation is an exact steady state: |dx/dt| < 1e-10 at the start, and
/// with constant inputs every output stays at its start value over 10 s (1e-9). E_fd0 = 1.25 is
/// not the model's 1.179 at the measured point: the P-held modes start at the Q where it is.
#[test]
fn every_mode_starts_in_exact_steady_state() {
    let units = [
        ("GENSAL+ST5B", mostar_unit()),
        ("GENSAL+ST5B+STAB3", with_pss("STAB3")),
    ];
    for (label, unit) in &units {
        for (mode, ifd, angle) in [
            (PlaybackMode::Phasor, None, true),
            (PlaybackMode::ExciterAlone, None, false),
            (PlaybackMode::ExciterAlone, Some(1.3), false),
            (PlaybackMode::MachineFromEfd, None, false),
            (PlaybackMode::ClosedLoop, None, false),
        ] {
            let ev = constant_event(1001, 0.01, 1.25, ifd, angle, vec![]);
            let pe = PreparedEvent::new(&ev);
            let what = format!("{label}, {mode}, I_fd {ifd:?}");
            let (names, dx) = initial_derivatives(unit, &pe, mode).unwrap();
            for (n, d) in names.iter().zip(&dx) {
                assert!(d.abs() < 1e-10, "{what}: d{n}/dt = {d:e}");
            }
            let o = simulate_mode(unit, &pe, mode, &tight()).unwrap();
            for c in [Channel::P, Channel::Q, Channel::V, Channel::Efd] {
                let y = o.channel(c).unwrap();
                assert!(max_dev(y) < 1e-9, "{what}: {c} drifts by {:e}", max_dev(y));
            }
            match mode {
                // The exciter starts at the measured E_fd0.
                PlaybackMode::ExciterAlone => assert!((o.efd[0] - 1.25).abs() < 1e-12),
                // The machine at the Q where its steady E_fd is the measured one.
                PlaybackMode::MachineFromEfd => {
                    assert!(o.q[0] > 0.074 + 0.01, "Q0* {} above the measured Q", o.q[0]);
                    assert!((o.p[0] - 0.17153).abs() < 1e-12);
                }
                // The unit at the measured point: P, Q, |V| are the measured ones.
                PlaybackMode::ClosedLoop | PlaybackMode::Phasor => {
                    assert!((o.q[0] - 0.07401).abs() < 1e-12, "{what}");
                    assert!((o.v[0] - 0.97043).abs() < 1e-12, "{what}");
                }
            }
        }
    }
}

/// The closed loop solves `V_t = E_∞ + j X_e I_t` at every sample, with E_∞ fixed by the
/// pre-step point.
#[test]
fn the_closed_loop_solves_the_network_at_every_sample() {
    let unit = mostar_unit();
    let steps = step_pair(1.0, 6.0);
    let ev = constant_event(2001, 0.005, 1.2, None, false, steps);
    let tr = simulate_mode_traces(&unit, &ev, PlaybackMode::ClosedLoop, &tight()).unwrap();
    let col = |n: &str| tr.get(n).unwrap();
    let (v, th, p, q) = (
        col("v_term"),
        col("theta_term"),
        col("p_mach_pu"),
        col("q_mach_pu"),
    );
    let x = 0.1169;
    // E = V − jX I, I = conj(S/V): E = V − jX conj(S)/conj(V).
    let e = |k: usize| {
        let (vr, vi) = (v[k] * th[k].cos(), v[k] * th[k].sin());
        let d = vr * vr + vi * vi;
        // conj(S)/conj(V) = (p − jq)(vr + j vi)/d
        let (ir, ii) = ((p[k] * vr + q[k] * vi) / d, (p[k] * vi - q[k] * vr) / d);
        (vr + x * ii, vi - x * ir)
    };
    let e0 = e(0);
    let mut worst = 0.0f64;
    for k in 0..v.len() {
        let ek = e(k);
        worst = worst.max((ek.0 - e0.0).hypot(ek.1 - e0.1));
    }
    assert!(worst < 1e-10, "E_inf moves by {worst:e}");
    // The step moved the terminal: |V| up by nearly the step (a high-gain AVR, a stiff grid).
    let dv = v[1000] - v[0];
    assert!(dv > 0.04 && dv < 0.05, "|V| rose by {dv}");
}

fn step_pair(up: f64, down: f64) -> Vec<SetpointStep> {
    vec![
        SetpointStep {
            time_s: up,
            size_pu: 0.05,
            reference: StepReference::VRef,
        },
        SetpointStep {
            time_s: down,
            size_pu: -0.05,
            reference: StepReference::VRef,
        },
    ]
}

/// The event a recorder would make of a simulated closed-loop step: |V|, P, Q, E_fd (and I_fd,
/// and the angle when `angle`) at every sample, with the same steps.
fn recorded(ev: &Event, out: &ModeOutputs, theta: &[f64], ifd: bool, angle: bool) -> Event {
    let rec = Record {
        time_s: ev.record.time_s.clone(),
        v_mag_pu: out.v.clone(),
        v_ang_rad: theta.to_vec(),
        p_pu: out.p.clone(),
        q_pu: out.q.clone(),
        freq_hz: None,
        efd_pu: Some(out.efd.clone()),
        ifd_pu: ifd.then(|| out.ifd.clone()),
    };
    let mut ch = vec![Channel::V, Channel::P, Channel::Q, Channel::Efd];
    if ifd {
        ch.push(Channel::Ifd);
    }
    if angle {
        ch.push(Channel::Angle);
    }
    let decl = Declaration {
        channels: Some(ch),
        steps: ev.steps.clone(),
        ..Default::default()
    };
    Event::from_record_declared(
        "recorded",
        rec,
        ev.system_mva,
        ev.nominal_hz,
        Some(ev.init),
        None,
        &decl,
    )
    .unwrap()
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// A +5 %/−5 % set-point step simulated in closed loop (the Mostar unit, X_e = 0.1169), recorded
/// at 1 kHz, played back: the exciter alone gives back the closed loop's E_fd (with the recorded
/// I_fd, and with the machine's from the recorded E_fd), the machine from E_fd gives back its Q,
/// and a phasor playback with the same steps gives back P and Q. What remains is the linear
/// interpolation of the inputs between samples.
#[test]
fn the_open_loop_modes_reproduce_a_closed_loop_step() {
    let unit = mostar_unit();
    let ev = constant_event(8001, 0.001, 1.2, None, false, step_pair(1.0, 5.0));
    let pe = PreparedEvent::new(&ev);
    let cl = simulate_mode(&unit, &pe, PlaybackMode::ClosedLoop, &tight()).unwrap();
    let tr = simulate_mode_traces(&unit, &ev, PlaybackMode::ClosedLoop, &tight()).unwrap();
    let theta = tr.get("theta_term").unwrap();
    // The step is a real one: E_fd peaks above 4 pu, Q rises by about 0.4 pu.
    assert!(cl.efd.iter().cloned().fold(0.0, f64::max) > 4.0);
    assert!(cl.q[4900] - cl.q[0] > 0.35, "ΔQ {}", cl.q[4900] - cl.q[0]);

    for ifd in [true, false] {
        let rec = recorded(&ev, &cl, theta, ifd, false);
        let pr = PreparedEvent::new(&rec);
        let ex = simulate_mode(&unit, &pr, PlaybackMode::ExciterAlone, &tight()).unwrap();
        let err = max_abs_diff(&ex.efd, &cl.efd);
        eprintln!("exciter_alone (I_fd recorded: {ifd}): max |ΔE_fd| = {err:e}");
        assert!(err < 1e-4, "E_fd error {err:e}");
        // Away from the steps the interpolation error vanishes.
        let calm = (2000..4900).chain(6000..8001);
        let err_calm = calm
            .map(|k| (ex.efd[k] - cl.efd[k]).abs())
            .fold(0.0, f64::max);
        assert!(
            err_calm < 1e-5,
            "E_fd error away from the steps {err_calm:e}"
        );
    }
    let rec = recorded(&ev, &cl, theta, false, false);
    let pr = PreparedEvent::new(&rec);
    let m = simulate_mode(&unit, &pr, PlaybackMode::MachineFromEfd, &tight()).unwrap();
    let err = max_abs_diff(&m.q, &cl.q);
    eprintln!("machine_from_efd: max |ΔQ| = {err:e}");
    assert!(err < 1.5e-4, "Q error {err:e}");
    let err_ifd = max_abs_diff(&m.ifd, &cl.ifd);
    eprintln!("machine_from_efd: max |ΔX_adI_fd| = {err_ifd:e}");
    assert!(err_ifd < 3e-4, "X_adI_fd error {err_ifd:e}");

    // The phasor playback of the same record, with its angle and the steps, as recorded: a
    // computed record has no noise to smooth, and the default low-pass would move it by a few
    // 1e-5 where a stretch between edges ends (P then 5.9e-5 off).
    let mut rec = recorded(&ev, &cl, theta, false, true);
    rec.set_input_lowpass(None).unwrap();
    let pr = PreparedEvent::new(&rec);
    let (p, q) = simulate_pq(&mut unit.clone(), &pr, &tight()).unwrap();
    let (ep, eq) = (max_abs_diff(&p, &cl.p), max_abs_diff(&q, &cl.q));
    eprintln!("phasor with steps: max |ΔP| = {ep:e}, |ΔQ| = {eq:e}");
    assert!(ep < 5e-6 && eq < 5e-6, "P {ep:e}, Q {eq:e}");
    // Without the steps the phasor playback misses the AVR's action entirely.
    let mut no_steps = rec.clone();
    no_steps.steps.clear();
    let (_, q0) = simulate_pq(&mut unit.clone(), &PreparedEvent::new(&no_steps), &tight()).unwrap();
    assert!(max_abs_diff(&q0, &cl.q) > 0.1);
}

/// One playback giving traces and channels (`simulate_mode_both`) gives exactly what the two
/// functions give on their own, in every mode, on a recorded step (every channel, and the angle
/// the phasor playback needs): the same unit, integrator and steps, bit for bit.
#[test]
fn traces_and_channels_of_one_playback_are_each_functions_own() {
    let unit = mostar_unit();
    let ev = constant_event(3001, 0.001, 1.2, None, false, step_pair(0.5, 2.0));
    let cl = simulate_mode(
        &unit,
        &PreparedEvent::new(&ev),
        PlaybackMode::ClosedLoop,
        &tight(),
    )
    .unwrap();
    let tr = simulate_mode_traces(&unit, &ev, PlaybackMode::ClosedLoop, &tight()).unwrap();
    let rec = recorded(&ev, &cl, tr.get("theta_term").unwrap(), true, true);
    let mut no_steps = rec.clone();
    no_steps.steps.clear();
    for (event, mode) in [
        (&rec, PlaybackMode::ClosedLoop),
        (&rec, PlaybackMode::ExciterAlone),
        (&rec, PlaybackMode::MachineFromEfd),
        (&rec, PlaybackMode::Phasor),
        (&no_steps, PlaybackMode::Phasor),
    ] {
        let (traces, outputs) = simulate_mode_both(&unit, event, mode, &tight()).unwrap();
        let alone = simulate_mode(&unit, &PreparedEvent::new(event), mode, &tight()).unwrap();
        let traces_alone = simulate_mode_traces(&unit, event, mode, &tight()).unwrap();
        assert_eq!(traces.names, traces_alone.names, "{mode}");
        for (a, b) in traces.columns.iter().zip(&traces_alone.columns) {
            assert!(
                a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits()),
                "{mode}: a trace differs"
            );
        }
        for c in [
            Channel::P,
            Channel::Q,
            Channel::V,
            Channel::Efd,
            Channel::Ifd,
        ] {
            let (x, y) = (outputs.channel(c).unwrap(), alone.channel(c).unwrap());
            assert!(
                x.iter().zip(y).all(|(a, b)| a.to_bits() == b.to_bits()),
                "{mode}: channel {c:?} differs"
            );
        }
        assert_eq!(outputs.stats, alone.stats, "{mode}");
        // The traces' P and Q are the channels' (the same measuring device on both).
        assert_eq!(traces.get("p_pu").unwrap(), &outputs.p[..], "{mode}");
        assert!(outputs.p.iter().all(|v| v.is_finite()), "{mode}");
    }
}

/// A V_ref step enters at the voltage summing point (after the transducer lag T_R = 25 ms) and
/// from its instant on: with an algebraic bridge (T_1 = 0), the open-loop exciter's E_fd jumps
/// at the first sample at or after the step by the regulator's high-frequency gain times the
/// step, `K_R (T_C1/T_B1)(T_C2/T_B2) · 0.05`, and not before.
#[test]
fn a_set_point_step_enters_at_the_summing_point_from_its_instant() {
    let unit = mostar_unit().with_params(&[("exciter.t_1", 0.0)]).unwrap();
    let up = vec![SetpointStep {
        time_s: 1.0,
        size_pu: 0.05,
        reference: StepReference::VRef,
    }];
    let ev = constant_event(301, 0.01, 1.2, None, false, up);
    let o = simulate_mode(
        &unit,
        &PreparedEvent::new(&ev),
        PlaybackMode::ExciterAlone,
        &tight(),
    )
    .unwrap();
    let hf = 358.6086 * (1.071137 / 10.7561) * (3.414283 / 1.701033);
    assert!(
        (o.efd[99] - 1.2).abs() < 1e-12,
        "before the step: {}",
        o.efd[99]
    );
    let jump = o.efd[100] - 1.2;
    assert!(
        (jump - hf * 0.05).abs() < 1e-9,
        "E_fd jumps by {jump} at the step, expected {}",
        hf * 0.05
    );
}

/// A mode that cannot play the unit or the record back says why.
#[test]
fn modes_refuse_what_they_cannot_play_back() {
    let ev = constant_event(201, 0.01, 1.2, None, false, step_pair(0.5, 1.5));
    let pe = PreparedEvent::new(&ev);
    // No grid equivalent in the closed loop.
    let no_grid = mostar_unit().without(&["grid"]).unwrap();
    let e = simulate_mode(&no_grid, &pe, PlaybackMode::ClosedLoop, &tight()).unwrap_err();
    assert!(
        matches!(e, SimError::ModeSetup { .. }) && e.to_string().contains("grid_equivalent"),
        "{e}"
    );
    // No phasor playback without an angle.
    let e = simulate_mode(&mostar_unit(), &pe, PlaybackMode::Phasor, &tight()).unwrap_err();
    assert!(matches!(e, SimError::NoAngle { .. }), "{e}");
    // A stabiliser reading the rotor speed in a mode that does not simulate it.
    let e = simulate_mode(
        &with_pss("IEEEST"),
        &pe,
        PlaybackMode::ExciterAlone,
        &tight(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("rotor speed"), "{e}");
    // No E_fd for the modes that play it back.
    let mut rec = ev.record.clone();
    rec.efd_pu = None;
    let decl = Declaration {
        channels: Some(vec![Channel::V, Channel::P, Channel::Q]),
        ..Default::default()
    };
    let no_efd = Event::from_record_declared("no-efd", rec, 30.0, 50.0, None, None, &decl).unwrap();
    for mode in [PlaybackMode::ExciterAlone, PlaybackMode::MachineFromEfd] {
        let e = simulate_mode(&mostar_unit(), &PreparedEvent::new(&no_efd), mode, &tight())
            .unwrap_err();
        assert!(matches!(e, SimError::MissingChannel { .. }), "{e}");
    }
    // A V_ref step into an ESST1A whose stabiliser signal enters after the regulator.
    let mut u = mostar_unit();
    let mut esst1a = registry::find("ESST1A").unwrap().create();
    esst1a.set_option("vos", "2").unwrap();
    u.put("exciter", esst1a, &[]).unwrap();
    let e = simulate_mode(&u, &pe, PlaybackMode::ClosedLoop, &tight()).unwrap_err();
    assert!(e.to_string().contains("vos"), "{e}");
    // E_fd that no operating point of the machine holds at the measured |V| and P.
    let volts = constant_event(201, 0.01, 19.0, None, false, vec![]);
    let e = simulate_mode(
        &mostar_unit(),
        &PreparedEvent::new(&volts),
        PlaybackMode::MachineFromEfd,
        &tight(),
    );
    if let Err(e) = e {
        assert!(
            matches!(e, SimError::ModeInit { .. } | SimError::Init(_)),
            "{e}"
        );
    }
}
