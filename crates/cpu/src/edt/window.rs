//! Windowed exact scan of a whole tile, vectorised across its lanes.
//!
//! For element `x` of a line, `min_i (x - i)² + f[i]` is at most `f[x]`
//! (take `i = x`), so only elements with `(x - i)² <= f[x]` can improve on
//! it: a window of radius `floor(sqrt(f[x]))`. Where the values of a tile
//! are small, as in the last scan of all but the sparsest grids, scanning
//! that window for all lanes at once is a branch-free minimum over SIMD
//! registers, much faster than the lower envelope, whose stack branches
//! mispredict. Where the windows would be long the caller falls back to the
//! envelope.
//!
//! An unreachable element means that the whole lower-dimensional slice
//! through it (a row for the y scan, a plane for the z scan) has no
//! obstacle, so it is unreachable in every lane of the tile: such *empty
//! rows* are skipped as sources, and as targets get the window that reaches
//! the nearest non-empty row.

use edtmap_core::{NO_SITE, UNREACHABLE_DIST_SQ};

/// Finite values and window bounds at or above this send the tile to the
/// envelope. It keeps every sum below `2^31`, and it is the starting value
/// of empty rows, which any real candidate beats.
const MAX_VALUE: u32 = 1 << 30;

/// Window positions per voxel (before the early exit) above which the
/// envelope is used instead; measured on random, structured and nearly
/// empty 256³ grids (docs/benchmarks/batch-edt.md, "Choices these
/// measurements made").
const MAX_WINDOW_PER_VOXEL: usize = 256;

/// Window offsets between two checks for an early end of the window.
const EARLY_EXIT_EVERY: usize = 2;

/// A tile stored element-major: element `i` of lane `w` at `i * lanes + w`.
pub(super) struct Tile<'a> {
    pub(super) f: &'a [u32],
    pub(super) site: &'a [u32],
    pub(super) lanes: usize,
}

/// Per-row window of a tile (radius, whether the row is empty) and the
/// scratch that plans it, reused from tile to tile.
#[derive(Debug, Default)]
pub(super) struct Windows {
    radius: Vec<usize>,
    empty: Vec<bool>,
    bound: Vec<u64>,
}

/// Scans `tile` into `out_f` / `out_site` (same layout) and returns true,
/// or returns false without writing if the windows would be too long.
/// `radius` is scratch space.
pub(super) fn scan_windowed(tile: &Tile<'_>, out_f: &mut [u32], out_site: &mut [u32], radius: &mut Windows) -> bool {
    #[cfg(target_arch = "x86_64")]
    if tile.lanes.is_multiple_of(8) && std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 and `lanes` is a multiple of 8.
        return unsafe { scan_windowed_avx2(tile, out_f, out_site, radius) };
    }
    scan_windowed_with(tile, out_f, out_site, radius, relax)
}

/// # Safety
/// The CPU supports AVX2 and `tile.lanes` is a multiple of 8.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn scan_windowed_avx2(tile: &Tile<'_>, out_f: &mut [u32], out_site: &mut [u32], radius: &mut Windows) -> bool {
    // SAFETY: AVX2 is available and every row has `lanes` elements, a
    // multiple of 8 (this function's contract).
    scan_windowed_with(tile, out_f, out_site, radius, |b, bs, row, dd, ties| unsafe {
        relax_avx2(b, bs, row, dd, ties)
    })
}

/// The windowed scan, with `relax` as the lane-wise update of one row.
#[inline(always)]
fn scan_windowed_with(
    tile: &Tile<'_>,
    out_f: &mut [u32],
    out_site: &mut [u32],
    windows: &mut Windows,
    relax: impl Fn(&mut [u32], &mut [u32], (&[u32], &[u32]), u32, bool),
) -> bool {
    let lanes = tile.lanes;
    let len = tile.f.len() / lanes;
    if !plan_windows(tile, len, windows) {
        return false;
    }
    let Windows { radius, empty, .. } = windows;
    let rows_f = tile.f.chunks_exact(lanes);
    let rows_site = tile.site.chunks_exact(lanes);
    let out_rows = out_f.chunks_exact_mut(lanes).zip(out_site.chunks_exact_mut(lanes));
    for (i, (((best, best_site), f), site)) in out_rows.zip(rows_f).zip(rows_site).enumerate() {
        if empty[i] {
            best.fill(MAX_VALUE);
            best_site.fill(NO_SITE);
        } else {
            best.copy_from_slice(f);
            best_site.copy_from_slice(site);
        }
        for d in 1..=radius[i] {
            let dd = (d * d) as u32;
            // Candidates d or more away are worth at least d²: once that
            // passes every lane's best, none can improve or tie.
            if d % EARLY_EXIT_EVERY == 0 && dd > best.iter().copied().fold(0, u32::max) {
                break;
            }
            // Ties go to the lower position, as in the envelope: a
            // candidate on the left is below every position seen so far,
            // one on the right above them.
            if let Some(j) = i.checked_sub(d).filter(|&j| !empty[j]) {
                relax(best, best_site, row(tile, j), dd, true);
            }
            if i + d < len && !empty[i + d] {
                relax(best, best_site, row(tile, i + d), dd, false);
            }
        }
    }
    true
}

/// Plans the window of each row: the radius that covers every lane's
/// possible improvement, and whether the row is empty. False if the tile
/// should go to the envelope instead: windows too long, values too large,
/// a row empty in some lanes only, or no non-empty row at all.
fn plan_windows(tile: &Tile<'_>, len: usize, w: &mut Windows) -> bool {
    let Windows { radius, empty, bound } = w;
    radius.clear();
    empty.clear();
    bound.clear();
    // A row's bound is its largest value; empty rows are filled in below.
    for f in tile.f.chunks_exact(tile.lanes) {
        let max = f.iter().copied().fold(0, u32::max);
        let is_empty = max == UNREACHABLE_DIST_SQ && f.iter().all(|&v| v == UNREACHABLE_DIST_SQ);
        if !is_empty && max >= MAX_VALUE {
            return false;
        }
        empty.push(is_empty);
        bound.push(if is_empty { u64::MAX } else { u64::from(max) });
    }
    // An empty row's bound: the cheapest way to reach a non-empty row, from
    // the nearest one before it, then the nearest one after it.
    let reach = |from: usize, to: usize, b: u64| (from.abs_diff(to) as u64).pow(2) + b;
    let mut last = None;
    for i in 0..len {
        match (empty[i], last) {
            (false, _) => last = Some(i),
            (true, Some(j)) => bound[i] = reach(i, j, bound[j]),
            (true, None) => {}
        }
    }
    let mut next = None;
    for i in (0..len).rev() {
        match (empty[i], next) {
            (false, _) => next = Some(i),
            (true, Some(j)) => bound[i] = bound[i].min(reach(i, j, bound[j])),
            (true, None) => {}
        }
    }
    let mut cost = 0;
    for &b in bound.iter() {
        if b >= u64::from(MAX_VALUE) {
            return false;
        }
        let r = ((b as f64).sqrt() as usize).min(len - 1);
        cost += 2 * r + 1;
        radius.push(r);
    }
    cost <= MAX_WINDOW_PER_VOXEL * len
}

#[inline(always)]
fn row<'a>(tile: &Tile<'a>, i: usize) -> (&'a [u32], &'a [u32]) {
    let lanes = i * tile.lanes..(i + 1) * tile.lanes;
    (&tile.f[lanes.clone()], &tile.site[lanes])
}

/// Lane-wise: where `f + dd` beats `best` (or equals it, with `ties`),
/// take it and its site.
#[inline(always)]
fn relax(best: &mut [u32], best_site: &mut [u32], (f, site): (&[u32], &[u32]), dd: u32, ties: bool) {
    let lanes = best.iter_mut().zip(best_site.iter_mut()).zip(f.iter().zip(site));
    for ((b, bs), (&f, &s)) in lanes {
        // Values are below 2^30 here, so the sum cannot overflow.
        let c = f + dd;
        if c < *b || (ties && c == *b) {
            *b = c;
            *bs = s;
        }
    }
}

/// [`relax`] with AVX2, 8 lanes at a time, every store unconditional
/// (compilers turn the scalar form into masked stores, slow on AMD CPUs).
///
/// # Safety
/// The CPU supports AVX2, and all four slices have the same length, a
/// multiple of 8.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn relax_avx2(best: &mut [u32], best_site: &mut [u32], (f, site): (&[u32], &[u32]), dd: u32, ties: bool) {
    use std::arch::x86_64::{
        __m256i, _mm256_add_epi32, _mm256_blendv_epi8, _mm256_cmpgt_epi32, _mm256_loadu_si256, _mm256_set1_epi32,
        _mm256_storeu_si256,
    };
    let n = best.len();
    debug_assert!(n.is_multiple_of(8) && best_site.len() == n && f.len() == n && site.len() == n);
    let vdd = _mm256_set1_epi32(dd as i32);
    for k in (0..n).step_by(8) {
        // SAFETY: `k + 8 <= n` for all four slices (the caller's contract),
        // with unaligned loads and stores. Values are below 2^30, so the
        // signed 32-bit comparison is exact.
        unsafe {
            let load = |p: *const u32| _mm256_loadu_si256(p.add(k).cast::<__m256i>());
            let c = _mm256_add_epi32(load(f.as_ptr()), vdd);
            let (b, bs, s) = (load(best.as_ptr()), load(best_site.as_ptr()), load(site.as_ptr()));
            let (new_best, new_site) = if ties {
                // Keep the best only where the candidate is above it.
                let keep = _mm256_cmpgt_epi32(c, b);
                (_mm256_blendv_epi8(c, b, keep), _mm256_blendv_epi8(s, bs, keep))
            } else {
                let take = _mm256_cmpgt_epi32(b, c);
                (_mm256_blendv_epi8(b, c, take), _mm256_blendv_epi8(bs, s, take))
            };
            _mm256_storeu_si256(best.as_mut_ptr().add(k).cast(), new_best);
            _mm256_storeu_si256(best_site.as_mut_ptr().add(k).cast(), new_site);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check_tile(lanes: usize, len: usize) {
        let f: Vec<u32> = (0..lanes * len).map(|k| ((k * 7919) % 23) as u32).collect();
        let site: Vec<u32> = (0..(lanes * len) as u32).collect();
        let (mut out_f, mut out_site) = (vec![0; f.len()], vec![0; f.len()]);
        let tile = Tile { f: &f, site: &site, lanes };
        assert!(scan_windowed(&tile, &mut out_f, &mut out_site, &mut Windows::default()));
        for w in 0..lanes {
            for x in 0..len {
                let want = (0..len).map(|i| (x.abs_diff(i).pow(2)) as u32 + f[i * lanes + w]).min();
                assert_eq!(Some(out_f[x * lanes + w]), want);
                let s = out_site[x * lanes + w] as usize;
                assert_eq!(s % lanes, w);
                assert_eq!(out_f[x * lanes + w], (x.abs_diff(s / lanes).pow(2)) as u32 + f[s]);
            }
        }
    }

    #[test]
    fn windowed_matches_brute_force_per_lane() {
        check_tile(3, 9); // the portable path
        check_tile(16, 11); // the SIMD path where the CPU has it
    }

    #[test]
    fn large_values_fall_back() {
        let f = vec![MAX_VALUE; 8];
        let tile = Tile { f: &f, site: &f, lanes: 2 };
        assert!(!scan_windowed(&tile, &mut [0; 8], &mut [0; 8], &mut Windows::default()));
    }
}
