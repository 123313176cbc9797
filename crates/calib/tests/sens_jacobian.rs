//! The Levenberg-Marquardt Jacobian by forward sensitivities
//! (`Problem::sensitivity_jacobian`) against central differences of the residuals on a tight
//! integrator: the playback's columns, the chain to box coordinates (linear and logarithmic
//! boxes), a tied parameter moving with its source, and the priors' rows.

use itaipu_calib::diagnose::trial::{base_unit, dip_event_with_field, dip_problem};
use itaipu_calib::local::lm_integrator;
use itaipu_calib::problem::{Prior, Problem};
use itaipu_dynamics::integrate::Method;

/// A 20 s dip into the synthetic unit (GENSAE, SEXS, STAB3, HYGOV; PMU noise, seed 1), eight
/// parameters free at 10 % above their values, priors on three, X''_q tied to X''_d.
fn problem() -> Problem {
    let mut pb = dip_problem(
        base_unit(),
        &[
            ("machine.h", 2.0, 8.0),
            ("machine.x_d", 0.6, 1.4),
            ("machine.x_d_pp", 0.15, 0.3),
            ("exciter.k", 20.0, 400.0),
            ("exciter.te", 0.01, 0.5),
            ("pss.k_x", 0.1, 5.0),
            ("governor.t_w", 0.5, 3.0),
            ("governor.r_temp", 0.1, 0.8),
        ],
        20.0,
        1,
        1.1,
    );
    for (i, spread) in [(1, 0.1), (3, 0.3), (6, 0.2)] {
        let c = pb.unit.get(pb.free[i].r);
        pb.free[i].prior = Some(Prior { center: c, spread });
    }
    pb.prior_weight = 0.5;
    let (from, to) = (
        pb.unit.param("machine.x_d_pp").unwrap(),
        pb.unit.param("machine.x_q_pp").unwrap(),
    );
    pb.ties.push((from, to));
    pb
}

#[test]
fn the_sensitivity_jacobian_is_the_derivative_of_the_residuals() {
    let pb = problem();
    assert!(pb.free.iter().any(|f| f.log) && pb.free.iter().any(|f| !f.log));
    columns_match_differences(&pb);
}

/// The same dip with the field recorded too (the unit's E_fd and X_ad I_fd with noise, σ 0.01
/// and 0.005 pu, seed 3) and compared by the phasor playback with P and Q (weights by their
/// noise): the field channels' rows come out of the same sensitivity passes, interleaved per
/// sample as the residuals are, and agree with the differences as P's and Q's do.
#[test]
fn the_field_channels_rows_are_the_derivative_of_their_residuals() {
    use itaipu_calib::problem::EventData;
    use itaipu_calib::spec::Compare;
    use itaipu_dynamics::event::Channel;
    use itaipu_dynamics::mode::PlaybackMode;
    let mut pb = problem();
    // `dip_problem`'s record of the truth (`base_unit`), with the field added.
    let ev = dip_event_with_field(&base_unit(), 20.0, 1, 3);
    pb.events = vec![EventData::new(&ev, None, None).unwrap()];
    pb.compare = Some(Compare {
        mode: PlaybackMode::Phasor,
        weights: vec![
            (Channel::P, 1.0),
            (Channel::Q, 1.0),
            (Channel::Efd, 0.04),
            (Channel::Ifd, 0.16),
        ],
    });
    assert!(pb.has_sensitivities());
    columns_match_differences(&pb);
}

/// Every column of `pb`'s sensitivity Jacobian at its start, on the replayed steps of its
/// Levenberg-Marquardt integrator, against central differences of its residuals on a tight
/// integrator (within 1e-5 of the column's norm), the priors' rows exactly.
fn columns_match_differences(pb: &Problem) {
    let u = pb.to_unit(&pb.start());
    let sim = lm_integrator(1e-7);
    let Method::Dopri5(o) = &sim.method else {
        unreachable!()
    };
    let (r, steps) = pb.residuals_with_steps(&pb.from_unit(&u), o).unwrap();
    let sims: Vec<_> = steps.iter().collect();
    let cols = pb
        .sensitivity_jacobian(&u, &sims)
        .expect("every block has dual equations");
    assert_eq!(cols.len(), u.len());
    let tight = lm_integrator(1e-11);
    for (j, col) in cols.iter().enumerate() {
        assert_eq!(
            col.len(),
            r.len(),
            "rows: the window's P and Q, then the priors"
        );
        let h = 1e-4;
        let at = |d: f64| {
            let mut v = u.clone();
            v[j] += d;
            pb.residuals(&pb.from_unit(&v), &tight).unwrap()
        };
        let (a, b) = (at(h), at(-h));
        let fd: Vec<f64> = a.iter().zip(&b).map(|(x, y)| (x - y) / (2.0 * h)).collect();
        let norm = |v: &mut dyn Iterator<Item = f64>| v.map(|x| x * x).sum::<f64>().sqrt();
        let err = norm(&mut col.iter().zip(&fd).map(|(x, y)| x - y));
        let scale = norm(&mut fd.iter().copied());
        let name = &pb.free[j].path;
        assert!(
            err < 1e-5 * scale,
            "{name}: off by {:.2e} of the column's norm",
            err / scale
        );
        // The priors' rows (the last three) are exact to the differences' truncation.
        let m = col.len();
        for k in m - 3..m {
            assert!(
                (col[k] - fd[k]).abs() <= 1e-6 * fd[k].abs().max(1e-6),
                "{name}: prior row {k}: {} for {}",
                col[k],
                fd[k]
            );
        }
    }
}

/// A unit with a block without dual equations (`grid_equivalent` here, the last registry model
/// without them, inert in the phasor playback) has no sensitivity Jacobian: the
/// Levenberg-Marquardt then takes differences.
#[test]
fn without_dual_equations_there_is_no_sensitivity_jacobian() {
    use itaipu_dynamics::registry;
    let mut unit = itaipu_dynamics::unit::Unit::new("grid", 737.0, 60.0);
    for (name, model) in [
        ("machine", "GENROU"),
        ("exciter", "SEXS"),
        ("grid", "grid_equivalent"),
    ] {
        unit.add(name, registry::find(model).unwrap().create(), &[])
            .unwrap();
    }
    unit.finish().unwrap();
    let pb = dip_problem(unit, &[("machine.h", 2.0, 8.0)], 5.0, 1, 1.1);
    let u = pb.to_unit(&pb.start());
    let sim = lm_integrator(1e-7);
    assert!(pb.sensitivity_jacobian(&u, &[&sim]).is_none());
    // The same stage on the synthetic unit has one.
    let pb = dip_problem(base_unit(), &[("machine.h", 2.0, 8.0)], 5.0, 1, 1.1);
    assert!(pb.sensitivity_jacobian(&u, &[&sim]).is_some());
}

/// Levenberg-Marquardt with its Jacobians by sensitivities (`LmStop::sensitivities`) from 10 %
/// off: it ends where the search on differences ends (within 1 % of J: both stop at the same
/// rule, on the same noisy record), far below the start. A wrong column (a sign, a missing
/// initialisation term) would stall it or send it elsewhere.
#[test]
fn levenberg_marquardt_on_sensitivities_reaches_the_differences_optimum() {
    use itaipu_calib::local::{levenberg_marquardt, LmStop};
    let pb = problem();
    let x0 = pb.start();
    let j0 =
        itaipu_calib::problem::sum_of_squares(&pb.residuals(&x0, &lm_integrator(1e-7)).unwrap());
    let on = |sensitivities: bool| {
        levenberg_marquardt(
            &pb,
            &x0,
            30,
            LmStop {
                sensitivities,
                ..LmStop::CALIBRATION
            },
        )
    };
    let (exact, diff) = (on(true), on(false));
    eprintln!(
        "J start {j0:.4}, sensitivities {:.6} ({} iterations, {}), differences {:.6} ({} iterations, {})",
        exact.best_cost, exact.iterations, exact.stopped_by, diff.best_cost, diff.iterations, diff.stopped_by
    );
    assert!(exact.iterations > 0);
    assert!(
        exact.best_cost < 0.2 * j0,
        "J {} from {j0}",
        exact.best_cost
    );
    assert!(
        (exact.best_cost / diff.best_cost - 1.0).abs() < 0.01,
        "J {} on sensitivities, {} on differences",
        exact.best_cost,
        diff.best_cost
    );
}
