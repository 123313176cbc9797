//! The [`Diagram`] block: its scratch signals, the evaluation of the compiled nodes in order,
//! the non-windup limit events and modes, and the [`Block`] implementation (initialisation
//! through [`super::init`]).

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use super::prim::{self, Kind, Node, Sig};
use super::{init, to_dot, DiagramDef, DiagramParams, MODEL};
use crate::block::{Block, InitPoint, Io, ModelError, Port};
use crate::models::limiter::NonWindup;

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
