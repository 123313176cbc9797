//! End-to-end: user-defined diagrams through the command line. The bundled Itaipu unit with
//! its SEXS and STAB3 written as diagrams (`data/diagrams/unit_itaipu_diagrams.toml`) simulates
//! and calibrates like the unit with the built-in blocks; bad diagrams exit 4, a diagram that
//! cannot start exits 5; `diagram` draws the wiring; `models diagram` lists the primitives.

use itaipu_calib_e2e::{cli, data, TempDir, FIT_BUDGET};

fn column(path: &std::path::Path, name: &str) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let k = header
        .iter()
        .position(|h| *h == name)
        .unwrap_or_else(|| panic!("no column {name}"));
    lines
        .map(|l| l.split(',').nth(k).unwrap().parse().unwrap())
        .collect()
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

#[test]
fn the_diagram_unit_simulates_and_calibrates_like_the_builtin_unit() {
    let tmp = TempDir::new("diagram");
    let unit_d = data("diagrams/unit_itaipu_diagrams.toml");
    let calib = data("itaipu/calibration.toml");
    let (od, ob) = (tmp.path().join("sd"), tmp.path().join("sb"));
    assert_eq!(
        cli(&[
            "simulate",
            "--unit",
            unit_d.to_str().unwrap(),
            "--out",
            od.to_str().unwrap(),
            "--no-plot"
        ]),
        0
    );
    assert_eq!(
        cli(&["simulate", "--out", ob.to_str().unwrap(), "--no-plot"]),
        0
    );
    for c in ["p_pu", "q_pu", "efd", "vs"] {
        let d = max_diff(
            &column(&od.join("traces.csv"), c),
            &column(&ob.join("traces.csv"), c),
        );
        assert!(d < 1e-6, "simulate: {c} differs by {d:.3e}");
    }
    // A short AVR stage on each, the swarm alone: the same calibration (the spec's names
    // exciter.k, … address the diagram's parameters). Not the local phase: from this quick
    // swarm's best, Levenberg-Marquardt steps into candidates whose limiters chatter (T_B near
    // 0.01 s), where the 1e-12 between the diagram and the built-in block decides whether a
    // simulation ends within its step budget, and the two runs part there. (The full `fit` of
    // either ends at the same J.)
    let (fd, fb) = (tmp.path().join("fd"), tmp.path().join("fb"));
    let mut swarm_only = FIT_BUDGET;
    assert_eq!(swarm_only[4], "--lbfgs-iterations");
    swarm_only[5] = "0";
    let small = [
        &[
            "--stage",
            "avr",
            "--no-plot",
            "--calib",
            calib.to_str().unwrap(),
        ][..],
        &swarm_only[..],
    ]
    .concat();
    let mut a = vec![
        "fit",
        "--unit",
        unit_d.to_str().unwrap(),
        "--out",
        fd.to_str().unwrap(),
    ];
    a.extend_from_slice(&small);
    assert_eq!(cli(&a), 0);
    let mut b = vec!["fit", "--out", fb.to_str().unwrap()];
    b.extend_from_slice(&small);
    assert_eq!(cli(&b), 0);
    let d = max_diff(
        &column(&fd.join("avr/traces.csv"), "q_pu"),
        &column(&fb.join("avr/traces.csv"), "q_pu"),
    );
    assert!(d < 1e-6, "fit: calibrated Q differs by {d:.3e}");
    let start = column(&fd.join("avr/traces_start.csv"), "q_pu");
    let after = column(&fd.join("avr/traces.csv"), "q_pu");
    assert!(max_diff(&start, &after) > 1e-4, "the stage moved the AVR");
    // The calibrated unit carries its diagram inline and simulates on its own.
    let cal = std::fs::read_to_string(fd.join("calibrated.toml")).unwrap();
    assert!(cal.contains("[exciter.diagram]"), "{cal}");
    let oc = tmp.path().join("sc");
    assert_eq!(
        cli(&[
            "simulate",
            "--unit",
            fd.join("calibrated.toml").to_str().unwrap(),
            "--out",
            oc.to_str().unwrap(),
            "--no-plot"
        ]),
        0
    );
    let d = max_diff(&column(&oc.join("traces.csv"), "q_pu"), &after);
    // (The fit records its traces on a tighter integrator tolerance than `simulate`.)
    assert!(d < 1e-6, "re-simulated calibrated unit differs by {d:.3e}");
}

#[test]
fn bad_diagrams_exit_4_and_a_diagram_that_cannot_start_exits_5() {
    let tmp = TempDir::new("diagram-bad");
    let sexs = std::fs::read_to_string(data("diagrams/sexs.toml")).unwrap();
    let stab3 = std::fs::read_to_string(data("diagrams/stab3.toml")).unwrap();
    let unit = std::fs::read_to_string(data("diagrams/unit_itaipu_diagrams.toml")).unwrap();
    tmp.write("stab3.toml", &stab3);
    tmp.write("unit.toml", &unit);
    let u = tmp.path().join("unit.toml");
    let out = tmp.path().join("o");
    let sim = || {
        cli(&[
            "simulate",
            "--unit",
            u.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--force",
            "--no-plot",
        ])
    };
    for (what, def) in [
        (
            "unknown primitive",
            sexs.replace("type = \"lead_lag\"", "type = \"leadlag\""),
        ),
        (
            "signal with no writer",
            sexs.replace("in = \"v_ll\"", "in = \"v_lead\""),
        ),
        (
            "two writers",
            sexs.replace("out = \"v_ll\"", "out = \"v_err\""),
        ),
        (
            "dangling output",
            sexs.replace("in = \"v_err\"", "in = \"vt\""),
        ),
        ("missing field", sexs.replace("t_b = \"tb\"\n", "")),
        (
            "algebraic loop",
            sexs.replace(
                "in = [\"vref\", \"vt\", \"vs\", \"voel\", \"vuel\"]",
                "in = [\"vref\", \"vt\", \"vs\", \"voel\", \"v_ll\"]",
            ),
        ),
    ] {
        tmp.write("sexs.toml", &def);
        assert_eq!(sim(), 4, "{what}");
    }
    // A parameter out of its declared range, in the unit file.
    tmp.write("sexs.toml", &sexs);
    assert_eq!(sim(), 0);
    tmp.write("unit.toml", &unit.replace("k = 100.0", "k = -100.0"));
    assert_eq!(sim(), 4, "negative gain");
    // A ceiling below E_fd0: a limit violated at t = 0.
    tmp.write("unit.toml", &unit.replace("e_max = 4.5", "e_max = 0.5"));
    assert_eq!(sim(), 5, "ceiling below E_fd0");
}

#[test]
fn the_diagram_command_draws_the_wiring_and_models_lists_the_primitives() {
    let tmp = TempDir::new("diagram-dot");
    let dot = tmp.path().join("sexs.dot");
    assert_eq!(
        cli(&[
            "diagram",
            data("diagrams/sexs.toml").to_str().unwrap(),
            "--out",
            dot.to_str().unwrap()
        ]),
        0
    );
    let text = std::fs::read_to_string(&dot).unwrap();
    assert!(
        text.starts_with("digraph")
            && text.contains("\"b_lead_lag\" -> \"b_exciter\" [label=\"v_ll\"]"),
        "{text}"
    );
    let dot2 = tmp.path().join("unit.dot");
    assert_eq!(
        cli(&[
            "diagram",
            data("diagrams/unit_itaipu_diagrams.toml").to_str().unwrap(),
            "--block",
            "pss",
            "--out",
            dot2.to_str().unwrap()
        ]),
        0
    );
    assert!(std::fs::read_to_string(&dot2)
        .unwrap()
        .starts_with("digraph pss"));
    let bad = tmp.write("bad.toml", "[[block]]\ntype = \"nope\"\nout = \"y\"\n");
    assert_eq!(cli(&["diagram", bad.to_str().unwrap()]), 4);
    assert_eq!(
        cli(&["diagram", data("itaipu/unit.toml").to_str().unwrap()]),
        2
    );
    assert_eq!(cli(&["models", "diagram"]), 0);
}
