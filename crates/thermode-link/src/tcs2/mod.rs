//! The QST.Lab TCS II thermal stimulator: its serial protocol ([`codec`]), the host in follow mode
//! ([`host::Tcs2Device`], `--device tcs2:PATH`) and the stimulator emulated ([`emulator::Tcs2Emulator`],
//! `thermode emulate --protocol tcs2`).
//!
//! Sources of the protocol facts: the stimulator's own command list (its `H` help text) as reproduced in public
//! projects that drive it (`mpcoll/pytcsii`; the `N`, `S`, `C`, `V`, `R`, `D`, `L`, `A`, `F`, `E`, `Q`, `Oa`,
//! `Ob`, `Od` follow mode, `Om` maximum temperature commands and their argument widths) and the format of its
//! temperature lines (`ulrikehorn/thermode-control`: a carriage return, the neutral temperature and each zone's,
//! signed, in tenths of a degree). The manual itself is not public; `docs/hardware.md` lists exactly what thermode
//! sends.

pub mod codec;
pub mod emulator;
pub mod host;
