//! Seeded random streams: one wyrand generator per model and robot, each seeded from a ChaCha8
//! stream of the configuration's one seed and the stream's stable name.
//!
//! Random draws are most of what the simulator computes (twelve noisy IMU channels per robot at
//! 83 Hz), so the generator is wyrand (Wang Yi's, with the constants of wyhash's final version;
//! the generator of the `fastrand` crate, written out here): a 64-bit counter and one 64x64-bit
//! multiplication per 64-bit word, about six instructions and no buffer to refill, where
//! ChaCha8 spent about five times as much per word with its block refills. It passes BigCrush
//! and PractRand; its period, 2^64 words per stream, is far beyond any simulation. ChaCha8
//! only derives each stream's starting state from the seed and the name, so streams of
//! different names start at unrelated places. A stream hands out 32-bit halves of each word:
//! uniforms take one half, and normal samples come from a 256-layer ziggurat (Marsaglia and
//! Tsang's, the layout `rand_distr` uses) that needs only one half — half the generator's work
//! of `rand_distr::StandardNormal`, which spends a whole 64-bit word per sample. The ziggurat's
//! tables and its rare exponentials are computed with pure arithmetic, not the C library, so
//! samples are the same bit for bit on every machine (the rare wedge test uses the library's
//! exponential; see `normal_edge`).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use strata_runtime::stable_hash;

/// A seeded random stream.
#[derive(Clone)]
pub(crate) struct Stream {
    /// wyrand's counter.
    state: u64,
    /// The last word; its upper half is unused while `spare` is set.
    word: u64,
    spare: bool,
    tables: &'static Ziggurat,
}

impl std::fmt::Debug for Stream {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Stream").field("state", &self.state).finish_non_exhaustive()
    }
}

impl Stream {
    /// The stream `name` under `seed`. Every model draws from its own stream, so changing what
    /// one model draws (a camera setting, one robot) does not change the others' draws.
    pub fn new(seed: u64, name: &str) -> Stream {
        let mut chacha = ChaCha8Rng::seed_from_u64(seed);
        chacha.set_stream(stable_hash(name));
        Stream { state: chacha.next_u64(), word: 0, spare: false, tables: ziggurat() }
    }

    /// The next 64-bit word (wyrand).
    #[inline(always)]
    pub fn next_u64(&mut self) -> u64 {
        let s = self.state.wrapping_add(0x2d35_8dcc_aa6c_78a5);
        self.state = s;
        let t = u128::from(s) * u128::from(s ^ 0x8bb8_4b93_962e_acc9);
        (t as u64) ^ (t >> 64) as u64
    }

    #[inline(always)]
    fn bits(&mut self) -> u32 {
        if self.spare {
            self.spare = false;
            (self.word >> 32) as u32
        } else {
            self.word = self.next_u64();
            self.spare = true;
            self.word as u32
        }
    }

    /// Uniform in [0, 1), 32 bits of resolution.
    #[inline]
    pub fn unit(&mut self) -> f64 {
        Stream::unit_from(self.bits())
    }

    /// Uniform in [0, 1) from 32 random bits.
    #[inline(always)]
    pub fn unit_from(bits: u32) -> f64 {
        f64::from(bits) * (1.0 / 4_294_967_296.0)
    }

    /// Uniform in (0, 1], for logarithms.
    fn open_unit(&mut self) -> f64 {
        (f64::from(self.bits()) + 1.0) * (1.0 / 4_294_967_296.0)
    }

    /// A standard normal sample.
    #[inline(always)]
    pub fn normal(&mut self) -> f64 {
        let bits = self.bits();
        self.normal_from(bits)
    }

    /// A standard normal sample from 32 random bits (more from the stream only in the rare
    /// edge cases).
    #[inline(always)]
    pub fn normal_from(&mut self, bits: u32) -> f64 {
        let layer = (bits & 0xff) as usize;
        // The upper 24 bits as a signed position across the layer: i / 2^23 in [-1, 1).
        let i = (bits as i32) >> 8;
        let x = f64::from(i) * self.tables.scaled[layer];
        // About 98.5 % of samples fall inside their layer's rectangle.
        if x.abs() < self.tables.x[layer + 1] { x } else { self.normal_edge(layer, i < 0, x) }
    }

    /// Two normal samples with standard deviations `s0` and `s1`, from one word.
    #[inline(always)]
    pub fn gauss_pair(&mut self, s0: f64, s1: f64) -> [f64; 2] {
        let word = self.next_u64();
        let n0 = self.normal_from(word as u32);
        let n1 = self.normal_from((word >> 32) as u32);
        [n0 * s0, n1 * s1]
    }

    /// The rare samples outside a layer's rectangle: the base layer's tail, or the wedge between
    /// a rectangle and the curve (accepted under the curve, otherwise a fresh sample).
    #[cold]
    #[inline(never)]
    fn normal_edge(&mut self, layer: usize, negative: bool, x: f64) -> f64 {
        if layer == 0 {
            let tail = self.normal_tail();
            return if negative { -tail } else { tail };
        }
        let t = self.tables;
        let y = t.f[layer + 1] + (t.f[layer] - t.f[layer + 1]) * self.unit();
        // The library's exponential only where the squeeze cannot decide: it can differ from
        // another machine's only in the last bit, which changes the comparison with a
        // probability of about 1e-16.
        let under = t.wedge_decides(layer, x.abs(), y).unwrap_or_else(|| y < (-0.5 * x * x).exp());
        if under { x } else { self.normal() }
    }

    /// Beyond the base layer's edge `R` (Marsaglia's method).
    fn normal_tail(&mut self) -> f64 {
        loop {
            let x = -ln(self.open_unit()) / ZIGGURAT_R;
            let y = -ln(self.open_unit());
            if 2.0 * y > x * x {
                return ZIGGURAT_R + x;
            }
        }
    }

    /// A normal sample with standard deviation `sigma`; no draw at all when `sigma` is zero,
    /// so the zero-noise mode is exact.
    #[inline(always)]
    pub fn gauss(&mut self, sigma: f64) -> f64 {
        if sigma > 0.0 { self.normal() * sigma } else { 0.0 }
    }

    /// True with probability `p`; no draw when the outcome is certain.
    #[inline]
    pub fn chance(&mut self, p: f64) -> bool {
        if p <= 0.0 {
            false
        } else if p >= 1.0 {
            true
        } else {
            self.unit() < p
        }
    }

    /// Exponential with `rate` (mean 1 / rate); infinite, without a draw, for a rate of zero.
    pub fn exponential(&mut self, rate: f64) -> f64 {
        if rate > 0.0 { -ln(self.open_unit()) / rate } else { f64::INFINITY }
    }

    /// Uniform in [lo, hi).
    #[inline]
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        if hi > lo { lo + (hi - lo) * self.unit() } else { lo }
    }
}

/// The base layer's edge and the area of each of the 256 layers of the normal ziggurat.
const ZIGGURAT_R: f64 = 3.654_152_885_361_009;
const ZIGGURAT_V: f64 = 0.004_928_673_233_99;

/// Layer edges `x` (x[0]: the base layer's equivalent width, x[256] = 0) and the unnormalized
/// density exp(-x^2/2) at them.
struct Ziggurat {
    x: [f64; 257],
    f: [f64; 257],
    /// x / 2^23: a layer's edge per unit of a 24-bit signed position.
    scaled: [f64; 256],
    /// Slope of the chord from (x[i + 1], f[i + 1]) to (x[i], f[i]) of layer i.
    chord: [f64; 256],
}

impl Ziggurat {
    /// Decides a point (x, y) of layer `layer`'s wedge (x between x[layer + 1] and x[layer],
    /// y between their densities) without the exponential when a bound does: the density
    /// exp(-x^2/2) is convex beyond 1, where it lies under the chord of the layer and above
    /// its tangent at x[layer], and concave below 1, where it lies above the chord and under
    /// the tangent at x[layer + 1] (McFarland's squeeze). Some(true): under the curve.
    #[inline]
    fn wedge_decides(&self, layer: usize, x: f64, y: f64) -> Option<bool> {
        let (lo, hi) = (self.x[layer + 1], self.x[layer]);
        let chord = self.f[layer + 1] + self.chord[layer] * (x - lo);
        if lo >= 1.0 {
            if y >= chord {
                return Some(false);
            }
            // The tangent at hi: f(hi) (1 - hi (x - hi)).
            if y < self.f[layer] * (1.0 - hi * (x - hi)) {
                return Some(true);
            }
        } else if hi <= 1.0 {
            if y < chord {
                return Some(true);
            }
            if y >= self.f[layer + 1] * (1.0 - lo * (x - lo)) {
                return Some(false);
            }
        }
        None
    }
}

fn ziggurat() -> &'static Ziggurat {
    static TABLES: std::sync::OnceLock<Ziggurat> = std::sync::OnceLock::new();
    TABLES.get_or_init(|| {
        let density = |x: f64| exp(-0.5 * x * x);
        let mut x = [0.0; 257];
        x[0] = ZIGGURAT_V / density(ZIGGURAT_R);
        x[1] = ZIGGURAT_R;
        for i in 1..255 {
            x[i + 1] = (-2.0 * ln(ZIGGURAT_V / x[i] + density(x[i]))).sqrt();
        }
        x[256] = 0.0;
        let mut f = [0.0; 257];
        for (f, x) in f.iter_mut().zip(&x) {
            *f = density(*x);
        }
        let mut scaled = [0.0; 256];
        for (s, x) in scaled.iter_mut().zip(&x) {
            *s = x * (1.0 / 8_388_608.0);
        }
        let mut chord = [0.0; 256];
        for (i, c) in chord.iter_mut().enumerate() {
            let width = x[i] - x[i + 1];
            *c = if width > 0.0 { (f[i] - f[i + 1]) / width } else { 0.0 };
        }
        Ziggurat { x, f, scaled, chord }
    })
}

/// 1/n! for n = 16 down to 0 (Horner order).
const EXP_TERMS: [f64; 17] = [
    1.0 / 20_922_789_888_000.0,
    1.0 / 1_307_674_368_000.0,
    1.0 / 87_178_291_200.0,
    1.0 / 6_227_020_800.0,
    1.0 / 479_001_600.0,
    1.0 / 39_916_800.0,
    1.0 / 3_628_800.0,
    1.0 / 362_880.0,
    1.0 / 40_320.0,
    1.0 / 5_040.0,
    1.0 / 720.0,
    1.0 / 120.0,
    1.0 / 24.0,
    1.0 / 6.0,
    1.0 / 2.0,
    1.0,
    1.0,
];

const LN2_HI: f64 = 6.931_471_803_691_238e-1;
const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;

/// e^x by pure arithmetic (reduction by powers of two, Taylor series), to about 1e-16
/// relative, for -700 < x < 700; deterministic on every machine, unlike the C library's.
pub(crate) fn exp(x: f64) -> f64 {
    if x.is_nan() {
        return x;
    }
    if x > 709.0 {
        return f64::INFINITY;
    }
    if x < -708.0 {
        return 0.0;
    }
    let k = (x * std::f64::consts::LOG2_E + 0.5f64.copysign(x)) as i64;
    let r = (x - k as f64 * LN2_HI) - k as f64 * LN2_LO;
    // |r| <= ln2 / 2: terms up to r^16/16! leave a remainder below 1e-19.
    let mut sum = 0.0;
    for c in EXP_TERMS {
        sum = sum * r + c;
    }
    sum * f64::from_bits(((k + 1023) as u64) << 52)
}

/// The natural logarithm of a positive finite number, by pure arithmetic (the mantissa's
/// atanh series), to about 1e-16.
pub(crate) fn ln(x: f64) -> f64 {
    if !(x > 0.0 && x.is_finite()) {
        return if x == 0.0 { f64::NEG_INFINITY } else { f64::NAN };
    }
    // x = m * 2^e with m in [sqrt(1/2), sqrt(2)); subnormals are first scaled up.
    let (x, shift) = if x < f64::MIN_POSITIVE { (x * 2f64.powi(60), -60) } else { (x, 0) };
    let bits = x.to_bits();
    let mut e = ((bits >> 52) & 0x7ff) as i64 - 1023 + shift;
    let mut m = f64::from_bits((bits & 0x000f_ffff_ffff_ffff) | 0x3ff0_0000_0000_0000);
    if m > std::f64::consts::SQRT_2 {
        m *= 0.5;
        e += 1;
    }
    let s = (m - 1.0) / (m + 1.0);
    let z = s * s;
    // |s| < 0.172: terms up to s^31 leave a remainder below 1e-20.
    let mut sum = 0.0;
    for k in (0..16).rev() {
        sum = sum * z + 1.0 / f64::from(2 * k + 1);
    }
    2.0 * s * sum + e as f64 * LN2_HI + e as f64 * LN2_LO
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_generator_is_wyrand() {
        // wyrand's (and `fastrand`'s) first outputs from the state 1.
        let mut s = Stream::new(0, "x");
        s.state = 1;
        let words: Vec<u64> = (0..4).map(|_| s.next_u64()).collect();
        assert_eq!(
            words,
            [
                12_120_239_713_417_281_201,
                9_861_924_296_701_902_397,
                4_420_488_659_902_023_302,
                14_367_571_835_928_699_312
            ]
        );
        // Streams of one seed and name repeat; other names differ.
        let (mut a, mut b) = (Stream::new(9, "n"), Stream::new(9, "n"));
        for _ in 0..1000 {
            assert_eq!(a.gauss_pair(1.0, 0.5), b.gauss_pair(1.0, 0.5));
        }
        assert_eq!(a.next_u64(), b.next_u64());
        assert_ne!(Stream::new(9, "n").next_u64(), Stream::new(9, "m").next_u64());
    }

    #[test]
    fn the_wedge_squeeze_agrees_with_the_density() {
        let t = ziggurat();
        let mut s = Stream::new(1, "squeeze");
        let (mut decided, n) = (0, 400_000);
        for _ in 0..n {
            let layer = 1 + (s.unit() * 255.0) as usize;
            let (lo, hi) = (t.x[layer + 1], t.x[layer]);
            let x = lo + (hi - lo) * s.unit();
            let y = t.f[layer + 1] + (t.f[layer] - t.f[layer + 1]) * s.unit();
            let density = (-0.5 * x * x).exp();
            if let Some(under) = t.wedge_decides(layer, x, y) {
                decided += 1;
                assert!(under == (y < density) || (y - density).abs() < 1e-15, "{layer} {x} {y}");
            }
        }
        assert!(decided > n * 9 / 10, "the squeeze decides most wedge points: {decided}");
    }

    #[test]
    fn zero_sigma_and_certain_events_draw_nothing() {
        let mut a = Stream::new(3, "x");
        let mut b = Stream::new(3, "x");
        assert_eq!(a.gauss(0.0), 0.0);
        assert!(!a.chance(0.0));
        assert!(a.chance(1.0));
        assert_eq!(a.unit(), b.unit());
        assert_ne!(Stream::new(3, "x").unit(), Stream::new(3, "y").unit());
    }

    #[test]
    fn pure_exp_and_ln_match_the_library() {
        for i in -7000..=7000 {
            let x = f64::from(i) * 0.01;
            let (ours, libm) = (exp(x), x.exp());
            assert!((ours - libm).abs() <= 1e-15 * libm, "exp({x}): {ours} vs {libm}");
        }
        for i in 1..=20000 {
            let x = f64::from(i) * 0.0137;
            let (ours, libm) = (ln(x), x.ln());
            assert!(
                (ours - libm).abs() <= 4e-16 * libm.abs().max(1.0),
                "ln({x}): {ours} vs {libm}"
            );
        }
        assert!((ln(1e-310) - 1e-310f64.ln()).abs() < 1e-12);
    }

    #[test]
    fn streams_draw_standard_normal_and_uniform_samples() {
        let mut s = Stream::new(7, "normal");
        let n = 1_000_000;
        let samples: Vec<f64> = (0..n).map(|_| s.normal()).collect();
        let mean = samples.iter().sum::<f64>() / f64::from(n);
        let var = samples.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / f64::from(n);
        let kurtosis =
            samples.iter().map(|x| (x - mean).powi(4)).sum::<f64>() / f64::from(n) / (var * var);
        assert!(mean.abs() < 0.005, "mean {mean}");
        assert!((var - 1.0).abs() < 0.005, "variance {var}");
        assert!((kurtosis - 3.0).abs() < 0.03, "kurtosis {kurtosis}");
        // Tail frequencies of a standard normal, including beyond the base layer (R = 3.65).
        for (limit, expected) in [
            (0.5, 0.617_075),
            (1.0, 0.317_311),
            (2.0, 0.045_500),
            (3.0, 0.002_700),
            (3.8, 1.447e-4),
        ] {
            let p = samples.iter().filter(|x| x.abs() > limit).count() as f64 / f64::from(n);
            let tolerance = 5.0 * (expected * (1.0 - expected) / f64::from(n)).sqrt();
            assert!(
                (p - expected).abs() < tolerance,
                "P(|x| > {limit}) = {p}, expected {expected}"
            );
        }
        let positive = samples.iter().filter(|x| **x > 0.0).count() as f64 / f64::from(n);
        assert!((positive - 0.5).abs() < 0.002, "symmetric: {positive}");
        let pairs: Vec<f64> = (0..n / 2).flat_map(|_| s.gauss_pair(2.0, 2.0)).collect();
        let var = pairs.iter().map(|x| x * x).sum::<f64>() / pairs.len() as f64;
        assert!((var - 4.0).abs() < 0.03, "paired samples: variance {var}");
        assert_eq!(s.gauss_pair(0.0, 0.0), [0.0; 2]);
        let units: Vec<f64> = (0..n).map(|_| s.unit()).collect();
        assert!(units.iter().all(|u| (0.0..1.0).contains(u)));
        let mean = units.iter().sum::<f64>() / f64::from(n);
        assert!((mean - 0.5).abs() < 0.002, "uniform mean {mean}");
    }
}
