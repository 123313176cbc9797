//! The [`Diagram`] block: its scratch signals, the evaluation of the compiled nodes in order,
//! the non-windup limit events and modes, and the [`Block`] implementation (initialisation
//! through [`super::init`]).

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use super::prim::{self, Kind, Node, Sig};
use super::{init, to_dot, DiagramDef, DiagramParams, MODEL};
use crate::block::{Block, InitPoint, Io, ModelError, Port};
use crate::models::limiter::NonWindup;
use crate::sens::{seeded, Scalar, D};

/// derivatives on a shared reference), hence atomics; a unit is simulated by one thread at a
/// time, so relaxed ordering is enough and the loads and stores are plain moves.
#[derive(Debug, Default)]
pub(super) struct Scratch(Box<[AtomicU64]>);

impl Scratch {
    pub(super) fn new(n: usize) -> Self {
        Self((0..n).map(|_| AtomicU64::new(0)).collect())
    }
    #[inline(always)]
    pub(super) fn set(&self, i: u32, v: f64) {
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
    pub(super) def: Arc<DiagramDef>,
    pub p: DiagramParams,
    nodes: Vec<Node>,
    modes: Vec<NonWindup>,
    scratch: Scratch,
    /// The nodes' values and list values on dual numbers, after [`Block::seed_dual`].
    dual: Option<Box<DualValues>>,
}

/// Every node's values `v` and list values on dual numbers (a sensitivity pass).
#[derive(Debug, Clone)]
struct DualValues {
    v: Vec<[D; prim::NV]>,
    list: Vec<Vec<D>>,
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
            dual: None,
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

    /// Evaluates all nodes where the outputs were last: the event functions and the mode
    /// updates are called without the time.
    #[inline]
    fn eval_at_last_outputs(&self, x: &[f64], io: &Io) {
        self.load_inputs(io);
        self.eval(self.scratch.s(self.t_slot()), x, &self.def.order);
    }

    /// For a node with a non-windup limited state: its mode index, its state's offset in `x`,
    /// its limits and the rate its state would take without them. `None` for other nodes.
    #[inline]
    fn limited(&self, n: &Node, x: &[f64]) -> Option<(usize, usize, f64, f64, f64)> {
        if n.lim == u32::MAX {
            return None;
        }
        let o = n.x as usize;
        let (lo, hi) = n.limits();
        Some((
            n.lim as usize,
            o,
            lo,
            hi,
            n.free_rate(&x[o..], &self.scratch),
        ))
    }

    /// The nodes in `order` evaluated on dual numbers into `sig` (inputs loaded from `io`).
    fn eval_dual(&self, d: &DualValues, t: f64, x: &[D], io: &Io<D>, order: &[u32]) -> Vec<D> {
        let mut sig = vec![D::cst(0.0); self.def.signals.len()];
        for (i, s) in sig.iter_mut().enumerate().take(self.def.n_in) {
            *s = io.get(i);
        }
        for &k in order {
            let (k, n) = (k as usize, &self.nodes[k as usize]);
            let o = n.x as usize;
            let y = n.output_in(&d.v[k], &d.list[k], self.lim(n), t, &x[o..], &sig[..], true);
            sig[n.out as usize] = y;
        }
        sig
    }

    /// After the initialisation's solve: every derivative zero and the target outputs met at
    /// `x`; the free outputs written to `io`.
    fn check_steady_state(
        &self,
        def: &DiagramDef,
        x: &[f64],
        targets: &[f64],
        io: &mut Io,
    ) -> Result<(), ModelError> {
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
                        "output '{}' = {y:.6} at t = 0 cannot meet its initial value {want:.6} (a limit?)",
                        def.ports[def.n_in + k].name
                    )));
                }
            } else {
                io.set(def.n_in + k, y);
            }
        }
        Ok(())
    }

    /// A Graphviz drawing of the diagram (dot text).
    pub fn to_dot(&self) -> String {
        to_dot(&self.def)
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
        self.dual = None;
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
        // The references' offsets are nuisances added after the initialisation, as the
        // built-in models' set-point offsets are: the steady state was solved without them and
        // is checked without them (the offset then acts from t = 0).
        let offsets: Vec<(usize, f64)> = (self.nodes.iter().enumerate())
            .filter(|(_, n)| n.kind == Kind::Reference)
            .map(|(k, n)| (k, n.v[0]))
            .collect();
        for &(k, _) in &offsets {
            self.nodes[k].v[0] = 0.0;
        }
        let checked = self.check_steady_state(&def, x, &targets, io);
        for &(k, v) in &offsets {
            self.nodes[k].v[0] = v;
        }
        checked
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
        self.eval_at_last_outputs(x, io);
        for n in &self.nodes {
            let Some((m, o, lo, hi, f)) = self.limited(n, x) else {
                continue;
            };
            self.modes[m].events(x[o], f, lo, hi, &mut g[2 * m..2 * m + 2]);
        }
    }
    fn update_modes(&mut self, x: &mut [f64], io: &Io) -> bool {
        if self.def.n_limits == 0 {
            return false;
        }
        self.eval_at_last_outputs(x, io);
        let mut changed = false;
        for n in &self.nodes {
            let Some((m, o, lo, hi, f)) = self.limited(n, x) else {
                continue;
            };
            changed |= self.modes[m].update(&mut x[o], f, lo, hi);
        }
        changed
    }

    /// The values the initialisation solved and the equations then hold: every `reference`'s
    /// `r` and every `initial`'s held value, in block order.
    fn init_constants(&self) -> Vec<f64> {
        self.nodes
            .iter()
            .filter_map(|n| match n.kind {
                Kind::Reference => Some(n.v[prim::slot::REF_R]),
                Kind::Initial => Some(n.v[0]),
                _ => None,
            })
            .collect()
    }

    /// Every node's values on dual numbers: the fields' expressions evaluated on the seeded
    /// parameters (the derived constants with them), the initialisation's constants from
    /// `consts`.
    fn seed_dual(&mut self, lanes: &[Option<usize>], consts: &[D]) -> bool {
        let p: Vec<D> = self
            .p
            .values
            .iter()
            .enumerate()
            .map(|(i, &v)| seeded(v, lanes.get(i).copied().flatten()))
            .collect();
        let mut consts = consts.iter().copied();
        let mut d = DualValues {
            v: Vec::with_capacity(self.nodes.len()),
            list: Vec::with_capacity(self.nodes.len()),
        };
        for (nd, n) in self.def.nodes.iter().zip(&self.nodes) {
            let (mut v, list) = super::compile::node_values(nd, &p);
            let solved = match n.kind {
                Kind::Reference => Some(prim::slot::REF_R),
                Kind::Initial => Some(0),
                _ => None,
            };
            if let Some(i) = solved {
                v[i] = consts.next().unwrap_or(D::cst(n.v[i]));
            }
            d.v.push(v);
            d.list.push(list);
        }
        self.dual = Some(Box::new(d));
        true
    }

    fn outputs_dual(&self, t: f64, x: &[D], io: &mut Io<D>) {
        let Some(d) = &self.dual else { return };
        self.scratch.set(self.t_slot(), t);
        let sig = self.eval_dual(d, t, x, io, &self.def.out_order);
        for (k, &slot) in self.def.out_slot.iter().enumerate() {
            io.set(self.def.n_in + k, sig[slot as usize]);
        }
    }

    fn derivatives_dual(&self, t: f64, x: &[D], io: &Io<D>, dx: &mut [D]) {
        let Some(d) = &self.dual else { return };
        let sig = self.eval_dual(d, t, x, io, &self.def.order);
        for (k, n) in self.nodes.iter().enumerate() {
            let o = n.x as usize;
            n.derivatives_in(&d.v[k], &x[o..], &sig[..], self.lim(n), &mut dx[o..]);
        }
    }

    fn pin_dual(&self, x: &mut [D], _io: &Io<D>) {
        let Some(d) = &self.dual else { return };
        for (k, n) in self.nodes.iter().enumerate() {
            if let Some(l) = self.lim(n) {
                let (lo, hi) = prim::limits_of(n.kind, &d.v[k]);
                l.pin(&mut x[n.x as usize], lo, hi);
            }
        }
    }

    fn events_dual(&self, x: &[D], io: &Io<D>, g: &mut [D]) -> bool {
        let Some(d) = &self.dual else { return false };
        if self.def.n_limits == 0 {
            return true;
        }
        let t = self.scratch.s(self.t_slot());
        let sig = self.eval_dual(d, t, x, io, &self.def.order);
        for (k, n) in self.nodes.iter().enumerate() {
            let Some(l) = self.lim(n) else { continue };
            let (m, o) = (n.lim as usize, n.x as usize);
            let (lo, hi) = prim::limits_of(n.kind, &d.v[k]);
            let f = n.free_rate_in(&d.v[k], &x[o..], &sig[..]);
            l.events(x[o], f, lo, hi, &mut g[2 * m..2 * m + 2]);
        }
        true
    }

    fn diagram(&self) -> Option<&Diagram> {
        Some(self)
    }

    /// The definition's `[exciter_roles]` table (checked when the diagram was loaded).
    fn exciter_roles(&self) -> Option<crate::models::exciter::roles::ExciterRoles> {
        let names: Vec<String> = self.def.specs.iter().map(|s| s.name.to_string()).collect();
        super::parse::exciter_roles(&self.def.source, &names)
            .ok()
            .flatten()
    }
}
