//! Unit conversions between the paper's cgs-calorie units and SI.
//!
//! 1 cal = 4.1868 J (international table calorie), so
//! k[W/m·K] = 418.68 · k[cal/cm·s·°C], c[J/kg·K] = 4186.8 · c[cal/g·°C], ρ[kg/m³] = 1000 · ρ[g/cm³].

/// Joules per (international table) calorie.
pub const JOULES_PER_CALORIE: f64 = 4.1868;

/// W/(m·K) per cal/(cm·s·°C).
pub const CONDUCTIVITY_SI_PER_CGS: f64 = JOULES_PER_CALORIE * 100.0;
/// J/(kg·K) per cal/(g·°C).
pub const SPECIFIC_HEAT_SI_PER_CGS: f64 = JOULES_PER_CALORIE * 1000.0;
/// kg/m³ per g/cm³.
pub const DENSITY_SI_PER_CGS: f64 = 1000.0;

/// Thermal conductivity: cal/(cm·s·°C) → W/(m·K).
pub fn conductivity_to_si(k_cal_cm_s_c: f64) -> f64 {
    k_cal_cm_s_c * CONDUCTIVITY_SI_PER_CGS
}

/// Thermal conductivity: W/(m·K) → cal/(cm·s·°C).
pub fn conductivity_to_cgs(k_w_mk: f64) -> f64 {
    k_w_mk / CONDUCTIVITY_SI_PER_CGS
}

/// Specific heat: cal/(g·°C) → J/(kg·K).
pub fn specific_heat_to_si(c_cal_g_c: f64) -> f64 {
    c_cal_g_c * SPECIFIC_HEAT_SI_PER_CGS
}

/// Specific heat: J/(kg·K) → cal/(g·°C).
pub fn specific_heat_to_cgs(c_j_kgk: f64) -> f64 {
    c_j_kgk / SPECIFIC_HEAT_SI_PER_CGS
}

/// Density: g/cm³ → kg/m³.
pub fn density_to_si(rho_g_cm3: f64) -> f64 {
    rho_g_cm3 * DENSITY_SI_PER_CGS
}

/// Density: kg/m³ → g/cm³.
pub fn density_to_cgs(rho_kg_m3: f64) -> f64 {
    rho_kg_m3 / DENSITY_SI_PER_CGS
}

/// Thermal effusivity e = √(kρc) [W·s^½/(m²·K)]: how strongly a body pulls the contact temperature towards its own.
pub fn effusivity(conductivity_w_mk: f64, density_kg_m3: f64, specific_heat_j_kgk: f64) -> f64 {
    (conductivity_w_mk * density_kg_m3 * specific_heat_j_kgk).sqrt()
}

/// Thermal diffusivity a = k/(ρc) [m²/s].
pub fn diffusivity_m2_s(conductivity_w_mk: f64, density_kg_m3: f64, specific_heat_j_kgk: f64) -> f64 {
    conductivity_w_mk / (density_kg_m3 * specific_heat_j_kgk)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_are_exact_to_rounding() {
        for v in [0.526, 0.00033, 1.0e-6, 12.5] {
            let back = conductivity_to_cgs(conductivity_to_si(v));
            assert!((back - v).abs() <= 1e-15 * v.max(1.0), "k: {v} -> {back}");
            let back = specific_heat_to_cgs(specific_heat_to_si(v));
            assert!((back - v).abs() <= 1e-15 * v.max(1.0), "c: {v} -> {back}");
            let back = density_to_cgs(density_to_si(v));
            assert!((back - v).abs() <= 1e-15 * v.max(1.0), "rho: {v} -> {back}");
        }
    }

    #[test]
    fn aluminium_from_table_1_converts_to_handbook_si() {
        // Table 1: k = 0.526 cal/cm·s·°C, c = 0.215 cal/g·°C, ρ = 2.70 g/cm³; handbooks give ≈ 220 W/m·K, 900 J/kg·K.
        let k = conductivity_to_si(0.526);
        let c = specific_heat_to_si(0.215);
        assert!((k - 220.2).abs() < 0.1, "k = {k}");
        assert!((c - 900.2).abs() < 0.1, "c = {c}");
        assert_eq!(density_to_si(2.70), 2700.0);
    }
}
