//! The neural SDE's Euler–Maruyama step (eq. 5, 8) as one ONNX graph, the
//! arithmetic of [`FusedSde`](crate::sde::FusedSde)'s step in the same order,
//! with the normaliser folded in, the noise an input, and the task's reward
//! and termination on the sampled next observation (what the server's `step`
//! answers per particle).

use super::graph::{Elem, Graph, Value};
use super::proto::onnx::ModelProto;
use super::task_rules::reward_and_terminal;
use crate::envs::RuleTerms;
use crate::sde::{DriftFeatures, NeuralSde};

/// The step's graph: inputs `observation [batch, obs]`, `action [batch, act]`
/// (clipped to `action_space`, as the server's default `clip`), `noise
/// [batch, state]` (ε ~ N(0, I) times the noise scale; state = obs, plus r_c
/// for NUNO^R); outputs `mean`, `sigma`, `h_eta`, `next_state` (`[batch, obs]`),
/// `eta`, `reward` (`[batch]` f32) and `terminal` (`[batch]` bool).
pub fn sde_step_graph(
    model: &NeuralSde,
    rules: &RuleTerms,
    action_space: &[(f32, f32)],
) -> ModelProto {
    let c = &model.constants;
    let (obs_dim, act_dim, state_dim) = (c.spec.obs_dim, c.spec.act_dim, c.state_dim());
    let normalizer = &c.scales.normalizer;
    let mut g = Graph::default();
    let obs = g.input("observation", obs_dim);
    let unclipped = g.input("action", act_dim);
    let noise = g.input("noise", state_dim);

    let action = clip(&mut g, &unclipped, action_space);
    let state = &normalizer.state;
    let obs_hat = normalise(&mut g, &obs, &state.mean[..obs_dim], &state.std[..obs_dim]);
    let action_hat = normalise(
        &mut g,
        &action,
        &normalizer.action.mean,
        &normalizer.action.std,
    );
    // σ_ϕ's, η_ϕ's and f_rew's input; [φ(s), â], the drift's.
    let input = g.concat(&[&obs_hat, &action_hat]);
    let phi = features(&mut g, &DriftFeatures::of(c), &obs, &obs_hat);
    let drift_input = g.concat(&[&phi, &action_hat]);

    let mean_obs = drift_mean(&mut g, model, (&obs, &action), (&phi, &drift_input));
    let mean = match &model.reward_net {
        // NUNO^R: r_c starts at 0 each step, so its mean is f_rew(s, a)·dt.
        Some(reward_net) => {
            let f_rew = g.mlp(reward_net, &input);
            let rate_dt = g.scalar(c.scales.reward_rate * c.spec.dt as f32);
            let r_c = g.mul(&f_rew, &rate_dt);
            g.concat(&[&mean_obs, &r_c])
        }
        None => mean_obs,
    };
    let (sigma, h_eta, eta) = diffusion(&mut g, model, &input);

    // eq. 5: s' = mean + (σ + h(η))·ε·sqrt(dt)
    let spread = g.add(&sigma, &h_eta);
    let scaled = g.mul(&spread, &noise);
    let sqrt_dt = g.scalar(c.spec.dt.sqrt() as f32);
    let step = g.mul(&scaled, &sqrt_dt);
    let next = g.add(&mean, &step);

    let observed: Vec<usize> = (0..obs_dim).collect();
    let next_obs = g.columns(&next, &observed);
    let (task_reward, terminal) =
        reward_and_terminal(&mut g, rules, (&obs, &action, &next_obs), obs_dim);
    let reward = if model.reward_net.is_some() {
        let r_c = g.columns(&next, &[obs_dim]);
        g.reshape(&r_c, &[-1])
    } else {
        task_reward
    };
    for (value, name) in [(&mean, "mean"), (&sigma, "sigma"), (&h_eta, "h_eta")] {
        let columns = g.columns(value, &observed);
        g.output(&columns, name, Some(obs_dim), Elem::F32);
    }
    g.output(&next_obs, "next_state", Some(obs_dim), Elem::F32);
    g.output(&eta, "eta", None, Elem::F32);
    g.output(&reward, "reward", None, Elem::F32);
    g.output(&terminal, "terminal", None, Elem::Bool);
    g.finish(
        "nuno_sde_step",
        "One Euler–Maruyama step of a nuno neural SDE (eq. 5, 8) with the task's reward and termination",
    )
}

/// Each action clamped into its `[low, high]`.
fn clip(g: &mut Graph, action: &Value, action_space: &[(f32, f32)]) -> Value {
    let low = g.row(&action_space.iter().map(|b| b.0).collect::<Vec<_>>());
    let high = g.row(&action_space.iter().map(|b| b.1).collect::<Vec<_>>());
    let above_low = g.op("Max", &[action, &low], vec![]);
    g.op("Min", &[&above_low, &high], vec![])
}

/// (x − mean)/std per column.
fn normalise(g: &mut Graph, x: &Value, mean: &[f32], std: &[f32]) -> Value {
    let (mean, std) = (g.row(mean), g.row(std));
    let centred = g.sub(x, &mean);
    g.div(&centred, &std)
}

/// φ(s): [ẑ(positions that are not angles), cos θ − cos m, sin θ − sin m, ẑ(velocities)].
fn features(g: &mut Graph, f: &DriftFeatures, obs: &Value, obs_hat: &Value) -> Value {
    let mut parts = vec![g.columns(obs_hat, &f.positions)];
    if !f.angles.is_empty() {
        let angles = g.columns(obs, &f.angles);
        for (op, means) in [("Cos", &f.cos_mean), ("Sin", &f.sin_mean)] {
            let wave = g.op(op, &[&angles], vec![]);
            let means = g.row(means);
            parts.push(g.sub(&wave, &means));
        }
    }
    parts.push(g.columns(obs_hat, &f.velocities));
    g.concat(&parts.iter().collect::<Vec<_>>())
}

/// Rows of `matrices` (`[batch, n·m]`, row-major n × m) times the rows of
/// `vectors` (`[batch, m]`): `[batch, n]`.
fn batched_matrix_vector(
    g: &mut Graph,
    matrices: &Value,
    vectors: &Value,
    (n, m): (usize, usize),
) -> Value {
    let matrices = g.reshape(matrices, &[-1, n as i64, m as i64]);
    let vectors = g.reshape(vectors, &[-1, 1, m as i64]);
    let products = g.mul(&matrices, &vectors);
    g.sum(&products, 2)
}

/// eq. 8's mean s + f(s, a)·dt of the observations: f_pos = the velocities
/// plus the residual, f_vel = G·a + H·v̂ (scaled) plus the residual.
fn drift_mean(
    g: &mut Graph,
    model: &NeuralSde,
    (obs, action): (&Value, &Value),
    (phi, drift_input): (&Value, &Value),
) -> Value {
    let c = &model.constants;
    let spec = &c.spec;
    let (obs_dim, act_dim) = (spec.obs_dim, spec.act_dim);
    let (n_pos, n_vel) = (spec.n_pos(), spec.n_vel());
    let g_columns: Vec<usize> = DriftFeatures::of(c).g_columns.collect();
    let g_input = g.columns(drift_input, &g_columns);
    let g_out = g.mlp(&model.g_net, &g_input);
    let g_a = batched_matrix_vector(g, &g_out, action, (n_vel, act_dim));
    let velocity = g.columns(obs, &(n_pos..obs_dim).collect::<Vec<_>>());
    let vel_std = g.row(&c.scales.normalizer.state.std[n_pos..obs_dim]);
    let velocity_hat = g.div(&velocity, &vel_std);
    let h_out = g.mlp(&model.h_net, phi);
    let h_v = batched_matrix_vector(g, &h_out, &velocity_hat, (n_vel, n_vel));
    let forces = g.add(&g_a, &h_v);
    let acceleration = g.row(&c.scales.acceleration[..n_vel]);
    let f_vel = g.mul(&forces, &acceleration);

    let res = g.mlp(&model.res_net, drift_input);
    let derivative = g.row(&c.scales.derivative[..obs_dim]);
    let res = g.mul(&res, &derivative);
    let res_pos = g.columns(&res, &(0..n_pos).collect::<Vec<_>>());
    let res_vel = g.columns(&res, &(n_pos..obs_dim).collect::<Vec<_>>());
    let position_velocity = g.columns(obs, &spec.split.position_velocity);
    let d_pos = g.add(&position_velocity, &res_pos);
    let d_vel = g.add(&f_vel, &res_vel);
    let drift = g.concat(&[&d_pos, &d_vel]);
    let dt = g.scalar(spec.dt as f32);
    let change = g.mul(&drift, &dt);
    g.add(obs, &change)
}

/// eq. 5's diffusion: σ_ϕ(s, a) (softplus, floored, scaled), h_ϕ(η) (η's
/// logit through its sigmoid, up to W^max), each `[batch, state]`, and η `[batch]`.
fn diffusion(g: &mut Graph, model: &NeuralSde, input: &Value) -> (Value, Value, Value) {
    let c = &model.constants;
    let config = &c.config;
    let state_dim = c.state_dim();
    let scale = &c.scales.diffusion[..state_dim];

    let eta_net = g.mlp(&model.distance.eta_net, input);
    let offset = g.scalar(config.eta_offset);
    let logit = g.sub(&eta_net, &offset);
    let unit_eta = g.sigmoid(&logit);
    let eta_max = g.scalar(config.eta_max);
    let eta = g.mul(&unit_eta, &eta_max);
    let eta = g.reshape(&eta, &[-1]);

    let sigma_net = g.mlp(&model.sigma_net, input);
    let positive = g.op("Softplus", &[&sigma_net], vec![]);
    let floor = g.scalar(config.sigma_min);
    let floored = g.add(&positive, &floor);
    let scale_row = g.row(scale);
    let sigma = g.mul(&floored, &scale_row);

    let weight = g.scalar(config.h_weight);
    let bias = g.scalar(config.h_bias);
    let weighted = g.mul(&logit, &weight);
    let shifted = g.add(&weighted, &bias);
    let unit_h = g.sigmoid(&shifted);
    let scaled = g.mul(&unit_h, &scale_row);
    let w_max = g.row(&config.w_max_per_dimension(state_dim));
    let h_eta = g.mul(&scaled, &w_max);
    (sigma, h_eta, eta)
}
