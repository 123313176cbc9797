//! Compilation of a diagram at the current parameter values: the parameters checked against
//! their allowed ranges, every block's fields evaluated and checked against their domains, and
//! the derived constants (inverse time constants, sum gains, pwl breakpoints) filled into the
//! simulated nodes.

use super::prim::{self, Kind, Node};
use super::{Diagram, NodeDef};
use crate::block::ModelError;

impl Diagram {
    /// Nodes with their fields evaluated at the current parameter values and checked.
    pub(super) fn compile(&self) -> Result<Vec<Node>, ModelError> {
        let def = &*self.def;
        let p = &self.p.values;
        for (i, s) in def.specs.iter().enumerate() {
            let v = p[i];
            let (lo, hi) = def.allowed[i];
            if !v.is_finite() {
                return Err(ModelError::param(
                    s.name,
                    format!("must be finite (got {v})"),
                ));
            }
            if v < lo || v > hi {
                return Err(ModelError::param(
                    s.name,
                    format!("{v} lies outside its allowed range [{lo}, {hi}]"),
                ));
            }
        }
        let mut nodes = def.skeleton.clone();
        for (nd, node) in def.nodes.iter().zip(nodes.iter_mut()) {
            let mut v = [0.0; prim::NV];
            for (k, f) in nd.info.fields.iter().enumerate() {
                let val = match &nd.fields[k] {
                    Some(e) => e.eval(p),
                    None => f.default.unwrap_or(f64::NAN),
                };
                // `guess` and `x0` NaN mean "choose" and "solve".
                if !((f.name == "guess" || f.name == "x0") && nd.fields[k].is_none()) {
                    f.dom.check(val).map_err(|m| {
                        ModelError::param(
                            &format!("{}.{}", nd.label(), f.name),
                            format!(
                                "{m} (got {val}{})",
                                nd.field_text[k]
                                    .as_ref()
                                    .map(|t| format!(" = {t}"))
                                    .unwrap_or_default()
                            ),
                        )
                    })?;
                }
                v[k] = val;
            }
            // Limits in order.
            let lim_at = nd.info.fields.iter().position(|f| f.name == "min");
            if let Some(a) = lim_at {
                let (lo, hi) = (v[a], v[a + 1]);
                if !(hi > lo) {
                    return Err(ModelError::param(
                        &format!("{}.max", nd.label()),
                        format!("must exceed min ({hi} <= {lo})"),
                    ));
                }
            }
            use prim::slot::*;
            match nd.info.kind {
                Kind::Lag => v[LAG_INV_T] = 1.0 / v[LAG_T],
                Kind::LeadLag => {
                    v[LL_RATIO] = v[1] / v[2];
                    v[LL_INV_TB] = 1.0 / v[2];
                }
                Kind::Washout | Kind::Derivative => v[W_INV_T] = 1.0 / v[1],
                Kind::Pid => v[PID_INV_TD] = 1.0 / v[3],
                Kind::RateLimiter => v[RL_INV_T] = 1.0 / v[0],
                _ => {}
            }
            node.v = v;
            node.list.clear();
            match nd.info.kind {
                Kind::Sum | Kind::Pwl => {
                    for (k, e) in nd.list.iter().enumerate() {
                        let val = e.eval(p);
                        if !val.is_finite() {
                            return Err(ModelError::param(
                                &format!("{}.{}", nd.label(), list_field(nd, k)),
                                format!("must be finite (got {val})"),
                            ));
                        }
                        node.list.push(val);
                    }
                    if nd.info.kind == Kind::Pwl {
                        let n = node.list.len() / 2;
                        if node.list[..n].windows(2).any(|w| !(w[1] > w[0])) {
                            return Err(ModelError::param(
                                &format!("{}.x", nd.label()),
                                "breakpoints must increase strictly",
                            ));
                        }
                    }
                }
                Kind::Product => node.list.extend_from_slice(&nd.exps),
                _ => {}
            }
        }
        Ok(nodes)
    }
}

fn list_field(nd: &NodeDef, k: usize) -> String {
    match nd.info.kind {
        Kind::Sum => format!("gains[{k}]"),
        _ => {
            let n = nd.list.len() / 2;
            if k < n {
                format!("x[{k}]")
            } else {
                format!("y[{}]", k - n)
            }
        }
    }
}
