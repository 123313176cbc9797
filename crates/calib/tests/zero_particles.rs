//! Issue 25: a swarm of no particle, which a program may ask for (the spec parser, the command
//! line and Python refuse fewer than 2), is a setup error of `fit` and `diagnose`; it was a
//! panic inside the swarm ("invalid PSO options").

use std::path::Path;

use itaipu_calib::diagnose::trial::base_unit;
use itaipu_calib::diagnose::{diagnose, DiagnoseError, DiagnoseOptions};
use itaipu_calib::fit::{fit, FitError, FitOptions, Silent};
use itaipu_calib::spec::CalibSpec;
use itaipu_dynamics::event::Event;
use itaipu_dynamics::synthetic::{synthesize, PmuNoise, VoltageProfile};

fn event() -> Event {
    let profile = VoltageProfile {
        duration_s: 3.0,
        ..VoltageProfile::default()
    };
    synthesize(
        "dip",
        &base_unit(),
        &profile,
        1000.0,
        &PmuNoise::typical(1),
        &Default::default(),
    )
    .unwrap()
}

#[test]
fn no_particle_is_a_setup_error_of_fit_and_diagnose() {
    let unit = base_unit();
    let ev = event();
    let text = "[calibration]\n[[calibration.stage]]\nname = \"gen\"\n\
                free = [ { param = \"machine.h\", min = 2.0, max = 8.0 } ]\n";
    let spec = CalibSpec::parse(text, Path::new("spec.toml")).unwrap();
    let opts = FitOptions {
        particles: 0,
        pso_iterations: 2,
        lbfgs_iterations: 1,
        ..FitOptions::from_spec(&spec)
    };
    match fit(&unit, &spec, std::slice::from_ref(&ev), &[], &opts, &Silent) {
        Err(FitError::Setup(msg)) => assert!(msg.contains("particles"), "{msg}"),
        other => panic!("{:?}", other.map(|r| r.unit.name)),
    }
    // Without a swarm, no particle is needed.
    let opts = FitOptions {
        pso_iterations: 0,
        ..opts
    };
    assert!(fit(&unit, &spec, std::slice::from_ref(&ev), &[], &opts, &Silent).is_ok());

    let opts = DiagnoseOptions {
        causes: vec!["terminal_load".into()],
        particles: 0,
        ..Default::default()
    };
    match diagnose(&unit, std::slice::from_ref(&ev), &[], &opts, &Silent) {
        Err(DiagnoseError::Setup(msg)) => assert!(msg.contains("particles"), "{msg}"),
        Err(e) => panic!("{e:?}"),
        Ok(_) => panic!("diagnosed with no particle"),
    }
}

/// The swarm's hand-over to the local method: `local_starts` below 1 is a spec error naming the
/// field; `local_starts` and `joint_iterations` reach the fit's options, with their defaults
/// when unset (one start; the joint pass's swarm as long as the stages'); a user's
/// `--pso-iterations` sets the stages' swarms and the joint pass's alike.
#[test]
fn local_starts_and_the_joint_swarm_come_from_the_spec() {
    let head = "[calibration]\n[calibration.pso]\n";
    let stage = "[[calibration.stage]]\nname = \"gen\"\n\
                 free = [ { param = \"machine.h\", min = 2.0, max = 8.0 } ]\n";
    let bad = format!("{head}local_starts = 0\n{stage}");
    let err = CalibSpec::parse(&bad, Path::new("spec.toml")).unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("calibration.pso.local_starts") && text.contains("spec.toml"),
        "{text}"
    );

    let given = format!("{head}local_starts = 2\njoint_iterations = 7\niterations = 5\n{stage}");
    let opts = FitOptions::from_spec(&CalibSpec::parse(&given, Path::new("s.toml")).unwrap());
    assert_eq!(
        (
            opts.local_starts,
            opts.joint_iterations(),
            opts.pso_iterations
        ),
        (2, 7, 5)
    );
    // The joint pass runs its own swarm budget and hands its best alone to the local method.
    let joint = opts.joint_pass();
    assert_eq!((joint.pso_iterations, joint.local_starts), (7, 1));
    let unset = format!("{head}{stage}");
    let opts = FitOptions::from_spec(&CalibSpec::parse(&unset, Path::new("s.toml")).unwrap());
    let d = itaipu_calib::spec::DEFAULT_PSO_ITERATIONS;
    assert_eq!(
        (
            opts.local_starts,
            opts.joint_iterations(),
            opts.pso_iterations
        ),
        (1, d, d)
    );
    let stages_only = format!(
        "{head}iterations = 9
{stage}"
    );
    let opts = FitOptions::from_spec(&CalibSpec::parse(&stages_only, Path::new("s.toml")).unwrap());
    assert_eq!((opts.joint_iterations(), opts.pso_iterations), (9, 9));

    let mut opts = FitOptions::from_spec(&CalibSpec::parse(&given, Path::new("s.toml")).unwrap());
    let request = itaipu_calib::request::FitRequest {
        search: itaipu_calib::request::Search {
            pso_iterations: Some(3),
            ..Default::default()
        },
        ..Default::default()
    };
    request.apply(&mut opts).unwrap();
    assert_eq!((opts.pso_iterations, opts.joint_iterations()), (3, 3));
}
