//! Identified device files kept in the state directory (issue 26 item 4, "identified on first use"):
//! `thermode identify --save` writes the identified device file of a real device to
//! `STATE_DIR/devices/<kind>-<identity>.toml` ([`file_name`]), and `serve`, `lab run --device` and `bench` find it
//! there for that device when no `--device-file` is given ([`find`]). The identity is what the device reports that
//! tells it apart from others of its kind ([`thermode_device::DevicePart::identity`]: a MeCom controller's serial
//! number, else its `?IF` text); a device that reports none (a TCS II, thermode's own protocol) is known by its port
//! path. The state directory is the dose ledger's (`--state-dir`, default `$XDG_STATE_HOME/thermode`, else
//! `~/.local/state/thermode`).

use std::path::{Path, PathBuf};

use anyhow::Result;
use thermode_device::{DeviceConfig, DevicePart};
use thermode_protocol::status::DeviceFileKind;

use crate::resolve;

/// The folder of the state directory that holds the identified device files.
pub const DEVICES_DIR: &str = "devices";

/// The header line of a saved file that says when it was identified (UTC, ISO 8601).
const IDENTIFIED_AT: &str = "# identified-at: ";

/// The first words of the header `thermode identify` writes into every device file it makes.
const IDENTIFY_HEADER: &str = "# Identified by `thermode identify`";

/// Longest file name stem \[characters\]: 100.
const MAX_STEM_CHARS: usize = 100;

/// A stored identified device file found for a device.
#[derive(Debug, Clone)]
pub struct Stored {
    /// Its path.
    pub path: PathBuf,
    /// The device file.
    pub config: DeviceConfig,
    /// When it was identified (`YYYY-MM-DDTHH:MM:SSZ`), from its header; `None` when the header lacks it.
    pub identified_at: Option<String>,
}

impl Stored {
    /// What the stored file is: `calibrated` with a `[calibration]` section, else `identified` (`identify` wrote it).
    pub fn kind(&self) -> DeviceFileKind {
        match self.config.calibration.is_set() {
            true => DeviceFileKind::Calibrated,
            false => DeviceFileKind::Identified,
        }
    }
}

/// The device of `part` on a display labelled `display_label`: the part's own label, or the display's for a display
/// of one unnamed device.
pub fn device_of(part: &DevicePart, display_label: &str) -> String {
    if part.label.is_empty() {
        display_label.to_string()
    } else {
        part.label.clone()
    }
}

/// The file name (`<kind>-<identity>.toml`) of the identified file of `device` (a `--device` spelling, e.g.
/// `mecom:/dev/ttyUSB0@2?mode=current`) reporting `identity`: the kind is the spelling's prefix (`mecom-tcp`
/// counts as `mecom`: one controller, whichever way it is reached); without an identity, the port path (options
/// dropped) stands for it. Every character but ASCII letters, digits, `.`, `_` and `-` becomes `-`.
pub fn file_name(device: &str, identity: Option<&str>) -> String {
    let (kind, rest) = device.split_once(':').unwrap_or(("device", device));
    let kind = if kind == "mecom-tcp" { "mecom" } else { kind };
    let port = rest.split('?').next().unwrap_or(rest);
    let who = identity.map(str::trim).filter(|i| !i.is_empty()).unwrap_or(port);
    format!("{}.toml", sanitise(&format!("{kind}-{who}")))
}

/// `text` as a file name stem: runs of other characters than ASCII letters, digits, `.`, `_`, `-` become one `-`,
/// leading and trailing `-` and `.` dropped, at most [`MAX_STEM_CHARS`] characters; `device` when nothing is left.
fn sanitise(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        let keep = c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-');
        if keep {
            out.push(c);
        } else if !out.ends_with('-') {
            out.push('-');
        }
    }
    let trimmed: String = out
        .trim_matches(|c| c == '-' || c == '.')
        .chars()
        .take(MAX_STEM_CHARS)
        .collect();
    if trimmed.is_empty() {
        "device".to_string()
    } else {
        trimmed
    }
}

/// Where the identified file of `device` reporting `identity` is kept in `state_dir`.
pub fn path_in(state_dir: &Path, device: &str, identity: Option<&str>) -> PathBuf {
    state_dir.join(DEVICES_DIR).join(file_name(device, identity))
}

/// The text `identify --save` stores: a header naming the device, its identity and the time, then `text` (the
/// identified device file as `identify` writes it).
pub fn stored_text(device: &str, identity: Option<&str>, identified_at: &str, text: &str) -> String {
    let who = identity.map_or_else(
        || "no identity: known by its port".to_string(),
        |i| format!("identity {i}"),
    );
    format!("# Saved by `thermode identify --save` for {device} ({who}).\n{IDENTIFIED_AT}{identified_at}\n{text}")
}

/// The stored identified file of `device` reporting `identity` in `state_dir`, if there is one; a file that is there
/// but cannot be read or is not a valid device file is an error (it names the file).
pub fn find(state_dir: &Path, device: &str, identity: Option<&str>) -> Result<Option<Stored>> {
    let path = path_in(state_dir, device, identity);
    if !path.is_file() {
        return Ok(None);
    }
    let text = resolve::read(&path)?;
    let config = resolve::device_config(Some(&path))?;
    let identified_at = text
        .lines()
        .find_map(|line| line.strip_prefix(IDENTIFIED_AT))
        .map(|s| s.trim().to_string());
    Ok(Some(Stored {
        path,
        config,
        identified_at,
    }))
}

/// What the device file `config` read from `text` is: `calibrated` with a `[calibration]` section, `identified`
/// when `thermode identify` wrote it (its header), `datasheet` otherwise (also the built-in default, `text` None).
pub fn kind_of(config: &DeviceConfig, text: Option<&str>) -> DeviceFileKind {
    if config.calibration.is_set() {
        DeviceFileKind::Calibrated
    } else if text.is_some_and(|t| t.lines().take(8).any(|l| l.starts_with(IDENTIFY_HEADER))) {
        DeviceFileKind::Identified
    } else {
        DeviceFileKind::Datasheet
    }
}

/// The kind's name as `/api/status` spells it.
pub fn kind_name(kind: DeviceFileKind) -> &'static str {
    match kind {
        DeviceFileKind::Datasheet => "datasheet",
        DeviceFileKind::Identified => "identified",
        DeviceFileKind::Calibrated => "calibrated",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn file_names_are_the_kind_and_the_identity_or_the_port_made_safe() {
        assert_eq!(file_name("mecom:/dev/ttyUSB0", Some("SN4242")), "mecom-SN4242.toml");
        assert_eq!(
            file_name("mecom-tcp:10.0.0.5:50000", Some("SN4242")),
            "mecom-SN4242.toml"
        );
        assert_eq!(
            file_name("mecom:/dev/ttyUSB0@2?mode=current", None),
            "mecom-dev-ttyUSB0-2.toml"
        );
        assert_eq!(
            file_name("mecom:/dev/ttyUSB0", Some("thermode-TEC EMU G01")),
            "mecom-thermode-TEC-EMU-G01.toml"
        );
        assert_eq!(file_name("tcs2:/dev/ttyACM0", None), "tcs2-dev-ttyACM0.toml");
        assert_eq!(
            file_name("mecom:../../etc/passwd", Some("  ")),
            "mecom-..-..-etc-passwd.toml"
        );
        assert_eq!(file_name("serial:", Some("/../")), "serial.toml");
        assert!(file_name("mecom:x", Some(&"9".repeat(500))).len() <= MAX_STEM_CHARS + 5);
    }

    #[test]
    fn a_file_is_identified_by_its_header_and_calibrated_by_its_section() {
        let mut config = DeviceConfig::default();
        assert_eq!(kind_of(&config, None), DeviceFileKind::Datasheet);
        assert_eq!(kind_of(&config, Some("[peltier]\n")), DeviceFileKind::Datasheet);
        let identified = format!("{IDENTIFY_HEADER} on mecom:/dev/x from …\n[peltier]\n");
        assert_eq!(kind_of(&config, Some(&identified)), DeviceFileKind::Identified);
        config.calibration.sensor_offset_c = 0.3;
        assert_eq!(kind_of(&config, Some(&identified)), DeviceFileKind::Calibrated);
    }
}
