//! One definition of every model parameter: name, PSS/E alias, unit, meaning, typical value,
//! plausible range.
//!
//! Each model declares its parameters once with [`param_set!`]. That single list is what the
//! simulator reads (as plain `f64` fields with descriptive names), what the unit-model parser
//! accepts (by name or PSS/E alias), what the calibrator addresses as `block.name`, and what the
//! Python module and `itaipu-calib models` print.

/// Static description of one parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamSpec {
    /// Canonical name (snake_case), e.g. `t_d0_prime`.
    pub name: &'static str,
    /// Name used by PSS/E and OpenIPSL, e.g. `Tpd0`. Accepted case-insensitively.
    pub alias: &'static str,
    /// Physical unit, e.g. `s`, `pu`, `pu/s`, `-`.
    pub unit: &'static str,
    /// One-line meaning.
    pub doc: &'static str,
    /// Typical value for a large hydro unit (the default in templates).
    pub typical: f64,
    /// Plausible range for a large hydro unit: the default search range of the diagnosis (a
    /// cause frees its extension's parameters within it, and `--refit PARAM` without bounds
    /// within it widened to hold the value) and the reference of the plausibility warnings
    /// (`plausibility::check_unit`: a value more than a range's width outside it).
    pub range: (f64, f64),
}

/// Access to a model's parameters by index (the order of [`ParamSet::specs`]).
pub trait ParamSet {
    fn specs(&self) -> &'static [ParamSpec];
    fn get(&self, index: usize) -> f64;
    fn set(&mut self, index: usize, value: f64);

    /// Index of a parameter by canonical name or PSS/E alias. An alias matches exactly first;
    /// case-insensitively only when that is unambiguous (HYGOV's `R`, permanent droop, and
    /// `r`, temporary droop, differ only in case: `r` is the temporary droop, never `R`).
    fn index_of(&self, name: &str) -> Option<usize> {
        let specs = self.specs();
        let unique = |hit: &dyn Fn(&ParamSpec) -> bool| {
            let mut found = specs.iter().enumerate().filter(|(_, s)| hit(s));
            match (found.next(), found.next()) {
                (Some((i, _)), None) => Some(i),
                _ => None,
            }
        };
        specs
            .iter()
            .position(|s| s.name == name)
            .or_else(|| specs.iter().position(|s| s.alias == name))
            .or_else(|| unique(&|s| s.alias.eq_ignore_ascii_case(name)))
            .or_else(|| unique(&|s| s.name.eq_ignore_ascii_case(name)))
    }

    /// All values in spec order.
    fn values(&self) -> Vec<f64> {
        (0..self.specs().len()).map(|i| self.get(i)).collect()
    }
}

/// A parameter struct on the dual numbers of a sensitivity pass, for code generic over the
/// parameter set (implemented by [`param_set!`] with its inherent `lift_dual`).
pub trait LiftDual {
    /// The struct on [`D`](crate::sens::D).
    type Dual;
    /// Parameter `i` (spec order) seeded on `lanes[i]`, a constant where it has no lane.
    fn lift_dual(&self, lanes: &[Option<usize>]) -> Self::Dual;
}

/// Declares a parameter struct (`f64` fields by default) and its [`ParamSpec`] table.
///
/// ```text
/// param_set! {
///     /// SEXS parameters.
///     pub struct SexsParams {
///         k: ("K", "pu", 100.0, (30.0, 400.0), "gain"),
///     }
/// }
/// ```
#[macro_export]
macro_rules! param_set {
    (
        $(#[$meta:meta])*
        pub struct $name:ident {
            $( $field:ident : ($alias:literal, $unit:literal, $typical:expr, ($lo:expr, $hi:expr), $doc:literal) ),* $(,)?
        }
    ) => {
        $(#[$meta])*
        ///
        /// Generic over the number type ([`Scalar`]($crate::sens::Scalar)): `f64` for the
        /// simulation; a [`Dual`]($crate::sens::Dual) copy ([`Self::lift`]) carries the
        /// derivatives of forward sensitivities.
        #[derive(Debug, Clone, PartialEq)]
        pub struct $name<S = f64> {
            $( #[doc = concat!($doc, " [", $unit, "] (PSS/E `", $alias, "`)")] pub $field: S, )*
        }

        impl $name {
            /// The parameter table of this model.
            pub const SPECS: &'static [$crate::params::ParamSpec] = &[
                $( $crate::params::ParamSpec {
                    name: stringify!($field), alias: $alias, unit: $unit, doc: $doc,
                    typical: $typical, range: ($lo, $hi),
                } ),*
            ];

            /// The same values on the number type `S`, parameter `i` (spec order) as
            /// `seed(i, value)`: a [`Dual`]($crate::sens::Dual) seeded on the parameters whose
            /// sensitivities are wanted, a constant for the others.
            #[allow(unused_assignments, unused_mut, unused_variables)]
            pub fn lift<S: $crate::sens::Scalar>(&self, seed: impl Fn(usize, f64) -> S) -> $name<S> {
                let mut k = 0usize;
                $name { $( $field: { let v = seed(k, self.$field); k += 1; v }, )* }
            }

            /// The values on the dual numbers of a sensitivity pass: parameter `i` (spec order)
            /// seeded on `lanes[i]`, a constant where it has no lane (or `lanes` is shorter).
            pub fn lift_dual(&self, lanes: &[Option<usize>]) -> $name<$crate::sens::D> {
                self.lift(|i, v| $crate::sens::seeded(v, lanes.get(i).copied().flatten()))
            }
        }

        impl $crate::params::LiftDual for $name {
            type Dual = $name<$crate::sens::D>;
            #[inline]
            fn lift_dual(&self, lanes: &[Option<usize>]) -> Self::Dual {
                <$name>::lift_dual(self, lanes)
            }
        }

        impl Default for $name {
            /// Typical values for a large hydro unit.
            fn default() -> Self {
                Self { $( $field: $typical ),* }
            }
        }

        impl $crate::params::ParamSet for $name {
            fn specs(&self) -> &'static [$crate::params::ParamSpec] {
                Self::SPECS
            }
            #[allow(unused_assignments)]
            fn get(&self, index: usize) -> f64 {
                let mut k = 0usize;
                $( if index == k { return self.$field; } k += 1; )*
                panic!("{}: parameter index {} out of range", stringify!($name), index)
            }
            #[allow(unused_assignments)]
            fn set(&mut self, index: usize, value: f64) {
                let mut k = 0usize;
                $( if index == k { self.$field = value; return; } k += 1; )*
                panic!("{}: parameter index {} out of range", stringify!($name), index)
            }
        }
    };
}
