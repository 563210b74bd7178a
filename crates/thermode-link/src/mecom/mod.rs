//! Meerstetter TEC controllers over MeCom: the frame codec ([`codec::frame`]), payloads and parameters ([`codec::payload`]), the
//! host side ([`host::MecomDevice`], `--device mecom:PATH` or `mecom-tcp:HOST:PORT`) and the device side emulated
//! ([`emulator::MecomEmulator`], `thermode emulate --protocol mecom`).
//!
//! Sources of the protocol facts (the public documents of Meerstetter Engineering, as published with the
//! `pyMeComTEC` and `pyMeCom` projects): *MeCom Protocol Specification* 5117C (frame, CRC, `?IF`, `RS`, `?VR`,
//! `VS`, `?VM`, server errors, the example frames the tests reproduce), *TEC Controller Communication Protocol*
//! 5136AL (parameter ids, volatile live parameters, the communication watchdog 2060, example frames) and the
//! *TEC-Family User Manual* 5216G (device status, error numbers, error state and its auto-restart delay).
//! `docs/hardware.md` says which parameters thermode writes and why.

pub mod codec;
pub mod emulator;
pub mod host;
pub mod line;
