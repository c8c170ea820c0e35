//! fit-policy for the methods that learn from the dataset alone (bc, td3-bc, cql, edac):
//! the same flags, run record, checkpoints, metrics and policies as the
//! model-based methods, with no model.

use std::path::PathBuf;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use nuno::agent::{LearnerConfig, Method, ModelFreeConfig, ModelFreeTraining, Preset};
use nuno::artifact::{
    BEST_POLICY, LAST_POLICY, PolicyProvenance, load_model_free_checkpoint,
    save_model_free_checkpoint, save_policy, sha256_file,
};
use nuno::data::read_system_dataset;
use nuno::envs::{ObservationLayout, System, TaskName};
use serde::Serialize;

use super::{Args, Plan, write_metrics};
use crate::data_source::system_of;
use crate::resume::checkpoint_to_resume;
use crate::run_record::write_run_record;

/// A model-free run: the data's system and the method's settings.
#[derive(Debug, Serialize)]
pub struct ModelFreePlan {
    /// The built-in task the data is of (`--task`, or the preset's).
    pub task: Option<TaskName>,
    pub layout: ObservationLayout,
    /// Or the system file (`--system`).
    pub system: Option<PathBuf>,
    pub config: ModelFreeConfig,
}

impl ModelFreePlan {
    fn system(&self) -> anyhow::Result<System> {
        let neorl = self.layout == ObservationLayout::Neorl;
        system_of(self.task, self.system.as_deref(), neorl)
    }
}

impl Args {
    /// A model-free method's plan: its reference settings with the budget's
    /// flags over them; the model-based flags refused.
    pub(super) fn model_free_plan(
        &self,
        preset: Option<&'static Preset>,
    ) -> anyhow::Result<ModelFreePlan> {
        let algo = self.algo;
        let in_model_flags = [
            (self.model.is_some(), "--model"),
            (self.horizon.is_some(), "--horizon"),
            (self.cvar_alpha.is_some(), "--cvar-alpha"),
            (self.penalty.is_some(), "--penalty"),
            (self.no_truncation, "--no-truncation"),
            (self.rollout_batch.is_some(), "--rollout-batch"),
            (self.model_buffer_factor.is_some(), "--model-buffer-factor"),
            (self.forward_velocity.is_some(), "--forward-velocity"),
            (self.root_x_reward.is_some(), "--root-x-reward"),
            (self.real_ratio.is_some(), "--real-ratio"),
            (self.combo_weight.is_some(), "--combo-weight"),
            (self.halt_penalty.is_some(), "--halt-penalty"),
            (self.state_box_margin.is_some(), "--state-box-margin"),
            (self.clip_observations, "--clip-observations"),
            (self.rollout_noise_scale.is_some(), "--rollout-noise-scale"),
            (self.target_entropy.is_some(), "--target-entropy"),
        ];
        if let Some((_, flag)) = in_model_flags.iter().find(|(given, _)| *given) {
            anyhow::bail!(
                "--algo {algo} learns from the dataset alone: {flag} is for the model-based methods"
            );
        }
        let (task, layout) = match (self.task, preset) {
            (Some(task), Some(p)) if p.task != task => {
                anyhow::bail!(
                    "--task {task} and the preset {} ({}) disagree",
                    p.name,
                    p.task
                )
            }
            (Some(task), _) => (Some(task), layout_of(self.neorl)),
            (None, Some(p)) if self.system.is_none() => (Some(p.task), p.layout),
            (None, _) => (None, layout_of(self.neorl)),
        };
        anyhow::ensure!(
            task.is_some() || self.system.is_some(),
            "--algo {algo} needs the data's system: --task, --system or a --preset naming a task"
        );
        let mut learner = self.learner(preset)?;
        learner.set_batch_size(self.batch_size);
        if let Some(hidden) = &self.hidden {
            learner.set_hidden(hidden);
        }
        Ok(ModelFreePlan {
            task,
            layout,
            system: self.system.clone(),
            config: ModelFreeConfig {
                learner,
                steps_per_epoch: self.steps_per_epoch,
                epochs: self.steps.div_ceil(self.steps_per_epoch),
                eval_episodes: self.eval_episodes,
                seed: self.seed,
            },
        })
    }
}

impl Args {
    /// The method's reference settings; EDAC's N and η from its table for the
    /// preset's dataset unless both flags give them.
    fn learner(&self, preset: Option<&'static Preset>) -> anyhow::Result<LearnerConfig> {
        let algo = self.algo;
        let flags = (self.edac_critics, self.edac_eta);
        if algo != Method::Edac {
            anyhow::ensure!(
                flags == (None, None),
                "--edac-critics and --edac-eta are EDAC's: they need --algo edac"
            );
            return Ok(LearnerConfig::for_method(algo)?);
        }
        let mut learner = match (flags, preset) {
            ((Some(_), Some(_)), _) => LearnerConfig::for_method(algo)?,
            (_, Some(preset)) => LearnerConfig::for_dataset(algo, preset.name)?,
            (_, None) => anyhow::bail!(
                "--algo edac takes its critics and η per dataset: give a --preset OfflineRL-Kit has them for, or --edac-critics and --edac-eta"
            ),
        };
        if let LearnerConfig::Edac(c) = &mut learner {
            anyhow::ensure!(flags.0 != Some(0), "--edac-critics must be at least 1");
            c.num_critics = flags.0.unwrap_or(c.num_critics);
            c.eta = flags.1.unwrap_or(c.eta);
        }
        Ok(learner)
    }
}

fn layout_of(neorl: bool) -> ObservationLayout {
    if neorl {
        ObservationLayout::Neorl
    } else {
        ObservationLayout::D4rl
    }
}

/// Reads the dataset, then trains epoch by epoch from the start or from the
/// last checkpoint, saving the best and last policies.
pub fn train(plan: &Plan, run: &ModelFreePlan) -> anyhow::Result<()> {
    let device = plan.device.device().map_err(anyhow::Error::msg)?;
    let system = run.system()?;
    let dataset = read_system_dataset(&plan.dataset, plan.format, &system)?;
    let mut training = ModelFreeTraining::new(run.config.clone(), &dataset, &system, &device)?;
    let dataset_sha256 = (plan.dataset.is_file())
        .then(|| sha256_file(&plan.dataset))
        .transpose()?;
    let checkpoints = plan.out.join("checkpoints");
    if let Some(checkpoint) = checkpoint_to_resume(&checkpoints, plan.resume, &plan.out, "a run")? {
        load_model_free_checkpoint(&checkpoint, &mut training)
            .with_context(|| format!("resuming from {}", checkpoint.display()))?;
        println!(
            "resumed from {} (epoch {})",
            checkpoint.display(),
            training.epoch
        );
    }
    write_run_record(&plan.out, "fit-policy", plan, &[&plan.dataset])?;
    let total = training.config.epochs * training.config.steps_per_epoch;
    let bar = ProgressBar::new(total as u64).with_style(ProgressStyle::with_template(
        "{bar:30} {pos}/{len} steps | {msg}",
    )?);
    bar.set_position(training.step as u64);
    std::fs::create_dir_all(&plan.policies)
        .with_context(|| format!("creating {}", plan.policies.display()))?;
    while training.epoch < training.config.epochs {
        let record = training.run_epoch(&dataset, plan.kernel)?;
        bar.set_position(training.step as u64);
        bar.set_message(format!(
            "updates/s {:.1} | {} {:.1}",
            record.sps,
            record.eval.score_name(),
            record.eval.score()
        ));
        save_policies(plan, &system, dataset_sha256.as_deref(), &training)?;
        save_model_free_checkpoint(&checkpoints, &training)?;
        write_metrics(&plan.out, &training.history)?;
    }
    bar.finish();
    Ok(())
}

/// The last policy after every epoch, and the best so far when this epoch's
/// score ties or beats every earlier one.
fn save_policies(
    plan: &Plan,
    system: &System,
    dataset_sha256: Option<&str>,
    training: &ModelFreeTraining,
) -> anyhow::Result<()> {
    let Some(record) = training.history.last() else {
        return Ok(());
    };
    let provenance = || PolicyProvenance {
        preset: plan.preset.map(|p| p.name.to_string()),
        dataset_sha256: dataset_sha256.map(String::from),
        epoch: record.epoch,
        step: record.step,
        normalized_score: Some(record.eval.normalized_score),
        mean_return: Some(record.eval.mean_return),
        model_free_training: Some(training.config.clone()),
        algorithm: Some(plan.method.to_string()),
        ..PolicyProvenance::default()
    };
    let actor = training.actor();
    save_policy(&plan.policies, LAST_POLICY, &actor, system, provenance())?;
    let best = (training.history.iter())
        .map(|r| r.eval.score())
        .fold(f64::NEG_INFINITY, f64::max);
    if record.eval.score() >= best {
        save_policy(&plan.policies, BEST_POLICY, &actor, system, provenance())?;
    }
    Ok(())
}
