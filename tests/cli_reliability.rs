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
