//! Seeded random streams: ChaCha8 from `rand_chacha`, one stream per model and robot, all from
//! the configuration's one seed.
//!
//! Random draws are most of what the simulator computes (twelve noisy IMU channels per robot at
//! 83 Hz), so a stream hands out 32-bit halves of each ChaCha word: uniforms take one half, and
//! normal samples come from a 256-layer ziggurat (Marsaglia and Tsang's, the layout `rand_distr`
//! uses) that needs only one half — half the generator's work of `rand_distr::StandardNormal`,
//! which spends a whole 64-bit word per sample. The ziggurat's tables and its rare exponentials
//! are computed with pure arithmetic, not the C library, so samples are the same bit for bit on
//! every machine (the rare wedge test uses the library's exponential; see `normal_edge`).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use strata_runtime::stable_hash;

/// A seeded random stream.
#[derive(Clone)]
pub(crate) struct Stream {
    rng: ChaCha8Rng,
    /// The last ChaCha word; its upper half is unused while `spare` is set.
    word: u64,
    spare: bool,
    tables: &'static Ziggurat,
}

impl std::fmt::Debug for Stream {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Stream").field("rng", &self.rng).finish_non_exhaustive()
    }
}

impl Stream {
    /// The stream `name` under `seed`. Every model draws from its own stream, so changing what
    /// one model draws (a camera setting, one robot) does not change the others' draws.
    pub fn new(seed: u64, name: &str) -> Stream {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(stable_hash(name));
        Stream { rng, word: 0, spare: false, tables: ziggurat() }
    }

    #[inline(always)]
    fn bits(&mut self) -> u32 {
        if self.spare {
            self.spare = false;
            (self.word >> 32) as u32
        } else {
            self.word = self.rng.next_u64();
            self.spare = true;
            self.word as u32
        }
    }

    /// Uniform in [0, 1), 32 bits of resolution.
    #[inline]
    pub fn unit(&mut self) -> f64 {
        f64::from(self.bits()) * (1.0 / 4_294_967_296.0)
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

    /// A standard normal sample from 32 random bits (more only in the rare edge cases).
    #[inline(always)]
    fn normal_from(&mut self, bits: u32) -> f64 {
        let layer = (bits & 0xff) as usize;
        // The upper 24 bits as a signed position in [-1, 1) across the layer.
        let u = f64::from(bits >> 8) * (1.0 / 8_388_608.0) - 1.0;
        let x = u * self.tables.x[layer];
        // About 98.5 % of samples fall inside their layer's rectangle.
        if x.abs() < self.tables.x[layer + 1] { x } else { self.normal_edge(layer, u, x) }
    }

    /// Normal samples with the given standard deviations, two per ChaCha word; no draw at all
    /// when every deviation is zero (a zero deviation in a noisy group gives exactly 0).
    #[inline(always)]
    pub fn gauss_n<const N: usize>(&mut self, sigmas: [f64; N]) -> [f64; N] {
        let mut out = [0.0; N];
        if sigmas.iter().all(|s| *s <= 0.0) {
            return out;
        }
        let mut i = 0;
        while i < N {
            let word = self.rng.next_u64();
            out[i] = self.normal_from(word as u32) * sigmas[i].max(0.0);
            if i + 1 < N {
                out[i + 1] = self.normal_from((word >> 32) as u32) * sigmas[i + 1].max(0.0);
            }
            i += 2;
        }
        out
    }

    /// The rare samples outside a layer's rectangle: the base layer's tail, or the wedge between
    /// a rectangle and the curve (accepted under the curve, otherwise a fresh sample).
    #[cold]
    #[inline(never)]
    fn normal_edge(&mut self, layer: usize, u: f64, x: f64) -> f64 {
        if layer == 0 {
            let tail = self.normal_tail();
            return if u < 0.0 { -tail } else { tail };
        }
        let t = self.tables;
        let y = t.f[layer + 1] + (t.f[layer] - t.f[layer + 1]) * self.unit();
        // The library's exponential: it can differ from another machine's only in the last
        // bit, which changes this comparison with a probability of about 1e-16.
        if y < (-0.5 * x * x).exp() { x } else { self.normal() }
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
        Ziggurat { x, f }
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
        let pairs: Vec<f64> = (0..n / 2).flat_map(|_| s.gauss_n([2.0, 2.0])).collect();
        let var = pairs.iter().map(|x| x * x).sum::<f64>() / pairs.len() as f64;
        assert!((var - 4.0).abs() < 0.03, "paired samples: variance {var}");
        assert_eq!(s.gauss_n([0.0; 3]), [0.0; 3]);
        let units: Vec<f64> = (0..n).map(|_| s.unit()).collect();
        assert!(units.iter().all(|u| (0.0..1.0).contains(u)));
        let mean = units.iter().sum::<f64>() / f64::from(n);
        assert!((mean - 0.5).abs() < 0.002, "uniform mean {mean}");
    }
}
