//! The MeCom wire format: the frame ([`frame`]: control character, address, sequence number, payload, CRC-16) and
//! the payloads and parameters thermode uses ([`payload`]).

pub mod frame;
pub mod payload;
