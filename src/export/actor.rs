//! SAC's tanh-Gaussian actor as an ONNX graph: the deterministic action
//! centre + half·tanh(μ(s)), and, for a given ε ~ N(0, I), the sampled action
//! centre + half·tanh(μ + σ·ε) with its log π(a|s) ([`Actor::sample`]).

use super::graph::{Elem, Graph};
use super::proto::onnx::ModelProto;
use crate::agent::Actor;

/// The actor's graph: inputs `observation [batch, obs]`, `noise [batch, act]`;
/// outputs `deterministic_action`, `sampled_action` (`[batch, act]`) and
/// `log_prob` (`[batch]`).
pub fn actor_graph(actor: &Actor) -> ModelProto {
    let config = &actor.config;
    let act = config.act_dim;
    let mut g = Graph::default();
    let obs = g.input("observation", config.obs_dim);
    let noise = g.input("noise", act);

    let out = g.mlp(&actor.net, &obs);
    let mean = g.columns(&out, &(0..act).collect::<Vec<_>>());
    let raw_log_std = g.columns(&out, &(act..2 * act).collect::<Vec<_>>());
    let (low, high) = (g.scalar(config.log_std_min), g.scalar(config.log_std_max));
    let log_std = g.op("Clip", &[&raw_log_std, &low, &high], vec![]);
    let (half, center) = config.box_half_center();
    let (half_row, center_row) = (g.row(&half), g.row(&center));
    let onto_box = |g: &mut Graph, u| {
        let t = g.op("Tanh", &[u], vec![]);
        let scaled = g.mul(&t, &half_row);
        g.add(&scaled, &center_row)
    };
    let deterministic = onto_box(&mut g, &mean);

    // u = μ + σ·ε
    let sigma = g.op("Exp", &[&log_std], vec![]);
    let spread = g.mul(&sigma, &noise);
    let u = g.add(&mean, &spread);
    let sampled = onto_box(&mut g, &u);

    // log N(u; μ, σ) = −ε²/2 − log σ − log(2π)/2, per dimension.
    let squared = g.mul(&noise, &noise);
    let minus_half = g.scalar(-0.5);
    let gaussian = g.mul(&squared, &minus_half);
    let gaussian = g.sub(&gaussian, &log_std);
    let half_log_two_pi = g.scalar(0.5 * (2.0 * std::f32::consts::PI).ln());
    let gaussian = g.sub(&gaussian, &half_log_two_pi);
    // log(1 − tanh²(u)) = 2·(log 2 − u − softplus(−2u)).
    let minus_two = g.scalar(-2.0);
    let minus_two_u = g.mul(&u, &minus_two);
    let softplus = g.op("Softplus", &[&minus_two_u], vec![]);
    let minus_u = g.op("Neg", &[&u], vec![]);
    let squash = g.sub(&minus_u, &softplus);
    let ln_two = g.scalar(std::f32::consts::LN_2);
    let squash = g.add(&squash, &ln_two);
    let two = g.scalar(2.0);
    let squash = g.mul(&squash, &two);
    let log_half = g.row(&half.iter().map(|h| h.ln()).collect::<Vec<_>>());
    let per_dimension = g.sub(&gaussian, &squash);
    let per_dimension = g.sub(&per_dimension, &log_half);
    let log_prob = g.sum(&per_dimension, 1);

    g.output(&deterministic, "deterministic_action", Some(act), Elem::F32);
    g.output(&sampled, "sampled_action", Some(act), Elem::F32);
    g.output(&log_prob, "log_prob", None, Elem::F32);
    g.finish(
        "nuno_policy",
        "SAC's tanh-Gaussian actor (nuno): deterministic and sampled actions for given standard normal noise",
    )
}
