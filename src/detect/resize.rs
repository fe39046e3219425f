//! Bilinear down-scaling of a grey image, bit for bit as OpenCV 4's `cv::resize(...,
//! INTER_LINEAR_EXACT)` does it for 8-bit images (`resize_bitExact` with
//! `interpolationLinear<uchar>`). The detector's image pyramid is built with it, and the
//! boxes only match OpenCV's when every pyramid pixel does.
//!
//! 1. Coordinates: destination pixel `d` samples the source at `f = s·(d + ½) − ½` with
//!    `s = 1 / (dst/src)` (all in f64, as OpenCV's `softdouble`); `i = ⌊f⌋`, and the weight of
//!    pixel `i + 1` is `round_half_even((f − i)·256)` (8 fractional bits), pixel `i` gets the
//!    rest of 256. Samples left of pixel 0 copy pixel 0; samples at or right of the last pixel
//!    copy the last pixel.
//! 2. Rows: each source row is interpolated horizontally into 8.8 fixed point (u16).
//! 3. Columns: two such rows are blended with 8-bit weights into 16.16 fixed point and
//!    rounded: `(a·r0 + b·r1 + 2^15) >> 16`.
//!
//! Units: pixels; weights in 1/256.

/// Per-axis sampling table: first source index and weight of the second pixel (of 256).
#[derive(Debug, Clone, Default)]
struct Axis {
    offset: Vec<u32>,
    weight: Vec<u16>,
    /// First destination index that interpolates (earlier ones copy source 0).
    min: usize,
    /// First destination index that copies the last source pixel.
    max: usize,
}

impl Axis {
    fn build(&mut self, src: usize, dst: usize) {
        self.offset.clear();
        self.weight.clear();
        self.min = 0;
        self.max = dst;
        let inv_scale = dst as f64 / src as f64;
        let scale = 1.0 / inv_scale;
        for d in 0..dst {
            let f = scale * (d as f64 + 0.5) - 0.5;
            let i = f.floor();
            if i >= 0.0 && src > 1 {
                if (i as usize) < src - 1 {
                    let w = ((f - i) * 256.0).round_ties_even() as u16;
                    self.offset.push(i as u32);
                    self.weight.push(w);
                } else {
                    self.offset.push(src as u32 - 1);
                    self.weight.push(0);
                    self.max = self.max.min(d);
                }
            } else {
                self.offset.push(0);
                self.weight.push(0);
                self.min = self.min.max(d + 1);
            }
        }
    }
}

/// Reusable tables and line buffers for repeated resizing.
#[derive(Debug, Clone, Default)]
pub struct Resizer {
    x: Axis,
    y: Axis,
    line0: Vec<u16>,
    line1: Vec<u16>,
    last: (usize, usize, usize, usize),
}

impl Resizer {
    /// A resizer with empty buffers.
    pub fn new() -> Self {
        Self::default()
    }

    /// Resizes the row-major `sw` × `sh` image `src` into `dst` (`dw` × `dh`, row-major),
    /// as `cv::resize(src, dst, Size(dw, dh), 0, 0, INTER_LINEAR_EXACT)`.
    pub fn resize(&mut self, src: &[u8], sw: usize, sh: usize, dst: &mut [u8], dw: usize, dh: usize) {
        self.resize_part(src, sw, sh, dst, dw, dh, 0..dh, dw);
    }

    /// Only part of [`Resizer::resize`]'s output: destination rows `rows` and columns
    /// `0..cols`, written row-major into `dst` (`rows.len()` × `cols`, stride `cols`). Every
    /// pixel is the one the whole resize gives (each output pixel depends only on its own
    /// sampling position), so a detector that reads only part of a pyramid level resizes
    /// only that part.
    #[allow(clippy::too_many_arguments)]
    pub fn resize_part(
        &mut self,
        src: &[u8],
        sw: usize,
        sh: usize,
        dst: &mut [u8],
        dw: usize,
        dh: usize,
        rows: std::ops::Range<usize>,
        cols: usize,
    ) {
        let cols = cols.min(dw);
        let rows = rows.start.min(dh)..rows.end.min(dh);
        assert!(
            src.len() >= sw * sh && dst.len() >= rows.len() * cols,
            "resize buffers too small"
        );
        if dw == 0 || dh == 0 || sw == 0 || sh == 0 || cols == 0 || rows.is_empty() {
            return;
        }
        if (sw, sh) == (dw, dh) {
            for (k, y) in rows.enumerate() {
                dst[k * cols..(k + 1) * cols].copy_from_slice(&src[y * sw..y * sw + cols]);
            }
            return;
        }
        if self.last != (sw, sh, dw, dh) {
            self.x.build(sw, dw);
            self.y.build(sh, dh);
            self.last = (sw, sh, dw, dh);
        }
        self.line0.resize(cols, 0);
        self.line1.resize(cols, 0);
        let mut have = (usize::MAX, usize::MAX); // source rows now in line0, line1
        for (k, dy) in rows.enumerate() {
            let out = &mut dst[k * cols..(k + 1) * cols];
            if dy < self.y.min || dy >= self.y.max {
                // Rows outside the interpolated band copy the first/last source row.
                let sy = if dy < self.y.min { 0 } else { sh - 1 };
                hline(&self.x, &src[sy * sw..(sy + 1) * sw], &mut self.line0);
                have = (usize::MAX, usize::MAX);
                for (o, &v) in out.iter_mut().zip(&self.line0) {
                    *o = ((v as u32 + 128) >> 8) as u8;
                }
                continue;
            }
            let iy = self.y.offset[dy] as usize;
            // 2. Horizontal pass on the two source rows, reusing lines already done.
            if have.0 != iy {
                if have.1 == iy {
                    std::mem::swap(&mut self.line0, &mut self.line1);
                } else {
                    hline(&self.x, &src[iy * sw..(iy + 1) * sw], &mut self.line0);
                }
                hline(&self.x, &src[(iy + 1) * sw..(iy + 2) * sw], &mut self.line1);
                have = (iy, iy + 1);
            }
            // 3. Vertical blend in 16.16 fixed point.
            let b = self.y.weight[dy] as u32;
            let a = 256 - b;
            for ((o, &p0), &p1) in out.iter_mut().zip(&self.line0).zip(&self.line1) {
                *o = ((p0 as u32 * a + p1 as u32 * b + (1 << 15)) >> 16) as u8;
            }
        }
    }

    /// The source rows that destination rows `rows` read when `sh` rows are resized to `dh`
    /// (a half-open range; empty for an empty `rows`).
    pub fn source_rows(sh: usize, dh: usize, rows: std::ops::Range<usize>) -> std::ops::Range<usize> {
        if rows.is_empty() || sh == 0 || dh == 0 {
            return 0..0;
        }
        if sh == dh {
            return rows.start.min(sh)..rows.end.min(sh);
        }
        let scale = 1.0 / (dh as f64 / sh as f64);
        let src_of = |d: usize| {
            let f = (scale * (d as f64 + 0.5) - 0.5).floor();
            if f < 0.0 {
                0
            } else {
                (f as usize).min(sh - 1)
            }
        };
        src_of(rows.start)..(src_of(rows.end - 1) + 2).min(sh)
    }
}

/// One source row interpolated horizontally into 8.8 fixed point.
/// `out` may be shorter than the destination row (the first `out.len()` columns).
fn hline(ax: &Axis, row: &[u8], out: &mut [u16]) {
    let n = out.len();
    let first = row[0] as u16 * 256;
    let last_src = row[row.len() - 1] as u16 * 256;
    let (lo, hi) = (ax.min.min(n), ax.max.min(n));
    out[..lo].fill(first);
    for ((o, &i), &b) in out[lo..hi.max(lo)]
        .iter_mut()
        .zip(&ax.offset[lo..hi.max(lo)])
        .zip(&ax.weight[lo..hi.max(lo)])
    {
        let i = i as usize;
        *o = (256 - b) * row[i] as u16 + b * row[i + 1] as u16;
    }
    for o in out.iter_mut().take(n).skip(ax.max.max(ax.min)) {
        *o = last_src;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_images_stay_constant() {
        let src = vec![77u8; 50 * 40];
        let mut dst = vec![0u8; 23 * 17];
        Resizer::new().resize(&src, 50, 40, &mut dst, 23, 17);
        assert!(dst.iter().all(|&v| v == 77));
    }

    #[test]
    fn a_part_is_the_same_as_the_whole() {
        let (sw, sh) = (37, 29);
        let mut seed = 3u32;
        let src: Vec<u8> = (0..sw * sh)
            .map(|_| {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                (seed >> 24) as u8
            })
            .collect();
        for (dw, dh) in [(30, 24), (17, 13), (37, 29), (5, 4)] {
            let mut whole = vec![0u8; dw * dh];
            Resizer::new().resize(&src, sw, sh, &mut whole, dw, dh);
            let mut r = Resizer::new();
            for (rows, cols) in [(0..dh, dw), (2..dh - 1, dw - 3), (dh / 2..dh, 1), (1..2, dw)] {
                let mut part = vec![0u8; rows.len() * cols];
                r.resize_part(&src, sw, sh, &mut part, dw, dh, rows.clone(), cols);
                for (k, y) in rows.clone().enumerate() {
                    assert_eq!(&part[k * cols..(k + 1) * cols], &whole[y * dw..y * dw + cols], "{dw}x{dh} row {y}");
                }
                // The source rows it reads: changing any other row changes nothing.
                let used = Resizer::source_rows(sh, dh, rows.clone());
                let mut other = src.clone();
                for y in (0..sh).filter(|y| !used.contains(y)) {
                    other[y * sw..(y + 1) * sw].fill(99);
                }
                let mut part2 = vec![0u8; rows.len() * cols];
                r.resize_part(&other, sw, sh, &mut part2, dw, dh, rows.clone(), cols);
                assert_eq!(part, part2, "{dw}x{dh} rows {rows:?} read outside {used:?}");
            }
        }
    }

    #[test]
    fn halving_averages_pairs() {
        // Scale 2: f = 2d + 0.5, weight 128/256: the mean of two pixels, rounded half up.
        let src: Vec<u8> = (0..8u8).map(|x| x * 10).collect();
        let mut dst = vec![0u8; 4];
        Resizer::new().resize(&src, 8, 1, &mut dst, 4, 1);
        assert_eq!(dst, vec![5, 25, 45, 65]);
    }
}
