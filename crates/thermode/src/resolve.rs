//! The one place the CLI turns names and file paths into the things every command needs: materials (library names,
//! `all-paper`, material files), skins, device files and PID gains files. Errors name the option and the file.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use thermode_control::PidGains;
use thermode_device::DeviceConfig;
use thermode_model::materials::{self, Material};
use thermode_model::Skin;
use thermode_pipeline::controllers::gains_from_toml_str;
use thermode_platform::fs::{read_text_at_most, MAX_SETTINGS_BYTES};

/// The name that stands for the paper's five materials (Table 1) in every `--material` option.
pub const ALL_PAPER: &str = "all-paper";

/// Reads a settings file (at most [`MAX_SETTINGS_BYTES`]); the error names it.
pub fn read(path: &Path) -> Result<String> {
    read_text_at_most(path, MAX_SETTINGS_BYTES).with_context(|| format!("cannot read {}", path.display()))
}

/// The library materials named on the command line (`all-paper` expanded), followed by the material files.
pub fn materials(names: &[String], files: &[PathBuf]) -> Result<Vec<Material>> {
    let mut out = Vec::new();
    for name in names {
        if name == ALL_PAPER {
            out.extend(materials::paper_materials());
        } else {
            out.push(materials::find(name)?);
        }
    }
    for path in files {
        out.push(Material::from_toml_str(&read(path)?, &path.display().to_string())?);
    }
    if out.is_empty() {
        bail!("no material given: use --material NAME or --material-file FILE");
    }
    Ok(out)
}

/// The skin file at `path`, or the default fingertip.
pub fn skin(path: Option<&Path>) -> Result<Skin> {
    match path {
        Some(path) => Ok(Skin::from_toml_str(&read(path)?, &path.display().to_string())?),
        None => Ok(Skin::fingertip()),
    }
}

/// The device file at `path` (`--device-file`), or the built-in default display.
pub fn device_config(path: Option<&Path>) -> Result<DeviceConfig> {
    match path {
        Some(path) => Ok(DeviceConfig::from_toml_str(&read(path)?, &path.display().to_string())?),
        None => Ok(DeviceConfig::default()),
    }
}

/// Where a device file came from, for messages: its path, or the built-in default display.
pub fn device_origin(path: Option<&Path>) -> String {
    path.map_or_else(
        || "the built-in default display".to_string(),
        |p| p.display().to_string(),
    )
}

/// The PID gains file at `path`.
pub fn gains(path: &Path) -> Result<PidGains> {
    Ok(gains_from_toml_str(&read(path)?, &path.display().to_string())?)
}
