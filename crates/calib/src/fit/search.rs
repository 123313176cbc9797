//! The search of one pass: the swarm then the local method from its best (and from extra
//! starts), and the Jacobian used for the identifiability report.

use rayon::prelude::*;

use crate::local;
use crate::problem::{accurate_integrator, Problem};
use crate::pso::{self, PsoOptions};
use crate::spec::LocalMethod;
use itaipu_dynamics::integrate::Method;
use itaipu_dynamics::simulate::SimOptions;

use super::*;

/// Iterations after which a swarm none of whose candidates has simulated gives up
/// ([`pso::StopReason::NothingFeasible`]). A stage may start from a unit no candidate near it
/// simulates within the search's step budget (a generator stage ending on a near-degenerate
/// machine, X'_d = X''_d = X_l, can make every later candidate fail after the full step budget);
/// the local method, with its larger budget, then starts from the stage's start as it would
/// after any number of such iterations: five show that the swarm learns nothing.
pub(crate) const SWARM_GIVE_UP_ITERATIONS: usize = 5;

/// Step attempts per played sample above which a swarm's candidates, averaged over its first
/// [`SWARM_GIVE_UP_ITERATIONS`] iterations, are too costly to go on with
/// ([`pso::StopReason::TooCostly`]): the local method then starts from the stage's start, as
/// after a swarm that found nothing feasible.
///
/// The rule (a physical limit of the record): a playback lands on every sample, so a candidate
/// the search integrator follows at the record's resolution takes about one step per sample
/// (fewer when the bounded evaluation stops it early). Four or more means steps of at most a
/// quarter of the sample interval throughout, which an explicit Dormand-Prince step takes only
/// when its stability holds it (|λ|·h ≤ 3.3): a mode of time constant below 1/(13 f_s), more
/// than four times faster than the fastest the samples resolve (1/(π f_s) at their Nyquist
/// frequency f_s/2). Such a mode is no dynamics the record can confirm, only the near-singular
/// equations of a unit at the edge of its ordering (say a machine left at X'_d = X''_d = X_l by
/// the previous stage, which every candidate of the next one inherits), and the swarm cannot
/// learn anything from such candidates at a normal swarm's cost. Ordinary candidates take about
/// one attempt per sample (`--example search_error` measures it on a set of records), far below
/// the limit.
pub(crate) const TOO_COSTLY_STEPS_PER_SAMPLE: f64 = 4.0;

/// Runs the swarm (its first particle at the problem's start), then the local method; returns
/// the best of the candidates on the accurate integrator (physical values) and the phase
/// reports.
///
/// The local method runs from the swarm's best (without a swarm, the start), from each point of
/// `also_from` (physical values: the joint pass gives the datasheet values, so that a stage that
/// derailed, fitted a unit whose other blocks were still wrong, cannot trap the result), and
/// with `opts.local_starts > 1` from the swarm's other distinct particles' bests
/// ([`distinct_bests`]).
pub(crate) fn search(
    problem: &Problem,
    opts: &FitOptions,
    stage: &str,
    progress: &dyn Progress,
    use_pso: bool,
    also_from: &[Vec<f64>],
) -> (Vec<f64>, Vec<PhaseReport>) {
    let n = problem.dim();
    let start = problem.start();
    let mut phases = vec![];
    let mut candidates = vec![start.clone()];
    // Further starts of the local method from the swarm (its other particles' bests).
    let mut from_swarm: Vec<Vec<f64>> = vec![];
    if use_pso && n > 0 && opts.pso_iterations > 0 {
        let (t0, sims0) = (std::time::Instant::now(), problem.simulations());
        let attempts0 = problem.attempts();
        // The swarm's work so far: step attempts per sample its candidates played.
        let steps_per_sample = || {
            let played = (problem.simulations() - sims0) as f64 / problem.events.len() as f64
                * problem.samples() as f64;
            (problem.attempts() - attempts0) as f64 / played.max(1.0)
        };
        progress.phase(stage, "pso", opts.pso_iterations as u64);
        let sim = &opts.swarm_integrator;
        let pso_opts = PsoOptions {
            particles: opts.particles,
            iterations: opts.pso_iterations,
            seed: opts.seed,
            stall_iterations: 30,
            failed_cost: problem.penalty,
            give_up_iterations: SWARM_GIVE_UP_ITERATIONS,
            ..Default::default()
        };
        // `pso::minimize` panics on invalid options or start: at least one particle is
        // checked where a fit or a diagnosis starts (`FitOptions::check`, `diagnose`), the
        // start has one coordinate per free parameter, and a start the box cannot place (a
        // NaN value in the unit) is left out of the swarm, whose candidates are drawn in the
        // box as usual.
        let u0 = Some(problem.to_unit(&start)).filter(|u| u.iter().all(|v| v.is_finite()));
        // Each candidate is simulated only as far as it can still beat its particle's best
        // (`Problem::cost_bounded`): the swarm is bit for bit the one with whole playbacks.
        let res = pso::minimize_bounded(
            |u: &[f64], bound: f64| problem.cost_bounded(&problem.from_unit(u), sim, bound),
            n,
            u0.as_deref(),
            &pso_opts,
            |i, best| progress.iteration(i as u64, best),
            || steps_per_sample() > TOO_COSTLY_STEPS_PER_SAMPLE,
        );
        phases.push(PhaseReport {
            phase: "pso".into(),
            iterations: res.iterations as u64,
            best_objective: res.best_cost,
            stopped_by: format!("{:?}", res.stopped_by),
            steps_per_sample: steps_per_sample(),
            wall_s: t0.elapsed().as_secs_f64(),
            simulations: problem.simulations() - sims0,
        });
        candidates.push(problem.from_unit(&res.best));
        from_swarm = distinct_bests(&res, opts.local_starts.saturating_sub(1), problem.penalty)
            .iter()
            .map(|u| problem.from_unit(u))
            .collect();
    }
    let from = candidates.last().cloned().unwrap_or_default();
    let lm = opts.local == LocalMethod::Lm;
    let starts: Vec<Vec<f64>> = std::iter::once(from)
        .chain(also_from.iter().cloned())
        .chain(from_swarm)
        .collect();
    for (i, from) in starts.iter().enumerate() {
        if n == 0 || opts.lbfgs_iterations == 0 {
            break;
        }
        let name = if lm { "levenberg-marquardt" } else { "lbfgs" };
        let (t0, sims0) = (std::time::Instant::now(), problem.simulations());
        progress.phase(stage, name, opts.lbfgs_iterations);
        let res = if lm {
            local::levenberg_marquardt(problem, from, opts.lbfgs_iterations, opts.lm_stop)
        } else {
            local::refine(
                problem,
                from,
                opts.lbfgs_iterations,
                opts.lbfgs_memory,
                opts.lbfgs_step_max_s,
            )
        };
        progress.iteration(res.iterations, res.best_cost);
        let from_txt = if i == 0 {
            String::new()
        } else {
            format!(" from start {}", i + 1)
        };
        phases.push(PhaseReport {
            phase: if lm {
                format!(
                    "{name}{from_txt} (Dormand-Prince, rtol {:e})",
                    opts.lm_stop.rtol
                )
            } else {
                format!("{name}{from_txt} (RK4 h = {:.3} ms)", res.step_s * 1e3)
            },
            iterations: res.iterations,
            best_objective: res.best_cost,
            stopped_by: res.stopped_by.clone(),
            steps_per_sample: 0.0,
            wall_s: t0.elapsed().as_secs_f64(),
            simulations: problem.simulations() - sims0,
        });
        if i > 0 {
            // The first start (the swarm's best or the stage start) is a candidate already.
            candidates.push(from.clone());
        }
        candidates.push(res.best);
    }
    // Keep the best candidate by an accurate evaluation (the phases used different integrators).
    let acc = accurate_integrator();
    let (_, k) = problem.best_of(&candidates, &acc);
    (candidates[k].clone(), phases)
}

/// Distance (in every box coordinate, a fraction of the parameter's range) within which two
/// particles' bests count as one start of the local method ([`distinct_bests`]).
pub(crate) const DISTINCT_START: f64 = 0.1;

/// Up to `k` particles' bests of the swarm `res`, best first, each apart from the swarm's best
/// and from the others taken by more than [`DISTINCT_START`] of its range in some coordinate
/// (points nearer than that are one valley's start twice), and each a simulated candidate (cost
/// below `penalty`).
///
/// Why: a swarm's iterations after it has found the valleys only refine its best, which the
/// local method does in a few steps; what the local method cannot do is leave the valley it
/// starts in. So a shorter swarm can hand over its best few distinct points for the local method
/// to polish each (`[calibration.pso] local_starts`; not the default: a shorter swarm also
/// lands more often in a valley a longer one leaves).
pub(crate) fn distinct_bests(res: &pso::PsoResult, k: usize, penalty: f64) -> Vec<Vec<f64>> {
    let mut picked: Vec<&[f64]> = vec![&res.best];
    for (c, p) in &res.personal_bests {
        if picked.len() > k || !(*c < penalty) {
            break;
        }
        let apart = picked
            .iter()
            .all(|q| q.iter().zip(p).any(|(a, b)| (a - b).abs() > DISTINCT_START));
        if apart {
            picked.push(p);
        }
    }
    picked[1..].iter().map(|p| p.to_vec()).collect()
}

/// Jacobian of the residuals in physical units, for the identifiability report and the standard
/// errors, on the steps of one run on the accurate integrator
/// ([`Problem::residuals_with_steps`]): by forward sensitivities
/// ([`Problem::sensitivity_jacobian_x`], exact for that discretised playback) where every block
/// has dual equations; otherwise forward differences between replays of those steps, each
/// column the derivative of the discretised playback (free of step-size noise, so the step can
/// be 1e-6 of the parameter's scale, where two adaptive runs needed central differences at
/// 1e-4), backwards where a parameter sits on its upper bound (the model may reject values
/// beyond it) or where the model refuses the forward step (a parameter pressed against another,
/// X'_d on X_d). The residuals replayed at `x` are the base of the differences; `None` when a
/// simulation fails.
pub(crate) fn jacobian(problem: &Problem, x: &[f64]) -> Option<Vec<Vec<f64>>> {
    let Method::Dopri5(acc) = accurate_integrator().method else {
        unreachable!("the accurate integrator is Dormand-Prince")
    };
    let (_, steps) = problem.residuals_with_steps(x, &acc)?;
    let replays: Vec<&SimOptions> = steps.iter().collect();
    if let Some(cols) = problem.sensitivity_jacobian_x(x, &replays) {
        let rows = cols.first().map_or(0, |c| c.len());
        return Some(
            (0..rows)
                .map(|k| cols.iter().map(|c| c[k]).collect())
                .collect(),
        );
    }
    let r0 = problem.residuals_each(x, &replays).ok()?;
    let cols: Vec<Option<Vec<f64>>> = (0..x.len())
        .into_par_iter()
        .map(|j| {
            let f = &problem.free[j];
            let scale = (f.hi - f.lo).min(x[j].abs().max(1e-3 * (f.hi - f.lo)));
            let h = JACOBIAN_STEP * scale;
            let column = |h: f64| -> Option<Vec<f64>> {
                let mut xv = x.to_vec();
                xv[j] += h;
                let r = problem.residuals_each(&xv, &replays).ok()?;
                (r.len() == r0.len()).then(|| r.iter().zip(&r0).map(|(a, b)| (a - b) / h).collect())
            };
            // Forwards but past the upper bound; where the model refuses the step (X'_d pressed
            // against X_d) the other side.
            let h = if x[j] + h > f.hi { -h } else { h };
            column(h).or_else(|| column(-h))
        })
        .collect();
    let cols: Vec<Vec<f64>> = cols.into_iter().collect::<Option<_>>()?;
    let rows = cols.first().map_or(0, |c| c.len());
    Some(
        (0..rows)
            .map(|k| cols.iter().map(|c| c[k]).collect())
            .collect(),
    )
}

/// Relative step of [`jacobian`]'s differences. A replay is smooth in the parameters, so the
/// step only balances the difference's truncation error, O(step) relative, against what still
/// varies without smoothness: rounding (1e-16 of residuals of order 1e3, the simulated values in
/// units of the noise) and event times located to 1e-12 s (a limiter's switch moving 1e-12 s,
/// at 10 pu/s and a noise of 1e-3 pu, moves a residual by 1e-5); divided by 1e-6 of a column of
/// order 1e2 both stay below 1e-4, the truncation error about 1e-6.
pub(crate) const JACOBIAN_STEP: f64 = 1e-6;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::trial::base_unit;
    use crate::problem::{EventData, FreeParam};
    use itaipu_dynamics::event::Event;
    use itaipu_dynamics::synthetic::{synthesize, PmuNoise, VoltageProfile};
    use itaipu_dynamics::unit::Unit;

    /// The playback's default voltage dip into `unit`, `duration_s` long at 1000 samples/s,
    /// with `noise`.
    fn dip(unit: &Unit, duration_s: f64, noise: &PmuNoise) -> Event {
        let profile = VoltageProfile {
            duration_s,
            ..VoltageProfile::default()
        };
        synthesize("dip", unit, &profile, 1000.0, noise, &Default::default()).unwrap()
    }

    /// The further starts: best first, never the swarm's best again, nothing within a tenth of
    /// the box of a start already taken, no failed candidate, at most `k`.
    #[test]
    fn distinct_bests_skip_near_and_failed_points() {
        let best = vec![0.50, 0.50];
        let res = pso::PsoResult {
            best: best.clone(),
            best_cost: 1.0,
            iterations: 1,
            evaluations: 12,
            history: vec![1.0, 1.0],
            stopped_by: pso::StopReason::MaxIterations,
            personal_bests: vec![
                (1.0, best.clone()),
                (1.1, vec![0.55, 0.45]), // within 0.1 of the best in every coordinate
                (1.2, vec![0.50, 0.75]), // apart in the second coordinate
                (1.3, vec![0.52, 0.70]), // near the point just taken
                (1.4, vec![0.90, 0.10]),
                (1.5, vec![0.10, 0.90]),
                (1e12, vec![0.0, 0.0]), // a failed candidate (the penalty)
            ],
        };
        let penalty = 1e12;
        assert_eq!(
            distinct_bests(&res, 3, penalty),
            vec![vec![0.50, 0.75], vec![0.90, 0.10], vec![0.10, 0.90]]
        );
        assert_eq!(
            distinct_bests(&res, 2, penalty),
            vec![vec![0.50, 0.75], vec![0.90, 0.10]]
        );
        assert!(distinct_bests(&res, 0, penalty).is_empty());
        // Nothing simulated below the penalty beyond the points taken: no more starts.
        assert_eq!(distinct_bests(&res, 10, penalty).len(), 3);
    }

    /// `local_starts`: the same swarm (same seed and budget) hands the local method more starts,
    /// each reported as a phase, and the search never ends above the one-start search (its
    /// candidates are a superset, ranked on the accurate integrator).
    #[test]
    fn more_local_starts_never_end_worse() {
        let truth = base_unit()
            .with_params(&[("machine.h", 3.1), ("machine.x_d_prime", 0.36)])
            .unwrap();
        let ev = dip(&truth, 3.0, &PmuNoise::typical(3));
        let unit = base_unit();
        let free: Vec<FreeParam> = [("machine.h", 2.0, 8.0), ("machine.x_d_prime", 0.2, 0.45)]
            .iter()
            .map(|&(p, lo, hi)| {
                let r = unit.param(p).unwrap();
                FreeParam::new(p.into(), r, lo, hi, unit.get(r), "")
            })
            .collect();
        let data = vec![EventData::new(&ev, None, None).unwrap()];
        let problem = Problem::new(unit, free, data, (1.0, 1.0));
        let acc = accurate_integrator();
        let run = |k: usize| {
            let opts = FitOptions {
                particles: 12,
                pso_iterations: 4,
                lbfgs_iterations: 10,
                local_starts: k,
                ..quick_options(&["gen"], 5)
            };
            let (best, phases) = search(&problem, &opts, "gen", &Silent, true, &[]);
            let locals = phases.iter().filter(|p| p.phase != "pso").count();
            (problem.cost(&best, &acc), locals)
        };
        let (one, one_locals) = run(1);
        let (four, four_locals) = run(4);
        assert_eq!(one_locals, 1);
        assert!(
            (2..=4).contains(&four_locals),
            "{four_locals} local phases from 4 starts"
        );
        assert!(four <= one, "4 starts end at {four}, 1 start at {one}");
    }

    /// A free parameter whose start is NaN (a unit holding a NaN value) does not reach the
    /// swarm's start point, which panics on it: the search runs from the box.
    #[test]
    fn a_nan_start_does_not_reach_the_swarm() {
        let unit = base_unit();
        let ev = dip(&unit, 2.0, &PmuNoise::typical(1));
        let r = unit.param("machine.h").unwrap();
        let f = FreeParam {
            start: f64::NAN,
            ..FreeParam::new("machine.h".into(), r, 2.0, 8.0, 4.5, "s")
        };
        let data = vec![EventData::new(&ev, None, None).unwrap()];
        let problem = Problem::new(unit, vec![f], data, (1.0, 1.0));
        let opts = FitOptions {
            particles: 3,
            pso_iterations: 2,
            lbfgs_iterations: 1,
            ..quick_options(&["gen"], 1)
        };
        let (best, _) = search(&problem, &opts, "gen", &Silent, true, &[]);
        assert_eq!(best.len(), 1);
        assert!((2.0..=8.0).contains(&best[0]), "{best:?}");
    }

    /// The Jacobians on replayed steps are the derivatives the finite differences of a tight
    /// integrator approximate: on a 6 s dip into the synthetic unit with PMU noise, six
    /// parameters of its four blocks (machine, exciter, stabiliser, governor), each column of the
    /// identifiability Jacobian (forward sensitivities on the accurate integrator's steps) within
    /// 1e-6, of the calibration's Levenberg-Marquardt Jacobian (replayed differences on steps at
    /// [`crate::local::JACOBIAN_RTOL`]) within 5e-2, and of the sensitivities on those same
    /// coarse steps within 1e-5, of central differences at rtol 1e-10 (step 1e-4 of the box), in
    /// the column's norm. Measured: 8e-9 to 1.7e-7 (replayed differences, before the
    /// sensitivities: 1e-7 to 9e-5); 2e-6 to 1.8e-2, the largest the exciter's T_E (a stage of
    /// a replayed step a hair past the ceiling takes the clamp's branch, dropping the state's
    /// dependence there; a Gauss-Newton direction needs far less than 5e-2: each step is
    /// checked on the objective); the sensitivities on the coarse steps 3e-7 to 3e-6.
    /// A Jacobian that lost the initialisation's or a block's dependence on a parameter would be
    /// off by its whole effect.
    #[test]
    fn replayed_columns_agree_with_accurate_central_differences() {
        check_replayed_columns(
            base_unit(),
            &[
                ("machine.h", 2.0, 8.0),
                ("machine.x_d_prime", 0.2, 0.45),
                ("exciter.k", 20.0, 400.0),
                ("exciter.te", 0.01, 0.5),
                ("pss.k_x", 0.1, 5.0),
                ("governor.t_g", 0.1, 1.0),
            ],
            (1e-6, 5e-2, Some(1e-5)),
        );
    }

    /// A parameter pressed against another (X'_d a hair below X_d, where the bundled Itaipu fit
    /// ends) still gets its column: the model refuses the forward step, and the identifiability
    /// Jacobian takes the backward one, which agrees with a backward difference of adaptive runs
    /// at the accurate integrator (to their noise, 1e-3 at this step).
    #[test]
    fn a_column_the_model_refuses_forwards_is_taken_backwards() {
        let x_d = 0.95;
        let unit = base_unit()
            .with_params(&[("machine.x_d", x_d), ("machine.x_d_prime", x_d - 1e-9)])
            .unwrap();
        let problem = crate::diagnose::trial::dip_problem(
            unit,
            &[("machine.x_d_prime", 0.2, 0.99), ("machine.h", 2.0, 8.0)],
            4.0,
            5,
            1.0,
        );
        let x = problem.start();
        let mut up = x.clone();
        up[0] += 1e-6;
        assert!(
            problem.residuals(&up, &accurate_integrator()).is_err(),
            "the model takes X'_d above X_d"
        );
        let jac = jacobian(&problem, &x).expect("a Jacobian");
        let col: Vec<f64> = jac.iter().map(|row| row[0]).collect();
        assert!(col.iter().all(|v| v.is_finite()));
        let h = 1e-4;
        let mut dn = x.clone();
        dn[0] -= h;
        let acc = accurate_integrator();
        let (r0, r1) = (
            problem.residuals(&x, &acc).unwrap(),
            problem.residuals(&dn, &acc).unwrap(),
        );
        let back: Vec<f64> = r0.iter().zip(&r1).map(|(a, b)| (a - b) / h).collect();
        let d: f64 = col.iter().zip(&back).map(|(a, b)| (a - b).powi(2)).sum();
        let e = (d / back.iter().map(|b| b * b).sum::<f64>()).sqrt();
        assert!(e < 1e-2, "X'_d column {e:e} off the backward difference");
    }

    /// The same on user-defined diagrams (the bundled Itaipu unit with its AVR and PSS as
    /// diagrams, `data/itaipu/unit_ud.toml`): their primitives (PI with a non-windup clamp,
    /// lags, lead-lag, washout, min/max selectors, products, sums, gains) and their Newton
    /// initialisation, which sets the diagrams' states and references from the parameters
    /// (`exciter.k_efd` scales the initial E_fd: a replay that kept the initial state would miss
    /// its whole effect). Looser than on the built-in blocks, and why: the selectors' kinks are
    /// crossed inside steps (no event locates them), where a Runge-Kutta step is first-order, so
    /// the adaptive reference itself carries step-size noise there. Measured: replays of the
    /// accurate steps 1e-4 to 1.3e-2 off the reference (the largest the transducer's T_R, 10 ms),
    /// on rtol-1e-6 steps 2e-4 to 3.6e-2; central differences of accurate adaptive runs 3e-4 to
    /// 6.7e-2 off the same reference. The diagrams have dual equations, so the identifiability
    /// Jacobian is their sensitivities on the accurate steps (9.7e-5 to 1.3e-2), and the
    /// sensitivities on the rtol-1e-6 steps match that replay's differences (2.3e-4 to
    /// 3.6e-2): both differentiate the discrete playback, whose kinks the reference resolves.
    #[test]
    fn replayed_columns_agree_on_user_defined_diagrams() {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/itaipu/unit_ud.toml");
        check_replayed_columns(
            itaipu_dynamics::unit_file::read_unit(&path).unwrap(),
            &[
                ("machine.h", 2.0, 8.0),
                ("exciter.k_v", 1.0, 200.0),
                ("exciter.k_ei", 5.0, 500.0),
                ("exciter.t_r", 0.005, 0.05),
                ("exciter.k_efd", 0.5, 2.0),
                ("pss.k_f", 0.1, 10.0),
                ("pss.t_f", 0.01, 0.5),
                ("pss.t_p", 0.5, 10.0),
            ],
            (5e-2, 5e-2, Some(5e-2)),
        );
    }

    /// Checks each column of the identifiability and the Levenberg-Marquardt Jacobians (and of
    /// the sensitivity Jacobian on the latter's steps, where the unit has dual equations: `None`
    /// requires that it has not) at 10 % above `unit`'s values of `params` against central
    /// differences at rtol 1e-10, to the relative errors `tol` (in the column's norm).
    fn check_replayed_columns(
        unit: itaipu_dynamics::unit::Unit,
        params: &[(&str, f64, f64)],
        tol: (f64, f64, Option<f64>),
    ) {
        use crate::local::{jacobian_columns, JACOBIAN_RTOL};
        use itaipu_dynamics::integrate::Dopri5Options;
        let problem = crate::diagnose::trial::dip_problem(unit, params, 6.0, 3, 1.1);
        let x = problem.start();
        let u = problem.to_unit(&x);
        let tight = SimOptions {
            method: Method::Dopri5(Dopri5Options {
                rtol: 1e-10,
                atol: 1e-11,
                h_max: 0.02,
                max_steps: 1_000_000,
                ..Default::default()
            }),
        };
        // Central differences in box coordinates, and the same columns in physical units.
        let hb = 1e-4;
        let reference: Vec<Vec<f64>> = (0..u.len())
            .map(|j| {
                let at = |d: f64| {
                    let mut v = u.clone();
                    v[j] += d;
                    problem.residuals(&problem.from_unit(&v), &tight).unwrap()
                };
                let (p, m) = (at(hb), at(-hb));
                p.iter()
                    .zip(&m)
                    .map(|(a, b)| (a - b) / (2.0 * hb))
                    .collect()
            })
            .collect();
        let rel = |c: &[f64], r: &[f64], scale: f64| {
            let d: f64 = c.iter().zip(r).map(|(a, b)| (a * scale - b).powi(2)).sum();
            (d / r.iter().map(|b| b * b).sum::<f64>()).sqrt()
        };
        let ident = jacobian(&problem, &x).unwrap();
        let coarse = Dopri5Options {
            rtol: JACOBIAN_RTOL,
            atol: 0.1 * JACOBIAN_RTOL,
            ..Default::default()
        };
        let (r, steps) = problem.residuals_with_steps(&x, &coarse).unwrap();
        let lm = jacobian_columns(&problem, &u, &r, &steps, &tight);
        let sims: Vec<&SimOptions> = steps.iter().collect();
        let sens = problem.sensitivity_jacobian(&u, &sims);
        assert_eq!(sens.is_some(), tol.2.is_some(), "sensitivities available");
        for (j, refc) in reference.iter().enumerate() {
            // d r / d u = d r / d x · d x / d u (the box may be linear or logarithmic).
            let mut v = u.clone();
            v[j] += 1e-7;
            let dxdu = (problem.from_unit(&v)[j] - x[j]) / 1e-7;
            let col: Vec<f64> = ident.iter().map(|row| row[j]).collect();
            let e = rel(&col, refc, dxdu);
            let path = &problem.free[j].path;
            let e_lm = rel(lm[j].as_ref().unwrap(), refc, 1.0);
            eprintln!("{path}: identifiability {e:.1e}, Levenberg-Marquardt {e_lm:.1e}");
            assert!(e < tol.0, "{path}: {e:e}");
            assert!(e_lm < tol.1, "{path}: {e_lm:e}");
            if let (Some(c), Some(t)) = (&sens, tol.2) {
                let e_s = rel(&c[j], refc, 1.0);
                eprintln!("{path}: sensitivities on the same steps {e_s:.1e}");
                assert!(e_s < t, "{path}: sensitivities {e_s:e}");
            }
        }
    }

    /// A stage never ends above its start on its own objective: the start is one of the
    /// candidates, and the best of them by one accurate evaluation is kept, whatever the swarm
    /// and the local method (each on its own, cheaper integrator) found. Here the start is the
    /// true unit of a noiseless record, with an exciter so fast (T_E = 10 µs, some 60 000
    /// steps for 2 s) that only the accurate integrator's step budget simulates it: the swarm
    /// and Levenberg-Marquardt fail it and return other, worse points; every pass keeps its
    /// start.
    #[test]
    fn no_stage_ends_above_its_start() {
        let truth = base_unit().with_params(&[("exciter.te", 1e-5)]).unwrap();
        let ev = dip(&truth, 2.0, &PmuNoise::none());
        let spec = crate::spec::CalibSpec::parse(
            r#"
[calibration]
[[calibration.stage]]
name = "gen"
free = [ { param = "machine.h", min = 2.0, max = 8.0 },
         { param = "machine.d", min = 0.0, max = 2.0 } ]
[[calibration.stage]]
name = "avr"
objective = "q"
free = [ { param = "exciter.k", min = 20.0, max = 400.0 },
         { param = "exciter.te", min = 1e-5, max = 0.5 } ]
"#,
            std::path::Path::new("spec.toml"),
        )
        .unwrap();
        // Sequential: the stages and the joint pass; incremental: its generator stage, freed one
        // parameter at a time (the other strategy runs the same passes).
        for (strategy, stages) in [
            (crate::spec::Strategy::Sequential, &["gen", "avr"][..]),
            (crate::spec::Strategy::Incremental, &["gen"][..]),
        ] {
            let opts = FitOptions {
                strategy,
                particles: 3,
                pso_iterations: 1,
                lbfgs_iterations: 1,
                polish: true,
                ..quick_options(stages, 7)
            };
            let res = crate::fit::fit(
                &truth,
                &spec,
                std::slice::from_ref(&ev),
                &[],
                &opts,
                &Silent,
            )
            .unwrap();
            for s in &res.report.stages {
                assert!(
                    s.objective_after <= s.objective_before,
                    "{strategy:?} {}: {} -> {}",
                    s.stage,
                    s.objective_before,
                    s.objective_after
                );
                for p in &s.parameters {
                    assert_eq!(p.result, p.start, "{strategy:?} {}: {}", s.stage, p.param);
                }
            }
        }
    }
}
