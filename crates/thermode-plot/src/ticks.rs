//! Tick labels as people write them: the ticks plotters places on an axis, each written with the fewest decimals
//! that state every tick of that axis exactly, trailing zeros dropped (`0`, `0.5`, `1`, never `1.0`), and never
//! `-0`.

use plotters::coord::ranged1d::Ranged;
use plotters::coord::types::RangedCoordf64;

/// Labelled ticks per axis (at most; plotters picks round steps): 8.
pub const TICKS_PER_AXIS: usize = 8;

/// Most decimals a tick label gets: 9.
const MAX_DECIMALS: usize = 9;

/// The tick values plotters draws on an axis spanning `low..high` with [`TICKS_PER_AXIS`] labels.
pub fn tick_values(low: f64, high: f64) -> Vec<f64> {
    RangedCoordf64::from(low..high).key_points(TICKS_PER_AXIS)
}

/// The fewest decimals (0–9) that write every tick of `low..high` to within a millionth of the span.
pub fn tick_decimals(low: f64, high: f64) -> usize {
    let span = (high - low).abs().max(f64::MIN_POSITIVE);
    let ticks = tick_values(low, high);
    (0..=MAX_DECIMALS)
        .find(|&decimals| {
            ticks.iter().all(|&tick| {
                format!("{tick:.decimals$}")
                    .parse::<f64>()
                    .is_ok_and(|written| (written - tick).abs() <= 1e-6 * span)
            })
        })
        .unwrap_or(MAX_DECIMALS)
}

/// `value` with at most `decimals` decimals, trailing zeros and a bare point dropped, `-0` written `0`.
pub fn tick_label(value: f64, decimals: usize) -> String {
    let mut text = format!("{value:.decimals$}");
    if text.contains('.') {
        text.truncate(text.trim_end_matches('0').trim_end_matches('.').len());
    }
    if text == "-0" {
        text.remove(0);
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_drop_needless_decimals_and_negative_zero() {
        assert_eq!(tick_label(-0.0000000001, 2), "0");
        assert_eq!(tick_label(-0.0, 1), "0");
        assert_eq!(tick_label(1.0, 1), "1");
        assert_eq!(tick_label(0.5, 1), "0.5");
        assert_eq!(tick_label(25.0, 0), "25");
        assert_eq!(tick_label(0.30000000000000004, 1), "0.3");
        assert_eq!(tick_label(-0.15, 2), "-0.15");
    }

    #[test]
    fn decimals_follow_the_tick_step() {
        // Steps of 5, 0.1, 0.05 and 0.1 (a tick at -2.8e-17): 0, 1, 2 and 1 decimals.
        for ((low, high), expected) in [((0.0, 30.0), 0), ((0.0, 0.7), 1), ((0.0, 0.3), 2), ((-0.22, 0.22), 1)] {
            let ticks = tick_values(low, high);
            assert_eq!(
                tick_decimals(low, high),
                expected,
                "axis {low}..{high}, ticks {ticks:?}"
            );
        }
    }
}
