//! Text descriptions: a diagram as Graphviz dot, and the primitive library as text (for
//! `itaipu-calib models`).

use std::fmt::Write as _;

use super::expr::Expr;
use super::prim::{self, Kind};
use super::DiagramDef;

/// Graphviz dot text of a diagram: inputs as ellipses, blocks as boxes with their fields,
/// outputs as double octagons, wires labelled with the signal.
pub fn to_dot(def: &DiagramDef) -> String {
    let q = |s: &str| format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""));
    let mut s = String::new();
    let _ = writeln!(s, "digraph diagram {{");
    let _ = writeln!(s, "  rankdir=LR;");
    if !def.title.is_empty() {
        let _ = writeln!(s, "  label={};", q(&def.title));
    }
    let _ = writeln!(s, "  node [fontname=\"Helvetica\", fontsize=10];");
    let node_id = |slot: usize| {
        if slot < def.n_in {
            format!("in_{}", def.signals[slot])
        } else {
            format!("b_{}", def.nodes[slot - def.n_in].name)
        }
    };
    for i in 0..def.n_in {
        let p = &def.ports[i];
        let _ = writeln!(
            s,
            "  {} [shape=ellipse, label={}];",
            q(&node_id(i)),
            q(&format!("{} ({})", p.name, p.signal))
        );
    }
    for (k, n) in def.nodes.iter().enumerate() {
        let mut label = format!("{}\\n{}", n.name, n.info.name);
        for (f, t) in n.info.fields.iter().zip(&n.field_text) {
            if let Some(t) = t {
                let _ = write!(label, "\\n{} = {}", f.name, t);
            }
        }
        let _ = writeln!(
            s,
            "  {} [shape=box, label=\"{}\"];",
            q(&node_id(def.n_in + k)),
            label.replace('"', "\\\"")
        );
    }
    for (k, n) in def.nodes.iter().enumerate() {
        let sk = &def.skeleton[k];
        for (j, &src) in sk.ins.iter().enumerate() {
            let sign = match n.info.kind {
                Kind::Sum if n.list.get(j) == Some(&Expr::Num(-1.0)) => " (−)",
                Kind::Product if n.exps.get(j) == Some(&-1.0) => " (÷)",
                _ => "",
            };
            let _ = writeln!(
                s,
                "  {} -> {} [label={}];",
                q(&node_id(src as usize)),
                q(&node_id(def.n_in + k)),
                q(&format!("{}{sign}", def.signals[src as usize]))
            );
        }
    }
    for (k, &slot) in def.out_slot.iter().enumerate() {
        let p = &def.ports[def.n_in + k];
        let id = format!("out_{}", p.name);
        let _ = writeln!(
            s,
            "  {} [shape=doubleoctagon, label={}];",
            q(&id),
            q(&format!("{} → {}", p.name, p.signal))
        );
        let _ = writeln!(s, "  {} -> {};", q(&node_id(slot as usize)), q(&id));
    }
    s.push_str("}\n");
    s
}

/// The primitive library as text (for `itaipu-calib models`).
pub fn describe_primitives() -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "diagram primitives (model = \"diagram\"; fields are numbers or expressions of the diagram's parameters):"
    );
    for p in prim::PRIMITIVES {
        let _ = writeln!(s, "\n  {:<13} {}", p.name, p.equation);
        let ins = p.arity.describe().1;
        let _ = writeln!(s, "      inputs: {ins}");
        for f in p.fields {
            let d = match f.default {
                None => "required".to_string(),
                Some(v) if v.is_nan() => "optional".to_string(),
                Some(v) => format!("default {v}"),
            };
            let _ = writeln!(
                s,
                "      {:<10} {} ({}; {})",
                f.name,
                f.doc,
                f.dom.describe(),
                d
            );
        }
        for (o, doc) in p.options {
            let _ = writeln!(s, "      {o:<10} {doc}");
        }
        if !p.states.is_empty() {
            let _ = writeln!(s, "      states: {}", p.states.join(", "));
        }
    }
    s
}
