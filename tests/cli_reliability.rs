//! End-to-end: nothing implausible accepted in silence, no panic (issue 13).

use itaipu_calib_e2e::{cli, data, file_names, TempDir};

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
    assert_eq!(
        file_names(&out),
        ["pss", "report.json", "tg"],
        "left as it was"
    );
    assert_eq!(cli(&args(true)), 0);
    assert_eq!(
        file_names(&out),
        [
            "calibrated.toml",
            "calibration.toml",
            "datasheet.toml",
            "gen",
            "manifest.json",
            "report.html",
            "report.json"
        ]
    );
    let m = itaipu_calib_cli::output::verify(&out).unwrap();
    assert_eq!(m.seed, Some(1));
    assert_eq!(m.command[1], "fit");
    assert!(m
        .files
        .iter()
        .any(|f| f.path == "gen/unit.toml" && f.bytes > 0));
    // A changed file no longer matches its manifest.
    std::fs::write(out.join("gen/unit.toml"), "edited").unwrap();
    assert!(itaipu_calib_cli::output::verify(&out).is_err());
    // Nothing temporary left beside the target.
    assert_eq!(file_names(tmp.path()), ["fit"]);
    // simulate too.
    let sim = tmp.path().join("sim");
    tmp.write("sim/traces.csv", "stale");
    tmp.write("sim/old.svg", "stale");
    assert_eq!(
        cli(&[
            "simulate",
            "--no-plot",
            "--force",
            "--out",
            sim.to_str().unwrap()
        ]),
        0
    );
    // warnings.json: the bundled record's end is a measurement drop-out (edge_dropout).
    assert_eq!(
        file_names(&sim),
        ["manifest.json", "traces.csv", "warnings.json"]
    );
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
    assert_eq!(file_names(tmp.path()), ["a-file", "bad_unit.toml"]);
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

/// Writes the Itaipu event with its CSV rows passed through `edit` (row index, fields).
fn itaipu_event_with(
    tmp: &TempDir,
    tag: &str,
    edit: impl Fn(usize, &mut Vec<f64>),
) -> std::path::PathBuf {
    let text = std::fs::read_to_string(data("itaipu/itaipu_pmu_60sps.csv")).unwrap();
    let mut lines = text.lines();
    let mut csv = format!("{}\n", lines.next().unwrap());
    for (i, l) in lines.enumerate() {
        let mut v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
        edit(i, &mut v);
        let s: Vec<String> = v.iter().map(|x| format!("{x:?}")).collect();
        csv.push_str(&s.join(","));
        csv.push('\n');
    }
    tmp.write(&format!("{tag}.csv"), &csv);
    let ev = std::fs::read_to_string(data("itaipu/event.toml"))
        .unwrap()
        .replace("itaipu_pmu_60sps.csv", &format!("{tag}.csv"));
    tmp.write(&format!("{tag}.toml"), &ev)
}

/// Implausible data stop the run before anything is computed (exit 3, nothing written);
/// implausible but possible data run with a warning kept in the outputs.
#[test]
fn implausible_events_stop_or_warn_through_the_cli() {
    let tmp = TempDir::new("plaus");
    let out = tmp.path().join("o");
    let o = out.to_str().unwrap();
    // A one-sample dropout, a 100 s gap, a time column in picoseconds, P on a wrong base.
    let dropout = itaipu_event_with(&tmp, "dropout", |i, v| {
        if i == 200 {
            v[1] = 0.0;
            v[2] = 0.0;
        }
    });
    let gap = itaipu_event_with(&tmp, "gap", |i, v| {
        if i >= 150 {
            v[0] += 100.0;
        }
    });
    let scaled = itaipu_event_with(&tmp, "scaled", |_, v| v[0] *= 1e-12);
    let base = itaipu_event_with(&tmp, "base", |_, v| {
        v[3] *= 1.6;
        v[4] *= 1.6;
    });
    for ev in [&dropout, &gap, &scaled, &base] {
        for cmd in ["simulate", "fit"] {
            let code = cli(&[cmd, "--event", ev.to_str().unwrap(), "--out", o]);
            assert_eq!(code, 3, "{cmd} {}", ev.display());
            assert!(!out.exists());
        }
    }
    // Flipped signs: a warning, kept in warnings.json.
    let flipped = itaipu_event_with(&tmp, "flipped", |_, v| {
        v[3] = -v[3];
        v[4] = -v[4];
    });
    let code = cli(&[
        "simulate",
        "--event",
        flipped.to_str().unwrap(),
        "--no-plot",
        "--out",
        o,
    ]);
    assert_eq!(code, 0);
    let w: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("warnings.json")).unwrap()).unwrap();
    assert_eq!(w[0]["kind"], "absorbing_p");
    assert_eq!(w[0]["severity"], "warning");
    assert!(w[0]["file"].as_str().unwrap().ends_with("flipped.csv"));
    itaipu_calib_cli::output::verify(&out).unwrap();
}

/// The rest of the bad-input table through the command line. A sample of 1e300 (it ended in
/// a step-size underflow at t = 1.65 s) and P and Q on a base 20 times too small though below
/// the reader's MW check (it ended in an E_fd0 beyond the ceiling) stop before anything is
/// computed, exit 3, naming the line or the base and the fix, and so does an angle column in
/// radians that wraps at ±π; h = 1e308 runs with its warning kept in warnings.json.
#[test]
fn the_rest_of_the_bad_input_table_through_the_cli() {
    let tmp = TempDir::new("table");
    let out = tmp.path().join("o");
    let o = out.to_str().unwrap();
    let unit_path = data("itaipu/unit.toml");
    let unit = itaipu_calib_cli::load_unit(&unit_path).unwrap();
    // The message the run stops with: the reader's or the plausibility layer's.
    let stop_message = |ev: &std::path::Path| match itaipu_calib_cli::load_event(ev) {
        Err(e) => (e.code, e.msg),
        Ok(e) => {
            let e = itaipu_calib_cli::plausibility(&[&e], &unit, &unit_path).unwrap_err();
            (e.code, e.msg)
        }
    };
    // Row 99 is t = 1.65 s, line 101 of the CSV.
    let huge = itaipu_event_with(&tmp, "huge", |i, v| {
        if i == 99 {
            v[1] = 1e300;
        }
    });
    let (code, msg) = stop_message(&huge);
    assert_eq!(code, 3);
    assert!(
        msg.contains("huge.csv line 101 (t = 1.65 s), |V|: 1e300 is far beyond"),
        "{msg}"
    );
    assert!(msg.contains("fix: "), "{msg}");
    let small_base = itaipu_event_with(&tmp, "small_base", |_, v| {
        v[3] *= 20.0;
        v[4] *= 20.0;
    });
    // Below the reader's MW check (|P| < 20 pu), so only the plausibility layer finds it.
    let e = itaipu_calib_cli::load_event(&small_base).unwrap();
    assert!(e.record.p_pu.iter().all(|p| p.abs() < 20.0));
    let (code, msg) = stop_message(&small_base);
    assert_eq!(code, 3);
    assert!(
        msg.contains("exceeds the machine's rating 737 MVA") && msg.contains("set system_mva"),
        "{msg}"
    );
    assert!(!msg.contains("E_fd0"), "{msg}");
    for ev in [&huge, &small_base] {
        for cmd in ["simulate", "fit"] {
            assert_eq!(cli(&[cmd, "--event", ev.to_str().unwrap(), "--out", o]), 3);
            assert!(!out.exists());
        }
    }
    // The angle in radians in an angle_deg column: |V| and the angle from the record's phasor.
    let text = std::fs::read_to_string(data("itaipu/itaipu_pmu_60sps.csv")).unwrap();
    let mut csv = String::from("time_s,v_pu,angle_deg,p_pu,q_pu\n");
    for l in text.lines().skip(1) {
        let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
        csv.push_str(&format!(
            "{:?},{:?},{:?},{:?},{:?}\n",
            v[0],
            v[1].hypot(v[2]),
            v[2].atan2(v[1]),
            v[3],
            v[4]
        ));
    }
    tmp.write("radians.csv", &csv);
    let ev = std::fs::read_to_string(data("itaipu/event.toml"))
        .unwrap()
        .replace("itaipu_pmu_60sps.csv", "radians.csv");
    let radians = tmp.write("radians.toml", &ev);
    // The Itaipu angle crosses ±180° in the record, so the radians wrap by 2π: an error.
    let (code, msg) = stop_message(&radians);
    assert_eq!(code, 3);
    assert!(
        msg.contains("radians.csv line 1, angle_deg: the angle stays within ±π and jumps by 2π")
            && msg.contains("fix: convert the column to degrees"),
        "{msg}"
    );
    assert_eq!(
        cli(&["simulate", "--event", radians.to_str().unwrap(), "--out", o]),
        3
    );
    assert!(!out.exists());
    // h = 1e308: a warning naming the parameter, kept with the results.
    let u = std::fs::read_to_string(&unit_path)
        .unwrap()
        .replace("h = 4.5 ", "h = 1e308 ");
    assert!(u.contains("h = 1e308 "));
    let u = tmp.write("h.toml", &u);
    let code = cli(&[
        "simulate",
        "--no-plot",
        "--out",
        o,
        "--unit",
        u.to_str().unwrap(),
    ]);
    assert_eq!(code, 0);
    itaipu_calib_cli::output::verify(&out).unwrap();
    let w: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("warnings.json")).unwrap()).unwrap();
    // After the record's own warning (its end is a measurement drop-out, edge_dropout).
    assert_eq!(w[0]["kind"], "edge_dropout");
    assert_eq!(w[1]["kind"], "parameter_range");
    assert_eq!(w[1]["column"], "machine.h");
    assert!(w[1]["file"].as_str().unwrap().ends_with("h.toml"));
}

/// A start value outside its bounds is no longer clamped in silence: the fit's report lists
/// the warning with the spec's field.
#[test]
fn a_clamped_start_is_reported() {
    let tmp = TempDir::new("clamp");
    // machine.h is 4.5 in the unit; bounds 0.1-3.0 put it outside.
    let text = std::fs::read_to_string(data("itaipu/calibration.toml"))
        .unwrap()
        .replace(
            "{ param = \"machine.h\", min = 0.1, max = 5.0 }",
            "{ param = \"machine.h\", min = 0.1, max = 3.0 }",
        );
    let spec = tmp.write("c.toml", &text);
    let out = tmp.path().join("o");
    let code = cli(&[
        "fit",
        "--calib",
        spec.to_str().unwrap(),
        "--stage",
        "gen",
        "--particles",
        "4",
        "--pso-iterations",
        "1",
        "--lbfgs-iterations",
        "1",
        "--no-plot",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0);
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    // The warnings on the inputs (those on the calibrated unit name calibrated.toml): only this
    // one and the bundled record's measurement drop-out at its end (edge_dropout, a warning):
    // the record, unit and spec are otherwise plausible as given (the spec gives the starts of
    // the parameters whose datasheet values lie outside RaPId's bounds).
    let w: Vec<&serde_json::Value> = r["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|x| x["file"] != "calibrated.toml")
        .collect();
    assert_eq!(w.len(), 2, "{w:#?}");
    assert!(w.iter().any(|x| x["kind"] == "edge_dropout"), "{w:#?}");
    let c = w
        .iter()
        .find(|x| x["kind"] == "start_clamped")
        .expect("start_clamped");
    assert!(c["column"]
        .as_str()
        .unwrap()
        .contains("calibration.stage[0].free[1] (machine.h)"));
    assert!(c["message"].as_str().unwrap().contains("starts from 3"));
}

/// `--method rk4 --step 1e-9` is refused at once (it ran for half an hour).
#[test]
fn absurd_rk4_steps_are_refused() {
    let t0 = std::time::Instant::now();
    assert_eq!(cli(&["simulate", "--method", "rk4", "--step", "1e-9"]), 2);
    assert!(t0.elapsed().as_secs_f64() < 2.0);
}

/// Run-time failures point at the data: an integration failure at t names the CSV line of the
/// sample there, an initialisation failure the operating point (on both bases) it was given.
#[test]
fn run_time_failures_point_at_the_data() {
    use itaipu_dynamics::integrate::SolveError;
    use itaipu_dynamics::simulate::{simulate, SimError, SimOptions};
    let event = itaipu_calib_cli::load_event(&data("itaipu/event.toml")).unwrap();
    let unit = itaipu_calib_cli::load_unit(&data("itaipu/unit.toml")).unwrap();
    let e = SimError::Solve(SolveError::StepUnderflow { t: 1.65, h: 1e-20 });
    let err = itaipu_calib_cli::explain_sim_error(e, &event, &unit);
    assert_eq!(err.code, 6);
    // t = 1.65 s is sample 99 at 60 samples/s: line 101 of the CSV (header = line 1).
    assert!(err.msg.contains("line 101 (t = 1.65"), "{}", err.msg);
    assert!(err.msg.contains("itaipu_pmu_60sps.csv"), "{}", err.msg);
    // A unit that cannot initialise at the operating point.
    let tmp = TempDir::new("explain");
    let text = std::fs::read_to_string(data("itaipu/unit.toml"))
        .unwrap()
        .replace("e_max = 4.5", "e_max = 1.01");
    let bad = itaipu_calib_cli::load_unit(&tmp.write("u.toml", &text)).unwrap();
    let e = simulate(&bad, &event, &SimOptions::default()).unwrap_err();
    let err = itaipu_calib_cli::explain_sim_error(e, &event, &bad);
    assert_eq!(err.code, 5);
    assert!(
        err.msg.contains("init window [0, 0.9666") && err.msg.contains("on the machine's 737 MVA"),
        "{}",
        err.msg
    );
    // diagnose and fit stop on it before any computation (exit 5), nothing written.
    let out = tmp.path().join("o");
    let bad_path = tmp.path().join("u.toml");
    let calib = data("itaipu/calibration.toml");
    for cmd in ["diagnose", "fit"] {
        let t0 = std::time::Instant::now();
        let mut args = vec![
            cmd,
            "--unit",
            bad_path.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        if cmd == "fit" {
            args.extend(["--calib", calib.to_str().unwrap()]);
        }
        let code = cli(&args);
        assert_eq!(code, 5, "{cmd}");
        assert!(!out.exists(), "{cmd}");
        assert!(
            t0.elapsed().as_secs_f64() < 5.0,
            "{cmd}: {:?}",
            t0.elapsed()
        );
    }
}
