//! Small numeric helpers shared by the models: fast, deterministic trigonometry.

/// Moves `value` towards `target` by at most `step`.
#[inline]
pub(crate) fn approach(value: f64, target: f64, step: f64) -> f64 {
    if (target - value).abs() <= step {
        target
    } else if target > value {
        value + step
    } else {
        value - step
    }
}

/// 0 at 0, 1 at 1, flat at both ends.
#[inline]
pub(crate) fn smoothstep(t: f64) -> f64 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Euclidean length. `f64::hypot` guards against overflow at a cost the simulator's small
/// numbers do not need (it was a fifth of the step time).
#[inline]
pub(crate) fn length(x: f64, y: f64) -> f64 {
    (x * x + y * y).sqrt()
}

/// Below this (rad), [`sin_cos`] skips the range reduction.
const SMALL_ANGLE: f64 = 0.25;
/// Below this (rad), [`sin_cos`] needs four terms per series.
const TINY_ANGLE: f64 = 0.0625;

/// Taylor coefficients: (-1)^k / (2k+1)! for the sine, (-1)^k / (2k)! for the cosine (k >= 1).
const S: [f64; 8] = [
    -1.0 / 6.0,
    1.0 / 120.0,
    -1.0 / 5040.0,
    1.0 / 362_880.0,
    -1.0 / 39_916_800.0,
    1.0 / 6_227_020_800.0,
    -1.0 / 1_307_674_368_000.0,
    1.0 / 355_687_428_096_000.0,
];
const C: [f64; 9] = [
    -1.0 / 2.0,
    1.0 / 24.0,
    -1.0 / 720.0,
    1.0 / 40_320.0,
    -1.0 / 3_628_800.0,
    1.0 / 479_001_600.0,
    -1.0 / 87_178_291_200.0,
    1.0 / 20_922_789_888_000.0,
    -1.0 / 6_402_373_705_728_000.0,
];

/// Sine and cosine without the library: a Taylor series on [-pi/4, pi/4] after reduction by
/// quarter turns (Cody-Waite, two-part pi/2), exact to about 1e-16 for the angles a simulation
/// sees. Pure arithmetic, so deterministic, and about twice as fast as `f64::sin_cos`, which
/// was a sixth of the step time.
#[inline(always)]
pub(crate) fn sin_cos(x: f64) -> (f64, f64) {
    if x.abs() < TINY_ANGLE {
        // Tiny angles (a step's turn, torso sway) need even fewer terms: the next ones are
        // below 3e-19 at 1/16 rad.
        let z = x * x;
        let sin = x + x * z * (S[0] + z * (S[1] + z * (S[2] + z * S[3])));
        let cos = 1.0 + z * (C[0] + z * (C[1] + z * (C[2] + z * C[3])));
        return (sin, cos);
    }
    if x.abs() < SMALL_ANGLE {
        // Small angles (turns and gait phase per step, sway, tilt) need no reduction and
        // fewer terms: the next terms are below 3e-18 at 0.25 rad.
        let z = x * x;
        let sin = x + x * z * (S[0] + z * (S[1] + z * (S[2] + z * (S[3] + z * S[4]))));
        let cos = 1.0 + z * (C[0] + z * (C[1] + z * (C[2] + z * (C[3] + z * (C[4] + z * C[5])))));
        return (sin, cos);
    }
    sin_cos_reduced(x)
}

#[inline(never)]
fn sin_cos_reduced(x: f64) -> (f64, f64) {
    if !x.is_finite() || x.abs() > 1e5 {
        return x.sin_cos();
    }
    // pi/2 rounded to a double, and the part of pi/2 that rounding lost.
    const PIO2_HI: f64 = std::f64::consts::FRAC_PI_2;
    const PIO2_LO: f64 = 6.123_233_995_736_766e-17;
    // Rounding by conversion: `f64::round` is a library call on baseline x86-64.
    let k = (x * std::f64::consts::FRAC_2_PI + 0.5f64.copysign(x)) as i64 as f64;
    let r = (x - k * PIO2_HI) - k * PIO2_LO;
    let z = r * r;
    let sin = r + r
        * z
        * (S[0]
            + z * (S[1]
                + z * (S[2] + z * (S[3] + z * (S[4] + z * (S[5] + z * (S[6] + z * S[7])))))));
    let cos = 1.0
        + z * (C[0]
            + z * (C[1]
                + z * (C[2]
                    + z * (C[3] + z * (C[4] + z * (C[5] + z * (C[6] + z * (C[7] + z * C[8]))))))));
    match (k as i64) & 3 {
        0 => (sin, cos),
        1 => (cos, -sin),
        2 => (-sin, -cos),
        _ => (-cos, sin),
    }
}

/// Taylor coefficients of atan, highest first: (-1)^k / (2k + 1) for k = 12 down to 1.
const ATAN: [f64; 12] = [
    1.0 / 25.0,
    -1.0 / 23.0,
    1.0 / 21.0,
    -1.0 / 19.0,
    1.0 / 17.0,
    -1.0 / 15.0,
    1.0 / 13.0,
    -1.0 / 11.0,
    1.0 / 9.0,
    -1.0 / 7.0,
    1.0 / 5.0,
    -1.0 / 3.0,
];

/// The angle of (x, y), without the library: reduction to [0, tan(pi/12)] and a Taylor series
/// (exact to about 2e-16), deterministic and about twice as fast as `f64::atan2`.
#[inline]
pub(crate) fn atan2(y: f64, x: f64) -> f64 {
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_6, PI};
    if !(x.is_finite() && y.is_finite()) || (x == 0.0 && y == 0.0) {
        return y.atan2(x);
    }
    let (ax, ay) = (x.abs(), y.abs());
    // atan of t = min / max in [0, 1].
    let (t, swapped) = if ay > ax { (ax / ay, true) } else { (ay / ax, false) };
    // Above tan(pi/12), shift by pi/6: atan t = pi/6 + atan((t sqrt3 - 1) / (t + sqrt3)).
    const TAN_PI_12: f64 = 0.267_949_192_431_122_7;
    const SQRT_3: f64 = 1.732_050_807_568_877_2;
    let (u, base) =
        if t > TAN_PI_12 { ((t * SQRT_3 - 1.0) / (t + SQRT_3), FRAC_PI_6) } else { (t, 0.0) };
    let z = u * u;
    // Horner from the highest term: 1/25 z^11 - 1/23 z^10 + ... - 1/3.
    let mut p = 0.0;
    for c in ATAN {
        p = p * z + c;
    }
    let series = u + u * z * p;
    let mut angle = base + series;
    if swapped {
        angle = FRAC_PI_2 - angle;
    }
    if x < 0.0 {
        angle = PI - angle;
    }
    if y < 0.0 { -angle } else { angle }
}

/// atan(k / 8) for k = 0..=8, correctly rounded (and padding: an index is masked to 4 bits).
const ATAN_EIGHTHS: [f64; 16] = [
    0.0,
    0.124_354_994_546_761_44,
    0.244_978_663_126_864_14,
    0.358_770_670_270_572_25,
    0.463_647_609_000_806_1,
    0.558_599_315_343_562_4,
    0.643_501_108_793_284_4,
    0.718_829_999_621_624_5,
    std::f64::consts::FRAC_PI_4,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
];

/// 1.5 * 2^52: adding it rounds a small non-negative number to an integer, which the sum's
/// lowest mantissa bits then hold (no float-to-integer conversion).
const ROUNDER: f64 = 6_755_399_441_055_744.0;

/// atan(t) for |t| <= 1: atan(c) + atan((t - c) / (1 + t c)) with c the nearest eighth, whose
/// series needs seven terms where [`atan2`]'s needs thirteen (within two units in the last
/// place).
#[inline]
fn atan_unit(t: f64) -> f64 {
    let a = t.abs();
    let rounded = a * 8.0 + ROUNDER;
    let k = (rounded.to_bits() & 15) as usize;
    let c = (rounded - ROUNDER) * 0.125;
    let u = (a - c) / (1.0 + a * c);
    let z = u * u;
    // |u| <= 1/16: the next term, u^15 / 15, is below 1e-18 of u.
    let p = -1.0 / 3.0
        + z * (1.0 / 5.0 + z * (-1.0 / 7.0 + z * (1.0 / 9.0 + z * (-1.0 / 11.0 + z / 13.0))));
    (ATAN_EIGHTHS[k] + (u + u * z * p)).copysign(t)
}

/// The angle of (x, y) like [`atan2`], faster for the points in front (x > 0, |y| <= x), such
/// as a camera's detections.
#[inline]
pub(crate) fn bearing(y: f64, x: f64) -> f64 {
    if x > 0.0 && y.abs() <= x { atan_unit(y / x) } else { atan2(y, x) }
}

/// Wraps an angle that is at most one turn outside (-pi, pi] back into it, without the
/// division of a general wrap.
#[inline]
pub(crate) fn wrap_near(angle: f64) -> f64 {
    use std::f64::consts::PI;
    if angle > PI {
        angle - 2.0 * PI
    } else if angle <= -PI {
        angle + 2.0 * PI
    } else {
        angle
    }
}

/// Sine and cosine of an angle that moves in small steps, kept by rotating the previous value
/// (four multiplications instead of a sine and a cosine) and recomputed exactly every few
/// steps so rounding cannot accumulate. The rotation of the last step is kept: a gait phase or
/// a head turning at its speed limit advances by the same step again and again.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Rotating {
    pub sin: f64,
    pub cos: f64,
    steps: u8,
    /// The last step and its sine and cosine.
    delta: f64,
    delta_sin: f64,
    delta_cos: f64,
}

impl Rotating {
    /// `Rotating::new(0.0)` written out: the odometry's turn is reset to it at every read
    /// (the same bits, see the test `the_zero_rotation_is_new_of_zero`).
    pub const ZERO: Rotating =
        Rotating { sin: 0.0, cos: 1.0, steps: 0, delta: 0.0, delta_sin: 0.0, delta_cos: 1.0 };

    pub fn new(angle: f64) -> Rotating {
        let (sin, cos) = sin_cos(angle);
        Rotating { sin, cos, steps: 0, delta: 0.0, delta_sin: 0.0, delta_cos: 1.0 }
    }

    /// The sine and cosine of `angle`, which is the previous angle plus `delta`.
    #[inline(always)]
    pub fn advance(&mut self, angle: f64, delta: f64) {
        self.steps += 1;
        if self.steps >= 32 || delta != self.delta {
            self.advance_by_new_step(angle, delta);
        } else {
            self.rotate();
        }
    }

    #[inline(never)]
    fn advance_by_new_step(&mut self, angle: f64, delta: f64) {
        if self.steps >= 32 || delta.abs() >= SMALL_ANGLE {
            let (sin, cos) = sin_cos(angle);
            (self.sin, self.cos, self.steps) = (sin, cos, 0);
            return;
        }
        (self.delta_sin, self.delta_cos) = sin_cos(delta);
        self.delta = delta;
        self.rotate();
    }

    /// Turns by the kept step.
    #[inline(always)]
    fn rotate(&mut self) {
        let (s, c) = (self.delta_sin, self.delta_cos);
        let sin = self.sin * c + self.cos * s;
        let cos = self.cos * c - self.sin * s;
        self.sin = sin;
        self.cos = cos;
    }
}

/// Wraps an angle into (-pi, pi], bit for bit as `strata_robot::normalize_angle`, without its
/// `%` (a library call) for angles within two turns: there `angle % 2pi` is `angle` or, exactly
/// (Sterbenz), `angle - 2pi`.
#[inline]
pub(crate) fn wrap_angle(angle: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    let mut a = if angle.abs() < TAU {
        angle
    } else if angle.abs() < 2.0 * TAU {
        // `%` keeps the dividend's sign, on a zero too.
        (angle - TAU.copysign(angle)).copysign(angle)
    } else {
        angle % TAU
    };
    if a <= -PI {
        a += TAU;
    } else if a > PI {
        a -= TAU;
    }
    a
}

/// Wraps an angle into (-pi/2, pi/2]: the direction of an undirected line.
#[inline]
pub(crate) fn wrap_half_turn(angle: f64) -> f64 {
    let mut a = wrap_angle(angle);
    if a > std::f64::consts::FRAC_PI_2 {
        a -= std::f64::consts::PI;
    } else if a <= -std::f64::consts::FRAC_PI_2 {
        a += std::f64::consts::PI;
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_trigonometry_matches_the_library() {
        for i in -2000..=2000 {
            let x = f64::from(i) * 1e-4;
            let (s, c) = sin_cos(x);
            let error = (s - x.sin()).abs().max((c - x.cos()).abs());
            assert!(error < 3e-16, "{x}: {error}");
        }
        for i in -100_000..=100_000 {
            let x = f64::from(i) * 1.3e-4;
            let (s, c) = sin_cos(x);
            let error = (s - x.sin()).abs().max((c - x.cos()).abs());
            assert!(error < 5e-16, "{x}: {error}");
        }
        assert!((length(3.0, 4.0) - 5.0).abs() < 1e-15);
        for i in -300..=300 {
            for j in -300..=300 {
                let (y, x) = (f64::from(i) * 0.037, f64::from(j) * 0.041);
                if i == 0 && j == 0 {
                    continue;
                }
                let error = (atan2(y, x) - y.atan2(x)).abs();
                assert!(error < 1e-15, "atan2({y}, {x}): {error}");
            }
        }
        let mut angle = 0.3;
        let mut r = Rotating::new(angle);
        for _ in 0..1000 {
            angle += 0.011;
            r.advance(angle, 0.011);
            let error = (r.sin - angle.sin()).abs().max((r.cos - angle.cos()).abs());
            // The reference accumulates rounding in `angle` itself (1e-15 per addition).
            assert!(error < 1e-13, "{angle}: {error} {r:?}");
        }
    }

    #[test]
    fn the_zero_rotation_is_new_of_zero() {
        let (zero, new) = (Rotating::ZERO, Rotating::new(0.0));
        let bits =
            |r: &Rotating| [r.sin, r.cos, r.delta, r.delta_sin, r.delta_cos].map(f64::to_bits);
        assert_eq!(bits(&zero), bits(&new));
        assert_eq!(zero.steps, new.steps);
    }

    #[test]
    fn bearings_in_front_match_the_library() {
        for i in -3000..=3000 {
            for x in [1e-3, 0.37, 1.0, 5.9, 1e6] {
                let y = x * f64::from(i) / 3000.0 * 1.0001;
                let (ours, libm) = (bearing(y, x), y.atan2(x));
                assert!(
                    (ours - libm).abs() <= 2.0 * f64::EPSILON * libm.abs(),
                    "({x}, {y}): {ours} vs {libm}"
                );
            }
        }
        assert_eq!(bearing(-0.0, 1.0).to_bits(), (-0.0f64).to_bits());
        assert_eq!(bearing(1.0, -1.0), atan2(1.0, -1.0));
        assert!(bearing(f64::NAN, 1.0).is_nan());
    }

    #[test]
    fn wrapping_matches_normalize_angle_bit_for_bit() {
        for i in -40_000..=40_000 {
            let x = f64::from(i) * 7.3e-4;
            for a in [x, x * 1.000_000_1, std::f64::consts::PI * f64::from(i % 9)] {
                let (ours, theirs) = (wrap_angle(a), strata_robot::normalize_angle(a));
                assert_eq!(ours.to_bits(), theirs.to_bits(), "{a}");
            }
        }
    }

    #[test]
    fn half_turn_wraps_lines() {
        assert!((wrap_half_turn(std::f64::consts::PI) - 0.0).abs() < 1e-12);
        assert!((wrap_half_turn(2.0) - (2.0 - std::f64::consts::PI)).abs() < 1e-12);
        assert!((wrap_half_turn(-1.0) + 1.0).abs() < 1e-12);
    }
}
