//! Local-patch plausibility (DECOR-GAN, SSG): 11^3 patches of a shape, each
//! matched against every patch of the exemplar's dictionary
//! ([`ExemplarPatches`]) for its best IoU and best boundary F-score; their
//! means and fractions above a threshold are LP-IoU and LP-F-score
//! ([`local_patch_scores`]). The maxima are exact: upper bounds from slab
//! histograms skip the patches that cannot beat the best so far.

use std::collections::HashMap;

use rayon::prelude::*;

use crate::grid::occupancy::{same_lattice, Occupancy};
use crate::util::rng::Rng;

/// Patch edge, voxels (DECOR-GAN / SSG: 11).
pub const PATCH: usize = 11;
const HALF: i64 = (PATCH / 2) as i64;
/// u64 words per 11^3 = 1331-bit patch.
pub const PATCH_WORDS: usize = (PATCH * PATCH * PATCH).div_ceil(64);

/// Parameters of the local-patch measures.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct LpParams {
    /// Spacing, in voxels, of the variant's patch centres (SSG: 5).
    pub variant_stride: u32,
    /// At most this many variant patches are scored (DECOR-GAN, SSG: 1000).
    pub max_patches: usize,
    /// Spacing of the exemplar's patch centres. 1 (default) = a patch on every
    /// surface voxel, which makes the measure exactly invariant to whole-voxel
    /// translations; 2 keeps one per 2^3 cell: ~3x fewer patches, but no
    /// longer translation invariant and slightly lower scores (bench: LP-IoU
    /// 0.954 vs 0.958, fraction > 0.95 0.73 vs 0.78).
    pub exemplar_stride: u32,
    /// A patch is "plausible" when its best score is above this (0.95).
    pub threshold: f64,
    /// Seed of the deterministic patch sampling.
    pub seed: u64,
}

impl Default for LpParams {
    fn default() -> Self {
        LpParams { variant_stride: 5, max_patches: 1000, exemplar_stride: 1, threshold: 0.95, seed: 1234 }
    }
}

/// One 11^3 patch in three bit layers. Bit `dx + 11 * (dy + 11 * dz)` is voxel
/// `centre + (dx, dy, dz) - 5`.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[repr(C, align(64))]
struct Patch {
    /// Occupancy.
    occ: [u64; PATCH_WORDS],
    /// DECOR-GAN boundary voxels (occupied with an empty 26-neighbour).
    edge: [u64; PATCH_WORDS],
    /// Boundary dilated by the 3^3 box (within 1 voxel, Chebyshev, of a boundary voxel).
    dil: [u64; PATCH_WORDS],
    occ_n: u32,
    edge_n: u32,
}

/// Slab histograms of a patch: for each layer (occupancy, boundary, dilated
/// boundary) and each axis, the number of set voxels in each of the 11 slabs
/// across that axis (padded to 16 bytes). `sum_s min(a_s, b_s)` over any axis
/// bounds `|A and B|` from above, which prunes most exemplar patches cheaply.
#[derive(Clone, Copy)]
#[repr(C, align(16))]
struct Sig {
    occ: [[u8; 16]; 3],
    edge: [[u8; 16]; 3],
    dil: [[u8; 16]; 3],
    /// Copies of the patch's counts, so the bound needs nothing else.
    occ_n: u32,
    edge_n: u32,
}

/// `SPREAD[b]` has byte i = bit i of `b`: adding these counts bits per position.
const SPREAD: [u64; 256] = {
    let mut t = [0u64; 256];
    let mut b = 0;
    while b < 256 {
        let mut i = 0;
        while i < 8 {
            if b >> i & 1 == 1 {
                t[b] |= 1u64 << (8 * i);
            }
            i += 1;
        }
        b += 1;
    }
    t
};

impl Sig {
    #[allow(clippy::needless_range_loop)] // parallel indices read best as loops
    fn of(p: &Patch) -> Sig {
        let mut s = Sig { occ: [[0; 16]; 3], edge: [[0; 16]; 3], dil: [[0; 16]; 3], occ_n: p.occ_n, edge_n: p.edge_n };
        for (words, hist) in [(&p.occ, &mut s.occ), (&p.edge, &mut s.edge), (&p.dil, &mut s.dil)] {
            // Row r = dy + 11 dz holds the 11 voxels along x at bits 11r ..
            let (mut lo, mut hi) = (0u64, 0u64);
            for r in 0..PATCH * PATCH {
                let bit = PATCH * r;
                let (wi, off) = (bit / 64, bit % 64);
                let mut v = words[wi] >> off;
                if off + PATCH > 64 {
                    v |= words[wi + 1] << (64 - off);
                }
                let v = v & ((1u64 << PATCH) - 1);
                let n = v.count_ones() as u8;
                hist[1][r % PATCH] += n;
                hist[2][r / PATCH] += n;
                lo += SPREAD[(v & 0xff) as usize];
                hi += SPREAD[(v >> 8) as usize];
            }
            for i in 0..8 {
                hist[0][i] = (lo >> (8 * i)) as u8;
            }
            for i in 0..PATCH - 8 {
                hist[0][8 + i] = (hi >> (8 * i)) as u8;
            }
        }
        s
    }
}

/// Exemplar patches per [`SigTile`]: one AVX2 register of u8 lanes.
const LANES: usize = 32;

/// The slab histograms of up to 32 consecutive dictionary patches, transposed
/// (lane = patch), so the bounds of a variant patch against all of them are a
/// few vector instructions per slab. Unused lanes are zero (bound 0, never
/// compared).
#[derive(Clone)]
#[repr(C, align(32))]
struct SigTile {
    /// `[layer: occupancy, boundary, dilated][axis][slab][lane]`.
    hist: [[[[u8; LANES]; PATCH]; 3]; 3],
    occ_n: [f32; LANES],
    edge_n: [f32; LANES],
}

impl SigTile {
    #[allow(clippy::needless_range_loop)] // parallel indices read best as loops
    fn new(sigs: &[Sig]) -> SigTile {
        let mut t = SigTile { hist: [[[[0; LANES]; PATCH]; 3]; 3], occ_n: [0.0; LANES], edge_n: [0.0; LANES] };
        for (l, s) in sigs.iter().enumerate().take(LANES) {
            for (layer, h) in [&s.occ, &s.edge, &s.dil].into_iter().enumerate() {
                for axis in 0..3 {
                    for slab in 0..PATCH {
                        t.hist[layer][axis][slab][l] = h[axis][slab];
                    }
                }
            }
            t.occ_n[l] = s.occ_n as f32;
            t.edge_n[l] = s.edge_n as f32;
        }
        t
    }

    /// Per lane, the tightest over the three axes of `sum_slab min(a, b)`, for
    /// variant histogram `a` against this tile's layer `layer`: an upper bound of
    /// `|A and B|`.
    #[inline(always)]
    #[allow(clippy::needless_range_loop)] // parallel indices read best as loops
    fn overlap_bound(&self, a: &[[u8; 16]; 3], layer: usize) -> [f32; LANES] {
        let mut best = [u16::MAX; LANES];
        for axis in 0..3 {
            let mut acc = [0u16; LANES];
            for slab in 0..PATCH {
                let av = a[axis][slab];
                let row = &self.hist[layer][axis][slab];
                for l in 0..LANES {
                    acc[l] += av.min(row[l]) as u16;
                }
            }
            for l in 0..LANES {
                best[l] = best[l].min(acc[l]);
            }
        }
        best.map(|v| v as f32)
    }
}

/// The layers patches are cut from, computed once per shape on the whole lattice
/// (so the boundary and its dilation see the voxels just outside a patch).
struct PatchLayers {
    occ: Occupancy,
    edge: Occupancy,
    dil: Occupancy,
    surface: Occupancy,
}

impl PatchLayers {
    fn new(occ: &Occupancy) -> Self {
        let edge = occ.boundary26();
        let dil = edge.dilate26();
        let surface = occ.surface();
        PatchLayers { occ: occ.clone(), edge, dil, surface }
    }

    fn patch(&self, c: [u32; 3]) -> Patch {
        let mut p = Patch { occ: [0; PATCH_WORDS], edge: [0; PATCH_WORDS], dil: [0; PATCH_WORDS], occ_n: 0, edge_n: 0 };
        let [cx, cy, cz] = c.map(|v| v as i64);
        for dz in 0..PATCH {
            for dy in 0..PATCH {
                let (y, z) = (cy + dy as i64 - HALF, cz + dz as i64 - HALF);
                let bit = PATCH * (dy + PATCH * dz);
                for (layer, dst) in [(&self.occ, &mut p.occ), (&self.edge, &mut p.edge), (&self.dil, &mut p.dil)] {
                    let v = layer.row_bits(y, z, cx - HALF, PATCH as u32);
                    if v != 0 {
                        let (wi, off) = (bit / 64, bit % 64);
                        dst[wi] |= v << off;
                        if off + PATCH > 64 {
                            dst[wi + 1] |= v >> (64 - off);
                        }
                    }
                }
            }
        }
        p.occ_n = p.occ.iter().map(|w| w.count_ones()).sum();
        p.edge_n = p.edge.iter().map(|w| w.count_ones()).sum();
        p
    }

    /// Patch centres: surface voxels, one per `stride`^3 cell of the lattice (the
    /// one nearest the cell's centre, ties to the first in storage order);
    /// stride 1 = every surface voxel. Sorted in storage order.
    fn centres(&self, stride: u32) -> Vec<[u32; 3]> {
        let surface = self.surface.voxels();
        if stride <= 1 {
            return surface;
        }
        let s = stride;
        let mid = (s - 1) as i64; // twice the cell centre offset
        let mut best: HashMap<[u32; 3], (i64, usize)> = HashMap::new();
        for (i, v) in surface.iter().enumerate() {
            let cell = v.map(|c| c / s);
            let d: i64 = v.iter().map(|&c| (2 * (c % s) as i64 - mid).pow(2)).sum();
            best.entry(cell)
                .and_modify(|b| {
                    if d < b.0 {
                        *b = (d, i)
                    }
                })
                .or_insert((d, i));
        }
        let mut idx: Vec<usize> = best.into_values().map(|b| b.1).collect();
        idx.sort_unstable();
        idx.into_iter().map(|i| surface[i]).collect()
    }
}

/// The exemplar's patch dictionary, built once and reused for every variant.
/// Memory: about 610 bytes per distinct patch (three 1331-bit layers, counts and
/// slab histograms): ~100 MB for a 256-grid exemplar with 167k surface voxels.
pub struct ExemplarPatches {
    /// Distinct patches, sorted (so an exact match is a binary search).
    patches: Vec<Patch>,
    /// Slab histograms of `patches`, 32 per tile, for the bounds.
    tiles: Vec<SigTile>,
    /// Surface voxels the patches were centred on (before removing duplicates).
    pub centres: usize,
}

impl ExemplarPatches {
    /// Patches centred on the exemplar's surface voxels (every one for
    /// `stride = 1`), identical patches kept once (the best match is unchanged).
    pub fn new(exemplar: &Occupancy, stride: u32) -> Self {
        let layers = PatchLayers::new(exemplar);
        let centres = layers.centres(stride);
        let all: Vec<Patch> = centres.par_iter().map(|&c| layers.patch(c)).collect();
        // Sort and deduplicate indices (moving 512-byte patches around is slow).
        let mut order: Vec<u32> = (0..all.len() as u32).collect();
        order.par_sort_unstable_by(|&i, &j| all[i as usize].cmp(&all[j as usize]));
        order.dedup_by(|i, j| all[*i as usize] == all[*j as usize]);
        let patches: Vec<Patch> = order.par_iter().map(|&i| all[i as usize]).collect();
        drop(all);
        let tiles =
            patches.par_chunks(LANES).map(|c| SigTile::new(&c.iter().map(Sig::of).collect::<Vec<_>>())).collect();
        log::debug!("exemplar patches: {} centres, {} distinct", centres.len(), patches.len());
        ExemplarPatches { patches, tiles, centres: centres.len() }
    }

    /// Distinct patches in the dictionary.
    pub fn len(&self) -> usize {
        self.patches.len()
    }

    pub fn is_empty(&self) -> bool {
        self.patches.is_empty()
    }
}

/// Scores of one shape's local patches against an exemplar.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LpScores {
    /// Mean over the variant's patches of the best IoU with any exemplar patch.
    pub lp_iou: f64,
    /// Fraction of the variant's patches whose best IoU is > threshold.
    pub lp_iou_above: f64,
    /// Mean over the variant's patches of the best boundary F-score.
    pub lp_fscore: f64,
    /// Fraction of the variant's patches whose best F-score is > threshold.
    pub lp_fscore_above: f64,
    /// Number of variant patches scored.
    pub patches: usize,
}

/// The best match so far of one variant patch, as exact fractions.
#[derive(Clone, Copy)]
struct Best {
    iou_num: u32,
    iou_den: u32,
    f_num: u64,
    f_den: u64,
}

impl Default for Best {
    fn default() -> Self {
        Best { iou_num: 0, iou_den: 1, f_num: 0, f_den: 1 }
    }
}

impl Best {
    fn iou(&self) -> f64 {
        self.iou_num as f64 / self.iou_den as f64
    }
    fn fscore(&self) -> f64 {
        self.f_num as f64 / self.f_den as f64
    }
}

/// LP-IoU and LP-F-score of `variant` against the exemplar's patch dictionary.
///
/// What is computed (all in voxels of the shared lattice):
/// 1. Surface voxels of the variant: occupied with an unoccupied 6-neighbour.
/// 2. Patch centres: one surface voxel per 5^3 cell of the lattice
///    (`variant_stride`), the one nearest the cell's centre; if there are more
///    than `max_patches` (1000), that many are drawn without replacement by a
///    seeded Fisher-Yates shuffle (deterministic).
/// 3. Each 11^3 patch (centred on its surface voxel) is matched against EVERY
///    exemplar patch (centred on every exemplar surface voxel, `exemplar_stride`
///    1, duplicates removed) and the best score is kept, separately for each
///    measure. The result is the exhaustive maximum; the speed comes from exact
///    upper bounds that skip most exemplar patches (see `match_patches`):
///    - IoU of the occupied voxels of the two patches;
///    - F-score of boundary voxels, as DECOR-GAN: boundary = occupied voxels with
///      an empty voxel among their 26 neighbours (computed on the whole shape);
///      precision = fraction of the variant patch's boundary voxels within 1 voxel
///      (3^3 box) of an exemplar boundary voxel, recall = fraction of the exemplar
///      patch's boundary voxels within 1 voxel of a variant boundary voxel,
///      F = 2PR / (P + R).
/// 4. LP-IoU = mean best IoU, and the fraction of patches whose best IoU >
///    `threshold` (0.95); LP-F-score likewise. (DECOR-GAN reports only the
///    fraction; SSG reports both.)
///
/// Reading the numbers: the IoU needs the patch to match voxel for voxel, so a
/// one-voxel offset of a flat surface already costs about 15%. The boundary
/// F-score tolerates one voxel and the 26-neighbour boundary of a slanted
/// surface is about 2 voxels thick, so its dilation covers ~half of a patch:
/// it is lenient (random 30%-dense voxels still average ~0.7-0.9, but almost
/// none of their patches pass 0.95), so its "> 0.95" fraction is the telling
/// part.
///
/// Patches reaching past the lattice read empty there. A shape without surface
/// voxels scores 0 with 0 patches. The bounds prune most pairs when the
/// variant is plausible, fewer for shapes with no plausible patches (random
/// voxels).
pub fn local_patch_scores(variant: &Occupancy, exemplar: &ExemplarPatches, params: &LpParams) -> LpScores {
    if exemplar.is_empty() {
        log::warn!("LP scores: the exemplar has no surface voxels");
    }
    let best = best_patch_matches(variant, exemplar, params);
    if best.is_empty() {
        log::warn!("LP scores: the variant has no surface voxels");
    }
    best.summary(params.threshold)
}

/// The best IoU and boundary F-score of each sampled patch of one shape
/// against a dictionary (one entry per sampled patch centre, in the order of
/// [`patch_centres`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PatchMatches {
    pub iou: Vec<f64>,
    pub fscore: Vec<f64>,
}

impl PatchMatches {
    pub fn len(&self) -> usize {
        self.iou.len()
    }

    pub fn is_empty(&self) -> bool {
        self.iou.is_empty()
    }

    /// Means and fractions above `threshold`; all 0 without patches.
    pub fn summary(&self, threshold: f64) -> LpScores {
        let n = self.len().max(1) as f64;
        let above = |v: &[f64]| v.iter().filter(|&&x| x > threshold).count() as f64 / n;
        LpScores {
            lp_iou: self.iou.iter().sum::<f64>() / n,
            lp_iou_above: above(&self.iou),
            lp_fscore: self.fscore.iter().sum::<f64>() / n,
            lp_fscore_above: above(&self.fscore),
            patches: self.len(),
        }
    }

    /// Patch by patch, the better of two match sets of the same centres (the
    /// coverage of an exemplar by a SET of variants: each exemplar patch counts
    /// as found when any variant holds it).
    pub fn max_with(&self, other: &PatchMatches) -> PatchMatches {
        assert_eq!(self.len(), other.len(), "patch matches of different centre sets");
        let m = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x.max(*y)).collect();
        PatchMatches { iou: m(&self.iou, &other.iou), fscore: m(&self.fscore, &other.fscore) }
    }
}

/// The sampled patch centres of a shape: one surface voxel per
/// `variant_stride`^3 cell, at most `max_patches` of them drawn by a seeded
/// Fisher-Yates shuffle (deterministic for a given shape and seed).
fn patch_centres(layers: &PatchLayers, params: &LpParams) -> Vec<[u32; 3]> {
    let mut centres = layers.centres(params.variant_stride);
    if centres.len() > params.max_patches {
        let mut rng = Rng::new(params.seed);
        for i in 0..params.max_patches {
            let j = i + (rng.next_u64() % (centres.len() - i) as u64) as usize;
            centres.swap(i, j);
        }
        centres.truncate(params.max_patches);
    }
    centres
}

/// Best matches of the sampled patches of `shape` in `dict` (see
/// [`local_patch_scores`] for what is sampled and compared). Empty when the
/// shape has no surface voxels; every score 0 when the dictionary is empty.
pub fn best_patch_matches(shape: &Occupancy, dict: &ExemplarPatches, params: &LpParams) -> PatchMatches {
    let layers = PatchLayers::new(shape);
    let best = best_at(&layers, &patch_centres(&layers, params), dict);
    PatchMatches { iou: best.iter().map(Best::iou).collect(), fscore: best.iter().map(Best::fscore).collect() }
}

/// The surface voxels of `shape` whose patch overlaps no patch of `dict` with
/// an IoU of `threshold` or more, in storage order: exactly the voxels whose
/// best IoU over the whole dictionary (the exhaustive maximum the LP matcher
/// finds) is below `threshold` (every voxel when the dictionary is empty),
/// without finding that maximum. A patch stops at its first match of
/// `threshold` (an identical patch, one of 512 evenly spaced seeds, or the
/// first dictionary patch the slab bound lets through that reaches it), so
/// only the patches like nothing in the dictionary are compared with all of
/// it; the IoU bound is the LP matcher's (slab histograms).
pub fn surface_voxels_below_iou(shape: &Occupancy, dict: &ExemplarPatches, threshold: f64) -> Vec<[u32; 3]> {
    let layers = PatchLayers::new(shape);
    let centres = layers.centres(1);
    if dict.is_empty() {
        return centres;
    }
    // The IoU as [`Best::iou`] has it, so a patch exactly at the threshold
    // is decided as there.
    let reaches = |inter: u32, union: u32| union > 0 && inter as f64 / union as f64 >= threshold;
    let below: Vec<bool> = centres
        .par_iter()
        .map(|&c| {
            let pa = layers.patch(c);
            if dict.patches.binary_search(&pa).is_ok() {
                return false;
            }
            let inter = |pb: &Patch| (0..PATCH_WORDS).map(|i| (pa.occ[i] & pb.occ[i]).count_ones()).sum::<u32>();
            let step = dict.patches.len().div_ceil(512).max(1);
            if dict.patches.iter().step_by(step).any(|pb| {
                let n = inter(pb);
                reaches(n, pa.occ_n + pb.occ_n - n)
            }) {
                return false;
            }
            let sig = Sig::of(&pa);
            for (block, tile) in dict.patches.chunks(LANES).zip(&dict.tiles) {
                let u = tile.overlap_bound(&sig.occ, 0);
                for (l, pb) in block.iter().enumerate() {
                    // The bound on the IoU, u / (|A| + |B| - u), first.
                    let ub = u[l] as u32;
                    if reaches(ub, pa.occ_n + pb.occ_n - ub) {
                        let n = inter(pb);
                        if reaches(n, pa.occ_n + pb.occ_n - n) {
                            return false;
                        }
                    }
                }
            }
            true
        })
        .collect();
    centres.into_iter().zip(below).filter(|(_, b)| *b).map(|(c, _)| c).collect()
}

/// The best match in `dict` of the patch centred on each of `centres` (every
/// score 0 when the dictionary is empty).
fn best_at(layers: &PatchLayers, centres: &[[u32; 3]], dict: &ExemplarPatches) -> Vec<Best> {
    if centres.is_empty() || dict.is_empty() {
        return vec![Best::default(); centres.len()];
    }
    let patches: Vec<Patch> = centres.par_iter().map(|&c| layers.patch(c)).collect();
    match_patches(&patches, dict)
}

/// Convenience: [`local_patch_scores`] with a fresh exemplar dictionary.
pub fn lp_scores(variant: &Occupancy, exemplar: &Occupancy, params: &LpParams) -> LpScores {
    same_lattice(variant, exemplar);
    local_patch_scores(variant, &ExemplarPatches::new(exemplar, params.exemplar_stride), params)
}

/// Best IoU and best F-score of every patch of `a` over all patches of the
/// dictionary `b`. Exact (the result equals the exhaustive maximum), made fast by:
/// - an exact match (binary search in the sorted dictionary) scores 1 and 1 at once;
/// - the best scores are seeded with an evenly spaced sample of 512 dictionary
///   patches, then every dictionary patch is first checked against upper bounds of
///   its IoU and F-score and compared bit by bit only when a bound could beat the
///   best so far. With slab histograms ([`Sig`]), `|A and B| <= U = min over the 3
///   axes of sum_slab min(a_slab, b_slab)`, so `IoU <= U / (|A| + |B| - U)`; the
///   same bound on `|Ea and Db|` and `|Da and Eb|` bounds the F-score (it grows
///   with both). The tests are exact (integers held in f32/f64 without rounding),
///   vectorised 32 dictionary patches at a time ([`SigTile`]);
/// - blocking: a tile of the dictionary stays in cache while a group of `a`
///   patches is matched against it; parallel over groups of `a`.
fn match_patches(a: &[Patch], b: &ExemplarPatches) -> Vec<Best> {
    const GROUP: usize = 16;
    let sigs_a: Vec<Sig> = a.par_iter().map(Sig::of).collect();
    let mut best = vec![Best::default(); a.len()];
    best.par_chunks_mut(GROUP).zip(a.par_chunks(GROUP)).zip(sigs_a.par_chunks(GROUP)).for_each(|((best, a), sa)| {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("popcnt") {
                // SAFETY: the CPU supports the features the function is compiled for.
                unsafe { match_group_avx2(a, sa, b, best) };
                return;
            }
        }
        match_group(a, sa, b, best);
    });
    best
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,popcnt")]
unsafe fn match_group_avx2(a: &[Patch], sa: &[Sig], b: &ExemplarPatches, best: &mut [Best]) {
    match_group(a, sa, b, best)
}

/// Full bit-by-bit comparison of two patches, folded into `bst`.
#[inline(always)]
fn compare(pa: &Patch, pb: &Patch, bst: &mut Best) {
    let (mut inter, mut tp_p, mut tp_r) = (0u32, 0u32, 0u32);
    for i in 0..PATCH_WORDS {
        inter += (pa.occ[i] & pb.occ[i]).count_ones();
        tp_p += (pa.edge[i] & pb.dil[i]).count_ones();
        tp_r += (pa.dil[i] & pb.edge[i]).count_ones();
    }
    bst.offer_iou(inter, pa.occ_n + pb.occ_n - inter);
    bst.offer_f(tp_p, tp_r, pa.edge_n, pb.edge_n);
}

impl Best {
    /// Keeps `inter / union` if it beats the best IoU (exact fractions).
    #[inline(always)]
    fn offer_iou(&mut self, inter: u32, union: u32) {
        if inter as u64 * self.iou_den as u64 > self.iou_num as u64 * union as u64 {
            self.iou_num = inter;
            self.iou_den = union;
        }
    }

    /// F = 2PR/(P+R) with P = tp_p/|Ea|, R = tp_r/|Eb|
    ///   = 2 tp_p tp_r / (tp_p |Eb| + tp_r |Ea|): as an exact fraction.
    #[inline(always)]
    fn f_fraction(tp_p: u32, tp_r: u32, ea: u32, eb: u32) -> (u64, u64) {
        (2 * tp_p as u64 * tp_r as u64, tp_p as u64 * eb as u64 + tp_r as u64 * ea as u64)
    }

    #[inline(always)]
    fn beats_f(&self, tp_p: u32, tp_r: u32, ea: u32, eb: u32) -> bool {
        let (num, den) = Self::f_fraction(tp_p, tp_r, ea, eb);
        num > 0 && num * self.f_den > self.f_num * den
    }

    #[inline(always)]
    fn offer_f(&mut self, tp_p: u32, tp_r: u32, ea: u32, eb: u32) {
        if self.beats_f(tp_p, tp_r, ea, eb) {
            let (num, den) = Self::f_fraction(tp_p, tp_r, ea, eb);
            self.f_num = num;
            self.f_den = den;
        }
    }

    fn is_perfect(&self) -> bool {
        self.iou_num == self.iou_den && self.f_num == self.f_den
    }
}

#[inline(always)]
fn match_group(a: &[Patch], sa: &[Sig], b: &ExemplarPatches, best: &mut [Best]) {
    const TILE: usize = 8; // SigTiles per block: 256 dictionary patches
    const SEEDS: usize = 512;
    let n = b.patches.len();
    let mut open: Vec<usize> = Vec::with_capacity(a.len());
    for (i, (pa, bst)) in a.iter().zip(best.iter_mut()).enumerate() {
        if b.patches.binary_search(pa).is_ok() {
            *bst = Best { iou_num: 1, iou_den: 1, f_num: 1, f_den: 1 };
            continue;
        }
        let step = n.div_ceil(SEEDS).max(1);
        for pb in b.patches.iter().step_by(step) {
            compare(pa, pb, bst);
        }
        if !bst.is_perfect() {
            open.push(i);
        }
    }
    if open.is_empty() {
        return;
    }
    // Blocks of TILE dictionary patches stay in cache while the group runs.
    for (block, tiles) in b.patches.chunks(TILE * LANES).zip(b.tiles.chunks(TILE)) {
        for &i in &open {
            let (pa, sga, bst) = (&a[i], &sa[i], &mut best[i]);
            let (ca, ea) = (sga.occ_n as f32, sga.edge_n as f32);
            for (t, tile) in tiles.iter().enumerate() {
                let u = tile.overlap_bound(&sga.occ, 0);
                let up = tile.overlap_bound(&sga.edge, 2);
                let ur = tile.overlap_bound(&sga.dil, 1);
                // Exact tests in floating point: every product below is an integer
                // under 2^24 (f32) or 2^53 (f64), so nothing is rounded.
                let (inum, iden) = (bst.iou_num as f32, bst.iou_den as f32);
                let (fnum, fden) = (bst.f_num as f64, bst.f_den as f64);
                let mut need = [false; LANES];
                for l in 0..LANES {
                    let iou_ub = u[l] * iden > inum * (ca + tile.occ_n[l] - u[l]);
                    let f_lhs = (2.0 * up[l] * ur[l]) as f64 * fden;
                    let f_rhs = fnum * (up[l] * tile.edge_n[l] + ur[l] * ea) as f64;
                    need[l] = iou_ub | (f_lhs > f_rhs);
                }
                for (l, pb) in block.iter().skip(t * LANES).take(LANES).enumerate() {
                    if need[l] {
                        compare(pa, pb, bst);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::metrics::iou;
    use crate::eval::metrics::test_shapes::{smooth_shape, unit_grid};
    use glam::Vec3;

    #[test]
    fn patch_extraction_matches_get() {
        let mut occ = Occupancy::empty([70, 20, 20]);
        let mut rng = Rng::new(3);
        for v in 0..70 * 20 * 20 {
            if rng.next_u64() & 1 == 0 {
                occ.set(v % 70, (v / 70) % 20, v / 1400);
            }
        }
        let layers = PatchLayers::new(&occ);
        for c in [[0u32, 0, 0], [3, 10, 10], [60, 5, 18], [69, 19, 19], [64, 7, 2]] {
            let p = layers.patch(c);
            for dz in 0..PATCH {
                for dy in 0..PATCH {
                    for dx in 0..PATCH {
                        let bit = dx + PATCH * (dy + PATCH * dz);
                        let got = p.occ[bit / 64] >> (bit % 64) & 1 == 1;
                        let (x, y, z) =
                            (c[0] as i64 + dx as i64 - 5, c[1] as i64 + dy as i64 - 5, c[2] as i64 + dz as i64 - 5);
                        assert_eq!(got, occ.get(x, y, z), "{c:?} {dx} {dy} {dz}");
                    }
                }
            }
            assert_eq!(p.occ_n, p.occ.iter().map(|w| w.count_ones()).sum::<u32>());
            // Slab histograms against a direct count.
            let sig = Sig::of(&p);
            for axis in 0..3 {
                for slab in 0..PATCH {
                    let mut n = 0;
                    for dz in 0..PATCH {
                        for dy in 0..PATCH {
                            for dx in 0..PATCH {
                                let d = [dx, dy, dz];
                                let bit = dx + PATCH * (dy + PATCH * dz);
                                if d[axis] == slab && p.edge[bit / 64] >> (bit % 64) & 1 == 1 {
                                    n += 1;
                                }
                            }
                        }
                    }
                    assert_eq!(sig.edge[axis][slab], n, "{c:?} axis {axis} slab {slab}");
                }
            }
        }
    }

    #[test]
    fn lp_self_is_one_noise_is_low_translation_invariant() {
        let grid = unit_grid(96);
        let ex = smooth_shape(&grid, Vec3::ZERO);
        let params = LpParams::default();
        let dict = ExemplarPatches::new(&ex, 1);
        let own = local_patch_scores(&ex, &dict, &params);
        assert!(own.patches > 100, "{own:?}");
        assert_eq!(own.lp_iou, 1.0);
        assert_eq!(own.lp_iou_above, 1.0);
        assert_eq!(own.lp_fscore, 1.0);
        assert_eq!(own.lp_fscore_above, 1.0);

        // Whole-voxel translation (3, -2, 1) voxels: local patches are unchanged.
        let t = Vec3::new(3.0, -2.0, 1.0) * grid.voxel;
        let moved = smooth_shape(&grid, t);
        assert!(iou(&moved, &ex) < 0.95);
        let s = local_patch_scores(&moved, &dict, &params);
        assert!(s.lp_iou > 0.995 && s.lp_iou_above > 0.99, "{s:?}");
        assert!(s.lp_fscore > 0.995 && s.lp_fscore_above > 0.99, "{s:?}");

        // Random voxels in the same box: no plausible patches.
        let mut noise = Occupancy::empty(grid.dims);
        let mut rng = Rng::new(99);
        for z in 20..76 {
            for y in 20..76 {
                for x in 15..85 {
                    if rng.next_u64() % 10 < 3 {
                        noise.set(x, y, z);
                    }
                }
            }
        }
        let n = local_patch_scores(&noise, &dict, &params);
        assert_eq!(n.patches, 1000);
        assert!(n.lp_iou < 0.6, "{n:?}");
        assert!(n.lp_iou_above == 0.0 && n.lp_fscore_above == 0.0, "{n:?}");

        // Deterministic sampling.
        assert_eq!(local_patch_scores(&noise, &dict, &params), n);
    }

    #[test]
    fn lp_scores_degrade_with_damage() {
        let grid = unit_grid(96);
        let ex = smooth_shape(&grid, Vec3::ZERO);
        // Carve a pattern of small holes: new local geometry the exemplar lacks.
        let mut damaged = ex.clone();
        for v in ex.voxels() {
            if v[0] % 9 < 2 && v[1] % 9 < 2 {
                let w = damaged.words_per_row();
                let r = v[1] as usize + grid.dims[1] as usize * v[2] as usize;
                damaged.bits[r * w + v[0] as usize / 64] &= !(1u64 << (v[0] % 64));
            }
        }
        let s = lp_scores(&damaged, &ex, &LpParams::default());
        assert!(s.lp_iou < 0.99 && s.lp_iou_above < 0.9, "{s:?}");
        assert!(s.lp_fscore < 0.99, "{s:?}");
    }

    /// The pruned matcher returns exactly the exhaustive maxima.
    #[test]
    fn pruned_matching_equals_brute_force() {
        let mut ex = Occupancy::empty([64, 64, 64]);
        for z in 0..64i64 {
            for y in 0..64i64 {
                for x in 0..64i64 {
                    let d = ((x - 32).pow(2) + (y - 30).pow(2) * 2 + (z - 32).pow(2)) as f64;
                    if d.sqrt() < 20.0 || (x > 30 && y < 20 && z < 40) {
                        ex.set(x, y, z);
                    }
                }
            }
        }
        // Variants: random voxels, and the exemplar with voxels removed.
        let mut rng = Rng::new(1);
        let mut noise = Occupancy::empty([64, 64, 64]);
        let mut damaged = ex.clone();
        for z in 10..54 {
            for y in 10..54 {
                for x in 10..54 {
                    if rng.next_u64() % 10 < 3 {
                        noise.set(x, y, z);
                    }
                    if rng.next_u64() % 10 < 1 && ex.get(x, y, z) {
                        let w = damaged.words_per_row();
                        let r = (y + 64 * z) as usize;
                        damaged.bits[r * w + x as usize / 64] &= !(1u64 << (x % 64));
                    }
                }
            }
        }
        let dict = ExemplarPatches::new(&ex, 1);
        for shape in [&noise, &damaged, &ex] {
            let layers = PatchLayers::new(shape);
            let pats: Vec<Patch> = layers.centres(5).iter().take(120).map(|&c| layers.patch(c)).collect();
            let fast = match_patches(&pats, &dict);
            for (k, pa) in pats.iter().enumerate() {
                let mut brute = Best::default();
                for pb in &dict.patches {
                    compare(pa, pb, &mut brute);
                }
                assert_eq!(fast[k].f_num * brute.f_den, brute.f_num * fast[k].f_den, "F of patch {k}");
                assert_eq!(
                    fast[k].iou_num as u64 * brute.iou_den as u64,
                    brute.iou_num as u64 * fast[k].iou_den as u64,
                    "IoU of patch {k}"
                );
            }
        }
    }
    /// The best IoU in `dict` of the patch centred on every surface voxel of
    /// `shape`, with the voxel, in storage order (the exact matcher's).
    fn best_iou_at_every_surface_voxel(shape: &Occupancy, dict: &ExemplarPatches) -> Vec<([u32; 3], f64)> {
        let layers = PatchLayers::new(shape);
        let centres = layers.centres(1);
        let best = best_at(&layers, &centres, dict);
        centres.into_iter().zip(best).map(|(c, b)| (c, b.iou())).collect()
    }

    /// The voxels below a threshold are exactly those whose exhaustive best
    /// IoU is below it, at thresholds that split the voxels.
    #[test]
    fn voxels_below_an_iou_are_those_of_the_exhaustive_maxima() {
        let grid = unit_grid(64);
        let ex = smooth_shape(&grid, Vec3::ZERO);
        // The shape moved by a fraction of a voxel and damaged: patches at
        // many IoUs.
        let mut shape = smooth_shape(&grid, Vec3::new(0.4, -0.3, 0.2) * grid.voxel);
        let mut rng = Rng::new(7);
        for v in shape.voxels() {
            if rng.next_u64().is_multiple_of(7) {
                let w = shape.words_per_row();
                let r = v[1] as usize + grid.dims[1] as usize * v[2] as usize;
                shape.bits[r * w + v[0] as usize / 64] &= !(1u64 << (v[0] % 64));
            }
        }
        // And a box of random voxels beside it: patches like nothing.
        for z in 4..18 {
            for y in 4..18 {
                for x in 4..18 {
                    if rng.next_u64() % 10 < 3 {
                        shape.set(x, y, z);
                    }
                }
            }
        }
        let dict = ExemplarPatches::new(&ex, 1);
        let exhaustive = best_iou_at_every_surface_voxel(&shape, &dict);
        for t in [0.5, 0.7, 0.85] {
            let want: Vec<[u32; 3]> = exhaustive.iter().filter(|(_, iou)| *iou < t).map(|(c, _)| *c).collect();
            assert!(!want.is_empty() && want.len() < exhaustive.len(), "threshold {t} splits nothing");
            let got = surface_voxels_below_iou(&shape, &dict, t);
            assert!(got == want, "threshold {t}: {} voxels below, {} exhaustively", got.len(), want.len());
        }
        // The exemplar against itself: nothing below; an empty dictionary: all.
        assert!(surface_voxels_below_iou(&ex, &dict, 0.99).is_empty());
        let empty = ExemplarPatches::new(&Occupancy::empty(grid.dims), 1);
        assert_eq!(surface_voxels_below_iou(&shape, &empty, 0.5).len(), exhaustive.len());
    }
}
