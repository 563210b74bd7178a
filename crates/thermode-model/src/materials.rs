//! The material library and material files.
//!
//! A [`Material`] is a homogeneous solid with conductivity, density, specific heat and a default thickness (the
//! thickness the models use for the touched object). The built-in library holds the paper's Table 1 exactly (cgs
//! values converted once to SI) and common materials a VR scene needs, each with the source of its numbers.
//! User material files are TOML; see [`Material::from_toml_str`].
//!
//! Default thickness: the paper says that all its stimuli were of equal size but not which size; thermode uses
//! 1 cm ([`DEFAULT_THICKNESS_M`]), a typical psychophysics sample, for the paper's materials and for most others.
//! Thin goods (leather, felt, cork sheet) get a thinner default, stated per entry.

use serde::Serialize;

use crate::error::{At, ParamError};
use crate::limits;
use crate::params::{self, Table, CONDUCTIVITY, DENSITY, SPECIFIC_HEAT};
use crate::units;

/// Default thickness of a touched object \[m\] (1 cm) when a material file gives none.
pub const DEFAULT_THICKNESS_M: f64 = 0.01;

/// Source string of the paper's five materials.
pub const PAPER_SOURCE: &str = "Table 1 of the founding paper (Development and Experimental Evaluation of a Thermal Display, after its ref. [23]), cgs values converted to SI";

const INCROPERA_A1: &str = "Incropera et al., Fundamentals of Heat and Mass Transfer, 7th ed., Table A.1 (300 K)";
const POLYMER_TYPICAL: &str = "typical values of unfilled grades from supplier data sheets, as collected in the \
     Engineering ToolBox tables 'Thermal Conductivity of Common Materials' and 'Specific Heat of Solids'";

/// A homogeneous solid that a finger can touch.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Material {
    /// Name as used on the command line and in files (lower case, no spaces).
    pub name: String,
    /// Thermal conductivity k [W/(m·K)].
    pub conductivity_w_mk: f64,
    /// Density ρ [kg/m³].
    pub density_kg_m3: f64,
    /// Specific heat capacity c [J/(kg·K)].
    pub specific_heat_j_kgk: f64,
    /// Thickness of the touched object \[m\]; the library's default is given per material.
    pub thickness_m: f64,
    /// Where the numbers come from.
    pub source: String,
}

impl Material {
    /// Thermal effusivity e = √(kρc) [W·s^½/(m²·K)].
    pub fn effusivity(&self) -> f64 {
        crate::units::effusivity(self.conductivity_w_mk, self.density_kg_m3, self.specific_heat_j_kgk)
    }

    /// Thermal diffusivity a = k/(ρc) [m²/s].
    pub fn diffusivity_m2_s(&self) -> f64 {
        crate::units::diffusivity_m2_s(self.conductivity_w_mk, self.density_kg_m3, self.specific_heat_j_kgk)
    }

    /// Checks every field: a non-empty name without white space, and conductivity, density, specific heat and
    /// thickness inside their physical ranges ([`limits::CONDUCTIVITY`], [`limits::DENSITY`],
    /// [`limits::SPECIFIC_HEAT`], [`limits::OBJECT_THICKNESS`]; NaN and ±∞ are refused). `origin` names where the
    /// values came from (a file, a network message) and appears in the error.
    pub fn validate(&self, origin: &str) -> Result<(), ParamError> {
        validate_name(origin, "name", &self.name)?;
        for (key, value, range) in [
            ("conductivity_w_mk", self.conductivity_w_mk, limits::CONDUCTIVITY),
            ("density_kg_m3", self.density_kg_m3, limits::DENSITY),
            ("specific_heat_j_kgk", self.specific_heat_j_kgk, limits::SPECIFIC_HEAT),
            ("thickness_m", self.thickness_m, limits::OBJECT_THICKNESS),
        ] {
            range.rule().check(key, value).at(origin)?;
        }
        Ok(())
    }

    /// Reads a material file (TOML). `origin` (usually the file name) appears in every error.
    ///
    /// Keys: `name` (string); conductivity as `conductivity_w_mk` [W/(m·K)] or `conductivity_cal_cm_s_c`
    /// [cal/(cm·s·°C)]; density as `density_kg_m3` or `density_g_cm3`; specific heat as `specific_heat_j_kgk` or
    /// `specific_heat_cal_g_c` [cal/(g·°C)]; optional `thickness_m` (default [`DEFAULT_THICKNESS_M`]); optional
    /// `source` (default: "user file " followed by `origin`). Exactly one spelling per quantity. Missing values,
    /// values outside their physical range (see [`Material::validate`]; a cgs value is checked in its own unit),
    /// non-finite values, both spellings, unknown keys and wrong types are errors naming the key.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Material, ParamError> {
        let toml = params::parse(text, origin)?;
        let file = Table::new(&toml, origin);
        let material = Material {
            name: file.required_string("name")?,
            conductivity_w_mk: file.required_either(CONDUCTIVITY, limits::CONDUCTIVITY.rule())?,
            density_kg_m3: file.required_either(DENSITY, limits::DENSITY.rule())?,
            specific_heat_j_kgk: file.required_either(SPECIFIC_HEAT, limits::SPECIFIC_HEAT.rule())?,
            thickness_m: file
                .number("thickness_m", limits::OBJECT_THICKNESS.rule())?
                .unwrap_or(DEFAULT_THICKNESS_M),
            source: file.string("source")?.unwrap_or_else(|| format!("user file {origin}")),
        };
        file.finish()?;
        material.validate(origin)?;
        Ok(material)
    }
}

fn validate_name(origin: &str, key: &str, name: &str) -> Result<(), ParamError> {
    if name.is_empty() || name.chars().any(|c| c.is_whitespace() || c.is_control()) {
        return Err(ParamError::Invalid {
            origin: origin.to_string(),
            message: format!("`{key}` = {name:?} must be a non-empty name without spaces"),
        });
    }
    Ok(())
}

/// The paper's five materials (Table 1), in the paper's order: aluminium, steel, stone, wood, rubber.
///
/// The paper's cgs values (k [cal/(cm·s·°C)], c [cal/(g·°C)], ρ [g/cm³]) are converted to SI with [`crate::units`];
/// the thickness is [`DEFAULT_THICKNESS_M`].
pub fn paper_materials() -> Vec<Material> {
    const TABLE_1: [(&str, f64, f64, f64); 5] = [
        ("aluminium", 0.526, 0.215, 2.70),
        ("steel", 0.110, 0.120, 7.85),
        ("stone", 0.0066, 0.194, 2.70),
        ("wood", 0.00033, 0.598, 0.60),
        ("rubber", 0.00032, 0.387, 0.99),
    ];
    TABLE_1
        .iter()
        .map(|&(name, k_cgs, c_cgs, rho_cgs)| Material {
            name: name.to_string(),
            conductivity_w_mk: units::conductivity_to_si(k_cgs),
            density_kg_m3: units::density_to_si(rho_cgs),
            specific_heat_j_kgk: units::specific_heat_to_si(c_cgs),
            thickness_m: DEFAULT_THICKNESS_M,
            source: PAPER_SOURCE.to_string(),
        })
        .collect()
}

/// One SI entry of the extended library: name, k [W/(m·K)], ρ [kg/m³], c [J/(kg·K)], thickness \[m\], source.
type Entry = (&'static str, f64, f64, f64, f64, &'static str);

/// Common materials a VR scene needs, SI, at room temperature.
const EXTENDED: [Entry; 20] = [
    ("copper", 401.0, 8933.0, 385.0, 0.01, INCROPERA_A1),
    (
        "brass",
        110.0,
        8530.0,
        380.0,
        0.01,
        "Incropera et al., 7th ed., Table A.1, cartridge brass (70% Cu, 30% Zn)",
    ),
    (
        "stainless_steel",
        14.9,
        7900.0,
        477.0,
        0.01,
        "Incropera et al., 7th ed., Table A.1, AISI 304",
    ),
    (
        "glass",
        1.4,
        2500.0,
        750.0,
        0.01,
        "Incropera et al., 7th ed., Table A.3, glass, plate (soda lime)",
    ),
    (
        "granite",
        2.79,
        2630.0,
        775.0,
        0.01,
        "Incropera et al., 7th ed., Table A.3, rock: granite, Barre",
    ),
    (
        "marble",
        2.80,
        2680.0,
        830.0,
        0.01,
        "Incropera et al., 7th ed., Table A.3, rock: marble, Halston",
    ),
    (
        "concrete",
        1.4,
        2300.0,
        880.0,
        0.01,
        "Incropera et al., 7th ed., Table A.3, concrete, stone mix",
    ),
    (
        "ice",
        1.88,
        920.0,
        2040.0,
        0.01,
        "Incropera et al., 7th ed., Table A.3, ice at 273 K",
    ),
    ("pmma", 0.19, 1190.0, 1470.0, 0.01, POLYMER_TYPICAL),
    ("polystyrene", 0.14, 1050.0, 1300.0, 0.01, POLYMER_TYPICAL),
    ("pvc", 0.19, 1400.0, 1000.0, 0.01, POLYMER_TYPICAL),
    ("nylon", 0.25, 1140.0, 1700.0, 0.01, POLYMER_TYPICAL),
    ("abs", 0.17, 1050.0, 1400.0, 0.01, POLYMER_TYPICAL),
    ("silicone_rubber", 0.20, 1150.0, 1300.0, 0.01, POLYMER_TYPICAL),
    (
        "cork",
        0.039,
        120.0,
        1800.0,
        0.005,
        "Incropera et al., 7th ed., Table A.3, insulation board: cork; 5 mm sheet",
    ),
    (
        "leather",
        0.159,
        998.0,
        1500.0,
        0.003,
        "k, ρ: Incropera et al., 7th ed., Table A.3, leather (sole); c: typical dry leather (Engineering ToolBox); \
         3 mm",
    ),
    (
        "oak",
        0.16,
        720.0,
        1255.0,
        0.01,
        "Incropera et al., 7th ed., Table A.3, structural woods: hardwoods (oak, maple)",
    ),
    (
        "pine",
        0.12,
        510.0,
        1380.0,
        0.01,
        "Incropera et al., 7th ed., Table A.3, structural woods: softwoods (fir, pine)",
    ),
    (
        "wool_felt",
        0.05,
        200.0,
        1360.0,
        0.005,
        "typical pressed wool felt: k 0.04-0.06 W/m·K, ρ 150-300 kg/m³ (Engineering ToolBox, felt insulation); \
         c of wool 1360 J/kg·K; 5 mm",
    ),
    (
        "ceramic",
        1.5,
        2400.0,
        1085.0,
        0.01,
        "typical porcelain (Engineering ToolBox, 'Specific Heat of Solids')",
    ),
];

/// The whole built-in library: the paper's Table 1 (see [`paper_materials`]) first, then common materials with the
/// source of each number. Names are lower case with underscores.
pub fn library() -> Vec<Material> {
    let extended = EXTENDED.iter().map(|&(name, k, rho, c, thickness, source)| Material {
        name: name.to_string(),
        conductivity_w_mk: k,
        density_kg_m3: rho,
        specific_heat_j_kgk: c,
        thickness_m: thickness,
        source: source.to_string(),
    });
    paper_materials().into_iter().chain(extended).collect()
}

/// Alternative spellings accepted by [`find`].
const ALIASES: [(&str, &str); 3] = [
    ("aluminum", "aluminium"),
    ("porcelain", "ceramic"),
    ("plexiglass", "pmma"),
];

/// Looks a material up by name: case-insensitive, `-` or a space accepted for `_`, and a few aliases
/// (`aluminum`, `porcelain`, `plexiglass`). An unknown name gives [`ParamError::UnknownMaterial`] with up to three
/// close names (by edit distance or common prefix).
pub fn find(name: &str) -> Result<Material, ParamError> {
    let key = normalise(name);
    let key = ALIASES
        .iter()
        .find(|(alias, _)| *alias == key)
        .map_or(key.clone(), |(_, real)| real.to_string());
    let all = library();
    if let Some(found) = all.iter().find(|m| m.name == key) {
        return Ok(found.clone());
    }
    Err(ParamError::UnknownMaterial {
        name: name.to_string(),
        close: close_names(&key, &all),
    })
}

fn normalise(name: &str) -> String {
    name.trim()
        .to_lowercase()
        .chars()
        .map(|c| if c == '-' || c == ' ' { '_' } else { c })
        .collect()
}

fn close_names(key: &str, all: &[Material]) -> Vec<String> {
    let limit = (key.chars().count() / 3).max(2);
    let mut scored: Vec<(usize, &str)> = all
        .iter()
        .map(|m| (edit_distance(key, &m.name), m.name.as_str()))
        .filter(|(d, name)| *d <= limit || (key.len() >= 2 && (name.starts_with(key) || key.starts_with(*name))))
        .collect();
    scored.sort();
    scored.into_iter().take(3).map(|(_, name)| name.to_string()).collect()
}

/// Levenshtein distance between two strings (by characters).
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut diagonal = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let substitute = diagonal + usize::from(ca != *cb);
            diagonal = row[j + 1];
            row[j + 1] = substitute.min(row[j] + 1).min(row[j + 1] + 1);
        }
    }
    row[b.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn material_file(extra: &str) -> String {
        format!("name = \"walnut\"\nconductivity_w_mk = 0.15\ndensity_kg_m3 = 650\nspecific_heat_j_kgk = 1600\n{extra}")
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-12 * b.abs()
    }

    #[test]
    fn table_1_is_exact_after_independent_conversion() {
        // Independently: 1 cal = 4.1868 J, so k×418.68, c×4186.8, ρ×1000.
        let want = [
            ("aluminium", 0.526 * 418.68, 0.215 * 4186.8, 2700.0),
            ("steel", 0.110 * 418.68, 0.120 * 4186.8, 7850.0),
            ("stone", 0.0066 * 418.68, 0.194 * 4186.8, 2700.0),
            ("wood", 0.00033 * 418.68, 0.598 * 4186.8, 600.0),
            ("rubber", 0.00032 * 418.68, 0.387 * 4186.8, 990.0),
        ];
        let got = paper_materials();
        assert_eq!(got.len(), 5);
        for (m, (name, k, c, rho)) in got.iter().zip(want) {
            assert_eq!(m.name, name);
            assert!(
                close(m.conductivity_w_mk, k),
                "{name}: k {} vs {k}",
                m.conductivity_w_mk
            );
            assert!(
                close(m.specific_heat_j_kgk, c),
                "{name}: c {} vs {c}",
                m.specific_heat_j_kgk
            );
            assert!(close(m.density_kg_m3, rho), "{name}: rho {} vs {rho}", m.density_kg_m3);
            assert_eq!(m.thickness_m, 0.01);
            assert!(m.source.contains("Table 1"), "{name}: source {}", m.source);
        }
        // Aluminium ≈ 220 W/m·K and 900 J/kg·K, the handbook values for aluminium alloys.
        assert!((got[0].conductivity_w_mk - 220.2).abs() < 0.1);
    }

    #[test]
    fn library_is_complete_valid_and_unique() {
        let all = library();
        assert!(all.len() >= 25, "only {} materials", all.len());
        let required = [
            "copper",
            "brass",
            "stainless_steel",
            "glass",
            "granite",
            "marble",
            "concrete",
            "ice",
            "pmma",
            "polystyrene",
            "pvc",
            "nylon",
            "abs",
            "silicone_rubber",
            "cork",
            "leather",
            "oak",
            "pine",
            "wool_felt",
            "ceramic",
        ];
        for name in required {
            assert!(all.iter().any(|m| m.name == name), "{name} missing from the library");
        }
        for (i, m) in all.iter().enumerate() {
            m.validate("built-in").unwrap_or_else(|e| panic!("{}: {e}", m.name));
            assert!(m.source.len() > 10, "{}: no real source", m.name);
            assert_eq!(m.name, m.name.to_lowercase());
            assert!(all[i + 1..].iter().all(|o| o.name != m.name), "duplicate {}", m.name);
        }
    }

    #[test]
    fn effusivities_are_ordered_as_physics_expects() {
        // Metals ≫ stone/glass ≫ polymers/wood ≫ cork/felt.
        let e = |n: &str| find(n).map(|m| m.effusivity()).unwrap_or(f64::NAN);
        assert!(e("copper") > e("aluminium") && e("aluminium") > e("steel"));
        assert!(e("steel") > e("granite") && e("granite") > e("pmma"));
        assert!(e("pmma") > e("cork") && e("oak") > e("cork"));
        // Copper: √(401·8933·385) = 37 140 W·s^½/m²K.
        assert!((e("copper") - (401.0f64 * 8933.0 * 385.0).sqrt()).abs() < 1e-9);
    }

    #[test]
    fn find_is_forgiving_about_case_and_separators() {
        for spelling in ["Stainless-Steel", "stainless steel", " STAINLESS_STEEL "] {
            let m = find(spelling).map(|m| m.name);
            assert_eq!(m, Ok("stainless_steel".to_string()), "{spelling}");
        }
        assert_eq!(find("Aluminum").map(|m| m.name), Ok("aluminium".to_string()));
    }

    #[test]
    fn unknown_material_lists_close_names() {
        match find("coper") {
            Err(ParamError::UnknownMaterial { name, close }) => {
                assert_eq!(name, "coper");
                assert_eq!(close.first().map(String::as_str), Some("copper"), "close: {close:?}");
                assert!(close.len() <= 3);
            }
            other => panic!("expected UnknownMaterial, got {other:?}"),
        }
        match find("stain") {
            Err(ParamError::UnknownMaterial { close, .. }) => assert!(close.contains(&"stainless_steel".to_string())),
            other => panic!("expected UnknownMaterial, got {other:?}"),
        }
        match find("xyzzyqwerty") {
            Err(ParamError::UnknownMaterial { close, .. }) => assert!(close.is_empty(), "close: {close:?}"),
            other => panic!("expected UnknownMaterial, got {other:?}"),
        }
        let message = find("coper").map(|m| m.name).unwrap_err().to_string();
        assert!(message.contains("did you mean copper"), "{message}");
    }

    #[test]
    fn edit_distance_known_values() {
        assert_eq!(edit_distance("kitten", "sitting"), 3);
        assert_eq!(edit_distance("", "abc"), 3);
        assert_eq!(edit_distance("steel", "steel"), 0);
    }

    #[test]
    fn material_file_si_and_cgs_spellings() {
        let m = Material::from_toml_str(&material_file("thickness_m = 0.02\nsource = \"lab\""), "walnut.toml");
        let m = m.unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            (m.conductivity_w_mk, m.density_kg_m3, m.specific_heat_j_kgk),
            (0.15, 650.0, 1600.0)
        );
        assert_eq!((m.thickness_m, m.source.as_str()), (0.02, "lab"));
        let cgs = "name = \"al\"\nconductivity_cal_cm_s_c = 0.526\ndensity_g_cm3 = 2.7\nspecific_heat_cal_g_c = 0.215";
        let m = Material::from_toml_str(cgs, "al.toml").unwrap_or_else(|e| panic!("{e}"));
        assert!(close(m.conductivity_w_mk, 0.526 * 418.68), "k {}", m.conductivity_w_mk);
        assert!(close(m.density_kg_m3, 2700.0) && close(m.specific_heat_j_kgk, 0.215 * 4186.8));
        assert_eq!(m.thickness_m, DEFAULT_THICKNESS_M);
        assert!(m.source.contains("al.toml"), "{}", m.source);
    }

    fn error_of(text: &str) -> ParamError {
        match Material::from_toml_str(text, "bad.toml") {
            Ok(m) => panic!("accepted {m:?}"),
            Err(e) => e,
        }
    }

    fn assert_bad_value(e: ParamError, want_key: &str) {
        match &e {
            ParamError::BadValue { origin, source } => {
                assert_eq!((origin.as_str(), source.name.as_ref()), ("bad.toml", want_key))
            }
            other => panic!("expected BadValue for {want_key}, got {other:?}"),
        }
        assert!(
            e.to_string().contains(want_key) && e.to_string().contains("bad.toml"),
            "{e}"
        );
    }

    #[test]
    fn material_file_errors_name_key_and_file() {
        let missing = "name = \"x\"\nconductivity_w_mk = 1\ndensity_kg_m3 = 1";
        assert_eq!(
            error_of(missing),
            ParamError::MissingKey {
                origin: "bad.toml".into(),
                key: "specific_heat_j_kgk".into()
            }
        );
        let no_name = "conductivity_w_mk = 1\ndensity_kg_m3 = 1\nspecific_heat_j_kgk = 1";
        assert_eq!(
            error_of(no_name),
            ParamError::MissingKey {
                origin: "bad.toml".into(),
                key: "name".into()
            }
        );
        assert_bad_value(
            error_of(&material_file("").replace("= 0.15", "= -0.15")),
            "conductivity_w_mk",
        );
        assert_bad_value(error_of(&material_file("").replace("= 650", "= 0")), "density_kg_m3");
        assert_bad_value(
            error_of(&material_file("").replace("= 1600", "= nan")),
            "specific_heat_j_kgk",
        );
        assert_bad_value(
            error_of(&material_file("").replace("= 1600", "= inf")),
            "specific_heat_j_kgk",
        );
        assert_bad_value(error_of(&material_file("thickness_m = -0.01")), "thickness_m");
        // Finite but unphysical: beyond diamond, lighter than any aerogel, a 10 m slab.
        assert_bad_value(
            error_of(&material_file("").replace("= 0.15", "= 1e300")),
            "conductivity_w_mk",
        );
        assert_bad_value(error_of(&material_file("").replace("= 650", "= 0.1")), "density_kg_m3");
        assert_bad_value(error_of(&material_file("thickness_m = 10")), "thickness_m");
        assert_bad_value(error_of(&material_file("density_g_cm3 = -1")), "density_g_cm3");
        assert_eq!(
            error_of(&material_file("conductivity_cal_cm_s_c = 0.1")),
            ParamError::BothSpellings {
                origin: "bad.toml".into(),
                si_key: "conductivity_w_mk".into(),
                cgs_key: "conductivity_cal_cm_s_c".into()
            }
        );
        assert_eq!(
            error_of(&material_file("colour = \"brown\"")),
            ParamError::UnknownKey {
                origin: "bad.toml".into(),
                key: "colour".into()
            }
        );
        match error_of(&material_file("thickness_m = \"1 cm\"")) {
            ParamError::WrongType { key, origin, .. } => {
                assert_eq!((key.as_str(), origin.as_str()), ("thickness_m", "bad.toml"))
            }
            other => panic!("expected WrongType, got {other:?}"),
        }
        match error_of("name = 3\nconductivity_w_mk = 1\ndensity_kg_m3 = 1\nspecific_heat_j_kgk = 1") {
            ParamError::WrongType { key, .. } => assert_eq!(key, "name"),
            other => panic!("expected WrongType, got {other:?}"),
        }
        match error_of(&material_file("").replace("walnut", "black walnut")) {
            ParamError::Invalid { message, .. } => assert!(message.contains("`name`"), "{message}"),
            other => panic!("expected Invalid, got {other:?}"),
        }
        match error_of("name = \"x\"\nconductivity_w_mk = ") {
            ParamError::Syntax { origin, .. } => assert_eq!(origin, "bad.toml"),
            other => panic!("expected Syntax, got {other:?}"),
        }
    }

    #[test]
    fn validate_catches_values_from_elsewhere() {
        let mut m = paper_materials().remove(0);
        assert_eq!(m.validate("net"), Ok(()));
        m.thickness_m = f64::NAN;
        match m.validate("net") {
            Err(ParamError::BadValue { origin, source }) => {
                assert_eq!((origin.as_str(), source.name.as_ref()), ("net", "thickness_m"))
            }
            other => panic!("expected BadValue, got {other:?}"),
        }
        m.thickness_m = 0.01;
        m.name = String::new();
        assert!(matches!(m.validate("net"), Err(ParamError::Invalid { .. })));
    }
}
