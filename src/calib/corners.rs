//! Checkerboard inner-corner finding with sub-pixel refinement (the calibration target of
//! Abdollahi 2011 and Zhang 2000). Not OpenCV's quad-linking detector, but its output in the
//! same form and order, refined by the same `cornerSubPix` iteration:
//!
//! 1. Blur (Gaussian, σ from the image size) and take the saddle response
//!    S = I_xy² − I_xx·I_yy (positive where two edges cross); local maxima are candidates.
//! 2. Ring test: on a circle round a candidate the grey level must change sign exactly four
//!    times (dark, bright, dark, bright quadrants); the four changes give the directions of
//!    the two board lines through it.
//! 3. Grid growth from a seed: its four neighbours along those lines, then whole new rows and
//!    columns predicted by extrapolation (quadratic when three rows are known) and accepted
//!    only when every corner of the row is found within 30 % of the spacing and the squares
//!    between alternate dark/bright. A seed succeeds when the grid is exactly the board.
//! 4. Order: rows of `cols` corners; the first row runs left to right (its direction nearest
//!    +x) and the next row lies below it (the grid is not mirrored).
//! 5. `cornerSubPix` (OpenCV's algorithm): the corner q is where every image gradient g_i in
//!    the window is orthogonal to (p_i − q), solved in a least-squares sense with Gaussian
//!    weights, iterated. Units: pixels, (0, 0) the centre of the top-left pixel.

use image::GrayImage;

/// Inner corners of a board: `cols` along a row, `rows` rows (OpenCV's `patternSize`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct BoardSize {
    /// Inner corners per row.
    pub cols: usize,
    /// Rows of inner corners.
    pub rows: usize,
}

impl std::str::FromStr for BoardSize {
    type Err = String;
    /// Parses `9x6`.
    fn from_str(s: &str) -> Result<Self, String> {
        let (a, b) = s
            .split_once(['x', 'X'])
            .ok_or_else(|| format!("board size '{s}' is not COLSxROWS, e.g. 9x6"))?;
        let p = |t: &str| {
            t.trim()
                .parse::<usize>()
                .map_err(|_| format!("board size '{s}': '{t}' is not a number"))
        };
        let (cols, rows) = (p(a)?, p(b)?);
        if cols < 3 || rows < 3 || cols > 64 || rows > 64 {
            return Err(format!("board size '{s}': each side must be 3..64 inner corners"));
        }
        Ok(BoardSize { cols, rows })
    }
}

/// Options of the sub-pixel refinement (OpenCV's `cornerSubPix` arguments).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CornerOptions {
    /// Half size of the search window, pixels (OpenCV's `winSize` = (11, 11) → 11). It is
    /// reduced to 0.55 × the board's smallest corner spacing when that is smaller.
    pub subpix_win: usize,
    /// Most iterations.
    pub max_iter: usize,
    /// Stop when a step is shorter than this, pixels.
    pub eps: f64,
}

impl Default for CornerOptions {
    fn default() -> Self {
        Self {
            subpix_win: 11,
            max_iter: 30,
            eps: 0.001,
        }
    }
}

/// A float image with clamped bilinear reads.
struct FImg {
    w: usize,
    h: usize,
    d: Vec<f32>,
}

impl FImg {
    fn from_gray(img: &GrayImage) -> FImg {
        FImg {
            w: img.width() as usize,
            h: img.height() as usize,
            d: img.as_raw().iter().map(|&v| v as f32).collect(),
        }
    }

    #[inline]
    fn at(&self, x: isize, y: isize) -> f32 {
        let x = x.clamp(0, self.w as isize - 1) as usize;
        let y = y.clamp(0, self.h as isize - 1) as usize;
        self.d[y * self.w + x]
    }

    /// Bilinear sample with replicated borders.
    fn sample(&self, x: f64, y: f64) -> f32 {
        let (x0, y0) = (x.floor(), y.floor());
        let (ax, ay) = ((x - x0) as f32, (y - y0) as f32);
        let (x0, y0) = (x0 as isize, y0 as isize);
        let a = self.at(x0, y0) * (1.0 - ax) + self.at(x0 + 1, y0) * ax;
        let b = self.at(x0, y0 + 1) * (1.0 - ax) + self.at(x0 + 1, y0 + 1) * ax;
        a * (1.0 - ay) + b * ay
    }

    fn blur(&self, sigma: f64) -> FImg {
        let r = (3.0 * sigma).ceil() as isize;
        let k: Vec<f32> = (-r..=r)
            .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp() as f32)
            .collect();
        let s: f32 = k.iter().sum();
        let k: Vec<f32> = k.iter().map(|v| v / s).collect();
        let mut tmp = vec![0f32; self.d.len()];
        for y in 0..self.h {
            for x in 0..self.w {
                let mut acc = 0.0;
                for (j, kv) in k.iter().enumerate() {
                    acc += kv * self.at(x as isize + j as isize - r, y as isize);
                }
                tmp[y * self.w + x] = acc;
            }
        }
        let t = FImg {
            w: self.w,
            h: self.h,
            d: tmp,
        };
        let mut out = vec![0f32; self.d.len()];
        for y in 0..self.h {
            for x in 0..self.w {
                let mut acc = 0.0;
                for (j, kv) in k.iter().enumerate() {
                    acc += kv * t.at(x as isize, y as isize + j as isize - r);
                }
                out[y * self.w + x] = acc;
            }
        }
        FImg {
            w: self.w,
            h: self.h,
            d: out,
        }
    }
}

/// A corner candidate: position, saddle strength and the directions of its two lines.
#[derive(Debug, Clone, Copy)]
struct Cand {
    p: [f64; 2],
    s: f32,
    /// Directions (radians, modulo π) of the two board lines through it.
    dirs: [f64; 2],
}

/// The saddle response −det(Hessian) of the blurred image `bl` (`w`×`h`) at every inner
/// pixel (0 on the border), and its largest value.
fn saddle_response(bl: &FImg, w: usize, h: usize) -> (Vec<f32>, f32) {
    let mut s = vec![0f32; w * h];
    let mut smax = 0f32;
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let (xi, yi) = (x as isize, y as isize);
            let c = bl.at(xi, yi);
            let ixx = bl.at(xi + 1, yi) - 2.0 * c + bl.at(xi - 1, yi);
            let iyy = bl.at(xi, yi + 1) - 2.0 * c + bl.at(xi, yi - 1);
            let ixy =
                (bl.at(xi + 1, yi + 1) - bl.at(xi + 1, yi - 1) - bl.at(xi - 1, yi + 1) + bl.at(xi - 1, yi - 1)) / 4.0;
            let v = ixy * ixy - ixx * iyy;
            s[y * w + x] = v;
            smax = smax.max(v);
        }
    }
    (s, smax)
}

/// Finds the `board`'s inner corners in `img`, refined to sub-pixel; `None` when the whole
/// board is not visible (the caller names the image).
pub fn find_chessboard(img: &GrayImage, board: BoardSize, opts: &CornerOptions) -> Option<Vec<[f64; 2]>> {
    let (w, h) = (img.width() as usize, img.height() as usize);
    if w < 16 || h < 16 {
        return None;
    }
    let raw = FImg::from_gray(img);
    let sigma = (w.max(h) as f64 / 400.0).clamp(1.0, 3.0);
    let bl = raw.blur(sigma);
    // 1. Saddle response and its local maxima.
    let (s, smax) = saddle_response(&bl, w, h);
    if smax <= 0.0 {
        return None;
    }
    let ring_r = (2.5 * sigma).max(3.0);
    let nms = 3isize;
    let margin = (ring_r.ceil() as usize + 2).max(nms as usize + 1);
    let thr = 0.005 * smax;
    let mut cands = vec![];
    for y in margin..h.saturating_sub(margin) {
        for x in margin..w.saturating_sub(margin) {
            let v = s[y * w + x];
            if v <= thr {
                continue;
            }
            let mut is_max = true;
            'n: for dy in -nms..=nms {
                for dx in -nms..=nms {
                    let q = s[(y as isize + dy) as usize * w + (x as isize + dx) as usize];
                    if q > v || (q == v && (dy, dx) < (0, 0)) {
                        is_max = false;
                        break 'n;
                    }
                }
            }
            if !is_max {
                continue;
            }
            // 2. Ring test.
            if let Some(dirs) = ring_test(&bl, x as f64, y as f64, ring_r) {
                cands.push(Cand {
                    p: [x as f64, y as f64],
                    s: v,
                    dirs,
                });
            }
        }
    }
    if cands.len() < board.cols * board.rows {
        return None;
    }
    // 3. Grid growth from the strongest seeds.
    let mut order: Vec<usize> = (0..cands.len()).collect();
    order.sort_by(|&a, &b| cands[b].s.total_cmp(&cands[a].s));
    let (big, small) = (board.cols.max(board.rows), board.cols.min(board.rows));
    let mut tried = vec![false; cands.len()];
    for &seed in order.iter().take(150) {
        if tried[seed] {
            continue;
        }
        let Some(grid) = grow(&cands, &bl, seed, big) else {
            continue;
        };
        for row in &grid {
            for &i in row {
                tried[i] = true;
            }
        }
        let (r, c) = (grid.len(), grid[0].len());
        if !((r == big && c == small) || (r == small && c == big)) {
            continue;
        }
        // 4. Rows of `cols` corners, not mirrored, first row running right.
        let mut g: Vec<Vec<[f64; 2]>> = grid
            .iter()
            .map(|row| row.iter().map(|&i| cands[i].p).collect())
            .collect();
        if g[0].len() != board.cols {
            g = transpose(&g);
        }
        orient(&mut g);
        let mut pts: Vec<[f64; 2]> = g.into_iter().flatten().collect();
        // 5. Sub-pixel refinement; the window is shrunk when it would reach well past half
        //    way to the next corner (OpenCV keeps the caller's window whatever the board).
        let spacing = min_spacing(&pts, board);
        let win = opts.subpix_win.min((0.55 * spacing) as usize).max(2);
        corner_subpix(img, &mut pts, win, opts.max_iter, opts.eps);
        return Some(pts);
    }
    None
}

/// Puts a grid of rows into the canonical orientation (step 4 of the module doc).
pub(crate) fn orient<T>(g: &mut [Vec<T>])
where
    T: Copy + Into<[f64; 2]>,
{
    let p = |g: &[Vec<T>], r: usize, c: usize| -> [f64; 2] { g[r][c].into() };
    let (rn, cn) = (g.len(), g[0].len());
    let a = p(g, 0, 0);
    let rv = [p(g, 0, cn - 1)[0] - a[0], p(g, 0, cn - 1)[1] - a[1]];
    let cv = [p(g, rn - 1, 0)[0] - a[0], p(g, rn - 1, 0)[1] - a[1]];
    if rv[0] * cv[1] - rv[1] * cv[0] < 0.0 {
        for row in g.iter_mut() {
            row.reverse();
        }
    }
    let a = p(g, 0, 0);
    if p(g, 0, cn - 1)[0] - a[0] < 0.0 {
        g.reverse();
        for row in g.iter_mut() {
            row.reverse();
        }
    }
}

/// Rotates a row-major grid of `board` corners by 180° (the other consistent labelling).
pub fn rotate_180(pts: &mut [[f64; 2]]) {
    pts.reverse();
}

/// The right image's corners `r` labelled as the left image's `l` are: the same corner gets
/// the same index in both. Of the two consistent labellings, the one that keeps the rows
/// level (a side-by-side pair).
pub fn orient_like(l: &[[f64; 2]], r: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let dy = |r: &[[f64; 2]]| l.iter().zip(r).map(|(p, q)| (p[1] - q[1]).powi(2)).sum::<f64>();
    let mut flipped = r.to_vec();
    rotate_180(&mut flipped);
    if dy(&flipped) < dy(r) {
        flipped
    } else {
        r.to_vec()
    }
}

fn min_spacing(pts: &[[f64; 2]], board: BoardSize) -> f64 {
    let mut m = f64::INFINITY;
    for r in 0..board.rows {
        for c in 0..board.cols {
            let p = pts[r * board.cols + c];
            if c + 1 < board.cols {
                let q = pts[r * board.cols + c + 1];
                m = m.min((p[0] - q[0]).hypot(p[1] - q[1]));
            }
            if r + 1 < board.rows {
                let q = pts[(r + 1) * board.cols + c];
                m = m.min((p[0] - q[0]).hypot(p[1] - q[1]));
            }
        }
    }
    m
}

fn transpose<T: Copy>(g: &[Vec<T>]) -> Vec<Vec<T>> {
    (0..g[0].len()).map(|c| g.iter().map(|row| row[c]).collect()).collect()
}

/// Step 2: four sign changes on a ring of radius `r`; returns the two line directions.
fn ring_test(bl: &FImg, x: f64, y: f64, r: f64) -> Option<[f64; 2]> {
    const N: usize = 32;
    let mut v = [0f32; N];
    for (k, val) in v.iter_mut().enumerate() {
        let a = std::f64::consts::TAU * k as f64 / N as f64;
        *val = bl.sample(x + r * a.cos(), y + r * a.sin());
    }
    let (lo, hi) = v.iter().fold((f32::MAX, f32::MIN), |a, &b| (a.0.min(b), a.1.max(b)));
    if hi - lo < 20.0 {
        return None;
    }
    let mid = 0.5 * (lo + hi);
    let sign: Vec<bool> = v.iter().map(|&a| a > mid).collect();
    let mut changes = vec![];
    for k in 0..N {
        if sign[k] != sign[(k + 1) % N] {
            changes.push(k);
        }
    }
    if changes.len() != 4 {
        return None;
    }
    // Each quadrant at least 3 samples wide.
    for i in 0..4 {
        let len = (changes[(i + 1) % 4] + N - changes[i]) % N;
        if len < 3 {
            return None;
        }
    }
    let ang = |k: usize| std::f64::consts::TAU * (k as f64 + 0.5) / N as f64;
    let mean_dir = |a: f64, b: f64| {
        // Directions modulo π: average on the doubled angle.
        let (s, c) = ((2.0 * a).sin() + (2.0 * b).sin(), (2.0 * a).cos() + (2.0 * b).cos());
        0.5 * s.atan2(c)
    };
    Some([
        mean_dir(ang(changes[0]), ang(changes[2])),
        mean_dir(ang(changes[1]), ang(changes[3])),
    ])
}

fn angle_diff_mod_pi(a: f64, b: f64) -> f64 {
    let mut d = (a - b) % std::f64::consts::PI;
    if d < 0.0 {
        d += std::f64::consts::PI;
    }
    d.min(std::f64::consts::PI - d)
}

/// The nearest candidate from `from` in direction `dir` (radians) within 20°.
fn neighbour(c: &[Cand], from: usize, dir: f64, used: &[bool]) -> Option<usize> {
    let p = c[from].p;
    let mut best: Option<(usize, f64)> = None;
    for (i, q) in c.iter().enumerate() {
        if i == from || used[i] {
            continue;
        }
        let (dx, dy) = (q.p[0] - p[0], q.p[1] - p[1]);
        let d = dx.hypot(dy);
        if d < 4.0 {
            continue;
        }
        let a = dy.atan2(dx);
        let mut da = (a - dir).abs() % std::f64::consts::TAU;
        if da > std::f64::consts::PI {
            da = std::f64::consts::TAU - da;
        }
        if da > 20f64.to_radians() {
            continue;
        }
        if best.is_none_or(|b| d < b.1) {
            best = Some((i, d));
        }
    }
    best.map(|b| b.0)
}

/// The candidate nearest `p` within `tol`, not yet used, whose lines agree with `dirs`.
fn nearest(c: &[Cand], p: [f64; 2], tol: f64, used: &[bool], dirs: [f64; 2]) -> Option<usize> {
    let mut best: Option<(usize, f64)> = None;
    for (i, q) in c.iter().enumerate() {
        if used[i] {
            continue;
        }
        let d = (q.p[0] - p[0]).hypot(q.p[1] - p[1]);
        if d > tol {
            continue;
        }
        // Each of its lines near one of the grid's local lines.
        let ok = q
            .dirs
            .iter()
            .all(|&a| dirs.iter().any(|&b| angle_diff_mod_pi(a, b) < 30f64.to_radians()));
        if ok && best.is_none_or(|b| d < b.1) {
            best = Some((i, d));
        }
    }
    best.map(|b| b.0)
}

/// Mean grey of the cell whose four corners are given.
fn cell_value(bl: &FImg, a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> f32 {
    bl.sample((a[0] + b[0] + c[0] + d[0]) / 4.0, (a[1] + b[1] + c[1] + d[1]) / 4.0)
}

/// Step 3: grows a grid (rows of candidate indices) from `seed`; `None` when no start.
fn grow(c: &[Cand], bl: &FImg, seed: usize, max_side: usize) -> Option<Vec<Vec<usize>>> {
    let mut used = vec![false; c.len()];
    used[seed] = true;
    let [d1, d2] = c[seed].dirs;
    let pi = std::f64::consts::PI;
    let right = neighbour(c, seed, d1, &used)?;
    let left = neighbour(c, seed, d1 + pi, &used)?;
    let down = neighbour(c, seed, d2, &used)?;
    let up = neighbour(c, seed, d2 + pi, &used)?;
    let ids = [right, left, down, up];
    if ids.iter().enumerate().any(|(i, a)| ids[i + 1..].contains(a)) {
        return None;
    }
    let dist = |a: usize| (c[a].p[0] - c[seed].p[0]).hypot(c[a].p[1] - c[seed].p[1]);
    let (r1, r2) = (dist(right) / dist(left), dist(down) / dist(up));
    if !(0.5..=2.0).contains(&r1) || !(0.5..=2.0).contains(&r2) {
        return None;
    }
    for &i in &ids {
        used[i] = true;
    }
    // The 3×3 start: the four diagonal corners by the parallelogram rule.
    let mut g = vec![vec![usize::MAX; 3]; 3];
    g[1][1] = seed;
    g[1][2] = right;
    g[1][0] = left;
    g[2][1] = down;
    g[0][1] = up;
    for (r, cc) in [(0usize, 0usize), (0, 2), (2, 0), (2, 2)] {
        let a = c[g[r][1]].p;
        let b = c[g[1][cc]].p;
        let o = c[seed].p;
        let pred = [a[0] + b[0] - o[0], a[1] + b[1] - o[1]];
        let step = (a[0] - o[0]).hypot(a[1] - o[1]).min((b[0] - o[0]).hypot(b[1] - o[1]));
        let i = nearest(c, pred, 0.3 * step, &used, c[seed].dirs)?;
        used[i] = true;
        g[r][cc] = i;
    }
    if !alternates(c, bl, &g) {
        return None;
    }
    // Grow in all four directions until none works.
    loop {
        let mut grew = false;
        for side in 0..4 {
            if g.len() > max_side || g[0].len() > max_side {
                return Some(g);
            }
            let mut h = match side {
                0 => g.clone(),
                1 => g.iter().rev().cloned().collect(),
                2 => transpose(&g),
                _ => transpose(&g).into_iter().rev().collect(),
            };
            if extend_bottom(c, bl, &mut h, &mut used) {
                g = match side {
                    0 => h,
                    1 => h.into_iter().rev().collect(),
                    2 => transpose(&h),
                    _ => transpose(&h.into_iter().rev().collect::<Vec<_>>()),
                };
                grew = true;
            }
        }
        if !grew {
            return Some(g);
        }
    }
}

/// Whether the cells of a grid alternate dark/bright like a checkerboard.
fn alternates(c: &[Cand], bl: &FImg, g: &[Vec<usize>]) -> bool {
    let p = |r: usize, k: usize| c[g[r][k]].p;
    let mut vals = vec![];
    for r in 0..g.len() - 1 {
        for k in 0..g[0].len() - 1 {
            vals.push((
                (r + k) % 2,
                cell_value(bl, p(r, k), p(r, k + 1), p(r + 1, k), p(r + 1, k + 1)),
            ));
        }
    }
    let mean = |par: usize| {
        let v: Vec<f32> = vals.iter().filter(|a| a.0 == par).map(|a| a.1).collect();
        (v.iter().sum::<f32>() / v.len() as f32, v)
    };
    let (m0, v0) = mean(0);
    let (m1, v1) = mean(1);
    let mid = 0.5 * (m0 + m1);
    if (m0 - m1).abs() < 20.0 {
        return false;
    }
    let s = m0 > m1;
    v0.iter().all(|&v| (v > mid) == s) && v1.iter().all(|&v| (v > mid) != s)
}

/// Adds one row below `g` when every corner of it is found; cells must alternate.
fn extend_bottom(c: &[Cand], bl: &FImg, g: &mut Vec<Vec<usize>>, used: &mut [bool]) -> bool {
    let n = g.len();
    let cols = g[0].len();
    let mut row = Vec::with_capacity(cols);
    let mut taken = vec![];
    for k in 0..cols {
        let a = c[g[n - 1][k]].p;
        let b = c[g[n - 2][k]].p;
        let pred = if n >= 3 {
            let q = c[g[n - 3][k]].p;
            [3.0 * a[0] - 3.0 * b[0] + q[0], 3.0 * a[1] - 3.0 * b[1] + q[1]]
        } else {
            [2.0 * a[0] - b[0], 2.0 * a[1] - b[1]]
        };
        let step = (a[0] - b[0]).hypot(a[1] - b[1]);
        let dirs = c[g[n - 1][k]].dirs;
        match nearest(c, pred, 0.3 * step, used, dirs) {
            Some(i) => {
                used[i] = true;
                taken.push(i);
                row.push(i);
            }
            None => {
                for i in taken {
                    used[i] = false;
                }
                return false;
            }
        }
    }
    // The new cells must be the opposite colour of the ones above them.
    let p = |i: usize| c[i].p;
    let above = |k: usize| {
        cell_value(
            bl,
            p(g[n - 2][k]),
            p(g[n - 2][k + 1]),
            p(g[n - 1][k]),
            p(g[n - 1][k + 1]),
        )
    };
    let below = |k: usize| cell_value(bl, p(g[n - 1][k]), p(g[n - 1][k + 1]), p(row[k]), p(row[k + 1]));
    let ok = (0..cols - 1).all(|k| {
        let (a, b) = (above(k), below(k));
        (a - b).abs() > 20.0 && (k == 0 || ((below(k) - below(k - 1)) * (a - b)) < 0.0)
    });
    if !ok {
        for i in taken {
            used[i] = false;
        }
        return false;
    }
    g.push(row);
    true
}

/// OpenCV's `cornerSubPix`: refines each corner within a (2·win+1)² window (Gaussian-weighted
/// gradient orthogonality), at most `max_iter` steps, stopping when a step is below `eps`
/// pixels. A corner that wanders further than the window is left where it was.
pub fn corner_subpix(img: &GrayImage, corners: &mut [[f64; 2]], win: usize, max_iter: usize, eps: f64) {
    let src = FImg::from_gray(img);
    let wn = win as isize;
    let side = 2 * win + 1;
    // The weights: exp(−x²)·exp(−y²) with x, y in [−1, 1] over the window.
    let mut mask = vec![0f64; side * side];
    for i in -wn..=wn {
        let y = i as f64 / wn as f64;
        let vy = (-y * y).exp();
        for j in -wn..=wn {
            let x = j as f64 / wn as f64;
            mask[((i + wn) as usize) * side + (j + wn) as usize] = (vy * (-x * x).exp()) as f32 as f64;
        }
    }
    let ps = side + 2;
    let mut patch = vec![0f32; ps * ps];
    let eps2 = eps * eps;
    for corner in corners.iter_mut() {
        let start = *corner;
        let mut ci = start;
        for _ in 0..max_iter.max(1) {
            // The (2·win+3)² patch centred on ci, bilinear.
            let (ox, oy) = (ci[0] - (win as f64 + 1.0), ci[1] - (win as f64 + 1.0));
            for y in 0..ps {
                for x in 0..ps {
                    patch[y * ps + x] = src.sample(ox + x as f64, oy + y as f64);
                }
            }
            let (mut a, mut b, mut c, mut bb1, mut bb2) = (0f64, 0f64, 0f64, 0f64, 0f64);
            for i in 0..side {
                let py = i as f64 - win as f64;
                for j in 0..side {
                    let px = j as f64 - win as f64;
                    let m = mask[i * side + j];
                    let tgx = (patch[(i + 1) * ps + j + 2] - patch[(i + 1) * ps + j]) as f64;
                    let tgy = (patch[(i + 2) * ps + j + 1] - patch[i * ps + j + 1]) as f64;
                    let gxx = tgx * tgx * m;
                    let gxy = tgx * tgy * m;
                    let gyy = tgy * tgy * m;
                    a += gxx;
                    b += gxy;
                    c += gyy;
                    bb1 += gxx * px + gxy * py;
                    bb2 += gxy * px + gyy * py;
                }
            }
            let det = a * c - b * b;
            if det.abs() <= f64::EPSILON * f64::EPSILON {
                break;
            }
            let sc = 1.0 / det;
            let nx = ci[0] + c * sc * bb1 - b * sc * bb2;
            let ny = ci[1] - b * sc * bb1 + a * sc * bb2;
            let err = (nx - ci[0]).powi(2) + (ny - ci[1]).powi(2);
            ci = [nx, ny];
            if ci[0] < 0.0 || ci[0] >= src.w as f64 || ci[1] < 0.0 || ci[1] >= src.h as f64 || err <= eps2 {
                break;
            }
        }
        if (ci[0] - start[0]).abs() > win as f64 || (ci[1] - start[1]).abs() > win as f64 {
            ci = start;
        }
        *corner = ci;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fronto-parallel board drawn with 4×4 supersampling: corners found at the drawn places.
    fn board_image(cols: usize, rows: usize, sq: f64, ox: f64, oy: f64, w: u32, h: u32) -> GrayImage {
        GrayImage::from_fn(w, h, |x, y| {
            let mut acc = 0.0;
            for sy in 0..4 {
                for sx in 0..4 {
                    let u = x as f64 + (sx as f64 + 0.5) / 4.0 - 0.5 - ox;
                    let v = y as f64 + (sy as f64 + 0.5) / 4.0 - 0.5 - oy;
                    // Squares from -1 to cols (so `cols` inner corners per row), white margin.
                    let (i, j) = ((u / sq).floor() as i64, (v / sq).floor() as i64);
                    let inside = i >= -1 && i < cols as i64 && j >= -1 && j < rows as i64;
                    let white = !inside || (i + j).rem_euclid(2) == 1;
                    acc += if white { 220.0 } else { 30.0 };
                }
            }
            image::Luma([(acc / 16.0) as u8])
        })
    }

    #[test]
    fn finds_a_drawn_board_in_order() {
        let img = board_image(9, 6, 20.0, 100.3, 80.7, 400, 300);
        let pts = find_chessboard(&img, BoardSize { cols: 9, rows: 6 }, &CornerOptions::default()).unwrap();
        assert_eq!(pts.len(), 54);
        for r in 0..6 {
            for c in 0..9 {
                let p = pts[r * 9 + c];
                let want = [100.3 + 20.0 * c as f64, 80.7 + 20.0 * r as f64];
                assert!(
                    (p[0] - want[0]).abs() < 0.05 && (p[1] - want[1]).abs() < 0.05,
                    "{r},{c}: {p:?} vs {want:?}"
                );
            }
        }
    }

    #[test]
    fn wrong_size_or_blank_is_none() {
        let img = board_image(9, 6, 20.0, 100.0, 80.0, 400, 300);
        assert!(find_chessboard(&img, BoardSize { cols: 7, rows: 6 }, &CornerOptions::default()).is_none());
        let blank = GrayImage::from_pixel(320, 240, image::Luma([128]));
        assert!(find_chessboard(&blank, BoardSize { cols: 9, rows: 6 }, &CornerOptions::default()).is_none());
    }

    #[test]
    fn board_size_parses() {
        assert_eq!("9x6".parse::<BoardSize>().unwrap(), BoardSize { cols: 9, rows: 6 });
        assert!("9".parse::<BoardSize>().is_err());
        assert!("2x6".parse::<BoardSize>().is_err());
    }
}
