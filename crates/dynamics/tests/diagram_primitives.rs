//! Every diagram primitive against an analytic response (step, ramp, limit hit), driven
//! directly through the block interface: the diagram's input `u` is a function of time, the
//! states are integrated with RK4 at 1 ms (modes re-evaluated after every step), and the output
//! is compared with the closed form.

use itaipu_dynamics::block::{Block, InitPoint, Io};
use itaipu_dynamics::diagram;

const OP: InitPoint = InitPoint {
    v_mag: 1.0,
    v_ang: 0.0,
    p: 0.0,
    q: 0.0,
    speed_dev: 0.0,
};

/// A diagram with input `u` (and `w`) and one free output `y`, blocks given as TOML text.
fn make(params: &str, blocks: &str) -> diagram::Diagram {
    let text = format!(
        "inputs = {{ u = \"u_sig\", w = {{ signal = \"w_sig\", optional = true }} }}\noutputs = {{ y = {{ signal = \"y_sig\", init = \"free\" }} }}\n[params]\n{params}\n{blocks}"
    );
    let t: toml::Table = text.parse().unwrap_or_else(|e| panic!("{e}\n{text}"));
    diagram::from_table(&t).unwrap_or_else(|e| panic!("{}: {}\n{text}", e.field, e.msg))
}

/// Runs the diagram from steady state at `u(0⁻) = u0` with input `u(t)` (w = 0) until `t_end`,
/// returning `(t, y)` every step.
fn run(d: &mut diagram::Diagram, u0: f64, u: &dyn Fn(f64) -> f64, t_end: f64) -> Vec<(f64, f64)> {
    let map = [0usize, 1, 2];
    let mut bus = vec![u0, 0.0, 0.0];
    let n = d.state_names().len();
    let mut x = vec![0.0; n];
    d.init(&OP, &mut x, &mut Io::new(&mut bus, &map)).unwrap();
    let h = 1e-3;
    let mut t = 0.0;
    let mut out = vec![];
    let f = |d: &diagram::Diagram, t: f64, x: &[f64], bus: &mut Vec<f64>, dx: &mut [f64]| {
        bus[0] = u(t);
        let mut io = Io::new(bus, &map);
        d.outputs(t, x, &mut io);
        d.derivatives(t, x, &io, dx);
    };
    let (mut k1, mut k2, mut k3, mut k4) = (vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    let mut xt = vec![0.0; n];
    // Output at t = 0 with the input applied.
    bus[0] = u(0.0);
    d.update_modes(&mut x, &Io::new(&mut bus, &map));
    d.outputs(0.0, &x, &mut Io::new(&mut bus, &map));
    out.push((0.0, bus[2]));
    while t < t_end - 1e-12 {
        f(d, t, &x, &mut bus, &mut k1);
        for i in 0..n {
            xt[i] = x[i] + 0.5 * h * k1[i];
        }
        f(d, t + 0.5 * h, &xt, &mut bus, &mut k2);
        for i in 0..n {
            xt[i] = x[i] + 0.5 * h * k2[i];
        }
        f(d, t + 0.5 * h, &xt, &mut bus, &mut k3);
        for i in 0..n {
            xt[i] = x[i] + h * k3[i];
        }
        f(d, t + h, &xt, &mut bus, &mut k4);
        for i in 0..n {
            x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
        t += h;
        bus[0] = u(t);
        d.outputs(t, &x, &mut Io::new(&mut bus, &map));
        d.update_modes(&mut x, &Io::new(&mut bus, &map));
        d.outputs(t, &x, &mut Io::new(&mut bus, &map));
        out.push((t, bus[2]));
    }
    out
}

fn compare(tr: &[(f64, f64)], exact: &dyn Fn(f64) -> f64, tol: f64, what: &str) {
    let mut worst = (0.0, 0.0);
    for &(t, y) in tr {
        let d = (y - exact(t)).abs();
        if d > worst.0 {
            worst = (d, t);
        }
    }
    assert!(
        worst.0 < tol,
        "{what}: error {:.3e} at t = {:.3} (tolerance {tol:.1e})",
        worst.0,
        worst.1
    );
}

const STEP: &dyn Fn(f64) -> f64 = &|_t| 1.0;

/// One block `b` from u to y.
fn one(ty_fields: &str) -> String {
    format!("[[block]]\nname = \"b\"\nin = \"u\"\nout = \"y\"\n{ty_fields}\n")
}

#[test]
fn lag_step_and_non_windup_limit() {
    let mut d = make(
        "k = 2.0\nt = 0.5",
        &one("type = \"lag\"\nk = \"k\"\nt = \"t\""),
    );
    let tr = run(&mut d, 0.0, STEP, 2.0);
    compare(&tr, &|t| 2.0 * (1.0 - (-t / 0.5).exp()), 1e-9, "lag step");
    // Limited at 1.5: reaches it at t = 0.5 ln 4 and stays; when the input drops to 0 at t = 2
    // it leaves at once (no windup): y = 1.5 e^{-(t-2)/0.5}.
    let mut d = make("", &one("type = \"lag\"\nk = 2.0\nt = 0.5\nmax = 1.5"));
    let tr = run(&mut d, 0.0, &|t| if t < 2.0 { 1.0 } else { 0.0 }, 3.0);
    let hit = 0.5 * 4f64.ln();
    compare(
        &tr,
        &|t| {
            if t < hit {
                2.0 * (1.0 - (-t / 0.5).exp())
            } else if t < 2.0 {
                1.5
            } else {
                1.5 * (-(t - 2.0) / 0.5).exp()
            }
        },
        3e-3,
        "limited lag",
    );
}

#[test]
fn lead_lag_washout_derivative() {
    let mut d = make(
        "",
        &one("type = \"lead_lag\"\nk = 3.0\nt_a = 2.0\nt_b = 0.5"),
    );
    compare(
        &run(&mut d, 0.0, STEP, 2.0),
        &|t| 3.0 * (1.0 + (2.0 / 0.5 - 1.0) * (-t / 0.5).exp()),
        1e-9,
        "lead-lag step",
    );
    let mut d = make("", &one("type = \"washout\"\nk = 2.0\nt = 0.4"));
    compare(
        &run(&mut d, 0.0, STEP, 2.0),
        &|t| 2.0 * (-t / 0.4).exp(),
        1e-9,
        "washout step",
    );
    // Ramp u = 0.5 t into k s/(1 + sT): y = 0.5 k (1 − e^{−t/T}).
    let mut d = make("", &one("type = \"derivative\"\nk = 3.0\nt = 0.2"));
    compare(
        &run(&mut d, 0.0, &|t| 0.5 * t, 2.0),
        &|t| 1.5 * (1.0 - (-t / 0.2).exp()),
        1e-9,
        "derivative ramp",
    );
}

#[test]
fn integrators_pi_pid_with_windup_and_non_windup_limits() {
    // Integrator of a unit step: y = x0 + k t. With u(0⁻) = 0 and no feedback its steady state
    // is not unique (the initialisation would refuse it): `x0` fixes it.
    let mut d = make("", &one("type = \"integrator\"\nk = 0.5\nx0 = 0.2"));
    compare(
        &run(&mut d, 0.0, STEP, 2.0),
        &|t| 0.2 + 0.5 * t,
        1e-9,
        "integrator ramp",
    );
    // Non-windup at 0.6: pinned from t = 0.8 and, when the input reverses at t = 2, leaves at once.
    let mut d = make(
        "",
        &one("type = \"integrator\"\nk = 0.5\nmin = -1.0\nmax = 0.6\nx0 = 0.2"),
    );
    let tr = run(&mut d, 0.0, &|t| if t < 2.0 { 1.0 } else { -1.0 }, 3.0);
    compare(
        &tr,
        &|t| {
            if t < 0.8 {
                0.2 + 0.5 * t
            } else if t < 2.0 {
                0.6
            } else {
                0.6 - 0.5 * (t - 2.0)
            }
        },
        2e-3,
        "non-windup integrator",
    );
    // Windup: the state keeps integrating to 1.2 at t = 2, so the output stays at 0.6 until
    // the state comes back down at t = 3.2.
    let mut d = make(
        "",
        &one("type = \"integrator\"\nk = 0.5\nmin = -1.0\nmax = 0.6\nx0 = 0.2\nlimit = \"windup\""),
    );
    let tr = run(&mut d, 0.0, &|t| if t < 2.0 { 1.0 } else { -1.0 }, 4.0);
    compare(
        &tr,
        &|t| {
            if t < 0.8 {
                0.2 + 0.5 * t
            } else if t < 3.2 {
                0.6
            } else {
                1.2 - 0.5 * (t - 2.0)
            }
        },
        2e-3,
        "windup integrator",
    );
    // PI step: y = k_p + k_i t (+ x0).
    let mut d = make("", &one("type = \"pi\"\nk_p = 2.0\nk_i = 0.5\nx0 = 0.0"));
    compare(
        &run(&mut d, 0.0, STEP, 2.0),
        &|t| 2.0 + 0.5 * t,
        1e-9,
        "pi step",
    );
    // PID step: y = k_p + k_i t + (k_d/T_d) e^{−t/T_d}.
    let mut d = make(
        "",
        &one("type = \"pid\"\nk_p = 1.0\nk_i = 0.5\nk_d = 0.2\nt_d = 0.1\nx0 = 0.0"),
    );
    compare(
        &run(&mut d, 0.0, STEP, 2.0),
        &|t| 1.0 + 0.5 * t + 2.0 * (-t / 0.1).exp(),
        1e-8,
        "pid step",
    );
}

#[test]
fn rate_limiter_follows_a_step_at_its_rate() {
    let mut d = make(
        "",
        &one("type = \"rate_limiter\"\nt = 0.01\nrise = 0.5\nfall = 2.0"),
    );
    // Up at 0.5/s until within 0.5·T of the target, then exponential.
    let tr = run(&mut d, 0.0, STEP, 3.0);
    compare(&tr, &|t| (0.5 * t).min(1.0), 6e-3, "rate-limited rise");
    let late = tr.last().unwrap().1;
    assert!((late - 1.0).abs() < 1e-9, "settles on the input: {late}");
}

#[test]
fn static_primitives() {
    let eval = |blocks: &str, u: f64, w: f64| -> f64 {
        let mut d = make("a = 2.0", blocks);
        let map = [0usize, 1, 2];
        let mut bus = vec![u, w, 0.0];
        let mut x = vec![0.0; d.state_names().len()];
        d.init(&OP, &mut x, &mut Io::new(&mut bus, &map)).unwrap();
        d.outputs(0.5, &x, &mut Io::new(&mut bus, &map));
        bus[2]
    };
    let b = |s: &str| format!("[[block]]\nname = \"b\"\nout = \"y\"\n{s}\n");
    assert_eq!(
        eval(&b("type = \"gain\"\nin = \"u\"\nk = \"-a*1.5\""), 2.0, 0.0),
        -6.0
    );
    assert_eq!(
        eval(
            &b("type = \"sum\"\nin = [\"u\", \"w\"]\nsigns = \"+-\""),
            2.0,
            0.5
        ),
        1.5
    );
    assert_eq!(
        eval(
            &b("type = \"sum\"\nin = [\"u\", \"w\"]\ngains = [\"a\", 3]"),
            2.0,
            0.5
        ),
        5.5
    );
    assert_eq!(
        eval(
            &b("type = \"product\"\nin = [\"u\", \"w\"]\nops = \"*/\""),
            2.0,
            0.5
        ),
        4.0
    );
    assert_eq!(
        eval(
            &b("type = \"product\"\nin = [\"u\", \"w\", \"u\"]"),
            2.0,
            0.5
        ),
        2.0
    );
    assert_eq!(eval(&b("type = \"abs\"\nin = \"u\""), -2.0, 0.0), 2.0);
    assert_eq!(
        eval(&b("type = \"min\"\nin = [\"u\", \"w\"]"), 2.0, 0.5),
        0.5
    );
    assert_eq!(
        eval(&b("type = \"max\"\nin = [\"u\", \"w\"]"), 2.0, 0.5),
        2.0
    );
    assert_eq!(
        eval(
            &b("type = \"limiter\"\nin = \"u\"\nmin = -1\nmax = 1"),
            0.3,
            0.0
        ),
        0.3
    );
    assert_eq!(
        eval(
            &b("type = \"deadband\"\nin = \"u\"\nwidth = 0.1"),
            0.05,
            0.0
        ),
        0.0
    );
    assert!(
        (eval(
            &b("type = \"deadband\"\nin = \"u\"\nwidth = 0.1"),
            -0.3,
            0.0
        ) + 0.2)
            .abs()
            < 1e-15
    );
    let pw = "type = \"pwl\"\nin = \"u\"\nx = [0, 1, 3]\ny = [0, 2, \"a\"]";
    assert_eq!(eval(&b(pw), 0.5, 0.0), 1.0);
    assert_eq!(eval(&b(pw), 2.0, 0.0), 2.0);
    assert_eq!(eval(&b(pw), 9.0, 0.0), 2.0);
    assert_eq!(eval(&b(pw), -9.0, 0.0), 0.0);
    // switch: [c, a, b] → a when c ≥ threshold.
    let sw = "[[block]]\nname = \"c1\"\ntype = \"constant\"\nvalue = 7\nout = \"seven\"\n[[block]]\nname = \"b\"\ntype = \"switch\"\nin = [\"u\", \"seven\", \"w\"]\nthreshold = 1.0\nout = \"y\"\n";
    assert_eq!(eval(sw, 1.0, 0.5), 7.0);
    assert_eq!(eval(sw, 0.9, 0.5), 0.5);
    // pulso (paper 000): 0 below p1, p2 between p1 and p3, p4 otherwise; on time without input.
    let pulso = |u: f64| {
        eval(
            &b("type = \"pulso\"\nin = \"u\"\np1 = 1\np2 = 5\np3 = 2\np4 = 9"),
            u,
            0.0,
        )
    };
    assert_eq!((pulso(0.5), pulso(1.5), pulso(2.5)), (0.0, 5.0, 9.0));
    let on_time = format!("{}[[block]]\nname = \"g\"\ntype = \"gain\"\nin = \"u\"\nk = 0\nout = \"unused\"\n[[block]]\nname = \"s\"\ntype = \"sum\"\nin = [\"pt\", \"unused\"]\nout = \"y\"\n", "[[block]]\nname = \"p\"\ntype = \"pulso\"\np1 = 0.25\np2 = 3\np3 = 1\np4 = 4\nout = \"pt\"\n");
    assert_eq!(
        eval(&on_time, 0.0, 0.0),
        3.0,
        "pulso on the time at t = 0.5"
    );
    // time, constant.
    assert_eq!(eval(&b("type = \"time\""), 0.0, 0.0), 0.5);
    assert_eq!(
        eval(&b("type = \"constant\"\nvalue = \"a/4\""), 0.0, 0.0),
        0.5
    );
}

#[test]
fn initial_holds_the_value_at_t0() {
    // y = u − u(0): zero at the start whatever u(0) is, then follows u.
    let mut d = make("", "[[block]]\nname = \"h\"\ntype = \"initial\"\nin = \"u\"\nout = \"u0\"\n[[block]]\nname = \"b\"\ntype = \"sum\"\nin = [\"u\", \"u0\"]\nsigns = \"+-\"\nout = \"y\"\n");
    compare(
        &run(&mut d, 3.0, &|t| 3.0 + t, 1.0),
        &|t| t,
        1e-12,
        "initial",
    );
}

#[test]
fn a_washout_declared_before_its_input_still_starts_in_steady_state() {
    // The washout's steady output is 0 whatever its input, so the steady-state order may
    // evaluate it before the gain that feeds it: its state must still take the input's value.
    let mut d = make(
        "",
        "[[block]]\nname = \"w\"\ntype = \"washout\"\nin = \"g\"\nt = 1.0\nout = \"wo\"\n\
         [[block]]\nname = \"g\"\ntype = \"gain\"\nin = \"u\"\nk = 3.0\nout = \"g\"\n\
         [[block]]\nname = \"d\"\ntype = \"derivative\"\nin = \"g\"\nt = 0.5\nout = \"do\"\n\
         [[block]]\nname = \"s\"\ntype = \"sum\"\nin = [\"wo\", \"do\"]\nout = \"y\"\n",
    );
    // Constant input 2: nothing moves.
    compare(
        &run(&mut d, 2.0, &|_| 2.0, 1.0),
        &|_| 0.0,
        1e-15,
        "washout at rest",
    );
}
