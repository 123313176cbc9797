//! The types of a parsed, checked diagram definition ([`DiagramDef`] and its blocks,
//! [`NodeDef`]), its definition errors ([`DefError`]) and its parameter values
//! ([`DiagramParams`]).

use super::expr::Expr;
use super::prim::{Node, PrimInfo};
use crate::block::Port;
use crate::params::{ParamSet, ParamSpec};

/// A definition error: the field (`params.k`, `block 'exc' (lag).t`, `outputs.efd`, …) and
/// the message.
#[derive(Debug, Clone, PartialEq)]
pub struct DefError {
    pub field: String,
    pub msg: String,
}

pub(super) fn derr(field: impl Into<String>, msg: impl Into<String>) -> DefError {
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
    pub(super) specs: &'static [ParamSpec],
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
