//! Lane detection after Rivera & Andaluz (2021), Sec. 3.2: ROI and bird's-eye warp
//! ([`warp`]), grey threshold and Canny edges ([`edges`], [`threshold`]), column histogram
//! and the two lines ([`lines`]).

pub mod warp;
