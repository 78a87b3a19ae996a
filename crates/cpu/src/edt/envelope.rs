//! One-dimensional exact distance kernels.
//!
//! Both kernels work on squared distances in voxel units and carry, for
//! every element, the linear index of its nearest obstacle.

use edtmap_core::{NO_SITE, UNREACHABLE_DIST_SQ};

/// First scan along a contiguous row (the paper's `INITSCAN`): the squared
/// 1D distance from each element to the nearest obstacle in its row.
///
/// `row_base` is the linear index of the row's first voxel.
pub(crate) fn sweep_row(is_obstacle: impl Fn(usize) -> bool, row_base: u32, dist: &mut [u32], near: &mut [u32]) {
    // Forward: remember the last obstacle at or before x.
    let mut last = NO_SITE;
    for (x, slot) in near.iter_mut().enumerate() {
        if is_obstacle(x) {
            last = x as u32;
        }
        *slot = last;
    }
    // Backward: keep the closer of the last obstacle before and the next one
    // after x.
    let mut next = NO_SITE;
    for x in (0..near.len()).rev() {
        let before = near[x];
        if before == x as u32 {
            next = x as u32;
        }
        let x32 = x as u32;
        let site = match (before, next) {
            (NO_SITE, NO_SITE) => NO_SITE,
            (NO_SITE, n) => n,
            (b, NO_SITE) => b,
            (b, n) => {
                if x32 - b <= n - x32 {
                    b
                } else {
                    n
                }
            }
        };
        if site == NO_SITE {
            dist[x] = UNREACHABLE_DIST_SQ;
            near[x] = NO_SITE;
        } else {
            let d = x32.abs_diff(site);
            dist[x] = d * d;
            near[x] = row_base + site;
        }
    }
}

/// Working memory of [`envelope`], reused across lines.
#[derive(Debug, Default)]
pub(crate) struct EnvelopeScratch {
    /// The parabolas of the lower envelope, left to right, plus a sentinel.
    stack: Vec<Parabola>,
}

/// One parabola `(x - pos)² + f` of the lower envelope, owning the integers
/// `start..` up to the next parabola's start.
#[derive(Debug, Default, Clone, Copy)]
struct Parabola {
    pos: i64,
    f: i64,
    start: i64,
    /// The parabola's value at `start`.
    at_start: i64,
}

/// Auxiliary scan along one line (the paper's `AUXSCAN`, eq. 5): for each x,
/// `min_i (x - i)² + f[i]` over the elements i with finite `f[i]`, and the
/// nearest obstacle `site[i]` of the minimising element.
///
/// Meijster et al.'s integer lower envelope: a parabola is kept only if it
/// is strictly lowest at one integer at least, so every `x` advances the
/// envelope by at most one parabola and the output loop has no
/// data-dependent branch. Ties keep the leftmost parabola.
///
/// Element `i` of the line is at index `i * stride` of every slice, so one
/// lane of a tile can be scanned in place; `n` is the line's length.
pub(crate) fn envelope(line: Line<'_>, out_f: &mut [u32], out_site: &mut [u32], s: &mut EnvelopeScratch) {
    let Line { site, stride, n, .. } = line;
    if s.stack.len() < n + 1 {
        s.stack.resize(n + 1, Parabola::default());
    }
    let k = build_envelope(line, &mut s.stack);
    if k == 0 {
        for x in 0..n {
            out_f[x * stride] = UNREACHABLE_DIST_SQ;
            out_site[x * stride] = NO_SITE;
        }
        return;
    }
    // Sentinel: no parabola starts inside the line after the last one.
    s.stack[k].start = n as i64;
    let mut j = 0;
    for x in 0..n {
        j += usize::from(s.stack[j + 1].start == x as i64);
        let p = s.stack[j];
        let d = x as i64 - p.pos;
        out_f[x * stride] = (d * d + p.f) as u32;
        out_site[x * stride] = site[p.pos as usize * stride];
    }
}

/// One line of squared distances `f` and nearest obstacles `site`, element
/// `i` at index `i * stride`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Line<'a> {
    pub(crate) f: &'a [u32],
    pub(crate) site: &'a [u32],
    pub(crate) stride: usize,
    pub(crate) n: usize,
}

/// Builds the lower envelope of the finite parabolas of `f` into `stack`;
/// returns the number of parabolas in it.
#[inline]
fn build_envelope(line: Line<'_>, stack: &mut [Parabola]) -> usize {
    let n = line.n as i64;
    let mut k = 0usize;
    for q in 0..line.n {
        let fq = line.f[q * line.stride];
        if fq == UNREACHABLE_DIST_SQ {
            continue;
        }
        let (q, fq) = (q as i64, i64::from(fq));
        // Drop the parabolas that q beats strictly where they start.
        while k > 0 {
            let top = stack[k - 1];
            let d = top.start - q;
            if top.at_start > d * d + fq {
                k -= 1;
            } else {
                break;
            }
        }
        let start = match k {
            0 => 0,
            _ => {
                let top = stack[k - 1];
                // q is strictly lower than top from the first x with
                // x > ((fq + q²) - (f + p²)) / (2 (q - p)).
                let num = fq + q * q - top.f - top.pos * top.pos;
                1 + num.div_euclid(2 * (q - top.pos))
            }
        };
        if start < n {
            let d = start - q;
            stack[k] = Parabola { pos: q, f: fq, start, at_start: d * d + fq };
            k += 1;
        }
    }
    k
}

#[cfg(test)]
mod tests {
    use super::*;

    fn brute(f: &[u32]) -> Vec<u32> {
        (0..f.len())
            .map(|x| {
                f.iter()
                    .enumerate()
                    .filter(|(_, &v)| v != UNREACHABLE_DIST_SQ)
                    .map(|(i, &v)| (x as u64).abs_diff(i as u64).pow(2) as u32 + v)
                    .min()
                    .unwrap_or(UNREACHABLE_DIST_SQ)
            })
            .collect()
    }

    #[test]
    fn envelope_matches_brute_force_on_small_lines() {
        // Every line of length up to 7 over the values {0, 1, 2, 4, 9, inf}
        // (2 makes crossings between integers and ties at them).
        let vals = [0, 1, 2, 4, 9, UNREACHABLE_DIST_SQ];
        let mut s = EnvelopeScratch::default();
        for n in 1..=7usize {
            for code in 0..vals.len().pow(n as u32) {
                let f: Vec<u32> = (0..n).map(|i| vals[code / vals.len().pow(i as u32) % vals.len()]).collect();
                let site: Vec<u32> = (0..n as u32).collect();
                let (mut out, mut out_site) = (vec![0; n], vec![0; n]);
                let line = Line { f: &f, site: &site, stride: 1, n };
                envelope(line, &mut out, &mut out_site, &mut s);
                assert_eq!(out, brute(&f), "line {f:?}");
                for (x, (&d, &p)) in out.iter().zip(&out_site).enumerate() {
                    if d != UNREACHABLE_DIST_SQ {
                        let p = p as usize;
                        assert_eq!(d, (x.abs_diff(p).pow(2)) as u32 + f[p], "line {f:?} x {x}");
                        // Ties keep the leftmost parabola.
                        let first =
                            (0..n).find(|&i| f[i] != UNREACHABLE_DIST_SQ && x.abs_diff(i).pow(2) as u32 + f[i] == d);
                        assert_eq!(Some(p), first, "line {f:?} x {x}: ties go to the lowest position");
                    }
                }
            }
        }
    }

    #[test]
    fn sweep_row_finds_nearest_in_row() {
        let row = [false, true, false, false, false, true, false];
        let (mut d, mut n) = (vec![0; 7], vec![0; 7]);
        sweep_row(|x| row[x], 100, &mut d, &mut n);
        assert_eq!(d, [1, 0, 1, 4, 1, 0, 1]);
        assert_eq!(n[0], 101);
        assert_eq!(n[6], 105);
        let (mut d, mut n) = (vec![0; 3], vec![0; 3]);
        sweep_row(|_| false, 0, &mut d, &mut n);
        assert_eq!(d, [UNREACHABLE_DIST_SQ; 3]);
        assert_eq!(n, [NO_SITE; 3]);
    }
}
