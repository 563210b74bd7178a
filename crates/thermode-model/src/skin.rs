//! Skin parameters: layers (outermost first), blood and air, a default fingertip, and skin files.
//!
//! A skin file is TOML: one `[[layer]]` table per tissue layer, outermost first, then optional `[blood]` and `[air]`
//! sections (see [`Skin::from_toml_str`]). [`Skin::to_toml_string`] writes the same shape back, exactly.

use serde::Serialize;

use crate::error::{At, ParamError};
use crate::limits;
use crate::params::{self, Rule, Table, DENSITY, SPECIFIC_HEAT};

/// One tissue layer.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SkinLayer {
    /// Layer name (e.g. "epidermis").
    pub name: String,
    /// Thickness Δx \[m\].
    pub thickness_m: f64,
    /// Thermal conductivity k [W/(m·K)].
    pub conductivity_w_mk: f64,
    /// Density ρ [kg/m³].
    pub density_kg_m3: f64,
    /// Specific heat capacity c [J/(kg·K)].
    pub specific_heat_j_kgk: f64,
    /// Blood perfusion rate ω_b \[1/s\] (volume of blood per volume of tissue per second, Pennes). Default 0.
    pub perfusion_per_s: f64,
    /// Metabolic heat q_m [W/m³]. Default 0.
    pub metabolic_w_m3: f64,
}

/// Arterial blood (Pennes' bio-heat term).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Blood {
    /// Arterial blood temperature T_art \[°C\]; the paper uses 36.8 °C.
    pub arterial_c: f64,
    /// Blood density ρ_b [kg/m³].
    pub density_kg_m3: f64,
    /// Blood specific heat c_b [J/(kg·K)].
    pub specific_heat_j_kgk: f64,
}

/// A complete skin description: layers outermost first, blood, and the convection coefficient in air.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Skin {
    /// Tissue layers, outermost (epidermis) first.
    pub layers: Vec<SkinLayer>,
    /// Arterial blood properties.
    pub blood: Blood,
    /// Heat transfer coefficient from skin to still air, convection plus radiation, α [W/(m²·K)].
    pub air_convection_w_m2k: f64,
}

/// Arterial blood temperature \[°C\], as in the paper (its refs. [17, 22]).
pub const ARTERIAL_C: f64 = 36.8;

/// Heat transfer coefficient from a resting finger to still room air, natural convection plus linearised radiation
/// [W/(m²·K)] (`model.md` §1: about 10 W/m²K; roughly 4–5 convective plus 5–6 radiative at skin temperature).
pub const AIR_CONVECTION_W_M2K: f64 = 10.0;

/// Perfusion of the default fingertip's subcutis \[1/s\] (≈ 12.8 ml blood per 100 ml tissue per minute).
///
/// Chosen so that the three-layer (Kron) model of [`Skin::fingertip`] at steady state in still air at 23 °C has an
/// epidermis temperature T1 of 32.0 °C, a typical fingertip at room temperature. Closed form: the heat lost to air
/// is q = α(T1 − 23 °C) = 90 W/m²; it crosses the series conductances G12 and G23, so
/// T3 = T1 + q(1/G12 + 1/G23) = 33.32 °C; the Pennes term must supply it, P = q/(T_art − T3) with
/// P = ω ρ_b c_b Δx3, giving ω = 0.002138 1/s, rounded to 0.00214 (T1 = 32.00 °C). Individual fingers differ;
/// `calibrate_to_surface` in the Kron module rescales it to a measured resting temperature.
pub const FINGERTIP_PERFUSION_PER_S: f64 = 0.00214;

impl Skin {
    /// The default fingertip: three layers (epidermis, dermis, subcutis) with perfusion in the deepest layer only,
    /// as in the paper.
    ///
    /// | layer | Δx \[mm\] | k [W/m·K] | ρ [kg/m³] | c [J/kg·K] | ω \[1/s\] |
    /// |---|---|---|---|---|---|
    /// | epidermis | 0.5 | 0.21 | 1150 | 3600 | 0 |
    /// | dermis | 1.5 | 0.37 | 1116 | 3224 | 0 |
    /// | subcutis | 3.0 | 0.16 | 971 | 2303 | 0.00214 |
    ///
    /// Sources:
    /// - Thicknesses: the epidermis of the volar (glabrous) fingertip is thick, about 0.4–0.7 mm, most of it stratum
    ///   corneum (Fruhstorfer et al., "Thickness of the stratum corneum of the volar fingertips", Clin. Anat. 13
    ///   (2000) 429–433); 0.5 mm is used. Dermis 1–4 mm by body site (Ye & De, "Thermal injury of skin and
    ///   subcutaneous tissues: a review", Burns 43 (2017) 909–932, Table 1); 1.5 mm, the thin end, for the
    ///   fingertip. Subcutis 3 mm: a modelling choice of the order of the fingertip pulp between dermis and distal
    ///   phalanx; its effect on the surface temperature is absorbed by the perfusion calibration.
    /// - Conductivity and specific heat: Ye & De (2017), Table 3 (epidermis k 0.21, c 3600; dermis k 0.37, c 3224;
    ///   subcutaneous fat k 0.16, c 2303 — in-vitro porcine values, the only complete set there; human epidermis
    ///   k 0.21 agrees).
    /// - Density: Ye & De (2017), Table 1, human: epidermis 1110–1190 (1150 used), dermis 1116, subcutaneous fat 971.
    /// - Perfusion: see [`FINGERTIP_PERFUSION_PER_S`]. Metabolic heat is 0: resting tissue produces a few hundred
    ///   W/m³, i.e. about 1 W/m² over 3 mm against 90 W/m² lost to air, and the perfusion calibration absorbs it.
    /// - Blood: T_art = 36.8 °C as in the paper; ρ_b = 1060 kg/m³ and c_b = 3800 J/(kg·K), within the literature
    ///   range (1050–1060 kg/m³, 3600–3900 J/(kg·K); e.g. the IT'IS Foundation tissue database lists 1050 and 3617).
    /// - Air: α = 10 W/(m²·K) ([`AIR_CONVECTION_W_M2K`]).
    pub fn fingertip() -> Skin {
        let layer = |name: &str, thickness_mm: f64, k: f64, rho: f64, c: f64, omega: f64| SkinLayer {
            name: name.to_string(),
            thickness_m: thickness_mm * 1e-3,
            conductivity_w_mk: k,
            density_kg_m3: rho,
            specific_heat_j_kgk: c,
            perfusion_per_s: omega,
            metabolic_w_m3: 0.0,
        };
        Skin {
            layers: vec![
                layer("epidermis", 0.5, 0.21, 1150.0, 3600.0, 0.0),
                layer("dermis", 1.5, 0.37, 1116.0, 3224.0, 0.0),
                layer("subcutis", 3.0, 0.16, 971.0, 2303.0, FINGERTIP_PERFUSION_PER_S),
            ],
            blood: Blood {
                arterial_c: ARTERIAL_C,
                density_kg_m3: 1060.0,
                specific_heat_j_kgk: 3800.0,
            },
            air_convection_w_m2k: AIR_CONVECTION_W_M2K,
        }
    }

    /// A copy with every layer's perfusion multiplied by `factor` (used to calibrate to a measured resting surface
    /// temperature). `factor` should be finite and not negative; [`Skin::validate`] rejects the result otherwise.
    pub fn with_perfusion_scaled(&self, factor: f64) -> Skin {
        let mut skin = self.clone();
        for layer in &mut skin.layers {
            layer.perfusion_per_s *= factor;
        }
        skin
    }

    /// Checks every value against its physical range ([`crate::limits`]): at least one layer; non-empty names;
    /// thickness ([`limits::SKIN_LAYER_THICKNESS`]), conductivity, density, specific heat and metabolic heat of
    /// every layer; arterial temperature, blood density and specific heat; the air's heat transfer coefficient.
    /// Perfusion only has to be finite and not negative here: the resting-surface calibration scales it beyond
    /// [`limits::PERFUSION`] by design; skin files are held to that range ([`Skin::from_toml_str`]). `origin`
    /// appears in the error.
    pub fn validate(&self, origin: &str) -> Result<(), ParamError> {
        if self.layers.is_empty() {
            return Err(ParamError::Invalid {
                origin: origin.to_string(),
                message: "a skin needs at least one layer".into(),
            });
        }
        for (i, layer) in self.layers.iter().enumerate() {
            validate_layer(origin, &layer_prefix(i), layer)?;
        }
        for (key, value, range) in [
            ("blood.arterial_c", self.blood.arterial_c, limits::ARTERIAL_TEMPERATURE),
            ("blood.density_kg_m3", self.blood.density_kg_m3, limits::DENSITY),
            (
                "blood.specific_heat_j_kgk",
                self.blood.specific_heat_j_kgk,
                limits::SPECIFIC_HEAT,
            ),
            (
                "air.convection_w_m2k",
                self.air_convection_w_m2k,
                limits::AIR_CONVECTION,
            ),
        ] {
            range.rule().check(key, value).at(origin)?;
        }
        Ok(())
    }

    /// Reads a skin file (TOML). `origin` (usually the file name) appears in every error.
    ///
    /// Shape: one `[[layer]]` table per layer, outermost first, each with `name`, `thickness_m`, conductivity
    /// (`conductivity_w_mk` or `conductivity_cal_cm_s_c`), density (`density_kg_m3` or `density_g_cm3`), specific
    /// heat (`specific_heat_j_kgk` or `specific_heat_cal_g_c`), optional `perfusion_per_s` and `metabolic_w_m3`
    /// (default 0). `[blood]` holds `arterial_c`, density and specific heat (same spelling choices); `[air]` holds
    /// `convection_w_m2k`. Each section present must be complete; an absent `[blood]` or `[air]` section takes the
    /// [`Skin::fingertip`] values. Exactly one spelling per quantity; every number must lie in its physical range
    /// (see [`Skin::validate`]; perfusion in [`limits::PERFUSION`]); unknown keys, wrong types and bad numbers are
    /// errors naming the key (layers as `layer[1]`, `layer[2]`, … counted from the outermost).
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Skin, ParamError> {
        let toml = params::parse(text, origin)?;
        let file = Table::new(&toml, origin);
        let defaults = Skin::fingertip();
        let layers = match file.sections("layer")? {
            Some(tables) => tables.iter().map(parse_layer).collect::<Result<_, _>>()?,
            None => Vec::new(),
        };
        let blood = match file.section("blood")? {
            Some(t) => parse_blood(&t)?,
            None => defaults.blood,
        };
        let air_convection_w_m2k = match file.section("air")? {
            Some(air) => {
                let value = air.required_number("convection_w_m2k", limits::AIR_CONVECTION.rule())?;
                air.finish()?;
                value
            }
            None => defaults.air_convection_w_m2k,
        };
        file.finish()?;
        let skin = Skin {
            layers,
            blood,
            air_convection_w_m2k,
        };
        skin.validate(origin)?;
        Ok(skin)
    }

    /// Writes the skin as a skin file in the shape [`Skin::from_toml_str`] reads (SI spellings, all sections).
    /// Numbers are written in Rust's shortest round-trip form, so reading the text back gives an identical `Skin`.
    pub fn to_toml_string(&self) -> String {
        let mut out = String::new();
        for layer in &self.layers {
            out.push_str("[[layer]]\n");
            out.push_str(&format!("name = {}\n", toml::Value::String(layer.name.clone())));
            push_number(&mut out, "thickness_m", layer.thickness_m);
            push_number(&mut out, "conductivity_w_mk", layer.conductivity_w_mk);
            push_number(&mut out, "density_kg_m3", layer.density_kg_m3);
            push_number(&mut out, "specific_heat_j_kgk", layer.specific_heat_j_kgk);
            push_number(&mut out, "perfusion_per_s", layer.perfusion_per_s);
            push_number(&mut out, "metabolic_w_m3", layer.metabolic_w_m3);
            out.push('\n');
        }
        out.push_str("[blood]\n");
        push_number(&mut out, "arterial_c", self.blood.arterial_c);
        push_number(&mut out, "density_kg_m3", self.blood.density_kg_m3);
        push_number(&mut out, "specific_heat_j_kgk", self.blood.specific_heat_j_kgk);
        out.push_str("\n[air]\n");
        push_number(&mut out, "convection_w_m2k", self.air_convection_w_m2k);
        out
    }
}

/// `{:?}` of an f64 is the shortest text that parses back to the same number and is valid TOML for finite values.
fn push_number(out: &mut String, key: &str, value: f64) {
    out.push_str(&format!("{key} = {value:?}\n"));
}

fn layer_prefix(index: usize) -> String {
    format!("layer[{}].", index + 1)
}

fn validate_layer(origin: &str, prefix: &str, layer: &SkinLayer) -> Result<(), ParamError> {
    if layer.name.trim().is_empty() {
        return Err(ParamError::Invalid {
            origin: origin.to_string(),
            message: format!("`{prefix}name` is empty"),
        });
    }
    for (key, value, rule) in [
        ("thickness_m", layer.thickness_m, limits::SKIN_LAYER_THICKNESS.rule()),
        (
            "conductivity_w_mk",
            layer.conductivity_w_mk,
            limits::CONDUCTIVITY.rule(),
        ),
        ("density_kg_m3", layer.density_kg_m3, limits::DENSITY.rule()),
        (
            "specific_heat_j_kgk",
            layer.specific_heat_j_kgk,
            limits::SPECIFIC_HEAT.rule(),
        ),
        // Calibrated skins scale the perfusion beyond its range of measured tissues (see `Skin::validate`).
        ("perfusion_per_s", layer.perfusion_per_s, Rule::NonNegative),
        ("metabolic_w_m3", layer.metabolic_w_m3, limits::METABOLIC_HEAT.rule()),
    ] {
        if !rule.admits(value) {
            return rule.check(format!("{prefix}{key}"), value).at(origin).map(drop);
        }
    }
    Ok(())
}

fn parse_layer(t: &Table) -> Result<SkinLayer, ParamError> {
    // `source` is allowed (and ignored) so that a layer can say where its numbers come from.
    t.string("source")?;
    let layer = SkinLayer {
        name: t.required_string("name")?,
        thickness_m: t.required_number("thickness_m", limits::SKIN_LAYER_THICKNESS.rule())?,
        conductivity_w_mk: t.required_either(params::CONDUCTIVITY, limits::CONDUCTIVITY.rule())?,
        density_kg_m3: t.required_either(DENSITY, limits::DENSITY.rule())?,
        specific_heat_j_kgk: t.required_either(SPECIFIC_HEAT, limits::SPECIFIC_HEAT.rule())?,
        perfusion_per_s: t.number("perfusion_per_s", limits::PERFUSION.rule())?.unwrap_or(0.0),
        metabolic_w_m3: t
            .number("metabolic_w_m3", limits::METABOLIC_HEAT.rule())?
            .unwrap_or(0.0),
    };
    t.finish()?;
    Ok(layer)
}

fn parse_blood(t: &Table) -> Result<Blood, ParamError> {
    let blood = Blood {
        arterial_c: t.required_number("arterial_c", limits::ARTERIAL_TEMPERATURE.rule())?,
        density_kg_m3: t.required_either(DENSITY, limits::DENSITY.rule())?,
        specific_heat_j_kgk: t.required_either(SPECIFIC_HEAT, limits::SPECIFIC_HEAT.rule())?,
    };
    t.finish()?;
    Ok(blood)
}

#[cfg(test)]
mod tests {
    use super::*;

    const EXAMPLE: &str = r#"
[[layer]]
name = "epidermis"
thickness_m = 0.0005
conductivity_w_mk = 0.21
density_kg_m3 = 1100
specific_heat_j_kgk = 3600
perfusion_per_s = 0.0
metabolic_w_m3 = 0.0
[blood]
arterial_c = 36.8
density_kg_m3 = 1060
specific_heat_j_kgk = 3800
[air]
convection_w_m2k = 10.0
"#;

    fn error_of(text: &str) -> ParamError {
        match Skin::from_toml_str(text, "skin.toml") {
            Ok(s) => panic!("accepted {s:?}"),
            Err(e) => e,
        }
    }

    fn key_of(e: &ParamError) -> String {
        match e {
            ParamError::BadValue { source, origin } => {
                assert_eq!(origin, "skin.toml");
                source.name.to_string()
            }
            ParamError::MissingKey { key, origin }
            | ParamError::UnknownKey { key, origin }
            | ParamError::WrongType { key, origin, .. } => {
                assert_eq!(origin, "skin.toml");
                key.clone()
            }
            other => panic!("no key in {other:?}"),
        }
    }

    #[test]
    fn the_issue_example_reads() {
        let skin = Skin::from_toml_str(EXAMPLE, "skin.toml").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(skin.layers.len(), 1);
        let l = &skin.layers[0];
        assert_eq!(
            (
                l.thickness_m,
                l.conductivity_w_mk,
                l.density_kg_m3,
                l.specific_heat_j_kgk
            ),
            (0.0005, 0.21, 1100.0, 3600.0)
        );
        assert_eq!(
            skin.blood,
            Blood {
                arterial_c: 36.8,
                density_kg_m3: 1060.0,
                specific_heat_j_kgk: 3800.0
            }
        );
        assert_eq!(skin.air_convection_w_m2k, 10.0);
    }

    #[test]
    fn absent_sections_take_fingertip_defaults_and_optional_keys_default_to_zero() {
        let text = "[[layer]]\nname = \"a\"\nthickness_m = 0.001\nconductivity_cal_cm_s_c = 0.001\n\
                    density_g_cm3 = 1.0\nspecific_heat_cal_g_c = 0.9\n";
        let skin = Skin::from_toml_str(text, "skin.toml").unwrap_or_else(|e| panic!("{e}"));
        let fingertip = Skin::fingertip();
        assert_eq!(skin.blood, fingertip.blood);
        assert_eq!(skin.air_convection_w_m2k, fingertip.air_convection_w_m2k);
        let l = &skin.layers[0];
        assert!(
            (l.conductivity_w_mk - 0.41868).abs() < 1e-15,
            "k {}",
            l.conductivity_w_mk
        );
        assert!((l.density_kg_m3 - 1000.0).abs() < 1e-12 && (l.specific_heat_j_kgk - 0.9 * 4186.8).abs() < 1e-9);
        assert_eq!((l.perfusion_per_s, l.metabolic_w_m3), (0.0, 0.0));
    }

    #[test]
    fn to_toml_round_trips_exactly() {
        let mut skin = Skin::fingertip();
        skin.layers[1].metabolic_w_m3 = 368.1;
        skin.layers[0].name = "epi \"dermis\"".to_string();
        // Numbers without a short decimal form, inside their physical ranges.
        skin.layers[2].perfusion_per_s = 1.0 / 30.0;
        skin.blood.arterial_c = 36.8 + f64::EPSILON * 32.0;
        skin.air_convection_w_m2k = 10.0 / 3.0;
        let text = skin.to_toml_string();
        let back = Skin::from_toml_str(&text, "written").unwrap_or_else(|e| panic!("{e}\n{text}"));
        assert_eq!(back, skin, "text:\n{text}");
        assert_eq!(
            Skin::from_toml_str(&Skin::fingertip().to_toml_string(), "w"),
            Ok(Skin::fingertip())
        );
    }

    #[test]
    fn fingertip_is_valid_and_perfused_only_in_the_deepest_layer() {
        let skin = Skin::fingertip();
        assert_eq!(skin.validate("built-in"), Ok(()));
        assert_eq!(skin.layers.len(), 3);
        assert!(skin.layers[..2]
            .iter()
            .all(|l| l.perfusion_per_s == 0.0 && l.metabolic_w_m3 == 0.0));
        assert!(skin.layers[2].perfusion_per_s > 0.0);
    }

    #[test]
    fn perfusion_scaling_scales_every_layer() {
        let mut skin = Skin::fingertip();
        skin.layers[0].perfusion_per_s = 0.001;
        let scaled = skin.with_perfusion_scaled(2.5);
        for (a, b) in skin.layers.iter().zip(&scaled.layers) {
            assert_eq!(b.perfusion_per_s, a.perfusion_per_s * 2.5);
            assert_eq!(b.thickness_m, a.thickness_m);
        }
        assert!(skin.with_perfusion_scaled(f64::NAN).validate("x").is_err());
    }

    #[test]
    fn skin_file_errors_name_the_key() {
        let bad = |from: &str, to: &str| error_of(&EXAMPLE.replace(from, to));
        assert_eq!(
            key_of(&bad("thickness_m = 0.0005", "thickness_m = 0")),
            "layer[1].thickness_m"
        );
        assert_eq!(
            key_of(&bad("thickness_m = 0.0005", "thickness_m = -1e-3")),
            "layer[1].thickness_m"
        );
        assert_eq!(
            key_of(&bad("perfusion_per_s = 0.0", "perfusion_per_s = -0.001")),
            "layer[1].perfusion_per_s"
        );
        assert_eq!(
            key_of(&bad("metabolic_w_m3 = 0.0", "metabolic_w_m3 = nan")),
            "layer[1].metabolic_w_m3"
        );
        assert_eq!(
            key_of(&bad("arterial_c = 36.8", "arterial_c = inf")),
            "blood.arterial_c"
        );
        assert_eq!(key_of(&bad("arterial_c = 36.8", "")), "blood.arterial_c");
        assert_eq!(
            key_of(&bad("convection_w_m2k = 10.0", "convection_w_m2k = 0")),
            "air.convection_w_m2k"
        );
        assert_eq!(key_of(&bad("thickness_m = 0.0005", "")), "layer[1].thickness_m");
        // Finite but unphysical: a 1 m skin layer, the kidney's perfusion tenfold, a feverish 45 °C blood.
        assert_eq!(
            key_of(&bad("thickness_m = 0.0005", "thickness_m = 1.0")),
            "layer[1].thickness_m"
        );
        assert_eq!(
            key_of(&bad("perfusion_per_s = 0.0", "perfusion_per_s = 1.0")),
            "layer[1].perfusion_per_s"
        );
        assert_eq!(key_of(&bad("arterial_c = 36.8", "arterial_c = 45")), "blood.arterial_c");
        assert_eq!(
            key_of(&bad("conductivity_w_mk = 0.21", "conductivity_w_mk = 1e300")),
            "layer[1].conductivity_w_mk"
        );
        assert_eq!(key_of(&bad("name = \"epidermis\"", "")), "layer[1].name");
        assert_eq!(
            key_of(&bad("perfusion_per_s = 0.0", "perfusion = 0.0")),
            "layer[1].perfusion"
        );
        assert_eq!(key_of(&bad("[air]", "[air]\nwind = 1")), "air.wind");
        assert_eq!(key_of(&bad("[blood]", "[bleed]")), "bleed");
        assert_eq!(
            key_of(&bad("thickness_m = 0.0005", "thickness_m = \"thin\"")),
            "layer[1].thickness_m"
        );
        assert_eq!(
            key_of(&bad("[air]\nconvection_w_m2k = 10.0", "air = 10.0")),
            "blood.air"
        );
        assert_eq!(key_of(&error_of("air = 10.0")), "air");
        assert_eq!(key_of(&error_of("layer = [1]")), "layer[1]");
        assert_eq!(key_of(&error_of("layer = 1")), "layer");
        match bad("density_kg_m3 = 1100", "density_kg_m3 = 1100\ndensity_g_cm3 = 1.1") {
            ParamError::BothSpellings { si_key, cgs_key, .. } => {
                assert_eq!(
                    (si_key.as_str(), cgs_key.as_str()),
                    ("layer[1].density_kg_m3", "layer[1].density_g_cm3")
                )
            }
            other => panic!("expected BothSpellings, got {other:?}"),
        }
        match bad(
            "specific_heat_j_kgk = 3800",
            "specific_heat_j_kgk = 3800\nspecific_heat_cal_g_c = 0.9",
        ) {
            ParamError::BothSpellings { si_key, .. } => assert_eq!(si_key, "blood.specific_heat_j_kgk"),
            other => panic!("expected BothSpellings, got {other:?}"),
        }
        assert!(matches!(
            error_of("[air]\nconvection_w_m2k = 10.0"),
            ParamError::Invalid { .. }
        ));
        assert!(matches!(error_of("[[layer]\nname = 1"), ParamError::Syntax { .. }));
    }

    #[test]
    fn second_layer_errors_say_which_layer() {
        let two = format!(
            "{}\n[[layer]]\nname = \"dermis\"\nthickness_m = 0.001\n",
            EXAMPLE.split("[blood]").next().unwrap_or("")
        );
        let e = error_of(&two);
        assert_eq!(key_of(&e), "layer[2].conductivity_w_mk");
        assert!(
            e.to_string().contains("layer[2].conductivity_w_mk") && e.to_string().contains("skin.toml"),
            "{e}"
        );
    }
}
