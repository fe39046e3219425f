//! A route: the user's choice at each fork of the road, one step per fork reached, in driving
//! order (Rivera & Andaluz 2021, Sec. 6: "travel the route defined by the user").
//!
//! A route is written as words — `route = ["left", "straight", "right"]` in a track file or
//! `[route] steps` in `car.toml`, or `--route left,straight,right` — and read here, below both
//! the simulator (which predicts the path a route gives on a track's map) and the pipeline
//! (which has no map: at a fork it follows the lane line on the side of the chosen branch,
//! `lane::junction`). Depends on nothing in the crate.

use serde::{Deserialize, Serialize};

/// One step of a route: which way to go at a fork.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Step {
    /// The branch that bends left (at a Y fork, the left one of the two).
    Left,
    /// The branch that keeps on (the one whose line does not bend away).
    Straight,
    /// The branch that bends right.
    Right,
}

impl Step {
    /// Every step, in the order the words are listed in messages.
    pub const ALL: [Step; 3] = [Step::Left, Step::Straight, Step::Right];

    /// The word used in files, flags and telemetry.
    pub fn name(self) -> &'static str {
        match self {
            Step::Left => "left",
            Step::Straight => "straight",
            Step::Right => "right",
        }
    }

    /// Reads one word (`left`, `straight`, `right`; also `l`, `s`, `r`), any case.
    pub fn parse(word: &str) -> Option<Step> {
        match word.trim().to_ascii_lowercase().as_str() {
            "left" | "l" => Some(Step::Left),
            "straight" | "s" | "ahead" => Some(Step::Straight),
            "right" | "r" => Some(Step::Right),
            _ => None,
        }
    }
}

impl std::fmt::Display for Step {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Why a branch was taken at a fork (telemetry, the sim's report).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Why {
    /// The route's next step.
    Route,
    /// A turn sign standing before the fork (it overrides the route).
    Sign,
    /// No step left in the route, no sign: keep on (the line that does not bend away).
    Default,
}

impl Why {
    /// The word used in telemetry.
    pub fn name(self) -> &'static str {
        match self {
            Why::Route => "route",
            Why::Sign => "sign",
            Why::Default => "default",
        }
    }
}

/// Most steps a route may have (a flag or a file a user writes).
pub const MAX_STEPS: usize = 1000;

/// Reads a comma-separated route (`left,straight,right`; spaces allowed; empty = no steps).
/// The error names the word and its position (from 1).
pub fn parse_list(text: &str) -> Result<Vec<Step>, String> {
    let text = text.trim();
    if text.is_empty() {
        return Ok(Vec::new());
    }
    let words: Vec<&str> = text.split(',').collect();
    if words.len() > MAX_STEPS {
        return Err(format!("{} steps: a route may have at most {MAX_STEPS}", words.len()));
    }
    words
        .iter()
        .enumerate()
        .map(|(i, w)| {
            Step::parse(w).ok_or_else(|| {
                format!(
                    "step {} is `{}`: each step is left, straight or right",
                    i + 1,
                    w.trim()
                )
            })
        })
        .collect()
}

/// The steps as one comma-separated string (what `--route` takes).
pub fn to_list(steps: &[Step]) -> String {
    steps.iter().map(|s| s.name()).collect::<Vec<_>>().join(",")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_words_and_names_the_bad_one() {
        assert_eq!(
            parse_list(" left, S ,Right").unwrap(),
            vec![Step::Left, Step::Straight, Step::Right]
        );
        assert!(parse_list("").unwrap().is_empty());
        let e = parse_list("left,up").unwrap_err();
        assert!(e.contains("step 2") && e.contains("`up`"), "{e}");
        assert_eq!(to_list(&[Step::Left, Step::Right]), "left,right");
        let long = vec!["l"; MAX_STEPS + 1].join(",");
        assert!(parse_list(&long).is_err());
    }
}
