//! Typed failures of the links to real displays (`thermode-link`), carried by [`crate::DeviceError::Link`]: which
//! device ([`LinkError::Device`]: its port path, `HOST:PORT`, or the name a host was given) and why
//! ([`LinkFault`]), a `--device` spelling that names no display ([`LinkError::Spec`], [`SpecFault`]), or a MeCom
//! channel that cannot exist ([`LinkError::BadChannel`]). Every field is a number, a path, an operating-system error
//! ([`OsError`]: its kind and errno, no text) or an enum of reasons, so callers can match on them; the messages read as the hosts' messages always did.

use std::io;
use std::ops::Range;
use std::path::PathBuf;

use thiserror::Error;

/// An operating-system error as a link keeps it: its kind and, when it has one, its errno, so that the message is
/// the system's own ("No such file or directory (os error 2)") while the error stays a plain value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OsError {
    /// The I/O error's kind.
    pub kind: io::ErrorKind,
    /// The system's error number, when the error came from the system.
    pub code: Option<i32>,
}

impl From<&io::Error> for OsError {
    fn from(error: &io::Error) -> Self {
        OsError {
            kind: error.kind(),
            code: error.raw_os_error(),
        }
    }
}

impl From<io::Error> for OsError {
    fn from(error: io::Error) -> Self {
        OsError::from(&error)
    }
}

impl From<io::ErrorKind> for OsError {
    fn from(kind: io::ErrorKind) -> Self {
        OsError { kind, code: None }
    }
}

impl std::fmt::Display for OsError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match (self.code, self.kind) {
            (Some(code), _) => io::Error::from_raw_os_error(code).fmt(f),
            (None, io::ErrorKind::NotFound) => f.write_str("no such file or device"),
            (None, kind) => kind.fmt(f),
        }
    }
}

/// Why a link to a real display failed.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum LinkError {
    /// The device `device` (its port's path, `HOST:PORT`, or a host's name) failed.
    #[error("{}: {fault}", device.display())]
    Device {
        /// The device: its port's path, `HOST:PORT` for TCP, or the name given to a host over byte streams.
        device: PathBuf,
        /// Why.
        fault: LinkFault,
    },
    /// A `--device` spelling that names no real display.
    #[error("--device {spec:?}: {}", fault.describe(&spec.to_string_lossy()))]
    Spec {
        /// The spelling as given.
        spec: PathBuf,
        /// What is wrong with it.
        fault: SpecFault,
    },
    /// A MeCom channel outside the protocol's ranges.
    #[error("MeCom channel {address}:{instance}: addresses are 0 to 254 and instances start at 1")]
    BadChannel {
        /// Device address.
        address: u8,
        /// Instance.
        instance: u8,
    },
}

impl LinkError {
    /// `fault` of the device named `device`.
    pub fn device(device: impl Into<PathBuf>, fault: LinkFault) -> Self {
        LinkError::Device {
            device: device.into(),
            fault,
        }
    }

    /// The device's fault, if this is one.
    pub fn fault(&self) -> Option<&LinkFault> {
        match self {
            LinkError::Device { fault, .. } => Some(fault),
            _ => None,
        }
    }
}

/// What a host was doing when its port could not be opened.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum OpenStep {
    /// Opening the serial port.
    #[error("cannot open the serial port")]
    Open,
    /// Sharing the serial port between the reader and the writer.
    #[error("cannot share the serial port")]
    Share,
    /// Setting the port's write timeout.
    #[error("cannot set the write timeout of the serial port")]
    WriteTimeout,
    /// Resolving `HOST:PORT`.
    #[error("cannot resolve the address")]
    Resolve,
    /// Connecting over TCP.
    #[error("cannot connect")]
    Connect,
    /// Configuring the TCP connection (timeouts, no delay).
    #[error("cannot configure the connection")]
    Configure,
    /// Starting the host's reader, worker or reconnector thread.
    #[error("cannot start the link's thread")]
    Thread,
}

/// What a host waited for in vain while connecting.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum Awaited {
    /// thermode's own protocol: `Identify` in answer to `Hello`.
    #[error("no Identify answer to Hello")]
    Identify,
    /// thermode's own protocol: a report with the drives released after `ClearFault`.
    #[error("no unlatched sensor report")]
    Released,
    /// TCS II: `TCS` in answer to `?`.
    #[error("the stimulator did not answer TCS to '?'")]
    StimulatorIdentity,
    /// TCS II: the error state in answer to `Q`.
    #[error("the stimulator did not answer 'Q'")]
    StimulatorErrorState,
    /// TCS II: a temperature line.
    #[error("the stimulator sent no temperatures")]
    StimulatorTemperatures,
}

/// What a host's readings went without.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum Silence {
    /// thermode's own protocol: sensor reports.
    #[error("sensor report")]
    SensorReport,
    /// TCS II: temperature lines.
    #[error("temperatures")]
    Temperatures,
}

/// Why one MeCom request got no usable answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum RequestFault {
    /// No answer, even when repeated.
    #[error("no answer")]
    NoAnswer,
    /// The device answered with a server error.
    #[error("the device answered server error {code} ({meaning})")]
    Server {
        /// The code.
        code: u8,
        /// What the code means.
        meaning: &'static str,
    },
    /// The answer has the wrong shape for the request.
    #[error("unexpected answer of {length} characters to {request}")]
    Unexpected {
        /// The answer's payload length \[characters\].
        length: usize,
        /// The request's command (`?IF`, `?VR`, `VS`, …).
        request: &'static str,
    },
    /// The port failed.
    #[error("port failed: {error}")]
    Port {
        /// The system's error.
        error: OsError,
    },
}

/// Why a device's link failed.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum LinkFault {
    /// The port could not be opened or set up.
    #[error("{step}: {error}")]
    Open {
        /// What failed.
        step: OpenStep,
        /// The system's error.
        error: OsError,
    },
    /// `HOST:PORT` resolves to no address.
    #[error("resolves to no address")]
    NoAddress,
    /// A `serial:PATH` was expected.
    #[error("is not a serial device (serial:PATH)")]
    NotSerial,
    /// The port reached its end (closed).
    #[error("the serial port reached its end (closed)")]
    PortClosed,
    /// Reading the port failed.
    #[error("serial port read failed: {error}")]
    ReadFailed {
        /// The system's error.
        error: OsError,
    },
    /// Writing the port failed (or timed out: the device stopped reading).
    #[error("serial port write failed: {error}")]
    WriteFailed {
        /// The system's error.
        error: OsError,
    },
    /// The host's reader or worker thread failed (its state is gone).
    #[error("the link's reader failed")]
    ReaderFailed,
    /// A frame could not be encoded.
    #[error("cannot encode a frame")]
    Encode,
    /// The handshake did not finish within its timeout.
    #[error("{awaited} within {timeout_s} s{}", handshake_hint(*awaited, *other_version))]
    Handshake {
        /// What the host waited for.
        awaited: Awaited,
        /// The handshake timeout \[s\].
        timeout_s: f64,
        /// The device refused the host's protocol version.
        other_version: bool,
    },
    /// Nothing to read from yet.
    #[error("no {silence} yet")]
    NothingYet {
        /// What has not arrived.
        silence: Silence,
    },
    /// Nothing arrived for longer than the link timeout.
    #[error("no {silence} for {silent_s:.3} s (link timeout {timeout_s} s)")]
    Silent {
        /// What did not arrive.
        silence: Silence,
        /// How long nothing arrived \[s\].
        silent_s: f64,
        /// The link timeout \[s\].
        timeout_s: f64,
    },
    /// The device latched its drives off (thermode's own protocol).
    #[error(
        "the device latched its drives off ({}); they are released once every channel is commanded 0 A",
        if *watchdog { "its watchdog expired" } else { "it restarted" }
    )]
    Latched {
        /// Its watchdog expired (else it restarted).
        watchdog: bool,
    },
    /// The link is down and being re-opened.
    #[error("link down: {reason}")]
    Down {
        /// Why it went down.
        reason: DownReason,
    },
    /// A link the reconnector made was not adopted (the old link's remains).
    #[error("replaced by a new link")]
    Replaced,
    /// The device came back with another number of channels.
    #[error("the device now has {now} channels, not {before}: not adopted")]
    ChannelsChanged {
        /// Channels now.
        now: usize,
        /// Channels before.
        before: usize,
    },
    /// TCS II: the stimulator reports an error on its neutral sensor (`zone` None) or a zone (from 1).
    #[error(
        "the stimulator reports error {code} on {}",
        match zone { Some(z) => format!("zone {z}"), None => "its neutral sensor".to_string() }
    )]
    Stimulator {
        /// The zone from 1, or None for the neutral sensor.
        zone: Option<usize>,
        /// The error code.
        code: u8,
    },
    /// TCS II: the temperature lines have no such zone.
    #[error("the stimulator's temperatures have no zone {zone}")]
    NoZone {
        /// The zone from 1.
        zone: usize,
    },
    /// MeCom: a channel has not been read yet.
    #[error("no reading of channel {channel} yet")]
    NoReading {
        /// The channel.
        channel: usize,
    },
    /// MeCom: a channel did not answer for longer than the link timeout.
    #[error("channel {channel} has not answered for {silent_s:.3} s (link timeout {timeout_s} s): {why}")]
    NotAnswered {
        /// The channel.
        channel: usize,
        /// How long \[s\].
        silent_s: f64,
        /// The link timeout \[s\].
        timeout_s: f64,
        /// Why its last request failed.
        why: RequestFault,
    },
    /// MeCom: the device's port failed.
    #[error("{0}")]
    Request(RequestFault),
    /// MeCom: the device is in its error state.
    #[error("the device is in its error state with its output off: error {number} ({meaning}); reconnect to reset it")]
    ErrorState {
        /// The device's error number.
        number: i32,
        /// What it means.
        meaning: &'static str,
    },
    /// MeCom: switching every output off was not acknowledged in time.
    #[error("the device did not acknowledge switching every output off within {wait_s:.2} s")]
    OffNotAcknowledged {
        /// How long the host waited \[s\].
        wait_s: f64,
    },
    /// MeCom: connecting or configuring failed.
    #[error("{0}")]
    Setup(MecomSetup),
}

/// What a handshake's message adds after its timeout.
fn handshake_hint(awaited: Awaited, other_version: bool) -> &'static str {
    match (awaited, other_version) {
        (_, true) => " (it speaks another protocol version)",
        (Awaited::Released, false) => " of the handshake",
        _ => "",
    }
}

/// Why the link was taken down.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum DownReason {
    /// The link failed.
    #[error("{0}")]
    Failed(Box<LinkFault>),
    /// No report for longer than the reconnection threshold.
    #[error("no report for {silent_s:.1} s (more than {limit_s} s)")]
    Silent {
        /// How long \[s\].
        silent_s: f64,
        /// The threshold \[s\].
        limit_s: f64,
    },
}

/// Why connecting to and configuring a MeCom device failed.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum MecomSetup {
    /// An address did not answer `?IF` before the handshake timeout.
    #[error("address {address} did not identify itself (?IF) before the handshake timeout: {last}")]
    NoIdentity {
        /// The address.
        address: u8,
        /// Why the last try failed.
        last: RequestFault,
    },
    /// The number of TEC instances could not be read.
    #[error("cannot count the TEC instances (?VM of parameter 1000): {0}")]
    CountInstances(RequestFault),
    /// The device has no or too many instances.
    #[error("the device has {count} TEC instances; thermode drives 1 to {max}")]
    InstanceCount {
        /// Instances found.
        count: usize,
        /// The most thermode drives.
        max: usize,
    },
    /// The device status of an address could not be read.
    #[error("cannot read the device status (104) of address {address}: {why}")]
    ReadStatus {
        /// The address.
        address: u8,
        /// Why.
        why: RequestFault,
    },
    /// An address is in its error state and the reset is not allowed.
    #[error("address {address} is in its error state, error {number} ({meaning}); clear it or allow the reset")]
    InErrorState {
        /// The address.
        address: u8,
        /// Its error number.
        number: i32,
        /// What it means.
        meaning: &'static str,
    },
    /// The reset of an address failed.
    #[error("cannot reset address {address} from error {number}: {why}")]
    Reset {
        /// The address.
        address: u8,
        /// Its error number.
        number: i32,
        /// Why.
        why: RequestFault,
    },
    /// The object temperature could not be read (temperature mode).
    #[error("cannot read the object temperature (1000): {0}")]
    ReadObject(RequestFault),
    /// A channel refused a configuration step.
    #[error("address {address} instance {instance} refused {step}: {why}")]
    Refused {
        /// The address.
        address: u8,
        /// The instance.
        instance: u8,
        /// The step (what was set).
        step: &'static str,
        /// Why.
        why: RequestFault,
    },
    /// "Positive current is" could not be read.
    #[error("cannot read 'positive current is' (3034): {0}")]
    ReadSign(RequestFault),
    /// An address did not take the communication watchdog.
    #[error(
        "address {address} did not take the communication watchdog (2060 = {watchdog_s} s): {why}. thermode drives \
         no TEC controller that keeps its output on when the host is gone: update its firmware, or use its hardware \
         enable with a dead-man switch (docs/hardware.md)"
    )]
    Watchdog {
        /// The address.
        address: u8,
        /// The watchdog asked for \[s\].
        watchdog_s: f64,
        /// Why.
        why: RequestFault,
    },
    /// An address entered its error state while being configured.
    #[error("address {address} entered its error state while being configured: error {number} ({meaning})")]
    ErrorWhileConfiguring {
        /// The address.
        address: u8,
        /// Its error number.
        number: i32,
        /// What it means.
        meaning: &'static str,
    },
}

/// What is wrong with a `--device` spelling. The text at fault is named by its byte range in the spelling (which
/// [`LinkError::Spec`] carries), so the message quotes it as typed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SpecFault {
    /// `serial:` with no path.
    NoPath,
    /// No path or address after the prefix.
    NoTarget,
    /// An option is not `key=value`.
    NotKeyValue {
        /// The option.
        option: Range<usize>,
    },
    /// An option the protocol does not take.
    UnknownOption {
        /// The protocol (`MeCom`, `TCS II`).
        protocol: &'static str,
        /// The option's key.
        key: Range<usize>,
    },
    /// An option's value is not one the option takes.
    BadValue {
        /// The option.
        key: &'static str,
        /// Its value.
        value: Range<usize>,
        /// What is wrong, as the message goes on after the quoted value (`": use current or temperature"`,
        /// `" is not a number"`).
        requirement: &'static str,
    },
    /// A MeCom channel that is not `ADDRESS:INSTANCE`.
    NotAChannel {
        /// The channel as given.
        channel: Range<usize>,
    },
    /// No known prefix.
    NotHardware,
    /// Several `mecom:PATH@ADDR` on one port (a bus) with a `channels=` list: the bus takes every instance of each
    /// address.
    BusWithChannels,
}

impl SpecFault {
    /// What is wrong with `spec`, quoting the text at fault.
    pub fn describe(&self, spec: &str) -> String {
        let text = |range: &Range<usize>| spec.get(range.clone()).unwrap_or_default().to_string();
        match self {
            SpecFault::NoPath => "no path".to_string(),
            SpecFault::NoTarget => "no path or address".to_string(),
            SpecFault::NotKeyValue { option } => format!("option {:?} is not key=value", text(option)),
            SpecFault::UnknownOption { protocol, key } => format!("unknown {protocol} option {:?}", text(key)),
            SpecFault::BadValue {
                key,
                value,
                requirement,
            } => format!("{key}={:?}{requirement}", text(value)),
            SpecFault::NotAChannel { channel } => format!("channel {:?} is not ADDRESS:INSTANCE", text(channel)),
            SpecFault::NotHardware => {
                "not a real display: use serial:PATH, mecom:PATH, mecom-tcp:HOST:PORT or tcs2:PATH".to_string()
            }
            SpecFault::BusWithChannels => {
                "several addresses on one port take every instance of each address: no channels= list".to_string()
            }
        }
    }
}
