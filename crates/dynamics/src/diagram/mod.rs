//! User-defined control models: block diagrams declared in TOML, simulated, initialised and
//! calibrated like the built-in models (paper 000: Itaipu's AVR, PSS and governor are
//! user-defined diagrams).
//!
//! A diagram is a block of model `"diagram"` in a unit file, in any section (`[exciter]`,
//! `[pss]`, `[governor]`, `[[block]]`). Its definition is inline (`[exciter.diagram]`) or a
//! file of its own (`diagram = "sexs.diagram.toml"`, relative to the unit file); the parameter
//! values are keys of the section, as for a built-in model:
//!
//! ```toml
//! [exciter]
//! model = "diagram"
//! diagram = "sexs.diagram.toml"
//! k = 100.0                          # every declared parameter without a default
//! t_e = 0.05
//! ```
//!
//! The definition:
//!
//! ```toml
//! title = "SEXS as a diagram"
//! inputs = { vt = "v_term", vs = { signal = "vs", optional = true } }   # local name = unit signal
//! outputs = { efd = "efd" }          # diagram signal = unit signal (E_fd, P_m: targets at t = 0)
//! [params]
//! k = { range = [30.0, 400.0], unit = "pu", doc = "gain", min = 0.0 }
//! v_ref_offset = { default = 0.0, unit = "pu", doc = "reference offset (nuisance)" }
//! [[block]]
//! name = "vref"                      # optional, defaults to `out`
//! type = "reference"
//! out = "vref"
//! offset = "v_ref_offset"
//! [[block]]
//! type = "sum"
//! in = ["vref", "vt", "vs"]
//! signs = "+-+"
//! out = "verr"
//! # …
//! ```
//!
//! Primitives and their equations: [`prim`]. A field is a number or an expression of the
//! parameters ([`expr`]). Parameters are addressed `exciter.k` by the calibration spec and
//! everything else, like any model's.
//!
//! **Evaluation.** At load time the blocks are put in an order where each block's algebraic
//! (feed-through) inputs come first; an algebraic loop is refused, naming the blocks on it.
//! The step loop evaluates the compiled blocks in that order into a scratch array owned by the
//! block (no allocation). `outputs` evaluates only the blocks the outputs depend on
//! algebraically; `derivatives` evaluates them all with the whole bus current. An input port is
//! declared feed-through when an algebraic path leads from it to an output, so the unit orders
//! the diagram after the blocks that write it.
//!
//! **Initialisation** (steady state at t = 0): every state derivative is zero. In steady state a
//! lag is a gain, a lead-lag passes its input, a washout or derivative outputs 0, and an
//! integrator (`integrator`, `pi`, `pid`) has input 0 and a free state. The unknowns are the
//! integrators' states, the `reference` values (one per *target* output: an output whose value
//! the machine fixes, E_fd or P_m by default) and, where a steady-state loop passes through lags
//! only, one lag state per loop; the equations are the integrators' inputs = 0, the loops'
//! consistency and the target outputs = their values. Newton's method with a finite-difference
//! Jacobian solves them (a linear diagram in one step). A singular Jacobian names the block
//! whose state is not determined (an integrator in a loop with no free reference); a steady
//! state outside a limit names the block and the limit.

pub mod expr;
pub mod intern;
pub mod prim;

mod init;

use std::collections::HashMap;
use std::fmt::Write as _;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use crate::block::{Block, Dir, InitPoint, Io, ModelError, Port, PortInit};
use crate::models::limiter::NonWindup;
use crate::params::{ParamSet, ParamSpec};
use expr::Expr;
use prim::{Kind, Node, PrimInfo, Sig};

/// Model name of a diagram in unit files.
pub const MODEL: &str = "diagram";

/// Unit signals whose value the machine fixes at initialisation: a diagram output wired to one
/// is a *target* (solved for) unless declared otherwise.
pub const TARGET_SIGNALS: [&str; 2] = ["efd", "pm"];

/// A definition error: the field (`params.k`, `block 'exc' (lag).t`, `outputs.efd`, …) and
/// the message.
#[derive(Debug, Clone, PartialEq)]
pub struct DefError {
    pub field: String,
    pub msg: String,
}

fn derr(field: impl Into<String>, msg: impl Into<String>) -> DefError {
    DefError {
        field: field.into(),
        msg: msg.into(),
    }
}

/// A block of the definition, as declared.
#[derive(Debug, Clone)]
pub struct NodeDef {
    pub name: String,
    pub info: &'static PrimInfo,
    pub ins: Vec<String>,
    pub out: String,
    /// One per [`PrimInfo::fields`]: the expression given, or `None` (the default).
    pub fields: Vec<Option<Expr>>,
    /// The text of each field as written (for drawings and messages).
    pub field_text: Vec<Option<String>>,
    /// Sum gains, or pwl breakpoints followed by values.
    pub list: Vec<Expr>,
    /// Product exponents (±1).
    pub exps: Vec<f64>,
    pub windup: bool,
    /// Has a non-windup limited state (events and modes).
    pub limited: bool,
}

impl NodeDef {
    /// `block 'name' (type)`, for messages.
    pub fn label(&self) -> String {
        format!("block '{}' ({})", self.name, self.info.name)
    }
}

/// What the initialisation solves for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Unknown {
    /// The state of an integrating block; equation: its input = 0.
    Integrator(u32),
    /// A lag-type state tearing a steady-state loop; equation: state = its steady value.
    Tear(u32),
    /// A reference value; equations: the target outputs.
    Reference(u32),
}

/// A parsed, checked diagram: structure only (parameter values live in the block).
#[derive(Debug)]
pub struct DiagramDef {
    pub title: String,
    /// The definition as read (written back inline by `unit_to_toml`).
    pub source: toml::Table,
    pub specs: &'static [ParamSpec],
    /// Allowed range of each parameter (declared `min`, `max`; default ±∞).
    pub allowed: Vec<(f64, f64)>,
    /// Value when the unit file omits the parameter.
    pub defaults: Vec<Option<f64>>,
    pub ports: &'static [Port],
    pub n_in: usize,
    /// Scratch slot of each output port.
    pub out_slot: Vec<u32>,
    /// Is each output port a target?
    pub target: Vec<bool>,
    pub state_names: &'static [&'static str],
    pub nodes: Vec<NodeDef>,
    /// Compiled wiring (values filled at compilation).
    pub skeleton: Vec<Node>,
    /// Evaluation order of all nodes, and of those the outputs depend on.
    pub order: Vec<u32>,
    pub out_order: Vec<u32>,
    /// Steady-state evaluation order and the unknowns of the initialisation.
    pub steady_order: Vec<u32>,
    pub unknowns: Vec<Unknown>,
    /// Signal name of each scratch slot (inputs, then one per node).
    pub signals: Vec<String>,
    pub n_states: usize,
    pub n_limits: usize,
}

/// Parameter values of a diagram (the table is the definition's).
#[derive(Debug, Clone, PartialEq)]
pub struct DiagramParams {
    specs: &'static [ParamSpec],
    pub values: Vec<f64>,
}

impl ParamSet for DiagramParams {
    fn specs(&self) -> &'static [ParamSpec] {
        self.specs
    }
    fn get(&self, index: usize) -> f64 {
        self.values.get(index).copied().unwrap_or(f64::NAN)
    }
    fn set(&mut self, index: usize, value: f64) {
        if let Some(v) = self.values.get_mut(index) {
            *v = value;
        }
    }
}

/// Scratch signals. Written through `&self` (the block interface evaluates outputs and
/// derivatives on a shared reference), hence atomics; a unit is simulated by one thread at a
/// time, so relaxed ordering is enough and the loads and stores are plain moves.
#[derive(Debug, Default)]
struct Scratch(Box<[AtomicU64]>);

impl Scratch {
    fn new(n: usize) -> Self {
        Self((0..n).map(|_| AtomicU64::new(0)).collect())
    }
    #[inline(always)]
    fn set(&self, i: u32, v: f64) {
        self.0[i as usize].store(v.to_bits(), Ordering::Relaxed);
    }
}

impl Clone for Scratch {
    fn clone(&self) -> Self {
        Self(
            self.0
                .iter()
                .map(|a| AtomicU64::new(a.load(Ordering::Relaxed)))
                .collect(),
        )
    }
}

impl Sig for Scratch {
    #[inline(always)]
    fn s(&self, i: u32) -> f64 {
        f64::from_bits(self.0[i as usize].load(Ordering::Relaxed))
    }
}

/// A user-defined diagram as a [`Block`].
#[derive(Debug, Clone)]
pub struct Diagram {
    def: Arc<DiagramDef>,
    pub p: DiagramParams,
    nodes: Vec<Node>,
    modes: Vec<NonWindup>,
    scratch: Scratch,
}

impl Diagram {
    /// A diagram with its parameters at their defaults (NaN where none is declared).
    pub fn new(def: Arc<DiagramDef>) -> Self {
        let values = def.defaults.iter().map(|d| d.unwrap_or(f64::NAN)).collect();
        Self {
            p: DiagramParams {
                specs: def.specs,
                values,
            },
            nodes: def.skeleton.clone(),
            modes: vec![NonWindup::default(); def.n_limits],
            scratch: Scratch::new(def.signals.len() + 1),
            def,
        }
    }

    /// The definition.
    pub fn def(&self) -> &DiagramDef {
        &self.def
    }

    /// The `reference` blocks' values solved at the last initialisation, by block name.
    pub fn reference_values(&self) -> Vec<(String, f64)> {
        self.def
            .nodes
            .iter()
            .zip(&self.nodes)
            .filter(|(d, _)| d.info.kind == Kind::Reference)
            .map(|(d, n)| (d.name.clone(), n.v[prim::slot::REF_R]))
            .collect()
    }

    /// Nodes with their fields evaluated at the current parameter values and checked.
    fn compile(&self) -> Result<Vec<Node>, ModelError> {
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

    #[inline(always)]
    fn load_inputs(&self, io: &Io) {
        for i in 0..self.def.n_in {
            self.scratch.set(i as u32, io.get(i));
        }
    }

    /// Scratch slot remembering the time of the last output evaluation (for the event
    /// functions, which the block interface calls without the time).
    #[inline(always)]
    fn t_slot(&self) -> u32 {
        self.def.signals.len() as u32
    }

    #[inline(always)]
    fn eval(&self, t: f64, x: &[f64], order: &[u32]) {
        for &k in order {
            let n = &self.nodes[k as usize];
            let o = n.x as usize;
            let y = n.output(t, &x[o..], &self.scratch, true);
            self.scratch.set(n.out, y);
        }
    }

    #[inline(always)]
    fn lim(&self, n: &Node) -> Option<&NonWindup> {
        if n.lim == u32::MAX {
            None
        } else {
            Some(&self.modes[n.lim as usize])
        }
    }

    /// A Graphviz drawing of the diagram (dot text).
    pub fn to_dot(&self) -> String {
        to_dot(&self.def)
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

impl Block for Diagram {
    crate::block_common!();

    fn model(&self) -> &'static str {
        MODEL
    }
    fn ports(&self) -> &'static [Port] {
        self.def.ports
    }
    fn state_names(&self) -> &'static [&'static str] {
        self.def.state_names
    }
    fn validate(&self) -> Result<(), ModelError> {
        self.compile().map(|_| ())
    }

    fn init(&mut self, _op: &InitPoint, x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        self.nodes = self.compile()?;
        self.modes
            .iter_mut()
            .for_each(|m| *m = NonWindup::default());
        self.load_inputs(io);
        let def = self.def.clone();
        let targets: Vec<f64> = (0..def.out_slot.len())
            .filter(|&k| def.target[k])
            .map(|k| io.get(def.n_in + k))
            .collect();
        init::steady_state(&def, &mut self.nodes, &self.scratch, &targets, x)?;
        // Check the dynamics at the solution: every derivative zero, the targets met.
        self.eval(0.0, x, &def.order);
        let mut dx = vec![0.0; x.len()];
        for n in &self.nodes {
            let o = n.x as usize;
            n.derivatives(&x[o..], &self.scratch, self.lim(n), &mut dx[o..]);
        }
        for (k, nd) in def.nodes.iter().enumerate() {
            let n = &self.nodes[k];
            for j in 0..nd.info.states.len() {
                let i = n.x as usize + j;
                if !(dx[i].abs() <= 1e-7 * (1.0 + x[i].abs())) {
                    return Err(ModelError::Init(format!(
                        "{}: not in steady state at t = 0 (d{}/dt = {:.3e})",
                        nd.label(),
                        def.state_names[i],
                        dx[i]
                    )));
                }
            }
        }
        let mut ti = 0;
        for (k, &slot) in def.out_slot.iter().enumerate() {
            let y = self.scratch.s(slot);
            if def.target[k] {
                let want = targets[ti];
                ti += 1;
                if !((y - want).abs() <= 1e-8 * (1.0 + want.abs())) {
                    return Err(ModelError::Init(format!(
                        "output '{}' = {y:.6} at t = 0 cannot meet its initial value {want:.6} (a limit or a reference offset?)",
                        def.ports[def.n_in + k].name
                    )));
                }
            } else {
                io.set(def.n_in + k, y);
            }
        }
        Ok(())
    }

    #[inline]
    fn outputs(&self, t: f64, x: &[f64], io: &mut Io) {
        self.load_inputs(io);
        self.scratch.set(self.t_slot(), t);
        self.eval(t, x, &self.def.out_order);
        for (k, &slot) in self.def.out_slot.iter().enumerate() {
            io.set(self.def.n_in + k, self.scratch.s(slot));
        }
    }

    #[inline]
    fn derivatives(&self, t: f64, x: &[f64], io: &Io, dx: &mut [f64]) {
        self.load_inputs(io);
        self.eval(t, x, &self.def.order);
        for n in &self.nodes {
            let o = n.x as usize;
            n.derivatives(&x[o..], &self.scratch, self.lim(n), &mut dx[o..]);
        }
    }

    fn n_events(&self) -> usize {
        2 * self.def.n_limits
    }
    fn events(&self, x: &[f64], io: &Io, g: &mut [f64]) {
        if self.def.n_limits == 0 {
            return;
        }
        self.load_inputs(io);
        // The event functions are evaluated where the outputs were last.
        self.eval(self.scratch.s(self.t_slot()), x, &self.def.order);
        for n in &self.nodes {
            if n.lim == u32::MAX {
                continue;
            }
            let o = n.x as usize;
            let (lo, hi) = n.limits();
            let f = n.free_rate(&x[o..], &self.scratch);
            let e = 2 * n.lim as usize;
            self.modes[n.lim as usize].events(x[o], f, lo, hi, &mut g[e..e + 2]);
        }
    }
    fn update_modes(&mut self, x: &mut [f64], io: &Io) -> bool {
        if self.def.n_limits == 0 {
            return false;
        }
        self.load_inputs(io);
        self.eval(self.scratch.s(self.t_slot()), x, &self.def.order);
        let mut changed = false;
        for n in &self.nodes {
            if n.lim == u32::MAX {
                continue;
            }
            let o = n.x as usize;
            let (lo, hi) = n.limits();
            let f = n.free_rate(&x[o..], &self.scratch);
            changed |= self.modes[n.lim as usize].update(&mut x[o], f, lo, hi);
        }
        changed
    }

    fn diagram(&self) -> Option<&Diagram> {
        Some(self)
    }
}

// ---------------------------------------------------------------------------------------------
// Parsing

fn as_f64(v: &toml::Value) -> Option<f64> {
    match v {
        toml::Value::Float(f) => Some(*f),
        toml::Value::Integer(i) => Some(*i as f64),
        _ => None,
    }
}

/// Parses and checks a diagram definition. Errors name the field (`block 'x' (lag).t`, …).
pub fn parse_definition(t: &toml::Table) -> Result<DiagramDef, DefError> {
    for key in t.keys() {
        if !["title", "inputs", "outputs", "params", "block"].contains(&key.as_str()) {
            return Err(derr(
                key.as_str(),
                "unknown key (expected title, inputs, outputs, [params], [[block]])",
            ));
        }
    }
    let title = match t.get("title") {
        None => String::new(),
        Some(toml::Value::String(s)) => s.clone(),
        Some(_) => return Err(derr("title", "must be a string")),
    };

    // Parameters.
    let mut pnames: Vec<String> = vec![];
    let mut specs = vec![];
    let mut allowed = vec![];
    let mut defaults = vec![];
    if let Some(v) = t.get("params") {
        let pt = v
            .as_table()
            .ok_or_else(|| derr("params", "must be a table of parameter declarations"))?;
        for (name, decl) in pt {
            let f = format!("params.{name}");
            if !valid_name(name) {
                return Err(derr(&f, "a parameter name is letters, digits and _"));
            }
            let (mut default, mut range, mut lo, mut hi) =
                (None, None, f64::NEG_INFINITY, f64::INFINITY);
            let (mut unit, mut doc, mut alias) = ("-".to_string(), String::new(), name.clone());
            match decl {
                v if as_f64(v).is_some() => default = as_f64(v),
                toml::Value::Table(d) => {
                    for (k, v) in d {
                        let fk = format!("{f}.{k}");
                        let num = || as_f64(v).ok_or_else(|| derr(&fk, "must be a number"));
                        let text = || {
                            v.as_str()
                                .map(str::to_string)
                                .ok_or_else(|| derr(&fk, "must be a string"))
                        };
                        match k.as_str() {
                            "default" | "value" => default = Some(num()?),
                            "min" => lo = num()?,
                            "max" => hi = num()?,
                            "unit" => unit = text()?,
                            "doc" => doc = text()?,
                            "alias" => alias = text()?,
                            "range" => {
                                let a = v.as_array().filter(|a| a.len() == 2);
                                let r = a.and_then(|a| Some((as_f64(&a[0])?, as_f64(&a[1])?)));
                                match r {
                                    Some((a, b)) if a <= b => range = Some((a, b)),
                                    _ => return Err(derr(&fk, "must be [low, high] with low <= high")),
                                }
                            }
                            _ => {
                                return Err(derr(
                                    &fk,
                                    "unknown key (expected default, range, min, max, unit, doc, alias)",
                                ))
                            }
                        }
                    }
                }
                _ => return Err(derr(&f, "must be a number (the default) or a table { default, range, min, max, unit, doc }")),
            }
            if !(lo <= hi) {
                return Err(derr(&f, format!("min {lo} exceeds max {hi}")));
            }
            if let Some(d) = default {
                if !(d >= lo && d <= hi) {
                    return Err(derr(
                        &f,
                        format!("default {d} lies outside [min, max] = [{lo}, {hi}]"),
                    ));
                }
            }
            if default.is_none() && name.ends_with("_offset") {
                default = Some(0.0);
            }
            let range = range.unwrap_or_else(|| match default {
                Some(d) if d != 0.0 => {
                    let (a, b) = (0.5 * d, 2.0 * d);
                    (a.min(b), a.max(b))
                }
                _ if lo.is_finite() && hi.is_finite() => (lo, hi),
                _ => (0.0, 0.0),
            });
            let typical = default.unwrap_or(0.5 * (range.0 + range.1));
            specs.push(ParamSpec {
                name: intern::str(name),
                alias: intern::str(&alias),
                unit: intern::str(&unit),
                doc: intern::str(if doc.is_empty() {
                    "diagram parameter"
                } else {
                    &doc
                }),
                typical,
                range,
            });
            pnames.push(name.clone());
            allowed.push((lo, hi));
            defaults.push(default);
        }
    }
    let lookup = |n: &str| pnames.iter().position(|p| p == n);

    // Inputs.
    struct InDecl {
        local: String,
        signal: String,
        optional: bool,
    }
    let mut inputs: Vec<InDecl> = vec![];
    if let Some(v) = t.get("inputs") {
        let it = v
            .as_table()
            .ok_or_else(|| derr("inputs", "must be a table { name = \"unit signal\" }"))?;
        for (local, spec) in it {
            let f = format!("inputs.{local}");
            let (signal, optional) = match spec {
                toml::Value::String(s) => (s.clone(), false),
                toml::Value::Table(d) => {
                    let mut sig = None;
                    let mut optional = false;
                    for (k, v) in d {
                        match (k.as_str(), v) {
                            ("signal", toml::Value::String(s)) => sig = Some(s.clone()),
                            ("optional", toml::Value::Boolean(b)) => optional = *b,
                            _ => {
                                return Err(derr(
                                    format!("{f}.{k}"),
                                    "expected signal = \"...\" and optional = true|false",
                                ))
                            }
                        }
                    }
                    (
                        sig.ok_or_else(|| derr(&f, "needs signal = \"...\""))?,
                        optional,
                    )
                }
                _ => {
                    return Err(derr(
                        &f,
                        "must be a unit signal name or { signal, optional }",
                    ))
                }
            };
            inputs.push(InDecl {
                local: local.clone(),
                signal,
                optional,
            });
        }
    }

    // Blocks.
    let arr = match t.get("block") {
        Some(toml::Value::Array(a)) => a.clone(),
        Some(_) => return Err(derr("block", "must be an array of tables ([[block]])")),
        None => return Err(derr("block", "missing: a diagram needs [[block]] entries")),
    };
    let mut nodes: Vec<NodeDef> = vec![];
    for (k, item) in arr.iter().enumerate() {
        let bt = item
            .as_table()
            .ok_or_else(|| derr(format!("block[{k}]"), "must be a table"))?;
        let out = match bt.get("out") {
            Some(toml::Value::String(s)) => s.clone(),
            _ => {
                let who = bt
                    .get("name")
                    .and_then(|v| v.as_str())
                    .map(|n| format!("block '{n}'"))
                    .unwrap_or(format!("block[{k}]"));
                return Err(derr(
                    format!("{who}.out"),
                    "missing: every block needs out = \"signal\"",
                ));
            }
        };
        let name = match bt.get("name") {
            None => out.clone(),
            Some(toml::Value::String(s)) => s.clone(),
            Some(_) => return Err(derr(format!("block[{k}].name"), "must be a string")),
        };
        let who = format!("block '{name}'");
        let ty = bt.get("type").and_then(|v| v.as_str()).ok_or_else(|| {
            derr(
                format!("{who}.type"),
                format!("missing (one of: {})", prim::names()),
            )
        })?;
        let info = prim::find(ty).ok_or_else(|| {
            derr(
                format!("{who}.type"),
                format!("unknown primitive '{ty}' (known: {})", prim::names()),
            )
        })?;
        let label = format!("block '{name}' ({})", info.name);
        if nodes.iter().any(|n| n.name == name) {
            return Err(derr(format!("{label}.name"), "two blocks have this name"));
        }
        let ins: Vec<String> = match bt.get("in") {
            None => vec![],
            Some(toml::Value::String(s)) => vec![s.clone()],
            Some(toml::Value::Array(a)) => a
                .iter()
                .map(|v| v.as_str().map(str::to_string))
                .collect::<Option<_>>()
                .ok_or_else(|| {
                    derr(
                        format!("{label}.in"),
                        "must be a signal name or a list of them",
                    )
                })?,
            Some(_) => {
                return Err(derr(
                    format!("{label}.in"),
                    "must be a signal name or a list of them",
                ))
            }
        };
        let arity_ok = match info.arity {
            prim::Arity::None => ins.is_empty(),
            prim::Arity::One => ins.len() == 1,
            prim::Arity::OneOrTime => ins.len() <= 1,
            prim::Arity::Exactly(n) => ins.len() == n,
            prim::Arity::AtLeast(n) => ins.len() >= n,
        };
        if !arity_ok {
            let want = match info.arity {
                prim::Arity::None => "no input".to_string(),
                prim::Arity::One => "one input".to_string(),
                prim::Arity::OneOrTime => "one input or none (the time)".to_string(),
                prim::Arity::Exactly(n) => format!("exactly {n} inputs"),
                prim::Arity::AtLeast(n) => format!("at least {n} input(s)"),
            };
            return Err(derr(
                format!("{label}.in"),
                format!("{} takes {want} (got {})", info.name, ins.len()),
            ));
        }
        let mut fields: Vec<Option<Expr>> = vec![None; info.fields.len()];
        let mut field_text: Vec<Option<String>> = vec![None; info.fields.len()];
        let mut list = vec![];
        let mut exps = vec![];
        let mut windup = false;
        let parse_expr = |v: &toml::Value, f: &str| -> Result<(Expr, String), DefError> {
            match v {
                toml::Value::String(s) => {
                    Expr::parse(s, &lookup)
                        .map(|e| (e, s.clone()))
                        .map_err(|m| {
                            derr(
                                f,
                                format!(
                                    "{m} (parameters: {})",
                                    if pnames.is_empty() {
                                        "none declared".to_string()
                                    } else {
                                        pnames.join(", ")
                                    }
                                ),
                            )
                        })
                }
                v => as_f64(v)
                    .map(|x| (Expr::Num(x), format!("{x}")))
                    .ok_or_else(|| derr(f, "must be a number or an expression of the parameters")),
            }
        };
        let (mut signs, mut gains, mut xs, mut ys) = (None, None, None, None);
        for (key, v) in bt {
            let f = format!("{label}.{key}");
            match key.as_str() {
                "name" | "type" | "in" | "out" => {}
                "signs" if info.kind == Kind::Sum => {
                    signs = Some(
                        v.as_str()
                            .ok_or_else(|| derr(&f, "must be a string of + and -"))?
                            .to_string(),
                    )
                }
                "gains" if info.kind == Kind::Sum => {
                    gains = Some(
                        v.as_array()
                            .ok_or_else(|| derr(&f, "must be a list"))?
                            .clone(),
                    )
                }
                "ops" if info.kind == Kind::Product => {
                    let s = v
                        .as_str()
                        .ok_or_else(|| derr(&f, "must be a string of * and /"))?;
                    if s.chars().count() != ins.len() || s.chars().any(|c| c != '*' && c != '/') {
                        return Err(derr(
                            &f,
                            format!("must be one * or / per input ({} inputs)", ins.len()),
                        ));
                    }
                    exps = s
                        .chars()
                        .map(|c| if c == '*' { 1.0 } else { -1.0 })
                        .collect();
                }
                "x" if info.kind == Kind::Pwl => {
                    xs = Some(
                        v.as_array()
                            .ok_or_else(|| derr(&f, "must be a list"))?
                            .clone(),
                    )
                }
                "y" if info.kind == Kind::Pwl => {
                    ys = Some(
                        v.as_array()
                            .ok_or_else(|| derr(&f, "must be a list"))?
                            .clone(),
                    )
                }
                "limit" if matches!(info.kind, Kind::Integrator | Kind::Pi | Kind::Pid) => {
                    windup = match v.as_str() {
                        Some("non_windup") => false,
                        Some("windup") => true,
                        _ => return Err(derr(&f, "must be \"non_windup\" or \"windup\"")),
                    }
                }
                _ => {
                    let Some(i) = info.fields.iter().position(|x| x.name == key) else {
                        let mut known: Vec<&str> = info.fields.iter().map(|x| x.name).collect();
                        known.extend(info.options.iter().map(|o| o.0));
                        return Err(derr(
                            &f,
                            format!(
                                "unknown field of {} (fields: {})",
                                info.name,
                                if known.is_empty() {
                                    "none".to_string()
                                } else {
                                    known.join(", ")
                                }
                            ),
                        ));
                    };
                    let (e, txt) = parse_expr(v, &f)?;
                    fields[i] = Some(e);
                    field_text[i] = Some(txt);
                }
            }
        }
        for (i, fs) in info.fields.iter().enumerate() {
            if fs.default.is_none() && fields[i].is_none() {
                return Err(derr(
                    format!("{label}.{}", fs.name),
                    format!("missing: {} needs {} ({})", info.name, fs.name, fs.doc),
                ));
            }
        }
        match info.kind {
            Kind::Sum => {
                if signs.is_some() && gains.is_some() {
                    return Err(derr(
                        format!("{label}.gains"),
                        "give signs or gains, not both",
                    ));
                }
                if let Some(g) = gains {
                    if g.len() != ins.len() {
                        return Err(derr(
                            format!("{label}.gains"),
                            format!("needs one gain per input ({})", ins.len()),
                        ));
                    }
                    for (k, v) in g.iter().enumerate() {
                        list.push(parse_expr(v, &format!("{label}.gains[{k}]"))?.0);
                    }
                } else {
                    let s = signs.unwrap_or_else(|| "+".repeat(ins.len()));
                    if s.chars().count() != ins.len() || s.chars().any(|c| c != '+' && c != '-') {
                        return Err(derr(
                            format!("{label}.signs"),
                            format!(
                                "must be one + or - per input ({} inputs, got \"{s}\")",
                                ins.len()
                            ),
                        ));
                    }
                    list = s
                        .chars()
                        .map(|c| Expr::Num(if c == '+' { 1.0 } else { -1.0 }))
                        .collect();
                }
            }
            Kind::Product if exps.is_empty() => exps = vec![1.0; ins.len()],
            Kind::Pwl => {
                let (Some(xs), Some(ys)) = (xs, ys) else {
                    return Err(derr(
                        format!("{label}.x"),
                        "pwl needs x = [..] and y = [..]",
                    ));
                };
                if xs.len() != ys.len() || xs.len() < 2 {
                    return Err(derr(
                        format!("{label}.y"),
                        "x and y need the same length, at least 2",
                    ));
                }
                for (k, v) in xs.iter().enumerate() {
                    list.push(parse_expr(v, &format!("{label}.x[{k}]"))?.0);
                }
                for (k, v) in ys.iter().enumerate() {
                    list.push(parse_expr(v, &format!("{label}.y[{k}]"))?.0);
                }
            }
            _ => {}
        }
        let has_limits = info
            .fields
            .iter()
            .position(|f| f.name == "min")
            .is_some_and(|a| fields[a].is_some() || fields[a + 1].is_some());
        let limited = has_limits
            && matches!(
                info.kind,
                Kind::Lag | Kind::Integrator | Kind::Pi | Kind::Pid
            )
            && !windup;
        nodes.push(NodeDef {
            name,
            info,
            ins,
            out,
            fields,
            field_text,
            list,
            exps,
            windup,
            limited,
        });
    }

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
            toml::Value::Table(d) => {
                let mut sig = None;
                let mut init = None;
                for (k, v) in d {
                    match (k.as_str(), v.as_str()) {
                        ("signal", Some(s)) => sig = Some(s.to_string()),
                        ("init", Some("target")) => init = Some(true),
                        ("init", Some("free")) => init = Some(false),
                        _ => {
                            return Err(derr(
                                format!("{f}.{k}"),
                                "expected signal = \"...\" and init = \"target\" | \"free\"",
                            ))
                        }
                    }
                }
                (sig.ok_or_else(|| derr(&f, "needs signal = \"...\""))?, init)
            }
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

fn valid_name(s: &str) -> bool {
    !s.is_empty()
        && s.chars().all(|c| c.is_alphanumeric() || c == '_')
        && !s.chars().next().is_some_and(|c| c.is_ascii_digit())
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

/// Reads a diagram definition from a TOML table and makes the block.
pub fn from_table(t: &toml::Table) -> Result<Diagram, DefError> {
    Ok(Diagram::new(Arc::new(parse_definition(t)?)))
}

// ---------------------------------------------------------------------------------------------
// Drawing

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
        let ins = match p.arity {
            prim::Arity::None => "none".to_string(),
            prim::Arity::One => "in = \"u\"".to_string(),
            prim::Arity::OneOrTime => "in = \"u\" or none (time)".to_string(),
            prim::Arity::Exactly(n) => format!("in = [{n} signals]"),
            prim::Arity::AtLeast(n) => format!("in = [{n} or more signals]"),
        };
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
