//! Fitting the ensemble (MOPO as OfflineRL-Kit trains it): a holdout of
//! min(20 %, 1000) transitions; each member on its own bootstrap resample of
//! the rest, reshuffled every epoch; Gaussian NLL with per-layer weight decay
//! and the log-variance bounds' loss; an epoch counts as an update when some
//! member's holdout MSE improves by more than 1 % on its best, and the fit
//! stops after 5 epochs without one. Each member ends at its best epoch; the
//! elites are the members with the lowest holdout MSE. The members train on
//! the fused CPU path (`Kernel::Fused`) or through burn's autodiff
//! (`Kernel::Burn`, any device): the same loss, Adam and data order.

use burn::module::Module;
use burn::tensor::Device;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::EnsembleError;
use super::config::EnsembleConfig;
use super::fused_trainer::FusedTrainer;
use super::model::GaussianEnsemble;
use super::trainer::{BurnTrainer, EnsembleTrainer, LossTerms, MemberBatch};
use crate::data::Dataset;
use crate::infer::Kernel;
use crate::nn::{AdamState, seeded_init};

/// Inputs (s, a) and targets (s' − s, r) of a dataset, row-major.
struct Rows {
    inputs: Vec<f32>,
    targets: Vec<f32>,
    d_in: usize,
    d_out: usize,
}

impl Rows {
    fn of(dataset: &Dataset) -> Self {
        let (o, a) = (dataset.obs_dim(), dataset.act_dim());
        let n = dataset.len();
        let mut inputs = Vec::with_capacity(n * (o + a));
        let mut targets = Vec::with_capacity(n * (o + 1));
        for i in 0..n {
            let obs = dataset.observations.row(i);
            inputs.extend(obs.iter());
            inputs.extend(dataset.actions.row(i).iter());
            push_target(
                &mut targets,
                obs,
                dataset.next_observations.row(i),
                dataset.rewards[i],
            );
        }
        Self {
            inputs,
            targets,
            d_in: o + a,
            d_out: o + 1,
        }
    }

    /// The rows `index` selects into `batch`, inputs normalised.
    fn gather(&self, index: &[usize], scaler: &Scaler, batch: &mut MemberBatch) {
        let MemberBatch { x, y } = batch;
        x.clear();
        y.clear();
        for &i in index {
            let row = &self.inputs[i * self.d_in..(i + 1) * self.d_in];
            x.extend(
                row.iter()
                    .zip(&scaler.mean)
                    .zip(&scaler.std)
                    .map(|((v, m), s)| (v - m) / s),
            );
            y.extend_from_slice(&self.targets[i * self.d_out..(i + 1) * self.d_out]);
        }
    }
}

/// Per-input standardisation (OfflineRL-Kit's `StandardScaler`: a std below
/// 1e-12 counts as 1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Scaler {
    pub mean: Vec<f32>,
    pub std: Vec<f32>,
}

impl Scaler {
    fn fit(rows: &Rows, index: &[usize]) -> Self {
        let d = rows.d_in;
        let n = index.len().max(1) as f64;
        let mut mean = vec![0.0f64; d];
        let mut square = vec![0.0f64; d];
        for &i in index {
            for (j, &v) in rows.inputs[i * d..(i + 1) * d].iter().enumerate() {
                mean[j] += f64::from(v);
                square[j] += f64::from(v) * f64::from(v);
            }
        }
        let std = mean
            .iter()
            .zip(&square)
            .map(|(m, s)| {
                let var = (s / n - (m / n) * (m / n)).max(0.0);
                let std = var.sqrt();
                if std < 1e-12 { 1.0 } else { std as f32 }
            })
            .collect();
        Self {
            mean: mean.iter().map(|m| (m / n) as f32).collect(),
            std,
        }
    }

    /// The members' `[rows, obs_dim + act_dim]` inputs, standardised: each
    /// row's observation (the first `obs_dim` of every `stride` entries of
    /// `states`) then its action (`act_dim` entries of `actions`).
    pub fn inputs(
        &self,
        (states, stride): (&[f32], usize),
        actions: &[f32],
        act_dim: usize,
    ) -> Vec<f32> {
        let obs_dim = self.mean.len() - act_dim;
        let rows = actions.len() / act_dim.max(1);
        let mut x = Vec::with_capacity(rows * self.mean.len());
        for r in 0..rows {
            let row = states[r * stride..r * stride + obs_dim]
                .iter()
                .chain(&actions[r * act_dim..(r + 1) * act_dim]);
            x.extend(
                row.zip(&self.mean)
                    .zip(&self.std)
                    .map(|((v, m), d)| (v - m) / d),
            );
        }
        x
    }
}

/// The members' target for one transition, appended: (s' − s, r).
pub(super) fn push_target<'a>(
    targets: &mut Vec<f32>,
    obs: impl IntoIterator<Item = &'a f32>,
    next: impl IntoIterator<Item = &'a f32>,
    reward: f32,
) {
    targets.extend(next.into_iter().zip(obs).map(|(n, s)| n - s));
    targets.push(reward);
}

/// One epoch of the fit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EnsembleEpoch {
    pub epoch: usize,
    /// Mean training loss over the epoch's batches (all members summed).
    pub train_loss: f64,
    /// Each member's holdout MSE after the epoch.
    pub holdout_mse: Vec<f32>,
    /// Whether some member improved on its best by more than the threshold.
    pub improved: bool,
}

/// A fitted ensemble, each member at its best epoch.
#[derive(Debug, Clone)]
pub struct EnsembleFit {
    pub model: GaussianEnsemble,
    pub scaler: Scaler,
    /// Member indices by ascending holdout MSE, the first `config.elites`.
    pub elites: Vec<usize>,
    /// Each member's best holdout MSE.
    pub holdout_mse: Vec<f32>,
    pub history: Vec<EnsembleEpoch>,
}

/// Where a fit stands after an epoch: everything it needs to continue exactly
/// as if it had not stopped (the data's split, resamples and each epoch's
/// order follow from the seed and the epoch's number).
#[derive(Debug, Clone)]
pub struct EnsembleFitState {
    /// The epochs behind it; `history` has one record each.
    pub history: Vec<EnsembleEpoch>,
    /// Epochs in a row without an improvement.
    pub since_update: usize,
    /// Each member's best holdout MSE so far.
    pub best_mse: Vec<f32>,
    /// The members and bounds now.
    pub current: GaussianEnsemble,
    /// Each member at its best epoch (the bounds: now).
    pub best: GaussianEnsemble,
    /// Adam's state, moments by module path (either kernel's).
    pub adam: AdamState,
}

/// Fits `config`'s ensemble to `dataset`, its members trained by `kernel`
/// (burn's on `device`), continuing from `resume` when given (a state this
/// dataset and config produced). `on_epoch` sees the state after every epoch
/// (to report, or to checkpoint it); an error it returns stops the fit.
pub fn fit_ensemble(
    dataset: &Dataset,
    config: &EnsembleConfig,
    kernel: Kernel,
    device: &Device,
    resume: Option<EnsembleFitState>,
    on_epoch: &mut dyn FnMut(&EnsembleFitState) -> Result<(), EnsembleError>,
) -> Result<EnsembleFit, EnsembleError> {
    config.validate()?;
    let rows = Rows::of(dataset);
    let n = dataset.len();
    let holdout = ((n as f64 * config.holdout_fraction) as usize).min(config.max_holdout);
    if holdout == 0 || holdout >= n {
        return Err(EnsembleError::Config(format!(
            "{n} transitions leave no holdout or no training set"
        )));
    }
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let mut order: Vec<usize> = (0..n).collect();
    order.shuffle(&mut rng);
    let (holdout_index, train_index) = order.split_at(holdout);
    let scaler = Scaler::fit(&rows, train_index);
    let mut holdout_batch = MemberBatch::default();
    rows.gather(holdout_index, &scaler, &mut holdout_batch);

    let train_device = device.clone().autodiff();
    let model = seeded_init(&train_device, config.seed, || {
        GaussianEnsemble::init(
            rows.d_in,
            rows.d_out,
            &config.hidden,
            config.members,
            (config.max_logvar_init, config.min_logvar_init),
            &train_device,
        )
    });
    // Each member's bootstrap resample of the training rows, drawn once.
    let resamples: Vec<Vec<usize>> = (0..config.members)
        .map(|_| {
            (0..train_index.len())
                .map(|_| train_index[rng.random_range(0..train_index.len())])
                .collect()
        })
        .collect();
    let run = FitRun {
        rows: &rows,
        holdout: &holdout_batch,
        scaler: &scaler,
        resamples,
        config,
    };
    let terms = LossTerms::of(config);
    let (model, best_mse, history) = match kernel {
        Kernel::Burn => run.train(BurnTrainer::new(model, terms), resume, on_epoch)?,
        Kernel::Fused => run.train(FusedTrainer::new(model.valid(), terms), resume, on_epoch)?,
    };
    let mut ranked: Vec<usize> = (0..config.members).collect();
    ranked.sort_by(|&a, &b| best_mse[a].total_cmp(&best_mse[b]));
    ranked.truncate(config.elites);
    Ok(EnsembleFit {
        model,
        scaler,
        elites: ranked,
        holdout_mse: best_mse,
        history,
    })
}

/// Where a fit stands: each member's best holdout MSE and its weights then,
/// the epochs so far, and how many of the last improved no member.
struct Progress<M> {
    best_mse: Vec<f32>,
    best: Vec<M>,
    history: Vec<EnsembleEpoch>,
    since_update: usize,
}

impl<M> Progress<M> {
    fn fresh<T: EnsembleTrainer<Member = M>>(trainer: &T, members: usize) -> Self {
        Self {
            best_mse: vec![f32::INFINITY; members],
            best: (0..members).map(|m| trainer.member(m)).collect(),
            history: Vec::new(),
            since_update: 0,
        }
    }

    /// The checkpoint's progress, its current weights and Adam's state restored
    /// into `trainer`.
    fn resumed<T: EnsembleTrainer<Member = M>>(
        trainer: &mut T,
        state: EnsembleFitState,
        members: usize,
    ) -> Result<Self, EnsembleError> {
        if state.best_mse.len() != members
            || state.current.members.len() != members
            || state.best.members.len() != members
        {
            return Err(EnsembleError::Config(format!(
                "the checkpoint holds {} members, the config {members}",
                state.current.members.len(),
            )));
        }
        trainer.restore(&state.current, state.adam);
        Ok(Self {
            best: state
                .best
                .members
                .iter()
                .map(|m| trainer.member_of(m))
                .collect(),
            best_mse: state.best_mse,
            history: state.history,
            since_update: state.since_update,
        })
    }

    /// Keeps each member whose holdout MSE improved on its best by more than
    /// `min_improvement` (relative); whether any did.
    fn keep_improved<T: EnsembleTrainer<Member = M>>(
        &mut self,
        trainer: &T,
        holdout_mse: &[f32],
        min_improvement: f64,
    ) -> bool {
        let mut improved = false;
        for (m, &mse) in holdout_mse.iter().enumerate() {
            let best = self.best_mse[m];
            if best.is_infinite() || (best - mse) / best > min_improvement as f32 {
                self.best_mse[m] = mse;
                self.best[m] = trainer.member(m);
                improved = true;
            }
        }
        improved
    }

    /// The checkpoint of this point of the fit.
    fn state<T: EnsembleTrainer<Member = M>>(&self, trainer: &T) -> EnsembleFitState {
        let members = self.best.len();
        let current: Vec<M> = (0..members).map(|m| trainer.member(m)).collect();
        EnsembleFitState {
            history: self.history.clone(),
            since_update: self.since_update,
            best_mse: self.best_mse.clone(),
            current: trainer.model_with(&current),
            best: trainer.model_with(&self.best),
            adam: trainer.optimizer_state(),
        }
    }
}

/// The data side of a fit: which rows each member sees, in which order.
struct FitRun<'a> {
    rows: &'a Rows,
    holdout: &'a MemberBatch,
    scaler: &'a Scaler,
    resamples: Vec<Vec<usize>>,
    config: &'a EnsembleConfig,
}

impl FitRun<'_> {
    /// Epochs until MOPO's stop (or the cap), from `resume` when given: the
    /// model with each member at its best epoch, each member's best holdout
    /// MSE, and the history.
    fn train<T: EnsembleTrainer>(
        &self,
        mut trainer: T,
        resume: Option<EnsembleFitState>,
        on_epoch: &mut dyn FnMut(&EnsembleFitState) -> Result<(), EnsembleError>,
    ) -> Result<(GaussianEnsemble, Vec<f32>, Vec<EnsembleEpoch>), EnsembleError> {
        let config = self.config;
        let mut progress = match resume {
            Some(state) => Progress::resumed(&mut trainer, state, config.members)?,
            None => Progress::fresh(&trainer, config.members),
        };
        let mut batches = vec![MemberBatch::default(); config.members];
        while progress.since_update < config.max_epochs_since_update
            && config
                .max_epochs
                .is_none_or(|cap| progress.history.len() < cap)
        {
            let epoch = progress.history.len() + 1;
            let train_loss = self.train_epoch(&mut trainer, epoch, &mut batches);
            let holdout_mse = trainer.holdout_mse(self.holdout);
            let improved = progress.keep_improved(&trainer, &holdout_mse, config.min_improvement);
            progress.since_update = if improved {
                0
            } else {
                progress.since_update + 1
            };
            progress.history.push(EnsembleEpoch {
                epoch,
                train_loss,
                holdout_mse,
                improved,
            });
            on_epoch(&progress.state(&trainer))?;
        }
        Ok((
            trainer.model_with(&progress.best),
            progress.best_mse,
            progress.history,
        ))
    }

    /// One pass over every member's resample in minibatches; the mean loss.
    fn train_epoch<T: EnsembleTrainer>(
        &self,
        trainer: &mut T,
        epoch: usize,
        batches: &mut [MemberBatch],
    ) -> f64 {
        let batch_size = self.config.batch_size;
        let train_rows = self.resamples[0].len();
        let orders = self.epoch_orders(epoch);
        let mut losses = Vec::new();
        for start in (0..train_rows).step_by(batch_size) {
            let end = (start + batch_size).min(train_rows);
            for (batch, order) in batches.iter_mut().zip(&orders) {
                self.rows.gather(&order[start..end], self.scaler, batch);
            }
            losses.push(trainer.step(batches));
        }
        losses.iter().sum::<f64>() / losses.len().max(1) as f64
    }

    /// Each member's order of its resample in `epoch`: a fresh permutation
    /// from the seed's stream `epoch`, so a resumed fit sees what it would have.
    fn epoch_orders(&self, epoch: usize) -> Vec<Vec<usize>> {
        let mut rng = ChaCha8Rng::seed_from_u64(self.config.seed);
        rng.set_stream(epoch as u64);
        self.resamples
            .iter()
            .map(|resample| {
                let mut order = resample.clone();
                order.shuffle(&mut rng);
                order
            })
            .collect()
    }
}
