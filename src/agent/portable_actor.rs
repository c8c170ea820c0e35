//! The tanh-Gaussian actor that generates datasets, in portable arithmetic:
//! each layer output is its bias plus the inputs' products added in input
//! order, in f32, with no matrix library and no explicit SIMD. Vectorising
//! such a loop runs over outputs and keeps each output's operations, so the
//! same weights, observations and generator give the same bits on every
//! x86-64 CPU. The fused path (`FusedActor`) is faster but not portable:
//! gemm's kernels and nuno's vector levels add in other orders on AVX2 and
//! AVX-512 machines, and a dataset generated on one kind then differs from
//! the same recipe's on the other.
//!
//! Two actors use it: D4RL's "random" policy, a randomly initialised actor
//! (rlkit's `TanhGaussianPolicy`: hidden layers fan-in uniform with bias 0.1,
//! output layers uniform in ±1e-3, so the mean is near 0 and the std near 1
//! and actions are close to `tanh(N(0, 1))` per dimension), and a trained
//! behaviour policy, sampled as [`ActorPolicy`] samples it.

use rand::{Rng, RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use super::actor::{action_noise, tanh_gaussian_log_density};
use super::{ActionMode, ActorPolicy};
use crate::nn::to_f32_vec;
use crate::shared::{BatchPolicy, LoggedActions, act_batch};

/// rlkit's output-layer init range (`init_w`).
const OUTPUT_INIT: f32 = 1e-3;
/// rlkit's hidden-layer bias (`b_init_value`).
const HIDDEN_BIAS: f32 = 0.1;
/// Log-std clamp of rlkit's actor.
const RLKIT_LOG_STD_RANGE: (f32, f32) = (-20.0, 2.0);

/// One dense layer, `y = W x + b`, with `W` stored input-major (`[in, out]`)
/// so the forward pass is a run of `y += x_j · W_j` updates over outputs.
#[derive(Debug, Clone)]
struct Dense {
    weight: Vec<f32>,
    bias: Vec<f32>,
}

impl Dense {
    /// rlkit's initialisation: weights uniform in ±`w_range`, the bias
    /// `bias` or, without one, drawn like the weights.
    fn rlkit(
        inputs: usize,
        outputs: usize,
        w_range: f32,
        bias: Option<f32>,
        rng: &mut ChaCha8Rng,
    ) -> Self {
        let mut draw = |_| rng.random_range(-w_range..w_range);
        let weight = (0..inputs * outputs).map(&mut draw).collect();
        let bias = match bias {
            Some(b) => vec![b; outputs],
            None => (0..outputs).map(&mut draw).collect(),
        };
        Self { weight, bias }
    }

    /// The outputs side by side: `[self | other]` on the same inputs.
    fn beside(&self, other: &Dense) -> Dense {
        let (a, b) = (self.bias.len(), other.bias.len());
        let weight = self
            .weight
            .chunks_exact(a)
            .zip(other.weight.chunks_exact(b))
            .flat_map(|(x, y)| x.iter().chain(y).copied())
            .collect();
        let bias = self.bias.iter().chain(&other.bias).copied().collect();
        Dense { weight, bias }
    }

    fn forward(&self, x: &[f32], relu: bool) -> Vec<f32> {
        let mut y = self.bias.clone();
        for (xj, w) in x.iter().zip(self.weight.chunks_exact(y.len())) {
            for (yi, wi) in y.iter_mut().zip(w) {
                *yi += xj * wi;
            }
        }
        if relu {
            y.iter_mut().for_each(|v| *v = v.max(0.0));
        }
        y
    }
}

/// Where a sampled action's ε comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum NoiseStream {
    /// Drawn from the caller's generator entry by entry (the random policy,
    /// as every random dataset here has been generated).
    PerEntry,
    /// One seed from the caller's generator, then `action_noise`'s stream:
    /// the ε every kernel of a trained actor draws.
    Seeded,
}

/// A tanh-Gaussian MLP actor (ReLU hidden layers, an output of μ then log σ)
/// evaluated in portable arithmetic; a = centre + half·tanh(u).
#[derive(Debug, Clone)]
pub struct PortableActor {
    hidden: Vec<Dense>,
    /// `[μ | log σ]`, 2·act_dim wide.
    output: Dense,
    obs_dim: usize,
    act_dim: usize,
    log_std_range: (f32, f32),
    half: Vec<f32>,
    center: Vec<f32>,
    /// Σ log half, the action box's term of log π(a|s).
    log_half_sum: f32,
    mode: ActionMode,
    noise: NoiseStream,
}

impl PortableActor {
    /// D4RL's random policy: rlkit's actor (hidden sizes `hidden`, 2×256 in
    /// D4RL) with weights drawn from `seed`, actions sampled in [−1, 1].
    pub fn rlkit_random(obs_dim: usize, act_dim: usize, hidden: &[usize], seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut layers = Vec::new();
        let mut width = obs_dim;
        for &h in hidden {
            let fan_in = 1.0 / (width as f32).sqrt();
            layers.push(Dense::rlkit(width, h, fan_in, Some(HIDDEN_BIAS), &mut rng));
            width = h;
        }
        let mean = Dense::rlkit(width, act_dim, OUTPUT_INIT, None, &mut rng);
        let log_std = Dense::rlkit(width, act_dim, OUTPUT_INIT, None, &mut rng);
        Self {
            hidden: layers,
            output: mean.beside(&log_std),
            obs_dim,
            act_dim,
            log_std_range: RLKIT_LOG_STD_RANGE,
            half: vec![1.0; act_dim],
            center: vec![0.0; act_dim],
            log_half_sum: 0.0,
            mode: ActionMode::Sampled,
            noise: NoiseStream::PerEntry,
        }
    }

    /// `policy`'s weights, acting as it does (the same ε for the same
    /// generator; the same actions up to rounding).
    pub fn new(policy: &ActorPolicy) -> Self {
        let config = &policy.actor.config;
        let mut layers: Vec<Dense> = policy
            .actor
            .net
            .layers
            .iter()
            .map(|layer| Dense {
                weight: to_f32_vec(layer.weight.val()),
                bias: layer.bias.as_ref().map_or_else(
                    || vec![0.0; layer.weight.val().dims()[1]],
                    |b| to_f32_vec(b.val()),
                ),
            })
            .collect();
        let output = layers.pop().expect("an actor has an output layer");
        let (half, center) = config.box_half_center();
        Self {
            hidden: layers,
            output,
            obs_dim: config.obs_dim,
            act_dim: config.act_dim,
            log_std_range: (config.log_std_min, config.log_std_max),
            log_half_sum: half.iter().map(|h| h.ln()).sum(),
            half,
            center,
            mode: policy.mode,
            noise: NoiseStream::Seeded,
        }
    }

    /// What a dataset's metadata says about the random policy.
    pub fn rlkit_description(&self) -> String {
        let sizes: Vec<String> = self
            .hidden
            .iter()
            .map(|l| l.bias.len().to_string())
            .collect();
        format!(
            "randomly initialised tanh-Gaussian MLP actor (rlkit init: hidden [{}] ReLU fan-in uniform, \
             bias {HIDDEN_BIAS}, outputs uniform ±{OUTPUT_INIT}); actions sampled",
            sizes.join(", ")
        )
    }

    /// One row's action into `action`, with ε from `noise` (sampled mode);
    /// log π(a|s), 0 in deterministic mode.
    fn act_row(&self, obs: &[f32], noise: &mut dyn FnMut() -> f32, action: &mut [f32]) -> f32 {
        let features = self
            .hidden
            .iter()
            .fold(obs.to_vec(), |x, layer| layer.forward(&x, true));
        let out = self.output.forward(&features, false);
        let (mean, log_std) = out.split_at(self.act_dim);
        let mut log_prob = -self.log_half_sum;
        for d in 0..self.act_dim {
            let u = match self.mode {
                ActionMode::Deterministic => mean[d],
                ActionMode::Sampled => {
                    let log_std = log_std[d].clamp(self.log_std_range.0, self.log_std_range.1);
                    let eps = noise();
                    let u = mean[d] + log_std.exp() * eps;
                    log_prob += tanh_gaussian_log_density(eps, log_std, u);
                    u
                }
            };
            action[d] = u.tanh() * self.half[d] + self.center[d];
        }
        log_prob
    }
}

impl BatchPolicy for PortableActor {
    fn obs_dim(&self) -> usize {
        self.obs_dim
    }

    fn act_dim(&self) -> usize {
        self.act_dim
    }

    fn act(&self, observations: &[f32], rng: &mut dyn RngCore) -> Vec<f32> {
        self.act_logged(observations, rng).actions
    }

    fn act_logged(&self, observations: &[f32], rng: &mut dyn RngCore) -> LoggedActions {
        let batch = act_batch(self, observations);
        let sampled = self.mode == ActionMode::Sampled;
        let seeded = match (sampled, self.noise) {
            (true, NoiseStream::Seeded) => action_noise(batch * self.act_dim, rng),
            _ => Vec::new(),
        };
        let mut seeded = seeded.into_iter();
        let mut noise = || match self.noise {
            NoiseStream::PerEntry => rng.sample(StandardNormal),
            NoiseStream::Seeded => seeded.next().expect("one ε per sampled entry"),
        };
        let mut actions = vec![0.0; batch * self.act_dim];
        let log_probs = observations
            .chunks_exact(self.obs_dim)
            .zip(actions.chunks_exact_mut(self.act_dim))
            .map(|(obs, action)| self.act_row(obs, &mut noise, action))
            .collect();
        LoggedActions {
            actions,
            log_probs: sampled.then_some(log_probs),
        }
    }
}
