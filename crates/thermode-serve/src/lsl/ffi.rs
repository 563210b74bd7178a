//! The one FFI module of thermode: liblsl (Lab Streaming Layer) loaded at run time with `libloading`, wrapped in
//! safe types ([`Liblsl`], [`Outlet`]). Only `serve --lsl` loads it; nothing links against it, so a build never
//! needs it.
//!
//! Where the library is looked for, in order ([`Liblsl::locate`]):
//! 1. `THERMODE_LIBLSL`: a path to the library file (when set, only this one is tried);
//! 2. `PYLSL_LIB`: pylsl's own override, likewise;
//! 3. the system's library search path (`LD_LIBRARY_PATH`, the loader cache): `liblsl.so.2`, `liblsl.so`
//!    (`liblsl.dylib` on macOS, `lsl.dll` on Windows);
//! 4. the copy inside an installed `pylsl` wheel (pylsl 1.16+ ships `pylsl/lib/liblsl.so`), found by asking
//!    `python3` (or `$THERMODE_PYTHON`) where the `pylsl` package lives, without importing it; a probe that has not
//!    answered within [`PYTHON_PROBE_TIMEOUT_S`] is killed and counts as no package.
//!
//! A candidate that is not a regular file (a FIFO, a device) is refused without being opened.
//!
//! The C API used (liblsl 1.14+, `lsl_c.h`): stream info and its XML description, outlets, pushing one sample with
//! an explicit timestamp, and the LSL clock.
#![allow(unsafe_code)]

use std::ffi::{c_char, c_double, c_int, c_void, CString};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use libloading::Library;
use thiserror::Error;

/// `lsl_channel_format_t`: 64-bit floating point.
const CFT_DOUBLE64: c_int = 2;
/// `lsl_channel_format_t`: variable-length string.
const CFT_STRING: c_int = 3;

/// Why liblsl could not be used.
#[derive(Debug, Error)]
pub enum LslError {
    /// No candidate could be loaded.
    #[error(
        "liblsl (Lab Streaming Layer) not found; tried: {}. Install it (`python3 -m pip install pylsl` ships it) or \
         set THERMODE_LIBLSL to the library file",
        tried.join("; ")
    )]
    NotFound {
        /// Every candidate tried, with why it failed.
        tried: Vec<String>,
    },
    /// The library lacks a function thermode needs (too old a liblsl, or not liblsl).
    #[error("{path}: not a usable liblsl (missing {symbol}: {reason})")]
    MissingSymbol {
        /// The library loaded.
        path: String,
        /// The function.
        symbol: &'static str,
        /// The loader's message.
        reason: String,
    },
    /// liblsl refused to create a stream or an outlet.
    #[error("liblsl could not create the {what}")]
    Create {
        /// What: `stream info of …`, `outlet of …`.
        what: String,
    },
    /// A name or value holds a NUL byte.
    #[error("{0:?}: a text for liblsl must not contain a NUL byte")]
    Nul(String),
}

type CreateStreaminfo =
    unsafe extern "C" fn(*const c_char, *const c_char, c_int, c_double, c_int, *const c_char) -> *mut c_void;
type DestroyStreaminfo = unsafe extern "C" fn(*mut c_void);
type GetDesc = unsafe extern "C" fn(*mut c_void) -> *mut c_void;
type AppendChild = unsafe extern "C" fn(*mut c_void, *const c_char) -> *mut c_void;
type AppendChildValue = unsafe extern "C" fn(*mut c_void, *const c_char, *const c_char) -> *mut c_void;
type CreateOutlet = unsafe extern "C" fn(*mut c_void, c_int, c_int) -> *mut c_void;
type DestroyOutlet = unsafe extern "C" fn(*mut c_void);
type PushSampleD = unsafe extern "C" fn(*mut c_void, *const c_double, c_double, c_int) -> c_int;
type PushSampleStr = unsafe extern "C" fn(*mut c_void, *const *const c_char, c_double, c_int) -> c_int;
type LocalClock = unsafe extern "C" fn() -> c_double;
type LibraryVersion = unsafe extern "C" fn() -> c_int;

/// The functions of a loaded liblsl (plain function pointers, valid while `_library` is loaded).
struct Api {
    create_streaminfo: CreateStreaminfo,
    destroy_streaminfo: DestroyStreaminfo,
    get_desc: GetDesc,
    append_child: AppendChild,
    append_child_value: AppendChildValue,
    create_outlet: CreateOutlet,
    destroy_outlet: DestroyOutlet,
    push_sample_d: PushSampleD,
    push_sample_str: PushSampleStr,
    local_clock: LocalClock,
    library_version: LibraryVersion,
}

/// A loaded liblsl. Cheap to clone (shared); the library stays loaded while any clone or outlet lives.
#[derive(Clone)]
pub struct Liblsl {
    api: Arc<Api>,
    path: Arc<str>,
    // Declared last: dropped after the function pointers' last users.
    _library: Arc<Library>,
}

impl std::fmt::Debug for Liblsl {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Liblsl")
            .field("path", &self.path)
            .finish_non_exhaustive()
    }
}

impl Liblsl {
    /// Loads liblsl from the first candidate of the search order (module documentation) that loads.
    pub fn locate() -> Result<Liblsl, LslError> {
        let (candidates, mut tried) = candidates();
        for candidate in candidates {
            match Liblsl::open(&candidate) {
                Ok(lib) => return Ok(lib),
                Err(LslError::NotFound { tried: why }) => tried.extend(why),
                Err(other) => return Err(other),
            }
        }
        Err(LslError::NotFound { tried })
    }

    /// Loads liblsl from `path` (a file, or a bare name the system loader searches for). A path that is not a
    /// regular file (a FIFO, whose open would wait for a writer for ever; a device) is refused without opening it.
    pub fn open(path: &Path) -> Result<Liblsl, LslError> {
        let shown = path.display().to_string();
        // A bare name is the loader's to search (never the working folder); a path is checked where it points.
        let is_path = path.components().count() > 1 || path.is_absolute();
        if let Some(kind) = is_path
            .then(|| thermode_platform::fs::special_file_kind(path))
            .flatten()
        {
            return Err(LslError::NotFound {
                tried: vec![format!("{shown} (it is {kind}, not a regular file: not opened)")],
            });
        }
        // SAFETY: loading a shared library runs its initialisers; liblsl's (C++ static constructors of its
        // configuration and clock) have no preconditions on the caller. The path is one the operator pointed to
        // or liblsl's own installed name.
        let library = unsafe { Library::new(path) }.map_err(|e| LslError::NotFound {
            tried: vec![format!("{shown} ({e})")],
        })?;
        let api = Api::load(&library, &shown)?;
        Ok(Liblsl {
            api: Arc::new(api),
            path: Arc::from(shown),
            _library: Arc::new(library),
        })
    }

    /// The file or name it was loaded from.
    pub fn path(&self) -> &str {
        &self.path
    }

    /// liblsl's version (e.g. 116 for 1.16).
    pub fn version(&self) -> i32 {
        // SAFETY: `lsl_library_version` takes no argument and only returns a constant.
        unsafe { (self.api.library_version)() }
    }

    /// The LSL clock \[s\] (`lsl_local_clock`: the monotonic clock every LSL timestamp is on).
    pub fn local_clock(&self) -> f64 {
        // SAFETY: `lsl_local_clock` takes no argument and reads the monotonic clock.
        unsafe { (self.api.local_clock)() }
    }

    /// A new outlet of double-precision samples.
    pub fn double_outlet(&self, spec: &StreamSpec) -> Result<Outlet, LslError> {
        self.outlet(spec, CFT_DOUBLE64)
    }

    /// A new outlet of one string per sample (irregular rate: markers).
    pub fn string_outlet(&self, spec: &StreamSpec) -> Result<Outlet, LslError> {
        self.outlet(spec, CFT_STRING)
    }

    fn outlet(&self, spec: &StreamSpec, format: c_int) -> Result<Outlet, LslError> {
        let name = cstring(&spec.name)?;
        let kind = cstring(&spec.kind)?;
        let source = cstring(&spec.source_id)?;
        let count = c_int::try_from(spec.channels.len()).map_err(|_| LslError::Create {
            what: format!("stream info of {} ({} channels)", spec.name, spec.channels.len()),
        })?;
        // SAFETY: every pointer is a live NUL-terminated string for the call; liblsl copies them.
        let info = unsafe {
            (self.api.create_streaminfo)(
                name.as_ptr(),
                kind.as_ptr(),
                count,
                spec.rate_hz,
                format,
                source.as_ptr(),
            )
        };
        if info.is_null() {
            return Err(LslError::Create {
                what: format!("stream info of {}", spec.name),
            });
        }
        let described = self.describe(info, spec);
        // SAFETY: `info` is the live stream info created above; the outlet copies it (liblsl's documented
        // contract), so it is destroyed right after, once and only here.
        let outlet = described.map(|()| unsafe { (self.api.create_outlet)(info, 0, 360) });
        // SAFETY: as above: `info` is live and not used after this.
        unsafe { (self.api.destroy_streaminfo)(info) };
        let outlet = outlet?;
        if outlet.is_null() {
            return Err(LslError::Create {
                what: format!("outlet of {}", spec.name),
            });
        }
        Ok(Outlet {
            lib: self.clone(),
            raw: outlet,
            channels: spec.channels.len(),
        })
    }

    /// Writes `spec`'s description (`<desc><channels><channel><label/><unit/><type/></channel>…`, and the
    /// acquisition fields) into the stream info's XML.
    fn describe(&self, info: *mut c_void, spec: &StreamSpec) -> Result<(), LslError> {
        // SAFETY: `info` is a live stream info; `lsl_get_desc` returns a handle into it, valid while it lives.
        let desc = unsafe { (self.api.get_desc)(info) };
        for (key, value) in &spec.fields {
            self.child_value(desc, key, value)?;
        }
        let channels = self.child(desc, "channels")?;
        for channel in &spec.channels {
            let node = self.child(channels, "channel")?;
            self.child_value(node, "label", &channel.label)?;
            self.child_value(node, "unit", &channel.unit)?;
            self.child_value(node, "type", &channel.kind)?;
        }
        Ok(())
    }

    fn child(&self, parent: *mut c_void, name: &str) -> Result<*mut c_void, LslError> {
        let name = cstring(name)?;
        // SAFETY: `parent` is a live XML handle of a live stream info; `name` is NUL-terminated and copied.
        Ok(unsafe { (self.api.append_child)(parent, name.as_ptr()) })
    }

    fn child_value(&self, parent: *mut c_void, name: &str, value: &str) -> Result<(), LslError> {
        let (name, value) = (cstring(name)?, cstring(value)?);
        // SAFETY: as in `child`; both strings are NUL-terminated and copied by liblsl.
        unsafe { (self.api.append_child_value)(parent, name.as_ptr(), value.as_ptr()) };
        Ok(())
    }
}

impl Api {
    fn load(library: &Library, path: &str) -> Result<Api, LslError> {
        /// Looks a function up by its C name.
        fn get<T: Copy>(library: &Library, path: &str, symbol: &'static str) -> Result<T, LslError> {
            let name = format!("{symbol}\0");
            // SAFETY: each `T` below is the exact C signature of `symbol` in liblsl's `lsl_c.h`; the pointer is
            // only used while the library stays loaded (`Liblsl` keeps it alive).
            let found = unsafe { library.get::<T>(name.as_bytes()) };
            found.map(|f| *f).map_err(|e| LslError::MissingSymbol {
                path: path.to_string(),
                symbol,
                reason: e.to_string(),
            })
        }
        Ok(Api {
            create_streaminfo: get(library, path, "lsl_create_streaminfo")?,
            destroy_streaminfo: get(library, path, "lsl_destroy_streaminfo")?,
            get_desc: get(library, path, "lsl_get_desc")?,
            append_child: get(library, path, "lsl_append_child")?,
            append_child_value: get(library, path, "lsl_append_child_value")?,
            create_outlet: get(library, path, "lsl_create_outlet")?,
            destroy_outlet: get(library, path, "lsl_destroy_outlet")?,
            push_sample_d: get(library, path, "lsl_push_sample_dtp")?,
            push_sample_str: get(library, path, "lsl_push_sample_strtp")?,
            local_clock: get(library, path, "lsl_local_clock")?,
            library_version: get(library, path, "lsl_library_version")?,
        })
    }
}

/// One channel of a stream's description.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelSpec {
    /// Label, e.g. `ch0_sensor_c`.
    pub label: String,
    /// Unit, e.g. `degC`, `A`.
    pub unit: String,
    /// Type, e.g. `Temperature`, `Current`.
    pub kind: String,
}

/// What a stream is: name, type, rate, source id, channels, and extra description fields.
#[derive(Debug, Clone, PartialEq)]
pub struct StreamSpec {
    /// Stream name.
    pub name: String,
    /// Stream type (e.g. `Markers`).
    pub kind: String,
    /// Nominal rate \[Hz\]; 0 for an irregular stream.
    pub rate_hz: f64,
    /// Source id (a recorder reconnects to the same source across restarts).
    pub source_id: String,
    /// The channels.
    pub channels: Vec<ChannelSpec>,
    /// Extra `<desc>` fields (`key`, `value`).
    pub fields: Vec<(String, String)>,
}

/// A live LSL outlet; destroyed when dropped.
pub struct Outlet {
    lib: Liblsl,
    raw: *mut c_void,
    channels: usize,
}

// SAFETY: liblsl outlets are thread-safe (its documented contract); the handle is only a pointer to one.
unsafe impl Send for Outlet {}

impl std::fmt::Debug for Outlet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Outlet")
            .field("channels", &self.channels)
            .finish_non_exhaustive()
    }
}

impl Outlet {
    /// Pushes one sample of doubles stamped `timestamp_s` (LSL clock). `values` must have one value per channel
    /// (a sample of the wrong length is not pushed: false).
    pub fn push_doubles(&self, values: &[f64], timestamp_s: f64) -> bool {
        if values.len() != self.channels {
            return false;
        }
        // SAFETY: `raw` is a live double outlet of `channels` channels and `values` holds exactly that many.
        unsafe { (self.lib.api.push_sample_d)(self.raw, values.as_ptr(), timestamp_s, 1) == 0 }
    }

    /// Pushes one string (a one-channel string outlet) stamped `timestamp_s` (LSL clock). A text with a NUL byte
    /// is not pushed (false).
    pub fn push_string(&self, text: &str, timestamp_s: f64) -> bool {
        if self.channels != 1 {
            return false;
        }
        let Ok(text) = CString::new(text) else {
            return false;
        };
        let sample = [text.as_ptr()];
        // SAFETY: `raw` is a live one-channel string outlet; `sample` holds one NUL-terminated string, copied.
        unsafe { (self.lib.api.push_sample_str)(self.raw, sample.as_ptr(), timestamp_s, 1) == 0 }
    }
}

impl Drop for Outlet {
    fn drop(&mut self) {
        // SAFETY: `raw` is the live outlet created for this value, destroyed exactly once, here.
        unsafe { (self.lib.api.destroy_outlet)(self.raw) };
    }
}

fn cstring(text: &str) -> Result<CString, LslError> {
    CString::new(text).map_err(|_| LslError::Nul(text.to_string()))
}

/// The candidates of the search order (module documentation), and why a way of finding them failed (a Python probe
/// that did not answer), for the error's list of what was tried.
fn candidates() -> (Vec<PathBuf>, Vec<String>) {
    for variable in ["THERMODE_LIBLSL", "PYLSL_LIB"] {
        if let Some(path) = std::env::var_os(variable).filter(|v| !v.is_empty()) {
            return (vec![PathBuf::from(path)], Vec::new());
        }
    }
    let mut all: Vec<PathBuf> = system_names().iter().map(PathBuf::from).collect();
    match pylsl_copies() {
        Ok(copies) => {
            all.extend(copies);
            (all, Vec::new())
        }
        Err(why) => (all, vec![why]),
    }
}

fn system_names() -> &'static [&'static str] {
    if cfg!(target_os = "macos") {
        &["liblsl.dylib", "liblsl.2.dylib"]
    } else if cfg!(windows) {
        &["lsl.dll", "liblsl64.dll"]
    } else {
        &["liblsl.so.2", "liblsl.so"]
    }
}

/// The longest wait for the Python probe that finds the `pylsl` package \[s\]: 5 (it answers in about 0.05 s; a
/// hanging interpreter must not hold `serve --lsl` at start).
pub const PYTHON_PROBE_TIMEOUT_S: f64 = 5.0;

/// Why a probe program gave no answer.
#[derive(Debug)]
enum ProbeFailure {
    /// It could not be started (not installed), or it ended unsuccessfully: it has nothing to say.
    NoAnswer,
    /// It was still running, or its output still open, at the deadline (it is killed): the reason, in words.
    Hung(String),
}

/// What `program` with `args` printed on standard output, if it ended successfully within `timeout_s` \[s\]; else
/// why not (one that has not ended by then is killed). Its standard input and error are closed.
fn output_within(program: &str, args: &[&str], timeout_s: f64) -> Result<String, ProbeFailure> {
    use std::io::Read;
    use std::process::{Command, Stdio};
    use std::time::{Duration, Instant};
    let mut child = Command::new(program)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .map_err(|_| ProbeFailure::NoAnswer)?;
    let mut stdout = child.stdout.take().ok_or(ProbeFailure::NoAnswer)?;
    // Read on a thread of its own, so that neither a child writing much nor one whose own children keep the pipe
    // open can hold the wait past the deadline (such a reader is left to end with the pipe).
    let (send, receive) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut text = String::new();
        let _ = send.send(stdout.read_to_string(&mut text).map(|_| text));
    });
    let deadline = Instant::now() + Duration::from_secs_f64(timeout_s);
    loop {
        match child.try_wait() {
            Ok(Some(status)) if status.success() => break,
            Ok(Some(_)) => return Err(ProbeFailure::NoAnswer),
            Ok(None) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(10)),
            _ => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(ProbeFailure::Hung(format!("no answer within {timeout_s} s: killed")));
            }
        }
    }
    let left = deadline.saturating_duration_since(Instant::now());
    match receive.recv_timeout(left) {
        Ok(Ok(text)) => Ok(text),
        Ok(Err(_)) => Err(ProbeFailure::NoAnswer),
        Err(_) => Err(ProbeFailure::Hung(format!(
            "its output still open {timeout_s} s after it began"
        ))),
    }
}

/// The library files inside the installed `pylsl` package, if Python finds one within
/// [`PYTHON_PROBE_TIMEOUT_S`] (none when Python or the package is missing); why the probe failed when it hung.
fn pylsl_copies() -> Result<Vec<PathBuf>, String> {
    let python = std::env::var("THERMODE_PYTHON").unwrap_or_else(|_| "python3".into());
    let script = "import importlib.util as u; s = u.find_spec('pylsl'); \
                  print(s.submodule_search_locations[0] if s and s.submodule_search_locations else '')";
    let out = match output_within(&python, &["-c", script], PYTHON_PROBE_TIMEOUT_S) {
        Ok(out) => out,
        Err(ProbeFailure::NoAnswer) => return Ok(Vec::new()),
        Err(ProbeFailure::Hung(why)) => return Err(format!("the pylsl package, asked of {python} ({why})")),
    };
    let dir = out.trim().to_string();
    if dir.is_empty() {
        return Ok(Vec::new());
    }
    let lib = Path::new(&dir).join("lib");
    Ok(system_names().iter().map(|name| lib.join(name)).collect())
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    /// A FIFO as the library (`THERMODE_LIBLSL`) held `serve --lsl` at start for ever, the loader waiting for a
    /// writer; now it is refused without being opened. Judged on another thread with a generous bound.
    #[test]
    fn a_fifo_as_the_library_is_refused_without_opening_it() {
        let dir = tempfile::tempdir().expect("temporary folder");
        let fifo = dir.path().join("liblsl.so");
        let made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .expect("run mkfifo");
        assert!(made.success(), "mkfifo {}", fifo.display());
        let (send, receive) = std::sync::mpsc::channel();
        let path = fifo.clone();
        std::thread::spawn(move || {
            let _ = send.send(Liblsl::open(&path).map(|_| ()).map_err(|e| e.to_string()));
        });
        let answer = receive
            .recv_timeout(std::time::Duration::from_secs(30))
            .expect("Liblsl::open blocked on a FIFO");
        let text = answer.expect_err("a FIFO loaded as liblsl");
        assert!(
            text.contains("a FIFO, not a regular file") && text.contains(&fifo.display().to_string()),
            "{text}"
        );
    }

    /// A probe that hangs is killed at its deadline and says so; one that answers is read; one that cannot run or
    /// fails has nothing to say (as a machine without Python).
    #[test]
    fn a_probe_answers_within_its_time_out_or_is_killed() {
        match output_within("sleep", &["600"], 0.2) {
            Err(ProbeFailure::Hung(why)) => assert!(why.contains("killed"), "{why}"),
            other => panic!("a hanging probe: {other:?}"),
        }
        assert_eq!(
            output_within("sh", &["-c", "echo /some/where"], 30.0).expect("echo answers"),
            "/some/where\n"
        );
        assert!(matches!(
            output_within("/nonexistent/python3", &[], 30.0),
            Err(ProbeFailure::NoAnswer)
        ));
        assert!(matches!(output_within("false", &[], 30.0), Err(ProbeFailure::NoAnswer)));
        // A child whose own child keeps the pipe open past the deadline does not hold the wait either.
        match output_within("sh", &["-c", "sleep 5 & echo started"], 0.5) {
            Err(ProbeFailure::Hung(why)) => assert!(why.contains("still open"), "{why}"),
            other => panic!("a probe whose child holds its output: {other:?}"),
        }
    }
}
