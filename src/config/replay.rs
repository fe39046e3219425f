//! `[replay]`: running the pipeline over a folder of recorded frames (`rccar replay`).

use serde::{Deserialize, Serialize};

/// `[replay]`: running the pipeline over a folder of images.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ReplayConfig {
    /// Write an annotated PNG for every frame.
    pub annotate: bool,
}

impl Default for ReplayConfig {
    fn default() -> Self {
        Self { annotate: true }
    }
}
