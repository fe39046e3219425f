//! A bounded hand-over slot that holds only the newest value.
//!
//! A producer that must never wait (the control loop publishing to a dashboard, a camera's
//! capture thread handing frames to the loop) `put`s; the consumer `take`s or waits for the
//! newest. A value that was replaced before anyone took it is counted as dropped: late frames
//! are never queued, so a slow reader can never add latency to the writer.

use std::sync::{Condvar, Mutex, MutexGuard};
use std::time::Duration;

/// The newest value, with a count of the values replaced unread.
#[derive(Debug, Default)]
pub struct Latest<T> {
    inner: Mutex<Inner<T>>,
    cv: Condvar,
}

#[derive(Debug)]
struct Inner<T> {
    value: Option<T>,
    /// Incremented on every put: readers that keep a copy can tell whether it is new.
    version: u64,
    dropped: u64,
    closed: bool,
}

impl<T> Default for Inner<T> {
    fn default() -> Self {
        Self {
            value: None,
            version: 0,
            dropped: 0,
            closed: false,
        }
    }
}

impl<T> Latest<T> {
    /// An empty slot.
    pub fn new() -> Self {
        Self {
            inner: Mutex::new(Inner::default()),
            cv: Condvar::new(),
        }
    }

    fn lock(&self) -> MutexGuard<'_, Inner<T>> {
        // A panic elsewhere must not stop the car from reading its last frame or stopping.
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Replaces the value (never blocks beyond the short lock). Returns the new version.
    pub fn put(&self, v: T) -> u64 {
        let mut g = self.lock();
        if g.value.is_some() {
            g.dropped += 1;
        }
        g.value = Some(v);
        g.version += 1;
        let ver = g.version;
        drop(g);
        self.cv.notify_all();
        ver
    }

    /// Takes the value if there is one.
    pub fn take(&self) -> Option<T> {
        self.lock().value.take()
    }

    /// Waits up to `timeout` for a value and takes it. `None` on timeout or when closed.
    pub fn wait_take(&self, timeout: Duration) -> Option<T> {
        let mut g = self.lock();
        let deadline = std::time::Instant::now() + timeout;
        loop {
            if let Some(v) = g.value.take() {
                return Some(v);
            }
            if g.closed {
                return None;
            }
            let now = std::time::Instant::now();
            if now >= deadline {
                return None;
            }
            g = self.cv.wait_timeout(g, deadline - now).unwrap_or_else(|e| e.into_inner()).0;
        }
    }

    /// Values replaced before anyone took them.
    pub fn dropped(&self) -> u64 {
        self.lock().dropped
    }

    /// How many values were ever put.
    pub fn version(&self) -> u64 {
        self.lock().version
    }

    /// Marks the producer gone: waiting readers return.
    pub fn close(&self) {
        self.lock().closed = true;
        self.cv.notify_all();
    }

    /// Whether [`Latest::close`] was called.
    pub fn is_closed(&self) -> bool {
        self.lock().closed
    }
}

impl<T: Clone> Latest<T> {
    /// A copy of the newest value and its version, leaving it in place (many readers).
    pub fn peek(&self) -> Option<(T, u64)> {
        let g = self.lock();
        g.value.clone().map(|v| (v, g.version))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    #[test]
    fn keeps_only_the_newest_and_counts_drops() {
        let s = Latest::new();
        s.put(1);
        s.put(2);
        s.put(3);
        assert_eq!(s.take(), Some(3));
        assert_eq!(s.dropped(), 2);
        assert_eq!(s.take(), None);
        assert_eq!(s.version(), 3);
    }

    #[test]
    fn wait_take_wakes_on_put_and_times_out() {
        let s = Arc::new(Latest::new());
        let p = s.clone();
        let t = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(20));
            p.put(7u32);
        });
        assert_eq!(s.wait_take(Duration::from_secs(5)), Some(7));
        t.join().unwrap();
        assert_eq!(s.wait_take(Duration::from_millis(10)), None);
    }
}
