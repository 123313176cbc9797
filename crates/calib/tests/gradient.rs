//! The L-BFGS gradient (central differences in the unbounded coordinates, on fixed-step RK4)
//! agrees with an independent five-point stencil at a different step, at a point away from the
//! optimum, for every parameter.

use std::path::PathBuf;

use itaipu_calib::local::{gradient_integrator, LocalProblem, RK4_STEP_MAX_S};
use itaipu_calib::problem::{logit, EventData, FreeParam, Problem};
use itaipu_dynamics::event::Event;
use itaipu_dynamics::unit_file::read_unit;

#[test]
fn gradient_matches_a_five_point_stencil() {
    let data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/itaipu");
    let unit = read_unit(&data.join("unit.toml")).unwrap();
    let event = Event::from_toml_file(&data.join("event.toml")).unwrap();
    let params = [
        ("machine.h", 1.0, 10.0),
        ("machine.x_d_prime", 0.23, 0.6),
        ("exciter.k", 10.0, 1000.0),
        ("pss.t_x2", 0.5, 10.0),
    ];
    let free: Vec<FreeParam> = params
        .iter()
        .map(|(p, lo, hi)| {
            let r = unit.param(p).unwrap();
            FreeParam::new(
                p.to_string(),
                r,
                *lo,
                *hi,
                unit.get(r),
                unit.param_spec(r).unit,
            )
        })
        .collect();
    let events = vec![EventData::new(&event, None, None).unwrap()];
    let problem = Problem::new(unit, free, events, (1.0, 1.0));
    let x0 = problem.start();
    let sim = gradient_integrator(&problem, &x0, RK4_STEP_MAX_S);
    let local = LocalProblem::new(&problem, sim);
    let z: Vec<f64> = problem.to_unit(&x0).into_iter().map(logit).collect();
    let g = local.gradient_z(&z);
    let h = 1e-3;
    for i in 0..z.len() {
        let at = |d: f64| {
            let mut zz = z.clone();
            zz[i] += d;
            local.cost_z(&zz)
        };
        let five = (-at(2.0 * h) + 8.0 * at(h) - 8.0 * at(-h) + at(-2.0 * h)) / (12.0 * h);
        let rel = (g[i] - five).abs() / five.abs().max(1e-9);
        println!(
            "{}: gradient {:.6e}, five-point {:.6e}, relative difference {rel:.1e}",
            params[i].0, g[i], five
        );
        assert!(
            five.abs() > 1e-6,
            "{}: the test point should not be stationary",
            params[i].0
        );
        assert!(
            rel < 1e-4,
            "{}: gradient {:e} vs five-point stencil {:e}",
            params[i].0,
            g[i],
            five
        );
    }
}
