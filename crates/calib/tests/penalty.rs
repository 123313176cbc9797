//! A candidate the model rejects must never win against one that simulates, however large the
//! objective of the record (a diagnosis χ² normalised by the noise variance reaches 1e6-1e7 on a
//! record whose model misses an effect).

use std::path::PathBuf;

use itaipu_calib::problem::{EventData, FreeParam, Problem};
use itaipu_dynamics::event::Event;
use itaipu_dynamics::simulate::SimOptions;
use itaipu_dynamics::unit_file::read_unit;

#[test]
fn a_failing_candidate_never_beats_a_large_real_cost() {
    let data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/itaipu");
    let unit = read_unit(&data.join("unit.toml")).unwrap();
    let event = Event::from_toml_file(&data.join("event.toml")).unwrap();
    let r = unit.param("machine.x_d_prime").unwrap();
    let x_d_pp = unit.get(unit.param("machine.x_d_pp").unwrap());
    let free = vec![FreeParam::new(
        "machine.x_d_prime".into(),
        r,
        0.5 * x_d_pp,
        4.0 * x_d_pp,
        unit.get(r),
        unit.param_spec(r).unit,
    )];
    // Weights that scale J the way a noise-normalised χ² does on a badly fitting record.
    let events = vec![EventData::new(&event, None, None).unwrap()];
    let problem = Problem::new(unit, free, events, (1e9, 1e9));
    let sim = SimOptions::default();
    let feasible = problem.start();
    let real = problem.cost(&feasible, &sim);
    assert!(
        real.is_finite() && real > 1e6,
        "the test needs a large real cost: {real}"
    );
    // X'd below X''d: the machine refuses to initialise.
    let rejected = vec![0.8 * x_d_pp];
    assert!(problem.residuals(&rejected, &sim).is_err());
    assert!(problem.cost(&rejected, &sim) > real);
    let (best, k) = problem.best_of(&[rejected, feasible], &sim);
    assert_eq!(k, 1, "the rejected candidate won with cost {best}");
    // Both evaluations of the rejected candidate are counted as failures.
    assert_eq!(problem.failures(), 2);
}
