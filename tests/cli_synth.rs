//! End-to-end: `itaipu-calib synth` makes an event that `simulate` reads back, reproducibly, and
//! whose truth reproduces the measurement to the noise level.

use itaipu_calib_e2e::{cli, cli_on, TempDir};

fn rms_residuals(traces: &std::path::Path) -> (f64, f64) {
    let text = std::fs::read_to_string(traces).unwrap();
    let mut lines = text.lines();
    let h: Vec<&str> = lines.next().unwrap().split(',').collect();
    let c = |n: &str| h.iter().position(|x| *x == n).unwrap();
    let (mut sp, mut sq, mut n) = (0.0, 0.0, 0.0);
    for l in lines {
        let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
        sp += (v[c("p_pu")] - v[c("p_meas_pu")]).powi(2);
        sq += (v[c("q_pu")] - v[c("q_meas_pu")]).powi(2);
        n += 1.0;
    }
    ((sp / n).sqrt(), (sq / n).sqrt())
}

#[test]
fn synth_events_play_back_to_the_noise_level_and_are_reproducible() {
    let tmp = TempDir::new("synth");
    for kind in ["dip", "frequency", "step", "ambient"] {
        let a = tmp.path().join(format!("{kind}-a"));
        let b = tmp.path().join(format!("{kind}-b"));
        let args = |out: &std::path::Path| {
            vec![
                "synth".to_string(),
                "--kind".into(),
                kind.into(),
                "--duration".into(),
                "8".into(),
                "--seed".into(),
                "4".into(),
                "--v-sigma".into(),
                "0".into(),
                "--out".into(),
                out.to_str().unwrap().to_string(),
            ]
        };
        let run =
            |out: &std::path::Path| cli(&args(out).iter().map(|s| s.as_str()).collect::<Vec<_>>());
        assert_eq!(run(&a), 0, "{kind}");
        assert_eq!(run(&b), 0, "{kind}");
        let csv = format!("synthetic-{kind}-4.csv");
        assert_eq!(
            std::fs::read(a.join(&csv)).unwrap(),
            std::fs::read(b.join(&csv)).unwrap(),
            "{kind}: same seed, same bytes"
        );
        let sim = tmp.path().join(format!("{kind}-sim"));
        let code = cli_on(
            "simulate",
            a.join("event.toml"),
            a.join("truth.toml"),
            &sim,
            &["--no-plot"],
        );
        assert_eq!(code, 0, "{kind}");
        // White noise of 0.002 pu plus 0.0014 pu quantisation: RMS about 0.002. An ambient
        // record has no steady pre-event segment, so the operating point averaged over the
        // first second differs from the truth's exact initial state and Q keeps a small offset.
        let (rp, rq) = rms_residuals(&sim.join("traces.csv"));
        let q_max = if kind == "ambient" { 0.0035 } else { 0.0026 };
        assert!(
            rp > 0.0015 && rp < 0.0026 && rq > 0.0015 && rq < q_max,
            "{kind}: RMS P {rp}, Q {rq}"
        );
        let truth: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(a.join("truth.json")).unwrap()).unwrap();
        assert_eq!(truth["kind"], kind);
        assert_eq!(truth["hidden_effects"].as_array().unwrap().len(), 0);
    }
}

#[test]
fn a_hidden_skew_is_recorded_and_shows_in_the_residual() {
    let tmp = TempDir::new("skew");
    let out = tmp.path().join("s");
    let args = [
        "synth",
        "--duration",
        "6",
        "--skew-ms",
        "12",
        "--pq-sigma",
        "0",
        "--v-sigma",
        "0",
        "--quantum",
        "0",
        "--out",
        out.to_str().unwrap(),
    ];
    assert_eq!(cli(&args), 0);
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("truth.json")).unwrap()).unwrap();
    assert_eq!(truth["hidden_effects"][0]["cause"], "measurement_skew");
    assert!((truth["hidden_effects"][0]["delay_s"].as_f64().unwrap() - 0.012).abs() < 1e-12);
    let sim = tmp.path().join("sim");
    let event = out.join("event.toml");
    let unit = out.join("truth.toml");
    assert_eq!(cli_on("simulate", &event, &unit, &sim, &["--no-plot"]), 0);
    let (rp, _) = rms_residuals(&sim.join("traces.csv"));
    assert!(
        rp > 1e-3,
        "a 12 ms skew through a fault dip must leave a residual (RMS P {rp})"
    );
}

#[test]
fn synth_refuses_bad_arguments() {
    let tmp = TempDir::new("synthbad");
    let out = tmp.path().join("o");
    let out = out.to_str().unwrap();
    assert_eq!(cli(&["synth", "--kind", "earthquake", "--out", out]), 2);
    assert_eq!(cli(&["synth", "--rate", "0", "--out", out]), 2);
    assert_eq!(cli(&["synth", "--skew-ms", "-3", "--out", out]), 2);
    assert_eq!(cli(&["synth", "--unit", "missing.toml", "--out", out]), 4);
    let keep = tmp.write("full/x.txt", "mine");
    assert_eq!(
        cli(&["synth", "--out", keep.parent().unwrap().to_str().unwrap()]),
        7
    );
}

#[test]
fn a_hidden_torsional_mode_is_in_the_truth() {
    let tmp = TempDir::new("hide");
    let out = tmp.path().join("t");
    let args = [
        "synth",
        "--duration",
        "4",
        "--v-sigma",
        "0",
        "--hide",
        "torsional_mode:shaft.f_torsion_hz=5,shaft.zeta=0.05,shaft.h_turbine=0.6",
        "--hide",
        "terminal_load:load.p_load=0.04",
        "--out",
        out.to_str().unwrap(),
    ];
    assert_eq!(cli(&args), 0);
    let toml = std::fs::read_to_string(out.join("truth.toml")).unwrap();
    assert!(
        toml.contains("model = \"two_mass_shaft\"") && toml.contains("pm = \"p_shaft\""),
        "{toml}"
    );
    assert!(toml.contains("model = \"terminal_load\""), "{toml}");
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("truth.json")).unwrap()).unwrap();
    let hidden = truth["hidden_effects"].as_array().unwrap();
    assert_eq!(hidden.len(), 2);
    assert_eq!(hidden[0]["cause"], "torsional_mode");
    assert_eq!(hidden[0]["parameters"]["shaft.f_torsion_hz"], 5.0);
    assert_eq!(hidden[0]["parameters"]["shaft.zeta"], 0.05);
    assert_eq!(hidden[0]["parameters"]["shaft.h_turbine"], 0.6);
    assert_eq!(hidden[1]["cause"], "terminal_load");
    assert_eq!(hidden[1]["parameters"]["load.p_load"], 0.04);
    assert_eq!(truth["parameters"]["shaft.f_torsion_hz"], 5.0);
    assert_eq!(truth["parameters"]["load.p_load"], 0.04);
    // The truth plays back to the noise level: truth.toml is the unit that made the event.
    let sim = tmp.path().join("sim");
    let (event, unit) = (out.join("event.toml"), out.join("truth.toml"));
    assert_eq!(cli_on("simulate", &event, &unit, &sim, &["--no-plot"]), 0);
    let (rp, rq) = rms_residuals(&sim.join("traces.csv"));
    assert!(rp < 0.0026 && rq < 0.0026, "RMS P {rp}, Q {rq}");
}

#[test]
fn a_bad_hide_is_a_usage_error_and_writes_nothing() {
    let tmp = TempDir::new("hidebad");
    let out = tmp.path().join("o");
    let o = out.to_str().unwrap();
    for spec in [
        "earthquake",
        "torsional_mode:shaft.nope=3",
        "torsional_mode:shaft.f_torsion_hz",
        "torsional_mode:shaft.f_torsion_hz=fast",
        "torsional_mode:",
        ":shaft.zeta=0.1",
        "torsional_mode:shaft.zeta=0.1,shaft.zeta=0.2",
    ] {
        assert_eq!(
            cli(&["synth", "--duration", "3", "--hide", spec, "--out", o]),
            2,
            "{spec}"
        );
        assert!(!out.exists(), "{spec}: nothing may be written");
    }
    // A hidden ceiling below the operating point's field voltage: the truth cannot initialise.
    assert_eq!(
        cli(&[
            "synth",
            "--duration",
            "3",
            "--hide",
            "exciter_limit:exciter.e_max=0.5",
            "--out",
            o
        ]),
        5
    );
    assert!(!out.exists());
}
