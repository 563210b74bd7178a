//! Fast CSV text: numbers and fields appended to a [`CsvText`] buffer, for the large CSVs of `simulate` and `render`
//! (a 90 s run at 1 ms is 90 000 rows). [`CsvText::push_f64`] writes exactly what Rust's `{}` writes for an `f64`
//! (the shortest digits that read back as the same number, never an exponent): short decimals directly, the rest
//! from the `ryu` digits; [`CsvText::push_f64_decimals`] writes what `{:.N}` writes (correctly rounded to N
//! decimals), for a CSV whose reader does not need every bit; [`CsvText::push_number`] picks one of the two by a
//! [`Precision`]; [`CsvText::push_field`] quotes a text field as the `csv` crate does (only when needed).
//!
//! [`write_rows`] formats the rows of a large CSV in blocks on two threads (the caller's and one helper) and writes
//! them in order: the same bytes as one thread writes (the exact form about a fifth faster on this project's
//! two-core machine, docs/performance.md).
//!
//! A number is written into a fixed run of scratch bytes past the text and the length then advanced (no copy of
//! varying length per number); the buffer doubles, rarely, when the run does not fit.

use std::io::{self, Write};
use std::ops::Range;
use std::sync::mpsc;

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

/// The longest text a fixed-point number takes here, with room to spare: a sign, 16 whole digits, the point, and up
/// to [`MAX_DECIMALS`] decimals (the whole part and the decimals together have at most 16 digits, plus a leading 0).
const FIXED_POINT_LEN: usize = 32;

/// Bytes a new [`CsvText`] holds before it first grows (64 KiB, the size its users write out at).
const INITIAL_BYTES: usize = 64 * 1024 + 4096;

/// CSV text being built: [`CsvText::as_bytes`] is what has been appended.
#[derive(Debug, Clone)]
pub struct CsvText {
    /// The allocation, all of it initialised; the text is its first `len` bytes, the rest is scratch.
    bytes: Vec<u8>,
    /// Bytes of text.
    len: usize,
}

impl Default for CsvText {
    fn default() -> Self {
        Self::new()
    }
}

impl CsvText {
    /// An empty text with room for 68 KiB before it grows.
    pub fn new() -> Self {
        Self {
            bytes: vec![0; INITIAL_BYTES],
            len: 0,
        }
    }

    /// The text appended so far.
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes[..self.len]
    }

    /// Bytes of text appended so far.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether nothing has been appended.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Forgets the text, keeping the allocation.
    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// The `needed` bytes after the text, to write into (their content is undefined scratch).
    #[inline(always)]
    fn room(&mut self, needed: usize) -> &mut [u8] {
        if self.bytes.len() - self.len < needed {
            self.bytes = grown(std::mem::take(&mut self.bytes), self.len + needed);
        }
        &mut self.bytes[self.len..self.len + needed]
    }

    /// Appends one byte (a separator or a line end).
    #[inline(always)]
    pub fn push_byte(&mut self, byte: u8) {
        self.room(1)[0] = byte;
        self.len += 1;
    }

    /// Appends bytes as they are.
    #[inline(always)]
    pub fn push_bytes(&mut self, text: &[u8]) {
        self.room(text.len()).copy_from_slice(text);
        self.len += text.len();
    }

    /// Appends a copy of the text between byte offsets `span.0` and `span.1` (written earlier and still held).
    #[inline(always)]
    pub fn push_earlier(&mut self, span: (usize, usize)) {
        let (start, end) = span;
        self.room(end - start);
        self.bytes.copy_within(start..end, self.len);
        self.len += end - start;
    }

    /// Appends a text field, quoted (with doubled quotes) only when it holds a comma, a quote or a line break, as
    /// the `csv` crate writes it.
    pub fn push_field(&mut self, text: &str) {
        if text.bytes().any(|b| matches!(b, b',' | b'"' | b'\n' | b'\r')) {
            self.push_bytes(format!("\"{}\"", text.replace('"', "\"\"")).as_bytes());
        } else {
            self.push_bytes(text.as_bytes());
        }
    }

    /// Appends `x` written as `precision` says.
    #[inline(always)]
    pub fn push_number(&mut self, x: f64, precision: Precision) {
        match precision {
            Precision::Exact => self.push_f64(x),
            Precision::Decimals(decimals) => self.push_f64_decimals(x, decimals),
        }
    }

    /// Appends `x` as `format!("{x:.decimals$}")` would write it. `x·10^decimals` is rounded to an integer whose
    /// digits are written with the point put in; a value whose product lies within its own rounding error of a tie
    /// between two integers, or too large for exact integers, and every `decimals` above [`MAX_DECIMALS`], go to
    /// the formatter.
    #[inline(always)]
    pub fn push_f64_decimals(&mut self, x: f64, decimals: u8) {
        let written = match decimals {
            0 => self.push_rounded::<0>(x),
            1 => self.push_rounded::<1>(x),
            2 => self.push_rounded::<2>(x),
            3 => self.push_rounded::<3>(x),
            4 => self.push_rounded::<4>(x),
            5 => self.push_rounded::<5>(x),
            6 => self.push_rounded::<6>(x),
            7 => self.push_rounded::<7>(x),
            8 => self.push_rounded::<8>(x),
            9 => self.push_rounded::<9>(x),
            10 => self.push_rounded::<10>(x),
            11 => self.push_rounded::<11>(x),
            12 => self.push_rounded::<12>(x),
            _ => false,
        };
        if !written {
            self.push_bytes(formatted_with_decimals(x, decimals).as_bytes());
        }
    }

    /// Appends `x` rounded to `DECIMALS` places and returns true, or returns false (nothing written) for what it
    /// leaves to the formatter: non-finite values, values of 4e15 or more once scaled, and products within their own
    /// rounding error of a tie. The scale is an exact power of ten, so the product carries one rounding: at most half
    /// an ulp of `scaled`. Below 4e15 the whole part and the fraction are exact (no libm call: `round` and `trunc`
    /// are calls without SSE4.1).
    #[inline(always)]
    fn push_rounded<const DECIMALS: usize>(&mut self, x: f64) -> bool {
        let scaled = x.abs() * power_of_ten::<DECIMALS>() as f64;
        if !x.is_finite() || scaled >= 4.0e15 {
            return false;
        }
        // Signed conversions: single instructions both ways, where unsigned ones take several without AVX-512.
        let whole = scaled as i64;
        let fraction = scaled - whole as f64;
        if (fraction - 0.5).abs() <= scaled * f64::EPSILON {
            return false;
        }
        let value = whole.unsigned_abs() + u64::from(fraction > 0.5);
        self.push_fixed_point::<DECIMALS>(x.is_sign_negative(), value);
        true
    }

    /// Appends `value / 10^DECIMALS` (`value` below 1e16), with a minus sign when `negative`: at least one digit
    /// before the point, exactly `DECIMALS` after it (no point when `DECIMALS` is 0), written into a fixed run of
    /// scratch with divisions by constants ([`put_digits`]). Returns the text written.
    #[inline(always)]
    fn push_fixed_point<const DECIMALS: usize>(&mut self, negative: bool, value: u64) -> &[u8] {
        let whole = value / power_of_ten::<DECIMALS>();
        let whole_digits = decimal_digits(whole);
        let sign = usize::from(negative);
        let len = sign + whole_digits + usize::from(DECIMALS > 0) + DECIMALS;
        let text = self.room(FIXED_POINT_LEN);
        put_digits(text, len, value % power_of_ten::<DECIMALS>(), DECIMALS);
        put_digits(text, sign + whole_digits, whole, whole_digits);
        if DECIMALS > 0 {
            text[sign + whole_digits] = b'.';
        }
        if negative {
            text[0] = b'-';
        }
        let start = self.len;
        self.len += len;
        &self.bytes[start..self.len]
    }

    /// Appends `x` as `format!("{x}")` would write it.
    #[inline(always)]
    pub fn push_f64(&mut self, x: f64) {
        if self.push_short_decimal(x) {
            return;
        }
        if !x.is_finite() || may_tie(x) {
            self.push_bytes(format!("{x}").as_bytes());
            return;
        }
        let mut buffer = ryu::Buffer::new();
        let text = buffer.format_finite(x).as_bytes();
        let (negative, text) = match text.split_first() {
            Some((b'-', rest)) => (true, rest),
            _ => (false, text),
        };
        if negative {
            self.push_byte(b'-');
        }
        match text.iter().position(|&b| b == b'e') {
            Some(e) => self.push_bytes(&expanded(&text[..e], &text[e + 1..])),
            None => self.push_bytes(text.strip_suffix(b".0").unwrap_or(text)),
        }
    }

    /// Appends `x` and returns true when it is a decimal of at most six places and 15 significant digits (a time
    /// column of whole milliseconds, a set-point of 32.5): such a decimal that reads back as `x` is its shortest
    /// form, because two different decimals of at most 15 significant digits never read back as the same `f64`.
    /// `x·10^6` is rounded to the candidate integer, and the candidate kept only when dividing it by 10^6 (one
    /// correctly rounded division, as reading the text does) gives `x` back; its trailing zeros and a bare point
    /// are cut. Otherwise nothing is written.
    #[inline(always)]
    fn push_short_decimal(&mut self, x: f64) -> bool {
        const SCALE: f64 = 1e6;
        let scaled = x.abs() * SCALE;
        if !x.is_finite() || scaled >= 1e15 {
            return false;
        }
        let candidate = (scaled + 0.5) as i64;
        if candidate as f64 / SCALE != x.abs() {
            return false;
        }
        let text = self.push_fixed_point::<6>(x.is_sign_negative(), candidate.unsigned_abs());
        let cut = match text.iter().rposition(|&b| b != b'0') {
            Some(last) if text[last] == b'.' => text.len() - last,
            Some(last) => text.len() - last - 1,
            None => 0,
        };
        self.len -= cut;
        true
    }
}

/// Rows formatted together by [`write_rows`] (2048: about 200 KiB of a simulation's CSV).
const BLOCK_ROWS: usize = 2048;

/// Writes rows `0..rows` to `sink`: `format` appends the text of a range of rows to a [`CsvText`] (it must not
/// depend on what other blocks hold). Blocks of 2048 rows are formatted in pairs, the first on a helper
/// thread and the second on the caller's, and written in order, so the bytes are the same as one thread writes;
/// with a single core (or fewer than two blocks) everything is formatted here.
pub fn write_rows(
    sink: &mut dyn Write,
    rows: usize,
    format: impl Fn(Range<usize>, &mut CsvText) + Sync,
) -> io::Result<()> {
    let two_cores = std::thread::available_parallelism().is_ok_and(|cores| cores.get() >= 2);
    write_blocks(sink, rows, BLOCK_ROWS, two_cores, format)
}

/// [`write_rows`] with blocks of `block_rows` rows, formatted on two threads when `helper` is set.
fn write_blocks(
    sink: &mut dyn Write,
    rows: usize,
    block_rows: usize,
    helper: bool,
    format: impl Fn(Range<usize>, &mut CsvText) + Sync,
) -> io::Result<()> {
    let blocks: Vec<Range<usize>> = (0..rows)
        .step_by(block_rows.max(1))
        .map(|start| start..(start + block_rows).min(rows))
        .collect();
    let mut own_text = CsvText::new();
    if !helper || blocks.len() < 2 {
        for block in blocks {
            own_text.clear();
            format(block, &mut own_text);
            sink.write_all(own_text.as_bytes())?;
        }
        return Ok(());
    }
    let stopped = || io::Error::other("the CSV formatting thread stopped");
    std::thread::scope(|scope| {
        let (job_sender, jobs) = mpsc::channel::<(Range<usize>, CsvText)>();
        let (done_sender, done) = mpsc::channel::<CsvText>();
        let format = &format;
        scope.spawn(move || {
            for (block, mut text) in jobs {
                text.clear();
                format(block, &mut text);
                if done_sender.send(text).is_err() {
                    break;
                }
            }
        });
        let mut helper_text = CsvText::new();
        for pair in blocks.chunks(2) {
            job_sender.send((pair[0].clone(), helper_text)).map_err(|_| stopped())?;
            own_text.clear();
            if let Some(block) = pair.get(1) {
                format(block.clone(), &mut own_text);
            }
            helper_text = done.recv().map_err(|_| stopped())?;
            sink.write_all(helper_text.as_bytes())?;
            sink.write_all(own_text.as_bytes())?;
        }
        Ok(())
    })
}

/// `bytes` grown to at least `needed` bytes (at least doubled), the new bytes zero.
#[cold]
#[inline(never)]
fn grown(mut bytes: Vec<u8>, needed: usize) -> Vec<u8> {
    let len = needed.max(2 * bytes.len());
    bytes.resize(len, 0);
    bytes
}

/// `10^N` for `N` up to [`MAX_DECIMALS`].
const fn power_of_ten<const N: usize>() -> u64 {
    10u64.pow(N as u32)
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

/// Writes the last `count` decimal digits of `value` (with leading zeros) so that they end before `end`: four
/// digits split off at a time (two independent pairs, in 32 bits), then a pair, then a single digit.
#[inline(always)]
fn put_digits(text: &mut [u8], mut end: usize, mut value: u64, mut count: usize) {
    while count >= 4 {
        let group = (value % 10_000) as u32;
        value /= 10_000;
        put_pair(text, end - 2, group % 100);
        put_pair(text, end - 4, group / 100);
        end -= 4;
        count -= 4;
    }
    if count >= 2 {
        put_pair(text, end - 2, (value % 100) as u32);
        value /= 100;
        end -= 2;
        count -= 2;
    }
    if count == 1 {
        text[end - 1] = b'0' + (value % 10) as u8;
    }
}

/// How many decimal digits `value` has (1 for 0): its bit length times log10(2) (1233/4096) is the number of digits
/// or one fewer, and one comparison with a power of ten decides (the standard library's `ilog10` is a call).
#[inline(always)]
fn decimal_digits(value: u64) -> usize {
    const POWERS: [u64; 20] = {
        let mut powers = [1u64; 20];
        let mut i = 1;
        while i < 20 {
            powers[i] = powers[i - 1] * 10;
            i += 1;
        }
        powers
    };
    let value = value | 1;
    let estimate = ((64 - value.leading_zeros() as usize) * 1233) >> 12;
    estimate + usize::from(value >= POWERS[estimate])
}

/// Writes the two digits of `pair` (below 100) at `at`.
#[inline(always)]
fn put_pair(text: &mut [u8], at: usize, pair: u32) {
    let pair = pair as usize;
    text[at..at + 2].copy_from_slice(&DIGIT_PAIRS[2 * pair..2 * pair + 2]);
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

/// A number given by ryu as `mantissa` (`d` or `d.ddd`) and decimal `exponent`, written as plain decimals.
#[cold]
fn expanded(mantissa: &[u8], exponent: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
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
    out
}

/// What `{x:.decimals$}` writes (the few values the fast path leaves to the formatter).
#[cold]
fn formatted_with_decimals(x: f64, decimals: u8) -> String {
    format!("{x:.*}", usize::from(decimals))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn written(push: impl FnOnce(&mut CsvText)) -> String {
        let mut out = CsvText::new();
        push(&mut out);
        String::from_utf8(out.as_bytes().to_vec()).unwrap_or_default()
    }

    fn f64_text(x: f64) -> String {
        written(|out| out.push_f64(x))
    }

    fn decimals_text(x: f64, decimals: u8) -> String {
        written(|out| out.push_f64_decimals(x, decimals))
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

        /// Any bit pattern, numbers of the sizes thermode writes, short decimals (divided and multiplied out, as
        /// a time column is made) and their neighbours one ulp away: the same text as `{}`.
        #[test]
        fn any_f64_is_written_as_display_writes_it(bits in proptest::num::u64::ANY, y in -1.0e5..1.0e5f64,
            raw in proptest::num::i64::ANY, digits in 1u32..=17, places in 0i32..=8) {
            let x = f64::from_bits(bits);
            let short = raw % 10i64.pow(digits);
            let divided = short as f64 / 10f64.powi(places);
            let multiplied = short as f64 * 10f64.powi(-places);
            let neighbour = f64::from_bits(divided.to_bits() + 1);
            for value in [x, y, divided, multiplied, neighbour] {
                proptest::prop_assert_eq!(f64_text(value), format!("{}", value));
            }
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
    fn digit_counts_match_the_written_integers() {
        for power in 0..20 {
            let ten = 10u64.pow(power);
            for value in [ten - 1, ten, ten + 1, ten.saturating_mul(5)] {
                assert_eq!(decimal_digits(value), value.to_string().len(), "{value}");
            }
        }
        assert_eq!(decimal_digits(u64::MAX), 20);
    }

    #[test]
    fn fields_are_quoted_only_when_needed() {
        let text = written(|out| {
            out.push_field("aluminium");
            out.push_byte(b'|');
            out.push_field("a,b\"c");
        });
        assert_eq!(text, "aluminium|\"a,b\"\"c\"");
    }

    #[test]
    fn the_text_grows_past_its_first_allocation_and_keeps_every_byte() {
        let mut expected = String::new();
        let text = written(|out| {
            for k in 0..20_000 {
                let x = f64::from(k) * 1.37e-3 - 7.0;
                out.push_f64(x);
                out.push_byte(b',');
                out.push_f64_decimals(x, 12);
                out.push_bytes(b";\n");
                expected.push_str(&format!("{x},{x:.12};\n"));
            }
        });
        assert!(expected.len() > INITIAL_BYTES, "{} bytes", expected.len());
        assert_eq!(text, expected);
    }

    /// Rows of a test CSV: a number exact, copied right after it (as `simulate` copies an equal column), with
    /// twelve decimals, and copied again further back.
    fn format_rows(rows: Range<usize>, text: &mut CsvText) {
        for row in rows {
            let x = (row as f64).sqrt() * 1.37 - 7.0;
            let start = text.len();
            text.push_f64(x);
            let span = (start, text.len());
            text.push_byte(b',');
            text.push_earlier(span);
            text.push_byte(b',');
            text.push_f64_decimals(x, 12);
            text.push_byte(b',');
            text.push_earlier(span);
            text.push_byte(b'\n');
        }
    }

    #[test]
    fn rows_formatted_on_two_threads_are_the_bytes_one_thread_writes() {
        let expected: String = (0..1001)
            .map(|row| {
                let x = (row as f64).sqrt() * 1.37 - 7.0;
                format!("{x},{x},{x:.12},{x}\n")
            })
            .collect();
        for rows in [0, 1, 999, 1000, 1001] {
            for (block_rows, helper) in [(100, true), (100, false), (333, true), (5000, true), (1, true)] {
                let mut sink = Vec::new();
                write_blocks(&mut sink, rows, block_rows, helper, format_rows).unwrap();
                let lines: usize = expected.lines().take(rows).map(|line| line.len() + 1).sum();
                assert_eq!(
                    String::from_utf8(sink).unwrap(),
                    expected[..lines],
                    "{rows} rows in blocks of {block_rows}, helper {helper}"
                );
            }
        }
    }

    #[test]
    fn a_sink_that_fails_stops_the_rows_with_its_error() {
        struct Full;
        impl Write for Full {
            fn write(&mut self, _: &[u8]) -> io::Result<usize> {
                Err(io::Error::new(io::ErrorKind::StorageFull, "disk full"))
            }
            fn flush(&mut self) -> io::Result<()> {
                Ok(())
            }
        }
        for helper in [true, false] {
            let error = write_blocks(&mut Full, 10_000, 100, helper, format_rows).unwrap_err();
            assert_eq!(error.kind(), io::ErrorKind::StorageFull, "helper {helper}");
        }
    }
}
