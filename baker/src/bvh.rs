//! Nearest-point queries on a triangle set: a bounding-volume hierarchy and the exact
//! point-triangle distance. Used by the validator's honesty measure (`honesty`) and by the
//! baker's per-group deviation (`deviation`), so that both measure distance the same way.

/// Bounding-volume hierarchy over triangles for nearest-point queries (median split on the
/// longest axis, leaves of up to 4 triangles).
pub struct Bvh {
    nodes: Vec<Node>,
    order: Vec<u32>,
}

struct Node {
    lo: [f64; 3],
    hi: [f64; 3],
    /// Leaf: first triangle in `order` and count; inner: children at `start` and `start + 1`.
    start: u32,
    count: u32,
}

impl Bvh {
    /// Builds the hierarchy over `tris` (which later queries must pass again).
    pub fn new(tris: &[[[f64; 3]; 3]]) -> Bvh {
        let mut order: Vec<u32> = (0..tris.len() as u32).collect();
        let mut nodes = vec![Node { lo: [0.0; 3], hi: [0.0; 3], start: 0, count: 0 }];
        let mut stack = vec![(0usize, 0usize, tris.len())];
        while let Some((node, start, end)) = stack.pop() {
            let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
            for &t in &order[start..end] {
                for v in &tris[t as usize] {
                    for k in 0..3 {
                        lo[k] = lo[k].min(v[k]);
                        hi[k] = hi[k].max(v[k]);
                    }
                }
            }
            nodes[node].lo = lo;
            nodes[node].hi = hi;
            if end - start <= 4 {
                nodes[node].start = start as u32;
                nodes[node].count = (end - start) as u32;
                continue;
            }
            let axis = (0..3).max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b]))).unwrap_or(0);
            let centroid = |t: u32| tris[t as usize].iter().map(|v| v[axis]).sum::<f64>();
            let mid = (start + end) / 2;
            order[start..end].select_nth_unstable_by(mid - start, |&a, &b| centroid(a).total_cmp(&centroid(b)));
            let child = nodes.len();
            nodes.push(Node { lo, hi, start: 0, count: 0 });
            nodes.push(Node { lo, hi, start: 0, count: 0 });
            nodes[node].start = child as u32;
            stack.push((child, start, mid));
            stack.push((child + 1, mid, end));
        }
        Bvh { nodes, order }
    }

    /// Distance from `p` to the nearest of `tris` (infinite when there are none).
    pub fn distance(&self, tris: &[[[f64; 3]; 3]], p: [f64; 3]) -> f64 {
        self.nearest(tris, p).0
    }

    /// Distance to the nearest triangle and its index.
    pub fn nearest(&self, tris: &[[[f64; 3]; 3]], p: [f64; 3]) -> (f64, usize) {
        self.nearest_beyond(tris, p, 0.0)
    }

    /// Like [`Bvh::nearest`] where the distance exceeds `enough`; otherwise some triangle
    /// within `enough` of `p` (the search stops at the first one found). For a maximum over
    /// many points of their distance, where only distances above the current maximum matter.
    pub fn nearest_beyond(&self, tris: &[[[f64; 3]; 3]], p: [f64; 3], enough: f64) -> (f64, usize) {
        let mut best = (f64::INFINITY, 0usize);
        if self.order.is_empty() {
            return best;
        }
        // Depth is at most ~2·log2(n) + 1; 96 entries cover any mesh that fits in memory.
        let mut stack = [0u32; 96];
        let mut top = 1usize;
        let box_dist = |n: &Node| {
            let d = [0, 1, 2].map(|k| (n.lo[k] - p[k]).max(p[k] - n.hi[k]).max(0.0));
            d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
        };
        while top > 0 {
            top -= 1;
            let n = &self.nodes[stack[top] as usize];
            if box_dist(n) >= best.0 * best.0 {
                continue;
            }
            if n.count > 0 {
                for &t in &self.order[n.start as usize..(n.start + n.count) as usize] {
                    let d = point_triangle_distance(p, &tris[t as usize]);
                    if d < best.0 {
                        best = (d, t as usize);
                        if d <= enough {
                            return best;
                        }
                    }
                }
            } else if top + 2 <= stack.len() {
                let (a, b) = (n.start, n.start + 1);
                let (near, far) = if box_dist(&self.nodes[a as usize]) <= box_dist(&self.nodes[b as usize]) {
                    (a, b)
                } else {
                    (b, a)
                };
                stack[top] = far;
                stack[top + 1] = near;
                top += 2;
            }
        }
        best
    }
}

/// Distance from `p` to triangle `t` (closest point by region, Ericson's "Real-Time Collision
/// Detection" §5.1.5).
pub fn point_triangle_distance(p: [f64; 3], t: &[[f64; 3]; 3]) -> f64 {
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let (a, b, c) = (t[0], t[1], t[2]);
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    let at = |u: f64, v: f64| -> f64 {
        let q = [a[0] + ab[0] * u + ac[0] * v, a[1] + ab[1] * u + ac[1] * v, a[2] + ab[2] * u + ac[2] * v];
        dot(sub(p, q), sub(p, q)).sqrt()
    };
    if d1 <= 0.0 && d2 <= 0.0 {
        return at(0.0, 0.0);
    }
    let bp = sub(p, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return at(1.0, 0.0);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return at(d1 / (d1 - d3), 0.0);
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return at(0.0, 1.0);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return at(0.0, d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return at(1.0 - w, w);
    }
    let denom = 1.0 / (va + vb + vc);
    at(vb * denom, vc * denom)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_triangle_distances() {
        let t = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        assert!((point_triangle_distance([0.2, 0.2, 0.5], &t) - 0.5).abs() < 1e-12);
        assert!((point_triangle_distance([-1.0, 0.0, 0.0], &t) - 1.0).abs() < 1e-12);
        assert!((point_triangle_distance([1.0, 1.0, 0.0], &t) - 0.5f64.sqrt()).abs() < 1e-12);
        let tris: Vec<[[f64; 3]; 3]> = (0..100)
            .map(|i| {
                let x = i as f64;
                [[x, 0.0, 0.0], [x + 1.0, 0.0, 0.0], [x, 1.0, 0.0]]
            })
            .collect();
        let bvh = Bvh::new(&tris);
        let (d, t) = bvh.nearest(&tris, [50.2, 0.2, 3.0]);
        assert!((d - 3.0).abs() < 1e-12 && t == 50, "{d} {t}");
    }
}
