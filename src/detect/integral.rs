//! Integral images for Haar and LBP features, as OpenCV's `cv::integral(src, sum, sqsum,
//! tilted)` computes them (Viola & Jones 2001, Sec. 2.1; the rotated sum of Lienhart & Maydt
//! 2002, Eq. 3).
//!
//! For a `w` × `h` grey image `I`, all three tables are `(w + 1)` × `(h + 1)`:
//!
//! * `sum(X, Y)   = Σ_{x < X, y < Y} I(x, y)` (i32: fits for images up to 8 Mpx),
//! * `sqsum(X, Y) = Σ_{x < X, y < Y} I(x, y)²` (u64: a white 320×240 image overflows u32),
//! * `tilted(X, Y) = Σ_{y < Y, |x − X + 1| ≤ Y − 1 − y} I(x, y)`: the 45° triangle whose apex
//!   is pixel (X − 1, Y − 1), cut by the image's borders (i32).
//!
//! The tilted table follows Lienhart's recurrence
//! `T(X, Y) = T(X−1, Y−1) + T(X+1, Y−1) − T(X, Y−2) + I(X−1, Y−1) + I(X−1, Y−2)`; the two
//! triangles that stick out of the table on the left and right are the same sums as
//! `T(0, Y−2)` and `T(w, Y−2)` (a triangle cut by a border equals the shifted, cut one).
//!
//! Rows are stored with a caller-chosen `stride` ≥ w + 1, so the detector can keep one set of
//! feature offsets for every pyramid level. `sum` and `tilted` share one buffer
//! (`tilted` starts at [`Integrals::tilted_offset`]), so a feature's corners, upright or
//! tilted, are offsets from one base pointer, as in OpenCV's `sbuf`.

/// Sum, squared-sum and (optionally) tilted integral images of one grey image.
#[derive(Debug, Clone, Default)]
pub struct Integrals {
    /// Image width in pixels (the tables have `width + 1` used columns).
    pub width: usize,
    /// Image height in pixels (the tables have `height + 1` rows).
    pub height: usize,
    /// Elements per table row.
    pub stride: usize,
    /// `sum` at `[0, rows*stride)`, then `tilted` at `[tilted_offset, ...)` if computed.
    pub data: Vec<i32>,
    /// Where the tilted table starts in `data` (0 when it was not computed).
    pub tilted_offset: usize,
    /// Squared sums, same layout as `sum`.
    pub sqsum: Vec<u64>,
}

impl Integrals {
    /// An empty set; buffers grow on first use and are reused afterwards.
    pub fn new() -> Self {
        Self::default()
    }

    /// Computes the tables of the row-major `width` × `height` image `img` (stride `width`).
    /// `stride` is raised to at least `width + 1`. `rows_capacity` ≥ `height + 1` fixes where
    /// the tilted table starts, so offsets stay valid across images of different heights.
    pub fn compute(
        &mut self,
        img: &[u8],
        width: usize,
        height: usize,
        stride: usize,
        rows_capacity: usize,
        tilted: bool,
    ) {
        self.compute_strided(img, width, width, height, stride, rows_capacity, tilted);
    }

    /// Same as [`Integrals::compute`] for an image whose rows are `img_stride` ≥ `width` bytes
    /// apart (a crop of a wider image: the first `width` columns of each row are used).
    ///
    /// The tables of a crop give the same rectangle sums as the whole image's for every
    /// rectangle inside the crop, upright or tilted: a sum is a signed combination of corner
    /// values in which every pixel outside the rectangle cancels, so which pixels beyond the
    /// crop the corners would have included does not matter.
    #[allow(clippy::too_many_arguments)]
    pub fn compute_strided(
        &mut self,
        img: &[u8],
        img_stride: usize,
        width: usize,
        height: usize,
        stride: usize,
        rows_capacity: usize,
        tilted: bool,
    ) {
        assert!(img_stride >= width, "image stride below its width");
        assert!(
            height == 0 || img.len() >= img_stride * (height - 1) + width,
            "image buffer smaller than its rows"
        );
        let stride = stride.max(width + 1);
        let rows = rows_capacity.max(height + 1);
        self.width = width;
        self.height = height;
        self.stride = stride;
        self.tilted_offset = if tilted { rows * stride } else { 0 };
        let need = if tilted { 2 * rows * stride } else { rows * stride };
        if self.data.len() < need {
            self.data.resize(need, 0);
        }
        if self.sqsum.len() < rows * stride {
            self.sqsum.resize(rows * stride, 0);
        }
        // 1. Row 0 is zero; each further row adds the running row sum to the row above.
        self.data[..width + 1].fill(0);
        self.sqsum[..width + 1].fill(0);
        for y in 0..height {
            let src = &img[y * img_stride..y * img_stride + width];
            let (above, below) = self.data.split_at_mut((y + 1) * stride);
            let prev = &above[y * stride..y * stride + width + 1];
            let cur = &mut below[..width + 1];
            let (qa, qb) = self.sqsum.split_at_mut((y + 1) * stride);
            let qprev = &qa[y * stride..y * stride + width + 1];
            let qcur = &mut qb[..width + 1];
            cur[0] = 0;
            qcur[0] = 0;
            let mut s = 0i32;
            let mut q = 0u64;
            for x in 0..width {
                let v = src[x] as i32;
                s += v;
                q += (v * v) as u64;
                cur[x + 1] = prev[x + 1] + s;
                qcur[x + 1] = qprev[x + 1] + q;
            }
        }
        if tilted {
            self.compute_tilted(img, img_stride);
        }
    }

    /// 2. The tilted table, row by row with Lienhart's recurrence (see the module header).
    fn compute_tilted(&mut self, img: &[u8], img_stride: usize) {
        let (w, h, stride) = (self.width, self.height, self.stride);
        let t = &mut self.data[self.tilted_offset..];
        let pix = |x: usize, y: usize| img[y * img_stride + x] as i32;
        t[..w + 1].fill(0);
        if h == 0 {
            return;
        }
        // Row 1: the apex pixel only.
        t[stride] = 0;
        for x in 1..=w {
            t[stride + x] = pix(x - 1, 0);
        }
        for yy in 2..=h {
            let r = yy * stride;
            let r1 = (yy - 1) * stride;
            let r2 = (yy - 2) * stride;
            for x in 0..=w {
                let left = if x >= 1 { t[r1 + x - 1] } else { t[r2] };
                let right = if x < w { t[r1 + x + 1] } else { t[r2 + w] };
                let apex = if x >= 1 {
                    pix(x - 1, yy - 1) + pix(x - 1, yy - 2)
                } else {
                    0
                };
                // Wrapping: `left + right` can exceed i32 on huge images; the result fits.
                t[r + x] = left.wrapping_add(right).wrapping_sub(t[r2 + x]).wrapping_add(apex);
            }
        }
    }

    /// `sum(X, Y)`.
    pub fn sum_at(&self, x: usize, y: usize) -> i32 {
        self.data[y * self.stride + x]
    }

    /// `tilted(X, Y)` (only when computed with `tilted = true`).
    pub fn tilted_at(&self, x: usize, y: usize) -> i32 {
        self.data[self.tilted_offset + y * self.stride + x]
    }

    /// `sqsum(X, Y)`.
    pub fn sqsum_at(&self, x: usize, y: usize) -> u64 {
        self.sqsum[y * self.stride + x]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(w: usize, h: usize, seed: u32) -> Vec<u8> {
        let mut s = seed;
        (0..w * h)
            .map(|_| {
                s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                (s >> 24) as u8
            })
            .collect()
    }

    #[test]
    fn tables_match_their_definitions() {
        for (w, h) in [(1, 1), (5, 5), (7, 3), (3, 9), (13, 11)] {
            let img = image(w, h, (w * 31 + h) as u32);
            let mut ii = Integrals::new();
            ii.compute(&img, w, h, w + 4, h + 2, true);
            for yy in 0..=h {
                for xx in 0..=w {
                    let (mut s, mut q, mut t) = (0i64, 0u64, 0i64);
                    for y in 0..h {
                        for x in 0..w {
                            let v = img[y * w + x] as i64;
                            if x < xx && y < yy {
                                s += v;
                                q += (v * v) as u64;
                            }
                            if y < yy && (x as i64 - xx as i64 + 1).abs() <= yy as i64 - 1 - y as i64 {
                                t += v;
                            }
                        }
                    }
                    assert_eq!(ii.sum_at(xx, yy) as i64, s, "sum {w}x{h} at {xx},{yy}");
                    assert_eq!(ii.sqsum_at(xx, yy), q, "sqsum {w}x{h} at {xx},{yy}");
                    assert_eq!(ii.tilted_at(xx, yy) as i64, t, "tilted {w}x{h} at {xx},{yy}");
                }
            }
        }
    }

    #[test]
    fn a_crop_gives_the_same_rectangle_sums() {
        // Upright and tilted rectangle sums inside a crop equal the whole image's.
        let (w, h) = (23, 19);
        let img = image(w, h, 7);
        let mut full = Integrals::new();
        full.compute(&img, w, h, w + 1, h + 1, true);
        let (cx, cy, cw, ch) = (0, 5, 17, 11); // crops start at column 0 (as the pyramid's do)
        let mut crop = Integrals::new();
        crop.compute_strided(&img[cy * w + cx..], w, cw, ch, w + 1, h + 1, true);
        for y in 0..ch {
            for x in 0..cw {
                for (rw, rh) in [(1, 1), (3, 2), (cw - x, ch - y)] {
                    if x + rw > cw || y + rh > ch {
                        continue;
                    }
                    let s = |t: &Integrals, ox: usize, oy: usize| {
                        t.sum_at(ox + x + rw, oy + y + rh) - t.sum_at(ox + x, oy + y + rh) - t.sum_at(ox + x + rw, oy + y)
                            + t.sum_at(ox + x, oy + y)
                    };
                    assert_eq!(s(&crop, 0, 0), s(&full, cx, cy));
                }
                // A tilted square of side 2 with its top corner at (x, y): OpenCV's corners.
                let (rw, rh) = (2usize, 2usize);
                if x >= rh && x + rw <= cw && y + rw + rh <= ch {
                    let t = |ii: &Integrals, ox: usize, oy: usize| {
                        let (x, y) = (ox + x, oy + y);
                        ii.tilted_at(x, y) - ii.tilted_at(x - rh, y + rh) - ii.tilted_at(x + rw, y + rw)
                            + ii.tilted_at(x + rw - rh, y + rw + rh)
                    };
                    assert_eq!(t(&crop, 0, 0), t(&full, cx, cy), "tilted at {x},{y}");
                }
            }
        }
    }

    #[test]
    fn white_image_squares_need_u64() {
        let img = vec![255u8; 320 * 240];
        let mut ii = Integrals::new();
        ii.compute(&img, 320, 240, 0, 0, false);
        assert_eq!(ii.sqsum_at(320, 240), 320 * 240 * 255 * 255);
        assert!(ii.sqsum_at(320, 240) > u32::MAX as u64);
    }

    #[test]
    fn the_largest_allowed_white_image_does_not_overflow() {
        // 8 Mpx of 255 is the detector's limit: the sum is just below i32::MAX.
        let (w, h) = (4096, 2048);
        let img = vec![255u8; w * h];
        let mut ii = Integrals::new();
        ii.compute(&img, w, h, 0, 0, true);
        assert_eq!(ii.sum_at(w, h) as i64, 255 * (w * h) as i64);
        // The tilted triangle with apex at the bottom centre covers h rows of widths 1, 3, 5, …
        let full: i64 = (0..h as i64).map(|r| 2 * r + 1).sum::<i64>() * 255;
        assert_eq!(ii.tilted_at(w / 2, h) as i64, full);
    }
}
