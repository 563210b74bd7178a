//! Two semi-infinite bodies in contact: the paper's model (a) (after Ho & Jones) and the analytic anchor for the
//! finite-volume model (`model.md` §4).
//!
//! Skin (effusivity e_s, initial temperature T_s) meets an object (e_o, T_o) at t = 0.
//! - Perfect contact: the interface is at T_c = (e_s T_s + e_o T_o)/(e_s + e_o) for all t > 0, and inside the skin
//!   T(x, t) = T_c + (T_s − T_c) erf(x / 2√(a_s t)).
//! - With a contact resistance R_c [m²K/W]: with β = (1/R_c)(1/e_s + 1/e_o),
//!   T_surface(t) = T_s − (T_s − T_o) · e_o/(e_s + e_o) · [1 − exp(β²t) erfc(β√t)].

use std::f64::consts::PI;

/// Contact temperature of two semi-infinite bodies in perfect contact \[°C\].
pub fn interface_temperature_c(
    skin_effusivity: f64,
    skin_initial_c: f64,
    object_effusivity: f64,
    object_initial_c: f64,
) -> f64 {
    (skin_effusivity * skin_initial_c + object_effusivity * object_initial_c) / (skin_effusivity + object_effusivity)
}

/// Temperature inside the skin at depth `depth_m` (m) and time `time_s` (s) after perfect contact \[°C\].
/// `skin_diffusivity_m2_s` is a_s = k/(ρc). At t ≤ 0 the skin is still at its initial temperature.
pub fn skin_temperature_at_depth_c(
    interface_c: f64,
    skin_initial_c: f64,
    skin_diffusivity_m2_s: f64,
    depth_m: f64,
    time_s: f64,
) -> f64 {
    if time_s <= 0.0 {
        return skin_initial_c;
    }
    let eta = depth_m / (2.0 * (skin_diffusivity_m2_s * time_s).sqrt());
    interface_c + (skin_initial_c - interface_c) * libm::erf(eta)
}

/// β = (1/R_c)(1/e_s + 1/e_o) [1/√s] of the contact-resistance solution.
pub fn contact_beta(skin_effusivity: f64, object_effusivity: f64, contact_resistance_m2k_w: f64) -> f64 {
    (1.0 / contact_resistance_m2k_w) * (1.0 / skin_effusivity + 1.0 / object_effusivity)
}

/// Skin surface temperature at `time_s` (s) after contact through a contact resistance `contact_resistance_m2k_w`
/// [m²K/W]; a resistance of zero gives the perfect-contact interface temperature. At t ≤ 0 it is `skin_initial_c`.
pub fn surface_temperature_c(
    skin_effusivity: f64,
    skin_initial_c: f64,
    object_effusivity: f64,
    object_initial_c: f64,
    contact_resistance_m2k_w: f64,
    time_s: f64,
) -> f64 {
    if time_s <= 0.0 {
        return skin_initial_c;
    }
    let share = object_effusivity / (skin_effusivity + object_effusivity);
    if contact_resistance_m2k_w <= 0.0 {
        return skin_initial_c - (skin_initial_c - object_initial_c) * share;
    }
    let beta = contact_beta(skin_effusivity, object_effusivity, contact_resistance_m2k_w);
    skin_initial_c - (skin_initial_c - object_initial_c) * share * (1.0 - erfcx(beta * time_s.sqrt()))
}

/// Heat flux out of the skin surface into the object at `time_s` (s) after contact [W/m²] (t > 0).
///
/// Perfect contact: q = e_s (T_s − T_c)/√(πt). With a contact resistance the object's face rises as the skin's
/// surface falls, mirrored (weight e_s instead of e_o), so the drop across the resistance is
/// (T_s − T_o)·exp(β²t)erfc(β√t) and q = (T_s − T_o)·exp(β²t)erfc(β√t)/R_c.
pub fn surface_heat_flux_w_m2(
    skin_effusivity: f64,
    skin_initial_c: f64,
    object_effusivity: f64,
    object_initial_c: f64,
    contact_resistance_m2k_w: f64,
    time_s: f64,
) -> f64 {
    let difference = skin_initial_c - object_initial_c;
    if contact_resistance_m2k_w <= 0.0 {
        let share = object_effusivity / (skin_effusivity + object_effusivity);
        return skin_effusivity * difference * share / (PI * time_s).sqrt();
    }
    let beta = contact_beta(skin_effusivity, object_effusivity, contact_resistance_m2k_w);
    difference * erfcx(beta * time_s.sqrt()) / contact_resistance_m2k_w
}

/// The scaled complementary error function exp(x²)·erfc(x) for x ≥ 0, accurate where exp(x²) alone overflows.
///
/// Below x = 25 it multiplies libm's erfc (relatively accurate down to its underflow near x = 26.5) by exp(x²);
/// above, the asymptotic series 1/(x√π) · (1 − 1/(2x²) + 3/(4x⁴) − 15/(8x⁶) + 105/(16x⁸)), whose next term is
/// below 1e-12 of the sum there.
pub fn erfcx(x: f64) -> f64 {
    if x < 25.0 {
        libm::erfc(x) * (x * x).exp()
    } else {
        erfcx_asymptotic(x)
    }
}

fn erfcx_asymptotic(x: f64) -> f64 {
    let inv2 = 1.0 / (x * x);
    let series = 1.0 - 0.5 * inv2 + 0.75 * inv2 * inv2 - 1.875 * inv2.powi(3) + 6.5625 * inv2.powi(4);
    series / (x * PI.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn erfcx_is_continuous_at_the_switch_and_matches_known_values() {
        // exp(1) erfc(1) = 0.427583576155807 (tables of the scaled complementary error function).
        let at_one = erfcx(1.0);
        assert!((at_one - 0.427_583_576_155_807).abs() < 1e-14, "erfcx(1) = {at_one}");
        assert_eq!(erfcx(0.0), 1.0);
        for x in [24.0, 25.0, 26.0] {
            let direct = libm::erfc(x) * (x * x).exp();
            let series = erfcx_asymptotic(x);
            assert!(
                ((direct - series) / direct).abs() < 1e-12,
                "x = {x}: direct {direct}, series {series}"
            );
        }
        // Large x: erfcx(x) → 1/(x√π).
        let x = 1.0e6;
        let got = erfcx(x);
        let want = 1.0 / (x * PI.sqrt());
        assert!(
            ((got - want) / want).abs() < 1e-12,
            "erfcx(1e6) = {got}, 1/(x√π) = {want}"
        );
    }

    #[test]
    fn contact_resistance_solution_starts_at_skin_and_tends_to_perfect_contact() {
        let (es, ts, eo, to) = (1100.0, 33.0, 24_000.0, 23.0);
        let tc = interface_temperature_c(es, ts, eo, to);
        let early = surface_temperature_c(es, ts, eo, to, 1e-3, 1e-9);
        assert!((early - ts).abs() < 1e-3, "just after contact {early}, skin {ts}");
        // The approach is algebraic: T − T_c ≈ (T_s − T_o)·share/(β√(πt)).
        let late = surface_temperature_c(es, ts, eo, to, 1e-3, 1e12);
        assert!(
            (late - tc).abs() < 1e-5,
            "long after contact {late}, perfect contact {tc}"
        );
        let perfect = surface_temperature_c(es, ts, eo, to, 0.0, 1.0);
        assert_eq!(perfect, tc);
    }

    #[test]
    fn heat_flux_starts_at_the_resistance_limit_and_joins_perfect_contact() {
        let (es, ts, eo, to, rc) = (1100.0, 33.0, 24_000.0, 23.0, 1e-3);
        let first = surface_heat_flux_w_m2(es, ts, eo, to, rc, 1e-12);
        let want = (ts - to) / rc;
        assert!(
            (first - want).abs() < 1e-3 * want,
            "q(0+) = {first}, (T_s − T_o)/R_c = {want}"
        );
        let t = 1e8;
        let with = surface_heat_flux_w_m2(es, ts, eo, to, rc, t);
        let perfect = surface_heat_flux_w_m2(es, ts, eo, to, 0.0, t);
        assert!(
            ((with - perfect) / perfect).abs() < 1e-3,
            "late q {with} vs perfect contact {perfect}"
        );
    }

    #[test]
    fn heat_flux_integrates_to_the_energy_the_skin_loses() {
        // Perfect contact: the skin's temperature deficit ∫ (T_s − T) ρc dx = (T_s − T_c)·ρc·2√(a t/π) must equal
        // ∫ q dt = 2 e_s (T_s − T_c) √(t/π); with ρc√a = e_s the two agree. Check the flux by quadrature.
        let (es, ts, eo, to) = (1000.0, 34.0, 3000.0, 24.0);
        let tc = interface_temperature_c(es, ts, eo, to);
        let t_end: f64 = 4.0;
        let n = 400_000;
        let h = t_end / n as f64;
        let integral: f64 = (0..n)
            .map(|i| surface_heat_flux_w_m2(es, ts, eo, to, 0.0, (i as f64 + 0.5) * h) * h)
            .sum();
        let want = 2.0 * es * (ts - tc) * (t_end / PI).sqrt();
        assert!(
            ((integral - want) / want).abs() < 2e-3,
            "∫q dt = {integral}, analytic {want}"
        );
    }

    #[test]
    fn interface_temperature_is_effusivity_weighted_mean() {
        // Equal effusivities meet half-way.
        assert_eq!(interface_temperature_c(1000.0, 34.0, 1000.0, 24.0), 29.0);
        let depth = skin_temperature_at_depth_c(29.0, 34.0, 1e-7, 0.0, 5.0);
        assert_eq!(depth, 29.0);
        let deep = skin_temperature_at_depth_c(29.0, 34.0, 1e-7, 0.05, 5.0);
        assert!((deep - 34.0).abs() < 1e-9, "deep inside the skin {deep}");
    }
}
