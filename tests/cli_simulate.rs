//! End-to-end: `itaipu-calib simulate` on the bundled record, and its handling of bad input.

use itaipu_calib_e2e::{cli, cli_on, data, TempDir};

fn read_csv(path: &std::path::Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
    let rows = lines
        .map(|l| l.split(',').map(|v| v.parse::<f64>().unwrap()).collect())
        .collect();
    (header, rows)
}

#[test]
fn simulate_defaults_to_the_bundled_itaipu_event_and_writes_traces_and_plot() {
    let tmp = TempDir::new("sim");
    let out = tmp.path().join("run");
    assert_eq!(cli(&["simulate", "--out", out.to_str().unwrap()]), 0);
    let (header, rows) = read_csv(&out.join("traces.csv"));
    assert_eq!(rows.len(), 280, "one row per PMU sample");
    for col in [
        "time_s",
        "p_pu",
        "q_pu",
        "p_meas_pu",
        "q_meas_pu",
        "speed",
        "efd",
        "delta",
        "pm",
        "xadifd",
        "vs",
        "v_term",
    ] {
        assert!(
            header.iter().any(|h| h == col),
            "traces.csv lacks {col}: {header:?}"
        );
    }
    let idx = |n: &str| header.iter().position(|h| h == n).unwrap();
    // Pre-event (0-0.95 s): the model starts at the averaged operating point, so the mean of the
    // simulated P and Q equals the measured mean; sample by sample the played-back PMU noise
    // (about 0.05 deg in angle) moves P by a few 1e-3.
    let pre: Vec<&Vec<f64>> = rows.iter().filter(|r| r[idx("time_s")] <= 0.95).collect();
    let mean = |c: usize| pre.iter().map(|r| r[c]).sum::<f64>() / pre.len() as f64;
    assert!(
        (mean(idx("p_pu")) - mean(idx("p_meas_pu"))).abs() < 1e-3,
        "pre-event mean P"
    );
    assert!(
        (mean(idx("q_pu")) - mean(idx("q_meas_pu"))).abs() < 2e-3,
        "pre-event mean Q"
    );
    for row in &pre {
        assert!(
            (row[idx("p_pu")] - 0.6236).abs() < 6e-3,
            "pre-event P {}",
            row[idx("p_pu")]
        );
        assert!(
            (row[idx("q_pu")] - 0.0225).abs() < 1e-2,
            "pre-event Q {}",
            row[idx("q_pu")]
        );
    }
    // The fault dip must show in the simulation: P falls well below its pre-event value.
    let p_min = rows
        .iter()
        .map(|r| r[idx("p_pu")])
        .fold(f64::INFINITY, f64::min);
    assert!(
        p_min < 0.55,
        "the simulated P should react to the voltage dip (min {p_min})"
    );
    let svg = std::fs::read_to_string(out.join("plot.svg")).unwrap();
    assert!(svg.contains("<svg") && svg.contains("simulated") && svg.contains("measured"));
}

#[test]
fn an_existing_output_folder_is_not_overwritten_without_force() {
    let tmp = TempDir::new("force");
    let keep = tmp.write("notes.txt", "mine");
    let out = tmp.path().to_str().unwrap();
    assert_eq!(cli(&["simulate", "--out", out, "--no-plot"]), 7);
    assert_eq!(std::fs::read_to_string(&keep).unwrap(), "mine");
    assert!(!tmp.path().join("traces.csv").exists());
    // --force replaces a folder whole (issue 13), so it refuses one that is not an output of
    // ours: the user's notes stay.
    assert_eq!(cli(&["simulate", "--out", out, "--no-plot", "--force"]), 7);
    assert_eq!(std::fs::read_to_string(&keep).unwrap(), "mine");
    // An earlier run's folder is replaced whole: nothing of it stays beside the new results.
    let sim = tmp.path().join("sim");
    let o = sim.to_str().unwrap();
    assert_eq!(cli(&["simulate", "--out", o]), 0);
    assert!(sim.join("plot.svg").is_file());
    assert_eq!(cli(&["simulate", "--out", o, "--no-plot", "--force"]), 0);
    assert!(!sim.join("plot.svg").exists(), "replaced whole");
    itaipu_calib_cli::output::verify(&sim).unwrap();
    // A file the user put into it after the run is not deleted by --force.
    let added = tmp.write("sim/my-notes.txt", "mine");
    assert_eq!(cli(&["simulate", "--out", o, "--no-plot", "--force"]), 7);
    assert_eq!(std::fs::read_to_string(&added).unwrap(), "mine");
    assert!(sim.join("traces.csv").is_file());
}

#[test]
fn rk4_and_dopri5_agree_on_the_bundled_event() {
    let tmp = TempDir::new("methods");
    let a = tmp.path().join("a");
    let b = tmp.path().join("b");
    assert_eq!(
        cli(&[
            "simulate",
            "--out",
            a.to_str().unwrap(),
            "--no-plot",
            "--method",
            "rk4",
            "--step",
            "0.0005"
        ]),
        0
    );
    assert_eq!(
        cli(&[
            "simulate",
            "--out",
            b.to_str().unwrap(),
            "--no-plot",
            "--rtol",
            "1e-8"
        ]),
        0
    );
    let (h, ra) = read_csv(&a.join("traces.csv"));
    let (_, rb) = read_csv(&b.join("traces.csv"));
    for name in ["p_pu", "q_pu", "efd", "speed"] {
        let k = h.iter().position(|x| x == name).unwrap();
        let worst = ra
            .iter()
            .zip(&rb)
            .map(|(x, y)| (x[k] - y[k]).abs())
            .fold(0.0, f64::max);
        assert!(
            worst < 2e-4,
            "{name}: RK4 0.5 ms vs Dopri5 1e-8 differ by {worst:e}"
        );
    }
}

fn unit_text() -> String {
    std::fs::read_to_string(data("itaipu/unit.toml")).unwrap()
}

#[test]
fn bad_inputs_give_their_exit_codes() {
    let tmp = TempDir::new("bad");
    let out = tmp.path().join("o");
    let out = out.to_str().unwrap();
    let event = data("itaipu/event.toml");
    let event = event.to_str().unwrap();

    // 2: usage
    assert_eq!(cli(&["simulate", "--method", "euler"]), 2);
    assert_eq!(
        cli(&["simulate", "--method", "rk4", "--step", "-1", "--out", out]),
        2
    );
    assert_eq!(cli(&["frobnicate"]), 2);
    // 0: help
    assert_eq!(cli(&["simulate", "--help"]), 0);

    // 3: event data (missing file, unknown column)
    assert_eq!(
        cli(&["simulate", "--event", "no/such/event.toml", "--out", out]),
        3
    );
    let csv = tmp.write("bad.csv", "time_s,v_re_pu,v_im_pu,p_pu,q_pu,extra\n0,1,0,0.5,0.1,1\n0.1,1,0,0.5,0.1,1\n0.2,1,0,0.5,0.1,1\n0.3,1,0,0.5,0.1,1\n");
    let ev = tmp.write(
        "bad.toml",
        &format!(
            "name = \"x\"\ncsv = \"{}\"\nsystem_mva = 1000.0\nnominal_hz = 60.0\n",
            csv.file_name().unwrap().to_str().unwrap()
        ),
    );
    assert_eq!(
        cli(&["simulate", "--event", ev.to_str().unwrap(), "--out", out]),
        3
    );

    // 4: unit model (unknown parameter, unknown model, reactance ordering)
    let u = tmp.write(
        "u1.toml",
        &unit_text().replace("h = 4.5", "h = 4.5\ninertia = 3.0"),
    );
    assert_eq!(cli_on("simulate", event, &u, out, &[]), 4);
    let u = tmp.write(
        "u2.toml",
        &unit_text().replace("model = \"SEXS\"", "model = \"SEXS9\""),
    );
    assert_eq!(cli_on("simulate", event, &u, out, &[]), 4);
    let u = tmp.write(
        "u3.toml",
        &unit_text().replace("x_d_pp = 0.22", "x_d_pp = 0.15"),
    );
    assert_eq!(
        cli_on("simulate", event, &u, out, &[]),
        4,
        "X''d = Xl must be refused"
    );
    let u = tmp.write("u4.toml", &unit_text().replace("te = 0.05", "te = 0.0"));
    assert_eq!(
        cli_on("simulate", event, &u, out, &[]),
        4,
        "zero time constant"
    );

    // 5: cannot initialise (E_fd0 above E_MAX)
    let u = tmp.write(
        "u5.toml",
        &unit_text().replace("e_max = 4.5", "e_max = 1.0"),
    );
    assert_eq!(cli_on("simulate", event, &u, out, &[]), 5);
    assert!(
        !std::path::Path::new(out).exists(),
        "no output folder for a failed run"
    );
}
