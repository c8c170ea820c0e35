//! The policy behind D4RL's "random" datasets: a randomly initialised
//! tanh-Gaussian SAC actor (rlkit's `TanhGaussianPolicy`), whose actions are
//! sampled, not its mean. With rlkit's initialisation (hidden layers fan-in
//! uniform with bias 0.1, output layers uniform in ±1e-3) the mean is near 0
//! and the std near 1, so actions are close to `tanh(N(0, 1))` per dimension,
//! with a weak dependence on the state.

use rand::{Rng, RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use super::actor::tanh_gaussian_log_density;
use crate::shared::{BatchPolicy, LoggedActions, act_batch};

/// rlkit's output-layer init range (`init_w`).
const OUTPUT_INIT: f32 = 1e-3;
/// rlkit's hidden-layer bias (`b_init_value`).
const HIDDEN_BIAS: f32 = 0.1;
/// Log-std clamp of rlkit's actor.
const LOG_STD_RANGE: (f32, f32) = (-20.0, 2.0);

/// One dense layer, `y = W x + b`, with `W` stored input-major (`[in, out]`)
/// so the forward pass is a run of vectorisable `y += x_j · W_j` updates.
#[derive(Debug, Clone)]
struct Dense {
    weight: Vec<f32>,
    bias: Vec<f32>,
}

impl Dense {
    fn new(
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

/// A randomly initialised tanh-Gaussian actor with two hidden ReLU layers.
#[derive(Debug, Clone)]
pub struct RandomNetworkPolicy {
    hidden: Vec<Dense>,
    mean: Dense,
    log_std: Dense,
    obs_dim: usize,
}

impl RandomNetworkPolicy {
    /// rlkit's default actor (hidden sizes `[256, 256]`), weights drawn from `seed`.
    pub fn new(obs_dim: usize, act_dim: usize, hidden: &[usize], seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut layers = Vec::new();
        let mut width = obs_dim;
        for &h in hidden {
            let fan_in = 1.0 / (width as f32).sqrt();
            layers.push(Dense::new(width, h, fan_in, Some(HIDDEN_BIAS), &mut rng));
            width = h;
        }
        Self {
            mean: Dense::new(width, act_dim, OUTPUT_INIT, None, &mut rng),
            log_std: Dense::new(width, act_dim, OUTPUT_INIT, None, &mut rng),
            hidden: layers,
            obs_dim,
        }
    }

    /// What the dataset metadata says about this policy.
    pub fn description(&self) -> String {
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
}

impl BatchPolicy for RandomNetworkPolicy {
    fn obs_dim(&self) -> usize {
        self.obs_dim
    }

    fn act_dim(&self) -> usize {
        self.mean.bias.len()
    }

    fn act(&self, observations: &[f32], rng: &mut dyn RngCore) -> Vec<f32> {
        self.act_logged(observations, rng).actions
    }

    fn act_logged(&self, observations: &[f32], rng: &mut dyn RngCore) -> LoggedActions {
        let batch = act_batch(self, observations);
        let mut actions = Vec::with_capacity(batch * self.act_dim());
        let mut log_probs = Vec::with_capacity(batch);
        for obs in observations.chunks_exact(self.obs_dim) {
            let features = self
                .hidden
                .iter()
                .fold(obs.to_vec(), |x, layer| layer.forward(&x, true));
            let mean = self.mean.forward(&features, false);
            let log_std = self.log_std.forward(&features, false);
            let mut log_prob = 0.0;
            for (m, l) in mean.iter().zip(&log_std) {
                let log_std = l.clamp(LOG_STD_RANGE.0, LOG_STD_RANGE.1);
                let noise: f32 = rng.sample(StandardNormal);
                let u = m + log_std.exp() * noise;
                log_prob += tanh_gaussian_log_density(noise, log_std, u);
                actions.push(u.tanh());
            }
            log_probs.push(log_prob);
        }
        LoggedActions {
            actions,
            log_probs: Some(log_probs),
        }
    }
}
