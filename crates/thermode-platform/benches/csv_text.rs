//! Criterion benchmark of the CSV number writers (issue 13, the CSV's share of a run): the eight numbers of a row of
//! `simulate --dt 0.001` written exact (`CsvText::push_f64`, the shortest round-trip digits) and at six decimals
//! (`CsvText::push_f64_decimals`), per number.
#![allow(missing_docs)] // criterion_main! generates an undocumented `main`

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use thermode_platform::csv_text::CsvText;

/// Rows of one benchmark iteration (10 s at 1 ms).
const ROWS: usize = 10_000;

/// Numbers like a kron contact's row: time, five temperatures relaxing from 32 towards 23 °C at different rates, a
/// heat flux and a set-point.
fn rows() -> Vec<[f64; 8]> {
    (0..ROWS)
        .map(|k| {
            let t = k as f64 * 1e-3;
            let relax = |tau: f64| 23.0 + 9.0 * (-t / tau).exp();
            let surface = relax(1.7);
            [
                t,
                surface,
                relax(2.3),
                relax(5.1),
                relax(11.0),
                900.0 * (surface - 22.0),
                relax(0.4),
                surface,
            ]
        })
        .collect()
}

fn writers(c: &mut Criterion) {
    let rows = rows();
    let mut group = c.benchmark_group("csv_numbers");
    group.throughput(Throughput::Elements((ROWS * 8) as u64));
    let mut out = CsvText::new();
    group.bench_function("exact", |b| {
        b.iter(|| {
            out.clear();
            for row in &rows {
                for &x in row {
                    out.push_f64(black_box(x));
                    out.push_byte(b',');
                }
            }
            black_box(out.len())
        })
    });
    group.bench_function("six_decimals", |b| {
        b.iter(|| {
            out.clear();
            for row in &rows {
                for &x in row {
                    out.push_f64_decimals(black_box(x), 6);
                    out.push_byte(b',');
                }
            }
            black_box(out.len())
        })
    });
    group.finish();
}

criterion_group!(benches, writers);
criterion_main!(benches);
