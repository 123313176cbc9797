//! The smoothed input's spline and the searches' steps over its samples
//! ([`PlaybackInput::with_splines`], [`Dopri5Options::soft_knots`]).
//!
//! A low-passed voltage is band-limited far below the sample rate, so a natural cubic spline
//! through its samples follows it where a line between them cannot, and the spline's continuous
//! second derivative lets the adaptive integrator step over the samples: the playback then
//! costs fewer right-hand sides for the same P and Q within the tolerance.

use itaipu_dynamics::event::Event;
use itaipu_dynamics::integrate::{solve, Dopri5Options, Method, Stats, StepLog};
use itaipu_dynamics::simulate::{run_playback, simulate_pq, PreparedEvent, SimOptions};
use itaipu_dynamics::unit::{Playback, PlaybackInput};

use crate::playback_support;
use playback_support::{synthetic_dip, synthetic_unit as unit};

/// A 20 s fault dip into the synthetic unit at 60 samples/s with PMU noise (seed 5), played
/// back smoothed at the default cut-off (the synthetic path's default).
fn record() -> Event {
    let ev = synthetic_dip(20.0, 5);
    assert_eq!(ev.input_lowpass_hz, Some(4.0), "the default playback");
    ev
}

fn event() -> PreparedEvent {
    PreparedEvent::new(&record())
}

fn dopri(soft_knots: bool) -> Dopri5Options {
    Dopri5Options {
        soft_knots,
        ..Dopri5Options::search()
    }
}

/// A 2 Hz swing (the top of the electromechanical band) at 30 samples/s: between samples the
/// spline is within 1e-4 of it (measured 2.9e-5), a line is more than 5e-4 off (1.1e-3 by
/// `h²ω²A/8`); both pass through the samples. The knots inside the stretch are soft, its ends
/// and the samples outside it are not.
#[test]
fn a_spline_follows_a_band_limited_input_where_a_line_cannot() {
    let f = |t: f64| 1.0 + 0.05 * (2.0 * std::f64::consts::PI * 2.0 * t).sin();
    let t: Vec<f64> = (0..=90).map(|k| k as f64 / 30.0).collect();
    let v: Vec<f64> = t.iter().map(|&t| f(t)).collect();
    let a = vec![0.1; t.len()];
    // Samples 0-9 kept raw (an edge), 10-90 smoothed.
    let marked: Vec<bool> = (0..t.len()).map(|k| k >= 10).collect();
    let spline = PlaybackInput::with_splines(t.clone(), v.clone(), a.clone(), &marked);
    let line = PlaybackInput::linear(t.clone(), v.clone(), a);
    let (mut c1, mut c2) = (0, 0);
    let (mut e_spline, mut e_line) = (0.0f64, 0.0f64);
    for k in 12..88 {
        for frac in [0.0, 0.25, 0.5, 0.75] {
            let tk = t[k] + frac / 30.0;
            let (vs, ang) = spline.at_spline(tk, &mut c1);
            let (vl, _) = line.at(tk, &mut c2);
            assert_eq!(ang, 0.1, "a constant stays constant");
            if frac == 0.0 {
                assert!((vs - v[k]).abs() < 1e-15 && (vl - v[k]).abs() < 1e-15);
            }
            e_spline = e_spline.max((vs - f(tk)).abs());
            e_line = e_line.max((vl - f(tk)).abs());
        }
    }
    eprintln!("2 Hz at 30 samples/s: spline {e_spline:.2e}, line {e_line:.2e}");
    assert!(e_spline < 1e-4, "spline {e_spline:e}");
    assert!(e_line > 5e-4, "line {e_line:e}");
    // On the raw part the spline input is the line.
    for t_k in &t[..9] {
        let tk = t_k + 0.5 / 30.0;
        assert_eq!(spline.at_spline(tk, &mut c1), line.at(tk, &mut c2));
        assert_eq!(spline.at(tk, &mut c1), line.at(tk, &mut c2));
    }
    let soft: Vec<usize> = (0..t.len()).filter(|&k| spline.soft_knot(k)).collect();
    assert_eq!(soft, (11..90).collect::<Vec<_>>());
    assert!((0..t.len()).all(|k| !line.soft_knot(k)));
    // A stretch too short for a spline stays linear.
    let short: Vec<bool> = (0..t.len()).map(|k| (20..23).contains(&k)).collect();
    let s = PlaybackInput::with_splines(t.clone(), v.clone(), vec![0.0; t.len()], &short);
    assert!((0..t.len()).all(|k| !s.soft_knot(k)));
}

/// The states at every sample of a playback of `ev` on the spline input (or the linear one),
/// and the integrator's counts.
fn states(ev: &PreparedEvent, o: Dopri5Options, spline: bool) -> (Vec<Vec<f64>>, Stats) {
    let mut u = unit();
    let mut x = u.initialise(&ev.machine_point(&u)).unwrap();
    let mut sys = Playback::new(&mut u, &ev.input).over_samples(spline);
    let mut xs = vec![];
    let stats = solve(
        &Method::Dopri5(o),
        &mut sys,
        &mut x,
        &ev.input.time_s,
        |k, _, x: &[f64], _: &mut Playback| {
            assert_eq!(k, xs.len(), "the samples in order");
            xs.push(x.to_vec());
        },
    )
    .unwrap();
    (xs, stats)
}

/// Largest difference of two state histories, each state against its own scale (at least 1).
fn worst(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    a.iter()
        .zip(b)
        .flat_map(|(x, y)| x.iter().zip(y))
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs() / y.abs().max(1.0)))
}

/// On the 20 s dip, on the spline input at the search tolerance (rtol 1e-4 since stop 57):
/// stepping over the soft samples, every state at every sample within 3 × rtol of rtol 1e-9's
/// (each against its own scale, at least 1; measured 5.8e-5, and 9.5e-6 landing on every
/// sample, whose steps the samples hold shorter than the tolerance asks; at rtol 1e-5 1.2e-5
/// and 2.0e-6), for at most 80 % of the right-hand sides landing on every sample takes
/// (measured 35 %; 39 % at 1e-5). A logged run lands on every sample whatever the option (its
/// replay does): the same step ends as without it. The linear input moves the states further
/// than either (after the fault is cleared the angle swings, and a line between samples cuts
/// its corners: measured 1.5e-4 in the states, 2.7 × the error stepping over at rtol 1e-4;
/// 4e-3 pu in P at the samples just after it, the PMU noise being 2e-3), which is why the
/// option plays the spline: the samples are soft only on it.
#[test]
fn stepping_over_soft_knots_keeps_the_states_for_fewer_evaluations() {
    let ev = event();
    let (soft, s_soft) = states(&ev, dopri(true), true);
    let (hard, s_hard) = states(&ev, dopri(false), true);
    let accurate = Dopri5Options {
        rtol: 1e-9,
        atol: 1e-10,
        h_max: 0.02,
        ..Default::default()
    };
    let (acc, _) = states(&ev, accurate.clone(), true);
    let (acc_linear, _) = states(&ev, accurate, false);
    let (e_soft, e_hard, e_input) = (
        worst(&soft, &acc),
        worst(&hard, &acc),
        worst(&acc_linear, &acc),
    );
    eprintln!(
        "against rtol 1e-9 on the spline: stepping over the samples {e_soft:.2e}, landing on each \
         {e_hard:.2e}; the linear input {e_input:.2e}; right-hand sides {} against {} ({:.0} %)",
        s_soft.rhs_evals,
        s_hard.rhs_evals,
        100.0 * s_soft.rhs_evals as f64 / s_hard.rhs_evals as f64
    );
    assert_eq!(soft.len(), ev.input.time_s.len(), "every sample observed");
    let rtol = dopri(true).rtol;
    assert!(
        e_soft < 3.0 * rtol && e_hard < e_soft,
        "{e_soft:e} ({e_hard:e} landing)"
    );
    assert!(e_input > 2.0 * e_soft, "{e_input:e}");
    assert!(
        (s_soft.rhs_evals as f64) < 0.8 * s_hard.rhs_evals as f64,
        "{} against {}",
        s_soft.rhs_evals,
        s_hard.rhs_evals
    );
    // Through the playback API: the option plays the spline and steps over the samples.
    let opts = |o| SimOptions {
        method: Method::Dopri5(o),
    };
    let api = run_playback(&mut unit(), &ev, &opts(dopri(true)), |_, _, _| true).unwrap();
    assert_eq!(api.rhs_evals, s_soft.rhs_evals);
    let ends = |o: Dopri5Options| {
        let log = StepLog::default();
        simulate_pq(
            &mut unit(),
            &ev,
            &SimOptions {
                method: Method::Dopri5Logged(o, log.clone()),
            },
        )
        .unwrap();
        log.times()
    };
    assert_eq!(ends(dopri(true)), ends(dopri(false)));
}

/// The default event's input is a spline on its smoothed stretches; the same record played as
/// recorded is linear throughout.
#[test]
fn the_default_playback_input_is_a_spline_and_as_recorded_is_not() {
    let ev = event();
    let soft = (0..ev.input.time_s.len())
        .filter(|&k| ev.input.soft_knot(k))
        .count();
    // The fault's edges and their margins stay raw; the rest is smooth.
    assert!(
        soft * 10 > ev.input.time_s.len() * 9,
        "{soft} of {}",
        ev.input.time_s.len()
    );
    let mut raw = record();
    raw.set_input_lowpass(None).unwrap();
    let raw = PreparedEvent::new(&raw);
    assert!((0..raw.input.time_s.len()).all(|k| !raw.input.soft_knot(k)));
}
