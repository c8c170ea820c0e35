//! A built-in task's reward and termination ([`TaskRules`](crate::envs::TaskRules))
//! as ONNX nodes over a batch of transitions, from their [`RuleTerms`].

use super::graph::{Graph, Value, int, ints};
use crate::envs::{ForwardTerm, HealthRule, RuleTerms};

/// `r(s, a, s')` and the terminal flag, each `[batch]`, of `[batch, obs]`
/// observations `obs`, `next_obs` and `[batch, act]` actions.
pub fn reward_and_terminal(
    g: &mut Graph,
    terms: &RuleTerms,
    (obs, action, next_obs): (&Value, &Value, &Value),
    obs_dim: usize,
) -> (Value, Value) {
    let reward = reward(g, terms, (obs, action, next_obs));
    let healthy = healthy(g, &terms.health, terms.qpos_from, next_obs, obs_dim);
    (reward, g.op("Not", &[&healthy], vec![]))
}

/// Column `c` of `[batch, width]` rows as `[batch]`.
fn column(g: &mut Graph, x: &Value, c: usize) -> Value {
    let picked = g.columns(x, &[c]);
    g.reshape(&picked, &[-1])
}

/// w·v + healthy − c·|a|², as `TaskRules::reward` (there in f64).
fn reward(
    g: &mut Graph,
    terms: &RuleTerms,
    (obs, action, next_obs): (&Value, &Value, &Value),
) -> Value {
    let velocity = match terms.forward {
        ForwardTerm::Difference { root_x, dt } => {
            let (after, before) = (column(g, next_obs, root_x), column(g, obs, root_x));
            let moved = g.sub(&after, &before);
            let dt = g.scalar(dt as f32);
            g.div(&moved, &dt)
        }
        ForwardTerm::Next { x_velocity } => column(g, next_obs, x_velocity),
        ForwardTerm::Mean { x_velocity } => {
            let (before, after) = (column(g, obs, x_velocity), column(g, next_obs, x_velocity));
            let sum = g.add(&before, &after);
            let half = g.scalar(0.5);
            g.mul(&half, &sum)
        }
    };
    let weight = g.scalar(terms.forward_reward_weight as f32);
    let forward = g.mul(&weight, &velocity);
    let healthy = g.scalar(terms.healthy_reward as f32);
    let paid = g.add(&forward, &healthy);
    let squared = g.mul(action, action);
    let control = g.sum(&squared, 1);
    let cost_weight = g.scalar(terms.ctrl_cost_weight as f32);
    let cost = g.mul(&cost_weight, &control);
    g.sub(&paid, &cost)
}

/// `lo < x < hi`, elementwise.
fn strictly_inside(g: &mut Graph, x: &Value, (lo, hi): (f64, f64)) -> Value {
    let (lo, hi) = (g.scalar(lo as f32), g.scalar(hi as f32));
    let above = g.op("Greater", &[x, &lo], vec![]);
    let below = g.op("Less", &[x, &hi], vec![]);
    g.op("And", &[&above, &below], vec![])
}

/// Whether every entry of each row of the boolean `[batch, width]` `x` holds.
fn all_of_row(g: &mut Graph, x: &Value) -> Value {
    // ReduceMin takes no booleans: over 0/1 floats, the row holds where it is 1.
    let ones = g.op("Cast", &[x], vec![int("to", 1)]);
    let least = g.op(
        "ReduceMin",
        &[&ones],
        vec![ints("axes", &[1]), int("keepdims", 0)],
    );
    let half = g.scalar(0.5);
    g.op("Greater", &[&least, &half], vec![])
}

/// `health.is_healthy` of each `next_obs` row, `[batch]` booleans.
fn healthy(
    g: &mut Graph,
    health: &HealthRule,
    from: usize,
    next_obs: &Value,
    obs_dim: usize,
) -> Value {
    match *health {
        HealthRule::AlwaysHealthy => {
            let rows = g.op("Shape", &[next_obs], vec![int("start", 0), int("end", 1)]);
            let zeros = g.op("ConstantOfShape", &[&rows], vec![]);
            // ConstantOfShape's default fill is a float 0: cast, all true.
            let floats = g.op("Cast", &[&zeros], vec![int("to", 9)]);
            g.op("Not", &[&floats], vec![])
        }
        HealthRule::Upright {
            z_range,
            angle_range,
            state_range,
        } => {
            let z = column(g, next_obs, 1 - from);
            let angle = column(g, next_obs, 2 - from);
            let z_ok = strictly_inside(g, &z, z_range);
            let angle_ok = strictly_inside(g, &angle, angle_range);
            let upright = g.op("And", &[&z_ok, &angle_ok], vec![]);
            match state_range {
                None => upright,
                Some(range) => {
                    let rest = g.columns(next_obs, &((2 - from)..obs_dim).collect::<Vec<_>>());
                    let inside = strictly_inside(g, &rest, range);
                    let rest_ok = all_of_row(g, &inside);
                    g.op("And", &[&upright, &rest_ok], vec![])
                }
            }
        }
        HealthRule::FiniteWithin { qpos, range } => {
            let nan = g.op("IsNaN", &[next_obs], vec![]);
            let inf = g.op("IsInf", &[next_obs], vec![]);
            let bad = g.op("Or", &[&nan, &inf], vec![]);
            let good = g.op("Not", &[&bad], vec![]);
            let finite = all_of_row(g, &good);
            let x = column(g, next_obs, qpos - from);
            let (lo, hi) = (g.scalar(range.0 as f32), g.scalar(range.1 as f32));
            let above = g.op("GreaterOrEqual", &[&x, &lo], vec![]);
            let below = g.op("LessOrEqual", &[&x, &hi], vec![]);
            let within = g.op("And", &[&above, &below], vec![]);
            g.op("And", &[&finite, &within], vec![])
        }
    }
}
