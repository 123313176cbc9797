//! The integrators on the full unit (GENSAE + SEXS + STAB3 + HYGOV) over a 20 s synthetic event:
//! the adaptive run at rtol 1e-6 lies within 1e-4 pu of an RK4 0.1 ms reference, and tightening
//! the tolerance converges to that reference.

use itaipu_dynamics::integrate::{Dopri5Options, Method};
use itaipu_dynamics::simulate::{simulate_pq, PreparedEvent, SimOptions};
use itaipu_dynamics::synthetic::{synthesize, PmuNoise, VoltageProfile};
use itaipu_dynamics::unit::Unit;
use itaipu_dynamics::unit_file::read_unit;

fn unit() -> Unit {
    let path = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../data/synthetic/unit_gensae_sexs_stab3_hygov.toml");
    read_unit(&path).unwrap()
}

fn run(method: Method, ev: &PreparedEvent) -> (Vec<f64>, Vec<f64>) {
    simulate_pq(&mut unit(), ev, &SimOptions { method }).unwrap()
}

fn max_diff(a: &(Vec<f64>, Vec<f64>), b: &(Vec<f64>, Vec<f64>)) -> f64 {
    let d = |x: &[f64], y: &[f64]| {
        x.iter()
            .zip(y)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max)
    };
    d(&a.0, &b.0).max(d(&a.1, &b.1))
}

#[test]
fn adaptive_converges_to_the_rk4_reference() {
    let event = synthesize(
        "conv",
        &unit(),
        &VoltageProfile::default(),
        737.0,
        &PmuNoise::typical(1),
        &SimOptions::default(),
    )
    .unwrap();
    let ev = PreparedEvent::new(&event);
    let reference = run(Method::Rk4 { h: 1e-4 }, &ev);
    // RK4 itself converges (order 4: halving 1 ms -> 0.5 ms cuts the error ~16x).
    let e_rk4_1ms = max_diff(&run(Method::Rk4 { h: 1e-3 }, &ev), &reference);
    let e_rk4_05ms = max_diff(&run(Method::Rk4 { h: 5e-4 }, &ev), &reference);
    assert!(
        e_rk4_1ms < 1e-5 && e_rk4_05ms < e_rk4_1ms / 8.0,
        "RK4 1 ms {e_rk4_1ms:e}, 0.5 ms {e_rk4_05ms:e}"
    );
    let mut last = f64::INFINITY;
    for rtol in [1e-3, 1e-5, 1e-7, 1e-9] {
        let opts = Dopri5Options {
            rtol,
            atol: rtol * 1e-2,
            h_max: 0.05,
            ..Default::default()
        };
        let e = max_diff(&run(Method::Dopri5(opts), &ev), &reference);
        println!("rtol {rtol:e}: max |dP|, |dQ| vs RK4 0.1 ms = {e:e}");
        assert!(
            e < last,
            "error must fall as rtol tightens ({rtol:e}: {e:e} after {last:e})"
        );
        last = e;
    }
    assert!(
        last < 1e-8,
        "rtol 1e-9 should agree with the reference to 1e-8 (got {last:e})"
    );
    let opts = Dopri5Options {
        rtol: 1e-6,
        atol: 1e-8,
        h_max: 0.05,
        ..Default::default()
    };
    let e = max_diff(&run(Method::Dopri5(opts), &ev), &reference);
    assert!(
        e < 1e-4,
        "rtol 1e-6 must be within 1e-4 pu of the RK4 0.1 ms reference (got {e:e})"
    );
}
