//! Interned names and tables for user-defined diagrams.
//!
//! The block interface hands out `&'static` parameter tables, ports and state names (the
//! built-in models' are compiled in). A diagram's are known only when its file is read, so they
//! are interned: each distinct table is stored once for the life of the process and shared by
//! every diagram that declares the same one. Reading the same diagram again (a calibration
//! reloading a unit, a Python session) therefore does not grow memory; only new, different
//! declarations do, by the size of the declaration.

use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};

use crate::block::Port;
use crate::params::ParamSpec;

fn strs() -> &'static Mutex<HashMap<String, &'static str>> {
    static S: OnceLock<Mutex<HashMap<String, &'static str>>> = OnceLock::new();
    S.get_or_init(Default::default)
}

/// `s` as a `&'static str`, stored once per distinct value.
pub fn str(s: &str) -> &'static str {
    let mut m = strs().lock().unwrap_or_else(|e| e.into_inner());
    if let Some(v) = m.get(s) {
        return v;
    }
    let v: &'static str = Box::leak(s.to_string().into_boxed_str());
    m.insert(s.to_string(), v);
    v
}

macro_rules! slice_interner {
    ($fn:ident, $t:ty) => {
        /// The slice as `&'static`, stored once per distinct content.
        pub fn $fn(v: Vec<$t>) -> &'static [$t] {
            static S: OnceLock<Mutex<HashMap<String, &'static [$t]>>> = OnceLock::new();
            let key = format!("{v:?}");
            let mut m = S
                .get_or_init(Default::default)
                .lock()
                .unwrap_or_else(|e| e.into_inner());
            if let Some(s) = m.get(&key) {
                return s;
            }
            let s: &'static [$t] = Box::leak(v.into_boxed_slice());
            m.insert(key, s);
            s
        }
    };
}

slice_interner!(specs, ParamSpec);
slice_interner!(ports, Port);
slice_interner!(names, &'static str);
