//! Wiring and checking the graph of a parsed diagram: one writer per signal, every block input
//! written and every block output read, the outputs and their targets, the evaluation order
//! (algebraic loops refused), the steady-state order (loops torn through lags), the unknowns of
//! the initialisation and the block's ports.

use std::collections::HashMap;

use super::parse::{signal_table, InDecl, Params};
use super::prim::{self, Kind, Node};
use super::{def::derr, intern, DefError, DiagramDef, NodeDef, Unknown, TARGET_SIGNALS};
use crate::block::{Dir, Port, PortInit};

/// Wires the parsed parts into the checked [`DiagramDef`].
pub(super) fn wire(
    t: &toml::Table,
    title: String,
    params: Params,
    inputs: Vec<InDecl>,
    nodes: Vec<NodeDef>,
) -> Result<DiagramDef, DefError> {
    let Params {
        specs,
        allowed,
        defaults,
        ..
    } = params;
    // Signals: inputs, then one per node.
    let mut signals: Vec<String> = inputs.iter().map(|i| i.local.clone()).collect();
    let mut writer: HashMap<String, usize> = HashMap::new();
    for (i, d) in inputs.iter().enumerate() {
        writer.insert(d.local.clone(), i);
    }
    let n_in = inputs.len();
    for (k, n) in nodes.iter().enumerate() {
        if let Some(&w) = writer.get(&n.out) {
            let other = if w < n_in {
                format!("input '{}'", inputs[w].local)
            } else {
                nodes[w - n_in].label()
            };
            return Err(derr(
                format!("{}.out", n.label()),
                format!(
                    "signal '{}' has two writers: {} and {}",
                    n.out,
                    other,
                    n.label()
                ),
            ));
        }
        writer.insert(n.out.clone(), n_in + k);
        signals.push(n.out.clone());
    }
    let mut read = vec![false; signals.len()];
    let mut skeleton = vec![];
    let (mut nx, mut nlim) = (0usize, 0usize);
    let mut state_names: Vec<&'static str> = vec![];
    for (k, n) in nodes.iter().enumerate() {
        let mut ins = vec![];
        for s in &n.ins {
            let &w = writer.get(s).ok_or_else(|| {
                derr(
                    format!("{}.in", n.label()),
                    format!("signal '{s}' has no writer (no block's out, no input)"),
                )
            })?;
            read[w] = true;
            ins.push(w as u32);
        }
        let kind = n.info.kind;
        let lim = if n.limited {
            nlim += 1;
            (nlim - 1) as u32
        } else {
            u32::MAX
        };
        skeleton.push(Node {
            kind,
            ins,
            out: (n_in + k) as u32,
            x: nx as u32,
            lim,
            windup: n.windup,
            v: [0.0; prim::NV],
            list: vec![],
        });
        for s in n.info.states {
            state_names.push(intern::str(&if n.info.states.len() == 1 {
                n.name.clone()
            } else {
                format!("{}.{s}", n.name)
            }));
        }
        nx += kind.n_states();
    }

    // Outputs.
    let mut out_ports = vec![];
    let mut out_slot = vec![];
    let mut target = vec![];
    let ot = match t.get("outputs") {
        Some(toml::Value::Table(o)) if !o.is_empty() => o,
        _ => {
            return Err(derr(
                "outputs",
                "missing: a diagram needs outputs = { signal = \"unit signal\" }",
            ))
        }
    };
    for (local, spec) in ot {
        let f = format!("outputs.{local}");
        let (signal, init) = match spec {
            toml::Value::String(s) => (s.clone(), None),
            toml::Value::Table(d) => signal_table(
                d,
                &f,
                "expected signal = \"...\" and init = \"target\" | \"free\"",
                |k, v| match (k, v.as_str()) {
                    ("init", Some("target")) => Some(true),
                    ("init", Some("free")) => Some(false),
                    _ => None,
                },
            )?,
            _ => return Err(derr(&f, "must be a unit signal name or { signal, init }")),
        };
        let &w = writer
            .get(local)
            .ok_or_else(|| derr(&f, format!("no block writes signal '{local}'")))?;
        if w < n_in {
            return Err(derr(
                &f,
                format!("'{local}' is an input; an output must be written by a block"),
            ));
        }
        read[w] = true;
        let is_target = init.unwrap_or(TARGET_SIGNALS.contains(&signal.as_str()));
        out_slot.push(w as u32);
        target.push(is_target);
        out_ports.push((local.clone(), signal, is_target));
    }
    for (k, n) in nodes.iter().enumerate() {
        if !read[n_in + k] {
            return Err(derr(
                format!("{}.out", n.label()),
                format!(
                    "signal '{}' is read by no block and is not an output (dangling)",
                    n.out
                ),
            ));
        }
    }

    // Evaluation order: a node depends on the writers of its inputs when it feeds through.
    let nn = nodes.len();
    let deps_of = |steady: bool, torn: &[bool]| -> Vec<Vec<usize>> {
        (0..nn)
            .map(|k| {
                let kind = nodes[k].info.kind;
                let ft = if steady {
                    kind.steady_feedthrough() && !torn[k]
                } else {
                    kind.feedthrough()
                };
                if !ft {
                    return vec![];
                }
                skeleton[k]
                    .ins
                    .iter()
                    .filter(|&&s| (s as usize) >= n_in)
                    .map(|&s| s as usize - n_in)
                    .collect()
            })
            .collect()
    };
    let no_tear = vec![false; nn];
    let deps = deps_of(false, &no_tear);
    let order = match topo(&deps) {
        Ok(o) => o,
        Err(left) => {
            let cyc = find_cycle(&deps, &left);
            let names: Vec<String> = cyc
                .iter()
                .map(|&k| format!("'{}'", nodes[k].name))
                .collect();
            return Err(derr(
                format!("block '{}'", nodes[cyc[0]].name),
                format!(
                    "algebraic loop with no state: {} -> '{}' (put a lag, integrator or other block with a state in the loop)",
                    names.join(" -> "),
                    nodes[cyc[0]].name
                ),
            ));
        }
    };
    // Nodes the outputs depend on algebraically.
    let mut need = vec![false; nn];
    let mut stack: Vec<usize> = out_slot.iter().map(|&s| s as usize - n_in).collect();
    while let Some(k) = stack.pop() {
        if need[k] {
            continue;
        }
        need[k] = true;
        stack.extend(deps[k].iter().copied());
    }
    let out_order: Vec<u32> = order
        .iter()
        .filter(|&&k| need[k])
        .map(|&k| k as u32)
        .collect();
    // Feed-through of the input ports.
    let mut in_ft = vec![false; n_in];
    for k in 0..nn {
        if need[k] && nodes[k].info.kind.feedthrough() {
            for &s in &skeleton[k].ins {
                if (s as usize) < n_in {
                    in_ft[s as usize] = true;
                }
            }
        }
    }

    // Steady-state order, tearing loops through lags.
    let mut torn = vec![false; nn];
    let steady_order = loop {
        let d = deps_of(true, &torn);
        match topo(&d) {
            Ok(o) => break o,
            Err(left) => {
                let cyc = find_cycle(&d, &left);
                match cyc.iter().find(|&&k| nodes[k].info.kind.tearable()) {
                    Some(&k) => torn[k] = true,
                    None => {
                        return Err(derr(
                            format!("block '{}'", nodes[cyc[0]].name),
                            "steady-state loop with no lag to solve it through".to_string(),
                        ))
                    }
                }
            }
        }
    };
    let mut unknowns = vec![];
    for (k, nd) in nodes.iter().enumerate() {
        let x0_given = nd
            .info
            .fields
            .iter()
            .position(|f| f.name == "x0")
            .is_some_and(|i| nd.fields[i].is_some());
        if nd.info.kind.integrating() && !x0_given {
            unknowns.push(Unknown::Integrator(k as u32));
        }
    }
    for (k, &t) in torn.iter().enumerate() {
        if t {
            unknowns.push(Unknown::Tear(k as u32));
        }
    }
    let refs: Vec<usize> = (0..nn)
        .filter(|&k| nodes[k].info.kind == Kind::Reference)
        .collect();
    let n_targets = target.iter().filter(|&&t| t).count();
    if refs.len() != n_targets {
        let tnames: Vec<&str> = out_ports
            .iter()
            .filter(|o| o.2)
            .map(|o| o.0.as_str())
            .collect();
        let rnames: Vec<String> = refs
            .iter()
            .map(|&k| format!("'{}'", nodes[k].name))
            .collect();
        return Err(derr(
            if refs.is_empty() { "outputs".to_string() } else { format!("block '{}'", nodes[refs[0]].name) },
            format!(
                "{} target output(s) fixed at initialisation ({}) need as many reference blocks, found {} ({}); declare a non-target output with {{ signal = \"…\", init = \"free\" }}",
                n_targets,
                if tnames.is_empty() { "none".to_string() } else { tnames.join(", ") },
                refs.len(),
                if rnames.is_empty() { "none".to_string() } else { rnames.join(", ") }
            ),
        ));
    }
    unknowns.extend(refs.iter().map(|&k| Unknown::Reference(k as u32)));

    // Ports.
    let mut ports: Vec<Port> = inputs
        .iter()
        .enumerate()
        .map(|(i, d)| Port {
            name: intern::str(&d.local),
            signal: intern::str(&d.signal),
            optional: d.optional,
            dir: Dir::In,
            init: PortInit::Needs,
            feedthrough: in_ft[i],
            doc: "diagram input",
        })
        .collect();
    for (local, signal, is_target) in &out_ports {
        ports.push(Port {
            name: intern::str(local),
            signal: intern::str(signal),
            optional: false,
            dir: Dir::Out,
            init: if *is_target {
                PortInit::Needs
            } else {
                PortInit::Gives
            },
            feedthrough: false,
            doc: if *is_target {
                "diagram output (target: its initial value is fixed by the machine)"
            } else {
                "diagram output"
            },
        });
    }

    Ok(DiagramDef {
        title,
        source: t.clone(),
        specs: intern::specs(specs),
        allowed,
        defaults,
        ports: intern::ports(ports),
        n_in,
        out_slot,
        target,
        state_names: intern::names(state_names),
        nodes,
        skeleton,
        order: order.iter().map(|&k| k as u32).collect(),
        out_order,
        steady_order: steady_order.iter().map(|&k| k as u32).collect(),
        unknowns,
        signals,
        n_states: nx,
        n_limits: nlim,
    })
}

/// Kahn's algorithm in declaration order; on a cycle returns the nodes left over.
fn topo(deps: &[Vec<usize>]) -> Result<Vec<usize>, Vec<usize>> {
    let n = deps.len();
    let mut done = vec![false; n];
    let mut order = Vec::with_capacity(n);
    while order.len() < n {
        match (0..n).find(|&b| !done[b] && deps[b].iter().all(|&a| done[a])) {
            Some(b) => {
                done[b] = true;
                order.push(b);
            }
            None => return Err((0..n).filter(|&b| !done[b]).collect()),
        }
    }
    Ok(order)
}

/// A cycle among the nodes `left` over by [`topo`] (each has a dependency among them), in
/// signal-flow order.
fn find_cycle(deps: &[Vec<usize>], left: &[usize]) -> Vec<usize> {
    let inleft = |k: usize| left.contains(&k);
    let mut path = vec![left[0]];
    loop {
        let last = *path.last().expect("non-empty");
        let Some(&next) = deps[last].iter().find(|&&a| inleft(a)) else {
            return path;
        };
        if let Some(p) = path.iter().position(|&k| k == next) {
            let mut cyc = path[p..].to_vec();
            cyc.reverse();
            return cyc;
        }
        path.push(next);
    }
}
