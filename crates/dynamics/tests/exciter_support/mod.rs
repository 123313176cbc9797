//! Helpers shared by the exciter tests (`exciters.rs`, `st5b_reference.rs`): a source block
//! that writes prescribed signals (piecewise linear in time) and fixes the initial E_fd an
//! exciter must hold, so that an exciter can be simulated alone on prescribed inputs.

#![allow(dead_code)]

use itaipu_dynamics::block::{Block, InitPoint, Io, ModelError, Port, PortInit};
use itaipu_dynamics::params::{ParamSet, ParamSpec};

/// A piecewise-linear series (held outside its range).
#[derive(Debug, Clone)]
pub struct Series {
    pub t: Vec<f64>,
    pub v: Vec<f64>,
}

impl Series {
    pub fn constant(v: f64) -> Self {
        Self {
            t: vec![0.0],
            v: vec![v],
        }
    }
    pub fn at(&self, t: f64) -> f64 {
        let n = self.t.len();
        if t <= self.t[0] {
            return self.v[0];
        }
        if t >= self.t[n - 1] {
            return self.v[n - 1];
        }
        let k = self.t.partition_point(|&s| s <= t) - 1;
        let w = (t - self.t[k]) / (self.t[k + 1] - self.t[k]);
        self.v[k] + w * (self.v[k + 1] - self.v[k])
    }
}

#[derive(Debug, Clone, Default)]
struct NoParams;

impl ParamSet for NoParams {
    fn specs(&self) -> &'static [ParamSpec] {
        &[]
    }
    fn get(&self, _: usize) -> f64 {
        f64::NAN
    }
    fn set(&mut self, _: usize, _: f64) {}
}

/// Writes each of its signals from a [`Series`]; with `efd0`, also fixes the initial value of
/// the signal `efd` (an input port that *gives* E_fd0 at initialisation, as a machine does).
#[derive(Debug, Clone)]
pub struct Source {
    p: NoParams,
    ports: &'static [Port],
    series: Vec<Series>,
    efd0: Option<f64>,
}

impl Source {
    pub fn new(signals: Vec<(&'static str, Series)>, efd0: Option<f64>) -> Self {
        let mut ports: Vec<Port> = signals
            .iter()
            .map(|(n, _)| Port::output(n, PortInit::Gives, "prescribed signal"))
            .collect();
        if efd0.is_some() {
            ports.push(Port::input("efd", PortInit::Gives, "E_fd0 target"));
        }
        Self {
            p: NoParams,
            ports: Box::leak(ports.into_boxed_slice()),
            series: signals.into_iter().map(|(_, s)| s).collect(),
            efd0,
        }
    }
}

impl Block for Source {
    fn model(&self) -> &'static str {
        "test_source"
    }
    fn ports(&self) -> &'static [Port] {
        self.ports
    }
    fn state_names(&self) -> &'static [&'static str] {
        &[]
    }
    fn params(&self) -> &dyn ParamSet {
        &self.p
    }
    fn params_mut(&mut self) -> &mut dyn ParamSet {
        &mut self.p
    }
    fn validate(&self) -> Result<(), ModelError> {
        Ok(())
    }
    fn init(&mut self, _op: &InitPoint, _x: &mut [f64], io: &mut Io) -> Result<(), ModelError> {
        for (k, s) in self.series.iter().enumerate() {
            io.set(k, s.at(0.0));
        }
        if let Some(e) = self.efd0 {
            io.set(self.series.len(), e);
        }
        Ok(())
    }
    fn outputs(&self, t: f64, _x: &[f64], io: &mut Io) {
        for (k, s) in self.series.iter().enumerate() {
            io.set(k, s.at(t));
        }
    }
    fn derivatives(&self, _t: f64, _x: &[f64], _io: &Io, _dx: &mut [f64]) {}
    fn clone_box(&self) -> Box<dyn Block> {
        Box::new(self.clone())
    }
}
