//! The ensemble's fit on the fused CPU path (`crate::infer`): each member a
//! [`TrainableMlp`] on one core, the members spread over the cores; the loss's
//! gradient with respect to each member's output by hand, through the soft
//! log-variance bounds (`GaussianEnsemble::member`):
//!
//! log σ²₁ = max − softplus(max − raw), log σ² = min + softplus(log σ²₁ − min);
//! ∂/∂μ = 2(μ − y)·e^(−log σ²)/n, ∂/∂log σ² = (1 − (μ − y)²·e^(−log σ²))/n
//! (n = rows × outputs), ∂log σ²/∂log σ²₁ = s(log σ²₁ − min),
//! ∂log σ²₁/∂raw = s(max − raw), the rest to max and min (s the sigmoid).
//! The same Adam as burn's path (`nn::Adam`), so both train the same model;
//! `tests/ensemble.rs` holds them to each other.

use burn::module::Param;
use burn::tensor::{Tensor, TensorData};
use rayon::prelude::*;

use super::model::{BoundedLogvar, GaussianEnsemble};
use super::trainer::{ADAM_EPSILON, EnsembleTrainer, LossTerms, MemberBatch};
use crate::infer::{MlpTape, TrainableMlp};
use crate::nn::{Adam, AdamState, Mlp, to_f32_vec};

/// One member with its optimiser state and buffers.
struct Member {
    net: TrainableMlp,
    grads: TrainableMlp,
    tape: MlpTape,
    state: AdamState,
    /// ∂L/∂output, `[rows, 2·d_out]`.
    grad_output: Vec<f32>,
}

impl Member {
    /// One Adam step of this member on its NLL of `batch` and weight decay,
    /// plus `extra`'s rows (inputs, ∂term/∂output) after the batch's in the
    /// same pass; returns its loss and its gradient by the bounds.
    fn step(
        &mut self,
        batch: &MemberBatch,
        extra: Option<&(Vec<f32>, Vec<f32>)>,
        (max, min): (&[f32], &[f32]),
        (terms, adam): (&LossTerms, Adam),
    ) -> BoundsGradient {
        let d = max.len();
        let rows = batch.y.len() / d;
        let joined;
        let (input, all_rows) = match extra {
            Some((x, grad)) => {
                joined = [batch.x.as_slice(), x].concat();
                (joined.as_slice(), rows + grad.len() / (2 * d))
            }
            None => (batch.x.as_slice(), rows),
        };
        self.net.forward(input, all_rows, &mut self.tape);
        let mut bounds = nll_gradient(
            &self.tape.output[..rows * 2 * d],
            &batch.y,
            (max, min),
            &mut self.grad_output,
        );
        if let Some((_, grad)) = extra {
            self.grad_output.extend_from_slice(grad);
        }
        (self.net).backward(
            &mut self.tape,
            &self.grad_output,
            Some(&mut self.grads),
            None,
        );
        for ((layer, grad), &c) in (self.net.layers.iter())
            .zip(&mut self.grads.layers)
            .zip(&terms.weight_decay)
        {
            let c = c as f32;
            let mut squares = 0.0f64;
            for (g, &w) in grad.weight.iter_mut().zip(&layer.weight) {
                *g += c * w;
                squares += f64::from(w) * f64::from(w);
            }
            bounds.loss += 0.5 * f64::from(c) * squares;
        }
        let step = adam.begin(&mut self.state, terms.learning_rate);
        for (path, param, grad) in self.net.params_with(&self.grads) {
            let moments = self.state.moments.entry(path).or_default();
            adam.update(step, param, grad, moments);
        }
        bounds
    }
}

/// What one member's step reports: its loss (NLL and weight decay) and its
/// gradient with respect to the shared bounds.
struct BoundsGradient {
    loss: f64,
    max: Vec<f32>,
    min: Vec<f32>,
}

/// A term beside the fit's loss whose gradient the caller has taken with
/// respect to some members' outputs on rows of their own (RAMBO's adversarial
/// term, `super::adversarial`).
pub(super) struct OutputTerm {
    /// Per member: normalised inputs `[rows, d_in]` and ∂term/∂output
    /// `[rows, 2·d_out]` (by the raw log-variance, through the bounds), or none.
    pub rows: Vec<Option<(Vec<f32>, Vec<f32>)>>,
    /// ∂term/∂ the log-variance limits.
    pub max: Vec<f32>,
    pub min: Vec<f32>,
}

pub(super) struct FusedTrainer {
    members: Vec<Member>,
    max_logvar: Vec<f32>,
    min_logvar: Vec<f32>,
    bounds_state: AdamState,
    adam: Adam,
    terms: LossTerms,
    /// The model the weights came from, written back at the end.
    template: GaussianEnsemble,
}

impl FusedTrainer {
    /// Trains `model`'s weights (read to host memory once).
    pub fn new(model: GaussianEnsemble, terms: LossTerms) -> Self {
        let members = model
            .members
            .iter()
            .map(|mlp| {
                let net = TrainableMlp::from_burn(mlp);
                Member {
                    grads: net.zeros_like(),
                    net,
                    // One core each: the members themselves are spread over the cores.
                    tape: MlpTape::on_cores(1),
                    state: AdamState::default(),
                    grad_output: Vec::new(),
                }
            })
            .collect();
        Self {
            members,
            max_logvar: to_f32_vec(model.max_logvar.val()),
            min_logvar: to_f32_vec(model.min_logvar.val()),
            bounds_state: AdamState::default(),
            adam: Adam::new(ADAM_EPSILON),
            terms,
            template: model,
        }
    }

    /// One Adam step on the fit's loss over `batches` plus `term`, whose
    /// gradient the caller has taken; returns the fit's loss before the step
    /// (the term's value is the caller's).
    pub fn step_with(&mut self, batches: &[MemberBatch], term: Option<&OutputTerm>) -> f64 {
        let (adam, terms) = (self.adam, &self.terms);
        let bounds = (self.max_logvar.as_slice(), self.min_logvar.as_slice());
        let contributions: Vec<BoundsGradient> = (self.members.par_iter_mut().zip(batches))
            .enumerate()
            .map(|(m, (member, batch))| {
                let extra = term.and_then(|t| t.rows[m].as_ref());
                member.step(batch, extra, bounds, (terms, adam))
            })
            .collect();
        self.step_bounds(&contributions, term)
    }

    /// Adam's step on the shared bounds from the members' contributions, the
    /// term's and the bounds' own loss; returns the whole loss.
    fn step_bounds(&mut self, contributions: &[BoundsGradient], term: Option<&OutputTerm>) -> f64 {
        let coef = self.terms.bounds_coef as f32;
        let mut loss = self.terms.bounds_coef
            * (self.max_logvar.iter().map(|&v| f64::from(v)).sum::<f64>()
                - self.min_logvar.iter().map(|&v| f64::from(v)).sum::<f64>());
        let mut grad_max = vec![coef; self.max_logvar.len()];
        let mut grad_min = vec![-coef; self.min_logvar.len()];
        let added = |into: &mut Vec<f32>, values: &[f32]| {
            into.iter_mut().zip(values).for_each(|(g, v)| *g += v);
        };
        for c in contributions {
            loss += c.loss;
            added(&mut grad_max, &c.max);
            added(&mut grad_min, &c.min);
        }
        if let Some(term) = term {
            added(&mut grad_max, &term.max);
            added(&mut grad_min, &term.min);
        }
        let step = self
            .adam
            .begin(&mut self.bounds_state, self.terms.learning_rate);
        for (name, param, grad) in [
            ("max_logvar", &mut self.max_logvar, &grad_max),
            ("min_logvar", &mut self.min_logvar, &grad_min),
        ] {
            let moments = self.bounds_state.moments.entry(name.into()).or_default();
            self.adam.update(step, param, grad, moments);
        }
        loss
    }

    /// The raw outputs (μ, then the unbounded log-variance; `[rows, 2·d_out]`)
    /// of each of `members`, in their order, at normalised inputs `x`.
    pub fn outputs(&mut self, members: &[usize], x: &[f32]) -> Vec<Vec<f32>> {
        let rows = x.len() / self.members[0].net.d_in();
        let mut by_member: Vec<Option<Vec<f32>>> = (self.members.par_iter_mut().enumerate())
            .map(|(m, member)| {
                members.contains(&m).then(|| {
                    member.net.forward(x, rows, &mut member.tape);
                    member.tape.output.clone()
                })
            })
            .collect();
        (members.iter())
            .filter_map(|&m| by_member.get_mut(m)?.take())
            .collect()
    }

    /// How many members it trains.
    pub fn member_count(&self) -> usize {
        self.members.len()
    }

    /// The log-variance limits now (max, min).
    pub fn bounds(&self) -> (&[f32], &[f32]) {
        (&self.max_logvar, &self.min_logvar)
    }

    /// The ensemble with the members' current weights.
    pub fn model(&self) -> GaussianEnsemble {
        let current: Vec<TrainableMlp> = self.members.iter().map(|m| m.net.clone()).collect();
        self.model_with(&current)
    }
}

impl EnsembleTrainer for FusedTrainer {
    type Member = TrainableMlp;

    fn step(&mut self, batches: &[MemberBatch]) -> f64 {
        self.step_with(batches, None)
    }

    fn holdout_mse(&mut self, holdout: &MemberBatch) -> Vec<f32> {
        let d = self.max_logvar.len();
        let rows = holdout.y.len() / d;
        self.members
            .par_iter_mut()
            .map(|member| {
                member.net.forward(&holdout.x, rows, &mut member.tape);
                let out = &member.tape.output;
                let mut sum = 0.0f64;
                for (r, y) in holdout.y.chunks_exact(d).enumerate() {
                    for (mean, y) in out[r * 2 * d..r * 2 * d + d].iter().zip(y) {
                        sum += f64::from(mean - y) * f64::from(mean - y);
                    }
                }
                (sum / (rows * d) as f64) as f32
            })
            .collect()
    }

    fn member(&self, m: usize) -> TrainableMlp {
        self.members[m].net.clone()
    }

    fn member_of(&self, mlp: &Mlp) -> TrainableMlp {
        TrainableMlp::from_burn(mlp)
    }

    fn model_with(&self, best: &[TrainableMlp]) -> GaussianEnsemble {
        let mut model = self.template.clone();
        model.members = model
            .members
            .into_iter()
            .zip(best)
            .map(|(mlp, net)| net.write_to(mlp))
            .collect();
        model.max_logvar = replaced(model.max_logvar, self.max_logvar.clone());
        model.min_logvar = replaced(model.min_logvar, self.min_logvar.clone());
        model
    }

    fn optimizer_state(&self) -> AdamState {
        let mut state = AdamState {
            time: self.bounds_state.time,
            moments: self.bounds_state.moments.clone(),
        };
        for (m, member) in self.members.iter().enumerate() {
            for (path, moments) in &member.state.moments {
                state
                    .moments
                    .insert(format!("members.{m}.{path}"), moments.clone());
            }
        }
        state
    }

    fn restore(&mut self, current: &GaussianEnsemble, adam: AdamState) {
        for (member, mlp) in self.members.iter_mut().zip(&current.members) {
            member.net = TrainableMlp::from_burn(mlp);
            member.state = AdamState {
                time: adam.time,
                moments: Default::default(),
            };
        }
        self.bounds_state = AdamState {
            time: adam.time,
            moments: Default::default(),
        };
        // `members.{m}.{path}` is member m's; the rest (the bounds) is shared.
        for (path, moments) in adam.moments {
            let owner = path
                .strip_prefix("members.")
                .and_then(|rest| rest.split_once('.'))
                .and_then(|(m, rest)| Some((m.parse::<usize>().ok()?, rest)));
            match owner {
                Some((m, rest)) if m < self.members.len() => {
                    self.members[m]
                        .state
                        .moments
                        .insert(rest.to_string(), moments);
                }
                _ => {
                    self.bounds_state.moments.insert(path, moments);
                }
            }
        }
        self.max_logvar = to_f32_vec(current.max_logvar.val());
        self.min_logvar = to_f32_vec(current.min_logvar.val());
    }
}

/// `param` holding `values` (its id kept).
fn replaced(param: Param<Tensor<1>>, values: Vec<f32>) -> Param<Tensor<1>> {
    let (id, old) = (param.id, param.val());
    let n = values.len();
    Param::initialized(
        id,
        Tensor::from_data(TensorData::new(values, [n]), &old.device()),
    )
}

/// The mean Gaussian NLL of one member's `output` (`[rows, 2·d]`: μ, then the
/// raw log-variance) against `targets` (`[rows, d]`), its gradient with respect
/// to the output into `grad_output`, and its gradient with respect to the
/// bounds.
fn nll_gradient(
    output: &[f32],
    targets: &[f32],
    (max, min): (&[f32], &[f32]),
    grad_output: &mut Vec<f32>,
) -> BoundsGradient {
    let d = max.len();
    let rows = targets.len() / d;
    let scale = 1.0 / (rows * d) as f32;
    grad_output.resize(rows * 2 * d, 0.0);
    let mut bounds = BoundsGradient {
        loss: 0.0,
        max: vec![0.0; d],
        min: vec![0.0; d],
    };
    let mut sum = 0.0f64;
    for ((out, grad), y) in output
        .chunks_exact(2 * d)
        .zip(grad_output.chunks_exact_mut(2 * d))
        .zip(targets.chunks_exact(d))
    {
        for j in 0..d {
            let logvar = BoundedLogvar::of(out[d + j], max[j], min[j]);
            let diff = out[j] - y[j];
            let inverse_variance = (-logvar.value).exp();
            sum += f64::from(diff * diff * inverse_variance + logvar.value);
            grad[j] = 2.0 * diff * inverse_variance * scale;
            let d_logvar = (1.0 - diff * diff * inverse_variance) * scale;
            grad[d + j] = d_logvar * logvar.d_raw;
            bounds.max[j] += d_logvar * logvar.d_max;
            bounds.min[j] += d_logvar * logvar.d_min;
        }
    }
    bounds.loss = sum * f64::from(scale);
    bounds
}
