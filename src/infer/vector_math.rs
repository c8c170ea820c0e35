//! Hidden-layer activations over whole slices, vectorised.
//!
//! The standard library's `exp` is a scalar libm call: with ~2,500 activations
//! per transition it would cost more than the matrix work. Here e^x is
//! computed in f64 by a short polynomial and rounded once (so it agrees with a
//! correctly rounded `expf`), branch-free so the compiler vectorises it, and
//! every activation is compiled three times: AVX-512, AVX2 + FMA, and the
//! portable baseline, picked at run time. The polynomial uses `mul_add`: one
//! instruction where FMA exists, a (slow, exact) libm call on the rare x86-64
//! CPU without it.

use super::simd::{SimdLevel, simd_level};
use crate::nn::Activation;

/// Adds `bias` to every row of `values` (rows as wide as `bias`), then
/// applies `activation` (if any), in place: one pass over a layer's output.
pub fn bias_then_activate(values: &mut [f32], bias: &[f32], activation: Option<Activation>) {
    match activation {
        Some(Activation::Swish) => widest(BiasMap(values, bias, swish)),
        Some(Activation::Tanh) => widest(BiasMap(values, bias, tanh)),
        Some(Activation::Relu) => widest(BiasMap(values, bias, |v: f32| v.max(0.0))),
        None => widest(BiasMap(values, bias, |v: f32| v)),
    }
}

/// A loop to compile for several instruction sets. `run` must be
/// `#[inline(always)]`: it is then inlined into each variant of [`widest`] and
/// vectorised there (a closure would not be: its body stays baseline code).
pub(crate) trait Vectorized {
    fn run(self);
}

/// `v ← f(v + b)` for every element `v` of each row and `b` of the bias.
struct BiasMap<'a, F>(&'a mut [f32], &'a [f32], F);

impl<F: Fn(f32) -> f32> Vectorized for BiasMap<'_, F> {
    #[inline(always)]
    fn run(self) {
        let BiasMap(values, bias, f) = self;
        for row in values.chunks_exact_mut(bias.len()) {
            for (v, b) in row.iter_mut().zip(bias) {
                *v = f(*v + b);
            }
        }
    }
}

/// `v ← activation(v)` for every element, in place.
pub fn activate(values: &mut [f32], activation: Activation) {
    struct Map<'a, F>(&'a mut [f32], F);
    impl<F: Fn(f32) -> f32> Vectorized for Map<'_, F> {
        #[inline(always)]
        fn run(self) {
            for v in self.0.iter_mut() {
                *v = (self.1)(*v);
            }
        }
    }
    match activation {
        Activation::Swish => widest(Map(values, swish)),
        Activation::Tanh => widest(Map(values, tanh)),
        Activation::Relu => widest(Map(values, |v: f32| v.max(0.0))),
    }
}

/// `g ← g ⊙ act'(z)` in place: a gradient through a hidden layer whose
/// activations are `outputs`. ReLU's and tanh's derivatives follow from the
/// outputs (relu' = [a > 0], tanh' = 1 − a²); swish's needs the layer's
/// pre-activations `pre` (swish'(z) = s(z)·(1 + z·(1 − s(z))), s the sigmoid).
pub fn activation_gradient(
    activation: Activation,
    grad: &mut [f32],
    outputs: &[f32],
    pre: Option<&[f32]>,
) {
    struct Scale<'a, F>(&'a mut [f32], &'a [f32], F);
    impl<F: Fn(f32) -> f32> Vectorized for Scale<'_, F> {
        #[inline(always)]
        fn run(self) {
            for (g, &x) in self.0.iter_mut().zip(self.1) {
                *g *= (self.2)(x);
            }
        }
    }
    assert_eq!(grad.len(), outputs.len(), "activation_gradient: sizes");
    match activation {
        // A select, not a branch, so that it vectorises; and 0 (not 0·g) where
        // the unit is off, so that an infinite g stays out.
        Activation::Relu => {
            struct Mask<'a>(&'a mut [f32], &'a [f32]);
            impl Vectorized for Mask<'_> {
                #[inline(always)]
                fn run(self) {
                    for (g, &a) in self.0.iter_mut().zip(self.1) {
                        *g = if a > 0.0 { *g } else { 0.0 };
                    }
                }
            }
            widest(Mask(grad, outputs))
        }
        Activation::Tanh => widest(Scale(grad, outputs, |a: f32| 1.0 - a * a)),
        Activation::Swish => {
            let pre = pre.expect("swish's gradient needs the pre-activations");
            assert_eq!(pre.len(), grad.len(), "activation_gradient: sizes");
            widest(Scale(grad, pre, swish_derivative))
        }
    }
}

/// swish'(z) = s(z)·(1 + z·(1 − s(z))), s(z) = 1/(1 + e^(−z)).
#[inline(always)]
pub fn swish_derivative(z: f32) -> f32 {
    let e = exp(-f64::from(z.abs())) as f32;
    let (s, one_minus_s) = if z >= 0.0 {
        (1.0 / (1.0 + e), e / (1.0 + e))
    } else {
        (e / (1.0 + e), 1.0 / (1.0 + e))
    };
    s * (1.0 + z * one_minus_s)
}

/// φ'(z) into `slope` and φ''(z) into `curvature` for a hidden layer whose
/// activations are `outputs` (and pre-activations `pre`, which swish needs):
/// relu' = [a > 0], relu'' = 0; tanh' = 1 − a², tanh'' = −2a(1 − a²);
/// swish'' = s(1 − s)(2 + z(1 − 2s)). For losses on an input gradient (η's, eq. 3, 4).
pub fn activation_slopes(
    activation: Activation,
    outputs: &[f32],
    pre: Option<&[f32]>,
    slope: &mut Vec<f32>,
    curvature: &mut Vec<f32>,
) {
    slope.resize(outputs.len(), 0.0);
    curvature.resize(outputs.len(), 0.0);
    let pairs = slope.iter_mut().zip(curvature.iter_mut());
    match activation {
        Activation::Relu => {
            for ((p, q), &a) in pairs.zip(outputs) {
                (*p, *q) = (if a > 0.0 { 1.0 } else { 0.0 }, 0.0);
            }
        }
        Activation::Tanh => {
            for ((p, q), &a) in pairs.zip(outputs) {
                let one_minus = 1.0 - a * a;
                (*p, *q) = (one_minus, -2.0 * a * one_minus);
            }
        }
        Activation::Swish => {
            let pre = pre.expect("swish's slopes need the pre-activations");
            assert_eq!(pre.len(), outputs.len(), "activation_slopes: sizes");
            for ((p, q), &z) in pairs.zip(pre) {
                let s = sigmoid(z);
                *p = s * (1.0 + z * (1.0 - s));
                *q = s * (1.0 - s) * (2.0 + z * (1.0 - 2.0 * s));
            }
        }
    }
}

/// s(z) = 1/(1 + e^(−z)), without overflow on either side.
#[inline(always)]
fn sigmoid(z: f32) -> f32 {
    let e = exp(-f64::from(z.abs())) as f32;
    if z >= 0.0 {
        1.0 / (1.0 + e)
    } else {
        e / (1.0 + e)
    }
}

/// `sums[j] = Σ_rows values[row, j]` (rows as wide as `sums`), overwriting `sums`.
pub fn column_sums(values: &[f32], sums: &mut [f32]) {
    struct Sums<'a>(&'a [f32], &'a mut [f32]);
    impl Vectorized for Sums<'_> {
        #[inline(always)]
        fn run(self) {
            self.1.fill(0.0);
            for row in self.0.chunks_exact(self.1.len()) {
                for (s, v) in self.1.iter_mut().zip(row) {
                    *s += v;
                }
            }
        }
    }
    widest(Sums(values, sums));
}

/// Runs `work` compiled for the widest vector instructions this CPU has
/// (capped: [`super::simd`]).
#[inline(always)]
pub(crate) fn widest(work: impl Vectorized) {
    #[cfg(target_arch = "x86_64")]
    match simd_level() {
        // SAFETY: simd_level() is at most what the CPU supports (AVX-512F and FMA).
        SimdLevel::Avx512 => return unsafe { avx512(work) },
        // SAFETY: as above, AVX2 and FMA.
        SimdLevel::Avx2 => return unsafe { avx2(work) },
        SimdLevel::Portable => {}
    }
    work.run();
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,fma")]
unsafe fn avx512(work: impl Vectorized) {
    work.run();
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn avx2(work: impl Vectorized) {
    work.run();
}

/// swish(z) = z·sigmoid(z), with burn's f32 steps on a correctly rounded
/// e^(−|z|): the same value as burn's `silu` in nearly every case, which
/// matters because model rollouts amplify per-step differences ~20-fold over
/// ten steps.
#[inline(always)]
pub fn swish(z: f32) -> f32 {
    let e = exp(-f64::from(z.abs())) as f32;
    let sigmoid = if z >= 0.0 {
        1.0 / (1.0 + e)
    } else {
        e / (1.0 + e)
    };
    z * sigmoid
}

/// tanh(z) = sign(z)·(1 − 2/(e^(2|z|) + 1)), in f64 (no cancellation that
/// matters at f32 precision) and rounded once.
#[inline(always)]
pub fn tanh(z: f32) -> f32 {
    let a = f64::from(z.abs());
    let t = 1.0 - 2.0 / (exp(2.0 * a) + 1.0);
    (t as f32).copysign(z)
}

/// e^x in f64 for f32-range arguments: 2^n·e^r with n = round(x·log₂e),
/// |r| ≤ ln2/2, e^r by its degree-8 Taylor polynomial (relative error < 1e-9,
/// far below f32's half ulp); x is clamped so that 2^n stays a normal float.
#[inline(always)]
pub fn exp(x: f64) -> f64 {
    // Adding 1.5·2⁵² rounds to an integer, which then sits in the low mantissa bits.
    const SHIFTER: f64 = 6_755_399_441_055_744.0;
    let x = x.clamp(-200.0, 200.0);
    let shifted = x.mul_add(std::f64::consts::LOG2_E, SHIFTER);
    let n = shifted - SHIFTER;
    let r = (-n).mul_add(std::f64::consts::LN_2, x);
    let mut p: f64 = 1.0 / 40_320.0;
    for k in (1..=7).rev() {
        p = p.mul_add(r, 1.0 / FACTORIALS[k]);
    }
    let e_r = p.mul_add(r, 1.0);
    // The low bits of `shifted` hold n; (n + 1023) << 52 is 2^n's bit pattern.
    e_r * f64::from_bits(shifted.to_bits().wrapping_add(1023) << 52)
}

/// k! for k = 0..=7.
const FACTORIALS: [f64; 8] = [1.0, 1.0, 2.0, 6.0, 24.0, 120.0, 720.0, 5040.0];

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> impl Iterator<Item = f32> {
        (-40_000..=40_000).map(|i| i as f32 * 2.5e-3)
    }

    #[test]
    fn exp_is_far_more_accurate_than_f32() {
        for x in grid().map(f64::from).chain([-180.0, 150.0]) {
            let want = x.exp();
            let rel = ((exp(x) - want) / want).abs();
            assert!(rel < 1e-9, "exp({x}): relative error {rel}");
        }
    }

    #[test]
    fn tanh_and_swish_match_f64() {
        for x in grid().chain([1e-6, -3e-4]) {
            let want = f64::from(x).tanh();
            let got = f64::from(tanh(x));
            assert!(
                (got - want).abs() <= 3e-7 * want.abs().max(1e-30) + 1e-12,
                "tanh({x}) = {got}, want {want}"
            );
            let want = f64::from(x) / (1.0 + (-f64::from(x)).exp());
            let got = f64::from(swish(x));
            assert!(
                (got - want).abs() <= 3e-7 * want.abs() + 1e-30,
                "swish({x}) = {got}, want {want}"
            );
        }
    }

    #[test]
    fn dispatched_slices_equal_the_scalar_functions() {
        let values: Vec<f32> = grid().step_by(97).take(330).collect();
        let bias: Vec<f32> = (0..33).map(|i| i as f32 * 0.25 - 4.0).collect();
        let biased = |x: &f32, i: usize| x + bias[i % bias.len()];
        for (activation, f) in [
            (Activation::Swish, swish as fn(f32) -> f32),
            (Activation::Tanh, tanh),
        ] {
            let mut out = values.clone();
            bias_then_activate(&mut out, &bias, Some(activation));
            for (i, (x, y)) in values.iter().zip(&out).enumerate() {
                let want = f(biased(x, i));
                assert!((want - y).abs() <= 1e-7 * y.abs().max(1e-30), "{x}");
            }
        }
        let mut plain = values.clone();
        bias_then_activate(&mut plain, &bias, None);
        for (i, (x, y)) in values.iter().zip(&plain).enumerate() {
            assert_eq!(*y, biased(x, i));
        }
        let mut relu = vec![-1.0, 0.5];
        bias_then_activate(&mut relu, &[0.25], Some(Activation::Relu));
        assert_eq!(relu, [0.0, 0.75]);
    }

    #[test]
    fn activation_gradients_and_column_sums_by_hand() {
        let mut grad = vec![1.0, -2.0, 3.0, 4.0, 5.0];
        let outputs = [0.5, 0.0, -1.0, 2.0, f32::MIN_POSITIVE];
        activation_gradient(Activation::Relu, &mut grad, &outputs, None);
        assert_eq!(grad, [1.0, 0.0, 0.0, 4.0, 5.0]);
        let mut grad = vec![2.0, 2.0];
        activation_gradient(Activation::Tanh, &mut grad, &[0.5, -0.25], None);
        assert_eq!(grad, [1.5, 1.875]);
        // swish'(z) against a central difference of swish in f64.
        let z: Vec<f32> = grid().step_by(53).collect();
        let mut grad = vec![1.0; z.len()];
        activation_gradient(Activation::Swish, &mut grad, &z, Some(&z));
        let swish64 = |x: f64| x / (1.0 + (-x).exp());
        for (x, g) in z.iter().zip(&grad) {
            let (x, h) = (f64::from(*x), 1e-5);
            let want = (swish64(x + h) - swish64(x - h)) / (2.0 * h);
            assert!(
                (f64::from(*g) - want).abs() < 1e-6,
                "swish'({x}) = {g}, want {want}"
            );
        }
        let mut values = vec![-2.0, 0.0, 3.0];
        activate(&mut values, Activation::Swish);
        assert_eq!(values, [swish(-2.0), 0.0, swish(3.0)]);
        let mut sums = vec![9.0; 3];
        column_sums(&[1.0, 2.0, 3.0, 10.0, 20.0, 30.0], &mut sums);
        assert_eq!(sums, [11.0, 22.0, 33.0]);
    }
}
