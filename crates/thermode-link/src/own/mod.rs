//! thermode's own protocol: the binary host–device protocol ([`codec`]: COBS frames, CRC-32, sequence numbers,
//! watchdog; specified in `docs/protocol.md`), the host ([`host::SerialDevice`], `--device serial:PATH`) and the
//! device emulated ([`emulator::Emulator`], `thermode emulate`) with its own over- and under-temperature cut
//! ([`guard`]).

pub mod codec;
pub mod emulator;
pub mod guard;
pub mod host;
