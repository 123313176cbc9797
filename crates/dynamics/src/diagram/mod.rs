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
//! An exciter diagram may declare which of its parameters plays each exciter role (gain, field
//! time constant, ceiling, …) in an optional `[exciter_roles]` table, e.g. `gain = "k"`,
//! `transient_gain_reduction = { ratio = "ta_tb", lag = "tb" }`, `supply_ceiling = { none =
//! "constant limits" }` ([`crate::models::exciter::roles::ExciterRoles::from_toml`]); the block
//! then answers [`Block::exciter_roles`](crate::block::Block::exciter_roles) like a built-in
//! exciter. A role naming an undeclared parameter is a definition error.
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
//! state outside a limit names the block and the limit. A `reference`'s `offset` (a set-point
//! nuisance) is left out of the solve and of its check, and acts from t = 0, as the built-in
//! models' offsets do. Once the tolerance is met, up to two more Newton steps polish the
//! solution to rounding: the sensitivities take the initial state's derivatives as central
//! differences of this solve.
//!
//! **Sensitivities.** A diagram has dual equations ([`crate::sens`]): its fields are evaluated
//! on the seeded parameters by the function the compilation uses, the nodes by the same generic
//! evaluation as the simulation ([`prim`]).
//!
//! **Layout.** `def.rs` holds the types of a parsed definition; `parse.rs` reads the
//! TOML (parameters, inputs, blocks); `graph.rs` wires the signals, checks the graph (writers,
//! dangling signals, algebraic loops) and orders the evaluation; `compile.rs` evaluates the
//! fields at the parameter values into the simulated nodes; `sim.rs` is the [`Diagram`] block
//! (evaluation, events, the [`Block`](crate::block::Block) implementation); `init.rs` solves the
//! steady state; `describe.rs` draws a diagram and lists the primitives.

pub mod expr;
pub mod intern;
pub mod prim;

mod compile;
mod def;
mod describe;
mod graph;
mod init;
mod parse;
mod sim;

pub use def::{DefError, DiagramDef, DiagramParams, NodeDef, Unknown};
pub use describe::{describe_primitives, to_dot};
pub use parse::{from_table, parse_definition};
pub use sim::Diagram;

/// Model name of a diagram in unit files.
pub const MODEL: &str = "diagram";

/// Unit signals whose value the machine fixes at initialisation: a diagram output wired to one
/// is a *target* (solved for) unless declared otherwise.
pub const TARGET_SIGNALS: [&str; 2] = ["efd", "pm"];
