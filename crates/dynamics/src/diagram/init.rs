//! Steady-state initialisation of a diagram (see the module documentation of
//! [`super`]): Newton's method on the integrators' inputs, the torn loops and the target
//! outputs, over the integrators' states, the torn states and the references.

use super::prim::{slot, Kind, Node, Sig};
use super::sim::Scratch;
use super::{DiagramDef, Unknown};
use crate::block::ModelError;

/// Evaluates the diagram in steady state with the unknowns `z`: sets every state in `x`, the
/// held and reference values in `nodes`, every signal in `s`, and writes the residuals.
/// `(z, z_of)`: the unknowns' values and, per node, the index of its unknown.
fn evaluate(
    def: &DiagramDef,
    nodes: &mut [Node],
    s: &Scratch,
    (z, z_of): (&[f64], &[Option<usize>]),
    targets: &[f64],
    x: &mut [f64],
    res: &mut [f64],
) {
    for &k in &def.steady_order {
        let k = k as usize;
        let unknown = z_of[k].map(|i| z[i]);
        let n = &mut nodes[k];
        let o = n.x as usize;
        let u = n.ins.first().map(|&i| s.s(i)).unwrap_or(0.0);
        let y = match (n.kind, unknown) {
            (Kind::Reference, Some(r)) => {
                n.v[slot::REF_R] = r;
                r
            }
            (Kind::Initial, Some(h)) => {
                n.v[0] = h;
                h
            }
            (Kind::Initial, None) => {
                n.v[0] = u;
                u
            }
            (Kind::Lag | Kind::RateLimiter, Some(xs)) => {
                x[o] = xs;
                xs
            }
            _ => {
                match n.kind {
                    Kind::Lag => x[o] = n.v[slot::K] * u,
                    Kind::LeadLag | Kind::Washout | Kind::Derivative | Kind::RateLimiter => {
                        x[o] = u
                    }
                    Kind::Integrator => x[o] = unknown.unwrap_or(n.v[slot::I_X0]),
                    Kind::Pi => x[o] = unknown.unwrap_or(n.v[slot::PI_X0]),
                    Kind::Pid => {
                        x[o] = unknown.unwrap_or(n.v[slot::PID_X0]);
                        x[o + 1] = u;
                    }
                    _ => {}
                }
                n.output(0.0, &x[o..], s, false)
            }
        };
        s.set(n.out, y);
    }
    // A washout's or derivative's output is 0 in steady state whatever its input, so the
    // steady order may place it before its input is known: its state follows the input now.
    for n in nodes.iter() {
        if matches!(n.kind, Kind::Washout | Kind::Derivative) {
            x[n.x as usize] = s.s(n.ins[0]);
        }
    }
    let mut r = 0;
    for unk in &def.unknowns {
        match *unk {
            Unknown::Integrator(k) => {
                res[r] = s.s(nodes[k as usize].ins[0]);
                r += 1;
            }
            Unknown::Tear(k) => {
                let n = &nodes[k as usize];
                let u = s.s(n.ins[0]);
                let steady = if n.kind == Kind::Lag {
                    n.v[slot::K] * u
                } else {
                    u
                };
                res[r] = steady - z[z_of[k as usize].expect("torn")];
                r += 1;
            }
            Unknown::Reference(_) => {}
        }
    }
    let mut ti = 0;
    for (k, &sl) in def.out_slot.iter().enumerate() {
        if def.target[k] {
            res[r] = s.s(sl) - targets[ti];
            ti += 1;
            r += 1;
        }
    }
}

fn describe(def: &DiagramDef, u: Unknown) -> String {
    match u {
        Unknown::Integrator(k) => format!(
            "{}: its steady state is not determined (an integrator in a loop with no free reference, or one whose input does not depend on it)",
            def.nodes[k as usize].label()
        ),
        Unknown::Tear(k) => format!(
            "{}: the steady-state loop through it has no unique solution",
            def.nodes[k as usize].label()
        ),
        Unknown::Reference(k) => format!(
            "{}: no target output depends on it, so initialisation cannot solve it",
            def.nodes[k as usize].label()
        ),
    }
}

/// Solves the steady state; fills `x` and the nodes' held and reference values.
pub(super) fn steady_state(
    def: &DiagramDef,
    nodes: &mut [Node],
    s: &Scratch,
    targets: &[f64],
    x: &mut [f64],
) -> Result<(), ModelError> {
    let n = def.unknowns.len();
    let mut z_of = vec![None; def.nodes.len()];
    let mut z = vec![0.0; n];
    for (i, u) in def.unknowns.iter().enumerate() {
        let k = match *u {
            Unknown::Integrator(k) | Unknown::Tear(k) | Unknown::Reference(k) => k as usize,
        };
        z_of[k] = Some(i);
        let node = &nodes[k];
        let guess_slot = match node.kind {
            Kind::Integrator => Some(slot::I_GUESS),
            Kind::Pi => Some(slot::PI_GUESS),
            Kind::Pid => Some(slot::PID_GUESS),
            Kind::Reference => Some(1),
            _ => None,
        };
        let (lo, hi) = node.limits();
        z[i] = match guess_slot.map(|g| node.v[g]) {
            Some(g) if g.is_finite() => g,
            _ if lo.is_finite() && hi.is_finite() => 0.5 * (lo + hi),
            _ => 1.0,
        };
    }
    let mut res = vec![0.0; n];
    let eval = |z: &[f64], x: &mut [f64], res: &mut [f64], nodes: &mut [Node]| {
        evaluate(def, nodes, s, (z, &z_of), targets, x, res);
        res.iter().fold(0.0f64, |m, r| {
            if r.is_nan() {
                f64::INFINITY
            } else {
                m.max(r.abs())
            }
        })
    };
    let mut norm = eval(&z, x, &mut res, nodes);
    let tol = 1e-11 * (1.0 + targets.iter().fold(0.0f64, |m, t| m.max(t.abs())));
    let mut jac = vec![0.0; n * n];
    let mut r2 = vec![0.0; n];
    let mut zt = vec![0.0; n];
    let mut iter = 0;
    let mut polished = 0;
    // Newton's method; the Jacobian is also formed at the solution, because a singular one
    // there means the steady state is not unique even when the first guess satisfies it.
    loop {
        let done = norm <= tol;
        iter += 1;
        if !done && (iter > 60 || !norm.is_finite()) {
            let (worst, _) = res.iter().enumerate().fold((0, -1.0), |b, (i, r)| {
                if r.abs() > b.1 || r.is_nan() {
                    (i, r.abs())
                } else {
                    b
                }
            });
            let what = residual_name(def, worst);
            return Err(ModelError::Init(format!(
                "the steady state was not found ({what} stays at {:.3e} after {} Newton steps)",
                res[worst],
                iter - 1
            )));
        }
        // Forward-difference Jacobian.
        for j in 0..n {
            let h = 1e-7 * z[j].abs().max(1.0);
            zt.copy_from_slice(&z);
            zt[j] += h;
            eval(&zt, x, &mut r2, nodes);
            for i in 0..n {
                jac[i * n + j] = (r2[i] - res[i]) / h;
            }
        }
        let mut dz: Vec<f64> = res.iter().map(|r| -r).collect();
        if let Err(col) = solve(&mut jac, &mut dz, n) {
            return Err(ModelError::Init(describe(def, def.unknowns[col])));
        }
        if done {
            // Polish: the sensitivities take the initialisation's derivatives with respect to
            // the parameters as central differences of this solve (crate::sens), whose error is
            // the residual left over the step (1e-11 / 1e-6: 1e-5 relative at the tolerance).
            // Full Newton steps continue while they reduce the residual, at most
            // `POLISH_STEPS`, down to the rounding floor.
            if polished == POLISH_STEPS || norm == 0.0 {
                break;
            }
            polished += 1;
            for i in 0..n {
                zt[i] = z[i] + dz[i];
            }
            let nt = eval(&zt, x, &mut r2, nodes);
            if !(nt < norm) {
                break;
            }
            z.copy_from_slice(&zt);
            res.copy_from_slice(&r2);
            norm = nt;
            continue;
        }
        // Backtracking line search on the largest residual.
        let mut lambda = 1.0;
        loop {
            for i in 0..n {
                zt[i] = z[i] + lambda * dz[i];
            }
            let nt = eval(&zt, x, &mut r2, nodes);
            if nt < norm || lambda < 1e-4 {
                z.copy_from_slice(&zt);
                res.copy_from_slice(&r2);
                norm = nt;
                break;
            }
            lambda *= 0.5;
        }
    }
    // Final evaluation at the solution (sets x and the nodes' values).
    eval(&z, x, &mut res, nodes);
    // Limits at t = 0.
    for (k, nd) in def.nodes.iter().enumerate() {
        let node = &nodes[k];
        let (lo, hi) = node.limits();
        if !(lo.is_finite() || hi.is_finite()) {
            continue;
        }
        let o = node.x as usize;
        let v = node.output(0.0, &x[o..], s, false);
        // A saturated limiter has a flat steady state nothing can be solved through.
        let what = if node.kind == Kind::Limiter {
            "its input"
        } else {
            "the steady state"
        };
        if !(v >= lo && v <= hi) {
            return Err(ModelError::Init(format!(
                "{}: {what} at t = 0 is {v:.4}, outside [min, max] = [{lo}, {hi}] (a limit violated at t = 0)",
                nd.label()
            )));
        }
    }
    Ok(())
}

/// Newton steps after the tolerance is met ([`steady_state`]'s polish).
const POLISH_STEPS: usize = 2;

fn residual_name(def: &DiagramDef, i: usize) -> String {
    let eqs = def
        .unknowns
        .iter()
        .filter(|u| !matches!(u, Unknown::Reference(_)))
        .count();
    if i < eqs {
        let u = def
            .unknowns
            .iter()
            .filter(|u| !matches!(u, Unknown::Reference(_)))
            .nth(i)
            .copied();
        match u {
            Some(Unknown::Integrator(k)) => {
                format!("the input of {}", def.nodes[k as usize].label())
            }
            Some(Unknown::Tear(k)) => format!("the loop through {}", def.nodes[k as usize].label()),
            _ => "a residual".into(),
        }
    } else {
        let k = (0..def.target.len())
            .filter(|&k| def.target[k])
            .nth(i - eqs)
            .unwrap_or(0);
        format!("the error of output '{}'", def.ports[def.n_in + k].name)
    }
}

/// Solves `a x = b` in place (Gaussian elimination, partial pivoting). On a singular matrix
/// returns the column without a pivot.
fn solve(a: &mut [f64], b: &mut [f64], n: usize) -> Result<(), usize> {
    let scale = a.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-300);
    for c in 0..n {
        let (p, pv) = (c..n)
            .map(|r| (r, a[r * n + c].abs()))
            .fold((c, -1.0), |b, e| if e.1 > b.1 { e } else { b });
        if !(pv > 1e-10 * scale) {
            return Err(c);
        }
        if p != c {
            for j in 0..n {
                a.swap(p * n + j, c * n + j);
            }
            b.swap(p, c);
        }
        for r in c + 1..n {
            let f = a[r * n + c] / a[c * n + c];
            if f != 0.0 {
                for j in c..n {
                    a[r * n + j] -= f * a[c * n + j];
                }
                b[r] -= f * b[c];
            }
        }
    }
    for c in (0..n).rev() {
        let mut v = b[c];
        for j in c + 1..n {
            v -= a[c * n + j] * b[j];
        }
        b[c] = v / a[c * n + c];
    }
    Ok(())
}
