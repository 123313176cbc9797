//! The swarm simulates each candidate only as far as it can still beat its particle's best
//! (`Problem::cost_bounded`, `pso::minimize_bounded`): the objective bit for bit where it
//! matters, a stop where it cannot, and the same swarm, bit for bit, as with whole playbacks;
//! with priors, with the field channels compared, and with a measuring device that acts on the
//! recorded series after the playback.

use itaipu_calib::diagnose::trial::{base_unit, dip_event_with_field, dip_problem};
use itaipu_calib::problem::{search_integrator, EventData, Prior, Problem};
use itaipu_calib::pso::{self, PsoOptions};
use itaipu_calib::spec::Compare;
use itaipu_dynamics::event::Channel;
use itaipu_dynamics::mode::PlaybackMode;

/// A 10 s dip into the synthetic unit (PMU noise, seed 4), five parameters free at 15 % above
/// their values, priors on two.
fn problem() -> Problem {
    let mut pb = dip_problem(
        base_unit(),
        &[
            ("machine.h", 2.0, 8.0),
            ("machine.x_d", 0.6, 1.4),
            ("exciter.k", 20.0, 400.0),
            ("exciter.te", 0.01, 0.5),
            ("pss.k_x", 0.1, 5.0),
        ],
        10.0,
        4,
        1.15,
    );
    for (i, spread) in [(0, 0.1), (2, 0.3)] {
        let c = pb.unit.get(pb.free[i].r);
        pb.free[i].prior = Some(Prior { center: c, spread });
    }
    pb.prior_weight = 0.5;
    pb
}

/// `problem()` with the unit's field recorded (with noise) and E_fd compared with P and Q.
fn with_field() -> Problem {
    let mut pb = problem();
    let ev = dip_event_with_field(&base_unit(), 10.0, 4, 5);
    assert_eq!(ev.record.p_pu, pb.events[0].p_meas, "dip_problem's record");
    pb.events = vec![EventData::new(&ev, None, None).unwrap()];
    pb.compare = Some(Compare {
        mode: PlaybackMode::Phasor,
        weights: vec![(Channel::P, 1.0), (Channel::Q, 1.0), (Channel::Efd, 0.04)],
    });
    pb
}

/// `problem()` with a measuring device delaying P and Q by 20 ms behind the voltage.
fn with_device() -> Problem {
    let mut pb = problem();
    pb.unit
        .put(
            "measurement",
            itaipu_dynamics::registry::find("pmu_measurement")
                .unwrap()
                .create(),
            &[],
        )
        .unwrap();
    let r = pb.unit.param("measurement.pq_delay_s").unwrap();
    pb.unit.set(r, 0.02);
    assert!(pb.unit.transforms_pq());
    pb
}

fn check(pb: &Problem, what: &str) {
    let sim = search_integrator();
    let x = pb.start();
    let full = pb.cost(&x, &sim);
    assert!(full.is_finite() && full < pb.penalty, "{what}: {full}");
    // Above the objective (or no bound): the objective, bit for bit.
    for bound in [f64::INFINITY, pb.penalty, full * 1.001] {
        assert_eq!(
            pb.cost_bounded(&x, &sim, bound).to_bits(),
            full.to_bits(),
            "{what}: bound {bound}"
        );
    }
    // Below it: at or above the bound, and short of the objective, for a device that acts
    // after the playback too (the samples are then summed once it ends).
    let stopped = pb.cost_bounded(&x, &sim, full / 3.0);
    assert!(
        stopped >= full / 3.0 && stopped < full,
        "{what}: {stopped} for a bound {} and an objective {full}",
        full / 3.0
    );

    // The swarm: bit for bit the swarm with whole playbacks.
    let opts = PsoOptions {
        particles: 8,
        iterations: 6,
        seed: 11,
        stall_iterations: 0,
        failed_cost: pb.penalty,
        ..Default::default()
    };
    let u0 = pb.to_unit(&x);
    let whole = pso::minimize(
        |u: &[f64]| pb.cost(&pb.from_unit(u), &sim),
        u0.len(),
        Some(&u0),
        &opts,
        |_, _| {},
    );
    let stops = std::sync::atomic::AtomicUsize::new(0);
    let bounded = pso::minimize_bounded(
        |u: &[f64], bound: f64| {
            let c = pb.cost_bounded(&pb.from_unit(u), &sim, bound);
            if c >= bound && c < pb.cost(&pb.from_unit(u), &sim) {
                stops.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            }
            c
        },
        u0.len(),
        Some(&u0),
        &opts,
        |_, _| {},
        || false,
    );
    assert_eq!(bounded.best, whole.best, "{what}");
    assert_eq!(
        bounded.best_cost.to_bits(),
        whole.best_cost.to_bits(),
        "{what}"
    );
    assert_eq!(bounded.history, whole.history, "{what}");
    assert_eq!(bounded.personal_bests, whole.personal_bests, "{what}");
    assert_eq!(bounded.evaluations, whole.evaluations, "{what}");
    let stops = stops.into_inner();
    assert!(
        stops >= opts.particles,
        "{what}: only {stops} candidates stopped early"
    );
}

#[test]
fn a_bounded_swarm_is_the_whole_swarm_bit_for_bit() {
    check(&problem(), "P and Q with priors");
}

#[test]
fn a_bounded_swarm_comparing_the_field_is_the_whole_swarm() {
    let pb = with_field();
    assert!(pb.events[0].efd_meas.is_some());
    check(&pb, "P, Q and E_fd");
}

#[test]
fn a_bounded_swarm_through_a_measuring_device_is_the_whole_swarm() {
    check(&with_device(), "a delayed P and Q");
}

/// The Levenberg-Marquardt iterations stop a trial step's playback once it cannot lower the
/// objective: the same iterations, bit for bit, as with whole playbacks (the same problem with
/// a penalty of 0, below every bound, never stops one), with sensitivities (a diagnosis
/// re-fit) and with differences (a calibration), on P and Q and on the field.
#[test]
fn a_bounded_local_method_takes_the_whole_playbacks_steps() {
    use itaipu_calib::local::{levenberg_marquardt, LmStop};
    for (make, what) in [
        (problem as fn() -> Problem, "P and Q"),
        (with_field, "P, Q and E_fd"),
    ] {
        for stop in [LmStop::COMPARISON, LmStop::CALIBRATION] {
            let (bounded, mut whole) = (make(), make());
            whole.penalty = 0.0;
            let x0 = bounded.start();
            let a = levenberg_marquardt(&bounded, &x0, 8, stop);
            let b = levenberg_marquardt(&whole, &x0, 8, stop);
            assert_eq!(a.best, b.best, "{what}, {stop:?}");
            assert_eq!(a.best_cost.to_bits(), b.best_cost.to_bits(), "{what}");
            assert_eq!((a.iterations, &a.stopped_by), (b.iterations, &b.stopped_by));
            assert_eq!(bounded.simulations(), whole.simulations(), "{what}");
            assert!(a.iterations >= 2 && a.best_cost < bounded.cost(&x0, &search_integrator()));
        }
    }
}

/// A grid scan takes its best point only when it is below the start: bounded by the start's
/// objective, the best point and its objective are the whole scan's, bit for bit.
#[test]
fn a_bounded_scan_finds_the_whole_scans_best() {
    let pb = problem();
    let sim = search_integrator();
    let x0 = pb.start();
    let start = pb.cost(&x0, &sim);
    // machine.h over its range: the truth (1/1.15 of the start) lies between grid points.
    let points: Vec<Vec<f64>> = (0..9)
        .map(|i| {
            let mut x = x0.clone();
            x[0] = 2.0 + 6.0 * i as f64 / 8.0;
            x
        })
        .collect();
    let whole = pb.best_of(&points, &sim);
    let bounded = pb.best_of_below(&points, &sim, start);
    assert!(whole.0 < start, "a grid point below the start");
    assert_eq!(
        (bounded.0.to_bits(), bounded.1),
        (whole.0.to_bits(), whole.1)
    );
    // The grid's ends stop short of their objective (and at or above the start's).
    let stopped = [&points[0], &points[8]]
        .iter()
        .filter(|x| {
            let (c, exact) = (pb.cost_bounded(x, &sim, start), pb.cost(x, &sim));
            c >= start && c < exact
        })
        .count();
    assert!(stopped >= 1, "no grid point stopped early");
}
