//! The lab's random numbers: one reproducible ChaCha8 stream per trial ([`trial_rng`]) and standard normal draws
//! from it ([`standard_normal`]), shared by the simulated participant (perceptual noise) and the stimuli (finger
//! drift), so that a resumed session draws the same numbers.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A standard normal number (Box–Muller on two uniforms from `rng`).
pub fn standard_normal(rng: &mut impl Rng) -> f64 {
    let u1: f64 = 1.0 - rng.gen::<f64>(); // (0, 1]: the logarithm stays finite
    let u2: f64 = rng.gen::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// The random stream of one trial: ChaCha8 seeded with `seed`, stream number `participant_index · 2³² + trial`.
pub fn trial_rng(seed: u64, participant_index: usize, trial: usize) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(((participant_index as u64) << 32) | (trial as u64 & 0xffff_ffff));
    rng
}
