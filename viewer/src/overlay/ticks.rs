//! Round numbers for a legend: tick values at 1, 2 or 5 × 10ᵏ steps, and numbers printed
//! as people write them (`0.05`, `12`, `1.2e-3`, `3e5`).

/// Ticks inside `[lo, hi]` at a round step, 3 to 7 of them when the range allows (a range
/// of zero width gives its one value); ascending.
pub fn nice_ticks(lo: f64, hi: f64) -> Vec<f64> {
    if !(lo.is_finite() && hi.is_finite()) {
        return Vec::new();
    }
    let (lo, hi) = (lo.min(hi), lo.max(hi));
    if hi - lo <= f64::EPSILON * hi.abs().max(lo.abs()).max(f64::MIN_POSITIVE) {
        return vec![lo];
    }
    // The smallest round step giving at most 7 ticks, then the first that gives at least 3.
    let mut best: Option<Vec<f64>> = None;
    for step in candidate_steps(hi - lo) {
        let ticks = ticks_at(lo, hi, step);
        if ticks.len() <= 7 && ticks.len() >= 3 {
            // Candidates run from small to large steps: the first that fits has the most
            // ticks within the limit.
            return ticks;
        }
        if ticks.len() <= 7 && best.is_none() {
            best = Some(ticks);
        }
    }
    best.unwrap_or_else(|| vec![lo, hi])
}

/// Round steps `m · 10ᵉ` (m = 1, 2, 5) from about a twentieth of the range up to the
/// range, ascending.
fn candidate_steps(range: f64) -> Vec<(f64, i32)> {
    let k = (range / 20.0).log10().floor() as i32;
    let mut steps = Vec::new();
    for e in k..=k + 3 {
        for m in [1.0, 2.0, 5.0] {
            steps.push((m, e));
        }
    }
    steps
}

/// The multiples of `m · 10ᵉ` in `[lo, hi]`, each the correctly rounded `f64` of its
/// decimal value (`i·m / 10⁻ᵉ`: a division by an exact power of ten, so 78 × 0.05 prints
/// as 3.9, not 3.9000000000000004).
fn ticks_at(lo: f64, hi: f64, (m, e): (f64, i32)) -> Vec<f64> {
    let step = m * 10f64.powi(e);
    let value = |i: f64| {
        if e < 0 {
            i * m / 10f64.powi(-e)
        } else {
            i * m * 10f64.powi(e)
        }
    };
    let first = (lo / step).ceil();
    let last = (hi / step).floor();
    if !(first.is_finite() && last.is_finite()) || last - first > 1000.0 {
        return Vec::new();
    }
    let mut v = Vec::new();
    let mut i = first;
    while i <= last {
        let t = value(i);
        if t >= lo && t <= hi {
            v.push(if t == 0.0 { 0.0 } else { t });
        }
        i += 1.0;
    }
    v
}

/// `v` as printed on a legend whose ticks are `step` apart: as many decimals as the step
/// needs, in scientific notation (`1.2e-3`) for magnitudes below 0.01 or from 10⁵ on.
pub fn format_tick(v: f64, step: f64) -> String {
    if v == 0.0 {
        return "0".to_string();
    }
    let mag = v.abs();
    if !(1e-2..1e5).contains(&mag) {
        // Significant digits of the step relative to the value, at least one.
        let digits = ((mag.log10().floor() - step.abs().log10().floor()).max(0.0) as usize).min(6);
        return trim_exponent(&format!("{v:.digits$e}"));
    }
    let decimals = if step > 0.0 && step.is_finite() {
        (-step.log10().floor()).max(0.0) as usize
    } else {
        3
    };
    format!("{v:.decimals$}")
}

/// A value of its own (an iso value): 3 significant digits, in the same notation rules as
/// [`format_tick`].
pub fn format_value(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let step = 10f64.powf(v.abs().log10().floor() - 2.0);
    let s = format_tick(v, step);
    // Trailing zeros of the decimals say nothing here.
    if s.contains('.') && !s.contains('e') {
        let t = s.trim_end_matches('0').trim_end_matches('.');
        return t.to_string();
    }
    s
}

/// Rust prints `1.2e-3` already; `1.0e5` becomes `1e5`.
fn trim_exponent(s: &str) -> String {
    match s.split_once('e') {
        Some((m, e)) => {
            let m = if m.contains('.') {
                m.trim_end_matches('0').trim_end_matches('.')
            } else {
                m
            };
            format!("{m}e{e}")
        }
        None => s.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_round_inside_and_three_to_seven() {
        for (lo, hi) in [
            (0.0, 1.0),
            (0.012, 0.072),
            (-0.3, 0.56),
            (0.0, 0.0613),
            (3.7, 3.9),
            (-1e-4, 2e-3),
            (1.0, 1000.0),
            (12345.0, 98765.0),
            (-5.0, -4.99),
        ] {
            let t = nice_ticks(lo, hi);
            assert!((3..=7).contains(&t.len()), "{lo}..{hi}: {t:?}");
            assert!(t.iter().all(|&v| v >= lo && v <= hi), "{lo}..{hi}: {t:?}");
            // Each is the f64 nearest its decimal (prints without round-off digits).
            assert!(
                t.iter().all(|v| format!("{v}").len() < 12),
                "{lo}..{hi}: {t:?}"
            );
            let step = t[1] - t[0];
            let m = step / 10f64.powf(step.log10().floor());
            assert!(
                [1.0, 2.0, 5.0, 10.0].iter().any(|r| (m - r).abs() < 1e-6),
                "{lo}..{hi}: step {step}"
            );
        }
        assert_eq!(nice_ticks(2.0, 2.0), vec![2.0]);
        assert!(nice_ticks(f64::NAN, 1.0).is_empty());
    }

    #[test]
    fn numbers_print_as_people_write_them() {
        assert_eq!(format_tick(0.05, 0.01), "0.05");
        assert_eq!(format_tick(0.3, 0.1), "0.3");
        assert_eq!(format_tick(12.0, 2.0), "12");
        assert_eq!(format_tick(0.0012, 0.0002), "1.2e-3");
        assert_eq!(format_tick(0.002, 0.001), "2e-3");
        assert_eq!(format_tick(300000.0, 100000.0), "3e5");
        assert_eq!(format_tick(0.0, 0.5), "0");
        assert_eq!(format_value(0.05), "0.05");
        assert_eq!(format_value(1.18), "1.18");
        assert_eq!(format_value(-0.00125), "-1.25e-3");
    }
}
