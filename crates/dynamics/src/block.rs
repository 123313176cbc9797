//! The block abstraction: a model with states, parameters and named ports wired to signals.
//!
//! A unit (see [`crate::unit`]) is a set of blocks connected through named **signals** on a
//! shared bus (`efd`, `pm`, `speed`, `pe`, `vs`, …). Each block declares its ports; by default a
//! port is wired to the signal of the same name, and a unit model may rewire any port. Adding a
//! block (a two-mass shaft, a limiter, a measurement filter, a user-defined control diagram)
//! therefore never touches the machine code: it reads and writes signals.
//!
//! Evaluation of the right-hand side has two phases: [`Block::outputs`] for every block in an
//! order where the driver of every *feed-through* input comes first, then
//! [`Block::derivatives`] for every block with the whole bus known.
//!
//! Initialisation runs backwards from the measured operating point: the machine computes its
//! states and *gives* the values its inputs must have (`efd`, `pm`); each controller then
//! *needs* those values as targets for its own output and solves for its states and internal
//! references. [`PortInit`] says, per port, which side of that exchange the block is on.

use crate::params::ParamSet;
use crate::sens::{Scalar, D};

/// Direction of a port at run time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dir {
    /// Read from the bus.
    In,
    /// Written to the bus by [`Block::outputs`]; each signal has at most one writer.
    Out,
}

/// Role of a port during initialisation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PortInit {
    /// The value must be known before this block initialises (an input, or a target for an
    /// output that another block has fixed).
    Needs,
    /// This block's initialisation sets the value.
    Gives,
}

/// A named port.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Port {
    /// Port name.
    pub name: &'static str,
    /// Signal the port is wired to unless the unit file rewires it (usually the port name).
    pub signal: &'static str,
    /// For inputs: may be left undriven (then it reads 0), e.g. limiter or stabiliser signals.
    pub optional: bool,
    pub dir: Dir,
    pub init: PortInit,
    /// For inputs: does the value reach an output in the same instant (algebraic path)?
    pub feedthrough: bool,
    /// Meaning and unit, for documentation.
    pub doc: &'static str,
}

impl Port {
    pub const fn input(name: &'static str, init: PortInit, doc: &'static str) -> Self {
        Self {
            name,
            signal: name,
            optional: false,
            dir: Dir::In,
            init,
            feedthrough: false,
            doc,
        }
    }
    /// An input with a direct (algebraic) path to an output.
    pub const fn input_ft(name: &'static str, init: PortInit, doc: &'static str) -> Self {
        Self {
            name,
            signal: name,
            optional: false,
            dir: Dir::In,
            init,
            feedthrough: true,
            doc,
        }
    }
    pub const fn output(name: &'static str, init: PortInit, doc: &'static str) -> Self {
        Self {
            name,
            signal: name,
            optional: false,
            dir: Dir::Out,
            init,
            feedthrough: false,
            doc,
        }
    }
    /// Wires the port to `signal` by default.
    pub const fn wired(mut self, signal: &'static str) -> Self {
        self.signal = signal;
        self
    }
    /// Marks an input that reads 0 when nothing drives it.
    pub const fn optional(mut self) -> Self {
        self.optional = true;
        self
    }
}

/// A block's view of the bus: port `i` reads or writes signal `map[i]`. The bus holds `f64`
/// in a simulation and [`D`] in a sensitivity pass ([`Block::outputs_dual`]).
pub struct Io<'a, S = f64> {
    bus: &'a mut [S],
    map: &'a [usize],
}

impl<'a, S: Copy> Io<'a, S> {
    pub fn new(bus: &'a mut [S], map: &'a [usize]) -> Self {
        Self { bus, map }
    }
    /// Value on port `port`.
    #[inline(always)]
    pub fn get(&self, port: usize) -> S {
        self.bus[self.map[port]]
    }
    /// Writes port `port`.
    #[inline(always)]
    pub fn set(&mut self, port: usize, value: S) {
        self.bus[self.map[port]] = value;
    }
}

/// Operating point the machine initialises from, on the **machine base**.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InitPoint {
    /// Terminal voltage magnitude [pu].
    pub v_mag: f64,
    /// Terminal voltage angle [rad] in the nominal-frequency frame.
    pub v_ang: f64,
    /// Active power delivered [pu on machine base].
    pub p: f64,
    /// Reactive power delivered [pu on machine base].
    pub q: f64,
    /// Initial speed deviation Δω0 = (f0 − f_n)/f_n [pu].
    pub speed_dev: f64,
}

/// Why a block could not initialise or its parameters are invalid.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelError {
    /// A parameter violates a guard (field names the parameter).
    #[error("parameter {param}: {msg}")]
    BadParam { param: String, msg: String },
    /// Parameters are valid one by one but the model cannot start at the operating point.
    #[error("cannot initialise: {0}")]
    Init(String),
}

impl ModelError {
    pub fn param(param: &str, msg: impl Into<String>) -> Self {
        ModelError::BadParam {
            param: param.to_string(),
            msg: msg.into(),
        }
    }
}

/// A dynamic model with named ports. See the module documentation.
pub trait Block: Send + Sync {
    /// Model name as written in unit files, e.g. `GENSAE`, `SEXS`.
    fn model(&self) -> &'static str;
    /// Ports in index order.
    fn ports(&self) -> &'static [Port];
    /// State names in the order of the state slice.
    fn state_names(&self) -> &'static [&'static str];
    fn params(&self) -> &dyn ParamSet;
    fn params_mut(&mut self) -> &mut dyn ParamSet;
    /// Checks parameter guards (positive time constants, reactance ordering, …).
    fn validate(&self) -> Result<(), ModelError>;

    /// Sets the states `x` for steady state. Ports with [`PortInit::Needs`] hold known values;
    /// the block writes every [`PortInit::Gives`] port. `op` is the measured operating point
    /// (used by the machine; controllers ignore it).
    fn init(&mut self, op: &InitPoint, x: &mut [f64], io: &mut Io) -> Result<(), ModelError>;

    /// Writes the output ports from the states and (feed-through) inputs at time `t`.
    fn outputs(&self, t: f64, x: &[f64], io: &mut Io);

    /// Writes `dx/dt`. All signals on the bus are current.
    fn derivatives(&self, t: f64, x: &[f64], io: &Io, dx: &mut [f64]);

    /// Number of event functions (limiter guards) of this block.
    fn n_events(&self) -> usize {
        0
    }
    /// Event functions, positive while the current mode stays valid (see [`crate::integrate`]).
    fn events(&self, _x: &[f64], _io: &Io, _g: &mut [f64]) {}
    /// Re-evaluates discrete modes at the current point; may project `x`. Returns `true` when
    /// anything changed.
    fn update_modes(&mut self, _x: &mut [f64], _io: &Io) -> bool {
        false
    }

    /// Constants [`Block::init`] computed from the operating point and the parameters that the
    /// equations then hold fixed (an internal reference, GENCLS's E'). A sensitivity pass
    /// differentiates them with the initial state and gives them back to
    /// [`Block::seed_dual`]. Default: none.
    fn init_constants(&self) -> Vec<f64> {
        Vec::new()
    }

    /// Forward sensitivities: prepares the dual equations with respect to this block's
    /// parameters after [`Block::init`]: `lanes[i]` is the tangent lane of parameter `i` (spec
    /// order; `None`: held), `consts` the [`Block::init_constants`] with their derivatives.
    /// `false` when the block has no dual equations: the caller then falls back to
    /// differences.
    fn seed_dual(&mut self, _lanes: &[Option<usize>], _consts: &[D]) -> bool {
        false
    }

    /// [`Block::outputs`] on dual numbers (after [`Block::seed_dual`] returned `true`).
    fn outputs_dual(&self, _t: f64, _x: &[D], _io: &mut Io<D>) {}

    /// [`Block::derivatives`] on dual numbers (after [`Block::seed_dual`] returned `true`).
    fn derivatives_dual(&self, _t: f64, _x: &[D], _io: &Io<D>, _dx: &mut [D]) {}

    /// [`Block::transform_pq`] on dual numbers (after [`Block::seed_dual`]): the transform of
    /// the simulated series' derivatives and its own parameters' part. A block with a transform
    /// must give it here. Default: none.
    fn transform_pq_dual(&self, _t: &[f64], _p: &mut [D], _q: &mut [D]) {}

    /// [`Block::terminal_load`] on dual numbers (after [`Block::seed_dual`]): a block with a
    /// terminal load must give its derivatives here. Default: none.
    fn terminal_load_dual(&self, _v: f64) -> (D, D) {
        (D::cst(0.0), D::cst(0.0))
    }

    /// After [`Block::update_modes`] in a sensitivity pass: every state the current modes pin
    /// to a limit takes the limit's value and derivatives (the sensitivity of a pinned state is
    /// that of its limit: the derivative of the mode switch's reset map). Default: no pinned
    /// states.
    fn pin_dual(&self, _x: &mut [D], _io: &Io<D>) {}

    /// The states the current modes pin to a *moving* limit (one computed from signals, as a
    /// bus-fed ceiling `V_t·V_RMAX`), with the limit: `(state index in this block, value)`.
    /// While pinned such a block uses the limit itself and its stored state only tracks it; a
    /// mode change projects the state onto it. At a release a sensitivity pass differentiates
    /// that projection, `x⁺ = L(t*)`: the limit's derivatives, plus its rate along the
    /// trajectory times the release time's shift ([`crate::sens`]). Default: none.
    fn moving_pins(&self, _x: &[f64], _io: &Io, _out: &mut Vec<(usize, f64)>) {}

    /// [`Block::moving_pins`] on dual numbers (after [`Block::seed_dual`]).
    fn moving_pins_dual(&self, _x: &[D], _io: &Io<D>, _out: &mut Vec<(usize, D)>) {}

    /// [`Block::events`] on dual numbers (after [`Block::seed_dual`]): the guards' derivatives
    /// `∂g/∂x S + ∂g/∂p`, from which a sensitivity pass takes the shift of a crossing's time
    /// with the parameters (the saltation of [`crate::sens`]). `false`: the block's guards have
    /// no dual form (the pass then keeps the sensitivities continuous across its switches,
    /// which [`Block::pin_dual`] makes exact for a non-windup limit on a constant limit).
    fn events_dual(&self, _x: &[D], _io: &Io<D>, _g: &mut [D]) -> bool {
        false
    }

    /// Post-processes the recorded terminal P and Q series (sample times `t`) as a measuring
    /// device would before they are compared with the recording (PMU skew, phase and ratio
    /// errors). Default: no change.
    fn transform_pq(&self, _t: &[f64], _p: &mut [f64], _q: &mut [f64]) {}

    /// Whether [`Block::transform_pq`] acts (a block that overrides it says `true`).
    fn transforms_pq(&self) -> bool {
        false
    }

    /// P and Q [pu machine base] drawn between the machine terminals and the measurement point
    /// at terminal voltage `v` [pu]: the machine initialises delivering the measured power plus
    /// this, and the recorded P, Q are the machine's minus this. Default: none.
    fn terminal_load(&self, _v: f64) -> (f64, f64) {
        (0.0, 0.0)
    }

    /// Called when the unit is assembled ([`crate::unit::Unit::finish`]) with the indices of
    /// this block's optional input ports that no block drives (they read 0). A block whose input
    /// enters through an HV/LV gate uses it to leave the gate inactive, as PSS/E does when no
    /// limiter model is attached. Default: ignored.
    fn set_undriven_inputs(&mut self, _ports: &[usize]) {}

    /// Sets the nominal frequency [Hz] (machines use ω_b = 2π f_n). Default: ignored.
    fn set_nominal_frequency(&mut self, _hz: f64) {}

    /// Model options that are words, not numbers (e.g. the machine's `swing` convention).
    /// Returns the accepted option names when `key` is unknown.
    fn set_option(&mut self, key: &str, _value: &str) -> Result<(), ModelError> {
        Err(ModelError::param(key, "unknown option"))
    }
    /// Current options as `(key, value)` pairs (written back to unit files).
    fn options(&self) -> Vec<(&'static str, String)> {
        vec![]
    }

    /// The block as a user-defined diagram, when it is one (written back with its definition,
    /// drawn by `itaipu-calib diagram`). Default: `None`.
    fn diagram(&self) -> Option<&crate::diagram::Diagram> {
        None
    }

    /// For an exciter: which of its parameters plays each role a diagnosis reasons about (gain,
    /// field time constant, ceiling, …; [`crate::models::exciter::roles`]). Default: `None`
    /// (not an exciter, or a model that declares nothing).
    fn exciter_roles(&self) -> Option<crate::models::exciter::roles::ExciterRoles> {
        None
    }

    /// For a governor: which of its parameters plays each governor role (droop, servo and
    /// turbine time constants, limits, …; [`crate::models::governor::roles`]). Default: `None`.
    fn governor_roles(&self) -> Option<crate::models::governor::roles::GovernorRoles> {
        None
    }

    /// For a stabiliser: which of its parameters plays each stabiliser role (gain, washout,
    /// lead-lags, output limits; [`crate::models::pss::roles`]). Default: `None`.
    fn pss_roles(&self) -> Option<crate::models::pss::roles::PssRoles> {
        None
    }

    fn clone_box(&self) -> Box<dyn Block>;
}

impl Clone for Box<dyn Block> {
    fn clone(&self) -> Self {
        self.clone_box()
    }
}

/// Implements the boilerplate `params`, `params_mut`, `clone_box` for a block whose parameter
/// struct is in field `p`.
#[macro_export]
macro_rules! block_common {
    () => {
        fn params(&self) -> &dyn $crate::params::ParamSet {
            &self.p
        }
        fn params_mut(&mut self) -> &mut dyn $crate::params::ParamSet {
            &mut self.p
        }
        fn clone_box(&self) -> Box<dyn $crate::block::Block> {
            Box::new(self.clone())
        }
    };
}

/// Guard helpers used by `validate` implementations.
pub mod guard {
    use super::ModelError;

    pub fn positive(name: &str, v: f64) -> Result<(), ModelError> {
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(ModelError::param(name, format!("must be > 0 (got {v})")))
        }
    }
    pub fn non_negative(name: &str, v: f64) -> Result<(), ModelError> {
        if v.is_finite() && v >= 0.0 {
            Ok(())
        } else {
            Err(ModelError::param(name, format!("must be >= 0 (got {v})")))
        }
    }
    pub fn finite(name: &str, v: f64) -> Result<(), ModelError> {
        if v.is_finite() {
            Ok(())
        } else {
            Err(ModelError::param(name, format!("must be finite (got {v})")))
        }
    }
    /// `a > b` with a message naming both.
    pub fn greater(a_name: &str, a: f64, b_name: &str, b: f64) -> Result<(), ModelError> {
        if a > b {
            Ok(())
        } else {
            Err(ModelError::param(
                a_name,
                format!("must exceed {b_name} ({a} <= {b})"),
            ))
        }
    }
    pub fn greater_eq(a_name: &str, a: f64, b_name: &str, b: f64) -> Result<(), ModelError> {
        if a >= b {
            Ok(())
        } else {
            Err(ModelError::param(
                a_name,
                format!("must be >= {b_name} ({a} < {b})"),
            ))
        }
    }
}
