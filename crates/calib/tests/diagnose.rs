//! Diagnosis on synthetic events with a hidden cause (issue 4), with the protocol of
//! `itaipu_calib::diagnose::trial`: the cause is hidden in the true unit (the catalog's own
//! extension, `catalog::hide`), a 20 s PMU event is made from it (60 samples/s, 0.002 pu noise and
//! 0.0014 pu quantisation on P and Q, 1e-4 noise on the voltage phasor, fixed seeds), a nominal
//! unit 25-50 % off the truth in H, X'_d, K_A and T_E is calibrated on the event first, and
//! `diagnose` then runs the whole catalog on the calibrated unit.
//!
//! Requirement: the hidden cause is named first (the verdict), with its key parameter recovered
//! (mode frequency within 5 %, PMU delay within half a sample, limits within 5 %); on clean
//! events the verdict is `none`. The hit and false-alarm rates over a larger sweep are measured
//! by `examples/diagnose_sweep.rs`.

use itaipu_calib::bounds::FreeBound;
use itaipu_calib::diagnose::catalog::{self, Context};
use itaipu_calib::diagnose::trial::{base_unit, run, scenario};
use itaipu_calib::diagnose::{diagnose, DiagnoseError, DiagnoseOptions};
use itaipu_calib::fit::Silent;
use itaipu_dynamics::synthetic::EventKind;

/// The noise-fitting gain a diagnosis nets out is the mean of its surrogate draws'
/// (`DiagnoseOptions::null_draws`), the first draw being the one-draw diagnosis's own: a hidden
/// terminal load (a gain that passes, so its surrogate re-fits run), that cause alone, with one
/// draw and with three. The extension's own re-fit does not depend on the draws.
#[test]
fn the_noise_fitting_gain_netted_out_is_the_mean_of_its_draws() {
    let t = scenario("terminal_load", 101, None);
    let gains = |draws: usize| {
        let o = run(
            &t,
            &DiagnoseOptions {
                seed: 101,
                look_alikes: false,
                causes: vec!["terminal_load".into()],
                null_draws: draws,
                ..Default::default()
            },
        )
        .unwrap_or_else(|e| panic!("{draws} draws: {e}"));
        o.report
            .candidates
            .into_iter()
            .find(|c| c.cause == "terminal_load")
            .and_then(|c| c.gains)
            .expect("the terminal load's gains")
    };
    let (one, three) = (gains(1), gains(3));
    println!(
        "one draw {:?}, three {:?}",
        one.null_gains_fit, three.null_gains_fit
    );
    assert_eq!(one.null_gains_fit.len(), 1);
    assert_eq!(three.null_gains_fit.len(), 3);
    assert_eq!(one.null_gain_fit, one.null_gains_fit[0]);
    assert_eq!(
        three.null_gains_fit[0], one.null_gains_fit[0],
        "the first draw is the same"
    );
    let mean = three.null_gains_fit.iter().sum::<f64>() / 3.0;
    assert!((three.null_gain_fit - mean).abs() <= 1e-12 * mean.max(1.0));
    // The held-out samples' gain per draw, the same draws: its mean is the one netted out.
    assert_eq!(one.null_gains_held.len(), 1);
    assert_eq!(three.null_gains_held.len(), 3);
    assert_eq!(one.null_gain_held, one.null_gains_held[0]);
    assert_eq!(three.null_gains_held[0], one.null_gains_held[0]);
    let mean_held = three.null_gains_held.iter().sum::<f64>() / 3.0;
    assert!((three.null_gain_held - mean_held).abs() <= 1e-12 * mean_held.max(1.0));
    assert!(
        three.null_gains_fit[1..]
            .iter()
            .any(|g| *g != three.null_gains_fit[0]),
        "the draws are other records"
    );
    assert_eq!(one.chi2_fit_ext, three.chi2_fit_ext);
    assert_eq!(one.chi2_fit_base, three.chi2_fit_base);
}

#[test]
fn every_extension_of_the_catalog_starts_in_steady_state_on_the_base_unit() {
    // The extended units the diagnosis fits must initialise at a real operating point.
    let base = base_unit();
    let t = scenario("none", 1, None);
    let (_, ev) = itaipu_calib::diagnose::trial::truth_and_event(&t).unwrap();
    let ctx = itaipu_calib::diagnose::context(&base, &ev).unwrap();
    let every_variant = catalog::CAUSES.iter().map(|c| c.info()).flat_map(|c| {
        let all =
            catalog::extend_all(c.id, &base, &ctx).unwrap_or_else(|e| panic!("{}: {e}", c.id));
        all.into_iter().map(move |x| (c, x))
    });
    for (c, ext) in every_variant {
        let tr = itaipu_dynamics::simulate::simulate(
            &ext.unit,
            &ev,
            &itaipu_dynamics::simulate::SimOptions::default(),
        )
        .unwrap_or_else(|e| panic!("{}: {e}", c.id));
        // Steady state: the first samples (pre-event) do not drift.
        let q = tr.get("q_pu").unwrap();
        assert!(
            (q[10] - q[0]).abs() < 5e-3,
            "{}: Q drifts {} -> {} before the event",
            c.id,
            q[0],
            q[10]
        );
        // Every free parameter resolves in the extended unit.
        for f in ext.extension_free.iter().chain(&ext.interacting_free) {
            ext.unit
                .param(&f.param)
                .unwrap_or_else(|e| panic!("{}: {e}", c.id));
            assert!(
                f.min < f.max && f.start.is_some_and(|s| s >= f.min && s <= f.max),
                "{}: bounds of {}",
                c.id,
                f.param
            );
        }
    }
}

#[test]
fn the_exciter_ceiling_is_tried_constant_and_fed_from_the_terminals() {
    // A SEXS unit on a dip: two structures, the second the bus-fed SEXS with the same gains,
    // each counting the choice between them as one discrete parameter.
    let base = base_unit();
    let t = scenario("none", 1, None);
    let (_, ev) = itaipu_calib::diagnose::trial::truth_and_event(&t).unwrap();
    let ctx = itaipu_calib::diagnose::context(&base, &ev).unwrap();
    let all = catalog::extend_all("exciter_limit", &base, &ctx).unwrap();
    assert_eq!(all.len(), 2);
    assert!(all.iter().all(|x| x.discrete_params == 1));
    let exc = |x: &catalog::Extension| x.unit.block("exciter").unwrap().model().to_string();
    assert_eq!(exc(&all[0]), "SEXS");
    assert_eq!(exc(&all[1]), "SEXS_bus_fed");
    for p in ["k", "te", "ta_tb", "tb"] {
        let path = format!("exciter.{p}");
        let v = |u: &itaipu_dynamics::unit::Unit| u.get(u.param(&path).unwrap());
        assert_eq!(v(&all[1].unit), v(&base), "{path}");
    }
    let free: Vec<&str> = all[1]
        .extension_free
        .iter()
        .map(|f| f.param.as_str())
        .collect();
    assert_eq!(free, ["exciter.vr_max", "exciter.k_c", "exciter.vr_min"]);
    // A cause with one structure has one extension and no discrete parameter for it.
    let one = catalog::extend_all("saturation", &base, &ctx).unwrap();
    assert_eq!((one.len(), one[0].discrete_params), (1, 0));
}

#[test]
fn hide_rejects_unknown_causes_and_parameters() {
    let base = base_unit();
    let ctx = Context {
        efd0: Some(1.5),
        xadifd0: Some(1.5),
        rate_hz: 60.0,
        ..Default::default()
    };
    let err = |r: Result<(itaipu_dynamics::unit::Unit, catalog::Extension), catalog::HideError>| {
        r.err().expect("must be refused").to_string()
    };
    assert!(err(catalog::hide(
        "no_such_cause",
        &base,
        &ctx,
        &Default::default()
    ))
    .contains("unknown cause"));
    let bad = [("shaft.no_such_param".to_string(), 1.0)]
        .into_iter()
        .collect();
    assert!(err(catalog::hide("torsional_mode", &base, &ctx, &bad)).contains("unknown parameter"));
    let ok = [("shaft.f_torsion_hz".to_string(), 7.5)]
        .into_iter()
        .collect();
    let u = catalog::hide("torsional_mode", &base, &ctx, &ok)
        .unwrap_or_else(|e| panic!("{e}"))
        .0;
    // A tied parameter is refused with the one to set instead.
    let tied = [("shaft.h_generator".to_string(), 3.0)]
        .into_iter()
        .collect();
    assert!(
        err(catalog::hide("torsional_mode", &base, &ctx, &tied)).contains("set machine.h instead")
    );
    assert_eq!(u.get(u.param("shaft.f_torsion_hz").unwrap()), 7.5);
    // The tie holds: the shaft's generator mass is the machine's inertia.
    assert_eq!(
        u.get(u.param("shaft.h_generator").unwrap()),
        u.get(u.param("machine.h").unwrap())
    );
}

#[test]
fn bad_requests_are_setup_errors() {
    let base = base_unit();
    let (_, ev) =
        itaipu_calib::diagnose::trial::truth_and_event(&scenario("none", 3, None)).unwrap();
    let err = |opts: DiagnoseOptions| match diagnose(
        &base,
        std::slice::from_ref(&ev),
        &[],
        &opts,
        &Silent,
    ) {
        Err(e) => e,
        Ok(_) => panic!("accepted"),
    };
    let e = err(DiagnoseOptions {
        causes: vec!["flux_capacitor".into()],
        ..Default::default()
    });
    assert!(
        matches!(e, DiagnoseError::Setup(_)) && e.to_string().contains("flux_capacitor"),
        "{e}"
    );
    let e = err(DiagnoseOptions {
        refit: vec![FreeBound {
            param: "machine.h".into(),
            min: 5.0,
            max: 2.0,
            start: Some(3.0),
            spread: None,
            scan: 0,
            polish_only: true,
            prior: None,
        }],
        ..Default::default()
    });
    assert!(e.to_string().contains("upside down"), "{e}");
    let e = err(DiagnoseOptions {
        refit: vec![FreeBound {
            param: "machine.h_bar".into(),
            min: 1.0,
            max: 2.0,
            start: Some(1.0),
            spread: None,
            scan: 0,
            polish_only: true,
            prior: None,
        }],
        ..Default::default()
    });
    assert!(e.to_string().contains("machine.h_bar"), "{e}");
    assert!(matches!(
        diagnose(&base, &[], &[], &DiagnoseOptions::default(), &Silent),
        Err(DiagnoseError::Setup(_))
    ));
}

/// One thread scores the candidates one after another, two score them side by side (each with
/// the baselines re-fitted before its batch and its own): every candidate's numbers, its
/// baseline's and its noise-fitting gain the same to the bit; and a baseline two causes of the
/// batch share re-fitted once.
#[test]
fn a_seed_gives_the_same_diagnosis_on_one_and_two_threads() {
    let t = scenario("measurement_skew", 7, None);
    let (truth, ev) = itaipu_calib::diagnose::trial::truth_and_event(&t).unwrap();
    // Diagnose the truth without its measurement block (the base unit), two causes, small budget.
    let _ = truth;
    let opts = DiagnoseOptions {
        // Saturation and the OEL re-free the same field-side parameters: one baseline.
        causes: vec![
            "measurement_skew".into(),
            "terminal_load".into(),
            "saturation".into(),
            "oel".into(),
        ],
        particles: 8,
        pso_iterations: 5,
        lbfgs_iterations: 4,
        ..Default::default()
    };
    let run_on = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            diagnose(&base_unit(), std::slice::from_ref(&ev), &[], &opts, &Silent).unwrap()
        })
    };
    let (a, b) = (run_on(1), run_on(2));
    let key = |r: &itaipu_calib::diagnose::DiagnoseResult| {
        r.report
            .candidates
            .iter()
            .map(|c| {
                (
                    c.cause.clone(),
                    c.gains.as_ref().map(|g| {
                        [
                            g.chi2_fit_ext,
                            g.chi2_fit_base,
                            g.chi2_held_base,
                            g.null_gain_fit,
                        ]
                        .map(f64::to_bits)
                    }),
                    c.parameters
                        .iter()
                        .map(|p| p.result.to_bits())
                        .collect::<Vec<_>>(),
                )
            })
            .collect::<Vec<_>>()
    };
    assert_eq!(key(&a), key(&b));
    assert_eq!(a.report.verdict.cause, "measurement_skew");
    // Each baseline re-fitted once, side by side as one after another (two causes of a batch
    // that share one do not both re-fit it).
    let baselines = |r: &itaipu_calib::diagnose::DiagnoseResult| {
        r.report
            .profile
            .iter()
            .filter(|p| p.kind == "baselines" && p.phase == "whole re-fit")
            .map(|p| p.refits)
            .sum::<usize>()
    };
    assert_eq!(baselines(&a), baselines(&b));
    let applicable = a.report.candidates.iter().filter(|c| c.applicable).count();
    assert!(
        baselines(&a) < applicable,
        "{} baselines for {applicable} causes",
        baselines(&a)
    );
}

#[test]
fn a_cancelled_diagnosis_stops_within_a_second_and_keeps_nothing() {
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::Arc;
    use std::time::{Duration, Instant};
    let base = itaipu_calib::diagnose::trial::base_unit();
    let (_, ev) =
        itaipu_calib::diagnose::trial::truth_and_event(&scenario("none", 3, None)).unwrap();
    // The whole catalog with a large budget: minutes uninterrupted.
    let cancel = Arc::new(AtomicBool::new(false));
    let opts = DiagnoseOptions {
        particles: 40,
        pso_iterations: 400,
        lbfgs_iterations: 200,
        cancel: Some(cancel.clone()),
        ..Default::default()
    };
    let flag = cancel.clone();
    let setter = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_millis(1500));
        flag.store(true, Ordering::SeqCst);
        Instant::now()
    });
    let r = diagnose(&base, std::slice::from_ref(&ev), &[], &opts, &Silent);
    let back = Instant::now();
    let set_at = setter.join().unwrap();
    assert!(
        cancel.load(Ordering::SeqCst),
        "finished before the flag was set"
    );
    let lag = back.duration_since(set_at);
    assert!(
        lag < Duration::from_secs(1),
        "stopped {lag:?} after the flag"
    );
    match r {
        Err(e @ DiagnoseError::Interrupted { .. }) => assert_eq!(e.kind(), "interrupted"),
        Err(e) => panic!("another error: {e}"),
        Ok(_) => panic!("a verdict from an interrupted run"),
    }
}

/// A cause's gains do not depend on which causes were tried before it: the baseline a cause's
/// extension found a better start for stays that cause's (the shared cache holds each baseline
/// as its own search found it). On the bundled Itaipu unit as given (large residuals: every
/// candidate's gain could pass, so every one runs its "baseline again"), three causes sharing
/// interacting parameters in both orders give the same numbers.
#[test]
fn a_causes_gains_do_not_depend_on_the_order_the_causes_are_tried() {
    let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/itaipu");
    let unit = itaipu_dynamics::unit_file::read_unit(&root.join("unit.toml")).unwrap();
    let event = itaipu_dynamics::event::Event::from_toml_file(&root.join("event.toml")).unwrap();
    let causes = ["saturation", "terminal_load", "exciter_limit"];
    let run = |order: Vec<&str>| {
        let opts = DiagnoseOptions {
            causes: order.iter().map(|s| s.to_string()).collect(),
            particles: 6,
            pso_iterations: 4,
            lbfgs_iterations: 4,
            ..Default::default()
        };
        diagnose(&unit, std::slice::from_ref(&event), &[], &opts, &Silent)
            .unwrap()
            .report
    };
    let a = run(causes.to_vec());
    let b = run(causes.iter().rev().copied().collect());
    for c in causes {
        let find = |r: &itaipu_calib::diagnose::Diagnosis| {
            r.candidates
                .iter()
                .find(|x| x.cause == c)
                .and_then(|x| x.gains.clone())
                .map(|g| (g.delta_bic, g.chi2_fit_base, g.chi2_fit_ext, g.held_drop))
        };
        assert_eq!(find(&a), find(&b), "{c}: gains differ with the order");
    }
    assert_eq!(a.verdict.cause, b.verdict.cause);
}

/// Any exciter in the diagnosis (issue 27): on units with SEXS, ST5B, IEEET1 and ESST1A (the
/// registry's typical values on the base machine), every cause of the catalog either builds its
/// extension, which starts in steady state with every free parameter resolving in its bounds, or
/// says why it does not apply; the exciter-side causes reach the exciter through the roles its
/// model declares, so each exciter takes part in `exciter_limit`. A short diagnosis of the whole
/// catalog then runs on each unit without an error.
#[test]
fn the_whole_catalog_runs_on_units_with_any_exciter() {
    use itaipu_dynamics::simulate::{simulate, SimOptions};
    use itaipu_dynamics::synthetic::{synthesize, PmuNoise, VoltageProfile};
    for model in ["SEXS", "ST5B", "IEEET1", "ESST1A"] {
        let mut unit = base_unit();
        let block = itaipu_dynamics::registry::find(model).unwrap().create();
        unit.put("exciter", block, &[])
            .unwrap_or_else(|e| panic!("{model}: {e}"));
        let profile = VoltageProfile::preset(EventKind::FaultDip, 8.0, 30.0, 3);
        let ev = synthesize(
            model,
            &unit,
            &profile,
            unit.machine_mva,
            &PmuNoise::typical(3),
            &SimOptions::default(),
        )
        .unwrap_or_else(|e| panic!("{model}: {e}"));
        let ctx = itaipu_calib::diagnose::context(&unit, &ev).unwrap();
        let mut applied = vec![];
        for c in catalog::CAUSES {
            let id = c.info().id;
            match catalog::extend_all(id, &unit, &ctx) {
                Ok(all) => {
                    for ext in &all {
                        let tr = simulate(&ext.unit, &ev, &SimOptions::default())
                            .unwrap_or_else(|e| panic!("{model} {id}: {e}"));
                        let q = tr.get("q_pu").unwrap();
                        assert!(
                            (q[10] - q[0]).abs() < 5e-3,
                            "{model} {id}: Q drifts {} -> {} before the event",
                            q[0],
                            q[10]
                        );
                        for f in ext.free() {
                            ext.unit
                                .param(&f.param)
                                .unwrap_or_else(|e| panic!("{model} {id}: {e}"));
                            assert!(
                                f.min < f.max && f.start.is_some_and(|s| s >= f.min && s <= f.max),
                                "{model} {id}: bounds of {}",
                                f.param
                            );
                        }
                    }
                    applied.push(id);
                }
                Err(catalog::CauseError::NotApplicable(why)) => {
                    assert!(
                        !why.to_string().trim().is_empty(),
                        "{model} {id}: no reason given"
                    );
                    println!("{model} {id}: not applicable: {why}");
                }
                Err(e) => panic!("{model} {id}: {e}"),
            }
        }
        println!("{model}: {applied:?}");
        assert!(
            applied.contains(&"exciter_limit"),
            "{model}: exciter_limit does not apply"
        );
        // The field-side causes re-free the exciter's gain by its role.
        let gain = catalog::exciter_roles(&unit, "exciter").gain;
        let gain = format!("exciter.{}", gain.name().unwrap());
        let sat = catalog::extend_all("saturation", &unit, &ctx).unwrap();
        assert!(
            sat[0].free().any(|f| f.param == gain),
            "{model}: saturation does not re-free {gain}"
        );
        let opts = DiagnoseOptions {
            particles: 4,
            pso_iterations: 2,
            lbfgs_iterations: 2,
            ..Default::default()
        };
        let d = diagnose(&unit, std::slice::from_ref(&ev), &[], &opts, &Silent)
            .unwrap_or_else(|e| panic!("{model}: {e}"));
        // Every catalog cause has a report (the look-alikes outside the catalog follow when
        // one was significant).
        assert_eq!(
            d.report.candidates.iter().filter(|c| !c.look_alike).count(),
            catalog::CAUSES.len()
        );
    }
}
