//! Fits the perceptual simulated participant once and writes `crates/thermode-lab/data/participant_fit.toml`:
//!
//!     cargo run --release -p thermode-lab --example fit_participant -- --write
//!
//! (a) The sensory noise follows in closed form from the 2AFC Weber fraction of heat-extraction rate (0.43,
//! Bergmann Tiest & Kappers 2009); (b) the non-thermal recognition probabilities are fitted to the paper's
//! real-condition identification rates (53, 54, 80, 97, 56 %) on 2000 persons × 3 trials per material of real
//! contact under the default fv model, 30 s; the response biases stay 0 (every material is presented equally often
//! and every object was shown beforehand). The memory noise is not fitted: it is the context-coding noise of the
//! references' perceived range at the 2.5-bit capacity of absolute identification (Miller 1956;
//! `perception::memory_noise_sd_for`), set before (b). Without `--write` it prints the fit only.

use thermode_lab::perception::{
    memory_noise_sd_for, perceived_range, PerceptionParams, PerceptualParticipant, IDENTIFICATION_CAPACITY_BITS,
};
use thermode_lab::runner::FvContact;
use thermode_lab::validation::{contact_features, fit_real_rates, PAPER_MATERIALS, PAPER_REAL_RATES};

/// Seed of the fit's common random numbers.
const FIT_SEED: u64 = 28;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let write = std::env::args().any(|a| a == "--write");
    let mut start = PerceptionParams::fitted();
    start.bias.values_mut().for_each(|b| *b = 0.0);
    let references = contact_features(&FvContact::default(), 30.0)?;
    let range = perceived_range(&references);
    let memory_sd = memory_noise_sd_for(range, IDENTIFICATION_CAPACITY_BITS);
    start.memory_noise_ratio = (memory_sd / start.sensory_sd() * 1e4).round() / 1e4;
    let options: Vec<String> = PAPER_MATERIALS.iter().map(|s| s.to_string()).collect();
    let base = PerceptualParticipant::new(options, &references, start, FIT_SEED)?;
    let (mut params, rates) = fit_real_rates(&base, &PAPER_REAL_RATES, 2000, 3);
    params.fitted_on = today_utc();
    params.inputs = "2AFC Weber fraction 0.43 (Bergmann Tiest & Kappers 2009); real-condition rates 0.53 0.54 0.80 \
                     0.97 0.56 (paper Tables 2-3); fv contact, 30 s; 2000 persons x 3 trials, seed 28; memory noise: perceived \
                     range / (2^2.5 sqrt(2 pi e)) (capacity 2.5 bits, Miller 1956)"
        .to_string();
    println!("sensory sd {:.4}", params.sensory_sd());
    for (name, r) in PAPER_MATERIALS.iter().zip(&references) {
        let q = r.perceived();
        println!("{name:10} perceived real-contact cues {:.3} {:.3}", q[0], q[1]);
    }
    println!(
        "perceived range {range:.3}, memory sd {memory_sd:.4}, memory/sensory ratio {}",
        params.memory_noise_ratio
    );
    for ((name, target), rate) in PAPER_MATERIALS.iter().zip(PAPER_REAL_RATES).zip(&rates) {
        println!(
            "{name:10} target {target:.2} thermal alone {rate:.3} non-thermal recognition {:.4} bias {:+.4}",
            params.non_thermal_recognition[*name], params.bias[*name]
        );
    }
    if write {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/data/participant_fit.toml");
        std::fs::write(path, params.to_toml())?;
        println!("wrote {path}");
    }
    Ok(())
}

/// Today's date (UTC) as YYYY-MM-DD (civil-from-days, H. Hinnant's algorithm).
fn today_utc() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let z = (secs / 86_400) as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!("{year:04}-{month:02}-{day:02}")
}
