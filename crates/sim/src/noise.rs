//! Per-ray measurement noise, deterministic from (seed, frame, ray).
//!
//! Each ray hashes its key with splitmix64 into a private stream, so the
//! noise does not depend on the order in which rayon casts the rays.

/// Gaussian range noise and dropout for one frame.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RayNoise {
    key: u64,
    sigma_m: f64,
    dropout: f64,
}

impl RayNoise {
    /// The noise of frame `frame` under `seed`.
    pub(crate) fn new(seed: u64, frame: usize, sigma_m: f64, dropout: f64) -> Self {
        RayNoise { key: mix(mix(seed) ^ frame as u64), sigma_m, dropout }
    }

    /// The measured value of ray `ray` whose true value is `value`: NaN when
    /// dropped, else `value` plus Gaussian noise.
    pub(crate) fn apply(&self, ray: usize, value: f64) -> f64 {
        if self.sigma_m == 0.0 && self.dropout == 0.0 {
            return value;
        }
        let mut stream = Stream(mix(self.key ^ ray as u64));
        if stream.unit() < self.dropout {
            return f64::NAN;
        }
        value + self.sigma_m * stream.gaussian()
    }
}

/// The splitmix64 output function of `x`.
fn mix(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A splitmix64 stream.
struct Stream(u64);

impl Stream {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        mix(self.0)
    }

    /// Uniform in `[0, 1)`.
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Standard normal (Box–Muller).
    fn gaussian(&mut self) -> f64 {
        let u1 = 1.0 - self.unit();
        let u2 = self.unit();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_has_the_asked_statistics() {
        let n = RayNoise::new(7, 3, 0.02, 0.1);
        let values: Vec<f64> = (0..20000).map(|i| n.apply(i, 5.0)).collect();
        let kept: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
        let drop = 1.0 - kept.len() as f64 / values.len() as f64;
        assert!((drop - 0.1).abs() < 0.01, "dropout {drop}");
        let mean = kept.iter().sum::<f64>() / kept.len() as f64;
        let sd = (kept.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / kept.len() as f64).sqrt();
        assert!((mean - 5.0).abs() < 0.001 && (sd - 0.02).abs() < 0.001, "mean {mean} sd {sd}");
    }

    #[test]
    fn noise_is_a_function_of_seed_frame_and_ray() {
        let a = RayNoise::new(7, 3, 0.02, 0.0);
        assert_eq!(a.apply(10, 1.0), RayNoise::new(7, 3, 0.02, 0.0).apply(10, 1.0));
        assert_ne!(a.apply(10, 1.0), RayNoise::new(8, 3, 0.02, 0.0).apply(10, 1.0));
        assert_ne!(a.apply(10, 1.0), RayNoise::new(7, 4, 0.02, 0.0).apply(10, 1.0));
        assert_ne!(a.apply(10, 1.0), a.apply(11, 1.0));
        assert_eq!(RayNoise::new(7, 3, 0.0, 0.0).apply(10, 1.25), 1.25);
    }
}
