//! Step 5: pooling 2x2x2 children into parents (QEM or mean points).

use super::*;

/// How a voxel's surface point is carried from children to parent.
pub(super) trait PointRule: Copy + Send + Sync {
    /// From one surface sample: point `p` (normalised units) with unit normal `n`.
    fn from_sample(p: DVec3, n: DVec3) -> Self;
    fn add(&mut self, other: &Self);
    fn scale(&mut self, s: f64);
    /// The voxel's point, normalised units (not yet clamped to the voxel).
    fn point(&self, centre: DVec3) -> DVec3;
}

/// Plane quadric Q = q q^T, q = (n, -n.p), symmetric 4x4 stored as its upper
/// triangle: a00 a01 a02 a03 a11 a12 a13 a22 a23 a33. Normalised units, f64: the
/// minimiser is a small correction of O(1) numbers.
#[derive(Clone, Copy, Debug)]
pub(super) struct Quadric(pub(super) [f64; 10]);

/// Singular values below this fraction of the largest are dropped from the
/// pseudo-inverse (docs/method.md section 2.5): directions the planes do not pin down (along a
/// flat patch or a crease) stay at the voxel centre instead of running off.
pub(super) const QEM_RELATIVE_THRESHOLD: f64 = 0.05;

impl PointRule for Quadric {
    fn from_sample(p: DVec3, n: DVec3) -> Self {
        let q = [n.x, n.y, n.z, -n.dot(p)];
        #[rustfmt::skip]
        let upper = [
            q[0] * q[0], q[0] * q[1], q[0] * q[2], q[0] * q[3],
            q[1] * q[1], q[1] * q[2], q[1] * q[3],
            q[2] * q[2], q[2] * q[3],
            q[3] * q[3],
        ];
        Quadric(upper)
    }
    fn add(&mut self, o: &Self) {
        for (a, b) in self.0.iter_mut().zip(&o.0) {
            *a += b;
        }
    }
    fn scale(&mut self, s: f64) {
        for a in &mut self.0 {
            *a *= s;
        }
    }
    /// Minimises `v^T A v - 2 b.v` (+ const) with `A = Q[:3,:3]`, `b = -Q[:3,3]`, by the
    /// truncated pseudo-inverse around the centre c: v = c + A+ (b - A c). A is
    /// symmetric positive semi-definite, so its SVD is its eigen-decomposition.
    fn point(&self, c: DVec3) -> DVec3 {
        let q = &self.0;
        let a = [[q[0], q[1], q[2]], [q[1], q[4], q[5]], [q[2], q[5], q[7]]];
        let b = -DVec3::new(q[3], q[6], q[8]);
        let ac = DVec3::new(
            a[0][0] * c.x + a[0][1] * c.y + a[0][2] * c.z,
            a[1][0] * c.x + a[1][1] * c.y + a[1][2] * c.z,
            a[2][0] * c.x + a[2][1] * c.y + a[2][2] * c.z,
        );
        let rhs = b - ac;
        let (values, vectors) = symmetric_eigen(a);
        let s_max = values.iter().fold(0.0f64, |m, s| m.max(s.abs()));
        let mut v = c;
        if s_max > 0.0 {
            for (s, e) in values.iter().zip(&vectors) {
                if s.abs() > QEM_RELATIVE_THRESHOLD * s_max {
                    v += *e * (e.dot(rhs) / s);
                }
            }
        }
        if v.is_finite() {
            v
        } else {
            c
        }
    }
}

/// Plain mean of the children's points (normalised units).
#[derive(Clone, Copy, Debug)]
pub(super) struct MeanPoint(pub(super) DVec3);

impl PointRule for MeanPoint {
    fn from_sample(p: DVec3, _n: DVec3) -> Self {
        MeanPoint(p)
    }
    fn add(&mut self, o: &Self) {
        self.0 += o.0;
    }
    fn scale(&mut self, s: f64) {
        self.0 *= s;
    }
    fn point(&self, _c: DVec3) -> DVec3 {
        self.0
    }
}

/// Eigenvalues and unit eigenvectors of a symmetric 3x3 matrix (cyclic Jacobi;
/// converges to machine precision in a handful of sweeps).
pub(super) fn symmetric_eigen(mut a: [[f64; 3]; 3]) -> ([f64; 3], [DVec3; 3]) {
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let scale = a.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    for _ in 0..50 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        if off <= 1e-18 * scale || off == 0.0 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let cs = 1.0 / (t * t + 1.0).sqrt();
            let sn = t * cs;
            // A <- J^T A J: columns p, q, then rows p, q.
            for row in &mut a {
                let (akp, akq) = (row[p], row[q]);
                row[p] = cs * akp - sn * akq;
                row[q] = sn * akp + cs * akq;
            }
            let (rp, rq) = (a[p], a[q]);
            a[p] = std::array::from_fn(|k| cs * rp[k] - sn * rq[k]);
            a[q] = std::array::from_fn(|k| sn * rp[k] + cs * rq[k]);
            for row in &mut v {
                let (vkp, vkq) = (row[p], row[q]);
                row[p] = cs * vkp - sn * vkq;
                row[q] = sn * vkp + cs * vkq;
            }
        }
    }
    let col = |j: usize| DVec3::new(v[0][j], v[1][j], v[2][j]);
    ([a[0][0], a[1][1], a[2][2]], [col(0), col(1), col(2)])
}

/// A pooled voxel: means of its children's normals (not renormalised, as the
/// reference code), colours and point rule.
#[derive(Clone, Copy, Debug)]
pub(super) struct Node<G> {
    pub(super) key: u64,
    pub(super) normal: Vec3,
    pub(super) colour: Vec3,
    pub(super) geom: G,
}

/// Pools `n` Morton-sorted children into their parents (`key >> 3`), keeping the
/// parents sorted. Each parent is the plain mean over its active children.
pub(super) fn pool<G: PointRule>(
    n: usize,
    key: impl Fn(usize) -> u64 + Sync,
    child: impl Fn(usize) -> Node<G> + Sync,
) -> Vec<Node<G>> {
    let starts = group_starts(n, |i| key(i) >> 3);
    starts
        .par_windows(2)
        .map(|g| {
            let mut acc = child(g[0]);
            for i in g[0] + 1..g[1] {
                let c = child(i);
                acc.normal += c.normal;
                acc.colour += c.colour;
                acc.geom.add(&c.geom);
            }
            let inv = 1.0 / (g[1] - g[0]) as f64;
            acc.normal *= inv as f32;
            acc.colour *= inv as f32;
            acc.geom.scale(inv);
            acc.key >>= 3;
            acc
        })
        .collect()
}
