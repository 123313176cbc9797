//! The practice protocol on the bundled cases (`data/practice/`, events made by an independent
//! implementation): the nominal model is the unit, one spec frees the same 20 parameters on
//! every case, the default staged fit must reach the answer key's floor, and the key is read
//! only to score. The whole set: `cargo run --release -p itaipu-calib --example practice`.

use std::path::PathBuf;

use itaipu_calib::fit::{fit, fitness, FitOptions, Silent};
use itaipu_calib::practice::{
    practice_spec, truth_j, AnswerKey, PracticeCase, FREE, RELATIVE_BOUNDS,
};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/practice")
}

fn case(name: &str) -> PracticeCase {
    PracticeCase::load(&root().join("cases").join(name)).unwrap()
}

#[test]
fn the_one_spec_frees_the_twenty_parameters_within_the_same_relative_bounds() {
    let c = case("p01");
    let spec = practice_spec(&c.unit).unwrap();
    let names: Vec<&str> = spec.stages.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, ["gen", "avr", "pss", "tg"]);
    let free: Vec<_> = spec
        .stages
        .iter()
        .flat_map(|s| s.free.iter())
        .filter(|f| !f.param.ends_with("_offset"))
        .collect();
    assert_eq!(free.len(), FREE.len());
    for f in &free {
        let r = c.unit.param(&f.param).unwrap();
        let x0 = c.unit.get(r);
        assert!(
            (f.min - RELATIVE_BOUNDS.0 * x0).abs() < 1e-12 * x0
                && (f.max - RELATIVE_BOUNDS.1 * x0).abs() < 1e-12 * x0,
            "{}: [{}, {}] for nominal {x0}",
            f.param,
            f.min,
            f.max
        );
    }
    // The two set-point offsets are nuisance parameters of their stages; X''q follows X''d.
    let offsets: Vec<&str> = spec
        .stages
        .iter()
        .flat_map(|s| s.free.iter())
        .filter(|f| f.param.ends_with("_offset"))
        .map(|f| f.param.as_str())
        .collect();
    assert_eq!(offsets, ["exciter.v_ref_offset", "governor.n_ref_offset"]);
    assert_eq!(
        spec.stage("gen")
            .unwrap()
            .tie
            .get("machine.x_q_pp")
            .map(String::as_str),
        Some("machine.x_d_pp")
    );
    // The nominal model, not the truth: the key's wrong parameters differ from the unit.
    let key = AnswerKey::read(&root(), "p01").unwrap();
    for (p, nominal, truth) in &key.nominal_errors {
        let v = c.unit.get(c.unit.param(p).unwrap());
        assert_eq!(v, *nominal, "{p}");
        assert!((v - truth).abs() > 0.1 * truth.abs(), "{p}");
    }
}

/// The one spec says `channels = "recorded"` in every stage and the joint pass. Resolved on a
/// record with the field channels, each pass compares them with P and Q, each weighted by its
/// inverse noise variance against P's and Q's (σ 0.002 pu; E_fd 0.01, X_ad I_fd 0.005: weights
/// 0.04 and 0.16); resolved on a record without them, the passes keep the P+Q objective.
#[test]
fn the_one_spec_compares_the_recorded_field_channels_by_their_noise() {
    use itaipu_calib::spec::Channels;
    use itaipu_dynamics::event::{Event, Record, Window};
    use itaipu_dynamics::rng::Normal;
    let c = case("p01");
    let spec = practice_spec(&c.unit).unwrap();
    assert!(spec.compares_recorded());
    let plain = spec.resolve_recorded(&[&c.event], &[]);
    assert!(
        plain.stages.iter().all(|s| s.compare().is_none()) && plain.joint_compare().is_none(),
        "a record without the field is fitted on P and Q as before"
    );

    // 20 s at 60 samples/s, the first 10 s the initialisation window: each noise floor from
    // 600 samples (±3.5 %), a ratio of two variances within ±10 % (1 σ).
    let n = 1200;
    let mut rng = Normal::new(11);
    let mut noisy =
        |level: f64, s: f64| -> Vec<f64> { (0..n).map(|_| level + s * rng.sample()).collect() };
    let rec = Record {
        time_s: (0..n).map(|i| i as f64 / 60.0).collect(),
        v_mag_pu: noisy(1.0, 5e-4),
        v_ang_rad: noisy(0.2, 5e-4),
        p_pu: noisy(0.6, 0.002),
        q_pu: noisy(0.1, 0.002),
        freq_hz: None,
        efd_pu: Some(noisy(1.8, 0.01)),
        ifd_pu: Some(noisy(1.6, 0.005)),
    };
    let ev = Event::from_record(
        "field",
        rec,
        1000.0,
        60.0,
        Some(Window::new(0.0, 10.0)),
        None,
    )
    .unwrap();
    let resolved = spec.resolve_recorded(&[&ev], &[]);
    assert!(!resolved.compares_recorded());
    let joint = resolved
        .joint
        .as_ref()
        .expect("the joint pass compares them too");
    let compared = resolved
        .stages
        .iter()
        .map(|s| s.channels.as_ref())
        .chain([joint.channels.as_ref()]);
    for ch in compared {
        let Some(Channels::Weights(ch)) = ch else {
            panic!("every pass compares weighted channels: {ch:?}")
        };
        let w = |k: &str| ch.get(k).copied().unwrap_or(f64::NAN);
        assert_eq!((w("p"), w("q")), (1.0, 1.0), "{ch:?}");
        assert!((w("efd") / 0.04 - 1.0).abs() < 0.25, "{ch:?}");
        assert!((w("ifd") / 0.16 - 1.0).abs() < 0.25, "{ch:?}");
    }
    // A held-out event without the field: no pass compares it (it could not be scored there).
    let partial = spec.resolve_recorded(&[&ev], &[&c.event]);
    assert!(partial.stages.iter().all(|s| s.compare().is_none()));
}

#[test]
fn a_nominal_file_with_an_unknown_parameter_is_refused_by_name() {
    let dir = std::env::temp_dir().join(format!("itaipu-practice-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let src = root().join("cases/p01");
    std::fs::copy(src.join("data.csv"), dir.join("data.csv")).unwrap();
    let text = std::fs::read_to_string(src.join("nominal.json")).unwrap();
    std::fs::write(
        dir.join("nominal.json"),
        text.replacen("\"TE\":", "\"TEX\":", 1),
    )
    .unwrap();
    let e = PracticeCase::load(&dir)
        .err()
        .expect("an unknown key must be refused");
    assert!(
        e.to_string().contains("exciter.TEX") && e.to_string().contains("nominal.json"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn the_engine_reproduces_the_independent_floor_with_the_true_parameters() {
    // The true unit (from the key) with only the two set-point offsets fitted gives the key's
    // floor J: the playback, the models and the objective agree with the independent
    // implementation.
    let c = case("p01");
    let j = truth_j(&root(), &c).unwrap();
    let key = AnswerKey::read(&root(), "p01").unwrap();
    assert!(
        (j / key.floor_j - 1.0).abs() < 0.02,
        "J {j} against the key's floor {}",
        key.floor_j
    );
}

/// A data family of another unit (`data/families/other_unit`: GENSAL + ESST1A + IEEEST + HYGOV,
/// 50 Hz, 300 MVA on a 100 MVA base, made by an implementation that is not this engine): the
/// runner reads its nominal files by the models' own PSS/E names, the one spec frees that
/// unit's 20 parameters (ESST1A's KA, TC, TB, TA and IEEEST's KS, T1, T3 where the practice unit
/// has SEXS's and STAB3's), and the engine reproduces the key's floor from the key's own base.
#[test]
fn another_units_family_gets_its_own_twenty_parameters_and_floor() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/families/other_unit");
    let c = PracticeCase::load(&root.join("cases/o01")).unwrap();
    assert_eq!((c.unit.machine_mva, c.unit.nominal_hz), (300.0, 50.0));
    let spec = practice_spec(&c.unit).unwrap();
    let free: Vec<&str> = spec
        .stages
        .iter()
        .flat_map(|s| s.free.iter())
        .map(|f| f.param.as_str())
        .filter(|p| !p.ends_with("_offset"))
        .collect();
    assert_eq!(free.len(), 20, "{free:?}");
    for p in [
        "machine.x_d",
        "exciter.k_a",
        "exciter.t_c",
        "exciter.t_b",
        "exciter.t_a",
        "pss.ks",
        "pss.t1",
        "pss.t3",
        "governor.t_w",
    ] {
        assert!(free.contains(&p), "{p} not in {free:?}");
    }
    let key = AnswerKey::read(&root, "o01").unwrap();
    assert_eq!(key.cause, "none");
    for (p, nominal, _) in &key.nominal_errors {
        assert_eq!(c.unit.get(c.unit.param(p).unwrap()), *nominal, "{p}");
    }
    let j = truth_j(&root, &c).unwrap();
    assert!(
        (j / key.floor_j - 1.0).abs() < 0.02,
        "J {j} against the key's floor {}",
        key.floor_j
    );
}

#[test]
fn the_default_staged_fit_reaches_the_floor_with_every_uncertain_parameter_free() {
    let c = case("p01");
    let spec = practice_spec(&c.unit).unwrap();
    let opts = FitOptions::from_spec(&spec);
    let r = fit(
        &c.unit,
        &spec,
        std::slice::from_ref(&c.event),
        &[],
        &opts,
        &Silent,
    )
    .unwrap();
    let j_start = fitness(&c.unit, &c.event, false).unwrap().0.j_pq;
    let j = fitness(&r.unit, &c.event, false).unwrap().0.j_pq;
    // Scoring only now.
    let key = AnswerKey::read(&root(), "p01").unwrap();
    assert!(
        j <= 1.1 * key.floor_j,
        "J {j} after the fit, the key's floor {} (start {j_start})",
        key.floor_j
    );
    // The physical relations hold in the calibrated machine.
    let g = |p: &str| r.unit.get(r.unit.param(p).unwrap());
    assert!(g("machine.x_d") > g("machine.x_d_prime"));
    assert!(g("machine.x_d_prime") > g("machine.x_d_pp"));
    assert!(g("machine.x_d_pp") > g("machine.x_l"));
    assert!(g("machine.t_d0_prime") > g("machine.t_d0_pp"));
    assert_eq!(g("machine.x_q_pp"), g("machine.x_d_pp"));
    // The joint pass is reported, with its swarm and local phases.
    let joint = r.report.stages.last().unwrap();
    assert_eq!(joint.stage, "joint");
    assert!(joint.phases.iter().any(|p| p.phase == "pso"));
    assert!(joint
        .phases
        .iter()
        .any(|p| p.phase.starts_with("levenberg-marquardt")));
}

/// The protocol through the diagnosis: the default staged fit, then `diagnose` re-fitting the
/// whole calibrated set with its prior (as `cargo run --example practice` does); the verdict and
/// the candidates' report, the key read only to score.
fn fit_and_diagnose(name: &str) -> (itaipu_calib::diagnose::Diagnosis, String) {
    let (_, d) = itaipu_calib::practice::fit_and_diagnose(&case(name), &Silent).unwrap();
    let hidden = AnswerKey::read(&root(), name).unwrap().cause;
    (d.report, hidden)
}

#[test]
fn a_terminal_load_the_calibration_absorbed_is_named_on_held_out_data() {
    // p02: a constant-impedance load at the terminals acts in the 0.11 s dip. The calibration
    // absorbed it by bending the governor and X_d; the extension gains on the fitted blocks, and
    // data the re-fit did not see confirm it: the interleaved held-out blocks (aligned on the
    // record's onset, so that the dip is fitted and its recovery held out), or else the
    // held-out 3 s segments.
    let (report, hidden) = fit_and_diagnose("p02");
    assert_eq!(hidden, "terminal_load");
    assert_eq!(report.verdict.cause, hidden, "{}", report.verdict.statement);
    let c = &report.candidates[0];
    assert_eq!(c.cause, "terminal_load");
    let g = c.gains.as_ref().unwrap();
    let opts = itaipu_calib::diagnose::DiagnoseOptions::default();
    let blocks = g.held_drop >= opts.min_held_drop;
    let segments = g.held_drop_segments.is_some_and(|d| d >= 0.01);
    assert!(
        blocks || segments,
        "named without held-out confirmation: {g:?}"
    );
    assert!(
        g.fit_drop >= opts.min_fit_drop && g.delta_bic > opts.bic_threshold,
        "{g:?}"
    );
}

#[test]
fn a_clean_practice_record_is_diagnosed_none() {
    let (report, hidden) = fit_and_diagnose("p01");
    assert_eq!(hidden, "none");
    assert_eq!(report.verdict.cause, "none", "{}", report.verdict.statement);
}

/// A clean case of the second set (`practice2`, other seeds): a 10 s fault record. Nothing may
/// be named, and no candidate may pass its test (an `inconclusive` would be an alarm too).
#[test]
fn a_clean_record_of_the_second_set_is_diagnosed_none() {
    let (report, hidden) = fit_and_diagnose("q03");
    assert_eq!(hidden, "none");
    assert_eq!(report.verdict.cause, "none", "{}", report.verdict.statement);
    assert!(report.verdict.grade.is_none() && report.verdict.competing.is_empty());
    assert!(
        report.candidates.iter().all(|c| !c.significant),
        "{:?}",
        report
            .candidates
            .iter()
            .map(|c| (&c.cause, c.significant))
            .collect::<Vec<_>>()
    );
}

/// The diagnosis of a calibrated unit bundled in `data/practice/swarm50/` (the default fit of
/// the case with its swarms halved: it converged less), as the practice runner diagnoses it.
/// The diagnosis, as the practice runner makes it, of the calibrated unit `folder/name.toml`
/// (bundled) on the case's record; with the case's answer key, for scoring only. Without the
/// look-alikes outside the catalog. The rule: a look-alike is scored after every catalog cause
/// and is never named, so it can take a name away but cannot change a named cause's re-fit,
/// whose key these tests read; whether it takes a right name away is a property of the
/// verdict (its unit test in `verdict.rs`) and of the data, measured on every named record of
/// both practice sets by the runner, not here. The protocol with them is `fit_and_diagnose`.
fn diagnose_bundled_unit(
    folder: &str,
    name: &str,
) -> (itaipu_calib::diagnose::DiagnoseResult, AnswerKey) {
    use itaipu_calib::practice::diagnose_options;
    let case = case(name);
    let unit =
        itaipu_dynamics::unit_file::read_unit(&root().join(folder).join(format!("{name}.toml")))
            .unwrap();
    let spec = practice_spec(&case.unit).unwrap();
    let opts = FitOptions::from_spec(&spec);
    let dopts = itaipu_calib::diagnose::DiagnoseOptions {
        look_alikes: false,
        ..diagnose_options(&case, &spec, &opts.stages, &unit)
    };
    let d = itaipu_calib::diagnose::diagnose(
        &unit,
        std::slice::from_ref(&case.event),
        &[],
        &dopts,
        &Silent,
    )
    .unwrap();
    (d, AnswerKey::read(&root(), name).unwrap())
}

/// A named cause must not depend on how far the calibration converged: the bundled units of
/// `swarm50/` were fit with half the swarm and each bent its values differently from the default
/// fit. An OEL must still be named with its pickup within the key's 5 % and no rival passing its
/// test; a governor deadband may be missed (`none`), or left `unexplained` with its residual
/// placed where a governor acts (P, after the event's first seconds), but never given another
/// cause's name. Without a floor on the fitted χ² drop, p09's torsional mode passes its test
/// (1.9 % fitted, 2.7 % held out) at the lower edge of its band, asking for a slower effect than a
/// shaft mode: it must be refused its name, not named.
#[test]
fn a_less_converged_calibration_names_no_wrong_cause() {
    let (d, key) = diagnose_bundled_unit("swarm50", "p13");
    let report = &d.report;
    assert_eq!(key.cause, "oel");
    // Named, with the OEL's pickup read in the extended unit within the key's 5 %.
    assert_named_with_its_key("p13", &d, &key);
    let governor = candidate(report, "governor");
    assert!(!governor.significant, "{}", governor.note);

    let (d, key) = diagnose_bundled_unit("swarm50", "p09");
    let report = &d.report;
    assert_eq!(key.cause, "governor");
    let verdict = &report.verdict;
    assert!(
        ["none", "governor", "unexplained"].contains(&verdict.cause.as_str()),
        "{}",
        verdict.statement
    );
    if verdict.cause == "unexplained" {
        let (signal, window, start, _) = verdict.where_.as_ref().unwrap();
        assert_eq!((signal.as_str(), window.as_str()), ("P", "tail"));
        assert!(*start > case("p09").event.init.end_s + 1.0, "{start}");
    }
}

/// A skew belongs to the PMU, not to the unit: q05's default calibration absorbed part of its
/// 26.9 ms by bending the machine's q axis (X_q 3.5 prior spreads off), and the delay re-fitted
/// from those values stopped at 8.6 ms. The skew is named and its delay must be read within half
/// a sample interval of the key (the practice scoring), whichever start the re-fit keeps.
#[test]
fn a_skew_the_calibration_absorbed_is_read_at_its_whole_delay() {
    let (d, key) = diagnose_bundled_unit("default_fit", "q05");
    assert_eq!(key.cause, "measurement_skew");
    assert_named_with_its_key("q05", &d, &key);
}

/// A constant exciter ceiling that a calibration on P and Q alone absorbs (practice2 q11: it
/// bends X_d by 1.9 prior spreads and the exciter's gain, leaving the simulated field 7 (E_fd)
/// and 31 (X_ad I_fd) noise widths off the recorded one, and the diagnosis on P and Q finds
/// nothing), found through the recorded field: the default fit compares E_fd and X_ad I_fd
/// (`default_fit/q11.toml`, the practice spec on this record), and so does the diagnosis, which
/// names `exciter_limit` with E_MAX within the key's 5 %.
#[test]
fn a_ceiling_the_calibration_absorbed_is_named_from_the_recorded_field() {
    let (d, key) = diagnose_bundled_unit("default_fit", "q11");
    assert_eq!(key.cause, "exciter_limit");
    assert_eq!(d.report.noise.playback, "phasor: P, Q, Efd, Ifd");
    assert_named_with_its_key("q11", &d, &key);
}

/// The diagnosis names the key's cause, and its key parameter, read in the extended unit, is
/// within the key's tolerance (the practice runner's scoring).
fn assert_named_with_its_key(
    case: &str,
    d: &itaipu_calib::diagnose::DiagnoseResult,
    key: &AnswerKey,
) {
    let report = &d.report;
    assert_eq!(
        report.verdict.cause, key.cause,
        "{}",
        report.verdict.statement
    );
    let scored = itaipu_calib::practice::score(
        case,
        key,
        d.extended_unit.as_ref().unwrap(),
        0.0,
        0.0,
        Some((report.verdict.cause.as_str(), d.extended_unit.as_ref(), 0.0)),
    );
    let (what, truth, found, within) = scored.key.unwrap();
    assert!(within, "{case}: {what}: {found:?} for {truth}");
}

/// The report of the cause `id` among a diagnosis' candidates.
fn candidate<'a>(
    report: &'a itaipu_calib::diagnose::Diagnosis,
    id: &str,
) -> &'a itaipu_calib::diagnose::CandidateReport {
    report.candidates.iter().find(|c| c.cause == id).unwrap()
}

/// A fit whose phasor stages compare P and Q alone on a record that holds the field (q11) is
/// warned, per stage, with `channels = "recorded"` as the fix; the one spec, which says it, is
/// not; a record without the field channels is not.
#[test]
fn a_fit_that_leaves_the_recorded_field_out_is_warned() {
    use itaipu_calib::job::{prepare_fit, FitInputs};
    use itaipu_calib::request::FitRequest;
    use itaipu_calib::spec::CalibSpec;
    let inputs = |c: &PracticeCase, spec: CalibSpec| FitInputs {
        unit: c.unit.clone(),
        unit_path: None,
        spec,
        spec_path: Some(PathBuf::from("cal.toml")),
        spec_text: None,
        events: vec![c.event.clone()],
        held_out: vec![],
    };
    let kinds = |c: &PracticeCase, spec: CalibSpec| -> Vec<String> {
        let (_, w) = prepare_fit(&inputs(c, spec), &FitRequest::default()).unwrap();
        w.into_iter()
            .filter(|f| f.kind == "field_not_compared")
            .map(|f| format!("{}: {} ({})", f.column, f.message, f.fix))
            .collect()
    };
    let pq_only = |c: &PracticeCase| {
        let text = format!(
            "[calibration]\n[[calibration.stage]]\nname = \"gen\"\nfree = [ {{ param = \"machine.x_d\", min = {}, max = {} }} ]\n",
            0.5 * c.unit.get(c.unit.param("machine.x_d").unwrap()),
            2.0 * c.unit.get(c.unit.param("machine.x_d").unwrap()),
        );
        CalibSpec::parse(&text, std::path::Path::new("cal.toml")).unwrap()
    };
    let q11 = case("q11");
    let w = kinds(&q11, pq_only(&q11));
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(
        w[0].contains("calibration.stage[0] (stage gen)")
            && w[0].contains("efd, ifd")
            && w[0].contains("channels = \"recorded\""),
        "{w:?}"
    );
    assert!(kinds(&q11, practice_spec(&q11.unit).unwrap()).is_empty());
    let p01 = case("p01");
    assert!(kinds(&p01, pq_only(&p01)).is_empty());
}
