//! `[route]`: the way to take at each fork, and the junction rule's tunables (src/route.rs,
//! src/lane/junction.rs, docs/junctions.md). Units: lane widths, frames.

use super::check::Checker;
use crate::lane::junction::JunctionOptions;
use crate::route::Step;
use serde::{Deserialize, Serialize};

/// `[route]`: junctions and the user's route.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RouteConfig {
    /// The junction rule: at a fork keep the line of the chosen way, at a merge the steady
    /// line. `auto`: on when there is a route (`steps`, `--route`) or, in the simulator, the
    /// track has junctions; `on`; `off` (the lane method as in the paper).
    pub junctions: Junctions,
    /// The way at each fork reached, in order (`left`, `straight`, `right`); after the last,
    /// `straight`.
    pub steps: Vec<Step>,
    /// Lines further apart than this many lane widths mean a junction (1.05..2).
    pub fork_width: f64,
    /// A line that moved by more than this many lane widths in one frame jumped: a merge
    /// (0.1..1).
    pub jump: f64,
    /// The odd line leaning out (a fork) or in (a merge) by more than this many lane widths
    /// over the band decides which (0.005..0.5).
    pub lean: f64,
    /// Frames with the lines a lane apart again before the junction is over (1..100).
    pub settle_frames: u32,
    /// Most frames a junction lasts (10..3000).
    pub max_frames: u32,
    /// A turn sign decides a fork met at most this far past the sign, metres (0.5..20).
    pub sign_reach_m: f64,
    /// Lines parting again within this distance after a junction ended are the same junction:
    /// its line is kept again, no step used, metres (0..10; 0 = off).
    pub rejoin_m: f64,
}

impl Default for RouteConfig {
    fn default() -> Self {
        let o = JunctionOptions::default();
        Self {
            junctions: Junctions::Auto,
            steps: Vec::new(),
            fork_width: o.fork_width,
            jump: o.jump,
            lean: o.lean,
            settle_frames: o.settle_frames,
            max_frames: o.max_frames,
            sign_reach_m: o.sign_reach_m,
            rejoin_m: o.rejoin_m,
        }
    }
}

/// `route.junctions`: when the junction rule runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Junctions {
    /// On when there is a route, or the simulator's track has junctions.
    Auto,
    /// Always.
    On,
    /// Never: Eq. 3 on the two peaks, as in the paper.
    Off,
}

impl RouteConfig {
    /// Whether the pipeline runs the junction rule (`auto`: when there is a route).
    pub fn rule_on(&self) -> bool {
        match self.junctions {
            Junctions::On => true,
            Junctions::Off => false,
            Junctions::Auto => !self.steps.is_empty(),
        }
    }

    /// Checks of `[route]`: the ranges.
    pub(super) fn check(&self, c: &mut Checker) {
        c.range("route.fork_width", self.fork_width, 1.05, 2.0);
        c.range("route.jump", self.jump, 0.1, 1.0);
        c.range("route.lean", self.lean, 0.005, 0.5);
        c.range("route.settle_frames", self.settle_frames, 1, 100);
        c.range("route.max_frames", self.max_frames, 10, 3000);
        c.range("route.sign_reach_m", self.sign_reach_m, 0.5, 20.0);
        c.range("route.rejoin_m", self.rejoin_m, 0.0, 10.0);
        if self.steps.len() > crate::route::MAX_STEPS {
            c.range("route.steps (count)", self.steps.len(), 0, crate::route::MAX_STEPS);
        }
    }

    /// The junction rule's options.
    pub fn options(&self) -> JunctionOptions {
        JunctionOptions {
            fork_width: self.fork_width,
            jump: self.jump,
            lean: self.lean,
            settle_frames: self.settle_frames,
            max_frames: self.max_frames,
            sign_reach_m: self.sign_reach_m,
            rejoin_m: self.rejoin_m,
        }
    }
}
