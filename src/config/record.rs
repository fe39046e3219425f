//! `[record]`: recording frames and telemetry on the car: JPEG quality (1..=100), the disk
//! budget (megabytes) and the segment length (frames).

use super::check::Checker;
use serde::{Deserialize, Serialize};

/// `[record]`: recording frames and telemetry on the car (src/record.rs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RecordConfig {
    /// JPEG quality of recorded frames, 1..=100.
    pub jpeg_quality: u8,
    /// Disk budget of one recording, megabytes (10^6 bytes); the oldest frames go first.
    pub max_mb: f64,
    /// Frames per segment folder (the unit that is deleted when over budget).
    pub segment_frames: u32,
}

impl Default for RecordConfig {
    fn default() -> Self {
        Self {
            jpeg_quality: 90,
            max_mb: 2000.0,
            segment_frames: 300,
        }
    }
}

impl RecordConfig {
    /// The recorder's options.
    pub fn options(&self) -> crate::record::RecordOptions {
        crate::record::RecordOptions {
            jpeg_quality: self.jpeg_quality,
            max_bytes: (self.max_mb * 1e6).round() as u64,
            segment_frames: self.segment_frames,
        }
    }
}

impl RecordConfig {
    /// Range checks of `[record]`.
    pub(super) fn check(&self, c: &mut Checker) {
        let r = self;
        c.range("record.jpeg_quality", r.jpeg_quality, 1, 100);
        c.range("record.max_mb", r.max_mb, 1.0, 1_000_000.0);
        c.range("record.segment_frames", r.segment_frames, 1, 100_000);
    }
}
