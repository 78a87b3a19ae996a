//! Axis ranges and tick values: "nice" steps of 1, 2 or 5 × 10^k on linear
//! axes, whole decades (or 1, 2, 5 per decade) on log axes.

/// Slack for float round-off when comparing tick multiples with bounds.
const EPS: f64 = 1e-9;
/// More ticks than this are never drawn, whatever the float round-off.
const MAX_TICKS: usize = 1000;

/// The smallest step of 1, 2 or 5 × 10^k that splits `span` into at most
/// `max_count` intervals; not finite when `span` is not.
pub(super) fn nice_step(span: f64, max_count: usize) -> f64 {
    let raw = span / max_count.max(1) as f64;
    let k = (raw.log10() + EPS).floor();
    [1.0, 2.0, 5.0, 10.0].into_iter().map(|m| scaled(m, k)).find(|&s| s >= raw * (1.0 - EPS)).unwrap_or(f64::NAN)
}

/// `m` × 10^`k` for an integer `k`, rounded once (10^k itself is exact
/// up to 10^22, so dividing by 10^-k beats multiplying by 10^k < 1).
fn scaled(m: f64, k: f64) -> f64 {
    if k >= 0.0 {
        m * 10f64.powf(k)
    } else {
        m / 10f64.powf(-k)
    }
}

/// The multiples of `step` in `[lo, hi]`.
pub(super) fn linear_ticks(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let (first, last) = ((lo / step - EPS).ceil(), (hi / step + EPS).floor());
    if !(first.is_finite() && last.is_finite() && first <= last && last - first < MAX_TICKS as f64) {
        return Vec::new();
    }
    (0..=(last - first) as usize).map(|i| (first + i as f64) * step).collect()
}

/// Ticks of a log axis over `[lo, hi]` (both positive), at most about
/// `max_count`: decades (every n-th when there are many), or 1, 2 and 5
/// times each decade when there is room for them, or linear ticks when
/// even those are fewer than two.
pub(super) fn log_ticks(lo: f64, hi: f64, max_count: usize) -> Vec<f64> {
    let (a, b) = ((lo.log10() - EPS).ceil(), (hi.log10() + EPS).floor());
    if !(a.is_finite() && b.is_finite()) {
        return Vec::new();
    }
    let max_count = max_count.max(1);
    if b - a >= 1.0 && 3.0 * (b - a) > max_count as f64 {
        let decades = ((b - a) as usize + 1).min(MAX_TICKS);
        let every = decades.div_ceil(max_count);
        return (0..decades).step_by(every).map(|i| scaled(1.0, a + i as f64)).collect();
    }
    let first = (lo.log10() + EPS).floor();
    let ticks: Vec<f64> = (0..=(b - first).max(0.0) as usize)
        .flat_map(|i| [1.0, 2.0, 5.0].map(|m| scaled(m, first + i as f64)))
        .filter(|&v| v >= lo * (1.0 - EPS) && v <= hi * (1.0 + EPS))
        .collect();
    if ticks.len() >= 2 {
        return ticks;
    }
    linear_ticks(lo, hi, nice_step(hi - lo, max_count))
}

/// The range `[min, max]` of data widened to whole ticks: multiples of the
/// nice step on a linear axis, decades on a log axis. A single value is
/// widened first (by 10 % of itself, or 1 at zero; a decade each way on a
/// log axis).
pub(super) fn auto_range(min: f64, max: f64, log: bool, max_count: usize) -> (f64, f64) {
    if log {
        let (a, b) = ((min.log10() + EPS).floor(), (max.log10() - EPS).ceil());
        let (a, b) = if a < b { (a, b) } else { (a - 1.0, a + 1.0) };
        return (scaled(1.0, a), scaled(1.0, b));
    }
    let (min, max) = if min < max {
        (min, max)
    } else {
        let pad = if min == 0.0 { 1.0 } else { 0.1 * min.abs() };
        (min - pad, max + pad)
    };
    let step = nice_step(max - min, max_count);
    ((min / step + EPS).floor() * step, (max / step - EPS).ceil() * step)
}

/// Labels of `ticks`, each with the fewest digits that give its value
/// (to a millionth of the spacing of its neighbours): fixed-point, or
/// exponent form (`2e-5`, `1.5e6`) on an axis with a huge or a tiny value.
pub(super) fn labels(ticks: &[f64]) -> Vec<String> {
    let exponent_form = ticks.iter().any(|&v| v.is_finite() && v != 0.0 && !(1e-4..1e6).contains(&v.abs()));
    (0..ticks.len())
        .map(|i| {
            let v = ticks[i];
            let gap = [i.checked_sub(1), Some(i + 1)]
                .into_iter()
                .flatten()
                .filter_map(|j| ticks.get(j))
                .map(|&n| (n - v).abs())
                .fold(f64::INFINITY, f64::min);
            let tolerance = 1e-6 * if gap.is_finite() && gap > 0.0 { gap } else { v.abs() };
            let format = |digits: usize| match exponent_form {
                _ if v == 0.0 => "0".to_string(),
                true => format!("{v:.digits$e}"),
                false => format!("{v:.digits$}"),
            };
            (0..=16)
                .map(format)
                .find(|s| s.parse::<f64>().is_ok_and(|p| (p - v).abs() <= tolerance))
                .unwrap_or_else(|| format!("{v}"))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: &[f64], b: &[f64]) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() <= 1e-9 * y.abs().max(1e-300))
    }

    #[test]
    fn steps_are_one_two_or_five_times_a_power_of_ten() {
        assert_eq!(nice_step(1.0, 5), 0.2);
        assert_eq!(nice_step(1.0, 10), 0.1);
        assert_eq!(nice_step(15.9, 5), 5.0);
        assert_eq!(nice_step(7.0, 1), 10.0);
        assert_eq!(nice_step(3e-5, 6), 5e-6);
        assert_eq!(nice_step(1200.0, 6), 200.0);
    }

    #[test]
    fn auto_ranges_widen_to_whole_steps() {
        assert_eq!(auto_range(0.013, 0.87, false, 5), (0.0, 1.0));
        assert_eq!(auto_range(-3.7, 12.2, false, 5), (-5.0, 15.0));
        assert_eq!(auto_range(1.0, 100.0, false, 5), (0.0, 100.0));
        let (lo, hi) = auto_range(3.0, 3.0, false, 5);
        assert!(lo < 3.0 && hi > 3.0);
        assert_eq!(auto_range(0.0, 0.0, false, 4), (-1.0, 1.0));
        assert_eq!(auto_range(0.03, 420.0, true, 5), (0.01, 1000.0));
        assert_eq!(auto_range(10.0, 10.0, true, 5), (1.0, 100.0));
    }

    #[test]
    fn linear_ticks_are_the_multiples_inside_the_range() {
        assert!(close(&linear_ticks(0.0, 1.0, 0.2), &[0.0, 0.2, 0.4, 0.6, 0.8, 1.0]));
        assert!(close(&linear_ticks(-3.7, 12.2, 5.0), &[0.0, 5.0, 10.0]));
        assert!(close(&linear_ticks(0.1, 0.3, 0.1), &[0.1, 0.2, 0.3]));
        assert!(linear_ticks(f64::NAN, 1.0, 0.5).is_empty());
        assert!(linear_ticks(0.0, 1.0, 0.0).is_empty());
    }

    #[test]
    fn log_ticks_are_decades_or_one_two_five() {
        assert!(close(&log_ticks(1.0, 1000.0, 8), &[1.0, 10.0, 100.0, 1000.0]));
        assert!(close(&log_ticks(1e-6, 1e6, 5), &[1e-6, 1e-3, 1.0, 1e3, 1e6]));
        assert!(close(&log_ticks(1.0, 10.0, 8), &[1.0, 2.0, 5.0, 10.0]));
        assert!(close(&log_ticks(3.0, 8.0, 5), &[3.0, 4.0, 5.0, 6.0, 7.0, 8.0]));
        assert!(close(&log_ticks(0.01, 1.0, 8), &[0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0]));
    }

    #[test]
    fn labels_use_as_many_decimals_as_the_spacing_needs() {
        assert_eq!(labels(&[0.0, 0.2, 0.4]), ["0", "0.2", "0.4"]);
        assert_eq!(labels(&[-5.0, 0.0, 5.0]), ["-5", "0", "5"]);
        assert_eq!(labels(&[0.25, 0.5]), ["0.25", "0.5"]);
        assert_eq!(labels(&[0.1, 0.2, 0.30000000000000004]), ["0.1", "0.2", "0.3"]);
        assert_eq!(labels(&[1.0, 10.0, 100.0]), ["1", "10", "100"]);
        assert_eq!(labels(&[0.001, 0.01, 0.1]), ["0.001", "0.01", "0.1"]);
        assert_eq!(labels(&[0.0, 2e-5, 4e-5]), ["0", "2e-5", "4e-5"]);
        assert_eq!(labels(&[1e-6, 1e-3, 1.0]), ["1e-6", "1e-3", "1e0"]);
        assert_eq!(labels(&[1e6, 1.5e6, 2e6]), ["1e6", "1.5e6", "2e6"]);
        assert_eq!(labels(&[f64::NAN]), ["NaN"]);
    }
}
