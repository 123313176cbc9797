//! ST5B alone on prescribed inputs against an independent reference (`tools/st5b_reference.py`:
//! the block equations in Python, scipy `solve_ivp` DOP853 at rtol 1e-10, modes switched at
//! located events; `data/st5b/README.md`).
//!
//! The exciter is put in a unit with only a source block that writes X_adI_fd, V_S and V_OEL
//! (linear between the reference's 5 ms rows, as the reference's inputs are) and fixes E_fd0;
//! |V_t| is the played-back terminal voltage. E_fd is compared at every row. The cases drive the
//! regulator onto V_RMAX (the K_C-reduced ceiling V_RMAX − K_C·X_adI_fd), the bridge onto its
//! supply ceiling V_t·V_RMAX and floor V_t·V_RMIN, zero time constants (T_R, T_C1, T_B2,
//! T_1 = 0) and the OEL gate with its alternate lead-lag path.

use crate::exciter_support;

use std::path::PathBuf;

use exciter_support::{Series, Source};
use itaipu_dynamics::block::InitPoint;
use itaipu_dynamics::integrate::{solve, Dopri5Options, Method};
use itaipu_dynamics::registry;
use itaipu_dynamics::unit::{Playback, PlaybackInput, Unit};

fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../data/st5b")
        .join(rel)
}

struct Case {
    params: Vec<(String, f64)>,
    oel: String,
    efd0: f64,
    cols: Vec<String>,
    rows: Vec<Vec<f64>>,
}

impl Case {
    fn load(name: &str) -> Self {
        let j: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(data(&format!("{name}.json"))).unwrap())
                .unwrap();
        let params = j["params"]
            .as_object()
            .unwrap()
            .iter()
            .map(|(k, v)| (k.clone(), v.as_f64().unwrap()))
            .collect();
        let text = std::fs::read_to_string(data(&format!("{name}.csv"))).unwrap();
        let mut lines = text.lines();
        let cols = lines.next().unwrap().split(',').map(String::from).collect();
        let rows = lines
            .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
            .collect();
        Self {
            params,
            oel: j["options"]["oel"].as_str().unwrap().to_string(),
            efd0: j["efd0"].as_f64().unwrap(),
            cols,
            rows,
        }
    }
    fn col(&self, name: &str) -> Vec<f64> {
        let k = self.cols.iter().position(|c| c == name).unwrap();
        self.rows.iter().map(|r| r[k]).collect()
    }
    fn param(&self, name: &str) -> f64 {
        self.params.iter().find(|(k, _)| k == name).unwrap().1
    }
}

/// Max |E_fd − E_fd,ref| over every row, and the time where it occurs.
fn compare(name: &str) -> (f64, f64) {
    let c = Case::load(name);
    let t = c.col("time_s");
    let series = |n: &str| Series {
        t: t.clone(),
        v: c.col(n),
    };
    let mut exc = registry::find("ST5B").unwrap().create();
    for (k, v) in &c.params {
        let i = exc.params().index_of(k).unwrap();
        exc.params_mut().set(i, *v);
    }
    exc.set_option("oel", &c.oel).unwrap();
    let mut u = Unit::new(name, 30.0, 50.0);
    u.add("exciter", exc, &[]).unwrap();
    let src = Source::new(
        vec![
            ("xadifd", series("xadifd")),
            ("vs", series("vs")),
            ("voel", series("voel")),
        ],
        Some(c.efd0),
    );
    u.add("source", Box::new(src), &[]).unwrap();
    u.finish().unwrap();
    let v_t = c.col("v_t");
    let op = InitPoint {
        v_mag: v_t[0],
        v_ang: 0.0,
        p: 0.0,
        q: 0.0,
        speed_dev: 0.0,
    };
    let mut x = u.initialise(&op).unwrap();
    let input = PlaybackInput::linear(t.clone(), v_t, vec![0.0; t.len()]);
    let iefd = u.signal_index("efd").unwrap();
    let efd_ref = c.col("efd");
    let method = Method::Dopri5(Dopri5Options {
        rtol: 1e-10,
        atol: 1e-12,
        h_max: 0.005,
        ..Default::default()
    });
    let mut worst = (0.0, 0.0);
    let mut sys = Playback::new(&mut u, &input);
    solve(&method, &mut sys, &mut x, &t, |k, tk, x, s| {
        s.eval_signals(tk, x);
        let d = (s.unit.bus()[iefd] - efd_ref[k]).abs();
        if d > worst.0 {
            worst = (d, tk);
        }
    })
    .unwrap();
    println!(
        "{name}: max |E_fd − E_fd,ref| = {:.2e} pu at t = {:.3} s ({} rows)",
        worst.0,
        worst.1,
        t.len()
    );
    worst
}

/// Rows where the reference sits on each limit: (V_t·V_RMAX, V_t·V_RMIN, within 1e-3 of the
/// K_C-reduced ceiling V_RMAX − K_C·X_adI_fd while below V_t·V_RMAX).
fn limit_rows(name: &str) -> (usize, usize, usize) {
    let c = Case::load(name);
    let (efd, vt, ifd) = (c.col("efd"), c.col("v_t"), c.col("xadifd"));
    let (vmax, vmin, kc) = (c.param("vr_max"), c.param("vr_min"), c.param("k_c"));
    let mut n = (0, 0, 0);
    for k in 0..efd.len() {
        n.0 += ((efd[k] - vt[k] * vmax).abs() < 1e-9) as usize;
        n.1 += ((efd[k] - vt[k] * vmin).abs() < 1e-9) as usize;
        n.2 +=
            ((efd[k] - (vmax - kc * ifd[k])).abs() < 1e-3 && efd[k] < vt[k] * vmax - 1e-3) as usize;
    }
    n
}

// Measured (Dopri5, rtol 1e-10): max |ΔE_fd| 2.0e-7 (mostar_like), 6.8e-10
// (zero_time_constants), 1.5e-7 pu (oel_gate); the bound asked of the model is 1e-4 pu. With
// the limited lead-lags winding up (dx/dt = (u − x)/T_B on the limit) the first and the last
// case are off by 2.8 and 2.1 pu.
#[test]
fn st5b_mostar_like_regulator_matches_the_reference() {
    let (a, b, c) = limit_rows("mostar_like");
    assert!(
        a > 20 && b > 20 && c > 20,
        "the case must reach every limit: {a} {b} {c}"
    );
    let (d, _) = compare("mostar_like");
    assert!(d < 1e-4, "{d:e}");
}

#[test]
fn st5b_with_zero_time_constants_matches_the_reference() {
    let (a, _, _) = limit_rows("zero_time_constants");
    assert!(a > 20, "the case must reach the supply ceiling: {a}");
    let (d, _) = compare("zero_time_constants");
    assert!(d < 1e-4, "{d:e}");
}

#[test]
fn st5b_oel_gate_and_its_alternate_path_match_the_reference() {
    let (a, b, _) = limit_rows("oel_gate");
    assert!(a > 5 && b > 20, "{a} {b}");
    let (d, _) = compare("oel_gate");
    assert!(d < 1e-4, "{d:e}");
}
