//! The serial link to the Arduino (issue 3): the protocol (`protocol`, mirrored by the
//! firmware's `protocol.h` and documented as one table in `docs/protocol.md`) and, behind the
//! `serial` cargo feature, the transport that talks to a real port or the emulator's pty, and [`sink::LinkSink`],
//! the link as the drive loop's actuators, and [`bench`], the bench modes of `rccar link`.

pub mod protocol;
#[cfg(feature = "serial")]
pub mod transport;
#[cfg(feature = "serial")]
pub mod sink;
#[cfg(feature = "serial")]
pub mod bench;
