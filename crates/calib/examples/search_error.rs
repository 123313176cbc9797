//! The searches' integrator against the accurate one on every practice record (issue 28): what a
//! swarm ranks is a candidate's χ² on `problem::search_integrator`, so its error must move χ²
//! far less than the differences the search acts on.
//!
//! `cargo run --release -p itaipu-calib --example search_error [ROOT…]` (default: both practice
//! folders beside the checkout; seconds). For each record's nominal unit, played back as a user's
//! record is (smoothed at the default 4 Hz): the largest error of P and Q at the window's samples
//! in units of the record's own noise (σ from `EventData::noise_variances`, the robust estimate
//! the reports use), the χ² the error adds or removes (`Δχ²`, the weighted sum of squares on the
//! search integrator less the accurate one's), and the step attempts per sample at rtol 1e-4
//! (the search's) and 1e-5 (its tolerance before stop 57). Answer keys are not read.

use std::path::PathBuf;

use itaipu_calib::practice::{case_dirs, PracticeCase};
use itaipu_calib::problem::{accurate_integrator, search_integrator, EventData};
use itaipu_dynamics::integrate::{Dopri5Options, Method};
use itaipu_dynamics::simulate::{run_playback, simulate_pq, SimOptions};

fn main() {
    let args: Vec<PathBuf> = std::env::args().skip(1).map(PathBuf::from).collect();
    let roots = if args.is_empty() {
        let here = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared");
        vec![here.join("practice"), here.join("practice2")]
    } else {
        args
    };
    let before = SimOptions {
        method: Method::Dopri5(Dopri5Options {
            rtol: 1e-5,
            atol: 1e-6,
            ..Dopri5Options::search()
        }),
    };
    println!(
        "{:<5} {:>8} {:>9} {:>10} {:>10} {:>10}",
        "case", "err/σ", "Δχ²", "Δχ²/χ²", "steps 1e-4", "steps 1e-5"
    );
    let (mut worst_err, mut worst_chi2) = (0.0f64, 0.0f64);
    let mut ratios: Vec<f64> = vec![];
    for root in &roots {
        for dir in case_dirs(root).unwrap_or_else(|e| panic!("{e}")) {
            let name = dir.file_name().unwrap().to_string_lossy().to_string();
            let case = PracticeCase::load(&dir).unwrap_or_else(|e| panic!("{e}"));
            let data = EventData::new(&case.event, None, None).unwrap_or_else(|e| panic!("{e}"));
            let (vp, vq) = data.noise_variances();
            let run = |o: &SimOptions| {
                simulate_pq(&mut case.unit.clone(), &data.prepared, o)
                    .unwrap_or_else(|e| panic!("{name}: {e}"))
            };
            let ((pa, qa), (ps, qs)) = (run(&accurate_integrator()), run(&search_integrator()));
            let (mut err, mut chi2, mut chi2_a) = (0.0f64, 0.0, 0.0);
            for k in (0..pa.len()).filter(|&k| data.in_window[k]) {
                err = err
                    .max((ps[k] - pa[k]).abs() / vp.sqrt())
                    .max((qs[k] - qa[k]).abs() / vq.sqrt());
                let sq = |p: f64, q: f64| {
                    (p - data.p_meas[k]).powi(2) / vp + (q - data.q_meas[k]).powi(2) / vq
                };
                chi2 += sq(ps[k], qs[k]) - sq(pa[k], qa[k]);
                chi2_a += sq(pa[k], qa[k]);
            }
            let samples = data.prepared.input.time_s.len() as f64;
            let per_sample = |o: &SimOptions| {
                let s = run_playback(&mut case.unit.clone(), &data.prepared, o, |_, _, _| {})
                    .unwrap_or_else(|e| panic!("{name}: {e}"));
                (s.steps_accepted + s.steps_rejected) as f64 / samples
            };
            let (now, then) = (per_sample(&search_integrator()), per_sample(&before));
            let rel = chi2 / chi2_a;
            println!("{name:<5} {err:>8.4} {chi2:>9.3} {rel:>10.1e} {now:>10.2} {then:>10.2}");
            worst_err = worst_err.max(err);
            worst_chi2 = worst_chi2.max(rel.abs());
            ratios.push(now / then);
        }
    }
    ratios.sort_by(f64::total_cmp);
    println!(
        "{} records: largest error {worst_err:.4} σ, largest |Δχ²|/χ² {worst_chi2:.1e}; steps at rtol \
         1e-4 over 1e-5: median {:.2}, range {:.2}-{:.2}",
        ratios.len(),
        ratios[ratios.len() / 2],
        ratios[0],
        ratios[ratios.len() - 1]
    );
}
