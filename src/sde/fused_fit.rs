//! The SDE's fit step on the fused CPU kernels (`crate::infer`): eq. 7 and its
//! gradient by hand, each network a [`TrainableMlp`] whose products split
//! their rows over every core. `super::fit_step`'s burn trainer is the
//! reference; the unit tests below hold every gradient to it.
//!
//! L_data (eq. 6), per window step k with Σ = σ + h(η) and var = Σ²·dt:
//! ∂/∂mean = −2·err/var, ∂/∂Σ = (2/Σ)·(1 − err²/var) (times λ_data·w_k/B);
//! on the particle path step k + 1 starts at mean + c·Σ·√dt·ε, so its
//! gradient with respect to its start adds to step k's mean and, times
//! c·√dt·ε, to its Σ, and flows into step k's start through every network's
//! input gradient. h(η) reads η's logit detached, so it passes no gradient.
//!
//! η's losses (eq. 3, 4) hold ∇ₓη: with d = NN_ϕ, s = sigmoid(d − offset),
//! η = η_max·s and ∇η = η_max·s(1 − s)·∇d, so
//! ∂/∂d = ∂/∂η·η_max·s(1 − s) + (∂/∂∇η·∇d)·η_max·s(1 − s)(1 − 2s) and
//! ∂/∂∇d = ∂/∂∇η·η_max·s(1 − s), which
//! [`TrainableMlp::backward_through_input_gradient`] turns into the weights'.

use burn::module::Param;
use burn::tensor::{Tensor, TensorData};

use super::config::{EtaLossForm, LikelihoodPath, LossConfig, SCALAR_MU_FACTOR};
use super::drift_inputs::DriftFeatures;
use super::fit::window_states;
use super::fit_step::{SdeTrainer, StepDraws, StepLosses, StepSettings};
use super::fused::{sigmoid, softplus};
use super::model::NeuralSde;
use crate::infer::{MlpTape, TrainableMlp};
use crate::nn::{AdamState, clip_to_norm, to_f32_vec};

/// Every network of the SDE, in its module's field order.
#[derive(Debug, Clone)]
struct Nets {
    g: TrainableMlp,
    h: TrainableMlp,
    res: TrainableMlp,
    reward: Option<TrainableMlp>,
    sigma: TrainableMlp,
    eta: TrainableMlp,
    mu: MuParams,
}

/// μ_ϕ's parameters (`MuForm`): its network's, or the scalar form's p.
#[derive(Debug, Clone)]
enum MuParams {
    Network(TrainableMlp),
    Scalar(f32),
}

/// The scalar form's p, by its module path in [`NeuralSde`].
const MU_SCALAR_PATH: &str = "distance.mu_scalar";

impl MuParams {
    fn of(distance: &super::DistanceAware) -> Self {
        match (&distance.mu_net, &distance.mu_scalar) {
            (Some(net), _) => Self::Network(TrainableMlp::from_burn(net)),
            (None, Some(p)) => Self::Scalar(to_f32_vec(p.val())[0]),
            (None, None) => unreachable!("DistanceAware::init builds one form of μ"),
        }
    }

    fn zeros_like(&self) -> Self {
        match self {
            Self::Network(net) => Self::Network(net.zeros_like()),
            Self::Scalar(_) => Self::Scalar(0.0),
        }
    }

    fn write_to(&self, distance: &mut super::DistanceAware) {
        match self {
            Self::Network(net) => distance.mu_net = distance.mu_net.take().map(|m| net.write_to(m)),
            Self::Scalar(p) => {
                distance.mu_scalar = distance.mu_scalar.take().map(|param| {
                    let device = param.val().device();
                    let value = Tensor::<1>::from_data(TensorData::new(vec![*p], [1]), &device);
                    Param::initialized(param.id, value)
                })
            }
        }
    }
}

impl Nets {
    fn of(model: &NeuralSde) -> Self {
        Self {
            g: TrainableMlp::from_burn(&model.g_net),
            h: TrainableMlp::from_burn(&model.h_net),
            res: TrainableMlp::from_burn(&model.res_net),
            reward: model.reward_net.as_ref().map(TrainableMlp::from_burn),
            sigma: TrainableMlp::from_burn(&model.sigma_net),
            eta: TrainableMlp::from_burn(&model.distance.eta_net),
            mu: MuParams::of(&model.distance),
        }
    }

    fn zeros_like(&self) -> Self {
        Self {
            g: self.g.zeros_like(),
            h: self.h.zeros_like(),
            res: self.res.zeros_like(),
            reward: self.reward.as_ref().map(TrainableMlp::zeros_like),
            sigma: self.sigma.zeros_like(),
            eta: self.eta.zeros_like(),
            mu: self.mu.zeros_like(),
        }
    }

    /// `model` holding these weights.
    fn write_to(&self, mut model: NeuralSde) -> NeuralSde {
        model.g_net = self.g.write_to(model.g_net);
        model.h_net = self.h.write_to(model.h_net);
        model.res_net = self.res.write_to(model.res_net);
        if let (Some(net), Some(mlp)) = (&self.reward, model.reward_net.take()) {
            model.reward_net = Some(net.write_to(mlp));
        }
        model.sigma_net = self.sigma.write_to(model.sigma_net);
        model.distance.eta_net = self.eta.write_to(model.distance.eta_net);
        self.mu.write_to(&mut model.distance);
        model
    }

    /// The drift and diffusion networks (G, H, f_res, f_rew, σ), the reward's
    /// `None` without NUNO^R.
    fn nets(&self) -> [Option<&TrainableMlp>; 5] {
        [
            Some(&self.g),
            Some(&self.h),
            Some(&self.res),
            self.reward.as_ref(),
            Some(&self.sigma),
        ]
    }

    /// [`Nets::nets`], mutably.
    fn nets_mut(&mut self) -> [Option<&mut TrainableMlp>; 5] {
        [
            Some(&mut self.g),
            Some(&mut self.h),
            Some(&mut self.res),
            self.reward.as_mut(),
            Some(&mut self.sigma),
        ]
    }

    /// Each network under its module path in [`NeuralSde`].
    fn named_mut(&mut self) -> Vec<(&'static str, &mut TrainableMlp)> {
        let mut nets = vec![
            ("g_net", &mut self.g),
            ("h_net", &mut self.h),
            ("res_net", &mut self.res),
        ];
        if let Some(reward) = &mut self.reward {
            nets.push(("reward_net", reward));
        }
        nets.push(("sigma_net", &mut self.sigma));
        nets.push(("distance.eta_net", &mut self.eta));
        if let MuParams::Network(mu) = &mut self.mu {
            nets.push(("distance.mu_net", mu));
        }
        nets
    }
}

/// `total += part`, parameter by parameter.
fn accumulate(total: &mut TrainableMlp, part: &TrainableMlp) {
    for (t, p) in total.layers.iter_mut().zip(&part.layers) {
        t.weight
            .iter_mut()
            .zip(&p.weight)
            .for_each(|(t, p)| *t += p);
        t.bias.iter_mut().zip(&p.bias).for_each(|(t, p)| *t += p);
    }
}

/// The model's constants as the step reads them.
#[derive(Debug, Clone)]
struct Shape {
    obs: usize,
    act: usize,
    state: usize,
    n_pos: usize,
    n_vel: usize,
    /// The velocity of each position (eq. 8: f_pos).
    pairs: Vec<usize>,
    state_mean: Vec<f32>,
    state_std: Vec<f32>,
    action_mean: Vec<f32>,
    action_std: Vec<f32>,
    acceleration: Vec<f32>,
    derivative: Vec<f32>,
    reward_rate: f32,
    diffusion: Vec<f32>,
    w_max: Vec<f32>,
    /// 1/scale² of each state dimension: L_data's log-variance in normalised units.
    inv_scale2: Vec<f32>,
    dt: f32,
    /// φ(s), what G, H and f_res see of the state.
    features: DriftFeatures,
}

impl Shape {
    fn of(model: &NeuralSde) -> Self {
        let c = &model.constants;
        let n = &c.scales.normalizer;
        let (obs, state) = (c.spec.obs_dim, c.state_dim());
        let mut scale = n.state.std[..obs].to_vec();
        if c.config.reward_model {
            scale.push(n.reward.std[0]);
        }
        Self {
            obs,
            act: c.spec.act_dim,
            state,
            n_pos: c.spec.n_pos(),
            n_vel: c.spec.n_vel(),
            pairs: c.spec.split.position_velocity.clone(),
            state_mean: n.state.mean[..obs].to_vec(),
            state_std: n.state.std[..obs].to_vec(),
            action_mean: n.action.mean.clone(),
            action_std: n.action.std.clone(),
            acceleration: c.scales.acceleration.clone(),
            derivative: c.scales.derivative.clone(),
            reward_rate: c.scales.reward_rate,
            diffusion: c.scales.diffusion[..state].to_vec(),
            w_max: c.config.w_max_per_dimension(state),
            inv_scale2: scale.iter().map(|s| (s * s).recip()).collect(),
            dt: c.spec.dt as f32,
            features: DriftFeatures::of(c),
        }
    }

    fn input(&self) -> usize {
        self.obs + self.act
    }

    /// Width of `[φ(s), â]`, f_res's input.
    fn drift_input(&self) -> usize {
        self.features.width() + self.act
    }
}

/// The settings one step reads off the model (h's b changes during a fit).
#[derive(Debug, Clone, Copy)]
struct Knobs {
    h_weight: f32,
    h_bias: f32,
    sigma_min: f32,
    eta_offset: f32,
    eta_max: f32,
    noise_scale: f32,
}

impl Knobs {
    fn of(model: &NeuralSde) -> Self {
        let c = &model.constants.config;
        Self {
            h_weight: c.h_weight,
            h_bias: c.h_bias,
            sigma_min: c.sigma_min,
            eta_offset: model.distance.eta_offset,
            eta_max: model.distance.eta_max,
            noise_scale: c.sample_noise_scale,
        }
    }
}

/// One window step's forward values, kept for its backward pass.
#[derive(Debug, Default)]
struct StepTape {
    /// The step's start `[B, state]`, action `[B, act]` and recorded next state `[B, state]`.
    start: Vec<f32>,
    action: Vec<f32>,
    next: Vec<f32>,
    /// Normalised `(s, a)` `[B, obs + act]` (σ's, η's and f_rew's input);
    /// `[φ(s), â]` `[B, φ + act]` (f_res's), G's columns of it and H's (φ).
    x: Vec<f32>,
    x_drift: Vec<f32>,
    x_g: Vec<f32>,
    x_h: Vec<f32>,
    /// Velocities over their std, `[B, n_vel]`.
    v_hat: Vec<f32>,
    /// η's logit, `[B]`.
    logit: Vec<f32>,
    /// Σ, the mean, var = Σ²·dt and err = next − mean, each `[B, state]`.
    diffusion: Vec<f32>,
    mean: Vec<f32>,
    var: Vec<f32>,
    err: Vec<f32>,
    g: MlpTape,
    h: MlpTape,
    res: MlpTape,
    reward: MlpTape,
    sigma: MlpTape,
}

impl StepTape {
    fn on_cores(cores: usize) -> Self {
        Self {
            g: MlpTape::on_cores(cores),
            h: MlpTape::on_cores(cores),
            res: MlpTape::on_cores(cores),
            reward: MlpTape::on_cores(cores),
            sigma: MlpTape::on_cores(cores),
            ..Self::default()
        }
    }
}

/// Buffers of η's losses and the backward passes, reused every step.
#[derive(Debug, Default)]
struct Work {
    /// η at the data (with its input gradient), at the ball samples, at the
    /// far points, and for h(η) and h's b; μ at the data.
    eta_data: MlpTape,
    eta_ball: MlpTape,
    eta_far: MlpTape,
    eta_plain: MlpTape,
    mu: MlpTape,
    /// ∇ₓd at the data `[B, obs + act]`, the ball's points, ones `[B]`.
    grad_d: Vec<f32>,
    ball: Vec<f32>,
    ones: Vec<f32>,
    /// ∂L/∂ of a network's output (and ∂L/∂∇d).
    out_grad: Vec<f32>,
    q: Vec<f32>,
    /// ∂L/∂ of the normalised input, of `[φ(s), â]` and of the start state,
    /// this step's and the next's.
    x_grad: Vec<f32>,
    x_drift_grad: Vec<f32>,
    start_grad: Vec<f32>,
    next_start_grad: Vec<f32>,
    /// ∂L/∂ of each network's output in one step's backward pass.
    step: OutputGrads,
}

/// ∂L/∂ of each network's output at one window step, and of its input
/// (G, H, f_res, f_rew, σ).
#[derive(Debug, Default)]
struct OutputGrads {
    g: Vec<f32>,
    h: Vec<f32>,
    res: Vec<f32>,
    reward: Vec<f32>,
    sigma: Vec<f32>,
    inputs: [Vec<f32>; 5],
}

/// Trains a [`NeuralSde`]'s weights on host buffers, by hand.
pub(crate) struct FusedSdeTrainer {
    /// The model the weights came from (its constants hold h's current b).
    template: NeuralSde,
    shape: Shape,
    nets: Nets,
    grads: Nets,
    scratch: Nets,
    state: AdamState,
    settings: StepSettings,
    steps: Vec<StepTape>,
    work: Work,
}

impl FusedSdeTrainer {
    /// Trains `model`'s weights (read to host memory once).
    pub fn new(model: NeuralSde, settings: StepSettings) -> Self {
        let cores = tape_cores();
        let nets = Nets::of(&model);
        let on_cores = MlpTape::on_cores;
        Self {
            shape: Shape::of(&model),
            grads: nets.zeros_like(),
            scratch: nets.zeros_like(),
            nets,
            template: model,
            state: AdamState::default(),
            settings,
            steps: Vec::new(),
            work: Work {
                eta_data: on_cores(cores),
                eta_ball: on_cores(cores),
                eta_far: on_cores(cores),
                eta_plain: on_cores(cores),
                mu: on_cores(cores),
                ..Work::default()
            },
        }
    }

    /// eq. 7 on `draws` with its gradient in `self.grads`.
    fn loss_and_gradient(&mut self, draws: &StepDraws) -> StepLosses {
        let Self {
            template,
            shape: sh,
            nets,
            grads,
            scratch,
            settings,
            steps,
            work,
            ..
        } = self;
        let loss = &settings.loss;
        let knobs = Knobs::of(template);
        let windows = &draws.windows;
        let (batch, horizon) = (windows.batch, windows.horizon);
        let states = window_states(windows, sh.obs, template.constants.config.reward_model);
        steps.resize_with(horizon, || StepTape::on_cores(tape_cores()));
        let at = |values: &[f32], steps: usize, k: usize, width: usize, out: &mut Vec<f32>| {
            out.clear();
            for r in 0..batch {
                let row = (r * steps + k) * width;
                out.extend_from_slice(&values[row..row + width]);
            }
        };
        let particle = loss.likelihood == LikelihoodPath::Particle;

        // Forward, step by step.
        let (mut data, mut residual) = (0.0f64, 0.0f64);
        let mut weights = Vec::with_capacity(horizon);
        let mut weight = 1.0f32;
        for k in 0..horizon {
            let (before, after) = steps.split_at_mut(k);
            let tape = &mut after[0];
            at(&windows.actions, horizon, k, sh.act, &mut tape.action);
            at(&states, horizon + 1, k + 1, sh.state, &mut tape.next);
            match before.last() {
                Some(previous) if particle => {
                    let noise = (&draws.step_noise[..], k - 1, horizon);
                    particle_start(previous, noise, sh.state, knobs, &mut tape.start)
                }
                _ => at(&states, horizon + 1, k, sh.state, &mut tape.start),
            }
            let (nll, res) = forward_step(nets, sh, knobs, tape, &mut work.eta_plain);
            data += nll * f64::from(weight);
            residual += res;
            weights.push(weight);
            weight *= loss.step_discount;
        }
        let residual = residual / horizon as f64;

        // η's losses at each window's first (s, a), and their gradient.
        for net in nets_of(grads) {
            net.layers.iter_mut().for_each(|l| {
                l.weight.fill(0.0);
                l.bias.fill(0.0);
            });
        }
        let eta = eta_losses(
            nets,
            grads,
            scratch,
            sh,
            knobs,
            loss,
            &steps[0].x,
            draws,
            work,
        );

        // Backward, last step first.
        work.next_start_grad.clear();
        for k in (0..horizon).rev() {
            let coef = loss.lambda_data * weights[k] / batch as f32;
            let noise_k = (particle && k + 1 < horizon).then_some(k);
            let wants_start = particle && k > 0;
            backward_step(
                nets,
                grads,
                scratch,
                sh,
                knobs,
                &mut steps[k],
                work,
                (coef, loss.lambda_res / (batch * horizon) as f32),
                noise_k.map(|k| (&draws.step_noise[..], k, horizon)),
                wants_start,
            );
            std::mem::swap(&mut work.start_grad, &mut work.next_start_grad);
        }
        let data = data as f32;
        let residual = residual as f32;
        StepLosses {
            total: data * loss.lambda_data + eta.weighted_eta(loss) + residual * loss.lambda_res,
            data,
            residual,
            ..eta
        }
    }

    /// η's logit ℓ = NN_ϕ(x) − offset at the rows of `x`, into `out`.
    fn eta_logits(&mut self, x: &[f32], out: &mut Vec<f32>) {
        let rows = x.len() / self.shape.input();
        eta_logits(
            &self.nets.eta,
            self.template.distance.eta_offset,
            x,
            rows,
            &mut self.work.eta_plain,
            out,
        );
    }
}

/// Cores one network's products split their rows over: the networks of a
/// step run side by side, about four at a time, so each gets its share
/// (on two cores, one: splitting a 128-row product costs more in waiting
/// than it saves).
fn tape_cores() -> usize {
    (rayon::current_num_threads() / 4).max(1)
}

/// Every network of `nets`, mutably.
fn nets_of(nets: &mut Nets) -> impl Iterator<Item = &mut TrainableMlp> {
    nets.named_mut().into_iter().map(|(_, net)| net)
}

fn eta_logits(
    eta: &TrainableMlp,
    offset: f32,
    x: &[f32],
    rows: usize,
    tape: &mut MlpTape,
    out: &mut Vec<f32>,
) {
    eta.forward(x, rows, tape);
    out.clear();
    out.extend(tape.output.iter().map(|d| d - offset));
}

/// Step k + 1's start on the particle path from step k (`noise` = (ε, k,
/// horizon)): mean + c·√var·ε.
fn particle_start(
    previous: &StepTape,
    (noise, k, horizon): (&[f32], usize, usize),
    state: usize,
    knobs: Knobs,
    out: &mut Vec<f32>,
) {
    out.clear();
    let rows = previous
        .mean
        .chunks_exact(state)
        .zip(previous.var.chunks_exact(state));
    for (r, (mean, var)) in rows.enumerate() {
        let eps = &noise[(r * horizon + k) * state..][..state];
        let next = mean.iter().zip(var).zip(eps);
        out.extend(next.map(|((m, v), e)| m + v.sqrt() * knobs.noise_scale * e));
    }
}

/// One window step forward from `tape.start`: its mean, Σ, var and err, each
/// network's tape; returns Σ over rows and dimensions of err²/var + log(var/scale²)
/// over the batch, and the mean ‖f_res‖².
fn forward_step(
    nets: &Nets,
    sh: &Shape,
    knobs: Knobs,
    tape: &mut StepTape,
    eta_tape: &mut MlpTape,
) -> (f64, f64) {
    let (obs, act, s_dim, d_in) = (sh.obs, sh.act, sh.state, sh.input());
    let (n_pos, n_vel) = (sh.n_pos, sh.n_vel);
    let rows = tape.start.len() / s_dim;
    let (phi, d_drift, g_columns) = (
        sh.features.width(),
        sh.drift_input(),
        sh.features.g_columns(),
    );
    for buffer in [
        &mut tape.x,
        &mut tape.x_drift,
        &mut tape.x_g,
        &mut tape.x_h,
        &mut tape.v_hat,
    ] {
        buffer.clear();
    }
    for r in 0..rows {
        let s = &tape.start[r * s_dim..r * s_dim + obs];
        let a = &tape.action[r * act..(r + 1) * act];
        let obs_hat = (0..obs).map(|i| (s[i] - sh.state_mean[i]) / sh.state_std[i]);
        let act_hat = (0..act).map(|j| (a[j] - sh.action_mean[j]) / sh.action_std[j]);
        tape.x.extend(obs_hat.chain(act_hat));
        sh.features.extend(s, &mut tape.x_drift);
        tape.x_drift
            .extend_from_slice(&tape.x[r * d_in + obs..(r + 1) * d_in]);
        let x_drift = &tape.x_drift[r * d_drift..];
        tape.x_g.extend_from_slice(&x_drift[g_columns.clone()]);
        tape.x_h.extend_from_slice(&x_drift[..phi]);
        let vel_std = &sh.state_std[n_pos..obs];
        let v = s[n_pos..obs].iter().zip(vel_std);
        tape.v_hat.extend(v.map(|(v, s)| v / s));
    }
    // The networks are independent: one task each, spread over the cores.
    let offset = knobs.eta_offset;
    let StepTape {
        x,
        x_drift,
        x_g,
        x_h,
        logit,
        g,
        h,
        res,
        reward,
        sigma,
        ..
    } = tape;
    let (x, x_drift, x_g, x_h) = (&*x, &*x_drift, &*x_g, &*x_h);
    rayon::scope(|scope| {
        scope.spawn(|_| nets.g.forward(x_g, rows, g));
        scope.spawn(|_| nets.h.forward(x_h, rows, h));
        scope.spawn(|_| nets.res.forward(x_drift, rows, res));
        if let Some(net) = &nets.reward {
            scope.spawn(|_| net.forward(x, rows, reward));
        }
        scope.spawn(|_| nets.sigma.forward(x, rows, sigma));
        scope.spawn(|_| eta_logits(&nets.eta, offset, x, rows, eta_tape, logit));
    });

    for buffer in [
        &mut tape.diffusion,
        &mut tape.mean,
        &mut tape.var,
        &mut tape.err,
    ] {
        buffer.resize(rows * s_dim, 0.0);
    }
    let (mut nll, mut residual) = (0.0f64, 0.0f64);
    for r in 0..rows {
        let row = r * s_dim..(r + 1) * s_dim;
        let s = &tape.start[row.clone()];
        let a = &tape.action[r * act..(r + 1) * act];
        let g = &tape.g.output[r * n_vel * act..][..n_vel * act];
        let h = &tape.h.output[r * n_vel * n_vel..][..n_vel * n_vel];
        let v_hat = &tape.v_hat[r * n_vel..(r + 1) * n_vel];
        let res = &tape.res.output[r * obs..(r + 1) * obs];
        let u = &tape.sigma.output[row.clone()];
        let h_gate = sigmoid(tape.logit[r] * knobs.h_weight + knobs.h_bias);
        for d in 0..s_dim {
            // eq. 8: f = [vel, G·a + H·v̂] + f_res; NUNO^R's reward drift last.
            let drift = if d < n_pos {
                s[sh.pairs[d]] + res[d] * sh.derivative[d]
            } else if d < obs {
                let i = d - n_pos;
                let g_a: f32 = (0..act).map(|j| g[i * act + j] * a[j]).sum();
                let h_v: f32 = (0..n_vel).map(|j| h[i * n_vel + j] * v_hat[j]).sum();
                (g_a + h_v) * sh.acceleration[i] + res[d] * sh.derivative[d]
            } else {
                tape.reward.output[r] * sh.reward_rate
            };
            let i = r * s_dim + d;
            tape.mean[i] = s[d] + drift * sh.dt;
            // eq. 5: Σ = σ + h(η).
            let sigma = (softplus(u[d]) + knobs.sigma_min) * sh.diffusion[d];
            tape.diffusion[i] = sigma + h_gate * sh.diffusion[d] * sh.w_max[d];
            tape.var[i] = tape.diffusion[i] * tape.diffusion[i] * sh.dt;
            tape.err[i] = tape.next[i] - tape.mean[i];
            let (e, v) = (tape.err[i], tape.var[i]);
            nll += f64::from(e * e / v + (v * sh.inv_scale2[d]).ln());
        }
        residual += res.iter().map(|v| f64::from(v * v)).sum::<f64>();
    }
    (nll / rows as f64, residual / rows as f64)
}

/// η's losses (eq. 3, 4, in `loss`'s form) and L_far at the data `x`
/// (`[B, obs + act]`), their gradient added to `grads`' η and μ.
#[allow(clippy::too_many_arguments)]
fn eta_losses(
    nets: &Nets,
    grads: &mut Nets,
    scratch: &mut Nets,
    sh: &Shape,
    knobs: Knobs,
    loss: &LossConfig,
    x: &[f32],
    draws: &StepDraws,
    work: &mut Work,
) -> StepLosses {
    let d_in = sh.input();
    let rows = x.len() / d_in;
    let samples = draws.ball_noise.len() / (rows * d_in);
    // η and ∇ₓd at the data, μ there, η at the ball's points.
    nets.eta.forward(x, rows, &mut work.eta_data);
    work.ones.clear();
    work.ones.resize(rows, 1.0);
    nets.eta
        .backward(&mut work.eta_data, &work.ones, None, Some(&mut work.grad_d));
    let mu = mu_forward(&nets.mu, x, rows, &mut work.mu);
    work.ball.clear();
    for (b, datum) in x.chunks_exact(d_in).enumerate() {
        for eps in draws.ball_noise[b * samples * d_in..][..samples * d_in].chunks_exact(d_in) {
            let point = datum.iter().zip(eps);
            work.ball.extend(point.map(|(x, e)| x + e * loss.radius));
        }
    }
    nets.eta
        .forward(&work.ball, rows * samples, &mut work.eta_ball);

    let (losses, d_grad, mu_grad) =
        eta_row_gradients(knobs, loss, &draws.ball_noise, &mu, d_in, work);
    nets.eta.backward(
        &mut work.eta_ball,
        &work.out_grad,
        Some(&mut scratch.eta),
        None,
    );
    accumulate(&mut grads.eta, &scratch.eta);
    nets.eta.backward_through_input_gradient(
        &mut work.eta_data,
        &d_grad,
        &work.q,
        &mut scratch.eta,
    );
    accumulate(&mut grads.eta, &scratch.eta);
    mu_backward(
        &nets.mu,
        (&mut grads.mu, &mut scratch.mu),
        &mut work.mu,
        &mu,
        &mu_grad,
    );
    let far = far_loss(nets, grads, scratch, knobs, loss, draws, work);
    StepLosses { far, ..losses }
}

/// η's losses datum by datum: their values (batch means), ∂L/∂d at the data
/// and ∂L/∂μ at each datum (returned), ∂L/∂∇d (`work.q`) and ∂L/∂d at the
/// ball's points (`work.out_grad`), from the forward values in `work`.
fn eta_row_gradients(
    knobs: Knobs,
    loss: &LossConfig,
    ball_noise: &[f32],
    mu: &[f32],
    d_in: usize,
    work: &mut Work,
) -> (StepLosses, Vec<f32>, Vec<f32>) {
    let rows = mu.len();
    let samples = ball_noise.len() / (rows * d_in);
    let (eta_max, offset, n) = (knobs.eta_max, knobs.eta_offset, rows as f32);
    let code = loss.eta_losses == EtaLossForm::Code;
    let kappa = loss.eta_losses.mu_factor();
    let sigmoid_at = |b: usize| sigmoid(work.eta_data.output[b] - offset);
    // ‖∇η‖² at each datum, ∇η = η_max·s(1 − s)·∇d; under the code form its batch
    // mean G below the floor adds −w·ln G, whose ∂/∂∇η is −(w/G)·2∇η/n.
    let grad2: Vec<f32> = (0..rows)
        .map(|b| {
            let s = sigmoid_at(b);
            let slope = eta_max * s * (1.0 - s);
            let grad_d = &work.grad_d[b * d_in..(b + 1) * d_in];
            grad_d.iter().map(|d| (slope * d).powi(2)).sum()
        })
        .collect();
    let mean_grad2 = grad2.iter().sum::<f32>() / n;
    let floor_on = code && mean_grad2 < loss.grad_floor;
    let floor_coef = if floor_on {
        loss.grad_floor_weight / mean_grad2
    } else {
        0.0
    };
    let grad_coef = 2.0 * (loss.lambda_grad - floor_coef) / n;

    let (mut sc, mut grad_loss, mut mu_loss, mut value, mut one) = (0f64, 0f64, 0f64, 0f64, 0f64);
    work.out_grad.resize(rows * samples, 0.0);
    work.q.resize(rows * d_in, 0.0);
    let mut d_grad = vec![0.0; rows];
    let mut mu_grad = vec![0.0; rows];
    for b in 0..rows {
        let s = sigmoid_at(b);
        let (eta, slope, mu) = (eta_max * s, eta_max * s * (1.0 - s), mu[b]);
        let grad_d = &work.grad_d[b * d_in..(b + 1) * d_in];
        // ∂/∂∇η from L_grad (and the floor); ∂/∂η and ∂/∂μ from the form's other terms.
        let g_grad_eta = &mut work.q[b * d_in..(b + 1) * d_in];
        for (g, d) in g_grad_eta.iter_mut().zip(grad_d) {
            *g = grad_coef * slope * d;
        }
        let (mut g_eta, mut g_mu) = if code {
            grad_loss += f64::from(grad2[b]);
            mu_loss += f64::from(1.0 / (mu * mu));
            value += f64::from(eta);
            (
                loss.lambda_value / n,
                -2.0 * loss.lambda_mu / (n * mu * mu * mu),
            )
        } else {
            grad_loss += f64::from(grad2[b] + eta * eta);
            mu_loss += f64::from(1.0 / mu);
            (
                loss.lambda_grad * 2.0 * eta / n,
                -loss.lambda_mu / (n * mu * mu),
            )
        };
        // L_sc: c = η(x + δ) − η(x) − ∇η·δ − κμ‖δ‖², Σ min(c, 0)² over the batch;
        // the code's set-one term (η(x + δ)/η_max − 1)² at the same points.
        for j in 0..samples {
            let ball = b * samples + j;
            let eps = &ball_noise[ball * d_in..(ball + 1) * d_in];
            let (mut linear, mut distance2) = (0.0f32, 0.0f32);
            for (e, d) in eps.iter().zip(grad_d) {
                let delta = e * loss.radius;
                linear += slope * d * delta;
                distance2 += delta * delta;
            }
            let s_near = sigmoid(work.eta_ball.output[ball] - offset);
            let eta_near = eta_max * s_near;
            let c = eta_near - eta - linear - kappa * mu * distance2;
            let w = if c < 0.0 {
                sc += f64::from(c * c);
                loss.lambda_sc * 2.0 * c / n
            } else {
                0.0
            };
            let mut g_near = w;
            if code {
                let miss = eta_near / eta_max - 1.0;
                one += f64::from(miss * miss);
                g_near += loss.lambda_one * 2.0 * miss / (eta_max * n * samples as f32);
            }
            work.out_grad[ball] = g_near * eta_max * s_near * (1.0 - s_near);
            g_eta -= w;
            g_mu -= w * kappa * distance2;
            for (g, e) in g_grad_eta.iter_mut().zip(eps) {
                *g -= w * e * loss.radius;
            }
        }
        // Through η = η_max·s and ∇η = η_max·s(1 − s)·∇d to d and ∇d.
        let along: f32 = g_grad_eta.iter().zip(grad_d).map(|(g, d)| g * d).sum();
        d_grad[b] = g_eta * slope + along * slope * (1.0 - 2.0 * s);
        g_grad_eta.iter_mut().for_each(|g| *g *= slope);
        mu_grad[b] = g_mu;
    }
    let mean = |sum: f64, count: f32| (sum / f64::from(count)) as f32;
    let losses = StepLosses {
        sc: mean(sc, n),
        grad: mean(grad_loss, n),
        mu: mean(mu_loss, n),
        value: mean(value, n),
        one: mean(one, n * samples as f32),
        floor: if floor_on {
            -loss.grad_floor_weight * mean_grad2.ln()
        } else {
            0.0
        },
        ..StepLosses::default()
    };
    (losses, d_grad, mu_grad)
}

/// μ at each of the `rows` of `x`: exp of its network's output (its forward
/// values in `tape`), or the scalar form's one |100·p|.
fn mu_forward(mu: &MuParams, x: &[f32], rows: usize, tape: &mut MlpTape) -> Vec<f32> {
    match mu {
        MuParams::Network(net) => {
            net.forward(x, rows, tape);
            tape.output.iter().map(|o| o.exp()).collect()
        }
        MuParams::Scalar(p) => vec![(SCALAR_MU_FACTOR * p).abs(); rows],
    }
}

/// ∂L/∂μ at each datum (`mu_grad`, μ's `values` there) into the gradient of
/// μ's parameters (`grads`: the total and a scratch of the same form).
fn mu_backward(
    mu: &MuParams,
    (grads, scratch): (&mut MuParams, &mut MuParams),
    tape: &mut MlpTape,
    values: &[f32],
    mu_grad: &[f32],
) {
    match (mu, grads, scratch) {
        (MuParams::Network(net), MuParams::Network(total), MuParams::Network(part)) => {
            // μ = exp(NN): ∂μ/∂NN = μ.
            let out: Vec<f32> = mu_grad.iter().zip(values).map(|(g, m)| g * m).collect();
            net.backward(tape, &out, Some(part), None);
            accumulate(total, part);
        }
        (MuParams::Scalar(p), MuParams::Scalar(total), _) => {
            // μ = |F·p|: ∂μ/∂p = F·sign(p).
            *total = mu_grad.iter().sum::<f32>() * SCALAR_MU_FACTOR * p.signum();
        }
        _ => unreachable!("μ's gradients take the form of its parameters"),
    }
}

/// L_far on η's logit at the far points, its gradient added to `grads`' η.
fn far_loss(
    nets: &Nets,
    grads: &mut Nets,
    scratch: &mut Nets,
    knobs: Knobs,
    loss: &LossConfig,
    draws: &StepDraws,
    work: &mut Work,
) -> f32 {
    let far_rows = draws.far_mask.len();
    nets.eta
        .forward(&draws.far_points, far_rows, &mut work.eta_far);
    let target = (loss.far_target / (1.0 - loss.far_target)).ln();
    let mut far = 0.0f64;
    work.out_grad.resize(far_rows, 0.0);
    for (i, mask) in draws.far_mask.iter().enumerate() {
        let shortfall = (target - (work.eta_far.output[i] - knobs.eta_offset)).max(0.0);
        far += f64::from(shortfall * shortfall * mask);
        work.out_grad[i] = -loss.lambda_far * 2.0 * shortfall * mask / far_rows as f32;
    }
    if loss.lambda_far > 0.0 {
        let g = &work.out_grad[..far_rows];
        nets.eta
            .backward(&mut work.eta_far, g, Some(&mut scratch.eta), None);
        accumulate(&mut grads.eta, &scratch.eta);
    }
    (far / far_rows.max(1) as f64) as f32
}

/// One window step's backward pass: L_data's (times `coef` = λ_data·w_k/B) and
/// the residual penalty's (`res_coef` = λ_res/(B·H)) gradient into `grads`;
/// with `noise` (ε, k, H), the next step's start gradient
/// (`work.next_start_grad`) too; with `wants_start`, this step's start
/// gradient into `work.start_grad`.
#[allow(clippy::too_many_arguments)]
fn backward_step(
    nets: &Nets,
    grads: &mut Nets,
    scratch: &mut Nets,
    sh: &Shape,
    knobs: Knobs,
    tape: &mut StepTape,
    work: &mut Work,
    (coef, res_coef): (f32, f32),
    noise: Option<(&[f32], usize, usize)>,
    wants_start: bool,
) {
    let (obs, act, s_dim, d_in) = (sh.obs, sh.act, sh.state, sh.input());
    let (n_pos, n_vel) = (sh.n_pos, sh.n_vel);
    let rows = tape.start.len() / s_dim;
    let out = &mut work.step;
    out.g.resize(rows * n_vel * act, 0.0);
    out.h.resize(rows * n_vel * n_vel, 0.0);
    out.res.resize(rows * obs, 0.0);
    out.reward.resize(rows, 0.0);
    out.sigma.resize(rows * s_dim, 0.0);
    let start_grad = &mut work.start_grad;
    start_grad.resize(rows * s_dim, 0.0);
    let mut drift_grad = vec![0.0; s_dim];
    for r in 0..rows {
        let row = r * s_dim..(r + 1) * s_dim;
        // ∂/∂mean and ∂/∂Σ of err²/var + log var, var = Σ²·dt; the next start's.
        for d in 0..s_dim {
            let i = r * s_dim + d;
            let (e, v, sigma) = (tape.err[i], tape.var[i], tape.diffusion[i]);
            let mut g_mean = coef * (-2.0 * e / v);
            let mut g_diffusion = coef * (2.0 / sigma) * (1.0 - e * e / v);
            if let Some((eps, k, horizon)) = noise {
                let g_next = work.next_start_grad[i];
                let eps = eps[(r * horizon + k) * s_dim + d];
                g_mean += g_next;
                // ∂√var/∂Σ = Σ·dt/√var.
                g_diffusion += g_next * knobs.noise_scale * eps * sigma * sh.dt / v.sqrt();
            }
            start_grad[i] = g_mean;
            drift_grad[d] = g_mean * sh.dt;
            // σ = (softplus(u) + σ_min)·scale; softplus' = sigmoid.
            out.sigma[i] = g_diffusion * sh.diffusion[d] * sigmoid(tape.sigma.output[i]);
        }
        let a = &tape.action[r * act..(r + 1) * act];
        let v_hat = &tape.v_hat[r * n_vel..(r + 1) * n_vel];
        let h = &tape.h.output[r * n_vel * n_vel..][..n_vel * n_vel];
        let start = &mut start_grad[row];
        let res = &tape.res.output[r * obs..(r + 1) * obs];
        let res_grad = out.res[r * obs..(r + 1) * obs].iter_mut();
        for (((g, drift), scale), res) in res_grad.zip(&drift_grad).zip(&sh.derivative).zip(res) {
            *g = drift * scale + res_coef * 2.0 * res;
        }
        for (d, &velocity) in sh.pairs.iter().enumerate() {
            start[velocity] += drift_grad[d];
        }
        for i in 0..n_vel {
            let q = drift_grad[n_pos + i] * sh.acceleration[i];
            let g_grad = &mut out.g[(r * n_vel + i) * act..][..act];
            g_grad.iter_mut().zip(a).for_each(|(g, a)| *g = q * a);
            for j in 0..n_vel {
                out.h[(r * n_vel + i) * n_vel + j] = q * v_hat[j];
                start[n_pos + j] += q * h[i * n_vel + j] / sh.state_std[n_pos + j];
            }
        }
        if s_dim > obs {
            out.reward[r] = drift_grad[obs] * sh.reward_rate;
        }
    }

    // Through the networks, one task each; their input gradients then into the
    // start's, when asked: the drift's through φ(s), σ's and f_rew's through
    // the normalised (s, a).
    let (phi, d_drift) = (sh.features.width(), sh.drift_input());
    let tapes = [
        (&mut tape.g, &out.g[..], (true, sh.features.g_columns())),
        (&mut tape.h, &out.h[..], (true, 0..phi)),
        (&mut tape.res, &out.res[..], (true, 0..d_drift)),
        (&mut tape.reward, &out.reward[..], (false, 0..d_in)),
        (&mut tape.sigma, &out.sigma[..], (false, 0..d_in)),
    ];
    let mut jobs: Vec<_> = nets
        .nets()
        .into_iter()
        .zip(grads.nets_mut())
        .zip(scratch.nets_mut())
        .zip(tapes)
        .zip(&mut out.inputs)
        .filter_map(
            |((((net, grads), scratch), (tape, out_grad, columns)), input)| {
                Some((net?, grads?, scratch?, tape, out_grad, columns, input))
            },
        )
        .collect();
    rayon::scope(|scope| {
        for (net, grads, scratch, tape, out_grad, _, input) in &mut jobs {
            scope.spawn(move |_| {
                let input = wants_start.then_some(&mut **input);
                net.backward(tape, out_grad, Some(&mut **scratch), input);
                accumulate(grads, scratch);
            });
        }
    });
    if !wants_start {
        return;
    }
    work.x_grad.clear();
    work.x_grad.resize(rows * d_in, 0.0);
    work.x_drift_grad.clear();
    work.x_drift_grad.resize(rows * d_drift, 0.0);
    for (.., (drift, columns), input) in &jobs {
        let (target, stride) = if *drift {
            (&mut work.x_drift_grad, d_drift)
        } else {
            (&mut work.x_grad, d_in)
        };
        let width = columns.len();
        for (r, g) in input.chunks_exact(width).enumerate() {
            let x = &mut target[r * stride + columns.start..][..width];
            x.iter_mut().zip(g).for_each(|(x, g)| *x += g);
        }
    }
    let rows = start_grad
        .chunks_exact_mut(s_dim)
        .zip(tape.start.chunks_exact(s_dim))
        .zip(work.x_grad.chunks_exact(d_in))
        .zip(work.x_drift_grad.chunks_exact(d_drift));
    for (((start_grad, start), x), x_drift) in rows {
        for i in 0..obs {
            start_grad[i] += x[i] / sh.state_std[i];
        }
        sh.features
            .add_gradient(&start[..obs], &x_drift[..phi], start_grad);
    }
}

impl SdeTrainer for FusedSdeTrainer {
    #[cfg(test)]
    fn gradients(&mut self, draws: &StepDraws) -> (StepLosses, super::fit_step::Gradients) {
        let losses = self.loss_and_gradient(draws);
        let mut gradients = super::fit_step::Gradients::new();
        for (prefix, net) in self.grads.named_mut() {
            for (i, layer) in net.layers.iter().enumerate() {
                gradients.insert(format!("{prefix}.layers.{i}.weight"), layer.weight.clone());
                gradients.insert(format!("{prefix}.layers.{i}.bias"), layer.bias.clone());
            }
        }
        if let MuParams::Scalar(g) = self.grads.mu {
            gradients.insert(MU_SCALAR_PATH.to_string(), vec![g]);
        }
        (losses, gradients)
    }

    fn step(&mut self, draws: &StepDraws, lr: f64) -> StepLosses {
        let losses = self.loss_and_gradient(draws);
        let settings = &self.settings;
        let step = settings.adam.begin(&mut self.state, lr);
        let mut update = |path: String, values: &mut [f32], grad: &mut [f32]| {
            clip_to_norm(grad, settings.clip_norm);
            let step = step.at_rate(settings.rate(&path, lr));
            let moments = self.state.moments.entry(path).or_default();
            settings.adam.update(step, values, grad, moments);
        };
        let pairs = self
            .nets
            .named_mut()
            .into_iter()
            .zip(self.grads.named_mut());
        for ((prefix, net), (_, grads)) in pairs {
            for (i, (layer, grad)) in net.layers.iter_mut().zip(&mut grads.layers).enumerate() {
                update(
                    format!("{prefix}.layers.{i}.weight"),
                    &mut layer.weight,
                    &mut grad.weight,
                );
                update(
                    format!("{prefix}.layers.{i}.bias"),
                    &mut layer.bias,
                    &mut grad.bias,
                );
            }
        }
        if let (MuParams::Scalar(p), MuParams::Scalar(g)) = (&mut self.nets.mu, &mut self.grads.mu)
        {
            update(
                MU_SCALAR_PATH.to_string(),
                std::slice::from_mut(p),
                std::slice::from_mut(g),
            );
        }
        losses
    }

    fn calibrate_h_bias(&mut self, reference: &[f32]) {
        let mut logits = Vec::new();
        self.eta_logits(reference, &mut logits);
        let config = &mut self.template.constants.config;
        if let Some(bias) = config.calibrated_h_bias(logits) {
            config.h_bias = bias;
        }
    }

    fn model(&self) -> NeuralSde {
        self.nets.write_to(self.template.clone())
    }

    fn optimizer_state(&self) -> AdamState {
        self.state.clone()
    }

    fn restore(&mut self, current: &NeuralSde, adam: AdamState) {
        self.nets = Nets::of(current);
        self.template.constants = current.constants.clone();
        self.state = adam;
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use burn::module::Module;
    use burn::tensor::Device;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::StandardNormal;

    use super::*;
    use crate::data::{Dataset, DatasetParts, NormalizerConfig, WindowSampler};
    use crate::envs::{Joint, JointKind, StateSplit};
    use crate::nn::{seeded_init, standard_normal};
    use crate::sde::eta::FarField;
    use crate::sde::fit_step::{BurnSdeTrainer, Gradients};
    use crate::sde::{DriftInputs, DynamicsSpec, FitConfig, PhysicalScales, SdeConfig};

    const NQ: usize = 4;
    const ACT: usize = 2;
    const DT: f32 = 0.01;

    /// A planar system of NQ joints (D4RL layout: root x dropped) whose
    /// positions follow their velocities and whose velocities wander.
    fn dataset(rows: usize, seed: u64) -> (DynamicsSpec, Dataset) {
        // Root x and z slide, the rest hinge; root x is not observed.
        let joints: Vec<Joint> = (0..NQ)
            .map(|i| Joint {
                kind: if i < 2 {
                    JointKind::Slide
                } else {
                    JointKind::Hinge
                },
                qpos: i,
                dof: i,
            })
            .collect();
        let split = StateSplit::of_joints(&joints, NQ, NQ, 1);
        let obs_dim = split.obs_dim();
        let spec = DynamicsSpec {
            obs_dim,
            act_dim: ACT,
            split: split.clone(),
            dt: f64::from(DT),
        };
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut normal = || rng.sample::<f32, _>(StandardNormal);
        let (mut obs, mut next, mut act) = (Vec::new(), Vec::new(), Vec::new());
        let mut state: Vec<f32> = (0..obs_dim).map(|_| normal()).collect();
        for _ in 0..rows {
            let action: Vec<f32> = (0..ACT).map(|_| normal().tanh()).collect();
            let mut following = state.clone();
            for (p, &v) in split.position_velocity.iter().enumerate() {
                following[p] += state[v] * DT + 0.001 * normal();
            }
            for v in split.velocities.iter().copied() {
                following[v] += (action[v % ACT] - 0.5 * state[v]) * DT * 20.0 + 0.05 * normal();
            }
            obs.extend_from_slice(&state);
            act.extend(action);
            next.extend_from_slice(&following);
            state = following;
        }
        let mut timeouts = vec![false; rows];
        timeouts[rows - 1] = true;
        let parts = DatasetParts {
            observations: ndarray::Array2::from_shape_vec((rows, obs_dim), obs).unwrap(),
            actions: ndarray::Array2::from_shape_vec((rows, ACT), act).unwrap(),
            rewards: ndarray::Array1::from_shape_fn(rows, |i| (i as f32 * 0.1).sin()),
            next_observations: ndarray::Array2::from_shape_vec((rows, obs_dim), next).unwrap(),
            terminals: vec![false; rows],
            timeouts,
            qpos: None,
            qvel: None,
            action_log_probs: None,
            metadata: Default::default(),
        };
        (
            spec,
            Dataset::from_parts(parts, Path::new("planar")).unwrap(),
        )
    }

    /// A small fit config: narrow networks, both ways of η's far field on.
    fn config(reward_model: bool, path: LikelihoodPath) -> FitConfig {
        let mut model = SdeConfig::new();
        model.drift_hidden = vec![32, 32];
        model.sigma_hidden = vec![32];
        model.reward_hidden = vec![16];
        model.eta_hidden = vec![16, 16];
        model.mu_hidden = vec![8, 8];
        model.reward_model = reward_model;
        model.sample_noise_scale = 0.7;
        let mut config = FitConfig::new(model, crate::sde::LossConfig::new());
        config.loss.likelihood = path;
        config.loss.step_discount = 0.9;
        config.loss.lambda_far = 0.05;
        // η mid-sigmoid and L_grad heavy, so that every term of η's gradient counts.
        config.model.eta_offset = 1.0;
        config.loss.lambda_grad = 1.0;
        config.batch_size = 16;
        config.loss.convexity_samples = 5;
        config
    }

    /// Both trainers on one model, and one step's draws.
    fn trainers(config: &FitConfig, seed: u64) -> (BurnSdeTrainer, FusedSdeTrainer, StepDraws) {
        let (spec, data) = dataset(400, seed);
        let scales = PhysicalScales::measure(&data, &spec, &NormalizerConfig { std_floor: 1e-3 });
        let device = Device::flex().autodiff();
        let mut model = seeded_init(&device, seed, || {
            NeuralSde::init(spec.clone(), scales, config.model.clone(), &device)
        });
        model.constants.config.h_bias = -1.0;
        let mut rng = ChaCha8Rng::seed_from_u64(seed + 1);
        let windows = WindowSampler::new(&data, config.horizon)
            .unwrap()
            .sample(config.batch_size, &mut rng);
        let d_in = spec.obs_dim + spec.act_dim;
        let state_dim = model.constants.state_dim();
        let reference: Vec<f32> = standard_normal(64 * d_in, &mut rng);
        let far = FarField::new(reference, d_in, &config.loss);
        let (far_points, far_mask) = far.sample_values(config.batch_size, &mut rng);
        let draws = StepDraws {
            windows,
            step_noise: standard_normal(config.batch_size * config.horizon * state_dim, &mut rng),
            ball_noise: standard_normal(
                config.batch_size * config.loss.convexity_samples * d_in,
                &mut rng,
            ),
            far_points,
            far_mask,
        };
        let settings = StepSettings::of(config);
        let fused = FusedSdeTrainer::new(model.valid(), settings.clone());
        (BurnSdeTrainer::new(model, settings, device), fused, draws)
    }

    /// One gradient tensor against burn's: ‖fused − burn‖ ≤ 1e-5·‖burn‖ (L2),
    /// or every element within 1e-6. Per element, relative errors of f32 sums
    /// grow where terms cancel (on the particle path a few elements of σ's
    /// gradient differ by 1e-3 of themselves from burn's, while the tensor
    /// agrees to 1e-6), so the tensor, not the element, is what is compared.
    fn assert_close(name: &str, fused: &[f32], burn: &[f32]) {
        assert_eq!(fused.len(), burn.len(), "{name}: sizes");
        let norm = |v: &mut dyn Iterator<Item = f32>| v.map(|x| x * x).sum::<f32>().sqrt();
        let difference = norm(&mut fused.iter().zip(burn).map(|(f, b)| f - b));
        let largest = fused
            .iter()
            .zip(burn)
            .map(|(f, b)| (f - b).abs())
            .fold(0.0, f32::max);
        let scale = norm(&mut burn.iter().copied());
        assert!(
            difference <= 1e-5 * scale || largest <= 1e-6,
            "{name}: ‖fused − burn‖ = {difference:e} against ‖burn‖ = {scale:e} (largest \
             element difference {largest:e})"
        );
    }

    fn assert_gradients_match(config: &FitConfig) {
        let (mut burn, mut fused, draws) = trainers(config, 3);
        let (burn_losses, burn_grads) = burn.gradients(&draws);
        let (fused_losses, fused_grads) = fused.gradients(&draws);
        assert!(burn_losses.sc > 0.0, "L_sc's hinge should be active");
        assert!(burn_losses.far > 0.0, "L_far should be active");
        let losses = |l: StepLosses| {
            [
                l.total, l.data, l.sc, l.grad, l.mu, l.far, l.residual, l.value, l.one, l.floor,
            ]
        };
        for (f, b) in losses(fused_losses).iter().zip(losses(burn_losses)) {
            assert!(
                (f - b).abs() <= 1e-5 * b.abs(),
                "losses: fused {fused_losses:?}, burn {burn_losses:?}"
            );
        }
        let keys = |g: &Gradients| g.keys().cloned().collect::<Vec<_>>();
        assert_eq!(keys(&fused_grads), keys(&burn_grads));
        for (path, burn) in &burn_grads {
            assert_close(path, &fused_grads[path], burn);
        }
    }

    #[test]
    fn gradients_equal_burns_on_the_particle_path() {
        assert_gradients_match(&config(false, LikelihoodPath::Particle));
    }

    #[test]
    fn gradients_equal_burns_with_the_reward_model_on_the_data_path() {
        assert_gradients_match(&config(true, LikelihoodPath::Data));
    }

    #[test]
    fn gradients_equal_burns_with_pose_drift_inputs() {
        // The particle path carries gradients through step 2's start into φ's
        // cos and sin of step 1's sampled angles.
        let mut config = config(false, LikelihoodPath::Particle);
        config.model.drift_inputs = DriftInputs::Pose;
        let (burn, ..) = trainers(&config, 3);
        let angles = burn.model().spec().split.angles.len();
        assert!(angles >= 2, "the planar test system has angles");
        let g_inputs = burn.model().g_net.layers[0].weight.dims()[0];
        assert_eq!(g_inputs, 2 * NQ - 1 + angles, "G sees all of φ");
        assert_gradients_match(&config);
    }

    /// NUNO's code's η losses (D5): the scalar μ, ½μ in L_sc, the value and
    /// set-one terms, and the gradient floor (forced on by a floor above ‖∇η‖²).
    fn code_config() -> FitConfig {
        let mut config = config(false, LikelihoodPath::Particle);
        EtaLossForm::Code.apply_to_fit(&mut config);
        config.loss.lambda_grad = 1.0;
        config.loss.lambda_value = 0.3;
        config.loss.lambda_one = 0.2;
        config.loss.grad_floor = 1e6;
        config.loss.grad_floor_weight = 0.01;
        config
    }

    #[test]
    fn gradients_equal_burns_with_the_codes_eta_losses() {
        let config = code_config();
        let (mut burn, _, draws) = trainers(&config, 3);
        let (losses, grads) = burn.gradients(&draws);
        assert!(losses.value > 0.0 && losses.one > 0.0 && losses.floor != 0.0);
        assert!(
            grads.contains_key(MU_SCALAR_PATH)
                && !grads.contains_key("distance.mu_net.layers.0.weight")
        );
        assert_gradients_match(&config);
    }

    #[test]
    fn eta_steps_at_its_own_rate() {
        // Adam's first step moves every parameter by ≈ its rate (m̂/√v̂ = ±1), so
        // p of μ = |100·p| (from 1) moves by η's 1e-3 while the fit's rate is 0.1.
        let config = code_config();
        let (mut burn, mut fused, draws) = trainers(&config, 3);
        for trainer in [&mut burn as &mut dyn SdeTrainer, &mut fused] {
            let before = trainer.model();
            trainer.step(&draws, 0.1);
            let after = trainer.model();
            let p = |m: &NeuralSde| to_f32_vec(m.distance.mu_scalar.as_ref().unwrap().val())[0];
            assert!(((p(&after) - p(&before)).abs() - 1e-3).abs() < 1e-5);
            let bias = |m: &NeuralSde| to_f32_vec(m.g_net.layers[0].bias.as_ref().unwrap().val());
            let moved = bias(&after)
                .iter()
                .zip(bias(&before))
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f32::max);
            assert!((moved - 0.1).abs() < 1e-3, "G's bias moved by {moved}");
        }
    }
}
