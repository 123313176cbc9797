//! Compilation of a diagram at the current parameter values: the parameters checked against
//! their allowed ranges, every block's fields evaluated and checked against their domains, and
//! the derived constants (inverse time constants, sum gains, pwl breakpoints) filled into the
//! simulated nodes.

use super::prim::{self, Kind, Node};
use super::{Diagram, NodeDef};
use crate::block::ModelError;
use crate::sens::Scalar;

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
            let (v, list) = node_values(nd, p);
            for (k, f) in nd.info.fields.iter().enumerate() {
                let val = v[k];
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
            if matches!(nd.info.kind, Kind::Sum | Kind::Pwl) {
                if let Some(k) = list.iter().position(|val| !val.is_finite()) {
                    return Err(ModelError::param(
                        &format!("{}.{}", nd.label(), list_field(nd, k)),
                        format!("must be finite (got {})", list[k]),
                    ));
                }
                if nd.info.kind == Kind::Pwl {
                    let n = list.len() / 2;
                    if list[..n].windows(2).any(|w| !(w[1] > w[0])) {
                        return Err(ModelError::param(
                            &format!("{}.x", nd.label()),
                            "breakpoints must increase strictly",
                        ));
                    }
                }
            }
            node.v = v;
            node.list = list;
        }
        Ok(nodes)
    }
}

/// One node's values at the parameter values `p`: its fields in order (an omitted one at its
/// default) with the derived constants after them (inverse time constants, the lead-lag's
/// ratio; [`prim::slot`]), and its list values (sum gains, pwl breakpoints then values,
/// product exponents). Unchecked ([`Diagram::compile`] checks them). On dual numbers (a
/// sensitivity pass) the values carry their derivatives with respect to the parameters.
pub(super) fn node_values<S: Scalar>(nd: &NodeDef, p: &[S]) -> ([S; prim::NV], Vec<S>) {
    use prim::slot::*;
    let mut v = [S::cst(0.0); prim::NV];
    for (k, f) in nd.info.fields.iter().enumerate() {
        v[k] = match &nd.fields[k] {
            Some(e) => e.eval(p),
            None => S::cst(f.default.unwrap_or(f64::NAN)),
        };
    }
    match nd.info.kind {
        Kind::Lag => v[LAG_INV_T] = v[LAG_T].recip(),
        Kind::LeadLag => {
            v[LL_RATIO] = v[1] / v[2];
            v[LL_INV_TB] = v[2].recip();
        }
        Kind::Washout | Kind::Derivative => v[W_INV_T] = v[1].recip(),
        Kind::Pid => v[PID_INV_TD] = v[3].recip(),
        Kind::RateLimiter => v[RL_INV_T] = v[0].recip(),
        _ => {}
    }
    let list = match nd.info.kind {
        Kind::Sum | Kind::Pwl => nd.list.iter().map(|e| e.eval(p)).collect(),
        Kind::Product => nd.exps.iter().map(|&e| S::cst(e)).collect(),
        _ => Vec::new(),
    };
    (v, list)
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
