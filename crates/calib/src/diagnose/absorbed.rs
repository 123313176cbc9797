//! What the unit as diagnosed absorbs: re-freed calibrated parameters far outside the model
//! library's typical ranges, where their datasheet is not. A calibration that reaches the
//! noise floor only by pressing such values has absorbed an effect its model lacks into them,
//! so the verdict cannot say the model needs no extension.

use itaipu_dynamics::unit::Unit;

use crate::bounds::FreeBound;

use super::report::fmt_num;

/// How far outside its typical range `[lo, hi]` a value must lie to count as absorbing: more
/// than the range's own width beyond either end, the plausibility layer's "far outside"
/// ([`itaipu_dynamics::plausibility::check_unit`]). The library's ranges span the values
/// units of the model have; a width beyond them is no unit of it.
fn far_outside(v: f64, (lo, hi): (f64, f64)) -> bool {
    let w = hi - lo;
    lo.is_finite() && hi.is_finite() && w > 0.0 && (v < lo - w || v > hi + w)
}

/// The re-freed parameters (`refit`) of `unit` far outside their typical range while their
/// datasheet value (the prior's centre, or where the re-fit started when it has none) is not,
/// each described as `path = value (typical lo-hi, datasheet x)`.
pub(super) fn absorbed(unit: &Unit, refit: &[FreeBound]) -> Vec<String> {
    let params = unit.params();
    refit
        .iter()
        .filter_map(|b| {
            let (_, spec, v) = params.iter().find(|(p, _, _)| *p == b.param)?;
            let datasheet = b.prior.map(|p| p.center).or(b.start)?;
            (far_outside(*v, spec.range) && !far_outside(datasheet, spec.range)).then(|| {
                format!(
                    "{} = {} {} (typical {}-{}, datasheet {})",
                    b.param,
                    fmt_num(*v),
                    spec.unit,
                    fmt_num(spec.range.0),
                    fmt_num(spec.range.1),
                    fmt_num(datasheet)
                )
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A value more than a range's width outside it counts, one inside or just beyond it does
    /// not, nor a range that is not one.
    #[test]
    fn far_outside_is_a_range_width_beyond_either_end() {
        assert!(far_outside(1.83, (0.8, 1.2)));
        assert!(!far_outside(1.55, (0.8, 1.2)));
        assert!(!far_outside(0.41, (0.8, 1.2)));
        assert!(far_outside(0.39, (0.8, 1.2)));
        assert!(!far_outside(5.0, (1.0, 1.0)));
        assert!(!far_outside(5.0, (f64::NEG_INFINITY, 1.0)));
    }
}
