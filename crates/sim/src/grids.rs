use edtmap_core::{CoreError, Grid3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// A grid whose voxels are obstacles independently with probability
/// `density` (clamped to `[0, 1]`; NaN gives no obstacle).
pub fn random_grid(dims: [usize; 3], density: f64, seed: u64) -> Result<Grid3<bool>, CoreError> {
    let mut rng = StdRng::seed_from_u64(seed);
    // NaN counts as no obstacles.
    let density = if density.is_nan() { 0.0 } else { density.clamp(0.0, 1.0) };
    Grid3::from_fn(dims, |_, _, _| rng.random_bool(density))
}

/// Layout of the structured scene [`pillar_field`]: a floor, an outer wall,
/// one inner wall with a doorway and round pillars of random radius.
#[derive(Debug, Clone, PartialEq)]
pub struct PillarField {
    /// Grid dimensions `[nx, ny, nz]` in voxels.
    pub dims: [usize; 3],
    /// Number of pillars.
    pub pillars: usize,
    /// Pillar radius range in voxels.
    pub radius_vox: (f64, f64),
    /// Seed of the pillar placement.
    pub seed: u64,
}

impl PillarField {
    /// A field of `dims` with about one pillar per 800 floor voxels.
    pub fn new(dims: [usize; 3], seed: u64) -> Self {
        let pillars = (dims[0] * dims[1] / 800).max(1);
        let r_max = (dims[0].min(dims[1]) as f64 / 24.0).max(1.0);
        PillarField { dims, pillars, radius_vox: (r_max / 2.0, r_max), seed }
    }
}

/// Rasterises a [`PillarField`]: `true` marks an obstacle voxel.
pub fn pillar_field(field: &PillarField) -> Result<Grid3<bool>, CoreError> {
    Grid3::<bool>::voxel_count(field.dims)?;
    let [nx, ny, _] = field.dims;
    let mut rng = StdRng::seed_from_u64(field.seed);
    let (r_lo, r_hi) = field.radius_vox;
    let (r_lo, r_hi) = (r_lo.max(0.0), r_hi.max(0.0));
    let pillars: Vec<(f64, f64, f64)> = (0..field.pillars)
        .map(|_| {
            let r = if r_hi > r_lo { rng.random_range(r_lo..r_hi) } else { r_lo };
            // Non-empty ranges: the axes were checked above.
            (rng.random_range(0.0..nx as f64), rng.random_range(0.0..ny as f64), r)
        })
        .collect();
    let wall_x = nx / 2;
    let door = (ny / 3)..(ny / 3 + ny / 6 + 1);
    Grid3::from_fn(field.dims, |x, y, z| {
        let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
        let floor = z == 0;
        let outer = x == 0 || y == 0 || x + 1 == nx || y + 1 == ny;
        let inner = x == wall_x && !door.contains(&y);
        let pillar = pillars.iter().any(|&(cx, cy, r)| (px - cx).powi(2) + (py - cy).powi(2) <= r * r);
        floor || outer || inner || pillar
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn random_grid_is_seeded_and_has_the_density() {
        let a = random_grid([32, 32, 32], 0.1, 7).expect("valid dims");
        let b = random_grid([32, 32, 32], 0.1, 7).expect("valid dims");
        assert_eq!(a, b);
        let frac = a.as_slice().iter().filter(|&&o| o).count() as f64 / a.len() as f64;
        assert!((frac - 0.1).abs() < 0.01, "density {frac}");
        let none = random_grid([4, 4, 4], f64::NAN, 7).expect("valid dims");
        assert!(none.as_slice().iter().all(|&o| !o));
    }

    #[test]
    fn pillar_field_refuses_an_empty_axis() {
        assert!(pillar_field(&PillarField::new([8, 0, 8], 1)).is_err());
        let mut odd = PillarField::new([8, 8, 8], 1);
        odd.radius_vox = (f64::NAN, -3.0);
        assert!(pillar_field(&odd).is_ok());
    }

    #[test]
    fn pillar_field_has_floor_walls_and_free_space() {
        let g = pillar_field(&PillarField::new([64, 48, 16], 3)).expect("valid dims");
        assert_eq!(g.get([10, 10, 0]), Some(&true));
        assert_eq!(g.get([0, 20, 5]), Some(&true));
        assert_eq!(g.get([32, 2, 5]), Some(&true));
        assert_eq!(g.get([32, 18, 5]), Some(&false), "doorway is open");
        let free = g.as_slice().iter().filter(|&&o| !o).count();
        assert!(free > g.len() / 2);
    }
}
