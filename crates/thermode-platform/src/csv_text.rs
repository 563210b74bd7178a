//! Fast CSV text: numbers and fields appended to a byte buffer without allocating, for the large CSVs of `simulate`
//! and `render` (a 90 s run at 1 ms is 90 000 rows). [`push_f64`] writes exactly what Rust's `{}` writes for an `f64`
//! (the shortest digits that read back as the same number, never an exponent), from the `ryu` digits; [`push_field`]
//! quotes a text field as the `csv` crate does (only when needed).

use std::fmt::Write as _;

/// Appends `x` as `format!("{x}")` would write it.
pub fn push_f64(out: &mut Vec<u8>, x: f64) {
    if !x.is_finite() || may_tie(x) {
        push_display(out, x);
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

fn push_display(out: &mut Vec<u8>, x: f64) {
    let mut text = String::new();
    let _ = write!(text, "{x}");
    out.extend_from_slice(text.as_bytes());
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

    fn f64_text(x: f64) -> String {
        let mut out = Vec::new();
        push_f64(&mut out, x);
        String::from_utf8(out).unwrap_or_default()
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
