//! Fitting the neural SDE (Section 4.2, Appendix C.4), top to bottom: measure
//! scales, initialise, then Adam on eq. 7 over windows of H = 2 steps with the
//! learning rate decayed linearly 1e-2 → 1e-3 over 5000 steps, validation NLL
//! on held-out trajectories, early stopping on it, and the best model kept;
//! the whole state at every validation for checkpoints ([`fit_from`]).

use std::time::Instant;

use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::{Device, Tensor, TensorData};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::SdeError;
use super::config::{FitConfig, LossConfig};
use super::eta::FarField;
use super::fit_step::{BurnSdeTrainer, SdeTrainer, StepDraws, StepLosses, StepSettings};
use super::fused_fit::FusedSdeTrainer;
use super::losses::WindowTensors;
use super::model::NeuralSde;
use super::spec::{DynamicsSpec, PhysicalScales};
use crate::data::{Dataset, NormalizerConfig, WindowBatch, WindowSampler};
use crate::infer::Kernel;
use crate::nn::{AdamState, normal, seeded_init, standard_normal};
use crate::shared::{SeedStream, derive_seed};

/// Losses at one logged step (and the validation NLL when it was measured).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FitRecord {
    pub step: usize,
    pub learning_rate: f64,
    /// Every term, before the step's update (L_far 0 while λ_far = 0: no
    /// point is tested for being far then).
    #[serde(flatten)]
    pub losses: StepLosses,
    pub valid_nll: Option<f32>,
}

/// How fitting went.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FitSummary {
    pub steps: usize,
    pub best_step: usize,
    pub best_valid_nll: f32,
    pub stopped_early: bool,
    pub seconds: f64,
    pub train_transitions: usize,
    pub valid_transitions: usize,
}

/// Turns sampled windows into tensors; for NUNO^R the cumulative reward r_c
/// (0 at the window's start) is appended to each state.
pub fn window_tensors(
    batch: &WindowBatch,
    obs_dim: usize,
    reward_model: bool,
    device: &Device,
) -> WindowTensors {
    let (b, h) = (batch.batch, batch.horizon);
    let act_dim = batch.actions.len() / (b * h).max(1);
    let state_dim = obs_dim + usize::from(reward_model);
    let states = window_states(batch, obs_dim, reward_model);
    WindowTensors {
        states: Tensor::from_data(TensorData::new(states, [b, h + 1, state_dim]), device),
        actions: Tensor::from_data(
            TensorData::new(batch.actions.clone(), [b, h, act_dim]),
            device,
        ),
    }
}

/// The windows' states `[batch, horizon + 1, state_dim]`, r_c appended for NUNO^R.
pub(super) fn window_states(batch: &WindowBatch, obs_dim: usize, reward_model: bool) -> Vec<f32> {
    let (b, h) = (batch.batch, batch.horizon);
    let state_dim = obs_dim + usize::from(reward_model);
    if reward_model {
        let mut states = Vec::with_capacity(b * (h + 1) * state_dim);
        for w in 0..b {
            let mut cumulative = 0.0;
            for k in 0..=h {
                let row = (w * (h + 1) + k) * obs_dim;
                states.extend_from_slice(&batch.states[row..row + obs_dim]);
                states.push(cumulative);
                if k < h {
                    cumulative += batch.rewards[w * h + k];
                }
            }
        }
        states
    } else {
        batch.states.clone()
    }
}

/// Mean L_data of `model` over the given windows with fixed noise, in chunks.
pub fn validation_nll(
    model: &NeuralSde,
    windows: &WindowSampler,
    starts: &[usize],
    loss: &LossConfig,
    seed: u64,
    device: &Device,
) -> f32 {
    const CHUNK: usize = 512;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let state_dim = model.constants.state_dim();
    let mut total = 0.0;
    for chunk in starts.chunks(CHUNK) {
        let batch = windows.gather(chunk);
        let tensors = window_tensors(
            &batch,
            model.spec().obs_dim,
            model.constants.config.reward_model,
            device,
        );
        let noise = normal([chunk.len(), batch.horizon, state_dim], &mut rng, device);
        let (nll, _) = model.data_nll(&tensors, noise, loss.likelihood, loss.step_discount);
        total += nll.into_scalar::<f32>() * chunk.len() as f32;
    }
    total / starts.len() as f32
}

/// Where a fit stands at one of its evaluations: enough to continue it
/// exactly as if it had not stopped.
#[derive(Debug, Clone)]
pub struct SdeFitState {
    /// Gradient steps taken.
    pub step: usize,
    /// Every record logged so far.
    pub records: Vec<FitRecord>,
    /// The model now (its config holds h's calibrated bias).
    pub current: NeuralSde,
    /// The model at the best validation NLL so far, and where that was.
    pub best: NeuralSde,
    pub best_nll: f32,
    pub best_step: usize,
    pub evals_without_improvement: usize,
    /// Adam's state, moments by module path.
    pub adam: AdamState,
    /// The generator's position (batches, noise, far-field samples).
    pub rng: ChaCha8Rng,
}

/// Fits a neural SDE on `train`, early-stopping on `valid`; `on_record` sees
/// every logged step. Returns the best model (without autodiff) and a summary.
pub fn fit(
    train: &Dataset,
    valid: &Dataset,
    spec: DynamicsSpec,
    config: &FitConfig,
    device: &Device,
    on_record: &mut dyn FnMut(&FitRecord),
) -> Result<(NeuralSde, FitSummary), SdeError> {
    fit_from(
        train,
        valid,
        spec,
        config,
        device,
        None,
        on_record,
        &mut |_| Ok(()),
    )
}

/// [`fit`], continuing from `resume` when given (a state the same data and
/// config produced, up to `max_steps`), with `on_evaluation` seeing the state
/// after every validation (to checkpoint it; an error it returns stops the fit).
#[allow(clippy::too_many_arguments)]
pub fn fit_from(
    train: &Dataset,
    valid: &Dataset,
    spec: DynamicsSpec,
    config: &FitConfig,
    device: &Device,
    resume: Option<SdeFitState>,
    on_record: &mut dyn FnMut(&FitRecord),
    on_evaluation: &mut dyn FnMut(&SdeFitState) -> Result<(), SdeError>,
) -> Result<(NeuralSde, FitSummary), SdeError> {
    spec.validate()?;
    config.validate(spec.obs_dim)?;
    let started = Instant::now();
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let train_windows = WindowSampler::new(train, config.horizon)?;
    let validation = Validation::new(valid, config, device)?;

    let FitStart {
        mut trainer,
        reference,
        draws,
    } = FitStart::new(train, spec, config, device, &mut rng);

    let mut state = SdeFitState::start(trainer.model(), &validation, rng);
    if let Some(resumed) = resume {
        state.resume_from(resumed, trainer.as_mut())?;
    }
    while state.step < config.max_steps && state.evals_without_improvement < config.patience {
        // eq. 7 on a batch of windows of horizon H.
        let lr = config.learning_rate(state.step);
        let step_draws = draws.draw(config, &train_windows, &mut state.rng);
        let terms = trainer.step(&step_draws, lr);
        state.step += 1;
        let step = state.step;
        if step.is_multiple_of(config.h_bias_every) {
            trainer.calibrate_h_bias(&reference);
        }

        let record = FitRecord {
            step,
            learning_rate: lr,
            losses: terms,
            valid_nll: None,
        };
        log_step(
            &mut state,
            trainer.as_ref(),
            &validation,
            config,
            record,
            on_record,
            on_evaluation,
        )?;
    }
    let summary = FitSummary {
        steps: state.step,
        best_step: state.best_step,
        best_valid_nll: state.best_nll,
        stopped_early: state.step < config.max_steps,
        seconds: started.elapsed().as_secs_f64(),
        train_transitions: train.len(),
        valid_transitions: valid.len(),
    };
    Ok((state.best, summary))
}

/// What a fit starts from: the kernel with the seed's networks on the training
/// data's scales, the reference inputs h's bias is calibrated on (calibrated
/// once already), and the shapes of each step's draws.
struct FitStart {
    trainer: Box<dyn SdeTrainer>,
    reference: Vec<f32>,
    draws: DrawShapes,
}

impl FitStart {
    fn new(
        train: &Dataset,
        spec: DynamicsSpec,
        config: &FitConfig,
        device: &Device,
        rng: &mut ChaCha8Rng,
    ) -> Self {
        // Scales from the training data; networks initialised from the seed.
        let scales = PhysicalScales::measure(
            train,
            &spec,
            &NormalizerConfig {
                std_floor: config.std_floor,
            },
        );
        let train_device = device.clone().autodiff();
        let model = seeded_init(&train_device, config.seed, || {
            NeuralSde::init(spec, scales, config.model.clone(), &train_device)
        });
        let reference = training_inputs(&model, train, config.loss.far_reference, rng);
        let input_dim = model.spec().obs_dim + model.spec().act_dim;
        let draws = DrawShapes {
            state_dim: model.constants.state_dim(),
            far_field: FarField::new(reference.clone(), input_dim, &config.loss),
            input_dim,
        };
        let mut trainer = sde_trainer(model, config, train_device);
        trainer.calibrate_h_bias(&reference);
        Self {
            trainer,
            reference,
            draws,
        }
    }
}

/// The kernel `config` names, taking its gradient steps from `model`.
fn sde_trainer(model: NeuralSde, config: &FitConfig, train_device: Device) -> Box<dyn SdeTrainer> {
    let settings = StepSettings::of(config);
    match config.kernel {
        Kernel::Burn => Box::new(BurnSdeTrainer::new(model, settings, train_device)),
        Kernel::Fused => Box::new(FusedSdeTrainer::new(model.valid(), settings)),
    }
}

/// Logging and early stopping after a step, kept apart from the algorithm: `record` every
/// `log_every` steps and, at every evaluation, the validation NLL, the best model so far and
/// the state handed to `on_evaluation`.
fn log_step(
    state: &mut SdeFitState,
    trainer: &dyn SdeTrainer,
    validation: &Validation,
    config: &FitConfig,
    mut record: FitRecord,
    on_record: &mut dyn FnMut(&FitRecord),
    on_evaluation: &mut dyn FnMut(&SdeFitState) -> Result<(), SdeError>,
) -> Result<(), SdeError> {
    let step = state.step;
    let evaluate = step.is_multiple_of(config.eval_every) || step == config.max_steps;
    if !(step.is_multiple_of(config.log_every) || evaluate) {
        return Ok(());
    }
    if evaluate {
        state.current = trainer.model();
        let nll = validation.nll(&state.current);
        record.valid_nll = Some(nll);
        state.offer_current(nll);
    }
    on_record(&record);
    state.records.push(record);
    if evaluate {
        state.adam = trainer.optimizer_state();
        on_evaluation(state)?;
    }
    Ok(())
}

/// The fixed validation windows every evaluation scores, with the fit's noise.
struct Validation<'a> {
    windows: WindowSampler<'a>,
    starts: Vec<usize>,
    loss: &'a LossConfig,
    seed: u64,
    device: &'a Device,
}

impl<'a> Validation<'a> {
    /// `config.valid_windows` windows of `valid`, drawn (with replacement) from their own stream.
    fn new(
        valid: &'a Dataset,
        config: &'a FitConfig,
        device: &'a Device,
    ) -> Result<Self, SdeError> {
        let windows = WindowSampler::new(valid, config.horizon)?;
        let all = windows.starts();
        let mut pick =
            ChaCha8Rng::seed_from_u64(derive_seed(config.seed, SeedStream::ValidWindows));
        let starts = (0..config.valid_windows.min(all.len()))
            .map(|_| all[pick.random_range(0..all.len())])
            .collect();
        Ok(Self {
            windows,
            starts,
            loss: &config.loss,
            seed: config.seed,
            device,
        })
    }

    fn nll(&self, model: &NeuralSde) -> f32 {
        validation_nll(
            model,
            &self.windows,
            &self.starts,
            self.loss,
            self.seed,
            self.device,
        )
    }
}

/// The sizes of one step's random draws, and L_far's sampler.
struct DrawShapes {
    state_dim: usize,
    input_dim: usize,
    far_field: FarField,
}

impl DrawShapes {
    /// One gradient step's draws, in the fit's order: windows, the particles' noise,
    /// L_sc's ball offsets, L_far's points.
    fn draw(&self, config: &FitConfig, windows: &WindowSampler, rng: &mut ChaCha8Rng) -> StepDraws {
        let batch = config.batch_size;
        let windows = windows.sample(batch, rng);
        let step_noise = standard_normal(batch * config.horizon * self.state_dim, rng);
        let samples = batch * config.loss.convexity_samples;
        let ball_noise = standard_normal(samples * self.input_dim, rng);
        // Off, L_far's points are drawn (the same stream either way) but none is far.
        let (far_points, far_mask) = if config.loss.lambda_far > 0.0 {
            self.far_field.sample_values(batch, rng)
        } else {
            (self.far_field.sample_points(batch, rng), vec![0.0; batch])
        };
        StepDraws {
            windows,
            step_noise,
            ball_noise,
            far_points,
            far_mask,
        }
    }
}

impl SdeFitState {
    /// Before the first step: the initial model is the best so far, at its validation NLL.
    fn start(model: NeuralSde, validation: &Validation, rng: ChaCha8Rng) -> Self {
        let best_nll = validation.nll(&model);
        Self {
            step: 0,
            records: Vec::new(),
            current: model.clone(),
            best: model,
            best_nll,
            best_step: 0,
            evals_without_improvement: 0,
            adam: AdamState::default(),
            rng,
        }
    }

    /// Continues from `resumed`, refusing one fitted on other data, and hands its model and
    /// Adam's moments to `trainer`.
    fn resume_from(
        &mut self,
        resumed: SdeFitState,
        trainer: &mut dyn SdeTrainer,
    ) -> Result<(), SdeError> {
        let fresh = &self.best.constants;
        if resumed.current.constants.spec != fresh.spec
            || resumed.current.constants.scales != fresh.scales
        {
            return Err(SdeError::Config(
                "the checkpoint was fitted on other data (its scales differ)".into(),
            ));
        }
        trainer.restore(&resumed.current, resumed.adam.clone());
        *self = resumed;
        Ok(())
    }

    /// Early stopping's bookkeeping for the model just evaluated at `nll`.
    fn offer_current(&mut self, nll: f32) {
        if nll < self.best_nll {
            (self.best, self.best_nll, self.best_step) = (self.current.clone(), nll, self.step);
            self.evals_without_improvement = 0;
        } else {
            self.evals_without_improvement += 1;
        }
    }
}

/// A fixed random subset of the training data's normalised `(s, a)`, row-major:
/// L_far's reference, and where h(η)'s b is calibrated.
fn training_inputs(
    model: &NeuralSde,
    train: &Dataset,
    count: usize,
    rng: &mut ChaCha8Rng,
) -> Vec<f32> {
    let normalizer = &model.constants.scales.normalizer;
    let (obs_dim, act_dim) = (train.obs_dim(), train.act_dim());
    let mut reference = Vec::with_capacity(count * (obs_dim + act_dim));
    for _ in 0..count.min(train.len()) {
        let i = rng.random_range(0..train.len());
        let mut state = train.observations.row(i).to_vec();
        let mut action = train.actions.row(i).to_vec();
        normalizer.state.normalize(&mut state);
        normalizer.action.normalize(&mut action);
        reference.extend(state);
        reference.extend(action);
    }
    reference
}

/// Fits η_ϕ and μ_ϕ alone on points (already normalised), with the η terms of
/// eq. 7: a distance-aware score for any point cloud (Appendix B.2's toy
/// examples), and the same losses the SDE fit uses.
///
/// # Shapes
/// - `points`: row-major `[n, dim]`
pub fn fit_eta(
    points: &[f32],
    dim: usize,
    config: &FitConfig,
    device: &Device,
) -> Result<super::DistanceAware, SdeError> {
    config.loss.validate()?;
    if dim == 0 || points.is_empty() || !points.len().is_multiple_of(dim) {
        return Err(SdeError::Spec(format!(
            "fit_eta: {} values do not form rows of width {dim}",
            points.len()
        )));
    }
    let train_device = device.clone().autodiff();
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let mut model = seeded_init(&train_device, config.seed, || {
        super::DistanceAware::init(dim, &config.model, &train_device)
    });
    let mut optimizer = AdamConfig::new().with_epsilon(config.adam_epsilon).init();
    let n = points.len() / dim;
    let reference: Vec<f32> = (0..config.loss.far_reference.min(n))
        .flat_map(|_| {
            let i = rng.random_range(0..n);
            points[i * dim..(i + 1) * dim].to_vec()
        })
        .collect();
    let far_field = FarField::new(reference, dim, &config.loss);
    for step in 0..config.max_steps {
        let rows: Vec<f32> = (0..config.batch_size)
            .flat_map(|_| {
                let i = rng.random_range(0..n);
                points[i * dim..(i + 1) * dim].iter().copied()
            })
            .collect();
        let x = Tensor::from_data(
            TensorData::new(rows, [config.batch_size, dim]),
            &train_device,
        );
        let noise = normal(
            [config.batch_size * config.loss.convexity_samples, dim],
            &mut rng,
            &train_device,
        );
        let far = far_field.sample(config.batch_size, &mut rng, &train_device);
        let total = model
            .losses(x, noise, far, &config.loss)
            .weighted(&config.loss);
        let grads = GradientsParams::from_grads(total.backward(), &model);
        model = optimizer.step(config.learning_rate(step), model, grads);
    }
    Ok(model.valid())
}
