//! @brief Detail transfer: a finer level made without a network, by copying the
//! exemplar's own fine voxels where the coarse neighbourhoods match (patch-based
//! synthesis, coarse to fine).
//!
//! For a variant's coarse level `V` (index l - 1) and the exemplar's levels
//! l - 1 (`E`) and l (`F`):
//! 1. every surface voxel of `V` and of `E` gets a descriptor of its coarse
//!    neighbourhood: the (2r+1)^3 window around it, each cell holding occupancy,
//!    the surface point's offset (voxels), normal and colour, weighted by a
//!    Gaussian of the cell's distance from the centre;
//! 2. every voxel `v` of `V` is matched to the voxel `e` of `E` with the nearest
//!    descriptor by PatchMatch on the sparse grid: each round, in parallel, a
//!    voxel tries its own match, its neighbours' matches shifted by the
//!    neighbour's offset (so contiguous regions of the exemplar are copied
//!    whole: seams are rare and edges stay sharp), voxels near its match and a
//!    few drawn anywhere in the exemplar. Shifted neighbour matches win ties
//!    by `coherence` (a relative bonus);
//! 3. the children of `v` are the children of `e` in `F`, with their offsets,
//!    normals and colours: exact exemplar colours and edges.
//!
//! When the coarse level was itself made by transfer, each voxel starts from
//! the exemplar voxel it was copied from, so consecutive transfer levels stay
//! coherent and a round or two suffice.
//!
//! Deterministic: every voxel's random draws come from (seed, round, voxel),
//! so the result does not depend on the number of threads.

use crate::grid::VoxelMap;

use glam::{IVec3, Vec3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::util::seed::{derive_seed, Stream};
use crate::level::Level;
use crate::util::rng::Rng;

/// Settings of detail transfer (`[transfer]` in a profile).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TransferConfig {
    /// Levels of this resolution (voxels per axis) and finer are made by
    /// transfer instead of a trained diffusion model (0: none, the paper's
    /// method). Level 0 always has a network.
    pub from_resolution: u32,
    /// Half-width of the matched window, coarse voxels (1: 3^3 cells).
    pub radius: i32,
    /// PatchMatch rounds on a level whose coarse level came from a network.
    pub rounds: usize,
    /// Rounds when the coarse level was itself transferred (matches start from
    /// the voxels copied).
    pub refine_rounds: usize,
    /// Uniformly drawn exemplar candidates per voxel and round.
    pub random_candidates: usize,
    /// Relative bonus of a neighbour's shifted match (0: none).
    pub coherence: f32,
    /// A fine voxel exists where most of the sources proposed by the 3^3
    /// neighbours' matches have it, copied from the source most of them share
    /// (mends seams between copied regions); false: the voxel's own match's
    /// children.
    pub vote: bool,
    /// Weights of the descriptor's channels (squared-distance weights).
    pub occupancy_weight: f32,
    pub offset_weight: f32,
    pub normal_weight: f32,
    pub colour_weight: f32,
}

impl Default for TransferConfig {
    fn default() -> Self {
        TransferConfig {
            from_resolution: 0,
            radius: 3,
            rounds: 8,
            refine_rounds: 2,
            random_candidates: 4,
            coherence: 0.5,
            vote: true,
            occupancy_weight: 1.0,
            offset_weight: 1.0,
            normal_weight: 0.5,
            colour_weight: 1.0,
        }
    }
}

impl TransferConfig {
    pub fn is_off(&self) -> bool {
        self.from_resolution == 0
    }
    pub fn validate(&self) -> Result<(), String> {
        if !(1..=3).contains(&self.radius) {
            return Err(format!("transfer.radius {} must be 1, 2 or 3", self.radius));
        }
        let w = [self.occupancy_weight, self.offset_weight, self.normal_weight, self.colour_weight, self.coherence];
        if w.iter().any(|x| !(x.is_finite() && *x >= 0.0)) || self.coherence >= 1.0 {
            return Err("transfer weights must be finite and >= 0, coherence below 1".into());
        }
        if self.from_resolution != 0 && !self.from_resolution.is_power_of_two() {
            return Err(format!("transfer.from_resolution {} must be a power of two (or 0: off)", self.from_resolution));
        }
        if self.rounds == 0 {
            return Err("transfer.rounds must be at least 1".into());
        }
        Ok(())
    }
}

/// Errors of detail transfer.
#[derive(Debug, thiserror::Error)]
pub enum TransferError {
    #[error("detail transfer: {0}")]
    Invalid(String),
}

crate::stage_error!(TransferError);

/// A transferred level and, per voxel, the exemplar voxel (coordinates at the
/// same level) it was copied from.
#[derive(Clone, Debug)]
pub struct Transferred {
    pub level: Level,
    pub sources: Vec<IVec3>,
}

/// Values per window cell: occupancy, offset (3), normal (3), colour (3).
const CELL: usize = 10;

/// The surface voxels (mask > 0) of a level, numbered 0.. in row order
/// ("slots"), with a lookup by coordinate.
struct Surface<'a> {
    level: &'a Level,
    /// The level's row of each slot.
    rows: Vec<u32>,
    slot: VoxelMap<u32>,
}

impl<'a> Surface<'a> {
    fn new(level: &'a Level) -> Self {
        let rows: Vec<u32> = (0..level.len() as u32).filter(|&i| level.mask[i as usize] > 0.0).collect();
        let slot = rows.iter().enumerate().map(|(s, &r)| (level.coords[r as usize], s as u32)).collect();
        Surface { level, rows, slot }
    }
    fn len(&self) -> usize {
        self.rows.len()
    }
    fn coord(&self, s: u32) -> IVec3 {
        self.level.coords[self.rows[s as usize] as usize]
    }
    fn find(&self, c: IVec3) -> Option<u32> {
        self.slot.get(c).copied()
    }
    /// The level's row of the surface voxel at `c`.
    fn row(&self, c: IVec3) -> Option<usize> {
        self.find(c).map(|s| self.rows[s as usize] as usize)
    }
}

/// The window's cell offsets and their weights (a Gaussian of the distance, sigma = radius).
fn window(radius: i32) -> Vec<(IVec3, f32)> {
    let mut w = Vec::new();
    let s2 = 2.0 * (radius as f32).powi(2);
    for x in -radius..=radius {
        for y in -radius..=radius {
            for z in -radius..=radius {
                let d = IVec3::new(x, y, z);
                w.push((d, (-(d.length_squared() as f32) / s2).exp()));
            }
        }
    }
    w
}

/// Descriptors of the surface voxels, one block of `window.len() * CELL` per slot.
fn descriptors(surface: &Surface, window: &[(IVec3, f32)], cfg: &TransferConfig) -> Vec<f32> {
    let level = surface.level;
    let width = window.len() * CELL;
    let (wo, wp, wn, wc) = (cfg.occupancy_weight.sqrt(), cfg.offset_weight.sqrt(), cfg.normal_weight.sqrt(), cfg.colour_weight.sqrt());
    let mut out = vec![0f32; surface.len() * width];
    out.par_chunks_mut(width).enumerate().for_each(|(s, d)| {
        let c = surface.coord(s as u32);
        for (k, &(o, g)) in window.iter().enumerate() {
            let Some(j) = surface.row(c + o) else { continue };
            let g = g.sqrt();
            let cell = &mut d[k * CELL..(k + 1) * CELL];
            cell[0] = wo * g;
            let put = |cell: &mut [f32], at: usize, v: Vec3, w: f32| {
                cell[at] = v.x * w * g;
                cell[at + 1] = v.y * w * g;
                cell[at + 2] = v.z * w * g;
            };
            put(cell, 1, level.offsets[j], wp);
            put(cell, 4, level.normals[j].normalize_or_zero(), wn);
            put(cell, 7, level.colours[j], wc);
        }
    });
    out
}

#[inline]
fn distance(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// Floats summed between checks against the bound (a few window cells).
const DISTANCE_BLOCK: usize = 80;

/// [`distance`], or some value above `bound` as soon as the partial sum
/// exceeds it: most PatchMatch candidates lose, and lose early.
#[inline]
fn distance_below(a: &[f32], b: &[f32], bound: f32) -> f32 {
    let mut sum = 0.0;
    for (x, y) in a.chunks(DISTANCE_BLOCK).zip(b.chunks(DISTANCE_BLOCK)) {
        sum += distance(x, y);
        if sum >= bound {
            return sum;
        }
    }
    sum
}

/// The level after `coarse` (a variant's level, index l - 1) by detail transfer
/// from the exemplar's levels l - 1 and l. `init`: per voxel of `coarse`, the
/// exemplar voxel it was itself copied from (a previous transfer), if any.
pub fn transfer(
    exemplar_coarse: &Level,
    exemplar_fine: &Level,
    coarse: &Level,
    init: Option<&[IVec3]>,
    cfg: &TransferConfig,
    seed: u64,
) -> Result<Transferred, TransferError> {
    if exemplar_fine.resolution != exemplar_coarse.resolution * 2 || coarse.resolution != exemplar_coarse.resolution {
        return Err(TransferError::Invalid(format!(
            "resolutions do not chain: exemplar {}^3 -> {}^3, variant {}^3",
            exemplar_coarse.resolution, exemplar_fine.resolution, coarse.resolution
        )));
    }
    cfg.validate().map_err(TransferError::Invalid)?;
    let ex = Surface::new(exemplar_coarse);
    let var = Surface::new(coarse);
    let fine_level = |voxels: Vec<(IVec3, usize, IVec3)>| {
        let mut level = Level {
            index: coarse.index + 1,
            resolution: coarse.resolution * 2,
            frame: coarse.frame,
            ..Default::default()
        };
        let mut sources = Vec::with_capacity(voxels.len());
        for (c, j, s) in voxels {
            level.coords.push(c);
            level.offsets.push(exemplar_fine.offsets[j]);
            level.normals.push(exemplar_fine.normals[j]);
            level.colours.push(exemplar_fine.colours[j]);
            level.mask.push(1.0);
            sources.push(s);
        }
        Transferred { level, sources }
    };
    if ex.len() == 0 || var.len() == 0 {
        return Ok(fine_level(Vec::new()));
    }
    let win = window(cfg.radius);
    let width = win.len() * CELL;
    let ex_desc = descriptors(&ex, &win, cfg);
    let var_desc = descriptors(&var, &win, cfg);
    let ex_d = |s: u32| &ex_desc[s as usize * width..(s as usize + 1) * width];
    let var_d = |i: usize| &var_desc[i * width..(i + 1) * width];
    let n_ex = ex.len() as u64;

    // Start: the voxel copied from (consecutive transfers) or a random one.
    let mut matches: Vec<(u32, f32)> = (0..var.len())
        .into_par_iter()
        .map(|i| {
            let from = init.and_then(|s| s.get(var.rows[i] as usize)).and_then(|&c| ex.find(c));
            let s = from.unwrap_or_else(|| {
                (Rng::new(derive_seed(seed, i as u64, Stream::Transfer, 0)).next_u64() % n_ex) as u32
            });
            (s, distance(var_d(i), ex_d(s)))
        })
        .collect();
    let rounds = if init.is_some() { cfg.refine_rounds } else { cfg.rounds };
    // Neighbours whose matches propagate: the 26 around, and the 6 axis steps of 2, 4 and 8
    // (long jumps spread a good match across a region in few parallel rounds).
    let mut steps: Vec<IVec3> = window(1).into_iter().map(|(d, _)| d).filter(|d| *d != IVec3::ZERO).collect();
    for k in [2, 4, 8] {
        for a in 0..3 {
            let mut d = IVec3::ZERO;
            d[a] = k;
            steps.push(d);
            steps.push(-d);
        }
    }
    let bonus = 1.0 - cfg.coherence;
    for round in 1..=rounds {
        matches = (0..var.len())
            .into_par_iter()
            .map(|i| {
                let c = var.coord(i as u32);
                let d = var_d(i);
                let mut best = matches[i];
                let consider = |best: &mut (u32, f32), s: u32, factor: f32| {
                    if s == best.0 {
                        return;
                    }
                    let cost = distance_below(d, ex_d(s), best.1 / factor) * factor;
                    if cost < best.1 {
                        *best = (s, cost);
                    }
                };
                // Neighbours' matches, shifted back by the neighbour's offset.
                for &o in &steps {
                    if let Some(j) = var.find(c + o) {
                        if let Some(s) = ex.find(ex.coord(matches[j as usize].0) - o) {
                            consider(&mut best, s, bonus);
                        }
                    }
                }
                let mut rng = Rng::new(derive_seed(seed, i as u64, Stream::Transfer, round as u64));
                // Near the current match, at shrinking radii.
                let here = ex.coord(best.0);
                for r in [8, 4, 2, 1] {
                    let o = IVec3::new(
                        (rng.next_u64() % (2 * r + 1)) as i32 - r as i32,
                        (rng.next_u64() % (2 * r + 1)) as i32 - r as i32,
                        (rng.next_u64() % (2 * r + 1)) as i32 - r as i32,
                    );
                    if let Some(s) = ex.find(here + o) {
                        consider(&mut best, s, 1.0);
                    }
                }
                for _ in 0..cfg.random_candidates {
                    consider(&mut best, (rng.next_u64() % n_ex) as u32, 1.0);
                }
                best
            })
            .collect();
    }

    if log::log_enabled!(log::Level::Debug) {
        // Coherence: face-neighbour pairs whose matches are neighbours the same way.
        let (mut pairs, mut whole) = (0usize, 0usize);
        for i in 0..var.len() {
            for a in 0..3 {
                let mut o = IVec3::ZERO;
                o[a] = 1;
                if let Some(j) = var.find(var.coord(i as u32) + o) {
                    pairs += 1;
                    whole += (ex.coord(matches[j as usize].0) == ex.coord(matches[i].0) + o) as usize;
                }
            }
        }
        let mean = matches.iter().map(|m| m.1 as f64).sum::<f64>() / matches.len() as f64;
        log::debug!(
            "transfer to {}^3: {} voxels, mean match distance {mean:.3}, coherent neighbour pairs {:.1}%",
            coarse.resolution * 2,
            var.len(),
            100.0 * whole as f64 / pairs.max(1) as f64
        );
    }
    // Copy: the children of each match in the exemplar's fine level.
    let fine = Surface::new(exemplar_fine);
    let neighbourhood: Vec<IVec3> = window(1).into_iter().map(|(d, _)| d).collect();
    let voxels: Vec<(IVec3, usize, IVec3)> = (0..var.len())
        .into_par_iter()
        .flat_map_iter(|i| {
            let v = var.coord(i as u32);
            let e = ex.coord(matches[i].0);
            // With voting, the sources this voxel's neighbours' matches propose
            // for it (each shifted back by the neighbour's offset): inside a
            // coherent region they all equal `e`; at a seam between two copied
            // regions they disagree, and a child exists where most say so.
            let proposals: Vec<IVec3> = if cfg.vote {
                neighbourhood
                    .iter()
                    .filter_map(|&o| var.find(v + o).map(|j| ex.coord(matches[j as usize].0) - o))
                    .filter(|&p| ex.find(p).is_some())
                    .collect()
            } else {
                Vec::new()
            };
            let fine = &fine;
            (0..8).filter_map(move |a| {
                let child = IVec3::new(a & 1, (a >> 1) & 1, (a >> 2) & 1);
                let own = e * 2 + child;
                if proposals.is_empty() {
                    return fine.row(own).map(|j| (v * 2 + child, j, own));
                }
                let present: Vec<IVec3> =
                    proposals.iter().map(|p| *p * 2 + child).filter(|&s| fine.find(s).is_some()).collect();
                if 2 * present.len() <= proposals.len() {
                    return None;
                }
                // The source most proposals share (inside a coherent region: the
                // own match's, so exact copies stay exact); ties go to the own match.
                let votes = |s: &IVec3| present.iter().filter(|p| *p == s).count();
                let src = present.iter().copied().max_by_key(|s| (votes(s), *s == own)).unwrap_or(own);
                Some((v * 2 + child, fine.row(src)?, src))
            })
        })
        .collect();
    Ok(fine_level(voxels))
}

/// Levels `coarse.index + 1 ..= last` of a variant by detail transfer from
/// `exemplar_levels`, starting from its level `coarse`; each level's matches
/// start from the voxels the previous transferred level copied. `seed`: the
/// variant's seed. `repairs`: per level, what it gets after the copy
/// ([`crate::level::repair::repairs`]: specks removed, a sheet mended;
/// empty: nothing); the voxels a mend adds were copied from nowhere, so the
/// next level's matches start at random there.
pub fn extend(
    exemplar_levels: &[Level],
    coarse: &Level,
    last: usize,
    cfg: &TransferConfig,
    seed: u64,
    repairs: &[crate::level::repair::LevelRepair],
) -> Result<Vec<Level>, TransferError> {
    extend_observed(exemplar_levels, coarse, last, cfg, seed, repairs, &mut |_| {})
}

/// [`extend`], telling `on_level` of every level as it is made (the studio
/// shows each as it finishes).
pub fn extend_observed(
    exemplar_levels: &[Level],
    coarse: &Level,
    last: usize,
    cfg: &TransferConfig,
    seed: u64,
    repairs: &[crate::level::repair::LevelRepair],
    on_level: &mut dyn FnMut(&Level),
) -> Result<Vec<Level>, TransferError> {
    if last >= exemplar_levels.len() {
        return Err(TransferError::Invalid(format!(
            "level {last} asked for, the exemplar has levels 0..{}",
            exemplar_levels.len().saturating_sub(1)
        )));
    }
    // The matches' random draws follow the voxels' order: a level read back
    // from its file continues as the one sampled in memory did.
    let coarse = &coarse.in_coordinate_order();
    let mut out: Vec<Level> = Vec::new();
    let mut sources: Option<Vec<IVec3>> = None;
    for l in coarse.index + 1..=last {
        let from = out.last().unwrap_or(coarse);
        let t = std::time::Instant::now();
        let next = transfer(
            &exemplar_levels[l - 1],
            &exemplar_levels[l],
            from,
            sources.as_deref(),
            cfg,
            derive_seed(seed, l as u64, Stream::Transfer, 0),
        )?;
        let Transferred { mut level, sources: mut copied } = next;
        if let Some(r) = repairs.get(l).and_then(|repair| repair.apply(&level)) {
            log::debug!("transfer: level {l}: {} speck voxels removed, {} voxels mend the sheet", r.removed(level.len()), r.added);
            copied = r.kept.iter().map(|&i| copied[i]).collect();
            copied.resize(r.level.len(), IVec3::splat(i32::MIN));
            level = r.level;
        }
        log::info!("transfer: level {l} ({}^3, {} voxels) in {:.2} s", level.resolution, level.len(), t.elapsed().as_secs_f64());
        sources = Some(copied);
        on_level(&level);
        out.push(level);
    }
    Ok(out)
}

#[cfg(test)]
mod tests;
