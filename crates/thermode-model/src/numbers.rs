//! Numbers as people write them: a value rounded to a resolution (a clock's nanosecond, a sensor's decimals), an
//! `f32` reading widened to `f64` as the decimal it stands for (23.28, not 23.280000686645508), a bound written to
//! six significant digits (2.38846e-5, not 0.000023884589662749594), and a p-value as a paper writes it
//! (`p < 0.001`). Pure; [`round_decimals`] and [`f32_as_decimal`] do not allocate (they serve device reads).

use std::fmt;

/// Significant digits of a bound in a message: 6.
pub const BOUND_SIGNIFICANT_DIGITS: u32 = 6;

/// `x` rounded to `decimals` decimal places (0–15), the nearest `f64` to that decimal (so it prints as it), or `x`
/// itself where it is not finite or too large for the rounding to be exact (|x|·10^decimals ≥ 2^53).
pub fn round_decimals(x: f64, decimals: u32) -> f64 {
    let scale = 10f64.powi(decimals.min(15) as i32);
    let scaled = x * scale;
    if !scaled.is_finite() || scaled.abs() >= 9.007_199_254_740_992e15 {
        return x;
    }
    // Both the rounded integer and the power of ten are exact, so the division is correctly rounded: the result is
    // the f64 nearest to the decimal, which is what parsing the decimal would give.
    scaled.round() / scale
}

/// The `f64` of the shortest decimal that reads back as `value` in `f32`: a reading a device sends as an `f32`
/// (a MeCom controller's temperatures) as the decimal it stands for. Non-finite values pass unchanged.
pub fn f32_as_decimal(value: f32) -> f64 {
    let wide = f64::from(value);
    if !value.is_finite() || value == 0.0 {
        return wide;
    }
    // An f32 has at most 9 significant digits; the first digit count whose rounding reads back as `value` wins.
    let magnitude = wide.abs().log10().floor() as i32;
    for digits in 1..=9 {
        let decimals = digits - 1 - magnitude;
        if !(0..=15).contains(&decimals) {
            continue;
        }
        let candidate = round_decimals(wide, decimals as u32);
        if candidate as f32 == value {
            return candidate;
        }
    }
    wide
}

/// `x` rounded to `digits` significant digits (1–15; correctly rounded, through its decimal text); non-finite
/// values pass unchanged.
pub fn round_significant(x: f64, digits: u32) -> f64 {
    if !x.is_finite() {
        return x;
    }
    let precision = (digits.clamp(1, 15) - 1) as usize;
    format!("{x:.precision$e}").parse().unwrap_or(x)
}

/// A number written to [`BOUND_SIGNIFICANT_DIGITS`] significant digits, as plainly as it reads: `1000`, `0.01`,
/// `5.97115`, and in scientific form below 1e-4 or from 1e9 on (`2.38846e-5`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Significant(pub f64);

impl fmt::Display for Significant {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let x = round_significant(self.0, BOUND_SIGNIFICANT_DIGITS);
        let size = x.abs();
        if x != 0.0 && x.is_finite() && !(1e-4..1e9).contains(&size) {
            write!(f, "{x:e}")
        } else {
            write!(f, "{x}")
        }
    }
}

/// A p-value as a paper writes it: `p < 0.001` below a thousandth, else `p = ` with three decimals.
pub fn p_value_text(p: f64) -> String {
    if p < 0.001 {
        "p < 0.001".to_string()
    } else {
        format!("p = {p:.3}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounding_gives_the_decimal_a_person_would_write() {
        assert_eq!(round_decimals(16.686951061000002, 9).to_string(), "16.686951061");
        assert_eq!(round_decimals(0.1 + 0.2, 9).to_string(), "0.3");
        assert_eq!(round_decimals(-2.5e-10, 9), -0.0);
        assert!(round_decimals(f64::NAN, 3).is_nan());
        assert_eq!(round_decimals(1e300, 9), 1e300);
    }

    #[test]
    fn an_f32_reading_reads_as_its_shortest_decimal() {
        // 23.28_f32 is 23.280000686645508 as an f64; "23.28" is what the device meant.
        assert_eq!(f64::from(23.28_f32), 23.280000686645508);
        for (value, text) in [
            (23.28_f32, "23.28"),
            (-12.5_f32, "-12.5"),
            (0.1_f32, "0.1"),
            (1.0e-3_f32, "0.001"),
            (32.123456_f32, "32.123455"),
            (12345.678_f32, "12345.678"),
        ] {
            let wide = f32_as_decimal(value);
            assert_eq!(wide.to_string(), text, "{value} as f64");
            assert_eq!(wide as f32, value, "{wide} does not read back as {value}");
            assert_eq!(wide.to_string(), value.to_string(), "not the f32's shortest decimal");
        }
        assert!(f32_as_decimal(f32::NAN).is_nan());
        assert_eq!(f32_as_decimal(f32::INFINITY), f64::INFINITY);
    }

    #[test]
    fn bounds_are_written_to_six_significant_digits() {
        let cases = [
            (0.01 / 418.68, "2.38846e-5"),
            (2500.0 / 418.68, "5.97115"),
            (1000.0, "1000"),
            (0.01, "0.01"),
            (-30.0, "-30"),
            (0.0, "0"),
            (1e300, "1e300"),
        ];
        for (value, text) in cases {
            assert_eq!(Significant(value).to_string(), text, "{value}");
        }
    }

    #[test]
    fn p_values_as_a_paper_writes_them() {
        assert_eq!(p_value_text(0.0004), "p < 0.001");
        assert_eq!(p_value_text(0.0), "p < 0.001");
        assert_eq!(p_value_text(0.0123), "p = 0.012");
        assert_eq!(p_value_text(0.392), "p = 0.392");
    }
}
