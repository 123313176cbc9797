//! End-to-end: nothing implausible accepted in silence, no panic (issue 13).

use itaipu_calib_e2e::{cli, data, TempDir};

fn spec_with(replace: &str, by: &str) -> String {
    let text = std::fs::read_to_string(data("itaipu/calibration.toml")).unwrap();
    assert!(text.contains(replace), "{replace}");
    text.replace(replace, by)
}

/// A stage whose objective sums nothing (weights all zero for the signals it names) used to
/// panic with an index out of bounds after the whole calculation; it is now a spec error (exit
/// 4) before anything runs, naming the stage and the field.
#[test]
fn zero_stage_weights_are_a_spec_error_before_any_computation() {
    let tmp = TempDir::new("zeroweights");
    let out = tmp.path().join("o");
    let cases = [
        (
            "pq with p = q = 0",
            spec_with(
                "name = \"gen\"\nobjective = \"pq\"",
                "name = \"gen\"\nobjective = \"pq\"\nweights = { p = 0, q = 0 }",
            ),
            "calibration.stage[0].weights (stage gen)",
        ),
        (
            "q with q = 0",
            spec_with(
                "name = \"avr\"\nobjective = \"q\"",
                "name = \"avr\"\nobjective = \"q\"\nweights = { p = 1, q = 0 }",
            ),
            "calibration.stage[1].weights.q (stage avr)",
        ),
        (
            "p with p = 0",
            spec_with(
                "name = \"gen\"\nobjective = \"pq\"",
                "name = \"gen\"\nobjective = \"p\"\nweights = { p = 0 }",
            ),
            "calibration.stage[0].weights.p (stage gen)",
        ),
    ];
    for (what, text, field) in cases {
        let spec = tmp.write("spec.toml", &text);
        let err = itaipu_calib::spec::CalibSpec::from_file(&spec).unwrap_err();
        assert_eq!(err.kind(), "field", "{what}");
        let msg = err.to_string();
        assert!(msg.contains(field), "{what}: {msg}");
        let t0 = std::time::Instant::now();
        let code = cli(&[
            "fit",
            "--calib",
            spec.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_eq!(code, 4, "{what}");
        // Refused while reading: far less than one stage's swarm.
        assert!(t0.elapsed().as_secs_f64() < 5.0, "{what}: refused late");
        assert!(!out.exists(), "{what}: nothing written");
    }
    // A zero weight on the signal the objective does not use is fine (q-only stage, p = 0).
    let ok = spec_with(
        "name = \"avr\"\nobjective = \"q\"",
        "name = \"avr\"\nobjective = \"q\"\nweights = { p = 0, q = 1 }",
    );
    let spec = tmp.write("ok.toml", &ok);
    assert!(itaipu_calib::spec::CalibSpec::from_file(&spec).is_ok());
}

fn names(dir: &std::path::Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// `--force` replaces the whole folder: stage folders and files of an earlier run do not stay
/// beside the new report; the manifest lists exactly what is there.
#[test]
fn force_replaces_the_whole_folder_and_the_manifest_matches() {
    let tmp = TempDir::new("force");
    let out = tmp.path().join("fit");
    tmp.write("fit/pss/unit.toml", "stale");
    tmp.write("fit/tg/traces.csv", "stale");
    tmp.write("fit/report.json", "{}");
    let args = |force: bool| {
        let mut v = vec![
            "fit",
            "--stage",
            "gen",
            "--particles",
            "4",
            "--pso-iterations",
            "2",
            "--lbfgs-iterations",
            "1",
            "--no-plot",
            "--out",
            out.to_str().unwrap(),
        ];
        if force {
            v.push("--force");
        }
        v
    };
    assert_eq!(cli(&args(false)), 7, "refused without --force");
    assert_eq!(names(&out), ["pss", "report.json", "tg"], "left as it was");
    assert_eq!(cli(&args(true)), 0);
    assert_eq!(
        names(&out),
        [
            "calibrated.toml",
            "calibration.toml",
            "datasheet.toml",
            "gen",
            "manifest.json",
            "report.json"
        ]
    );
    let m = itaipu_calib_cli::output::verify(&out).unwrap();
    assert_eq!(m.seed, Some(1));
    assert_eq!(m.command[1], "fit");
    assert!(m.files.iter().any(|f| f.path == "gen/unit.toml" && f.bytes > 0));
    // A changed file no longer matches its manifest.
    std::fs::write(out.join("gen/unit.toml"), "edited").unwrap();
    assert!(itaipu_calib_cli::output::verify(&out).is_err());
    // Nothing temporary left beside the target.
    assert_eq!(names(tmp.path()), ["fit"]);
    // simulate too.
    let sim = tmp.path().join("sim");
    tmp.write("sim/old.svg", "stale");
    assert_eq!(
        cli(&["simulate", "--no-plot", "--force", "--out", sim.to_str().unwrap()]),
        0
    );
    assert_eq!(names(&sim), ["manifest.json", "traces.csv"]);
    itaipu_calib_cli::output::verify(&sim).unwrap();
}

/// An output folder that cannot be written is found before the computation (exit 7), and a
/// run that fails leaves neither the target nor a temporary folder.
#[test]
fn unwritable_output_fails_before_computing_and_failures_leave_nothing() {
    let tmp = TempDir::new("unwritable");
    let file = tmp.write("a-file", "x");
    let out = file.join("sub");
    let t0 = std::time::Instant::now();
    // The default fit takes seconds; refused at once.
    assert_eq!(cli(&["fit", "--out", out.to_str().unwrap()]), 7);
    assert!(t0.elapsed().as_secs_f64() < 2.0, "refused late");
    assert_eq!(cli(&["simulate", "--out", out.to_str().unwrap()]), 7);
    // A unit that cannot initialise (exit 5): nothing written.
    let text = std::fs::read_to_string(data("itaipu/unit.toml")).unwrap();
    let bad = text.replace("e_max = 4.5", "e_max = 1.01");
    assert_ne!(bad, text);
    let unit = tmp.write("bad_unit.toml", &bad);
    let out = tmp.path().join("sim");
    let code = cli(&[
        "simulate",
        "--unit",
        unit.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_ne!(code, 0);
    assert_eq!(names(tmp.path()), ["a-file", "bad_unit.toml"]);
}

/// `--particles 0` (and 1) used to become 2 in silence: a usage error now, for fit and
/// diagnose.
#[test]
fn too_few_particles_is_a_usage_error() {
    for cmd in ["fit", "diagnose"] {
        for n in ["0", "1"] {
            assert_eq!(cli(&[cmd, "--particles", n]), 2, "{cmd} --particles {n}");
        }
    }
}
