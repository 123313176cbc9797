//! The seeds' Table 1 (`examples/table1.rs`) on quick budgets: the generator stage is one stage
//! shared by both columns (both start from byte-identical machines, the stage's own result),
//! run as the paper ran it (no control in the loop), and no stage ends above its start on its
//! own objective.

#[allow(dead_code)]
#[path = "../examples/table1.rs"]
mod example;

use example::{machine_text, run, Budget, CONTROLS};

#[test]
fn the_generator_stage_is_shared_and_no_stage_ends_above_its_start() {
    let root = example::repo();
    let budget = Budget {
        particles: Some(4),
        pso_iterations: Some(2),
        local_iterations: Some(2),
    };
    let t = run(
        &root,
        &root.join("data/itaipu/calibration_table1.toml"),
        &budget,
        &[],
    )
    .unwrap();

    // The paper's generator stage: the machine alone (E_fd and P_m held), not a control.
    assert_eq!(t.gen.models, ["machine=GENSAE"], "{:?}", t.gen.models);
    assert!(t.generator.without(&CONTROLS).is_ok());
    assert!(
        t.generator.block("exciter").is_none() && t.generator.block("pss").is_none(),
        "the shared generator holds a control"
    );

    // Shared: both columns start from the stage's result, byte for byte, as given to the fit
    // and as its first control stage saw it.
    let shared = machine_text(&t.generator).unwrap();
    assert_eq!(t.columns.len(), 2);
    for c in &t.columns {
        assert_eq!(machine_text(&c.start).unwrap(), shared, "{}: start", c.name);
        assert_eq!(
            machine_text(&c.first_stage_start).unwrap(),
            shared,
            "{}: the AVR stage's start",
            c.name
        );
        // The generator's parameters, not the datasheet's, reached the column.
        for (path, _, v) in t.generator.params() {
            let r = c.start.param(&path).unwrap();
            assert_eq!(c.start.get(r).to_bits(), v.to_bits(), "{}: {path}", c.name);
        }
        let stages: Vec<&str> = c.rows.iter().map(|r| r.stage.as_str()).collect();
        assert_eq!(stages, ["avr", "pss", "tg", "joint"], "{}", c.name);
    }
    assert_ne!(
        t.columns[0]
            .first_stage_start
            .block("exciter")
            .unwrap()
            .model(),
        t.columns[1]
            .first_stage_start
            .block("exciter")
            .unwrap()
            .model(),
        "the columns differ in their controls"
    );

    // No stage ends above its start on its own objective (the Q-only stages may on J).
    for (col, r) in std::iter::once(("shared", &t.gen)).chain(
        t.columns
            .iter()
            .flat_map(|c| c.rows.iter().map(move |r| (c.name, r))),
    ) {
        assert!(
            r.objective_after <= r.objective_before,
            "{col} {}: {} -> {}",
            r.stage,
            r.objective_after,
            r.objective_before
        );
        assert!(r.j.is_finite() && (r.norm() - r.j.sqrt()).abs() == 0.0);
        assert_eq!(r.samples, 280);
    }
    let text = t.to_text();
    assert!(text.contains("GENSAE generator (shared)"), "{text}");
    assert!(!text.contains("a defect"), "{text}");
}
