//! The live dashboard (issue 11): what the control loop hands to the web server and what it
//! takes back ([`messages`]: no sockets, no clock), the loop's side ([`observer`]), the dashboard of one run ([`run`]), and the
//! HTTP server ([`server`], feature `dashboard`: the network side, on threads and a tokio
//! runtime of its own, the one part of the library that reads the wall clock, for its
//! connection deadlines and the operator's heartbeat).
//!
//! ```text
//!   Driver ──on_frame──► DashObserver ──put──► Latest<Arc<Snapshot>>  ──► server threads
//!          ◄─before_frame─  (drains)   ◄──try_send── bounded inbox  ◄──  (annotate, JPEG,
//!                                                                        JSON, validation)
//! ```
//!
//! The loop never waits for the web: publishing is one `put` into a newest-only slot at most
//! `stream_fps` times per second of frame time (a copy of the frame and the lane images, a few
//! hundred kB), and control messages arrive through a bounded channel that `before_frame`
//! drains without blocking (except while the operator has paused the simulator). Every change
//! becomes an event in the telemetry record of the first frame it acts on
//! ([`crate::telemetry::FrameRecord::events`]), with the time the operator asked for it.
//!
//! Values are checked with the configuration's own ranges ([`validate_set`] goes through
//! [`crate::config::Config::with_override`]), so the page can never set what `config/car.toml` could not.

//!
//! The files import one another one way: [`messages`] and [`shared`] import none of the
//! others, [`observer`] uses `messages`, the server uses `messages` and `shared`, [`run`] uses
//! all three; this file only declares and re-exports.

pub mod local_toml;
pub mod messages;
pub mod observer;
pub mod run;
#[cfg(feature = "dashboard")]
pub mod server;
pub mod shared;

pub use messages::{
    get_value, parse_body, settable, validate_set, Control, ControlError, ControlSender, DriveRequest, Live, ModeRequest, RecordRequest,
    PlaceRequest, PlotPoint, SetRequest, Snapshot, INBOX_CAPACITY, MAX_BODY,
};
pub use observer::{apply_value, channel, Channel, DashObserver};
pub use run::Dash;
pub use shared::{DashboardError, Sent};
