//! SAC's update, the same as [`Sac::update`], on plain `f32` buffers: the actor
//! and the critics (SAC's twin, EDAC's N) as [`TrainableMlp`]s (each product one
//! `gemm` over the batch, the critics side by side on the cores), the
//! tanh-Gaussian's gradient written out, and Adam from
//! [`crate::nn::Adam`], the one both kernels step with. A [`FusedSac`] starts
//! from a burn [`Sac`] and writes back into it, so the policy loop, evaluation
//! and checkpoints see one agent whichever kernel trains it.

use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use super::actor::{Actor, tanh_gaussian_log_density};
use super::critic::Temperature;
use super::sac::{CriticBackup, Sac, SacAdam, SacConfig, SacLosses};
use crate::infer::{MlpTape, TrainableMlp};
use crate::nn::{Adam, AdamState, AdamStep, Mlp, fill_standard_normal, to_f32_vec};
use crate::shared::LoggedActions;
use crate::shared::TransitionBatch;

mod conservative;
mod diversity;

/// The agent's networks, temperature and Adam state as host buffers.
pub struct FusedSac {
    obs_dim: usize,
    act_dim: usize,
    gamma: f32,
    /// The critic target's form where it is not SAC's (MOBILE).
    backup: Option<CriticBackup>,
    tau: f64,
    lr: (f64, f64, f64),
    target_entropy: f32,
    log_std: (f32, f32),
    /// The action box: a = centre + half·tanh(u).
    half: Vec<f32>,
    center: Vec<f32>,
    log_half_sum: f32,
    adam: Adam,
    actor: TrainableMlp,
    critics: Vec<Critic>,
    log_alpha: f32,
    state: SacAdam,
    work: Workspace,
}

/// What [`FusedSac::from_parts`] reads of a burn agent besides its critics.
struct Agent<'a> {
    actor: &'a Actor,
    config: &'a SacConfig,
    target_entropy: f64,
    temperature: &'a Temperature,
    /// The optimiser with the agent's ε, and its state.
    adam: (Adam, &'a SacAdam),
}

/// The losses of an update's actor and α steps.
struct PolicySteps {
    actor_loss: f32,
    alpha_loss: f32,
    entropy: f32,
}

impl PolicySteps {
    /// The update's losses: these, α as the actor read it, and the critics'.
    fn with(self, alpha: f32, critic: SacLosses) -> SacLosses {
        SacLosses {
            actor_loss: self.actor_loss,
            alpha,
            alpha_loss: self.alpha_loss,
            entropy: self.entropy,
            ..critic
        }
    }
}

/// One critic Q_j, its target Q̄_j and the buffers its passes reuse.
struct Critic {
    /// Its burn module's path (`q1`, `q2`; EDAC's `members.j`): its Adam moments' prefix.
    path: String,
    net: TrainableMlp,
    target: TrainableMlp,
    tape: MlpTape,
    grads: TrainableMlp,
    /// ∂L/∂Q per row, and ∂L/∂[s, a] where a pass wants it.
    grad_q: Vec<f32>,
    grad_input: Vec<f32>,
    /// ∂L/∂(∂Q/∂[s, a]) where a loss reads the input gradient (EDAC's ES).
    upstream: Vec<f32>,
}

impl Critic {
    /// `(path, Q_j, Q̄_j)` of every critic, the cores shared out among them.
    fn all(nets: Vec<(String, TrainableMlp, TrainableMlp)>) -> Vec<Self> {
        let (cores, n) = (rayon::current_num_threads(), nets.len().max(1));
        (nets.into_iter().enumerate())
            .map(|(j, (path, net, target))| Self {
                path,
                tape: MlpTape::on_cores((cores / n + usize::from(j < cores % n)).max(1)),
                grads: net.zeros_like(),
                net,
                target,
                grad_q: Vec::new(),
                grad_input: Vec::new(),
                upstream: Vec::new(),
            })
            .collect()
    }
}

/// Buffers reused by every update.
struct Workspace {
    actor_tape: MlpTape,
    actor_grads: TrainableMlp,
    noise: Vec<f32>,
    sample: Sample,
    critic_input: Vec<f32>,
    y: Vec<f32>,
    grad_action: Vec<f32>,
    grad_actor: Vec<f32>,
    /// The conservative term's states repeated N times ([s; s']) and its uniform actions.
    repeated: Vec<f32>,
    uniform: Vec<f32>,
}

/// ã ~ π(·|s) for a batch, and what its gradient needs.
#[derive(Default)]
struct Sample {
    action: Vec<f32>,
    log_prob: Vec<f32>,
    /// tanh(u)
    squashed: Vec<f32>,
    /// σ = exp(clamped log σ)
    std: Vec<f32>,
    /// Whether log σ lay inside its clamp (else its gradient is 0).
    inside: Vec<bool>,
}

/// Gradients of one loss, by network, as [`FusedSac::gradients`] returns them.
#[derive(Debug, Clone, PartialEq)]
pub struct FusedGradients {
    /// Each critic's, in order (SAC: Q₁, Q₂).
    pub critics: Vec<TrainableMlp>,
    pub actor: TrainableMlp,
    pub log_alpha: f32,
}

impl FusedSac {
    /// The state of `sac` (networks, temperature, Adam) on host buffers.
    pub fn from_sac(sac: &Sac) -> Self {
        let critics = vec![
            critic_pair("q1", &sac.critic.q1, &sac.target_critic.q1),
            critic_pair("q2", &sac.critic.q2, &sac.target_critic.q2),
        ];
        let agent = Agent {
            actor: &sac.actor,
            config: &sac.config,
            target_entropy: sac.target_entropy,
            temperature: &sac.temperature,
            adam: (sac.optimizer(), &sac.adam),
        };
        Self::from_parts(agent, critics)
    }

    /// The host buffers of `agent` with `critics`' `(path, Q_j, Q̄_j)`.
    fn from_parts(agent: Agent, critics: Vec<(String, TrainableMlp, TrainableMlp)>) -> Self {
        let (config, c) = (agent.config, &agent.actor.config);
        let (half, center) = c.box_half_center();
        let actor = TrainableMlp::from_burn(&agent.actor.net);
        let work = Workspace {
            // The actor runs alone on every core, the critics side by side.
            actor_tape: MlpTape::on_cores(rayon::current_num_threads()),
            actor_grads: actor.zeros_like(),
            noise: Vec::new(),
            sample: Sample::default(),
            critic_input: Vec::new(),
            y: Vec::new(),
            grad_action: Vec::new(),
            grad_actor: Vec::new(),
            repeated: Vec::new(),
            uniform: Vec::new(),
        };
        Self {
            obs_dim: c.obs_dim,
            act_dim: c.act_dim,
            gamma: config.gamma as f32,
            backup: config.backup,
            tau: config.tau,
            lr: (config.critic_lr, config.actor_lr, config.alpha_lr),
            target_entropy: agent.target_entropy as f32,
            log_std: (c.log_std_min, c.log_std_max),
            log_half_sum: half.iter().map(|h| h.ln()).sum(),
            half,
            center,
            adam: agent.adam.0,
            actor,
            critics: Critic::all(critics),
            log_alpha: to_f32_vec(agent.temperature.log_alpha.val())[0],
            state: agent.adam.1.clone(),
            work,
        }
    }

    /// Writes every network, the temperature and the Adam state into `sac`.
    pub fn write_to(&self, sac: &mut Sac) {
        self.write_actor_to(sac);
        let [q1, q2] = [&self.critics[0], &self.critics[1]];
        sac.critic.q1 = q1.net.write_to(sac.critic.q1.clone());
        sac.critic.q2 = q2.net.write_to(sac.critic.q2.clone());
        sac.target_critic.q1 = q1.target.write_to(sac.target_critic.q1.clone());
        sac.target_critic.q2 = q2.target.write_to(sac.target_critic.q2.clone());
        sac.temperature = sac.temperature.with_log_alpha(self.log_alpha);
        sac.adam = self.state.clone();
    }

    /// Writes the actor alone (what rollouts need) into `sac`.
    pub fn write_actor_to(&self, sac: &mut Sac) {
        sac.actor.net = self.actor.write_to(sac.actor.net.clone());
    }

    /// One SAC update on `batch`, drawing ε from `rng` exactly as [`Sac::update`] does.
    pub fn update(&mut self, batch: &TransitionBatch, rng: &mut ChaCha8Rng) -> SacLosses {
        // On a worker thread of the pool, each join below queues one half
        // where the other worker takes it; from outside the pool, every join
        // would hand both halves over and put this thread to sleep (measured
        // 10–15 % slower).
        rayon::scope(|_| self.update_on_pool(batch, rng))
    }

    fn update_on_pool(&mut self, batch: &TransitionBatch, rng: &mut ChaCha8Rng) -> SacLosses {
        let b = batch.rewards.len();
        let alpha = self.log_alpha.exp();
        fill_standard_normal(&mut self.work.noise, b * self.act_dim, rng);
        self.critic_target(batch, alpha, self.backup);
        let critic = self.critic_gradients(batch);
        self.step_critics();

        // Actor step, through the updated critics, then the temperature's.
        let policy = self.policy_steps(&batch.observations, alpha, rng);
        self.update_targets();
        policy.with(alpha, critic)
    }

    /// The policy's half of an update: ε from `rng`, the actor's gradient
    /// through the critics as they are at α `alpha`, its Adam step, then α's.
    fn policy_steps(
        &mut self,
        observations: &[f32],
        alpha: f32,
        rng: &mut ChaCha8Rng,
    ) -> PolicySteps {
        let b = observations.len() / self.obs_dim;
        fill_standard_normal(&mut self.work.noise, b * self.act_dim, rng);
        let actor_loss = self.actor_gradients(observations, alpha);
        self.step_actor();
        let (alpha_loss, entropy) = self.step_alpha();
        PolicySteps {
            actor_loss,
            alpha_loss,
            entropy,
        }
    }

    /// One Adam step of every critic on its `grads`.
    fn step_critics(&mut self) {
        let step = self.adam.begin(&mut self.state.critic, self.lr.0);
        let state = &mut self.state.critic;
        for c in &mut self.critics {
            step_network(&self.adam, step, state, &c.path, &mut c.net, &c.grads);
        }
    }

    /// One Adam step of the actor on `work.actor_grads`.
    fn step_actor(&mut self) {
        let step = self.adam.begin(&mut self.state.actor, self.lr.1);
        let (actor, grads) = (&mut self.actor, &self.work.actor_grads);
        step_network(&self.adam, step, &mut self.state.actor, "net", actor, grads);
    }

    /// One Adam step of log α on the actor step's sample; returns (L_α, the entropy estimate).
    fn step_alpha(&mut self) -> (f32, f32) {
        let (alpha_loss, alpha_grad, entropy) = self.alpha_gradient();
        let mut log_alpha = [self.log_alpha];
        let step = self.adam.begin(&mut self.state.alpha, self.lr.2);
        let moments = self
            .state
            .alpha
            .moments
            .entry("log_alpha".into())
            .or_default();
        self.adam
            .update(step, &mut log_alpha, &[alpha_grad], moments);
        self.log_alpha = log_alpha[0];
        (alpha_loss, entropy)
    }

    /// Targets: Q̄ ← τ·Q + (1 − τ)·Q̄, with burn's f32 factors.
    fn update_targets(&mut self) {
        let (tau, keep) = (self.tau as f32, (1.0 - self.tau) as f32);
        for c in &mut self.critics {
            for (_, target, online) in c.target.params_with(&c.net) {
                for (t, o) in target.iter_mut().zip(online) {
                    *t = o * tau + *t * keep;
                }
            }
        }
    }

    /// Every gradient of one update's three losses at the current weights
    /// (the actor's through the current critics, not the stepped ones), with
    /// ε drawn as [`FusedSac::update`] draws it: what the kernel-equivalence
    /// tests compare with burn's autodiff.
    pub fn gradients(&mut self, batch: &TransitionBatch, rng: &mut ChaCha8Rng) -> FusedGradients {
        let b = batch.rewards.len();
        let alpha = self.log_alpha.exp();
        fill_standard_normal(&mut self.work.noise, b * self.act_dim, rng);
        self.critic_target(batch, alpha, self.backup);
        self.critic_gradients(batch);
        fill_standard_normal(&mut self.work.noise, b * self.act_dim, rng);
        self.actor_gradients(&batch.observations, alpha);
        let (_, log_alpha, _) = self.alpha_gradient();
        FusedGradients {
            critics: self.critics.iter().map(|c| c.grads.clone()).collect(),
            actor: self.work.actor_grads.clone(),
            log_alpha,
        }
    }

    /// a ~ π(·|s) for `observations` with log π(a|s), ε drawn from `rng`:
    /// how online SAC acts in the task between updates, on the weights it trains.
    pub fn act_logged(&mut self, observations: &[f32], rng: &mut ChaCha8Rng) -> LoggedActions {
        let b = observations.len() / self.obs_dim;
        fill_standard_normal(&mut self.work.noise, b * self.act_dim, rng);
        self.sample_actor(observations);
        let s = &self.work.sample;
        LoggedActions {
            actions: s.action.clone(),
            log_probs: Some(s.log_prob.clone()),
        }
    }

    /// ã ~ π(·|s) for `observations` with `work.noise` into `work.sample`
    /// (the actor's tape keeps what its gradient needs).
    fn sample_actor(&mut self, observations: &[f32]) {
        let b = observations.len() / self.obs_dim;
        let w = &mut self.work;
        self.actor.forward(observations, b, &mut w.actor_tape);
        sample(
            &w.actor_tape.output,
            &w.noise,
            (&self.half, &self.center, self.log_half_sum),
            self.log_std,
            &mut w.sample,
        );
    }

    /// ã ~ π(·|s) for `observations`, drawn with `work.noise` (the actor's tape
    /// and `work.sample` keep what its gradient needs), and `[s | ã]` into
    /// `work.critic_input`.
    fn act_into_critic_input(&mut self, observations: &[f32]) {
        self.sample_actor(observations);
        let w = &mut self.work;
        concat_rows(
            observations,
            &w.sample.action,
            self.obs_dim,
            self.act_dim,
            &mut w.critic_input,
        );
    }

    /// y = r + γ(1 − d)(min_i Q̄_i(s', ã') − α·log π(ã'|s')), ã' drawn with
    /// `work.noise`, into `work.y` (as [`Sac::critic_target`]: without the
    /// entropy term under a deterministic `backup`, at least its floor).
    fn critic_target(&mut self, batch: &TransitionBatch, alpha: f32, backup: Option<CriticBackup>) {
        let b = batch.rewards.len();
        self.act_into_critic_input(&batch.next_observations);
        let min_q = self.target_minimum(b);
        let w = &mut self.work;
        w.y.clear();
        for (r, min_q) in min_q.into_iter().enumerate() {
            let next_value = if backup.is_some_and(|b| b.deterministic) {
                min_q
            } else {
                min_q - w.sample.log_prob[r] * alpha
            };
            let not_done = -batch.terminals[r] + 1.0;
            let y = batch.rewards[r] + not_done * next_value * self.gamma;
            let floor = backup.and_then(|b| b.floor);
            w.y.push(floor.map_or(y, |floor| y.max(floor)));
        }
    }

    /// min_j Q̄_j on the `rows` rows of `work.critic_input`, the targets side by side.
    fn target_minimum(&mut self, rows: usize) -> Vec<f32> {
        let input = &self.work.critic_input;
        (self.critics.par_iter_mut()).for_each(|c| c.target.forward(input, rows, &mut c.tape));
        (0..rows)
            .map(|r| (self.critics.iter()).fold(f32::INFINITY, |m, c| m.min(c.tape.output[r])))
            .collect()
    }

    /// min_i Q̄_i(s, ã) at ã ~ π(·|s) for every row of `observations`, ε from
    /// `rng` (as [`Sac::target_values`]): MOBILE's penalty samples.
    pub fn target_values(&mut self, observations: &[f32], rng: &mut ChaCha8Rng) -> Vec<f32> {
        let b = observations.len() / self.obs_dim;
        fill_standard_normal(&mut self.work.noise, b * self.act_dim, rng);
        rayon::scope(|_| {
            self.act_into_critic_input(observations);
            self.target_minimum(b)
        })
    }

    /// ∂L_Q/∂θ of every critic into its `grads`; returns the critics' losses
    /// (the first two's: SAC's Q₁ and Q₂).
    fn critic_gradients(&mut self, batch: &TransitionBatch) -> SacLosses {
        let b = batch.rewards.len();
        let w = &mut self.work;
        concat_rows(
            &batch.observations,
            &batch.actions,
            self.obs_dim,
            self.act_dim,
            &mut w.critic_input,
        );
        // Each critic on its share of the cores: forward, (Q − y)², backward.
        let (input, y) = (&w.critic_input, &w.y);
        let losses: Vec<f32> = (self.critics.par_iter_mut())
            .map(|c| {
                c.net.forward(input, b, &mut c.tape);
                c.grad_q.clear();
                let mut squares = 0.0;
                for (q, y) in c.tape.output.iter().zip(y) {
                    squares += (q - y) * (q - y);
                    c.grad_q.push(2.0 * (q - y) / b as f32);
                }
                c.net
                    .backward(&mut c.tape, &c.grad_q, Some(&mut c.grads), None);
                squares / b as f32
            })
            .collect();
        self.critic_losses(&losses, b)
    }

    /// SAC's loss fields from each critic's squared error (Q₁'s and Q₂'s),
    /// with mean Q₁ over the first `b` rows of its last forward pass.
    fn critic_losses(&self, losses: &[f32], b: usize) -> SacLosses {
        SacLosses {
            qf1_loss: losses[0],
            qf2_loss: losses.get(1).copied().unwrap_or(0.0),
            qf1_values: mean(&self.critics[0].tape.output[..b]),
            ..SacLosses::default()
        }
    }

    /// ∂L_π/∂θ of the actor into `work.actor_grads`, ã drawn with
    /// `work.noise`; returns L_π. `work.sample` keeps log π(ã|s).
    fn actor_gradients(&mut self, observations: &[f32], alpha: f32) -> f32 {
        let (o, a) = (self.obs_dim, self.act_dim);
        let b = observations.len() / o;
        self.act_into_critic_input(observations);
        let w = &mut self.work;
        let input = &w.critic_input;
        (self.critics.par_iter_mut()).for_each(|c| c.net.forward(input, b, &mut c.tape));

        // min_j Q_j passes −1/B to the smallest critic of each row (the first on ties).
        let mut loss = 0.0;
        for c in &mut self.critics {
            c.grad_q.clear();
            c.grad_q.resize(b, 0.0);
        }
        for r in 0..b {
            let (smallest, min_q) = (self.critics.iter().enumerate())
                .map(|(j, c)| (j, c.tape.output[r]))
                .fold(
                    (0, f32::INFINITY),
                    |m, (j, q)| if q < m.1 { (j, q) } else { m },
                );
            loss += w.sample.log_prob[r] * alpha - min_q;
            self.critics[smallest].grad_q[r] = -1.0 / b as f32;
        }
        // ∂L/∂ã through every critic, side by side (inputs only; the critics
        // do not learn here).
        (self.critics.par_iter_mut())
            .for_each(|c| (c.net).backward(&mut c.tape, &c.grad_q, None, Some(&mut c.grad_input)));
        w.grad_action.clear();
        w.grad_action.resize(b * a, 0.0);
        for c in &self.critics {
            for (sum, row) in
                (w.grad_action.chunks_exact_mut(a)).zip(c.grad_input.chunks_exact(o + a))
            {
                sum.iter_mut().zip(&row[o..]).for_each(|(s, g)| *s += g);
            }
        }
        // Through ã = centre + half·tanh(u), u = μ + σ·ε, and log π's own terms:
        // ∂log π/∂u = 2·tanh(u) (from −log(1 − tanh²u)), ∂log π/∂log σ = −1.
        let per_row = alpha / b as f32;
        w.grad_actor.resize(b * 2 * a, 0.0);
        let s = &w.sample;
        for r in 0..b {
            for j in 0..a {
                let i = r * a + j;
                let t = s.squashed[i];
                let g_u = w.grad_action[i] * self.half[j] * (1.0 - t * t) + per_row * 2.0 * t;
                w.grad_actor[r * 2 * a + j] = g_u;
                w.grad_actor[r * 2 * a + a + j] = if s.inside[i] {
                    g_u * s.std[i] * w.noise[i] - per_row
                } else {
                    0.0
                };
            }
        }
        self.actor.backward(
            &mut w.actor_tape,
            &w.grad_actor,
            Some(&mut w.actor_grads),
            None,
        );
        loss / b as f32
    }

    /// L_α = mean −log α·(log π(ã|s) + H̄) on the actor step's sample: returns
    /// (L_α, ∂L_α/∂log α, the entropy estimate −mean log π).
    fn alpha_gradient(&self) -> (f32, f32, f32) {
        let log_prob = &self.work.sample.log_prob;
        let mean_log_prob = mean(log_prob);
        let grad = -(mean_log_prob + self.target_entropy);
        (self.log_alpha * grad, grad, -mean_log_prob)
    }
}

/// `(path, Q_j, Q̄_j)` of a burn critic and its target.
fn critic_pair(path: &str, net: &Mlp, target: &Mlp) -> (String, TrainableMlp, TrainableMlp) {
    let (net, target) = (
        TrainableMlp::from_burn(net),
        TrainableMlp::from_burn(target),
    );
    (path.to_string(), net, target)
}

/// One Adam step of every parameter of `net`, its moments under `prefix.` + the
/// parameter's path (the burn module's, so both kernels share them).
fn step_network(
    adam: &Adam,
    step: AdamStep,
    state: &mut AdamState,
    prefix: &str,
    net: &mut TrainableMlp,
    grads: &TrainableMlp,
) {
    for (path, param, grad) in net.params_with(grads) {
        let moments = state.moments.entry(format!("{prefix}.{path}")).or_default();
        adam.update(step, param, grad, moments);
    }
}

/// a = centre + half·tanh(μ + σ·ε) and log π(a|s) from the actor's output
/// `[rows, 2·act_dim]` (μ, then log σ before its clamp), as `Actor::sample`.
fn sample(
    out: &[f32],
    noise: &[f32],
    (half, center, log_half_sum): (&[f32], &[f32], f32),
    (low, high): (f32, f32),
    s: &mut Sample,
) {
    let a = half.len();
    let rows = out.len() / (2 * a);
    for v in [&mut s.action, &mut s.squashed, &mut s.std] {
        v.resize(rows * a, 0.0);
    }
    s.inside.resize(rows * a, false);
    s.log_prob.resize(rows, 0.0);
    for r in 0..rows {
        let mut log_prob = 0.0;
        for j in 0..a {
            let i = r * a + j;
            let (mean, raw) = (out[r * 2 * a + j], out[r * 2 * a + a + j]);
            let log_std = raw.clamp(low, high);
            let std = log_std.exp();
            let eps = noise[i];
            let u = mean + std * eps;
            let t = u.tanh();
            log_prob += tanh_gaussian_log_density(eps, log_std, u);
            s.inside[i] = (low..=high).contains(&raw);
            s.std[i] = std;
            s.squashed[i] = t;
            s.action[i] = t * half[j] + center[j];
        }
        s.log_prob[r] = log_prob - log_half_sum;
    }
}

/// `[left | right]` row by row into `out`.
fn concat_rows(left: &[f32], right: &[f32], lw: usize, rw: usize, out: &mut Vec<f32>) {
    out.clear();
    for (l, r) in left.chunks_exact(lw).zip(right.chunks_exact(rw)) {
        out.extend_from_slice(l);
        out.extend_from_slice(r);
    }
}

fn mean(values: &[f32]) -> f32 {
    values.iter().sum::<f32>() / values.len().max(1) as f32
}
