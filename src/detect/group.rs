//! Grouping of raw detections, as OpenCV's `cv::groupRectangles(rects, weights,
//! groupThreshold, eps)` with the `cv::partition` union–find and `SimilarRects(eps)`.
//!
//! 1. Two rectangles are similar when each of their four edges differs by at most
//!    `δ = eps · (min(w1, w2) + min(h1, h2)) / 2`; similarity classes are the connected
//!    components of that relation.
//! 2. Each class becomes its mean rectangle (sums × `1/n` in f32, rounded half to even), and
//!    its size `n` is the neighbour count.
//! 3. Classes with `n ≤ groupThreshold` are dropped, and so is a class lying inside another
//!    kept class (enlarged by `eps` of its size) when that one has more than `max(3, n)`
//!    members (or this one has fewer than 3).
//!
//! The output follows the order in which classes first appear in the input. Units: pixels.

/// An axis-aligned rectangle in pixels (OpenCV's `cv::Rect`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize)]
pub struct Rect {
    /// Left column.
    pub x: i32,
    /// Top row.
    pub y: i32,
    /// Width.
    pub width: i32,
    /// Height.
    pub height: i32,
}

impl Rect {
    /// A rectangle from its left, top, width and height.
    pub const fn new(x: i32, y: i32, width: i32, height: i32) -> Self {
        Self { x, y, width, height }
    }

    /// Intersection with another rectangle (empty → zero size), as `cv::Rect::operator&`.
    pub fn intersect(&self, o: &Rect) -> Rect {
        let x0 = self.x.max(o.x);
        let y0 = self.y.max(o.y);
        let x1 = (self.x + self.width).min(o.x + o.width);
        let y1 = (self.y + self.height).min(o.y + o.height);
        if x1 <= x0 || y1 <= y0 {
            Rect::default()
        } else {
            Rect::new(x0, y0, x1 - x0, y1 - y0)
        }
    }

    /// Area in pixels².
    pub fn area(&self) -> i64 {
        self.width as i64 * self.height as i64
    }

    /// Intersection over union with another rectangle (0 when both are empty).
    pub fn iou(&self, o: &Rect) -> f64 {
        let i = self.intersect(o).area() as f64;
        let u = (self.area() + o.area()) as f64 - i;
        if u > 0.0 {
            i / u
        } else {
            0.0
        }
    }
}

fn similar(a: &Rect, b: &Rect, eps: f64) -> bool {
    let delta = eps * ((a.width.min(b.width) + a.height.min(b.height)) as f64) * 0.5;
    ((a.x - b.x).abs() as f64) <= delta
        && ((a.y - b.y).abs() as f64) <= delta
        && ((a.x + a.width - b.x - b.width).abs() as f64) <= delta
        && ((a.y + a.height - b.y - b.height).abs() as f64) <= delta
}

/// Labels the similarity classes of `rects` (0, 1, ... in order of first appearance);
/// returns the number of classes. A union–find like `cv::partition`.
pub fn partition(rects: &[Rect], eps: f64, labels: &mut Vec<usize>) -> usize {
    let n = rects.len();
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    // Candidates come sorted by nothing in particular; sort indices by x so that only
    // rectangles whose left edges are close enough can be compared (δ ≤ eps·max size).
    let max_side = rects.iter().map(|r| r.width.max(r.height)).max().unwrap_or(0) as f64;
    let reach = (eps * max_side).ceil() as i32 + 1;
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by_key(|&i| rects[i].x);
    for a in 0..n {
        let i = order[a];
        for &j in &order[a + 1..] {
            if rects[j].x - rects[i].x > reach {
                break;
            }
            if similar(&rects[i], &rects[j], eps) {
                let (ri, rj) = (find(&mut parent, i), find(&mut parent, j));
                if ri != rj {
                    parent[ri.max(rj)] = ri.min(rj);
                }
            }
        }
    }
    labels.clear();
    let mut class_of_root = vec![usize::MAX; n];
    let mut classes = 0;
    for i in 0..n {
        let r = find(&mut parent, i);
        if class_of_root[r] == usize::MAX {
            class_of_root[r] = classes;
            classes += 1;
        }
        labels.push(class_of_root[r]);
    }
    classes
}

/// Groups raw detections; returns the kept rectangles with their neighbour counts.
/// `group_threshold ≤ 0` keeps every rectangle with count 1, as OpenCV does.
pub fn group_rectangles(rects: &[Rect], group_threshold: i32, eps: f64) -> Vec<(Rect, u32)> {
    if group_threshold <= 0 || rects.is_empty() {
        return rects.iter().map(|&r| (r, 1)).collect();
    }
    // 1. Classes.
    let mut labels = Vec::new();
    let nclasses = partition(rects, eps, &mut labels);
    // 2. Mean rectangle and size of each class.
    let mut sums = vec![[0i64; 4]; nclasses];
    let mut counts = vec![0i32; nclasses];
    for (r, &c) in rects.iter().zip(&labels) {
        sums[c][0] += r.x as i64;
        sums[c][1] += r.y as i64;
        sums[c][2] += r.width as i64;
        sums[c][3] += r.height as i64;
        counts[c] += 1;
    }
    let means: Vec<Rect> = sums
        .iter()
        .zip(&counts)
        .map(|(s, &n)| {
            let k = 1.0f32 / n as f32;
            let m = |v: i64| (v as i32 as f32 * k).round_ties_even() as i32;
            Rect::new(m(s[0]), m(s[1]), m(s[2]), m(s[3]))
        })
        .collect();
    // 3. Thresholds and removal of small rectangles inside big, better supported ones.
    let mut out = Vec::new();
    for i in 0..nclasses {
        let (r1, n1) = (means[i], counts[i]);
        if n1 <= group_threshold {
            continue;
        }
        let swallowed = (0..nclasses).any(|j| {
            let n2 = counts[j];
            if j == i || n2 <= group_threshold {
                return false;
            }
            let r2 = means[j];
            let dx = (r2.width as f64 * eps).round_ties_even() as i32;
            let dy = (r2.height as f64 * eps).round_ties_even() as i32;
            r1.x >= r2.x - dx
                && r1.y >= r2.y - dy
                && r1.x + r1.width <= r2.x + r2.width + dx
                && r1.y + r1.height <= r2.y + r2.height + dy
                && (n2 > 3.max(n1) || n1 < 3)
        });
        if !swallowed {
            out.push((r1, n1 as u32));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn near_rectangles_merge_and_count() {
        let rects = [
            Rect::new(10, 10, 20, 20),
            Rect::new(11, 10, 20, 20),
            Rect::new(12, 11, 21, 21),
            Rect::new(100, 100, 20, 20),
        ];
        let g = group_rectangles(&rects, 2, 0.2);
        // mean of x: 33/3 = 11, y: 31/3 = 10.33 -> 10, w: 61/3 = 20.33 -> 20
        assert_eq!(g, vec![(Rect::new(11, 10, 20, 20), 3)]);
        let g = group_rectangles(&rects, 0, 0.2);
        assert_eq!(g.len(), 4);
    }

    #[test]
    fn small_box_inside_a_strong_big_one_is_dropped() {
        let mut rects = vec![Rect::new(0, 0, 100, 100); 6];
        rects.extend([Rect::new(30, 30, 20, 20); 2]);
        let g = group_rectangles(&rects, 1, 0.2);
        assert_eq!(g, vec![(Rect::new(0, 0, 100, 100), 6)]);
    }

    #[test]
    fn iou_of_half_overlap() {
        let a = Rect::new(0, 0, 10, 10);
        let b = Rect::new(5, 0, 10, 10);
        assert!((a.iou(&b) - 50.0 / 150.0).abs() < 1e-12);
    }
}
