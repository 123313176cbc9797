//! A generating unit: blocks wired by named signals, assembled into one explicit ODE.
//!
//! The state vector is the concatenation of the blocks' states in the order they were added
//! (the machine first). Signals live on a bus (`Vec<f64>`); each block port reads or writes one
//! slot. Two signals are written by the playback source, not by a block: `v_term` (|V|, pu) and
//! `theta_term` (angle, rad, unwrapped, nominal-frequency frame).
//!
//! Signals that no block writes at run time keep the value they had after initialisation. That
//! is how a unit without an exciter holds `E_fd` at `E_fd0` (the generator stage of a
//! calibration) and a unit without a governor holds `P_m` at `P_m0`.
//!
//! ## Adding a block
//! Implement [`Block`] (ports, states, parameters via `param_set!`, `init`, `outputs`,
//! `derivatives`, and the mode hooks if it has non-windup limits), register its model name in
//! [`crate::registry`], and add it to a unit file as `[[block]]` with any port rewired, e.g.
//! `inputs = { pm = "p_shaft" }`. The machine code is never touched.

use crate::block::{Block, Dir, InitPoint, Io, ModelError, PortInit};
use crate::integrate::OdeSystem;
use crate::params::ParamSpec;

/// Name of the signal carrying the played-back terminal voltage magnitude.
pub const SIG_V_TERM: &str = "v_term";
/// Name of the signal carrying the played-back terminal voltage angle.
pub const SIG_THETA_TERM: &str = "theta_term";

/// A block placed in a unit.
#[derive(Clone)]
pub struct Instance {
    /// Instance name (`machine`, `exciter`, `pss`, `governor`, or a user's name).
    pub name: String,
    pub block: Box<dyn Block>,
    /// Signal name for each port (after overrides).
    pub wiring: Vec<String>,
    map: Vec<usize>,
    x_offset: usize,
    ev_offset: usize,
    /// The block's state and event counts, set with the offsets by [`Unit::finish`] (read on
    /// every right-hand side: a virtual call each saved).
    x_len: usize,
    ev_len: usize,
}

impl Instance {
    fn nx(&self) -> usize {
        self.block.state_names().len()
    }
    /// The `(port, signal)` pairs where the wiring differs from the port's default.
    pub fn rewiring(&self) -> Vec<(String, String)> {
        self.block
            .ports()
            .iter()
            .zip(&self.wiring)
            .filter(|(p, w)| p.signal != w.as_str())
            .map(|(p, w)| (p.name.to_string(), w.clone()))
            .collect()
    }
}

/// Assembly or initialisation failure of a unit.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UnitError {
    #[error("{block} ({model}): {source}")]
    Model {
        block: String,
        model: String,
        source: ModelError,
    },
    #[error("wiring: {0}")]
    Wiring(String),
    #[error("unknown parameter '{0}' (use block.name, e.g. machine.h; see `itaipu-calib models`)")]
    UnknownParam(String),
}

impl UnitError {
    /// Short identifier of the error kind: `init` (a block cannot start at the operating
    /// point), `bad_param`, `wiring` or `unknown_param`.
    pub fn kind(&self) -> &'static str {
        match self {
            UnitError::Model {
                source: ModelError::Init(_),
                ..
            } => "init",
            UnitError::Model { .. } => "bad_param",
            UnitError::Wiring(_) => "wiring",
            UnitError::UnknownParam(_) => "unknown_param",
        }
    }
}

/// Address of one parameter in a unit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ParamRef {
    pub block: usize,
    pub index: usize,
}

/// A generating unit. Build with [`Unit::new`] and [`Unit::add`], then [`Unit::finish`].
#[derive(Clone)]
pub struct Unit {
    pub name: String,
    pub description: String,
    /// Machine base [MVA].
    pub machine_mva: f64,
    /// Nominal frequency [Hz].
    pub nominal_hz: f64,
    /// What the unit lacks of the model it was read from, one sentence each (a `.dyr` record
    /// of a model the engine lacks, left out on request): kept by the unit file and repeated
    /// as a warning by every report on the unit ([`crate::plausibility::check_unit`]).
    pub lacks: Vec<String>,
    instances: Vec<Instance>,
    /// Signals written by the playback driver besides `v_term` and `theta_term`
    /// ([`Unit::add_external`]); on the bus right after those two.
    externals: Vec<String>,
    signals: Vec<String>,
    bus: Vec<f64>,
    eval_order: Vec<usize>,
    init_order: Vec<usize>,
    sig_v: usize,
    sig_theta: usize,
    n_states: usize,
    n_events: usize,
    finished: bool,
}

impl Unit {
    pub fn new(name: &str, machine_mva: f64, nominal_hz: f64) -> Self {
        Self {
            name: name.to_string(),
            description: String::new(),
            machine_mva,
            nominal_hz,
            lacks: Vec::new(),
            instances: Vec::new(),
            externals: Vec::new(),
            signals: Vec::new(),
            bus: Vec::new(),
            eval_order: Vec::new(),
            init_order: Vec::new(),
            sig_v: 0,
            sig_theta: 0,
            n_states: 0,
            n_events: 0,
            finished: false,
        }
    }

    /// Adds a block under `name`, with optional `(port, signal)` rewiring.
    pub fn add(
        &mut self,
        name: &str,
        block: Box<dyn Block>,
        rewire: &[(String, String)],
    ) -> Result<(), UnitError> {
        if self.instances.iter().any(|i| i.name == name) {
            return Err(UnitError::Wiring(format!("two blocks are named '{name}'")));
        }
        let ports = block.ports();
        let mut wiring: Vec<String> = ports.iter().map(|p| p.signal.to_string()).collect();
        for (port, signal) in rewire {
            let Some(k) = ports.iter().position(|p| p.name == port) else {
                let names: Vec<_> = ports.iter().map(|p| p.name).collect();
                return Err(UnitError::Wiring(format!(
                    "{name} ({}) has no port '{port}' (ports: {})",
                    block.model(),
                    names.join(", ")
                )));
            };
            wiring[k] = signal.clone();
        }
        self.instances.push(Instance {
            name: name.to_string(),
            block,
            wiring,
            map: vec![],
            x_offset: 0,
            ev_offset: 0,
            x_len: 0,
            ev_len: 0,
        });
        self.finished = false;
        Ok(())
    }

    /// Connects ports of the block `name` to other signals (`(port, signal)` pairs), keeping
    /// its other connections. The wiring is resolved again on the next use (or
    /// [`Unit::finish`]), so that several edits can be made before it has to be consistent.
    pub fn rewire(&mut self, name: &str, ports: &[(String, String)]) -> Result<(), UnitError> {
        let inst = self
            .instances
            .iter_mut()
            .find(|i| i.name == name)
            .ok_or_else(|| UnitError::Wiring(format!("no block named '{name}'")))?;
        let block_ports = inst.block.ports();
        for (port, signal) in ports {
            let k = block_ports
                .iter()
                .position(|p| p.name == port)
                .ok_or_else(|| {
                    let names: Vec<_> = block_ports.iter().map(|p| p.name).collect();
                    UnitError::Wiring(format!(
                        "{name} ({}) has no port '{port}' (ports: {})",
                        inst.block.model(),
                        names.join(", ")
                    ))
                })?;
            inst.wiring[k] = signal.clone();
        }
        self.finished = false;
        Ok(())
    }

    /// A copy of this unit without the named blocks (their ports' signals then keep their
    /// initial values: no exciter holds E_fd at E_fd0, no governor holds P_m at P_m0).
    pub fn without(&self, names: &[&str]) -> Result<Unit, UnitError> {
        let mut u = Unit::new(&self.name, self.machine_mva, self.nominal_hz);
        u.description = self.description.clone();
        u.lacks = self.lacks.clone();
        u.externals = self.externals.clone();
        for inst in self
            .instances
            .iter()
            .filter(|i| !names.contains(&i.name.as_str()))
        {
            u.add(&inst.name, inst.block.clone(), &inst.rewiring())?;
        }
        u.finish()?;
        Ok(u)
    }

    /// Replaces the block named `name` (keeping its place in the state order) or appends it.
    pub fn put(
        &mut self,
        name: &str,
        block: Box<dyn Block>,
        rewire: &[(String, String)],
    ) -> Result<(), UnitError> {
        match self.instances.iter().position(|i| i.name == name) {
            Some(k) => {
                let mut tmp = Unit::new(&self.name, self.machine_mva, self.nominal_hz);
                tmp.add(name, block, rewire)?;
                self.instances[k] = tmp.instances.pop().expect("just added");
            }
            None => self.add(name, block, rewire)?,
        }
        self.finished = false;
        self.finish()
    }

    /// Declares `name` a signal the playback driver writes, as it writes `v_term` and
    /// `theta_term` (a measured input: a field voltage, a set-point step): no block may write it
    /// at run time, a block may read it without a writer, and the driver sets it with
    /// [`Unit::set_signal`] before every evaluation (and its initial value with
    /// [`Unit::initialise_with`]). A block may still *give* its initial value (the machine gives
    /// the E_fd it needs when its `efd` port reads a played-back field voltage). External
    /// signals sit on the bus right after `v_term` and `theta_term`, in the order declared.
    pub fn add_external(&mut self, name: &str) {
        if name != SIG_V_TERM && name != SIG_THETA_TERM && !self.externals.iter().any(|e| e == name)
        {
            self.externals.push(name.to_string());
            self.finished = false;
        }
    }

    /// The signals declared with [`Unit::add_external`].
    pub fn externals(&self) -> &[String] {
        &self.externals
    }

    /// Writes bus slot `index` (a signal the driver writes: [`Unit::add_external`]).
    #[inline(always)]
    pub fn set_signal(&mut self, index: usize, value: f64) {
        self.bus[index] = value;
    }

    #[inline(always)]
    fn is_external(&self, s: usize) -> bool {
        s < 2 + self.externals.len()
    }

    /// Resolves the wiring and computes evaluation and initialisation orders.
    pub fn finish(&mut self) -> Result<(), UnitError> {
        self.signals = vec![SIG_V_TERM.to_string(), SIG_THETA_TERM.to_string()];
        self.signals.extend(self.externals.iter().cloned());
        let (mut nx, mut nev) = (0, 0);
        for inst in &mut self.instances {
            inst.map.clear();
            for s in &inst.wiring {
                let k = match self.signals.iter().position(|x| x == s) {
                    Some(k) => k,
                    None => {
                        self.signals.push(s.clone());
                        self.signals.len() - 1
                    }
                };
                inst.map.push(k);
            }
            inst.x_offset = nx;
            inst.ev_offset = nev;
            inst.x_len = inst.nx();
            inst.ev_len = inst.block.n_events();
            nx += inst.x_len;
            nev += inst.ev_len;
            inst.block.set_nominal_frequency(self.nominal_hz);
        }
        self.sig_v = 0;
        self.sig_theta = 1;
        self.n_states = nx;
        self.n_events = nev;
        self.bus = vec![0.0; self.signals.len()];

        let ns = self.signals.len();
        // Run-time writers and init givers, one each per signal.
        let mut writer: Vec<Option<usize>> = vec![None; ns];
        let mut giver: Vec<Option<usize>> = vec![None; ns];
        for (b, inst) in self.instances.iter().enumerate() {
            for (port, &s) in inst.block.ports().iter().zip(&inst.map) {
                if port.dir == Dir::Out {
                    if s < 2 + self.externals.len() {
                        return Err(UnitError::Wiring(format!(
                            "{} writes '{}', which only the playback source may write",
                            inst.name, self.signals[s]
                        )));
                    }
                    if let Some(o) = writer[s] {
                        return Err(UnitError::Wiring(format!(
                            "signal '{}' is written by both {} and {}",
                            self.signals[s], self.instances[o].name, inst.name
                        )));
                    }
                    writer[s] = Some(b);
                }
                if port.init == PortInit::Gives {
                    if let Some(o) = giver[s] {
                        return Err(UnitError::Wiring(format!(
                            "signal '{}' is set at initialisation by both {} and {}",
                            self.signals[s], self.instances[o].name, inst.name
                        )));
                    }
                    giver[s] = Some(b);
                }
            }
        }
        // An output that needs a target must have a giver; a required input must be driven.
        for inst in &self.instances {
            for (port, &s) in inst.block.ports().iter().zip(&inst.map) {
                let external = self.is_external(s);
                if port.dir == Dir::In
                    && !port.optional
                    && !external
                    && writer[s].is_none()
                    && giver[s].is_none()
                {
                    return Err(UnitError::Wiring(format!(
                        "{} input '{}' reads signal '{}', which no block writes (rewire it with wiring = {{ {} = \"...\" }})",
                        inst.name, port.name, self.signals[s], port.name
                    )));
                }
                if port.dir == Dir::Out && port.init == PortInit::Needs && giver[s].is_none() {
                    return Err(UnitError::Wiring(format!(
                        "{} output '{}' (signal '{}') is not consumed by any block that fixes its initial value",
                        inst.name, port.name, self.signals[s]
                    )));
                }
            }
        }
        // Tell each block which of its optional inputs nothing drives (they read 0).
        let n_ext = 2 + self.externals.len();
        for inst in &mut self.instances {
            let undriven: Vec<usize> = (0..inst.map.len())
                .filter(|&k| {
                    let (port, s) = (&inst.block.ports()[k], inst.map[k]);
                    port.dir == Dir::In
                        && port.optional
                        && s >= n_ext
                        && writer[s].is_none()
                        && giver[s].is_none()
                })
                .collect();
            inst.block.set_undriven_inputs(&undriven);
        }
        let n = self.instances.len();
        let edges = |feedthrough_only: bool, providers: &Vec<Option<usize>>| {
            let mut deps: Vec<Vec<usize>> = vec![vec![]; n];
            for (b, inst) in self.instances.iter().enumerate() {
                for (port, &s) in inst.block.ports().iter().zip(&inst.map) {
                    let relevant = if feedthrough_only {
                        port.dir == Dir::In && port.feedthrough
                    } else {
                        port.init == PortInit::Needs
                    };
                    if relevant {
                        if let Some(a) = providers[s] {
                            if a != b {
                                deps[b].push(a);
                            }
                        }
                    }
                }
            }
            deps
        };
        self.eval_order = topo_order(&edges(true, &writer))
            .map_err(|c| UnitError::Wiring(format!("algebraic loop through {}", self.names(&c))))?;
        self.init_order = topo_order(&edges(false, &giver)).map_err(|c| {
            UnitError::Wiring(format!("initialisation cycle through {}", self.names(&c)))
        })?;
        for inst in &self.instances {
            inst.block.validate().map_err(|e| self.model_err(inst, e))?;
        }
        self.finished = true;
        Ok(())
    }

    fn names(&self, idx: &[usize]) -> String {
        idx.iter()
            .map(|&i| self.instances[i].name.as_str())
            .collect::<Vec<_>>()
            .join(" -> ")
    }

    fn model_err(&self, inst: &Instance, e: ModelError) -> UnitError {
        UnitError::Model {
            block: inst.name.clone(),
            model: inst.block.model().to_string(),
            source: e,
        }
    }

    /// Number of states.
    pub fn n_states(&self) -> usize {
        self.n_states
    }
    /// Number of event (limiter guard) functions.
    pub fn n_events(&self) -> usize {
        self.n_events
    }
    /// The blocks in state order.
    pub fn instances(&self) -> &[Instance] {
        &self.instances
    }
    /// Mutable access to the block named `name`.
    pub fn block_mut(&mut self, name: &str) -> Option<&mut Box<dyn Block>> {
        self.instances
            .iter_mut()
            .find(|i| i.name == name)
            .map(|i| &mut i.block)
    }
    /// The block named `name`.
    pub fn block(&self, name: &str) -> Option<&dyn Block> {
        self.instances
            .iter()
            .find(|i| i.name == name)
            .map(|i| i.block.as_ref())
    }
    /// Signal names in bus order.
    pub fn signal_names(&self) -> &[String] {
        &self.signals
    }
    /// Current bus values (valid after an RHS evaluation or initialisation).
    pub fn bus(&self) -> &[f64] {
        &self.bus
    }
    /// Bus index of a signal.
    pub fn signal_index(&self, name: &str) -> Option<usize> {
        self.signals.iter().position(|s| s == name)
    }
    /// The bus indices of the machine's electrical output `pe` and `qe` (what P and Q are
    /// computed from); a wiring error if the unit has no machine providing them.
    pub fn pq_signals(&self) -> Result<(usize, usize), UnitError> {
        let idx = |name: &str| {
            self.signal_index(name)
                .ok_or_else(|| UnitError::Wiring(format!("no signal '{name}'")))
        };
        Ok((idx("pe")?, idx("qe")?))
    }
    /// Names `block.state` of all states, in state-vector order.
    pub fn state_names(&self) -> Vec<String> {
        self.instances
            .iter()
            .flat_map(|i| {
                i.block
                    .state_names()
                    .iter()
                    .map(move |s| format!("{}.{}", i.name, s))
            })
            .collect()
    }

    /// Finds a parameter by `block.name` (name or PSS/E alias).
    pub fn param(&self, path: &str) -> Result<ParamRef, UnitError> {
        let (b, p) = path
            .split_once('.')
            .ok_or_else(|| UnitError::UnknownParam(path.to_string()))?;
        let block = self
            .instances
            .iter()
            .position(|i| i.name == b)
            .ok_or_else(|| UnitError::UnknownParam(path.to_string()))?;
        let index = self.instances[block]
            .block
            .params()
            .index_of(p)
            .ok_or_else(|| UnitError::UnknownParam(path.to_string()))?;
        Ok(ParamRef { block, index })
    }
    pub fn get(&self, r: ParamRef) -> f64 {
        self.instances[r.block].block.params().get(r.index)
    }
    pub fn set(&mut self, r: ParamRef, value: f64) {
        self.instances[r.block]
            .block
            .params_mut()
            .set(r.index, value)
    }
    /// Canonical `block.name` of a parameter.
    pub fn param_path(&self, r: ParamRef) -> String {
        let i = &self.instances[r.block];
        format!("{}.{}", i.name, i.block.params().specs()[r.index].name)
    }
    pub fn param_spec(&self, r: ParamRef) -> &'static ParamSpec {
        &self.instances[r.block].block.params().specs()[r.index]
    }
    /// Every parameter as `(path, spec, value)`.
    pub fn params(&self) -> Vec<(String, &'static ParamSpec, f64)> {
        let mut out = vec![];
        for i in &self.instances {
            let ps = i.block.params();
            for (k, s) in ps.specs().iter().enumerate() {
                out.push((format!("{}.{}", i.name, s.name), s, ps.get(k)));
            }
        }
        out
    }

    /// A copy with the parameters `values` (`(block.name, value)`, names or PSS/E aliases) set,
    /// checked as a unit file is: an unknown path is [`UnitError::UnknownParam`]; a non-finite
    /// value, or one that breaks its block's guards (a time constant ≤ 0, the reactance
    /// ordering, ...), is [`UnitError::Model`] naming the block and the parameter. `self` is
    /// left as it was in every case.
    pub fn with_params<S: AsRef<str>>(&self, values: &[(S, f64)]) -> Result<Unit, UnitError> {
        let mut unit = self.clone();
        let mut touched = vec![];
        for (path, value) in values {
            let r = self.param(path.as_ref())?;
            if !value.is_finite() {
                let inst = &self.instances[r.block];
                let name = inst.block.params().specs()[r.index].name;
                return Err(self.model_err(
                    inst,
                    ModelError::param(name, format!("must be finite (got {value})")),
                ));
            }
            unit.set(r, *value);
            if !touched.contains(&r.block) {
                touched.push(r.block);
            }
        }
        for b in touched {
            let inst = &unit.instances[b];
            inst.block.validate().map_err(|e| unit.model_err(inst, e))?;
        }
        Ok(unit)
    }

    /// Resolves the wiring if it has not been (signal and state names are then known).
    pub fn ensure_finished(&mut self) -> Result<(), UnitError> {
        if self.finished {
            Ok(())
        } else {
            self.finish()
        }
    }

    /// Validates parameters and initialises every block at the operating point `op` (machine
    /// base). Returns the initial state vector. Leaves the bus at the initial values.
    pub fn initialise(&mut self, op: &InitPoint) -> Result<Vec<f64>, UnitError> {
        self.initialise_with(op, &[])
    }

    /// [`Unit::initialise`] with the initial values `preset` (`(bus index, value)`) of signals
    /// the driver writes ([`Unit::add_external`]) set before any block initialises.
    pub fn initialise_with(
        &mut self,
        op: &InitPoint,
        preset: &[(usize, f64)],
    ) -> Result<Vec<f64>, UnitError> {
        self.ensure_finished()?;
        let mut x = vec![0.0; self.n_states];
        self.bus.fill(0.0);
        self.bus[self.sig_v] = op.v_mag;
        self.bus[self.sig_theta] = op.v_ang;
        for &(i, v) in preset {
            self.bus[i] = v;
        }
        for k in 0..self.init_order.len() {
            let b = self.init_order[k];
            let inst = &mut self.instances[b];
            let (o, n) = (inst.x_offset, inst.nx());
            let mut io = Io::new(&mut self.bus, &inst.map);
            if let Err(e) = inst.block.init(op, &mut x[o..o + n], &mut io) {
                let inst = &self.instances[b];
                return Err(self.model_err(inst, e));
            }
        }
        // Initial modes.
        self.eval_outputs(0.0, &x);
        self.update_modes(&mut x);
        Ok(x)
    }

    /// Phase 1 of the right-hand side: every block's outputs, in feed-through order. The
    /// playback signals must already be on the bus.
    #[inline]
    pub fn eval_outputs(&mut self, t: f64, x: &[f64]) {
        for &b in &self.eval_order {
            let inst = &self.instances[b];
            let (o, n) = (inst.x_offset, inst.x_len);
            let mut io = Io::new(&mut self.bus, &inst.map);
            inst.block.outputs(t, &x[o..o + n], &mut io);
        }
    }

    /// Phase 2: derivatives of all states (after [`Unit::eval_outputs`] at the same point).
    #[inline]
    pub fn eval_derivatives(&mut self, t: f64, x: &[f64], dx: &mut [f64]) {
        for inst in &self.instances {
            let (o, n) = (inst.x_offset, inst.x_len);
            let io = Io::new(&mut self.bus, &inst.map);
            inst.block
                .derivatives(t, &x[o..o + n], &io, &mut dx[o..o + n]);
        }
    }

    /// Applies every block's measurement transform ([`Block::transform_pq`]) to recorded P and
    /// Q series at sample times `t`.
    pub fn transform_pq(&self, t: &[f64], p: &mut [f64], q: &mut [f64]) {
        for inst in &self.instances {
            inst.block.transform_pq(t, p, q);
        }
    }

    /// Whether a block acts on the recorded P and Q after the playback
    /// ([`Unit::transform_pq`] is not the identity).
    pub fn transforms_pq(&self) -> bool {
        self.instances.iter().any(|i| i.block.transforms_pq())
    }

    /// Total load [pu machine base] between the machine and the measurement point at terminal
    /// voltage `v` ([`Block::terminal_load`]).
    pub fn terminal_load(&self, v: f64) -> (f64, f64) {
        self.instances.iter().fold((0.0, 0.0), |(p, q), i| {
            let (pl, ql) = i.block.terminal_load(v);
            (p + pl, q + ql)
        })
    }

    /// The P and Q a measuring device at the terminals records now [pu machine base]: the
    /// machine's `pe`, `qe` minus any [`Unit::terminal_load`] at the bus voltage.
    #[inline]
    pub fn measured_pq_now(&self, ip: usize, iq: usize) -> (f64, f64) {
        let (pl, ql) = self.terminal_load(self.bus[self.sig_v]);
        (self.bus[ip] - pl, self.bus[iq] - ql)
    }

    /// Sets the playback voltage on the bus.
    #[inline(always)]
    pub fn set_terminal_voltage(&mut self, v_mag: f64, v_ang: f64) {
        self.bus[self.sig_v] = v_mag;
        self.bus[self.sig_theta] = v_ang;
    }

    /// Every block's event functions at `x` (after [`Unit::eval_outputs`] at the same point).
    pub fn eval_events(&mut self, x: &[f64], g: &mut [f64]) {
        for inst in &self.instances {
            let ne = inst.ev_len;
            if ne == 0 {
                continue;
            }
            let (o, n) = (inst.x_offset, inst.x_len);
            let io = Io::new(&mut self.bus, &inst.map);
            inst.block.events(
                &x[o..o + n],
                &io,
                &mut g[inst.ev_offset..inst.ev_offset + ne],
            );
        }
    }

    /// Every block's discrete modes re-evaluated at `x` (after [`Unit::eval_outputs`]); may
    /// project `x`. Returns `true` when anything changed.
    pub fn update_modes(&mut self, x: &mut [f64]) -> bool {
        let mut changed = false;
        for inst in &mut self.instances {
            if inst.ev_len == 0 {
                continue;
            }
            let (o, n) = (inst.x_offset, inst.x_len);
            let io = Io::new(&mut self.bus, &inst.map);
            changed |= inst.block.update_modes(&mut x[o..o + n], &io);
        }
        changed
    }
}

/// Forward sensitivities ([`crate::sens`]): the same right-hand side on dual numbers.
impl Unit {
    /// The bus indices of `v_term` and `theta_term`.
    pub(crate) fn terminal_signals(&self) -> (usize, usize) {
        (self.sig_v, self.sig_theta)
    }

    /// Every block's [`Block::init_constants`], in instance order (after an initialisation).
    pub(crate) fn init_constants(&self) -> Vec<Vec<f64>> {
        self.instances
            .iter()
            .map(|i| i.block.init_constants())
            .collect()
    }

    /// Seeds every block's dual equations: `lanes[b][i]` is the tangent lane of parameter `i`
    /// of block `b`, `consts[b]` its initialisation constants with their derivatives. `Err`
    /// names the first block without dual equations.
    pub(crate) fn seed_dual(
        &mut self,
        lanes: &[Vec<Option<usize>>],
        consts: &[Vec<crate::sens::D>],
    ) -> Result<(), String> {
        for (b, inst) in self.instances.iter_mut().enumerate() {
            if !inst.block.seed_dual(&lanes[b], &consts[b]) {
                return Err(format!("{} ({})", inst.name, inst.block.model()));
            }
        }
        Ok(())
    }

    /// [`Unit::transform_pq`] on dual numbers (after [`Unit::seed_dual`]).
    pub(crate) fn transform_pq_dual(
        &self,
        t: &[f64],
        p: &mut [crate::sens::D],
        q: &mut [crate::sens::D],
    ) {
        for inst in &self.instances {
            inst.block.transform_pq_dual(t, p, q);
        }
    }

    /// [`Unit::terminal_load`] on dual numbers (after [`Unit::seed_dual`]).
    pub(crate) fn terminal_load_dual(&self, v: f64) -> (crate::sens::D, crate::sens::D) {
        use crate::sens::{Scalar, D};
        self.instances
            .iter()
            .fold((D::cst(0.0), D::cst(0.0)), |(p, q), i| {
                let (pl, ql) = i.block.terminal_load_dual(v);
                (p + pl, q + ql)
            })
    }

    /// [`Unit::eval_outputs`] on dual numbers, on the dual bus `bus`.
    #[inline]
    pub(crate) fn eval_outputs_dual(
        &self,
        t: f64,
        x: &[crate::sens::D],
        bus: &mut [crate::sens::D],
    ) {
        for &b in &self.eval_order {
            let inst = &self.instances[b];
            let (o, n) = (inst.x_offset, inst.x_len);
            let mut io = Io::new(bus, &inst.map);
            inst.block.outputs_dual(t, &x[o..o + n], &mut io);
        }
    }

    /// Every block's [`Block::pin_dual`] (after [`Unit::update_modes`] and
    /// [`Unit::eval_outputs_dual`] at the same point).
    pub(crate) fn pin_dual(&self, x: &mut [crate::sens::D], bus: &mut [crate::sens::D]) {
        for inst in &self.instances {
            if inst.ev_len == 0 {
                continue;
            }
            let (o, n) = (inst.x_offset, inst.x_len);
            let io = Io::new(bus, &inst.map);
            inst.block.pin_dual(&mut x[o..o + n], &io);
        }
    }

    /// Every block's [`crate::Block::moving_pins`] at `x` (after [`Unit::eval_outputs`]), the
    /// state indices in the unit's state vector.
    pub(crate) fn eval_moving_pins(&mut self, x: &[f64], out: &mut Vec<(usize, f64)>) {
        collect_pins(&self.instances, x, &mut self.bus, out, |b, x, io, v| {
            b.moving_pins(x, io, v)
        });
    }

    /// [`Unit::eval_moving_pins`] on dual numbers (after [`Unit::eval_outputs_dual`]).
    pub(crate) fn eval_moving_pins_dual(
        &self,
        x: &[crate::sens::D],
        bus: &mut [crate::sens::D],
        out: &mut Vec<(usize, crate::sens::D)>,
    ) {
        collect_pins(&self.instances, x, bus, out, |b, x, io, v| {
            b.moving_pins_dual(x, io, v)
        });
    }

    /// [`Unit::eval_events`] on dual numbers (after [`Unit::eval_outputs_dual`]); the guards of
    /// a block without their dual form ([`crate::Block::events_dual`]) are NaN.
    pub(crate) fn eval_events_dual(
        &self,
        x: &[crate::sens::D],
        bus: &mut [crate::sens::D],
        g: &mut [crate::sens::D],
    ) {
        for inst in &self.instances {
            let ne = inst.ev_len;
            if ne == 0 {
                continue;
            }
            let (o, n) = (inst.x_offset, inst.x_len);
            let io = Io::new(bus, &inst.map);
            let gs = &mut g[inst.ev_offset..inst.ev_offset + ne];
            if !inst.block.events_dual(&x[o..o + n], &io, gs) {
                gs.fill(<crate::sens::D as crate::sens::Scalar>::cst(f64::NAN));
            }
        }
    }

    /// [`Unit::eval_derivatives`] on dual numbers (after [`Unit::eval_outputs_dual`]).
    #[inline]
    pub(crate) fn eval_derivatives_dual(
        &self,
        t: f64,
        x: &[crate::sens::D],
        bus: &mut [crate::sens::D],
        dx: &mut [crate::sens::D],
    ) {
        for inst in &self.instances {
            let (o, n) = (inst.x_offset, inst.x_len);
            let io = Io::new(bus, &inst.map);
            inst.block
                .derivatives_dual(t, &x[o..o + n], &io, &mut dx[o..o + n]);
        }
    }
}

/// Kahn's algorithm; on a cycle returns the blocks left over.
fn topo_order(deps: &[Vec<usize>]) -> Result<Vec<usize>, Vec<usize>> {
    let n = deps.len();
    let mut done = vec![false; n];
    let mut order = Vec::with_capacity(n);
    while order.len() < n {
        let next = (0..n).find(|&b| !done[b] && deps[b].iter().all(|&a| done[a]));
        match next {
            Some(b) => {
                done[b] = true;
                order.push(b);
            }
            None => return Err((0..n).filter(|&b| !done[b]).collect()),
        }
    }
    Ok(order)
}

/// The played-back terminal voltage: magnitude and unwrapped angle, linear between samples,
/// held constant outside the record; on the stretches a low-pass smoothed
/// ([`crate::event::smoothing`]), a natural cubic spline through the smoothed samples for a
/// playback that steps over them ([`PlaybackInput::at_spline`]).
///
/// Interpolating (|V|, θ) rather than (v_re, v_im) keeps |V| exact between samples when the
/// phasor rotates (off-nominal frequency); the two differ only at second order (`models.md`
/// §1.1). The integrators stop at every sample instant, so no step straddles a kink of the
/// piecewise-linear input. The exception is an adaptive integrator that asks to step over the
/// samples ([`crate::Dopri5Options::soft_knots`], a diagnosis re-fit's search): its playback
/// ([`Playback::over_samples`]) interpolates the smoothed stretches by the spline, whose first
/// and second derivatives are continuous there ([`PlaybackInput::soft_knot`]), and still stops
/// at the stretches' edges and on the raw samples. Why a spline there: the smoothed voltage is
/// band-limited far below the sample rate (4 Hz at 30-60 samples/s), so the spline follows it
/// at least as well as a line does (a 2 Hz swing at 30 samples/s: 3e-5 against 1.1e-3 of a
/// 0.05 pu amplitude, `tests/soft_knots.rs`), and the steps are then set by the unit's
/// dynamics, not by the sample rate.
#[derive(Debug, Clone, PartialEq)]
pub struct PlaybackInput {
    pub time_s: Vec<f64>,
    pub v_mag: Vec<f64>,
    pub v_ang: Vec<f64>,
    /// The spline's second derivatives and which intervals it covers (`None`: linear
    /// throughout).
    spline: Option<InputSpline>,
}

/// The natural cubic splines of [`PlaybackInput`]'s smoothed stretches.
#[derive(Debug, Clone, PartialEq)]
struct InputSpline {
    /// Second derivatives of |V| and θ at each sample (0 outside the stretches and at their
    /// ends: natural end conditions).
    m_mag: Vec<f64>,
    m_ang: Vec<f64>,
    /// Whether the interval `[t_k, t_k+1]` is a spline piece.
    cubic: Vec<bool>,
}

/// Shortest stretch of smoothed samples interpolated by a spline (shorter ones stay linear).
const SPLINE_MIN_SAMPLES: usize = 4;

impl PlaybackInput {
    /// The input linear between every pair of samples (a record played as recorded).
    pub fn linear(time_s: Vec<f64>, v_mag: Vec<f64>, v_ang: Vec<f64>) -> Self {
        Self {
            time_s,
            v_mag,
            v_ang,
            spline: None,
        }
    }

    /// The input with the samples `smoothed` marks (a low-passed record's stretches,
    /// [`crate::event::smoothing::smoothed_input_marked`]) interpolated by a natural cubic
    /// spline per run of consecutive marked samples, linear elsewhere.
    pub fn with_splines(
        time_s: Vec<f64>,
        v_mag: Vec<f64>,
        v_ang: Vec<f64>,
        smoothed: &[bool],
    ) -> Self {
        let n = time_s.len();
        let mut sp = InputSpline {
            m_mag: vec![0.0; n],
            m_ang: vec![0.0; n],
            cubic: vec![false; n.saturating_sub(1)],
        };
        let mut k = 0;
        while k < n {
            if !smoothed.get(k).copied().unwrap_or(false) {
                k += 1;
                continue;
            }
            let a = k;
            while k < n && smoothed.get(k).copied().unwrap_or(false) {
                k += 1;
            }
            if k - a >= SPLINE_MIN_SAMPLES {
                let t = &time_s[a..k];
                natural_spline(t, &v_mag[a..k], &mut sp.m_mag[a..k]);
                natural_spline(t, &v_ang[a..k], &mut sp.m_ang[a..k]);
                sp.cubic[a..k - 1].iter_mut().for_each(|c| *c = true);
            }
        }
        let spline = sp.cubic.iter().any(|c| *c).then_some(sp);
        Self {
            time_s,
            v_mag,
            v_ang,
            spline,
        }
    }

    /// Whether interior sample `k` lies inside a spline stretch (the input has continuous
    /// first and second derivatives there): [`crate::integrate::OdeSystem::soft_knot`].
    #[inline]
    pub fn soft_knot(&self, k: usize) -> bool {
        self.spline
            .as_ref()
            .is_some_and(|s| k > 0 && k < s.cubic.len() && s.cubic[k - 1] && s.cubic[k])
    }

    /// `(|V|, θ)` at `t`, linear between samples, using and updating the search `cursor` (an
    /// index hint).
    #[inline(always)]
    pub fn at(&self, t: f64, cursor: &mut usize) -> (f64, f64) {
        self.interpolate(t, cursor, false)
    }

    /// [`PlaybackInput::at`] with the spline on the smoothed stretches (linear elsewhere): the
    /// input of a playback that steps over the samples there.
    #[inline(always)]
    pub fn at_spline(&self, t: f64, cursor: &mut usize) -> (f64, f64) {
        self.interpolate(t, cursor, true)
    }

    #[inline(always)]
    fn interpolate(&self, t: f64, cursor: &mut usize, spline: bool) -> (f64, f64) {
        let ts = &self.time_s;
        let n = ts.len();
        if t <= ts[0] {
            return (self.v_mag[0], self.v_ang[0]);
        }
        if t >= ts[n - 1] {
            return (self.v_mag[n - 1], self.v_ang[n - 1]);
        }
        let mut k = (*cursor).min(n - 2);
        while t < ts[k] {
            k -= 1;
        }
        while t > ts[k + 1] {
            k += 1;
        }
        *cursor = k;
        let h = ts[k + 1] - ts[k];
        let w = (t - ts[k]) / h;
        let lin = |y: &[f64]| y[k] + w * (y[k + 1] - y[k]);
        match self.spline.as_ref().filter(|_| spline) {
            Some(s) if s.cubic[k] => {
                // (A³ − A)·m_k + (B³ − B)·m_k+1, times h²/6, with A = 1 − w, B = w.
                let a = 1.0 - w;
                let (ca, cb) = ((a * a - 1.0) * a, (w * w - 1.0) * w);
                let c = h * h / 6.0;
                (
                    lin(&self.v_mag) + c * (ca * s.m_mag[k] + cb * s.m_mag[k + 1]),
                    lin(&self.v_ang) + c * (ca * s.m_ang[k] + cb * s.m_ang[k + 1]),
                )
            }
            _ => (lin(&self.v_mag), lin(&self.v_ang)),
        }
    }
}

/// The second derivatives `m` of the natural cubic spline through `(t, y)` (`m` = 0 at both
/// ends), by the tridiagonal system `h_i-1 m_i-1 + 2 (h_i-1 + h_i) m_i + h_i m_i+1 = 6 (Δ_i −
/// Δ_i-1)` (`Δ_i` the slope of interval `i`), solved by Thomas's algorithm (diagonally
/// dominant: no pivoting needed).
fn natural_spline(t: &[f64], y: &[f64], m: &mut [f64]) {
    let n = t.len();
    m.iter_mut().for_each(|v| *v = 0.0);
    if n < 3 {
        return;
    }
    let (mut c, mut d) = (vec![0.0; n], vec![0.0; n]);
    for i in 1..n - 1 {
        let (h0, h1) = (t[i] - t[i - 1], t[i + 1] - t[i]);
        let rhs = 6.0 * ((y[i + 1] - y[i]) / h1 - (y[i] - y[i - 1]) / h0);
        let diag = 2.0 * (h0 + h1) - h0 * c[i - 1];
        c[i] = h1 / diag;
        d[i] = (rhs - h0 * d[i - 1]) / diag;
    }
    for i in (1..n - 1).rev() {
        m[i] = d[i] - c[i] * m[i + 1];
    }
}

/// A unit driven by a playback input: the ODE the integrators solve.
///
/// The bus remembers the point `(t, x)` it was last evaluated at. The integrators evaluate the
/// event functions at the end of every step, which is where the last right-hand side was
/// evaluated (Dopri5's FSAL stage), and RK4 starts its next step there: those calls reuse the
/// bus instead of recomputing every block's outputs.
pub struct Playback<'a> {
    pub unit: &'a mut Unit,
    pub input: &'a PlaybackInput,
    /// Whether the playback steps over the samples inside the input's spline stretches (and so
    /// interpolates them by the spline): [`Playback::over_samples`].
    over_samples: bool,
    cursor: usize,
    bus_t: f64,
    bus_x: Vec<f64>,
    bus_valid: bool,
}

impl<'a> Playback<'a> {
    pub fn new(unit: &'a mut Unit, input: &'a PlaybackInput) -> Self {
        let n = unit.n_states;
        Self {
            unit,
            input,
            over_samples: false,
            cursor: 0,
            bus_t: f64::NAN,
            bus_x: vec![0.0; n],
            bus_valid: false,
        }
    }

    /// The playback for an integrator that steps over soft knots
    /// ([`crate::Dopri5Options::soft_knots`]): the input is the spline on its smoothed
    /// stretches, whose samples are then soft ([`PlaybackInput::soft_knot`]).
    pub fn over_samples(mut self, yes: bool) -> Self {
        self.over_samples = yes;
        self
    }
    /// Evaluates all signals at `(t, x)` (for recording).
    #[inline]
    pub fn eval_signals(&mut self, t: f64, x: &[f64]) {
        if self.bus_valid && t == self.bus_t && x == self.bus_x.as_slice() {
            return;
        }
        let (v, th) = if self.over_samples {
            self.input.at_spline(t, &mut self.cursor)
        } else {
            self.input.at(t, &mut self.cursor)
        };
        self.unit.set_terminal_voltage(v, th);
        self.unit.eval_outputs(t, x);
        self.bus_t = t;
        self.bus_x.copy_from_slice(x);
        self.bus_valid = true;
    }
}

impl OdeSystem for Playback<'_> {
    fn dim(&self) -> usize {
        self.unit.n_states
    }
    #[inline]
    fn rhs(&mut self, t: f64, x: &[f64], dx: &mut [f64]) {
        self.eval_signals(t, x);
        self.unit.eval_derivatives(t, x, dx);
    }
    fn n_events(&self) -> usize {
        self.unit.n_events
    }
    fn events(&mut self, t: f64, x: &[f64], g: &mut [f64]) {
        self.eval_signals(t, x);
        self.unit.eval_events(x, g);
    }
    fn handle_event(&mut self, t: f64, x: &mut [f64]) -> bool {
        self.eval_signals(t, x);
        let changed = self.unit.update_modes(x);
        // Modes (and possibly x) changed: outputs must be recomputed.
        self.bus_valid = false;
        changed
    }
    fn soft_knot(&self, k: usize) -> bool {
        self.over_samples && self.input.soft_knot(k)
    }
}

/// The blocks' moving pins (`pins` calls [`crate::Block::moving_pins`] or its dual form) with
/// their state indices moved to the unit's state vector.
fn collect_pins<S: Copy>(
    instances: &[Instance],
    x: &[S],
    bus: &mut [S],
    out: &mut Vec<(usize, S)>,
    pins: impl Fn(&dyn Block, &[S], &Io<S>, &mut Vec<(usize, S)>),
) {
    out.clear();
    let mut local = Vec::new();
    for inst in instances.iter().filter(|i| i.ev_len > 0) {
        let (o, n) = (inst.x_offset, inst.x_len);
        let io = Io::new(bus, &inst.map);
        local.clear();
        pins(inst.block.as_ref(), &x[o..o + n], &io, &mut local);
        out.extend(local.iter().map(|&(i, v)| (o + i, v)));
    }
}
