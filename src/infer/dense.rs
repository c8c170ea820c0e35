//! Dense layers and MLPs evaluated on a tile of rows in plain `f32` buffers:
//! each layer writes `x·W` to its output, then adds the bias and applies the
//! activation in one pass while the tile is still in cache.
//!
//! Matrix kernel, chosen by measurement (BENCHMARKS.md, "Fused CPU inference"):
//! the `gemm` crate's AVX-512 kernels from [`GEMM_MIN_ROWS`] rows up, a
//! row-times-matrix loop below that, where packing would cost more than it saves.

use super::simd::{SimdLevel, detected_simd_level, simd_level};
use super::vector_math::{Vectorized, bias_then_activate, widest};
use crate::nn::{Activation, Mlp, to_f32_vec};

/// From this many rows a layer goes through `gemm`; fewer use the row loop.
pub const GEMM_MIN_ROWS: usize = 8;
/// f32 lanes of an AVX-512 vector: W's rows are padded to a multiple of this.
const LANES: usize = 16;

/// Rows of a row-major matrix, possibly a column window of a wider one.
#[derive(Debug, Clone, Copy)]
pub struct Rows<'a> {
    /// Starts at the first element of the first row.
    pub data: &'a [f32],
    pub rows: usize,
    pub width: usize,
    /// Distance between the starts of consecutive rows (≥ `width`).
    pub stride: usize,
}

impl<'a> Rows<'a> {
    /// A dense `[rows, width]` matrix.
    pub fn dense(data: &'a [f32], width: usize) -> Self {
        Self {
            data,
            rows: data.len() / width,
            width,
            stride: width,
        }
    }

    /// Columns `start..start + width` of a dense matrix `width_all` wide.
    pub fn columns(data: &'a [f32], width_all: usize, start: usize, width: usize) -> Self {
        Self {
            data: &data[start..],
            rows: data.len() / width_all,
            width,
            stride: width_all,
        }
    }

    #[inline(always)]
    fn row(&self, r: usize) -> &'a [f32] {
        &self.data[r * self.stride..r * self.stride + self.width]
    }
}

/// `y = x·W + b`, with `W` row-major `[d_in, d_out]` (burn's `Linear` layout),
/// each row padded with zeros to a whole number of [`LANES`].
#[derive(Debug, Clone, PartialEq)]
pub struct Dense {
    d_in: usize,
    d_out: usize,
    /// Distance between W's rows: `d_out` rounded up to [`LANES`].
    stride: usize,
    weight: Vec<f32>,
    bias: Vec<f32>,
}

impl Dense {
    /// A layer from `weight` (row-major `[d_in, d_out]`) and `bias` (`[d_out]`).
    pub fn new(d_in: usize, d_out: usize, weight: &[f32], bias: Vec<f32>) -> Self {
        assert_eq!(weight.len(), d_in * d_out, "weight size");
        assert_eq!(bias.len(), d_out, "bias size");
        let stride = d_out.next_multiple_of(LANES);
        let mut padded = vec![0.0; d_in * stride];
        for (row, w) in padded
            .chunks_exact_mut(stride)
            .zip(weight.chunks_exact(d_out))
        {
            row[..d_out].copy_from_slice(w);
        }
        Self {
            d_in,
            d_out,
            stride,
            weight: padded,
            bias,
        }
    }

    pub fn d_in(&self) -> usize {
        self.d_in
    }

    pub fn d_out(&self) -> usize {
        self.d_out
    }

    /// `out[r] = activation(x[r]·W + b)` for every row of `input`; `out` is
    /// `[rows, d_out]`. The bias joins the activation's pass over the output
    /// (one pass fewer through memory than prefilling it).
    pub fn forward(&self, input: Rows, out: &mut [f32], activation: Option<Activation>) {
        assert_eq!(input.width, self.d_in, "layer input width");
        let rows = input.rows;
        assert_eq!(out.len(), rows * self.d_out, "layer output size");
        assert!(rows == 0 || input.data.len() >= (rows - 1) * input.stride + input.width);
        if rows >= GEMM_MIN_ROWS {
            product(
                (rows, self.d_out, self.d_in),
                out,
                (input.data, input.stride as isize, 1),
                (&self.weight, self.stride as isize, 1),
            );
        } else {
            out.fill(0.0);
            accumulate_rows(self, input, out);
        }
        bias_then_activate(out, &self.bias, activation);
    }
}

/// `dst = lhs·rhs` for `(m, n, k)`: dst row-major `[m, n]`, overwritten;
/// `lhs` `[m, k]` and `rhs` `[k, n]` given as (values, row stride, column stride).
pub(super) fn product(
    dims: (usize, usize, usize),
    dst: &mut [f32],
    lhs: (&[f32], isize, isize),
    rhs: (&[f32], isize, isize),
) {
    product_into(dims, dst, lhs, rhs, false)
}

/// [`product`], adding `lhs·rhs` to `dst` when `accumulate` (a sum of two
/// products, as a weight's gradient through a tangent pass is).
fn product_into(
    (m, n, k): (usize, usize, usize),
    dst: &mut [f32],
    lhs: (&[f32], isize, isize),
    rhs: (&[f32], isize, isize),
    accumulate: bool,
) {
    assert_eq!(dst.len(), m * n, "product: destination size");
    let last = |(values, rs, cs): (&[f32], isize, isize), r: usize, c: usize| {
        let last = (r - 1) * rs as usize + (c - 1) * cs as usize;
        assert!(last < values.len(), "product: operand too short");
    };
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        if !accumulate {
            dst.fill(0.0);
        }
        return;
    }
    last(lhs, m, k);
    last(rhs, k, n);
    // SAFETY: the asserts above keep every index gemm reads inside `lhs` and
    // `rhs` and every index it writes inside `dst`; `dst` is borrowed mutably,
    // so it overlaps neither.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            n as isize,
            accumulate,
            lhs.0.as_ptr(),
            lhs.2,
            lhs.1,
            rhs.0.as_ptr(),
            rhs.2,
            rhs.1,
            1.0,
            1.0,
            false,
            false,
            false,
            gemm::Parallelism::None,
        );
    }
}

/// [`product`] with `dst`'s rows split over `cores` cores (rayon), each part
/// at least [`SPLIT_MIN_ROWS`] rows so that it pays for its own packing of `rhs`.
pub(super) fn product_on_cores(
    cores: usize,
    dims: (usize, usize, usize),
    dst: &mut [f32],
    lhs: (&[f32], isize, isize),
    rhs: (&[f32], isize, isize),
) {
    product_on_cores_into(cores, dims, dst, lhs, rhs, false)
}

/// [`product_on_cores`], adding to `dst` when `accumulate`.
pub(super) fn product_on_cores_into(
    cores: usize,
    (m, n, k): (usize, usize, usize),
    dst: &mut [f32],
    lhs: (&[f32], isize, isize),
    rhs: (&[f32], isize, isize),
    accumulate: bool,
) {
    if cores < 2 || m < 2 * SPLIT_MIN_ROWS {
        return product_into((m, n, k), dst, lhs, rhs, accumulate);
    }
    // The top part gets its share of the cores, the bottom the rest.
    let top_cores = cores / 2;
    let top = m * top_cores / cores;
    let (dst_top, dst_bottom) = dst.split_at_mut(top * n);
    let lhs_bottom = (&lhs.0[top * lhs.1 as usize..], lhs.1, lhs.2);
    rayon::join(
        || product_on_cores_into(top_cores, (top, n, k), dst_top, lhs, rhs, accumulate),
        || {
            product_on_cores_into(
                cores - top_cores,
                (m - top, n, k),
                dst_bottom,
                lhs_bottom,
                rhs,
                accumulate,
            )
        },
    );
}

/// Fewest destination rows a part of [`product_on_cores`] gets (measured on
/// SAC's 256-row products: two parts of 128 pay, parts of 32 do not).
const SPLIT_MIN_ROWS: usize = 64;

/// A trained [`Mlp`]'s weights: the activation after every layer but the last.
#[derive(Debug, Clone, PartialEq)]
pub struct DenseMlp {
    pub layers: Vec<Dense>,
    pub activation: Activation,
}

/// Hidden activations of one tile, kept between calls so nothing is allocated per step.
#[derive(Debug, Default)]
pub struct MlpScratch {
    a: Vec<f32>,
    b: Vec<f32>,
}

impl DenseMlp {
    /// The same weights as `mlp` (copied to host memory as `f32`).
    pub fn from_burn(mlp: &Mlp) -> Self {
        let layers = mlp
            .layers
            .iter()
            .map(|layer| {
                let [d_in, d_out] = layer.weight.val().dims();
                let bias = match &layer.bias {
                    Some(bias) => to_f32_vec(bias.val()),
                    None => vec![0.0; d_out],
                };
                Dense::new(d_in, d_out, &to_f32_vec(layer.weight.val()), bias)
            })
            .collect();
        Self {
            layers,
            activation: mlp.activation,
        }
    }

    pub fn d_out(&self) -> usize {
        self.layers.last().map_or(0, |l| l.d_out)
    }

    /// Weights and biases, the memory one evaluation streams through.
    pub fn weight_count(&self) -> usize {
        self.layers
            .iter()
            .map(|l| l.weight.len() + l.bias.len())
            .sum()
    }

    /// The MLP on every row of `input`, into `out` (`[rows, d_out]`).
    pub fn forward(&self, input: Rows, out: &mut [f32], scratch: &mut MlpScratch) {
        let last = self.layers.len() - 1;
        let rows = input.rows;
        let (mut current, mut next) = (
            std::mem::take(&mut scratch.a),
            std::mem::take(&mut scratch.b),
        );
        for (i, layer) in self.layers.iter().enumerate() {
            let source = if i == 0 {
                input
            } else {
                Rows::dense(&current[..rows * layer.d_in], layer.d_in)
            };
            if i == last {
                layer.forward(source, out, None);
            } else {
                next.resize(rows * layer.d_out, 0.0);
                layer.forward(source, &mut next, Some(self.activation));
                std::mem::swap(&mut current, &mut next);
            }
        }
        (scratch.a, scratch.b) = (current, next);
    }
}

/// `out += input·W` for fewer than [`GEMM_MIN_ROWS`] rows: with AVX-512,
/// blocks of rows × columns held in registers; otherwise a plain loop.
fn accumulate_rows(layer: &Dense, input: Rows, out: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    if simd_level() == SimdLevel::Avx512 {
        // SAFETY: simd_level() is at most what the CPU supports: AVX-512F here.
        return unsafe { avx512::accumulate_rows(layer, input, out) };
    }
    // gemm sums each output as one chain of fused multiply-adds wherever the
    // CPU has FMA, whatever vector level the loop runs at: the loop sums the
    // same way, so a row's output does not depend on how many rows share the
    // call (a request batched with others answers as it does alone).
    let fused = detected_simd_level() >= SimdLevel::Avx2;
    widest(RowLoop {
        layer,
        input,
        out,
        fused,
    });
}

/// The portable row loop, vectorised along W's rows.
struct RowLoop<'a> {
    layer: &'a Dense,
    input: Rows<'a>,
    out: &'a mut [f32],
    /// Each step a fused multiply-add (one rounding), as gemm's where the CPU has FMA.
    fused: bool,
}

impl Vectorized for RowLoop<'_> {
    #[inline(always)]
    fn run(self) {
        let n = self.layer.d_out;
        for (r, y) in self.out.chunks_exact_mut(n).enumerate() {
            let weights = self.layer.weight.chunks_exact(self.layer.stride);
            for (&x, w) in self.input.row(r).iter().zip(weights) {
                if self.fused {
                    for (y, w) in y.iter_mut().zip(w) {
                        *y = x.mul_add(*w, *y);
                    }
                } else {
                    for (y, w) in y.iter_mut().zip(w) {
                        *y += x * w;
                    }
                }
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod avx512 {
    //! Register-blocked `out += input·W` for a few rows: each weight vector
    //! loaded from cache serves up to four rows, and up to 16 accumulator
    //! vectors stay in registers while W's rows stream past.

    use std::arch::x86_64::*;

    use super::{Dense, LANES, Rows};

    /// Accumulator registers a block may use (of AVX-512's 32).
    const ACCUMULATORS: usize = 16;

    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn accumulate_rows(layer: &Dense, input: Rows, mut out: &mut [f32]) {
        let row = |r| input.row(r);
        let mut r = 0;
        while r < input.rows {
            let block = match input.rows - r {
                4.. => 4,
                2 | 3 => 2,
                _ => 1,
            };
            let (y, rest) = out.split_at_mut(block * layer.d_out);
            match block {
                4 => rows_block(layer, [row(r), row(r + 1), row(r + 2), row(r + 3)], y),
                2 => rows_block(layer, [row(r), row(r + 1)], y),
                _ => rows_block(layer, [row(r)], y),
            }
            r += block;
            out = rest;
        }
    }

    /// `R` rows, in column blocks of `ACCUMULATORS / R` vectors, then ever
    /// smaller blocks for the vectors left.
    #[inline]
    #[target_feature(enable = "avx512f")]
    fn rows_block<const R: usize>(layer: &Dense, x: [&[f32]; R], y: &mut [f32]) {
        let vectors = layer.stride / LANES;
        let mut v = 0;
        while v < vectors {
            let left = vectors - v;
            let width = [16, 8, 4, 2, 1]
                .into_iter()
                .find(|&w| w * R <= ACCUMULATORS && w <= left)
                .unwrap_or(1);
            let j0 = v * LANES;
            match width {
                16 => columns_block::<R, 16>(layer, x, y, j0),
                8 => columns_block::<R, 8>(layer, x, y, j0),
                4 => columns_block::<R, 4>(layer, x, y, j0),
                2 => columns_block::<R, 2>(layer, x, y, j0),
                _ => columns_block::<R, 1>(layer, x, y, j0),
            }
            v += width;
        }
    }

    /// Columns `j0..j0 + 16·V` of `R` rows (padding columns masked off).
    #[inline]
    #[target_feature(enable = "avx512f")]
    fn columns_block<const R: usize, const V: usize>(
        layer: &Dense,
        x: [&[f32]; R],
        y: &mut [f32],
        j0: usize,
    ) {
        let n = layer.d_out;
        let masks: [__mmask16; V] = std::array::from_fn(|v| {
            let valid = n.saturating_sub(j0 + v * LANES).min(LANES);
            ((1u32 << valid) - 1) as __mmask16
        });
        let mut acc = [[_mm512_setzero_ps(); V]; R];
        for (r, acc) in acc.iter_mut().enumerate() {
            for (v, acc) in acc.iter_mut().enumerate() {
                let at = y.as_ptr().wrapping_add(r * n + j0 + v * LANES);
                // SAFETY: the mask covers only columns < n of row r of y.
                *acc = unsafe { _mm512_maskz_loadu_ps(masks[v], at) };
            }
        }
        for (i, w) in layer.weight.chunks_exact(layer.stride).enumerate() {
            let w = &w[j0..j0 + V * LANES];
            // SAFETY: `w` holds V·LANES floats (rows are padded to whole vectors).
            let w: [__m512; V] =
                std::array::from_fn(|v| unsafe { _mm512_loadu_ps(w.as_ptr().add(v * LANES)) });
            for (acc, x) in acc.iter_mut().zip(&x) {
                let xi = _mm512_set1_ps(x[i]);
                for (acc, w) in acc.iter_mut().zip(&w) {
                    *acc = _mm512_fmadd_ps(xi, *w, *acc);
                }
            }
        }
        for (r, acc) in acc.iter().enumerate() {
            for (v, acc) in acc.iter().enumerate() {
                let at = y.as_mut_ptr().wrapping_add(r * n + j0 + v * LANES);
                // SAFETY: as for the load.
                unsafe { _mm512_mask_storeu_ps(at, masks[v], *acc) };
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Row blocks on several cores give the naive triple loop's product, for
    /// uneven splits and a transposed operand (how backward passes read x).
    #[test]
    fn products_split_over_cores_equal_the_naive_product() {
        let (m, n, k) = (301, 7, 5);
        let lhs: Vec<f32> = (0..m * k).map(|i| (i % 13) as f32 - 6.0).collect();
        let rhs: Vec<f32> = (0..k * n).map(|i| (i % 5) as f32 * 0.5).collect();
        let mut want = vec![0.0; m * n];
        for r in 0..m {
            for c in 0..n {
                want[r * n + c] = (0..k).map(|i| lhs[r * k + i] * rhs[i * n + c]).sum();
            }
        }
        // lhsᵀ stored row-major [k, m], read back as lhs through its strides.
        let mut lhs_t = vec![0.0; m * k];
        for r in 0..m {
            for i in 0..k {
                lhs_t[i * m + r] = lhs[r * k + i];
            }
        }
        for cores in [1, 2, 3, 4] {
            let mut got = vec![f32::NAN; m * n];
            product_on_cores(
                cores,
                (m, n, k),
                &mut got,
                (&lhs, k as isize, 1),
                (&rhs, n as isize, 1),
            );
            assert_eq!(got, want, "{cores} cores");
            let mut got = vec![f32::NAN; m * n];
            product_on_cores(
                cores,
                (m, n, k),
                &mut got,
                (&lhs_t, 1, m as isize),
                (&rhs, n as isize, 1),
            );
            assert_eq!(got, want, "{cores} cores, transposed lhs");
        }
    }
}
