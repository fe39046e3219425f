//! Multi-scale sliding-window detection with a boosted cascade, with the semantics of OpenCV
//! 4's `cv::CascadeClassifier::detectMultiScale` (cascadedetect.cpp), so that the same
//! cascade on the same grey image gives the same boxes.
//!
//! 1. **Scales.** `factor = 1, f, f², …` (f64) while the rounded window `round(W·factor)` ×
//!    `round(H·factor)` fits the image; scales whose window is below `min_size` are skipped,
//!    and the list stops at the first window above `max_size`. If `min_size == max_size` and
//!    no scale matched, the scale whose window is closest to it is used (OpenCV ≥ 3.4). Scales
//!    are then stored as f32, as OpenCV does.
//! 2. **Pyramid, not scaled features.** Each scale resizes the image to
//!    `round(w/scale)` × `round(h/scale)` with OpenCV's bit-exact bilinear resize and runs the
//!    cascade's unscaled features on it. This is what OpenCV does; it is the only way to get
//!    the same box set (scaled features round rectangle corners differently), and it is also
//!    the fast way: feature offsets are integers fixed once per image size.
//! 3. **Integral images** of each level (sum, squared sum, tilted if needed), with one row
//!    stride for all levels so the compiled feature offsets are shared.
//! 4. **Scan.** Step `1` if `scale ≥ 2`, else `2`, in x and y; a window whose first stage
//!    fails makes the scan skip the next x position too (OpenCV's `if (result == 0) x += step`).
//! 5. **Window normalisation** over the inner rectangle `(1, 1, W−2, H−2)`:
//!    `nf = √(area·Σi² − (Σi)²)` in f64, `k = (f32)(1/nf)`; the window is rejected if
//!    `nf ≤ 0` or `area·k ≥ 0.1` (a flat patch). A Haar feature's value is
//!    `(w0·s0 + w1·s1 [+ w2·s2])·k` in f32; stage sums accumulate the f32 leaves in f64.
//! 6. **Early exit**: the first stage whose sum is below its threshold rejects the window.
//! 7. **Boxes**: `(round(x·scale), round(y·scale), round(W·scale), round(H·scale))`, grouped
//!    by [`group_rectangles`] with `eps = 0.2` and clipped to the image.
//!
//! Units: pixels of the input image; `scale_factor` is the ratio between pyramid levels.
//!
//! [`super::scan`] holds steps 1 and 4–7 for one cascade on one level, [`super::pyramid`]
//! steps 2–3 for any number of cascades; a [`Detector`] is one cascade with a pyramid of its own.

use super::cascade::Cascade;
use super::group::Rect;
use super::pyramid::Pyramid;
use super::scan::Scanner;
pub use super::scan::{DetectError, DetectParams, Detection, GROUP_EPS};
use image::GrayImage;

/// A cascade ready to run on frames; keeps its buffers between calls, so steady-state
/// detection allocates little.
#[derive(Debug, Clone)]
pub struct Detector {
    scanner: Scanner,
    /// Pyramid buffers for [`Detector::detect`] (a [`super::DetectStage`] shares one pyramid
    /// between its cascades instead).
    own: Box<Pyramid>,
}

impl Detector {
    /// A detector for a loaded cascade.
    pub fn new(cascade: Cascade) -> Self {
        Self {
            scanner: Scanner::new(cascade),
            own: Box::default(),
        }
    }

    /// The cascade this detector runs.
    pub fn cascade(&self) -> &Cascade {
        self.scanner.cascade()
    }

    /// Detects objects in a grey image (OpenCV's `detectMultiScale` with `numDetections`).
    pub fn detect(&mut self, img: &GrayImage, params: &DetectParams) -> Result<Vec<Detection>, DetectError> {
        let (w, h) = img.dimensions();
        self.detect_gray(img.as_raw(), w as usize, h as usize, params)
    }

    /// Same as [`Detector::detect`] on a row-major `width` × `height` byte buffer.
    pub fn detect_gray(
        &mut self,
        img: &[u8],
        width: usize,
        height: usize,
        params: &DetectParams,
    ) -> Result<Vec<Detection>, DetectError> {
        self.detect_raw(img, width, height, params)?;
        Ok(self.scanner.grouped(width, height, params.min_neighbors))
    }

    /// The raw (ungrouped) window hits of the last call, in input-image pixels.
    pub fn raw_hits(&self) -> &[Rect] {
        self.scanner.raw_hits()
    }

    /// Runs steps 1–6 and leaves the raw hits in [`Detector::raw_hits`].
    pub fn detect_raw(
        &mut self,
        img: &[u8],
        width: usize,
        height: usize,
        params: &DetectParams,
    ) -> Result<(), DetectError> {
        self.own.run(
            img,
            width,
            height,
            std::slice::from_mut(&mut self.scanner),
            &[*params],
            &[None],
            params.parallel,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_scale_factor_is_an_error() {
        let c = Cascade::from_xml_str(
            r#"<opencv_storage><cascade><stageType>BOOST</stageType><featureType>HAAR</featureType>
            <height>4</height><width>4</width><featureParams><maxCatCount>0</maxCatCount></featureParams>
            <stages><_><stageThreshold>0</stageThreshold><weakClassifiers><_><internalNodes>0 -1 0 0</internalNodes>
            <leafValues>1 1</leafValues></_></weakClassifiers></_></stages>
            <features><_><rects><_>0 0 4 4 1.</_></rects></_></features></cascade></opencv_storage>"#,
            "t",
        )
        .unwrap();
        let mut d = Detector::new(c);
        let img = GrayImage::new(10, 10);
        let p = DetectParams {
            scale_factor: 1.0,
            ..Default::default()
        };
        assert_eq!(d.detect(&img, &p), Err(DetectError::BadScaleFactor(1.0)));
        // A flat image has zero variance everywhere: no window passes.
        assert_eq!(d.detect(&img, &DetectParams::default()), Ok(vec![]));
        // An image smaller than the window: nothing, no error.
        assert_eq!(d.detect(&GrayImage::new(3, 3), &DetectParams::default()), Ok(vec![]));
        assert_eq!(d.detect(&GrayImage::new(0, 0), &DetectParams::default()), Ok(vec![]));
    }
}
