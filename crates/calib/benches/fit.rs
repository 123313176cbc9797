//! Calibration benchmarks (divan): `cargo bench -p itaipu-calib`.
//!
//! * `itaipu_fit_gen_avr_pss`: the whole bundled fit (RaPId's 18-parameter problem: generator,
//!   AVR and PSS stages, then the joint refinement) on the Itaipu record, all threads;
//! * `itaipu_gen_swarm`: the generator stage's swarm alone (40 particles, 10 iterations,
//!   440 objective evaluations) in a pool of 1 and of 2 threads, for the parallel speed-up;
//! * `diagnose_full_catalog_20s`: `diagnose` with the whole catalog (default options) on a 20 s
//!   synthetic fault-dip event at 60 samples/s with PMU noise, on the generic hydro unit (the
//!   issue's target: within 60 s on this 2-core machine);
//! * `jacobian_adaptive_differences` / `jacobian_replayed` / `jacobian_sensitivities`: one
//!   Levenberg-Marquardt Jacobian (12 parameters, a 20 s synthetic dip) by differences of
//!   adaptive runs, on replays, and by forward sensitivities;
//! * `swarm_whole_or_bounded`: one swarm with whole playbacks and with bounded ones (each
//!   candidate stopped once it cannot beat its particle's best);
//! * `practice_fit_and_diagnose`: the default fit and the diagnosis of the bundled practice case
//!   p01 with every uncertain parameter free (target: within 60 s).

use std::path::PathBuf;

use divan::Bencher;
use itaipu_calib::fit::{fit, FitOptions, Silent};
use itaipu_calib::spec::CalibSpec;
use itaipu_dynamics::event::Event;
use itaipu_dynamics::unit::Unit;
use itaipu_dynamics::unit_file::read_unit;

fn main() {
    divan::main();
}

fn inputs() -> (Unit, Event, CalibSpec) {
    let data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/itaipu");
    (
        read_unit(&data.join("unit.toml")).unwrap(),
        Event::from_toml_file(&data.join("event.toml")).unwrap(),
        CalibSpec::from_file(&data.join("calibration.toml")).unwrap(),
    )
}

#[divan::bench(sample_count = 1, sample_size = 1)]
fn itaipu_fit_gen_avr_pss(bencher: Bencher) {
    let (unit, event, spec) = inputs();
    let mut opts = FitOptions::from_spec(&spec);
    opts.stages = vec!["gen".into(), "avr".into(), "pss".into()];
    bencher.bench_local(|| {
        fit(
            &unit,
            &spec,
            std::slice::from_ref(&event),
            &[],
            &opts,
            &Silent,
        )
        .unwrap()
    });
}

#[divan::bench(args = [1, 2], sample_count = 3, sample_size = 1)]
fn itaipu_gen_swarm(bencher: Bencher, threads: usize) {
    let (unit, event, spec) = inputs();
    let mut opts = FitOptions::from_spec(&spec);
    opts.stages = vec!["gen".into()];
    opts.pso_iterations = 10;
    opts.lbfgs_iterations = 0;
    opts.polish = false;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    bencher.bench_local(|| {
        pool.install(|| {
            fit(
                &unit,
                &spec,
                std::slice::from_ref(&event),
                &[],
                &opts,
                &Silent,
            )
            .unwrap()
        })
    });
}

#[divan::bench(sample_count = 1, sample_size = 1)]
fn diagnose_full_catalog_20s(bencher: Bencher) {
    use itaipu_calib::diagnose::trial::{base_unit, scenario, truth_and_event};
    use itaipu_calib::diagnose::{diagnose, DiagnoseOptions};
    let (_, event) = truth_and_event(&scenario("none", 101, None)).unwrap();
    let unit = base_unit();
    bencher.bench_local(|| {
        diagnose(
            &unit,
            std::slice::from_ref(&event),
            &[],
            &DiagnoseOptions::default(),
            &Silent,
        )
        .unwrap()
    });
}

/// The practice protocol on the bundled practice case p01 (20 s fault record at 30 samples/s,
/// made by an independent implementation): the default staged fit of the nominal unit with the
/// one practice spec (20 parameters free), then `diagnose` re-fitting the whole calibrated set
/// with the calibration's prior. The target: within 60 s on 2 cores.
#[divan::bench(sample_count = 1, sample_size = 1)]
fn practice_fit_and_diagnose(bencher: Bencher) {
    use itaipu_calib::practice::{fit_and_diagnose, PracticeCase};
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/practice/cases/p01");
    let case = PracticeCase::load(&dir).unwrap();
    bencher.bench(|| {
        let (_, d) = fit_and_diagnose(&case, &Silent).unwrap();
        divan::black_box(d.report.verdict.cause)
    });
}

/// The problem of one Jacobian: a 20 s fault dip at 60 samples/s with PMU noise into the
/// synthetic unit, twelve parameters of its four blocks free, at 10 % off their values.
fn jacobian_problem() -> itaipu_calib::problem::Problem {
    use itaipu_calib::diagnose::trial::{base_unit, dip_problem};
    dip_problem(
        base_unit(),
        &[
            ("machine.h", 2.0, 8.0),
            ("machine.x_d", 0.6, 1.4),
            ("machine.x_d_prime", 0.2, 0.45),
            ("machine.t_d0_prime", 3.0, 12.0),
            ("exciter.k", 20.0, 400.0),
            ("exciter.te", 0.01, 0.5),
            ("exciter.tb", 1.0, 20.0),
            ("pss.k_x", 0.1, 5.0),
            ("pss.t_x2", 0.5, 10.0),
            ("governor.t_g", 0.1, 1.0),
            ("governor.t_w", 0.5, 3.0),
            ("governor.r_temp", 0.1, 0.8),
        ],
        20.0,
        1,
        1.1,
    )
}

/// One Levenberg-Marquardt Jacobian (12 columns, [`jacobian_problem`]) as a calibration took it
/// before replays: the residuals on Dormand-Prince at rtol 1e-7, then one adaptive run per
/// column.
#[divan::bench(sample_count = 5, sample_size = 1)]
fn jacobian_adaptive_differences(bencher: Bencher) {
    use itaipu_calib::local::{jacobian_columns, lm_integrator, LM_RTOL};
    let problem = jacobian_problem();
    let u = problem.to_unit(&problem.start());
    let sim = lm_integrator(LM_RTOL);
    bencher.bench_local(|| {
        let r = problem
            .residuals_logged(&problem.from_unit(&u), &sim)
            .unwrap();
        jacobian_columns(&problem, &u, &r, &[], &sim)
    });
}

/// The same Jacobian on replays, as a calibration takes it now: the residuals at rtol 1e-7, a
/// logged run at `JACOBIAN_RTOL`, then its replay at the point and one per column.
#[divan::bench(sample_count = 5, sample_size = 1)]
fn jacobian_replayed(bencher: Bencher) {
    use itaipu_calib::local::{jacobian_columns, lm_integrator, JACOBIAN_RTOL, LM_RTOL};
    use itaipu_dynamics::integrate::{Dopri5Options, Method};
    let problem = jacobian_problem();
    let u = problem.to_unit(&problem.start());
    let sim = lm_integrator(LM_RTOL);
    let Method::Dopri5(o) = &sim.method else {
        unreachable!()
    };
    let coarse = Dopri5Options {
        rtol: JACOBIAN_RTOL,
        atol: 0.1 * JACOBIAN_RTOL,
        ..o.clone()
    };
    bencher.bench_local(|| {
        let x = problem.from_unit(&u);
        let r = problem.residuals_logged(&x, &sim).unwrap();
        let (_, steps) = problem.residuals_with_steps(&x, &coarse).unwrap();
        jacobian_columns(&problem, &u, &r, &steps, &sim)
    });
}

/// The same Jacobian by forward sensitivities, as [`itaipu_calib::local::LmStop::sensitivities`]
/// takes it: the residuals at rtol 1e-7 with their steps logged, then the states and the twelve
/// columns' sensitivities on those steps (two passes of eight lanes, in parallel).
#[divan::bench(sample_count = 5, sample_size = 1)]
fn jacobian_sensitivities(bencher: Bencher) {
    use itaipu_calib::local::{lm_integrator, LM_RTOL};
    use itaipu_dynamics::integrate::Method;
    let problem = jacobian_problem();
    let u = problem.to_unit(&problem.start());
    let sim = lm_integrator(LM_RTOL);
    let Method::Dopri5(o) = &sim.method else {
        unreachable!()
    };
    bencher.bench_local(|| {
        let x = problem.from_unit(&u);
        let (_, steps) = problem.residuals_with_steps(&x, o).unwrap();
        let sims: Vec<_> = steps.iter().collect();
        problem.sensitivity_jacobian(&u, &sims).unwrap()
    });
}

/// A swarm of 20 particles and 10 iterations on [`jacobian_problem`] (220 candidates, search
/// integrator), with whole playbacks (`whole`) and with each candidate simulated only as far as
/// it can still beat its particle's best (`bounded`, as the calibration runs it): the same swarm
/// bit for bit (`tests/bounded_swarm.rs`), the time saved by the stops.
#[divan::bench(args = ["whole", "bounded"], sample_count = 3, sample_size = 1)]
fn swarm_whole_or_bounded(bencher: Bencher, how: &str) {
    use itaipu_calib::problem::search_integrator;
    use itaipu_calib::pso::{minimize, minimize_bounded, PsoOptions};
    let problem = jacobian_problem();
    let sim = search_integrator();
    let u0 = problem.to_unit(&problem.start());
    let opts = PsoOptions {
        particles: 20,
        iterations: 10,
        seed: 1,
        failed_cost: problem.penalty,
        ..Default::default()
    };
    bencher.bench_local(|| {
        let n = u0.len();
        if how == "whole" {
            minimize(
                |u: &[f64]| problem.cost(&problem.from_unit(u), &sim),
                n,
                Some(&u0),
                &opts,
                |_, _| {},
            )
        } else {
            minimize_bounded(
                |u: &[f64], b: f64| problem.cost_bounded(&problem.from_unit(u), &sim, b),
                n,
                Some(&u0),
                &opts,
                |_, _| {},
                || false,
            )
        }
    });
}
