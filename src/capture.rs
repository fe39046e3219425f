//! A camera on its own thread: the newest frame only, stall detection, reconnection.
//!
//! The capture thread grabs frames as fast as the device delivers them and puts each into a
//! [`Latest`] slot: the loop always gets the newest frame, never a queue of old ones (late
//! frames are dropped and counted). When no frame has arrived for `stall_after` (a camera that
//! stalls or was unplugged), [`CaptureSource::next_frame`] reports a *stalled* error: the loop
//! sends neutral at once and keeps waiting; the thread closes and reopens the device until it
//! delivers again. A device that delivers the wrong size is a fatal error (the source ends and
//! [`CaptureSource::fatal`] says why) rather than a silent resize of a mis-configured camera.
//!
//! A grab can also fail for one frame only ([`GrabError::Bad`]: a producer that wrote garbage):
//! that frame is counted and handed to the loop as an unusable frame, the source goes on. A
//! source that cannot go on at all ([`GrabError::Fatal`]: the camera program exited) ends with
//! [`CaptureSource::fatal`] saying why.
//!
//! The device itself is behind [`Grabber`] (nokhwa's V4L2 camera in `camera_source.rs`, a
//! camera program's pipe in `pipecam`, a scripted one in tests). Capture times come from the
//! [`Clock`] the caller passes in.

use crate::drive::{Clock, Latest};
use crate::source::{Frame, FrameError, FrameSource};
use image::RgbImage;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

/// Why a grab (or an open) gave no image.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum GrabError {
    /// The device is gone or failing (unplugged): it is closed and reopened.
    Lost(String),
    /// This one frame is unusable (a producer wrote garbage, a short frame): it is counted
    /// and handed on as an unusable frame; the device stays open.
    Bad(String),
    /// The source cannot go on (the camera program exited, cannot be started): it ends and
    /// [`CaptureSource::fatal_reason`] says why.
    Fatal(String),
}

impl From<String> for GrabError {
    fn from(why: String) -> Self {
        GrabError::Lost(why)
    }
}

/// A device that delivers images.
pub trait Grabber {
    /// Opens (or reopens) the device.
    fn open(&mut self) -> Result<(), GrabError>;
    /// The next image; blocks until the device delivers one. [`GrabError::Lost`] closes the
    /// device and the thread reopens it.
    fn grab(&mut self) -> Result<RgbImage, GrabError>;
    /// Closes the device (before a reopen, and at the end).
    fn close(&mut self) {}
    /// A label for frame names and messages (`/dev/video0`).
    fn label(&self) -> String;
}

struct Shot {
    index: u64,
    captured_s: f64,
    /// The image, or why this frame is unusable.
    image: Result<RgbImage, String>,
}

/// Frames from a [`Grabber`] on a thread of its own (see the module notes).
pub struct CaptureSource {
    slot: Arc<Latest<Shot>>,
    fatal: Arc<Mutex<Option<String>>>,
    quit: Arc<AtomicBool>,
    bad: Arc<AtomicU64>,
    thread: Option<JoinHandle<()>>,
    stall_after: Duration,
    label: String,
    t0: Option<f64>,
    stalled_at: u64,
}

impl CaptureSource {
    /// Starts capturing from the grabber `make` builds on the capture thread. Frames must be `width × height`; `stall_after` is the
    /// longest wait for a frame before the loop is told the camera stalled (0.5 s on the car).
    /// Reopen attempts are `retry` apart.
    pub fn start(
        make: impl FnOnce() -> Box<dyn Grabber> + Send + 'static,
        label: String,
        size: (u32, u32),
        clock: Arc<dyn Clock + Send + Sync>,
        stall_after: Duration,
        retry: Duration,
    ) -> CaptureSource {
        let slot = Arc::new(Latest::new());
        let fatal = Arc::new(Mutex::new(None));
        let quit = Arc::new(AtomicBool::new(false));
        let bad = Arc::new(AtomicU64::new(0));
        let (s, f, q, b) = (slot.clone(), fatal.clone(), quit.clone(), bad.clone());
        let thread = std::thread::Builder::new()
            .name("rccar-capture".into())
            .spawn(move || {
                // The device lives on this thread only (V4L2 handles need not be Send).
                let mut grabber = make();
                let mut open = false;
                let mut index = 0u64;
                let end = |msg: String| {
                    *f.lock().unwrap_or_else(|e| e.into_inner()) = Some(msg);
                    s.close();
                };
                while !q.load(Ordering::SeqCst) {
                    if !open {
                        match grabber.open() {
                            Ok(()) => open = true,
                            Err(GrabError::Fatal(msg)) => {
                                end(msg);
                                break;
                            }
                            Err(_) => {
                                std::thread::sleep(retry);
                                continue;
                            }
                        }
                    }
                    match grabber.grab() {
                        Ok(image) => {
                            if image.dimensions() != size {
                                let msg = format!(
                                    "{}: delivers {}×{} frames, the configuration asks for {}×{} ([camera] width/height)",
                                    grabber.label(),
                                    image.width(),
                                    image.height(),
                                    size.0,
                                    size.1
                                );
                                end(msg);
                                break;
                            }
                            s.put(Shot {
                                index,
                                captured_s: clock.now_s(),
                                image: Ok(image),
                            });
                            index += 1;
                        }
                        Err(GrabError::Bad(why)) => {
                            b.fetch_add(1, Ordering::SeqCst);
                            s.put(Shot {
                                index,
                                captured_s: clock.now_s(),
                                image: Err(why),
                            });
                            index += 1;
                        }
                        Err(GrabError::Fatal(msg)) => {
                            end(msg);
                            break;
                        }
                        Err(GrabError::Lost(_)) => {
                            grabber.close();
                            open = false;
                            std::thread::sleep(retry);
                        }
                    }
                }
                grabber.close();
            })
            .ok();
        CaptureSource {
            slot,
            fatal,
            quit,
            bad,
            thread,
            stall_after,
            label,
            t0: None,
            stalled_at: 0,
        }
    }

    /// Why the source ended, if the camera cannot be used at all.
    pub fn fatal_reason(&self) -> Option<String> {
        self.fatal.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// Frames the camera delivered that the loop never saw.
    pub fn dropped(&self) -> u64 {
        self.slot.dropped()
    }

    /// Unusable frames the device delivered ([`GrabError::Bad`]), whether the loop saw them
    /// or a newer frame replaced them first.
    pub fn bad_frames(&self) -> u64 {
        self.bad.load(Ordering::SeqCst)
    }

    /// Waits until the device has delivered its first frame (good or bad): `Ok`; or the
    /// source ended first (`Err` with [`CaptureSource::fatal_reason`]), or `timeout` passed
    /// or `give_up()` said so (`Err(None)`). The frame stays for the loop.
    pub fn wait_first(&self, timeout: Duration, give_up: impl Fn() -> bool) -> Result<(), Option<String>> {
        let t0 = std::time::Instant::now();
        loop {
            if self.slot.version() > 0 {
                return Ok(());
            }
            if self.slot.is_closed() {
                return Err(self.fatal_reason());
            }
            if t0.elapsed() >= timeout || give_up() {
                return Err(None);
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

impl FrameSource for CaptureSource {
    fn fatal(&self) -> Option<String> {
        self.fatal_reason()
    }

    fn next_frame(&mut self) -> Option<Result<Frame, FrameError>> {
        match self.slot.wait_take(self.stall_after) {
            Some(shot) => {
                let t0 = *self.t0.get_or_insert(shot.captured_s);
                let name = format!("camera_{:06}", shot.index);
                let image = match shot.image {
                    Ok(image) => image,
                    Err(why) => return Some(Err(FrameError::bad(shot.index, name, why))),
                };
                let mut f = Frame::new(shot.index, shot.captured_s - t0, name, image);
                f.captured_s = Some(shot.captured_s);
                Some(Ok(f))
            }
            None if self.slot.is_closed() => None,
            None => {
                self.stalled_at += 1;
                Some(Err(FrameError::stalled(
                    self.stalled_at,
                    self.label.clone(),
                    format!("no frame for {} ms (stalled or unplugged)", self.stall_after.as_millis()),
                )))
            }
        }
    }
}

impl Drop for CaptureSource {
    fn drop(&mut self) {
        self.quit.store(true, Ordering::SeqCst);
        // The thread may be blocked in a grab; don't wait for a dead camera.
        if let Some(t) = self.thread.take() {
            if t.is_finished() {
                let _ = t.join();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicU64;
    use std::time::Instant;

    struct TestClock(Instant);
    impl Clock for TestClock {
        fn now_s(&self) -> f64 {
            self.0.elapsed().as_secs_f64()
        }
    }

    /// 100 fps frames; between `stall.0` and `stall.1` seconds after start it delivers nothing
    /// (and fails, as an unplugged V4L2 device does).
    struct Script {
        t0: Instant,
        stall: (f64, f64),
        size: (u32, u32),
        opens: Arc<AtomicU64>,
    }
    impl Grabber for Script {
        fn open(&mut self) -> Result<(), GrabError> {
            let t = self.t0.elapsed().as_secs_f64();
            if t >= self.stall.0 && t < self.stall.1 {
                return Err(GrabError::Lost("no such device".into()));
            }
            self.opens.fetch_add(1, Ordering::SeqCst);
            Ok(())
        }
        fn grab(&mut self) -> Result<RgbImage, GrabError> {
            std::thread::sleep(Duration::from_millis(10));
            let t = self.t0.elapsed().as_secs_f64();
            if t >= self.stall.0 && t < self.stall.1 {
                return Err(GrabError::Lost("unplugged".into()));
            }
            Ok(RgbImage::new(self.size.0, self.size.1))
        }
        fn label(&self) -> String {
            "script".into()
        }
    }

    #[test]
    fn a_stall_is_reported_within_its_time_and_frames_come_back() {
        let opens = Arc::new(AtomicU64::new(0));
        let t0 = Instant::now();
        let o = opens.clone();
        let mut src = CaptureSource::start(
            move || {
                Box::new(Script {
                    t0,
                    stall: (0.3, 1.3),
                    size: (32, 24),
                    opens: o,
                })
            },
            "script".into(),
            (32, 24),
            Arc::new(TestClock(t0)),
            Duration::from_millis(500),
            Duration::from_millis(50),
        );
        let mut last_frame_at = 0.0;
        let mut stall_seen_after = None;
        let mut frames_after = 0;
        while t0.elapsed().as_secs_f64() < 2.0 {
            match src.next_frame() {
                Some(Ok(_)) => {
                    last_frame_at = t0.elapsed().as_secs_f64();
                    if stall_seen_after.is_some() {
                        frames_after += 1;
                    }
                }
                Some(Err(e)) => {
                    assert!(e.stalled, "{e}");
                    stall_seen_after.get_or_insert(t0.elapsed().as_secs_f64() - last_frame_at);
                }
                None => panic!("ended"),
            }
        }
        let gap = stall_seen_after.expect("a stall was reported");
        println!("stall reported {:.0} ms after the last frame", gap * 1e3);
        assert!(gap <= 0.5 + 0.1, "stall reported after {gap} s");
        assert!(frames_after > 10, "frames came back: {frames_after}");
        assert!(opens.load(Ordering::SeqCst) >= 2, "the device was reopened");
    }

    #[test]
    fn the_wrong_size_ends_the_source_with_a_clear_error() {
        let t0 = Instant::now();
        let mut src = CaptureSource::start(
            move || {
                Box::new(Script {
                    t0,
                    stall: (9.0, 9.0),
                    size: (640, 480),
                    opens: Arc::new(AtomicU64::new(0)),
                })
            },
            "script".into(),
            (320, 240),
            Arc::new(TestClock(t0)),
            Duration::from_millis(500),
            Duration::from_millis(50),
        );
        assert!(src.next_frame().is_none());
        let e = src.fatal_reason().expect("fatal error");
        assert!(e.contains("640×480") && e.contains("320×240"), "{e}");
    }
}
