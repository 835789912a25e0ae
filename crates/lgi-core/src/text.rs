//! Numbers in messages: what a user reads in an error is a number with four significant
//! digits and its unit, and a point is `(x, y, z)`, never Rust's debug formatting
//! (`DVec3(-1489.9417…)`, `1.1165008027718248e4`).

use glam::{DVec2, DVec3};

/// `x` with four significant digits, plain between 1e-4 and 1e6, else in exponent form
/// (`0.0123`, `1489`, `2.5e+07`, `nan`, `inf`).
pub(crate) fn num(x: f64) -> String {
    if !x.is_finite() {
        return format!("{x}");
    }
    if x == 0.0 {
        return "0".to_string();
    }
    let a = x.abs();
    if !(1e-4..1e6).contains(&a) {
        let s = format!("{x:.3e}");
        // `1.500e7` -> `1.5e+07`: trailing zeros of the mantissa and a signed two-digit exponent.
        let (m, e) = s.split_once('e').unwrap_or((&s, "0"));
        let m = trim_zeros(m);
        let e: i32 = e.parse().unwrap_or(0);
        let sign = if e < 0 { '-' } else { '+' };
        return format!("{m}e{sign}{:02}", e.abs());
    }
    let digits = 3 - a.log10().floor() as i32;
    trim_zeros(&format!("{x:.*}", digits.max(0) as usize)).to_string()
}

fn trim_zeros(s: &str) -> &str {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        s
    }
}

/// `x` with its unit (`12.5 cm`); the bare number when the unit is unknown (empty).
pub(crate) fn length(x: f64, units: &str) -> String {
    if units.is_empty() {
        num(x)
    } else {
        format!("{} {units}", num(x))
    }
}

/// A point as `(x, y, z)` with [`num`]'s digits.
pub(crate) fn point(p: DVec3) -> String {
    format!("({}, {}, {})", num(p.x), num(p.y), num(p.z))
}

/// A 2D point (a UV) as `(u, v)`.
pub(crate) fn uv(p: DVec2) -> String {
    format!("({}, {})", num(p.x), num(p.y))
}

/// A point with its unit: `(1, 2, 3) cm`.
pub(crate) fn point_in(p: DVec3, units: &str) -> String {
    if units.is_empty() {
        point(p)
    } else {
        format!("{} {units}", point(p))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn num_keeps_four_significant_digits_and_no_debug_forms() {
        assert_eq!(num(11165.008027718248), "11165");
        assert_eq!(num(-1489.9417), "-1490");
        assert_eq!(num(0.012345), "0.01235");
        assert_eq!(num(2.5), "2.5");
        assert_eq!(num(100.0), "100");
        assert_eq!(num(0.0), "0");
        assert_eq!(num(1e30), "1e+30");
        assert_eq!(num(-2.5e-7), "-2.5e-07");
        assert_eq!(num(f64::NAN), "NaN");
        assert_eq!(num(f64::INFINITY), "inf");
    }

    #[test]
    fn points_and_lengths_carry_the_unit_when_known() {
        let p = DVec3::new(-1489.9417, 0.5, 3.0);
        assert_eq!(point(p), "(-1490, 0.5, 3)");
        assert_eq!(point_in(p, "cm"), "(-1490, 0.5, 3) cm");
        assert_eq!(length(21.5, "mm"), "21.5 mm");
        assert_eq!(length(21.5, ""), "21.5");
    }
}
