//! Shapes onto the evaluation lattice: solid voxelisation of a mesh by its
//! winding number plus the voxels its surface passes through
//! ([`voxelise_mesh`]), the surface of an open mesh alone
//! ([`voxelise_mesh_surface`]), and the voxels that hold the points of a
//! point set ([`voxelise_points`], [`voxelise_normalised_points`]).

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use super::occupancy::{set_range, Occupancy, OccupancyGrid};
use crate::io::mesh::Mesh;

/// Fixed-point scale for the exact crossing test: lattice coordinates are
/// snapped to multiples of 2^-20 voxel, then all orientation tests are exact
/// integer arithmetic (i128).
const FIXED_BITS: u32 = 20;

/// Per-triangle data for the column sweep.
struct SweepTri {
    /// Lattice coordinates (f64), for crossing positions and surface clipping.
    p: [DVec3; 3],
    /// Fixed-point (y, z) of the vertices, for the exact inside test.
    q: [[i64; 2]; 3],
    /// Twice the signed (y, z)-projected area in fixed point = the sign of the
    /// normal's x component. 0 for triangles seen edge-on from +x.
    area2: i128,
}

/// Solid voxelisation of a mesh (world units) on `grid`'s lattice.
///
/// A voxel is occupied when |winding number| > 0.5 at its centre, or when the
/// surface passes through it (see the [`metrics`](super) module documentation
/// for why).
///
/// Winding number: for each voxel column (fixed y, z) a ray along +x through the
/// voxel centres is intersected with the triangles whose projection covers the
/// column (triangles are binned by column first). Each crossing counts -1 where
/// the triangle faces -x (the ray enters an outward-oriented solid) and +1 where
/// it faces +x; the winding number at a centre is minus the sum of the crossings
/// before it plus half the total, i.e. the mean of the counts from the -x and the
/// +x end. For a closed
/// mesh the total is 0 and this is the exact winding number; rays through edges
/// and vertices are resolved by symbolic perturbation in exact integer arithmetic,
/// so no crossing is counted twice or missed. For open meshes the two ends
/// disagree and the mean is only an approximation of the generalised winding
/// number (columns through a hole get 1/2 and stay empty); the surface voxels
/// still keep the sheet itself.
///
/// The absolute value (deviation from the paper's "winding number > 0.5", docs/method.md section 9) makes a
/// mesh with all faces flipped inward voxelise to the same solid as the correctly
/// oriented one (winding -1 inside); meshes with consistent orientation are not
/// affected.
///
/// Cost: parallel over columns; memory one bit per voxel plus the binned
/// (triangle, column) pairs.
pub fn voxelise_mesh(mesh: &Mesh, grid: &OccupancyGrid) -> Occupancy {
    voxelise_mesh_with(mesh, grid, true)
}

fn voxelise_mesh_with(mesh: &Mesh, grid: &OccupancyGrid, with_surface: bool) -> Occupancy {
    voxelise_mesh_fill(mesh, grid, with_surface, true)
}

fn voxelise_mesh_fill(mesh: &Mesh, grid: &OccupancyGrid, with_surface: bool, fill_inside: bool) -> Occupancy {
    let mut occ = Occupancy::empty(grid.dims);
    let [nx, ny, nz] = grid.dims.map(|d| d as usize);
    if nx == 0 || ny == 0 || nz == 0 {
        return occ;
    }
    let fixed = (1u64 << FIXED_BITS) as f64;
    let lattice: Vec<DVec3> = mesh.positions.iter().map(|&p| grid.world_to_grid(p)).collect();
    let snap = |v: f64| -> i64 { (v * fixed).round().clamp(-(1i64 << 60) as f64, (1i64 << 60) as f64) as i64 };

    // Triangles and their column ranges (columns whose square the bbox touches).
    let mut tris: Vec<SweepTri> = Vec::with_capacity(mesh.triangles.len());
    let mut ranges: Vec<[usize; 4]> = Vec::with_capacity(mesh.triangles.len());
    for t in &mesh.triangles {
        let Some(p) = t.iter().map(|&i| lattice.get(i as usize).copied()).collect::<Option<Vec<_>>>() else {
            continue;
        };
        if p.iter().any(|v| !v.is_finite()) {
            continue;
        }
        let p = [p[0], p[1], p[2]];
        let (lo, hi) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
        if hi.y < 0.0 || hi.z < 0.0 || lo.y >= ny as f64 || lo.z >= nz as f64 {
            continue;
        }
        let r = [
            lo.y.floor().max(0.0) as usize,
            (hi.y.floor() as i64).clamp(0, ny as i64 - 1) as usize,
            lo.z.floor().max(0.0) as usize,
            (hi.z.floor() as i64).clamp(0, nz as i64 - 1) as usize,
        ];
        let q = p.map(|v| [snap(v.y), snap(v.z)]);
        let area2 = orient(q[0], q[1], q[2]);
        tris.push(SweepTri { p, q, area2 });
        ranges.push(r);
    }

    // Bin triangles by column (CSR).
    let columns = ny * nz;
    let mut start = vec![0u32; columns + 1];
    for r in &ranges {
        for k in r[2]..=r[3] {
            for j in r[0]..=r[1] {
                start[j + ny * k + 1] += 1;
            }
        }
    }
    for c in 0..columns {
        start[c + 1] += start[c];
    }
    let mut fill = start.clone();
    let mut binned = vec![0u32; start[columns] as usize];
    for (t, r) in ranges.iter().enumerate() {
        for k in r[2]..=r[3] {
            for j in r[0]..=r[1] {
                let c = j + ny * k;
                binned[fill[c] as usize] = t as u32;
                fill[c] += 1;
            }
        }
    }
    drop(fill);
    log::debug!("voxelise: {} triangles, {} (triangle, column) pairs on {:?}", tris.len(), binned.len(), grid.dims);

    let w = occ.words_per_row();
    occ.bits.par_chunks_mut(w).enumerate().for_each_init(Vec::new, |crossings, (c, row)| {
        let (j, k) = (c % ny, c / ny);
        let list = &binned[start[c] as usize..start[c + 1] as usize];
        if list.is_empty() {
            return;
        }
        let ray = [((2 * j as i64 + 1) << (FIXED_BITS - 1)), ((2 * k as i64 + 1) << (FIXED_BITS - 1))];
        crossings.clear();
        for &t in list {
            let tri = &tris[t as usize];
            if fill_inside && tri.area2 != 0 {
                if let Some(x) = ray_crossing(tri, ray) {
                    crossings.push((x, if tri.area2 > 0 { 1i32 } else { -1 }));
                }
            }
            if with_surface {
                if let Some((x0, x1)) = clip_x_range(&tri.p, j as f64, k as f64) {
                    if x1 >= 0.0 && x0 < nx as f64 {
                        let lo = x0.floor().max(0.0) as usize;
                        let hi = (x1.floor() as i64).min(nx as i64 - 1) as usize;
                        set_range(row, lo, hi);
                    }
                }
            }
        }
        if crossings.is_empty() {
            return;
        }
        crossings.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        let total: i32 = crossings.iter().map(|c| c.1).sum();
        // Twice the winding number before the first crossing: 0 from the -x end
        // plus total/2 (mean with the count from the +x end).
        let mut w2 = total;
        let mut prev = f64::NEG_INFINITY;
        for m in 0..=crossings.len() {
            let next = crossings.get(m).map_or(f64::INFINITY, |c| c.0);
            // Voxel centres i + 0.5 in (prev, next].
            if w2.abs() > 1 {
                let lo = if prev == f64::NEG_INFINITY { 0 } else { (prev - 0.5).floor() as i64 + 1 };
                let hi = if next == f64::INFINITY { nx as i64 - 1 } else { (next - 0.5).floor() as i64 };
                let (lo, hi) = (lo.max(0), hi.min(nx as i64 - 1));
                if lo <= hi {
                    set_range(row, lo as usize, hi as usize);
                }
            }
            if let Some(c) = crossings.get(m) {
                // Entering through a face whose normal points to -x raises it.
                w2 -= 2 * c.1;
                prev = c.0;
            }
        }
    });
    occ
}

/// Twice the signed area of (u, v, p) in the (y, z) plane, exact.
fn orient(u: [i64; 2], v: [i64; 2], p: [i64; 2]) -> i128 {
    (v[0] - u[0]) as i128 * (p[1] - u[1]) as i128 - (v[1] - u[1]) as i128 * (p[0] - u[0]) as i128
}

/// Sign of the edge function of edge u -> v at p, with zeros resolved by the
/// symbolic perturbation p + eps * (1, eps'): consistent for the two triangles
/// sharing an edge (opposite directions give opposite signs).
fn edge_sign(u: [i64; 2], v: [i64; 2], p: [i64; 2]) -> i32 {
    let o = orient(u, v, p);
    if o != 0 {
        return if o > 0 { 1 } else { -1 };
    }
    let (ey, ez) = (v[0] - u[0], v[1] - u[1]);
    if ez != 0 {
        if ez > 0 {
            -1
        } else {
            1
        }
    } else if ey > 0 {
        1
    } else {
        -1
    }
}

/// Where the +x ray through `ray` (fixed-point y, z) crosses the triangle, in
/// lattice x, or None.
fn ray_crossing(tri: &SweepTri, ray: [i64; 2]) -> Option<f64> {
    let s = if tri.area2 > 0 { 1 } else { -1 };
    let [a, b, c] = tri.q;
    if edge_sign(a, b, ray) != s || edge_sign(b, c, ray) != s || edge_sign(c, a, ray) != s {
        return None;
    }
    // Barycentric weights: the weight of a vertex is the area opposite it.
    let la = orient(b, c, ray) as f64;
    let lb = orient(c, a, ray) as f64;
    let lc = orient(a, b, ray) as f64;
    let sum = tri.area2 as f64;
    Some((la * tri.p[0].x + lb * tri.p[1].x + lc * tri.p[2].x) / sum)
}

/// The x extent of the part of a triangle (lattice coordinates) inside the
/// column `[j, j+1] x [k, k+1]` in (y, z), or None if it misses the column.
fn clip_x_range(p: &[DVec3; 3], j: f64, k: f64) -> Option<(f64, f64)> {
    let mut poly = [DVec3::ZERO; 9];
    let mut n = 3;
    poly[..3].copy_from_slice(p);
    let mut tmp = [DVec3::ZERO; 9];
    // Half-planes as (axis, bound, keep >= bound?).
    for (axis, bound, above) in [(1usize, j, true), (1, j + 1.0, false), (2, k, true), (2, k + 1.0, false)] {
        let inside = |v: &DVec3| if above { v[axis] >= bound } else { v[axis] <= bound };
        let mut m = 0;
        for i in 0..n {
            let (cur, nxt) = (poly[i], poly[(i + 1) % n]);
            let (ci, ni) = (inside(&cur), inside(&nxt));
            if ci {
                tmp[m] = cur;
                m += 1;
            }
            if ci != ni {
                let t = (bound - cur[axis]) / (nxt[axis] - cur[axis]);
                let mut v = cur + (nxt - cur) * t;
                v[axis] = bound;
                tmp[m] = v;
                m += 1;
            }
        }
        n = m;
        if n == 0 {
            return None;
        }
        poly[..n].copy_from_slice(&tmp[..n]);
    }
    let (lo, hi) = poly[..n].iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v.x), hi.max(v.x)));
    Some((lo, hi))
}

/// Surface-only occupancy of a point set given in normalised units (the
/// lattice's own), e.g.
/// [`level_points_normalised`](super::level_points_normalised). Points
/// outside the lattice are dropped.
pub fn voxelise_normalised_points(positions: &[Vec3], grid: &OccupancyGrid) -> Occupancy {
    let mut occ = Occupancy::empty(grid.dims);
    for &p in positions {
        let g = ((p - grid.origin) / grid.voxel).floor();
        if g.is_finite() {
            occ.set(g.x as i64, g.y as i64, g.z as i64);
        }
    }
    occ
}

/// The voxels a mesh's surface passes through, nothing filled: how an OPEN
/// surface is voxelised (a sheet stays a sheet; the winding number of a
/// surface with holes does not say what is inside).
pub fn voxelise_mesh_surface(mesh: &Mesh, grid: &OccupancyGrid) -> Occupancy {
    voxelise_mesh_fill(mesh, grid, true, false)
}

/// Surface-only occupancy of a point set (world units, e.g.
/// [`Level::point_world`](crate::level::Level::point_world) of a coarse
/// level): the voxels that contain a point. Nothing is filled, so compare it
/// only with other point-set occupancies.
pub fn voxelise_points(positions: &[Vec3], grid: &OccupancyGrid) -> Occupancy {
    let mut occ = Occupancy::empty(grid.dims);
    for &p in positions {
        let g = grid.world_to_grid(p);
        if g.is_finite() {
            let f = g.floor();
            occ.set(f.x as i64, f.y as i64, f.z as i64);
        }
    }
    occ
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::metrics::test_shapes::{cube, sphere, unit_grid};
    use crate::io::mesh::MeshColours;
    use crate::level::Frame;

    fn mesh(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Mesh {
        Mesh { name: "t".into(), positions, triangles, colours: MeshColours::None, texture: None }
    }

    fn signed_volume(m: &Mesh) -> f32 {
        crate::testing::shapes::signed_volume(&m.positions, &m.triangles)
    }

    #[test]
    fn helper_meshes_are_outward() {
        assert!(signed_volume(&sphere(Vec3::ZERO, 1.0, 16, 32)) > 0.0);
        assert!(signed_volume(&cube(Vec3::ZERO, Vec3::ONE)) > 0.0);
    }

    #[test]
    fn sphere_volume_and_empty_outside() {
        // Sphere of radius 0.8 normalised; grid 256 voxels along its diameter.
        let r = 0.8f32;
        let m = sphere(Vec3::ZERO, r, 128, 256);
        let grid = OccupancyGrid::for_exemplar(&m, Frame::default(), 256);
        assert!((grid.voxel - 2.0 * r / 256.0).abs() < 1e-6);
        let occ = voxelise_mesh(&m, &grid);
        let rv = r / grid.voxel; // radius in voxels (128)
        let exact = 4.0 / 3.0 * std::f64::consts::PI * (rv as f64).powi(3);
        let vol = occ.count() as f64;
        assert!((vol / exact - 1.0).abs() < 0.02, "volume {vol} vs {exact}");
        // Interior by winding number only: much closer.
        let solid = voxelise_mesh_with(&m, &grid, false).count() as f64;
        assert!((solid / exact - 1.0).abs() < 0.005, "solid volume {solid} vs {exact}");
        // Empty outside (beyond the radius + a voxel's half-diagonal), full inside.
        for v in occ.surface().voxels() {
            let c = grid.origin + (Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32) + 0.5) * grid.voxel;
            assert!(c.length() / grid.voxel <= rv + 0.87, "occupied voxel {v:?} outside the sphere");
        }
        let [nx, ny, nz] = grid.dims.map(|d| d as i64);
        for z in (0..nz).step_by(3) {
            for y in (0..ny).step_by(3) {
                for x in 0..nx {
                    let c = grid.origin + (Vec3::new(x as f32, y as f32, z as f32) + 0.5) * grid.voxel;
                    if c.length() / grid.voxel < rv - 1.0 {
                        assert!(occ.get(x, y, z), "inside voxel ({x},{y},{z}) empty");
                    }
                }
            }
        }
    }

    #[test]
    fn cube_on_voxel_centres_is_exact_and_flip_invariant() {
        // Faces exactly on voxel-centre planes: rays hit edges and vertices, the
        // exact test must neither double count nor miss (no streaks).
        let res = 64;
        let grid = unit_grid(res);
        let g = |i: f32| i * grid.voxel - 1.0; // lattice coordinate -> normalised
        let (lo, hi) = (Vec3::new(g(10.5), g(20.5), g(30.5)), Vec3::new(g(40.5), g(33.5), g(50.5)));
        let m = cube(lo, hi);
        let occ = voxelise_mesh_with(&m, &grid, false);
        // Along x a centre exactly on the entry face (10.5) is outside, on the exit
        // face (40.5) inside; columns on the y/z faces are decided by the symbolic
        // perturbation (+y, then +z): the low faces are in, the high faces out.
        let mut expect = Occupancy::empty(grid.dims);
        for z in 30..=49 {
            for y in 20..=32 {
                for x in 11..=40 {
                    expect.set(x, y, z);
                }
            }
        }
        assert_eq!(occ.count(), expect.count());
        assert_eq!(occ, expect);
        // With the surface: exactly the box of voxels the closed cube touches.
        let full = voxelise_mesh(&m, &grid);
        let mut touched = Occupancy::empty(grid.dims);
        for z in 30..=50 {
            for y in 20..=33 {
                for x in 10..=40 {
                    touched.set(x, y, z);
                }
            }
        }
        assert_eq!(full, touched);

        // Inward-flipped: the winding number is -1 inside; |w| > 0.5 gives the same solid.
        let mut flipped = m.clone();
        flipped.triangles.iter_mut().for_each(|t| t.swap(1, 2));
        assert!(signed_volume(&flipped) < 0.0);
        assert_eq!(voxelise_mesh_with(&flipped, &grid, false), occ);
        assert_eq!(voxelise_mesh(&flipped, &grid), full);
    }

    #[test]
    fn open_sheet_keeps_its_surface_voxels() {
        let grid = unit_grid(32);
        let sheet = mesh(
            vec![
                Vec3::new(-0.5, -0.5, 0.01),
                Vec3::new(0.5, -0.5, 0.01),
                Vec3::new(0.5, 0.5, 0.01),
                Vec3::new(-0.5, 0.5, 0.01),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        let occ = voxelise_mesh(&sheet, &grid);
        // One voxel thick, 16 x 16 (plus the boundary row of touched voxels).
        assert!(occ.count() >= 16 * 16 && occ.count() <= 17 * 17, "{}", occ.count());
        assert!(voxelise_mesh_with(&sheet, &grid, false).count() == 0);
    }

    #[test]
    fn points_voxelise_to_their_voxels() {
        let grid = unit_grid(16);
        let occ =
            voxelise_points(&[Vec3::new(-0.99, -0.99, -0.99), Vec3::new(0.01, 0.01, 0.01), Vec3::splat(5.0)], &grid);
        assert_eq!(occ.voxels(), vec![[0, 0, 0], [8, 8, 8]]);
    }

    #[test]
    fn surface_voxelisation_keeps_sheets_and_hollows_solids() {
        let grid = unit_grid(32);
        let b = cube(Vec3::splat(-0.5), Vec3::splat(0.5));
        let solid = voxelise_mesh(&b, &grid);
        let shell = voxelise_mesh_surface(&b, &grid);
        // 16^3 cube (plus the touched boundary layer) vs its one-voxel shell.
        assert!(solid.count() >= 16 * 16 * 16, "{}", solid.count());
        assert!(shell.count() < solid.count() / 2 && shell.count() >= 6 * 15 * 15, "{}", shell.count());
        assert!(!shell.get(16, 16, 16), "nothing inside");
        // An open sheet: the same voxels whichever way (nothing to fill).
        let sheet = mesh(
            vec![Vec3::new(-0.5, -0.5, 0.01), Vec3::new(0.5, -0.5, 0.01), Vec3::new(0.5, 0.5, 0.01), Vec3::new(-0.5, 0.5, 0.01)],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        assert_eq!(voxelise_mesh_surface(&sheet, &grid), voxelise_mesh(&sheet, &grid));
    }
}
