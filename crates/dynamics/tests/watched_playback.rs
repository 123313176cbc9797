//! A playback whose observer says "enough" stops there ([`GoOn`]), and a watched playback shows
//! each sample's P and Q as they will be returned: on every integrator, with and without a
//! measuring device that acts on the recorded series after the playback.

use itaipu_dynamics::integrate::{Dopri5Options, Method, SolveError};
use itaipu_dynamics::mode::{simulate_mode, simulate_mode_watched, PlaybackMode};
use itaipu_dynamics::simulate::{
    run_playback, simulate_pq, simulate_pq_watched, PreparedEvent, SimError, SimOptions,
};

use crate::playback_support;
use playback_support::{synthetic_dip, synthetic_unit as unit};

/// A 6 s dip into the synthetic unit at 60 samples/s (PMU noise, seed 2).
fn event() -> PreparedEvent {
    PreparedEvent::new(&synthetic_dip(6.0, 2))
}

fn methods(ev: &PreparedEvent) -> Vec<Method> {
    let logged = itaipu_dynamics::integrate::StepLog::default();
    let opts = Dopri5Options {
        rtol: 1e-6,
        atol: 1e-7,
        h_max: 0.05,
        ..Default::default()
    };
    simulate_pq(
        &mut unit(),
        ev,
        &SimOptions {
            method: Method::Dopri5Logged(opts.clone(), logged.clone()),
        },
    )
    .unwrap();
    vec![
        Method::Rk4 { h: 2e-3 },
        Method::Dopri5(opts.clone()),
        // The samples observed on the dense output (the smoothed input's spline).
        Method::Dopri5(Dopri5Options {
            soft_knots: true,
            ..opts
        }),
        Method::Replay(logged.times()),
    ]
}

#[test]
fn an_observer_that_says_enough_stops_the_playback_at_that_sample() {
    let ev = event();
    let stop_at = 100;
    for method in methods(&ev) {
        let opts = SimOptions {
            method: method.clone(),
        };
        let mut seen = vec![];
        let err = run_playback(&mut unit(), &ev, &opts, |k, _, _| {
            seen.push(k);
            k < stop_at
        })
        .unwrap_err();
        assert!(err.is_stopped(), "{method}: {err}");
        let SimError::Solve(SolveError::Stopped { t }) = err else {
            unreachable!()
        };
        assert_eq!(t, ev.input.time_s[stop_at], "{method}");
        assert_eq!(seen, (0..=stop_at).collect::<Vec<_>>(), "{method}");
        // An observer that returns nothing runs to the end, as before.
        let mut n = 0;
        run_playback(&mut unit(), &ev, &opts, |_, _, _| n += 1).unwrap();
        assert_eq!(n, ev.input.time_s.len(), "{method}");
    }
}

#[test]
fn a_watched_playback_shows_the_samples_it_returns_and_stops_when_told() {
    let ev = event();
    let n = ev.input.time_s.len();
    let mut with_device = unit();
    with_device
        .put(
            "measurement",
            itaipu_dynamics::registry::find("pmu_measurement")
                .unwrap()
                .create(),
            &[],
        )
        .unwrap();
    let delay = with_device.param("measurement.pq_delay_s").unwrap();
    with_device.set(delay, 0.03);
    assert!(with_device.transforms_pq() && !unit().transforms_pq());
    for method in methods(&ev) {
        let opts = SimOptions {
            method: method.clone(),
        };
        for u in [unit(), with_device.clone()] {
            let whole = simulate_pq(&mut u.clone(), &ev, &opts).unwrap();
            let mut shown = (vec![f64::NAN; n], vec![f64::NAN; n]);
            let watched = simulate_pq_watched(&mut u.clone(), &ev, &opts, |k, p, q| {
                shown.0[k] = p;
                shown.1[k] = q;
                true
            })
            .unwrap()
            .expect("never stopped");
            assert_eq!(watched, whole, "{method}");
            assert_eq!(
                shown, whole,
                "{method}: the samples shown are the ones returned"
            );
            let mut last = 0;
            let stopped = simulate_pq_watched(&mut u.clone(), &ev, &opts, |k, _, _| {
                last = k;
                k < 50
            })
            .unwrap();
            assert!(stopped.is_none() && last == 50, "{method}");

            let whole = simulate_mode(&u, &ev, PlaybackMode::Phasor, &opts).unwrap();
            let mut efd = vec![f64::NAN; n];
            let watched = simulate_mode_watched(&u, &ev, PlaybackMode::Phasor, &opts, |k, o| {
                efd[k] = o.efd[k];
                true
            })
            .unwrap()
            .expect("never stopped");
            assert_eq!(watched.p, whole.p, "{method}");
            assert_eq!(watched.efd, whole.efd, "{method}");
            assert_eq!(efd, whole.efd, "{method}");
            let stopped =
                simulate_mode_watched(&u, &ev, PlaybackMode::Phasor, &opts, |k, _| k < 10).unwrap();
            assert!(stopped.is_none(), "{method}");
        }
    }
}

/// The work meter ([`attempts_on_this_thread`]) counts every step attempt of an adaptive run,
/// accepted and rejected, a run its observer stopped and a run out of its budget included, and
/// nothing for a replay.
#[test]
fn the_work_meter_counts_every_attempt_of_an_adaptive_run() {
    use itaipu_dynamics::integrate::dopri5::attempts_on_this_thread;
    let ev = event();
    let opts = Dopri5Options {
        rtol: 1e-6,
        atol: 1e-7,
        h_max: 0.05,
        ..Default::default()
    };
    let sim = SimOptions {
        method: Method::Dopri5(opts.clone()),
    };
    let a0 = attempts_on_this_thread();
    let stats = run_playback(&mut unit(), &ev, &sim, |_, _, _| {}).unwrap();
    let whole = stats.steps_accepted + stats.steps_rejected;
    assert!(whole > 100, "{whole} attempts");
    assert_eq!(attempts_on_this_thread() - a0, whole as u64);
    // Stopped by its observer at sample 60 of 360 (an error that carries no counts): the
    // attempts up to there, the same as the whole run's up to that sample.
    let a1 = attempts_on_this_thread();
    let upto = |k_stop: usize| {
        let sim = sim.clone();
        let ev = &ev;
        move || run_playback(&mut unit(), ev, &sim, |k, _, _| k < k_stop)
    };
    assert!(matches!(
        upto(60)(),
        Err(SimError::Solve(SolveError::Stopped { .. }))
    ));
    let part = attempts_on_this_thread() - a1;
    assert!(part > 0 && part < whole as u64 / 2, "{part} of {whole}");
    let a2 = attempts_on_this_thread();
    assert!(upto(60)().is_err());
    assert_eq!(attempts_on_this_thread() - a2, part);
    // Out of budget: every attempt it made before giving up.
    let tight = SimOptions {
        method: Method::Dopri5(Dopri5Options {
            max_steps: 50,
            ..opts.clone()
        }),
    };
    let a3 = attempts_on_this_thread();
    assert!(run_playback(&mut unit(), &ev, &tight, |_, _, _| {}).is_err());
    assert_eq!(attempts_on_this_thread() - a3, 50);
    // A replay of logged steps is not an adaptive run.
    let log = itaipu_dynamics::integrate::StepLog::default();
    let logged = SimOptions {
        method: Method::Dopri5Logged(opts, log.clone()),
    };
    run_playback(&mut unit(), &ev, &logged, |_, _, _| {}).unwrap();
    let a4 = attempts_on_this_thread();
    let replay = SimOptions {
        method: Method::Replay(log.times()),
    };
    run_playback(&mut unit(), &ev, &replay, |_, _, _| {}).unwrap();
    assert_eq!(attempts_on_this_thread(), a4);
}
