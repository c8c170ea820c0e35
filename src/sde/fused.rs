//! The neural SDE's Euler–Maruyama step (eq. 5, 8) on the fused CPU path:
//! the same arithmetic as [`NeuralSde::step`], over row tiles in parallel.

use std::cell::RefCell;
use std::sync::Mutex;

use super::drift_inputs::DriftFeatures;
use super::{NeuralSde, SdeConstants};
use crate::infer::{
    DenseMlp, GEMM_MIN_ROWS, Kernel, MlpScratch, Rows, row_chunks, run_tiles, tile_rows,
    with_buffers,
};
use crate::shared::{BatchDynamics, BatchShape, ModelStep, euler_maruyama, step_batch};

/// A [`NeuralSde`]'s weights laid out for [`BatchDynamics::step`] on the CPU.
#[derive(Debug, Clone)]
pub struct FusedSde {
    constants: SdeConstants,
    /// G(s_vel), H(s), f_res, f_rew, σ_ϕ and NN_ϕ of η_ϕ (μ_ϕ is only trained, never stepped).
    g: DenseMlp,
    h: DenseMlp,
    res: DenseMlp,
    reward: Option<DenseMlp>,
    sigma: DenseMlp,
    eta: DenseMlp,
    /// W^max of h_ϕ per state dimension, in multiples of the diffusion scale.
    w_max: Vec<f32>,
    /// φ(s), what G, H and f_res see of the state.
    features: DriftFeatures,
    split: NetworkSplit,
}

/// One tile's inputs and the slices of the step's outputs it fills.
struct Tile<'a> {
    states: &'a [f32],
    actions: &'a [f32],
    noise: &'a [f32],
    next: &'a mut [f32],
    mean: &'a mut [f32],
    sigma: &'a mut [f32],
    h_eta: &'a mut [f32],
    eta: &'a mut [f32],
}

/// A tile's intermediate values, one set per thread, reused across steps.
#[derive(Debug, Default)]
struct Scratch {
    input: Vec<f32>,
    /// `[φ(s), â]`, f_res's input (G and H read columns of it).
    drift_input: Vec<f32>,
    g: Vec<f32>,
    h: Vec<f32>,
    res: Vec<f32>,
    reward: Vec<f32>,
    sigma: Vec<f32>,
    eta: Vec<f32>,
}

thread_local! {
    static SCRATCH: RefCell<Scratch> = RefCell::new(Scratch::default());
    /// Hidden activations, apart from [`SCRATCH`]: networks of one step may run
    /// on other threads.
    static MLP_SCRATCH: RefCell<MlpScratch> = RefCell::new(MlpScratch::default());
}

/// One network to evaluate on a tile, and where its output goes.
struct Job<'a> {
    net: &'a DenseMlp,
    input: Rows<'a>,
    out: Mutex<&'a mut Vec<f32>>,
}

impl<'a> Job<'a> {
    fn new(net: &'a DenseMlp, input: Rows<'a>, out: &'a mut Vec<f32>) -> Self {
        Self {
            net,
            input,
            out: Mutex::new(out),
        }
    }

    fn run(&self) {
        let mut out = self.out.lock().unwrap_or_else(|e| e.into_inner());
        out.resize(self.input.rows * self.net.d_out(), 0.0);
        with_buffers(&MLP_SCRATCH, |scratch| {
            self.net.forward(self.input, &mut out, scratch)
        });
    }
}

/// Which core evaluates which network when a tile is split by network, each
/// core always taking the same networks: the model's ~2 MB of weights do not
/// fit one core's L2 cache, but each core's share does.
#[derive(Debug, Clone)]
struct NetworkSplit {
    threads: usize,
    /// Per network (in [`FusedSde::networks`] order), its core.
    owner: Vec<usize>,
}

impl NetworkSplit {
    /// Largest first, each to the least loaded core (weights only count).
    fn new(weights: &[usize], threads: usize) -> Self {
        let mut order: Vec<usize> = (0..weights.len()).collect();
        order.sort_by_key(|&j| std::cmp::Reverse(weights[j]));
        let mut load = vec![0usize; threads];
        let mut owner = vec![0usize; weights.len()];
        for j in order {
            let core = (0..threads).min_by_key(|&c| load[c]).unwrap_or(0);
            owner[j] = core;
            load[core] += weights[j];
        }
        Self { threads, owner }
    }
}

/// Evaluates every job: by rows when the tile is big enough for the matmul
/// kernel (the tiles themselves are already spread over the cores), else by
/// network across the cores, as `split` assigns them.
fn run_networks(split: &NetworkSplit, jobs: &[Job], rows: usize) {
    let threads = rayon::current_num_threads();
    if rows >= GEMM_MIN_ROWS || threads < 2 {
        jobs.iter().for_each(Job::run);
        return;
    }
    let other_pool;
    let split = if split.threads == threads {
        split
    } else {
        // Called from a pool of another size than the one the model was built in.
        let weights: Vec<usize> = jobs.iter().map(|job| job.net.weight_count()).collect();
        other_pool = NetworkSplit::new(&weights, threads);
        &other_pool
    };
    rayon::broadcast(|ctx| {
        for (job, &core) in jobs.iter().zip(&split.owner) {
            if core == ctx.index() {
                job.run();
            }
        }
    });
}

pub(super) fn sigmoid(z: f32) -> f32 {
    1.0 / (1.0 + (-z).exp())
}

/// softplus(z) = log(1 + e^z), in the form that cannot overflow.
pub(super) fn softplus(z: f32) -> f32 {
    z.max(0.0) + (-z.abs()).exp().ln_1p()
}

impl FusedSde {
    /// The same model as `model`, its weights copied out of burn.
    pub fn new(model: &NeuralSde) -> Self {
        let mut fused = Self {
            constants: model.constants.clone(),
            g: DenseMlp::from_burn(&model.g_net),
            h: DenseMlp::from_burn(&model.h_net),
            res: DenseMlp::from_burn(&model.res_net),
            reward: model.reward_net.as_ref().map(DenseMlp::from_burn),
            sigma: DenseMlp::from_burn(&model.sigma_net),
            eta: DenseMlp::from_burn(&model.distance.eta_net),
            w_max: model
                .constants
                .config
                .w_max_per_dimension(model.constants.state_dim()),
            features: DriftFeatures::of(&model.constants),
            split: NetworkSplit::new(&[], 1),
        };
        let weights: Vec<usize> = fused.networks().map(DenseMlp::weight_count).collect();
        fused.split = NetworkSplit::new(&weights, rayon::current_num_threads());
        fused
    }

    /// The networks a step evaluates, in the order of its jobs.
    fn networks(&self) -> impl Iterator<Item = &DenseMlp> {
        [&self.g, &self.h, &self.res, &self.sigma, &self.eta]
            .into_iter()
            .chain(self.reward.as_ref())
    }

    /// Fills one tile: networks over all its rows, then eq. 8 and eq. 5 row by row.
    fn step_tile(&self, tile: Tile, s: &mut Scratch) {
        let c = &self.constants;
        let spec = &c.spec;
        let normalizer = &c.scales.normalizer;
        let (obs_dim, act_dim) = (spec.obs_dim, spec.act_dim);
        let (n_pos, n_vel) = (spec.n_pos(), spec.n_vel());
        let state_dim = c.state_dim();
        let width = obs_dim + act_dim;
        let rows = tile.eta.len();

        // Normalised (s, a), σ's and η's input; [φ(s), â], the drift's.
        s.input.clear();
        s.drift_input.clear();
        for (state, action) in tile
            .states
            .chunks_exact(state_dim)
            .zip(tile.actions.chunks_exact(act_dim))
        {
            let obs = state[..obs_dim].iter().zip(&normalizer.state.mean);
            s.input.extend(
                obs.zip(&normalizer.state.std)
                    .map(|((x, m), sd)| (x - m) / sd),
            );
            let act = action.iter().zip(&normalizer.action.mean);
            s.input.extend(
                act.zip(&normalizer.action.std)
                    .map(|((x, m), sd)| (x - m) / sd),
            );
            self.features.extend(&state[..obs_dim], &mut s.drift_input);
            let row = s.input.len() - act_dim;
            s.drift_input.extend_from_slice(&s.input[row..]);
        }
        let input = Rows::dense(&s.input, width);
        let phi = self.features.width();
        let drift_width = phi + act_dim;
        let g_columns = self.features.g_columns();
        // In [`FusedSde::networks`] order: `self.split` assigns cores by position.
        let mut jobs = vec![
            Job::new(
                &self.g,
                Rows::columns(
                    &s.drift_input,
                    drift_width,
                    g_columns.start,
                    g_columns.len(),
                ),
                &mut s.g,
            ),
            Job::new(
                &self.h,
                Rows::columns(&s.drift_input, drift_width, 0, phi),
                &mut s.h,
            ),
            Job::new(
                &self.res,
                Rows::dense(&s.drift_input, drift_width),
                &mut s.res,
            ),
            Job::new(&self.sigma, input, &mut s.sigma),
            Job::new(&self.eta, input, &mut s.eta),
        ];
        if let Some(reward) = &self.reward {
            jobs.push(Job::new(reward, input, &mut s.reward));
        }
        run_networks(&self.split, &jobs, rows);

        let dt = spec.dt as f32;
        let sqrt_dt = spec.dt.sqrt() as f32;
        let vel_std = &normalizer.state.std[n_pos..obs_dim];
        let diffusion = &c.scales.diffusion[..state_dim];
        let (eta_max, eta_offset) = (c.config.eta_max, c.config.eta_offset);
        let w_max = &self.w_max;
        let (h_weight, h_bias) = (c.config.h_weight, c.config.h_bias);
        for r in 0..rows {
            let state = &tile.states[r * state_dim..(r + 1) * state_dim];
            let action = &tile.actions[r * act_dim..(r + 1) * act_dim];
            let span = r * state_dim..(r + 1) * state_dim;
            let (mean, next) = (&mut tile.mean[span.clone()], &mut tile.next[span.clone()]);
            let (sigma, h_eta) = (&mut tile.sigma[span.clone()], &mut tile.h_eta[span.clone()]);
            let noise = &tile.noise[span];
            let res = &s.res[r * obs_dim..(r + 1) * obs_dim];
            let g = &s.g[r * n_vel * act_dim..(r + 1) * n_vel * act_dim];
            let h = &s.h[r * n_vel * n_vel..(r + 1) * n_vel * n_vel];

            // eq. 8: f_pos = the velocities of the observed positions.
            for (i, &v) in spec.split.position_velocity.iter().enumerate() {
                mean[i] = state[i] + (state[v] + res[i] * c.scales.derivative[i]) * dt;
            }
            // eq. 8: f_vel = G(φ)·a + H(φ)·s_vel, velocities scaled, not shifted.
            let velocity = &state[n_pos..obs_dim];
            for i in 0..n_vel {
                let g_a: f32 = g[i * act_dim..(i + 1) * act_dim]
                    .iter()
                    .zip(action)
                    .map(|(g, a)| g * a)
                    .sum();
                let h_v: f32 = h[i * n_vel..(i + 1) * n_vel]
                    .iter()
                    .zip(velocity.iter().zip(vel_std))
                    .map(|(h, (v, sd))| h * (v / sd))
                    .sum();
                let d = n_pos + i;
                let f_vel = (g_a + h_v) * c.scales.acceleration[i];
                mean[d] = state[d] + (f_vel + res[d] * c.scales.derivative[d]) * dt;
            }
            if self.reward.is_some() {
                // NUNO^R: dr_c = f_rew(s, a) dt.
                let f_rew = s.reward[r] * c.scales.reward_rate;
                mean[obs_dim] = state[obs_dim] + f_rew * dt;
            }
            // eq. 5: Σ = σ_ϕ(s, a) + h_ϕ(η_ϕ(s, a)), then s' = mean + Σ·sqrt(dt)·ε.
            // h_ϕ reads η's logit (see `sde::model`).
            let logit = s.eta[r] - eta_offset;
            tile.eta[r] = sigmoid(logit) * eta_max;
            for d in 0..state_dim {
                sigma[d] =
                    (softplus(s.sigma[r * state_dim + d]) + c.config.sigma_min) * diffusion[d];
                h_eta[d] = sigmoid(logit * h_weight + h_bias) * diffusion[d] * w_max[d];
                next[d] = euler_maruyama(mean[d], sigma[d], h_eta[d], noise[d], sqrt_dt);
            }
        }
    }
}

impl BatchDynamics for FusedSde {
    fn shape(&self) -> BatchShape {
        self.constants.batch_shape()
    }

    fn sample_noise_scale(&self) -> f32 {
        self.constants.config.sample_noise_scale
    }

    fn step(&self, states: &[f32], actions: &[f32], noise: &[f32]) -> ModelStep {
        let batch = step_batch(self, states, actions, noise);
        let (state_dim, act_dim) = (self.state_dim(), self.constants.spec.act_dim);
        let zeros = vec![0.0; batch * state_dim];
        let mut out = ModelStep {
            next_states: zeros.clone(),
            means: zeros.clone(),
            sigma: zeros.clone(),
            h_eta: zeros,
            eta: vec![0.0; batch],
            truncation_signal: None,
        };
        let rows = tile_rows(batch);
        let tiles: Vec<Tile> = states
            .chunks(rows * state_dim)
            .zip(actions.chunks(rows * act_dim))
            .zip(noise.chunks(rows * state_dim))
            .zip(row_chunks(&mut out.next_states, rows, state_dim))
            .zip(row_chunks(&mut out.means, rows, state_dim))
            .zip(row_chunks(&mut out.sigma, rows, state_dim))
            .zip(row_chunks(&mut out.h_eta, rows, state_dim))
            .zip(row_chunks(&mut out.eta, rows, 1))
            .map(
                |(((((((states, actions), noise), next), mean), sigma), h_eta), eta)| Tile {
                    states,
                    actions,
                    noise,
                    next,
                    mean,
                    sigma,
                    h_eta,
                    eta,
                },
            )
            .collect();
        run_tiles(tiles, |tile| {
            with_buffers(&SCRATCH, |scratch| self.step_tile(tile, scratch));
        });
        out
    }
}

impl Kernel {
    /// `model` behind the batch interface, evaluated by this kernel.
    pub fn dynamics<'a>(self, model: &'a NeuralSde) -> Box<dyn BatchDynamics + 'a> {
        match self {
            Kernel::Fused => Box::new(FusedSde::new(model)),
            Kernel::Burn => Box::new(model),
        }
    }
}
