//! End-to-end: a cause written by the user (`diagnose --user-cause FILE`). The truth of a
//! synthetic dip is the generic unit with a reactive-current compensator (the user-defined
//! diagram `data/causes/reactive_droop.diagram.toml`) wired in front of its SEXS in the unit
//! file itself; `diagnose` on the generic unit with the cause file
//! `data/causes/reactive_droop.toml` names the cause and writes the extended unit. A bad cause
//! file exits 4, an id that is neither the catalog's nor a user cause's exits 2, nothing written.

use std::path::Path;

use itaipu_calib_e2e::{cli, cli_on, data, TempDir, DIAGNOSE_BUDGET};

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn a_user_cause_is_tried_named_and_its_extended_unit_written() {
    let tmp = TempDir::new("user-cause");
    let generic = data("synthetic/unit_gensae_sexs_stab3_hygov.toml");
    let diagram = data("causes/reactive_droop.diagram.toml");
    let truth_text = std::fs::read_to_string(&generic).unwrap().replace(
        "model = \"SEXS\"",
        "model = \"SEXS\"\nwiring = { v_term = \"v_comp\" }",
    ) + &format!(
        "\n[[block]]\nname = \"droop\"\nmodel = \"diagram\"\ndiagram = \"{}\"\nx_c = 0.07\n",
        diagram.display()
    );
    let truth = tmp.write("truth.toml", &truth_text);
    let ev_dir = tmp.path().join("ev");
    assert_eq!(
        cli(&[
            "synth",
            "--unit",
            truth.to_str().unwrap(),
            "--duration",
            "10",
            "--seed",
            "5",
            "--out",
            ev_dir.to_str().unwrap()
        ]),
        0
    );
    let event = ev_dir.join("event.toml");
    let cause = data("causes/reactive_droop.toml");
    let out = tmp.path().join("diag");
    let args = [
        "diagnose",
        "--event",
        event.to_str().unwrap(),
        "--unit",
        generic.to_str().unwrap(),
        "--user-cause",
        cause.to_str().unwrap(),
        "--cause",
        "reactive_droop,terminal_load",
        "--no-plot",
        "--out",
        out.to_str().unwrap(),
    ];
    let args = [&args[..], &DIAGNOSE_BUDGET].concat();
    assert_eq!(cli(&args), 0);
    let d = json(&out.join("diagnosis.json"));
    assert_eq!(
        d["verdict"]["cause"], "reactive_droop",
        "{}",
        d["verdict"]["statement"]
    );
    let x_c = d["verdict"]["key_parameters"]
        .as_array()
        .unwrap()
        .iter()
        .find(|k| k[0] == "droop.x_c")
        .map(|k| k[1].as_f64().unwrap())
        .expect("X_c in the verdict");
    assert!((x_c - 0.07).abs() < 0.01, "X_c {x_c}");
    // The extended unit carries the diagram inline and simulates on its own.
    let ext = std::fs::read_to_string(out.join("extended.toml")).unwrap();
    assert!(ext.contains("droop") && ext.contains("v_comp"), "{ext}");
    let sim = tmp.path().join("sim");
    assert_eq!(
        cli_on(
            "simulate",
            &event,
            out.join("extended.toml"),
            &sim,
            &["--no-plot"]
        ),
        0
    );
}

#[test]
fn bad_user_causes_exit_before_running() {
    let tmp = TempDir::new("user-cause-bad");
    let event = data("itaipu/event.toml");
    let unit = data("itaipu/unit.toml");
    let good = std::fs::read_to_string(data("causes/reactive_droop.toml"))
        .unwrap()
        .replace(
            "reactive_droop.diagram.toml",
            data("causes/reactive_droop.diagram.toml").to_str().unwrap(),
        );
    let out = tmp.path().join("o");
    let run = |cause_file: &Path, extra: &[&str]| {
        let mut a = vec!["--user-cause", cause_file.to_str().unwrap()];
        a.extend_from_slice(extra);
        cli_on("diagnose", &event, &unit, &out, &a)
    };
    // A bad file (a free parameter its block lacks) or a missing one: exit 4.
    let bad = tmp.write(
        "bad.toml",
        &good.replace("param = \"droop.x_c\"", "param = \"droop.k\""),
    );
    assert_eq!(run(&bad, &[]), 4);
    assert_eq!(run(&tmp.path().join("absent.toml"), &[]), 4);
    // --cause with an id that is neither the catalog's nor the user cause's: exit 2.
    let ok = tmp.write("ok.toml", &good);
    assert_eq!(run(&ok, &["--cause", "reactive_drop"]), 2);
    assert!(!out.exists(), "nothing written");
}
