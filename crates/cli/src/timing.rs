//! Repeated timing of a computation.

use std::time::Instant;

/// Wall-clock times of repeated runs, in milliseconds.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct RunTimes {
    ms: Vec<f64>,
}

impl RunTimes {
    /// Runs `f` `runs` times (at least once) and keeps the last result.
    pub(crate) fn measure<T>(runs: usize, mut f: impl FnMut() -> T) -> (T, RunTimes) {
        let mut timed = || {
            let start = Instant::now();
            let value = f();
            (value, start.elapsed().as_secs_f64() * 1e3)
        };
        let (mut last, first_ms) = timed();
        let mut ms = vec![first_ms];
        for _ in 1..runs {
            let (value, run_ms) = timed();
            last = value;
            ms.push(run_ms);
        }
        (last, RunTimes { ms })
    }

    pub(crate) fn runs(&self) -> usize {
        self.ms.len()
    }

    pub(crate) fn min_ms(&self) -> f64 {
        self.ms.iter().copied().fold(f64::INFINITY, f64::min)
    }

    /// The median (mean of the two middle runs for an even count), as
    /// `report.json` and `run`'s summary define it.
    pub(crate) fn median_ms(&self) -> f64 {
        crate::report::median(&self.ms).unwrap_or(f64::NAN)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_odd_and_even_counts() {
        assert_eq!(RunTimes { ms: vec![3.0, 1.0, 2.0] }.median_ms(), 2.0);
        assert_eq!(RunTimes { ms: vec![4.0, 1.0, 2.0, 3.0] }.median_ms(), 2.5);
        assert_eq!(RunTimes { ms: vec![4.0, 1.0] }.min_ms(), 1.0);
    }

    #[test]
    fn measure_runs_at_least_once() {
        let mut calls = 0;
        let (v, t) = RunTimes::measure(0, || {
            calls += 1;
            calls
        });
        assert_eq!((v, t.runs()), (1, 1));
    }
}
