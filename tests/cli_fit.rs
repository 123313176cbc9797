//! End-to-end: `itaipu-calib fit` on the bundled Itaipu record with RaPId's problem, and its
//! handling of bad calibration specs.

use itaipu_calib_e2e::{cli, data, TempDir};

fn json(path: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// RaPId's 18-parameter problem (constant P_m): its best stored result scores J = 2.097 over the
/// 280 samples; ours must score below 1.0, and the calibrated unit written to disk must
/// reproduce that number when simulated on its own.
#[test]
fn fit_beats_rapid_on_the_itaipu_record() {
    let tmp = TempDir::new("fit");
    let out = tmp.path().join("fit");
    assert_eq!(
        cli(&[
            "fit",
            "--stage",
            "gen,avr,pss",
            "--out",
            out.to_str().unwrap()
        ]),
        0
    );
    let report = json(&out.join("report.json"));
    let stages = report["stages"].as_array().unwrap();
    let names: Vec<&str> = stages
        .iter()
        .map(|s| s["stage"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["gen", "avr", "pss", "joint"]);
    let free: usize = stages[..3]
        .iter()
        .map(|s| s["parameters"].as_array().unwrap().len())
        .sum();
    assert_eq!(free, 18, "RaPId's 18 free parameters");
    let j = |s: &serde_json::Value| s["fitness"][0]["j_pq"].as_f64().unwrap();
    let j_start = report["start_fitness"][0]["j_pq"].as_f64().unwrap();
    let j_final = j(stages.last().unwrap());
    assert_eq!(
        stages.last().unwrap()["fitness"][0]["samples"].as_u64(),
        Some(280)
    );
    assert!(
        j_final < 1.0,
        "J = {j_final} (RaPId: 2.097, start {j_start})"
    );
    for s in stages {
        assert!(
            s["objective_after"].as_f64().unwrap()
                <= s["objective_before"].as_f64().unwrap() + 1e-12
        );
        assert!(s["wall_s"].as_f64().unwrap() > 0.0 && s["simulations"].as_u64().unwrap() > 0);
    }
    // The calibrated unit file simulates to the same J.
    let sim_out = tmp.path().join("sim");
    let unit = out.join("calibrated.toml");
    assert_eq!(
        cli(&[
            "simulate",
            "--unit",
            unit.to_str().unwrap(),
            "--out",
            sim_out.to_str().unwrap(),
            "--no-plot",
            "--rtol",
            "1e-9",
            "--atol",
            "1e-10"
        ]),
        0
    );
    let text = std::fs::read_to_string(sim_out.join("traces.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |n: &str| header.iter().position(|h| *h == n).unwrap();
    let mut j_sim = 0.0;
    for l in lines {
        let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
        j_sim += (v[col("p_pu")] - v[col("p_meas_pu")]).powi(2)
            + (v[col("q_pu")] - v[col("q_meas_pu")]).powi(2);
    }
    assert!(
        (j_sim - j_final).abs() < 1e-4 * j_final,
        "calibrated.toml gives J = {j_sim}, the report {j_final}"
    );
    for stage in ["gen", "avr", "pss", "joint"] {
        for f in ["unit.toml", "traces.csv", "traces_start.csv", "plot.svg"] {
            assert!(out.join(stage).join(f).is_file(), "{stage}/{f} missing");
        }
    }
    // The calibrated machine satisfies the physical relations.
    let text = std::fs::read_to_string(&unit).unwrap();
    let v = |k: &str| -> f64 {
        text.lines()
            .find(|l| l.starts_with(&format!("{k} =")))
            .and_then(|l| l.split('=').nth(1))
            .and_then(|r| r.split('#').next())
            .map(|x| x.trim().parse().unwrap())
            .unwrap()
    };
    assert!(v("x_d") > v("x_d_prime") && v("x_d_prime") > v("x_d_pp") && v("x_d_pp") > v("x_l"));
    assert!(v("t_d0_prime") > v("t_d0_pp"));
    // What `diagnose --fit` needs is written beside it, and it re-frees the calibrated set.
    assert!(out.join("datasheet.toml").is_file() && out.join("calibration.toml").is_file());
    let diag = tmp.path().join("diag");
    assert_eq!(
        cli(&[
            "diagnose",
            "--fit",
            out.to_str().unwrap(),
            "--cause",
            "measurement_skew",
            "--pso-iterations",
            "2",
            "--lbfgs-iterations",
            "2",
            "--no-plot",
            "--out",
            diag.to_str().unwrap()
        ]),
        0
    );
    let d = json(&diag.join("diagnosis.json"));
    let refit: Vec<&str> = d["refit"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| b["param"].as_str().unwrap())
        .collect();
    // Every parameter the spec frees that the calibrated unit has (the governor stage, which
    // would put in a HYGOV, did not run).
    assert_eq!(refit.len(), 18, "{refit:?}");
    assert!(refit.contains(&"machine.x_d_prime") && refit.contains(&"pss.t_x2"));
    // --fit and --unit exclude each other (usage error).
    assert_eq!(
        cli(&[
            "diagnose",
            "--fit",
            out.to_str().unwrap(),
            "--unit",
            unit.to_str().unwrap()
        ]),
        2
    );
}

fn spec_with(replace: &str, by: &str) -> String {
    let text = std::fs::read_to_string(data("itaipu/calibration.toml")).unwrap();
    assert!(text.contains(replace), "{replace}");
    text.replace(replace, by)
}

#[test]
fn bad_calibration_specs_exit_with_code_4_before_fitting() {
    let tmp = TempDir::new("badspec");
    let out = tmp.path().join("o");
    let out = out.to_str().unwrap();
    let cases = [
        (
            "upside-down bounds",
            spec_with(
                "{ param = \"machine.x_d\", min = 0.6, max = 2.0 }",
                "{ param = \"machine.x_d\", min = 2.0, max = 0.6 }",
            ),
        ),
        (
            "unknown parameter",
            spec_with("param = \"machine.x_d\",", "param = \"machine.x_dd\","),
        ),
        (
            "parameter of a block the papers' reduction removes",
            spec_with("param = \"machine.h\",", "param = \"exciter.k\",")
                .replace("seed = 1", "seed = 1\nstage_blocks = \"remove\""),
        ),
        (
            "parameter of a block the unit does not have yet",
            spec_with("param = \"machine.h\",", "param = \"governor.t_w\","),
        ),
        ("unknown key", spec_with("seed = 1", "seed = 1\nseeds = 2")),
        (
            "unknown stage",
            spec_with("name = \"pss\"", "name = \"pssx\""),
        ),
        ("no calibration table", "name = \"x\"\n".to_string()),
    ];
    for (what, text) in cases {
        let spec = tmp.write("spec.toml", &text);
        let code = cli(&[
            "fit",
            "--calib",
            spec.to_str().unwrap(),
            "--out",
            out,
            "--pso-iterations",
            "1",
            "--lbfgs-iterations",
            "1",
        ]);
        assert_eq!(code, 4, "{what}");
        assert!(
            !std::path::Path::new(out).exists(),
            "{what}: no output for a refused spec"
        );
    }
    // An existing output folder is refused before the fit runs.
    let keep = tmp.write("o2/mine.txt", "x");
    let _ = keep;
    assert_eq!(
        cli(&[
            "fit",
            "--out",
            tmp.path().join("o2").to_str().unwrap(),
            "--stage",
            "pss"
        ]),
        7
    );
}
