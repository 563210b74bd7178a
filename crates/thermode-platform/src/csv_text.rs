//! Fast CSV text: numbers and fields appended to a byte buffer without allocating, for the large CSVs of `simulate`
//! and `render` (a 90 s run at 1 ms is 90 000 rows). [`push_f64`] writes exactly what Rust's `{}` writes for an `f64`
//! (the shortest digits that read back as the same number, never an exponent), from the `ryu` digits;
//! [`push_f64_decimals`] writes what `{:.N}` writes (correctly rounded to N decimals), for a CSV whose reader does
//! not need every bit; [`push_number`] picks one of the two by a [`Precision`]; [`push_field`] quotes a text field
//! as the `csv` crate does (only when needed).

use std::io::Write as _;

/// How the numbers of a CSV are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Precision {
    /// The shortest digits that read back as the same `f64` (Rust's `{}`): nothing is lost (default).
    #[default]
    Exact,
    /// This many decimal places, correctly rounded (Rust's `{:.N}`), at most [`MAX_DECIMALS`].
    Decimals(u8),
}

/// The most decimal places [`Precision::Decimals`] takes (12: a picokelvin, far below any model's accuracy).
pub const MAX_DECIMALS: u8 = 12;

/// Appends `x` written as `precision` says.
pub fn push_number(out: &mut Vec<u8>, x: f64, precision: Precision) {
    match precision {
        Precision::Exact => push_f64(out, x),
        Precision::Decimals(decimals) => push_f64_decimals(out, x, decimals),
    }
}

/// Appends `x` as `format!("{x:.decimals$}")` would write it. `x·10^decimals` is rounded to an integer whose digits
/// are written with the point put in; a value whose product lies within its own rounding error of a tie between
/// two integers, or too large for exact integers, and every `decimals` above [`MAX_DECIMALS`], go to the formatter.
pub fn push_f64_decimals(out: &mut Vec<u8>, x: f64, decimals: u8) {
    const POWERS_OF_TEN: [f64; MAX_DECIMALS as usize + 1] =
        [1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12];
    let Some(&scale) = POWERS_OF_TEN.get(usize::from(decimals)) else {
        return push_formatted(out, format_args!("{x:.*}", usize::from(decimals)));
    };
    // Exact powers of ten, so the product carries one rounding: at most half an ulp of `scaled`. Below 4e15 the
    // whole part and the fraction are exact (no libm call: `round` and `trunc` are calls without SSE4.1).
    let scaled = x.abs() * scale;
    if !x.is_finite() || scaled >= 4.0e15 {
        return push_formatted(out, format_args!("{x:.*}", usize::from(decimals)));
    }
    let whole = scaled as u64;
    let fraction = scaled - whole as f64;
    if (fraction - 0.5).abs() <= scaled * f64::EPSILON {
        return push_formatted(out, format_args!("{x:.*}", usize::from(decimals)));
    }
    push_scaled_integer(
        out,
        x.is_sign_negative(),
        whole + u64::from(fraction > 0.5),
        usize::from(decimals),
    );
}

/// The two-digit strings "00" to "99", one after the other.
const DIGIT_PAIRS: [u8; 200] = {
    let mut pairs = [0u8; 200];
    let mut i = 0;
    while i < 100 {
        pairs[2 * i] = b'0' + (i / 10) as u8;
        pairs[2 * i + 1] = b'0' + (i % 10) as u8;
        i += 1;
    }
    pairs
};

/// Appends `value / 10^decimals` (`value` below 1e16, `decimals` at most [`MAX_DECIMALS`]), with a minus sign
/// when `negative`: at least one digit before the point, exactly `decimals` after it (no point when `decimals` is
/// 0), built right-aligned in a fixed array, two digits at a time.
fn push_scaled_integer(out: &mut Vec<u8>, negative: bool, mut value: u64, decimals: usize) {
    const LEN: usize = 32;
    let mut text = [b'0'; LEN];
    let mut start = LEN;
    let mut fraction_digits = decimals;
    while fraction_digits >= 2 {
        put_pair(&mut text, &mut start, value % 100);
        value /= 100;
        fraction_digits -= 2;
    }
    if fraction_digits == 1 {
        start -= 1;
        text[start] = b'0' + (value % 10) as u8;
        value /= 10;
    }
    if decimals > 0 {
        start -= 1;
        text[start] = b'.';
    }
    loop {
        if value < 10 {
            start -= 1;
            text[start] = b'0' + value as u8;
            break;
        }
        put_pair(&mut text, &mut start, value % 100);
        value /= 100;
        if value == 0 {
            break;
        }
    }
    if negative {
        start -= 1;
        text[start] = b'-';
    }
    out.extend_from_slice(&text[start..]);
}

/// Writes the two digits of `pair` (below 100) before `start` and moves `start` back by two.
fn put_pair(text: &mut [u8], start: &mut usize, pair: u64) {
    let pair = pair as usize;
    *start -= 2;
    text[*start..*start + 2].copy_from_slice(&DIGIT_PAIRS[2 * pair..2 * pair + 2]);
}

/// Appends `x` as `format!("{x}")` would write it.
pub fn push_f64(out: &mut Vec<u8>, x: f64) {
    if !x.is_finite() || may_tie(x) {
        push_formatted(out, format_args!("{x}"));
        return;
    }
    let mut buffer = ryu::Buffer::new();
    let text = buffer.format_finite(x).as_bytes();
    let (negative, text) = match text.split_first() {
        Some((b'-', rest)) => (true, rest),
        _ => (false, text),
    };
    if negative {
        out.push(b'-');
    }
    match text.iter().position(|&b| b == b'e') {
        Some(e) => push_expanded(out, &text[..e], &text[e + 1..]),
        None => out.extend_from_slice(text.strip_suffix(b".0").unwrap_or(text)),
    }
}

/// Whether two shortest digit strings could lie equally near `x`, where ryu (ties to even) and Rust's formatter may
/// choose differently. `x = m·2^q` (m odd) is exactly `m·5^(−q)·10^q`, which has at least 19 significant digits
/// when `q < −27` (5^27 > 10^18); a tie between two d-digit strings needs an exact value of d + 1 ≤ 18 digits. An
/// integer below 2^53 is its own unique shortest form. Everything else (rare in measured or simulated data) goes to
/// the formatter.
fn may_tie(x: f64) -> bool {
    let bits = x.to_bits();
    let exponent_field = ((bits >> 52) & 0x7ff) as i64;
    let fraction = bits & ((1u64 << 52) - 1);
    if exponent_field == 0 && fraction == 0 {
        return false;
    }
    let mantissa = if exponent_field == 0 {
        fraction
    } else {
        fraction | (1u64 << 52)
    };
    let q = exponent_field.max(1) - 1075 + i64::from(mantissa.trailing_zeros());
    if q >= 0 {
        x.abs() >= 9_007_199_254_740_992.0
    } else {
        q >= -27
    }
}

/// Appends a number given by ryu as `mantissa` (`d` or `d.ddd`) and decimal `exponent` as plain decimals.
fn push_expanded(out: &mut Vec<u8>, mantissa: &[u8], exponent: &[u8]) {
    let exponent: i64 = std::str::from_utf8(exponent)
        .ok()
        .and_then(|e| e.parse().ok())
        .unwrap_or(0);
    let point = mantissa.iter().position(|&b| b == b'.').unwrap_or(mantissa.len()) as i64;
    let digits: Vec<u8> = mantissa.iter().copied().filter(|&b| b != b'.').collect();
    let digits = match digits.iter().rposition(|&b| b != b'0') {
        Some(last) => &digits[..=last],
        None => &digits[..1],
    };
    let position = point + exponent;
    if position <= 0 {
        out.extend_from_slice(b"0.");
        out.extend(std::iter::repeat_n(b'0', position.unsigned_abs() as usize));
        out.extend_from_slice(digits);
    } else if position as usize >= digits.len() {
        out.extend_from_slice(digits);
        out.extend(std::iter::repeat_n(b'0', position as usize - digits.len()));
    } else {
        let (whole, fraction) = digits.split_at(position as usize);
        out.extend_from_slice(whole);
        out.push(b'.');
        out.extend_from_slice(fraction);
    }
}

/// Appends what the formatter writes for `args` (the few values the fast paths leave to it).
fn push_formatted(out: &mut Vec<u8>, args: std::fmt::Arguments<'_>) {
    // Writing into a vector cannot fail.
    let _ = out.write_fmt(args);
}

/// Appends a text field, quoted (with doubled quotes) only when it holds a comma, a quote or a line break, as the
/// `csv` crate writes it.
pub fn push_field(out: &mut Vec<u8>, text: &str) {
    if text.bytes().any(|b| matches!(b, b',' | b'"' | b'\n' | b'\r')) {
        out.push(b'"');
        for b in text.bytes() {
            if b == b'"' {
                out.push(b'"');
            }
            out.push(b);
        }
        out.push(b'"');
    } else {
        out.extend_from_slice(text.as_bytes());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn written(push: impl FnOnce(&mut Vec<u8>)) -> String {
        let mut out = Vec::new();
        push(&mut out);
        String::from_utf8(out).unwrap_or_default()
    }

    fn f64_text(x: f64) -> String {
        written(|out| push_f64(out, x))
    }

    fn decimals_text(x: f64, decimals: u8) -> String {
        written(|out| push_f64_decimals(out, x, decimals))
    }

    #[test]
    fn edge_values_are_written_as_display_writes_them() {
        for x in [
            0.0,
            -0.0,
            1.0,
            -1.5,
            0.1,
            1e-7,
            1.234e-300,
            5e-324,
            f64::MAX,
            f64::MIN_POSITIVE,
            1e21,
            123456789012345680.0,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            32.002564788860134,
        ] {
            assert_eq!(f64_text(x), format!("{x}"), "{x:e}");
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig { cases: 20_000, failure_persistence: None,
            ..proptest::prelude::ProptestConfig::default() })]

        /// Any bit pattern, and numbers of the sizes thermode writes: the same text as `{}`.
        #[test]
        fn any_f64_is_written_as_display_writes_it(bits in proptest::num::u64::ANY, y in -1.0e5..1.0e5f64) {
            let x = f64::from_bits(bits);
            proptest::prop_assert_eq!(f64_text(x), format!("{}", x));
            proptest::prop_assert_eq!(f64_text(y), format!("{}", y));
        }

        /// Any bit pattern, numbers of the sizes thermode writes, and exact ties (halves at the last decimal):
        /// the same text as `{:.N}`.
        #[test]
        fn any_f64_is_written_with_decimals_as_the_formatter_writes_it(bits in proptest::num::u64::ANY,
            y in -1.0e5..1.0e5f64, tie in -1_000_000i64..1_000_000, decimals in 0u8..=14) {
            let x = f64::from_bits(bits);
            let half = (tie as f64 + 0.5) / 10f64.powi(i32::from(decimals.min(6)));
            for value in [x, y, half] {
                proptest::prop_assert_eq!(decimals_text(value, decimals), format!("{:.*}", usize::from(decimals), value));
            }
        }
    }

    #[test]
    fn edge_values_are_written_with_decimals_as_the_formatter_writes_them() {
        for x in [
            0.0,
            -0.0,
            -0.001,
            0.125,
            0.375,
            2.5,
            -2.5,
            0.5,
            1.005,
            32.0025,
            9.999_999_5,
            1e15,
            4.0e15,
            1e300,
            5e-324,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            32.002564788860134,
        ] {
            for decimals in [0, 1, 2, 3, 6, 9, 12, 13, 17] {
                assert_eq!(
                    decimals_text(x, decimals),
                    format!("{x:.*}", usize::from(decimals)),
                    "{x:e} .{decimals}"
                );
            }
        }
    }

    #[test]
    fn fields_are_quoted_only_when_needed() {
        let mut out = Vec::new();
        push_field(&mut out, "aluminium");
        out.push(b'|');
        push_field(&mut out, "a,b\"c");
        assert_eq!(String::from_utf8(out).unwrap_or_default(), "aluminium|\"a,b\"\"c\"");
    }
}
