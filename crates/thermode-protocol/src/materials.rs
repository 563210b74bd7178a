//! Materials on the wire: a material a `touch` gives by its properties ([`MaterialProperties`], checked into a
//! `thermode_model::materials::Material` by [`MaterialProperties::to_material`]), and a library entry as
//! `/api/materials` and `thermode materials --format json` list it ([`MaterialInfo`]).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use thermode_model::error::ParamError;
use thermode_model::limits;
use thermode_model::materials::{Material, DEFAULT_THICKNESS_M};
use thermode_model::params::BadValue;

/// Longest accepted name (material or custom label) \[characters\].
pub const MAX_NAME_CHARS: usize = 64;

/// A material given by its SI properties (a `touch` request's `properties`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MaterialProperties {
    /// A label: 1 to 64 of `A–Z a–z 0–9 _ - .`; default `custom`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Thermal conductivity k \[W/(m·K)\].
    pub conductivity_w_mk: f64,
    /// Density ρ \[kg/m³\].
    pub density_kg_m3: f64,
    /// Specific heat capacity c \[J/(kg·K)\].
    pub specific_heat_j_kgk: f64,
    /// Thickness of the touched object \[m\]; default 0.01.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub thickness_m: Option<f64>,
}

/// Why [`MaterialProperties::to_material`] refused the properties.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PropertiesError {
    /// The label is not 1 to 64 of `A–Z a–z 0–9 _ - .`.
    #[error("`name` must be 1 to {MAX_NAME_CHARS} of A-Z a-z 0-9 _ - .")]
    Label,
    /// A number outside its physical range (docs/ranges.md).
    #[error("{0}")]
    Range(#[from] BadValue),
    /// The material as a whole is refused.
    #[error("{0}")]
    Material(#[from] ParamError),
}

impl MaterialProperties {
    /// The material, once every number lies in its physical range (as for material files) and the label is valid.
    pub fn to_material(&self) -> Result<Material, PropertiesError> {
        let name = match &self.name {
            None => "custom".to_string(),
            Some(name) => label(name)?,
        };
        let thickness_m = match self.thickness_m {
            None => DEFAULT_THICKNESS_M,
            Some(t) => limits::OBJECT_THICKNESS.rule().check("thickness_m", t)?,
        };
        let material = Material {
            name,
            conductivity_w_mk: limits::CONDUCTIVITY
                .rule()
                .check("conductivity_w_mk", self.conductivity_w_mk)?,
            density_kg_m3: limits::DENSITY.rule().check("density_kg_m3", self.density_kg_m3)?,
            specific_heat_j_kgk: limits::SPECIFIC_HEAT
                .rule()
                .check("specific_heat_j_kgk", self.specific_heat_j_kgk)?,
            thickness_m,
            source: "contact API properties".to_string(),
        };
        material.validate("properties")?;
        Ok(material)
    }
}

/// A custom material's label: 1 to 64 of `A–Z a–z 0–9 _ - .`.
fn label(name: &str) -> Result<String, PropertiesError> {
    let ok = !name.is_empty()
        && name.chars().count() <= MAX_NAME_CHARS
        && name.chars().all(|c| c.is_ascii_alphanumeric() || "_-.".contains(c));
    ok.then(|| name.to_string()).ok_or(PropertiesError::Label)
}

/// A library material as listed by `/api/materials` and `thermode materials --format json`: its SI properties and
/// the two derived quantities that govern the contact.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct MaterialInfo {
    /// The name (lower case, no spaces).
    pub name: String,
    /// Thermal conductivity k \[W/(m·K)\].
    pub conductivity_w_mk: f64,
    /// Density ρ \[kg/m³\].
    pub density_kg_m3: f64,
    /// Specific heat capacity c \[J/(kg·K)\].
    pub specific_heat_j_kgk: f64,
    /// Thermal effusivity e = √(kρc) \[W·s^½/(m²·K)\].
    pub effusivity: f64,
    /// Thermal diffusivity a = k/(ρc) \[m²/s\].
    pub diffusivity_m2_s: f64,
    /// Thickness of the object \[m\].
    pub thickness_m: f64,
    /// Where the numbers come from.
    pub source: String,
}

impl From<&Material> for MaterialInfo {
    fn from(m: &Material) -> Self {
        MaterialInfo {
            name: m.name.clone(),
            conductivity_w_mk: m.conductivity_w_mk,
            density_kg_m3: m.density_kg_m3,
            specific_heat_j_kgk: m.specific_heat_j_kgk,
            effusivity: m.effusivity(),
            diffusivity_m2_s: m.diffusivity_m2_s(),
            thickness_m: m.thickness_m,
            source: m.source.clone(),
        }
    }
}

/// The whole library as [`MaterialInfo`]s, in the library's order.
pub fn library_info() -> Vec<MaterialInfo> {
    thermode_model::materials::library()
        .iter()
        .map(MaterialInfo::from)
        .collect()
}
