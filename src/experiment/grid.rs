//! The grid file of an experiment (TOML): datasets × methods × seeds under one
//! step budget, expanded into cells in a fixed order, every name checked
//! before anything runs.
//!
//! ```toml
//! [budget]
//! model_steps = 5000        # fit-model's --max-steps
//! model_likelihood = "data" # fit-model's --likelihood (optional; default "particle")
//! recipe = "code"           # fit-model's and NUNO's fit-policy's --recipe (optional; default "paper")
//! model_sample_noise = "sqrt-dt"  # fit-model's --sample-noise (optional; default: the recipe's)
//! model_step_discount = 0.9 # fit-model's --step-discount (optional; default: the recipe's)
//! model_eta_losses = "code" # fit-model's --eta-losses (optional; default: the recipe's)
//! model_drift_inputs = "pose" # fit-model's --drift-inputs (optional; default: the recipe's)
//! threshold_max_margin = 1.1 # fit-model's --threshold-max-margin, ε(h, α ≥ 1) (optional; default: the recipe's)
//! model_buffer_factor = 10  # fit-policy's --model-buffer-factor (optional; default: the recipe's)
//! forward_velocity = "mean" # NUNO's fit-policy --forward-velocity (optional; default: the recipe's)
//! root_x_reward = "velocity" # NUNO's fit-policy --root-x-reward, on NeoRL's rows (optional; default: "difference")
//! rollout_batch = 5000      # fit-policy's --rollout-batch, every method (optional; default: each method's)
//! state_box_margin = 0.5    # fit-policy's --state-box-margin, every model-based method (optional; default: none)
//! clip_observations = true  # fit-policy's --clip-observations, every model-based method (optional; default: false)
//! target_entropy = -3.0     # fit-policy's --target-entropy, every model-based method (optional; default: −|A|)
//! penalty = 5.0             # NUNO's fit-policy --penalty, λ_pen over every row's (optional; default: the row's)
//! rollout_noise_scale = 0.0 # fit-policy's --rollout-noise-scale, every model-based method (optional; default: the model's)
//! truncated_step = "terminal" # fit-policy's --truncated-step, NUNO's methods and TATU+MOPO (optional; default: "drop")
//! mopo_settings = "nuno"    # MOPO's and NUNO's fit-policy --mopo-settings (optional; default: each method's own)
//! ensemble_max_epochs = 100 # fit-ensemble's --max-epochs (optional)
//! policy_steps = 100000     # fit-policy's --steps (the same for every method)
//! steps_per_epoch = 1000
//! eval_episodes = 10
//!
//! [[datasets]]
//! name = "hopper-random"
//! file = "data/hopper-random.hdf5"   # relative to the grid file
//! task = "hopper"
//! preset = "hopper-random"           # Table 3 row: h, α, λ_pen
//! # The baselines' settings where their tables have no row for the preset (optional):
//! rambo = { horizon = 2, weight = 3e-4 }    # RAMBO's h and w_adv
//! combo = { horizon = 5, weight = 5.0 }     # COMBO's h and β
//! edac = { critics = 50, eta = 1.0 }        # EDAC's N and η
//! methods = ["nuno", "nuno-r", "nuno-al", "mopo", "tatu-mopo", "rambo", "combo", "edac"]
//! seeds = [0, 1, 2]
//!
//! [[datasets]]
//! name = "halfcheetah-random"
//! file = "data/halfcheetah-random.hdf5"
//! task = "halfcheetah"
//! preset = "halfcheetah-random"
//! model_drift_inputs = "pose"        # this row's SDEs, over the budget's (optional)
//! methods = ["nuno", "mopo"]
//! seeds = [0, 1, 2]
//!
//! [[datasets]]                       # a system described as data
//! name = "pendulum"
//! file = "pendulum/log.csv"
//! system = "pendulum/system.toml"    # relative to the grid file, in place of task
//! policy = { horizon = 10, cvar_alpha = 0.95, penalty = 1.0 }   # in place of preset
//! methods = ["nuno", "mopo"]
//! seeds = [0, 1, 2]
//! ```

use std::fmt;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::ExperimentError;
use crate::agent::{Method, MopoSettings, PolicyLoopConfig, SacConfig, TruncatedStep, preset};

use crate::envs::{ForwardVelocity, ObservationLayout, RootXReward, TaskConfig, TaskName};
use crate::sde::{DriftInputs, EtaLossForm, LikelihoodPath, Recipe, SampleNoise};

/// The step budget every cell gets.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Budget {
    /// fit-model's gradient steps (NUNO's SDE).
    pub model_steps: usize,
    /// fit-model's `--likelihood`: where each step of L_data starts (eq. 6's
    /// particle, the default, or the recorded data).
    #[serde(default = "default_likelihood")]
    pub model_likelihood: LikelihoodPath,
    /// `--recipe` of fit-model and of the SDE methods' fit-policy: the paper's
    /// settings (the default) or NUNO's code's.
    #[serde(default)]
    pub recipe: Recipe,
    /// fit-model's `--sample-noise` (default: the recipe's).
    #[serde(default)]
    pub model_sample_noise: Option<SampleNoise>,
    /// fit-model's `--step-discount` (default: the recipe's).
    #[serde(default)]
    pub model_step_discount: Option<f32>,
    /// fit-model's `--eta-losses` (default: the recipe's).
    #[serde(default)]
    pub model_eta_losses: Option<EtaLossForm>,
    /// fit-model's `--drift-inputs` (default: the recipe's).
    #[serde(default)]
    pub model_drift_inputs: Option<DriftInputs>,
    /// fit-model's `--threshold-max-margin`: ε(h, α ≥ 1) is this × the largest
    /// window's accumulated η (default: the recipe's).
    #[serde(default)]
    pub threshold_max_margin: Option<f32>,
    /// fit-policy's `--model-buffer-factor` (default: the recipe's).
    #[serde(default)]
    pub model_buffer_factor: Option<usize>,
    /// The SDE methods' fit-policy `--forward-velocity` (default: the recipe's).
    #[serde(default)]
    pub forward_velocity: Option<ForwardVelocity>,
    /// The SDE methods' fit-policy `--root-x-reward` (default: root x's
    /// difference). Results written before it had the difference, and read so.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub root_x_reward: Option<RootXReward>,
    /// A cap on fit-ensemble's epochs (MOPO; default: until its early stop).
    #[serde(default)]
    pub ensemble_max_epochs: Option<usize>,
    pub policy_steps: usize,
    #[serde(default = "default_steps_per_epoch")]
    pub steps_per_epoch: usize,
    #[serde(default = "default_eval_episodes")]
    pub eval_episodes: usize,
    /// fit-policy's `--rollout-batch`, for every method (default: each method's own,
    /// NUNO's 5000 and MOPO's by its `mopo_settings`).
    #[serde(default)]
    pub rollout_batch: Option<usize>,
    /// fit-policy's `--state-box-margin`, for every model-based method (default:
    /// none). Results written before it had none, and read so.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub state_box_margin: Option<f64>,
    /// fit-policy's `--clip-observations`, for every model-based method
    /// (default: off). Results written before it clipped nothing, and read so.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub clip_observations: bool,
    /// fit-policy's `--target-entropy`, for every model-based method (default:
    /// −|A|). Results written before it had −|A|, and read so.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target_entropy: Option<f64>,
    /// NUNO's fit-policy `--penalty`: λ_pen over every row's preset or policy
    /// settings (default: the row's). Results written before it had the row's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub penalty: Option<f64>,
    /// fit-policy's `--rollout-noise-scale`, for every model-based method
    /// (default: the model's own). Results written before it had the model's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rollout_noise_scale: Option<f32>,
    /// fit-policy's `--truncated-step`, for the methods whose rollouts truncate
    /// on accumulated uncertainty (default: drop). Results written before it
    /// dropped the step, and read so.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub truncated_step: Option<TruncatedStep>,
    /// fit-policy's `--mopo-settings` for MOPO, TATU+MOPO and NUNO's methods
    /// (default: each method's own, OfflineRL-Kit's for MOPO, NUNO's for
    /// NUNO). The grids run before it existed name "nuno".
    #[serde(default)]
    pub mopo_settings: Option<MopoSettings>,
    /// Hidden sizes of every method's networks (default: each method's own,
    /// `Method::default_hidden`).
    #[serde(default)]
    pub hidden: Option<Vec<usize>>,
}

impl Budget {
    /// Refuses a budget no cell can run, naming the key.
    fn validate(&self) -> Result<(), String> {
        if self.model_steps == 0
            || self.policy_steps == 0
            || self.steps_per_epoch == 0
            || self.rollout_batch == Some(0)
        {
            return Err("budget: model_steps, policy_steps, steps_per_epoch and rollout_batch must be at least 1".into());
        }
        if let Some(hidden) = &self.hidden
            && (hidden.is_empty() || hidden.contains(&0))
        {
            return Err("budget: hidden needs positive layer sizes".into());
        }
        if let Some(d) = self.model_step_discount
            && !(d > 0.0 && d <= 1.0)
        {
            return Err(format!(
                "budget: model_step_discount = {d} must lie in (0, 1]"
            ));
        }
        if let Some(m) = self.threshold_max_margin
            && !(m.is_finite() && m >= 1.0)
        {
            return Err(format!(
                "budget: threshold_max_margin = {m} must be finite and at least 1"
            ));
        }
        if self.model_buffer_factor == Some(0) {
            return Err("budget: model_buffer_factor = 0 must be at least 1".into());
        }
        if let Some(h) = self.target_entropy
            && !h.is_finite()
        {
            return Err(format!("budget: target_entropy = {h} must be finite"));
        }
        let non_negative = [
            ("state_box_margin", self.state_box_margin),
            ("penalty", self.penalty),
            (
                "rollout_noise_scale",
                self.rollout_noise_scale.map(f64::from),
            ),
        ];
        for (key, value) in non_negative {
            if let Some(v) = value
                && !(v.is_finite() && v >= 0.0)
            {
                return Err(format!("budget: {key} = {v} must be finite and at least 0"));
            }
        }
        Ok(())
    }

    /// The networks' hidden sizes `method` trains with: the budget's, else the method's own.
    pub fn hidden_for(&self, method: Method) -> Vec<usize> {
        self.hidden
            .clone()
            .unwrap_or_else(|| method.default_hidden())
    }

    /// The budget's model and rollout settings at their defaults and none set:
    /// what a model-free method's cells record.
    fn model_free_base() -> Budget {
        Budget {
            model_steps: 0,
            model_likelihood: default_likelihood(),
            recipe: Recipe::default(),
            model_sample_noise: None,
            model_step_discount: None,
            model_eta_losses: None,
            model_drift_inputs: None,
            threshold_max_margin: None,
            model_buffer_factor: None,
            forward_velocity: None,
            root_x_reward: None,
            ensemble_max_epochs: None,
            policy_steps: 0,
            steps_per_epoch: default_steps_per_epoch(),
            eval_episodes: default_eval_episodes(),
            rollout_batch: None,
            state_box_margin: None,
            clip_observations: false,
            target_entropy: None,
            penalty: None,
            rollout_noise_scale: None,
            truncated_step: None,
            mopo_settings: None,
            hidden: None,
        }
    }

    /// This budget as `method` runs it: the settings of the other kind of method
    /// at their defaults (an ensemble method fits no SDE and runs no NUNO loop;
    /// NUNO's methods run no MOPO; a model-free method neither), so a grid may change those without touching
    /// this method's finished cells; and the MOPO settings and rollout batch a
    /// grid leaves to the method resolved to what the method runs, so naming a
    /// default and leaving it out are the same budget.
    pub fn for_method(&self, method: Method) -> Budget {
        if method.is_model_free() {
            // No model and no rollouts: only the policy's budget is the method's.
            return Budget {
                policy_steps: self.policy_steps,
                steps_per_epoch: self.steps_per_epoch,
                eval_episodes: self.eval_episodes,
                hidden: Some(self.hidden_for(method)),
                ..Budget::model_free_base()
            };
        }
        let mut budget = self.clone();
        budget.hidden = Some(self.hidden_for(method));
        let mut policy_loop = PolicyLoopConfig::new(SacConfig::new(), 0, 0.0, 0.0);
        match method {
            Method::Combo => policy_loop.apply_combo_settings(0.0),
            Method::Morel => policy_loop.apply_morel_settings(0.0),
            Method::Mobile => policy_loop.apply_mobile_settings(0.0, None),
            Method::Rambo => policy_loop.apply_rambo_settings(0.0),
            _ => {}
        }
        if method.is_mopo() {
            let settings = self.mopo_settings.unwrap_or_default();
            policy_loop.apply_mopo_settings(settings);
            budget.mopo_settings = Some(settings);
        } else if method.uses_sde() {
            // NUNO's own settings are `Nuno`: naming them is leaving them out.
            if let Some(settings) = self.mopo_settings {
                policy_loop.apply_mopo_settings(settings);
            }
            budget.mopo_settings = self.mopo_settings.filter(|&s| s != MopoSettings::Nuno);
        } else {
            budget.mopo_settings = None;
        }
        if !method.uses_sde() {
            budget.penalty = None;
        }
        // Dropping is the default: naming it is leaving it out.
        budget.truncated_step = (self.truncated_step)
            .filter(|&s| s != TruncatedStep::Drop && method.truncation().accumulates());
        budget.rollout_batch = Some(self.rollout_batch.unwrap_or(policy_loop.rollout_batch));
        if method.uses_ensemble() {
            budget.model_steps = 0;
            budget.model_likelihood = default_likelihood();
            budget.recipe = Recipe::default();
            budget.model_sample_noise = None;
            budget.model_step_discount = None;
            budget.model_eta_losses = None;
            budget.threshold_max_margin = None;
            budget.model_drift_inputs = None;
            budget.forward_velocity = None;
            budget.root_x_reward = None;
        } else {
            budget.ensemble_max_epochs = None;
        }
        budget
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn budget(extra: &str) -> Budget {
        toml::from_str(&format!(
            "model_steps = 5000\npolicy_steps = 50000\n{extra}"
        ))
        .unwrap()
    }

    /// The error a grid's text is refused with, when it reads as TOML.
    fn refusal(text: &str) -> String {
        let grid: Grid = toml::from_str(text).unwrap();
        grid.cells(Path::new("/grids")).unwrap_err()
    }

    #[test]
    fn a_default_named_and_a_default_left_out_are_one_budget() {
        // NUNO's scripts roll 5000 starts; OfflineRL-Kit's MOPO 50 000.
        let nuno = |b: &Budget| b.for_method(Method::Nuno);
        assert_eq!(nuno(&budget("")), nuno(&budget("rollout_batch = 5000")));
        assert_ne!(nuno(&budget("")), nuno(&budget("rollout_batch = 50000")));
        let mopo = |b: &Budget| b.for_method(Method::Mopo);
        let kit = budget("rollout_batch = 50000\nmopo_settings = \"offlinerl-kit\"");
        assert_eq!(mopo(&budget("")), mopo(&kit));
        assert_ne!(mopo(&budget("")), mopo(&budget("rollout_batch = 5000")));
        assert_eq!(
            mopo(&budget("mopo_settings = \"nuno\"")),
            mopo(&budget("mopo_settings = \"nuno\"\nrollout_batch = 5000"))
        );
        // NUNO's own settings are "nuno"; MOPO's make its rollouts 50 000 starts.
        assert_eq!(nuno(&budget("")), nuno(&budget("mopo_settings = \"nuno\"")));
        let nuno_kit = nuno(&budget("mopo_settings = \"offlinerl-kit\""));
        assert_ne!(nuno(&budget("")), nuno_kit);
        assert_eq!(
            nuno_kit,
            nuno(&budget(
                "mopo_settings = \"offlinerl-kit\"\nrollout_batch = 50000"
            ))
        );
        // A method that runs its own settings records none, nor NUNO's λ_pen.
        let combo = |b: &Budget| b.for_method(Method::Combo);
        assert_eq!(combo(&budget("")), combo(&kit));
        assert_eq!(mopo(&budget("")), mopo(&budget("penalty = 5.0")));
        assert_ne!(nuno(&budget("")), nuno(&budget("penalty = 5.0")));
    }

    #[test]
    fn a_task_without_a_table_3_row_takes_policy_settings() {
        let row = "[budget]\nmodel_steps = 100\npolicy_steps = 100\n\
                   [[datasets]]\nname = \"pendulum-random\"\nfile = \"p.hdf5\"\n\
                   task = \"invertedpendulum\"\n\
                   policy = { horizon = 5, cvar_alpha = 1.0, penalty = 0.5 }\n\
                   methods = [\"nuno\", \"mopo\"]\nseeds = [0]\n";
        let grid: Grid = toml::from_str(row).unwrap();
        let cells = grid.cells(Path::new("/grids")).unwrap();
        assert_eq!(cells.len(), 2);
        for cell in &cells {
            assert_eq!(cell.task, Some(TaskName::InvertedPendulum));
            assert_eq!(cell.preset, None);
            assert_eq!(cell.policy.map(|p| (p.horizon, p.penalty)), Some((5, 0.5)));
            assert_eq!(cell.file, Path::new("/grids/p.hdf5"));
        }
        // A preset and policy settings together are one too many.
        let both = row.replace("policy = ", "preset = \"hopper-random\"\npolicy = ");
        let error = refusal(&both);
        assert!(
            error.contains("`pendulum-random` needs task and preset"),
            "{error}"
        );
    }

    /// A NeoRL row gives MOPO's h and λ, which MOPO's table lacks: its
    /// MOPO-family cells carry them, its NUNO cells do not; a row that has
    /// MOPO's own preset row, or runs no method that reads them, is refused.
    #[test]
    fn a_neorl_row_gives_mopos_pair() {
        let row = "[budget]\nmodel_steps = 100\npolicy_steps = 100\n\
                   [[datasets]]\nname = \"low\"\nfile = \"l.npz\"\ntask = \"hopper\"\n\
                   preset = \"neorl-hopper-low\"\nmopo = { horizon = 5, penalty = 2.5 }\n\
                   methods = [\"nuno\", \"mopo\", \"morel\"]\nseeds = [0]\n";
        let grid: Grid = toml::from_str(row).unwrap();
        let cells = grid.cells(Path::new("/grids")).unwrap();
        let pair = |m: Method| cells.iter().find(|c| c.method == m).unwrap().mopo;
        let given = Some(MopoRow {
            horizon: 5,
            penalty: 2.5,
        });
        assert_eq!((pair(Method::Nuno), pair(Method::Mopo)), (None, given));
        assert_eq!(pair(Method::Morel), given);
        let without = row.replace("mopo = { horizon = 5, penalty = 2.5 }\n", "");
        let error = refusal(&without);
        assert!(error.contains("neorl-hopper-low (for MOPO)"), "{error}");
        let own = row.replace("neorl-hopper-low", "hopper-random");
        let error = refusal(&own);
        assert!(error.contains("`hopper-random` has its own row"), "{error}");
        let unread = row.replace("\"mopo\", \"morel\"", "\"bc\"");
        let error = refusal(&unread);
        assert!(
            error.contains("runs no mopo, tatu-mopo or morel"),
            "{error}"
        );
    }

    /// RAMBO's, COMBO's and EDAC's settings on a dataset their tables lack
    /// (random data) reach their own cells only; without them the row is
    /// refused by name, as is a row that gives them where the table has its
    /// own, for a method it does not run, or out of range.
    #[test]
    fn a_random_row_gives_the_baselines_settings_their_tables_lack() {
        let row = "[budget]\nmodel_steps = 100\npolicy_steps = 100\n\
                   [[datasets]]\nname = \"random\"\nfile = \"r.hdf5\"\ntask = \"hopper\"\n\
                   preset = \"hopper-random\"\nrambo = { horizon = 2, weight = 3e-4 }\n\
                   combo = { horizon = 5, weight = 5.0 }\nedac = { critics = 50, eta = 1.0 }\n\
                   methods = [\"mopo\", \"rambo\", \"combo\", \"edac\"]\nseeds = [0]\n";
        let grid: Grid = toml::from_str(row).unwrap();
        let cells = grid.cells(Path::new("/grids")).unwrap();
        let cell = |m: Method| cells.iter().find(|c| c.method == m).unwrap().clone();
        let (rambo, combo, edac) = (cell(Method::Rambo), cell(Method::Combo), cell(Method::Edac));
        let (h2, h5) = (
            HorizonWeight {
                horizon: 2,
                weight: 3e-4,
            },
            HorizonWeight {
                horizon: 5,
                weight: 5.0,
            },
        );
        assert_eq!(
            (rambo.rambo, rambo.combo, rambo.edac),
            (Some(h2), None, None)
        );
        assert_eq!(
            (combo.rambo, combo.combo, combo.edac),
            (None, Some(h5), None)
        );
        let n50 = EdacRow {
            critics: 50,
            eta: 1.0,
        };
        assert_eq!((edac.rambo, edac.combo, edac.edac), (None, None, Some(n50)));
        let mopo = cell(Method::Mopo);
        assert_eq!((mopo.rambo, mopo.combo, mopo.edac), (None, None, None));
        // A kept result of the same cell with other settings is another cell's.
        assert!(!rambo.is_same_cell_as(&Cell {
            rambo: Some(h5),
            ..rambo.clone()
        }));

        let without = row.replace("rambo = { horizon = 2, weight = 3e-4 }\n", "");
        let error = refusal(&without);
        assert!(error.contains("rambo needs its own row"), "{error}");
        let own = row.replace("hopper-random", "hopper-medium");
        let error = refusal(&own);
        assert!(error.contains("`hopper-medium` has its own row"), "{error}");
        let unread = row.replace("\"combo\", ", "");
        let error = refusal(&unread);
        assert!(
            error.contains("`combo` sets combo's settings, but the row runs no combo"),
            "{error}"
        );
        let lone = row.replace("critics = 50", "critics = 1");
        let error = refusal(&lone);
        assert!(error.contains("`edac` needs critics ≥ 2"), "{error}");
        let negative = row.replace("weight = 3e-4", "weight = -1.0");
        let error = refusal(&negative);
        assert!(
            error.contains("`rambo` needs horizon ≥ 1 and a finite weight ≥ 0"),
            "{error}"
        );
    }

    /// A row's own drift inputs are its SDE cells' budget and no other row's;
    /// MOPO's cells, which fit no SDE, read none; a row that fits no SDE is refused.
    #[test]
    fn a_rows_drift_inputs_are_its_cells_budget() {
        let rows = "[budget]\nmodel_steps = 100\npolicy_steps = 100\nmodel_drift_inputs = \"z-scores\"\n\
                    [[datasets]]\nname = \"hc\"\nfile = \"hc.hdf5\"\ntask = \"halfcheetah\"\n\
                    preset = \"halfcheetah-random\"\nmodel_drift_inputs = \"pose\"\n\
                    methods = [\"nuno\", \"mopo\"]\nseeds = [0]\n\
                    [[datasets]]\nname = \"hop\"\nfile = \"h.hdf5\"\ntask = \"hopper\"\n\
                    preset = \"hopper-random\"\nmethods = [\"nuno\"]\nseeds = [0]\n";
        let grid: Grid = toml::from_str(rows).unwrap();
        let cells = grid.cells(Path::new("/grids")).unwrap();
        let drift = |dataset: &str, method: Method| {
            let cell = cells
                .iter()
                .find(|c| c.dataset == dataset && c.method == method);
            grid.budget_for(cell.unwrap())
                .for_method(method)
                .model_drift_inputs
        };
        assert_eq!(drift("hc", Method::Nuno), Some(DriftInputs::Pose));
        assert_eq!(drift("hop", Method::Nuno), Some(DriftInputs::ZScores));
        assert_eq!(drift("hc", Method::Mopo), None);
        let unread = rows.replace("[\"nuno\", \"mopo\"]", "[\"mopo\"]");
        let error = refusal(&unread);
        assert!(
            error.contains("dataset `hc`") && error.contains("runs no nuno"),
            "{error}"
        );
    }
}

fn default_likelihood() -> LikelihoodPath {
    LikelihoodPath::Particle
}
fn default_steps_per_epoch() -> usize {
    1000
}
fn default_eval_episodes() -> usize {
    10
}

/// One dataset row of the grid, as written: a built-in task's data with its
/// Table 3 preset or with the policy step's h, α and λ_pen, or a system file's
/// data with them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridDataset {
    pub name: String,
    pub file: PathBuf,
    #[serde(default)]
    pub task: Option<TaskName>,
    /// A system file, relative to the grid file.
    #[serde(default)]
    pub system: Option<PathBuf>,
    #[serde(default)]
    pub preset: Option<String>,
    /// What a preset gives, for a system or a task without a Table 3 row.
    #[serde(default)]
    pub policy: Option<PolicySettings>,
    /// MOPO's h and λ for a preset MOPO's table has no row for (NeoRL's): what
    /// mopo and tatu-mopo run with, and morel's h.
    #[serde(default)]
    pub mopo: Option<MopoRow>,
    /// RAMBO's h and w_adv for a preset its table has no row for (random
    /// data): fit-policy's `--horizon` and `--rambo-weight`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rambo: Option<HorizonWeight>,
    /// COMBO's h and β for a preset its table has no row for: `--horizon`
    /// and `--combo-weight`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub combo: Option<HorizonWeight>,
    /// EDAC's N and η for a preset its table has no row for:
    /// `--edac-critics` and `--edac-eta`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edac: Option<EdacRow>,
    /// fit-model's `--drift-inputs` for this row's SDEs, in place of the
    /// budget's: a task whose data the grid's drift does not suit
    /// (halfcheetah's, where the z-score drift runs away: BENCHMARKS.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_drift_inputs: Option<DriftInputs>,
    pub methods: Vec<String>,
    pub seeds: Vec<u64>,
}

/// Why `method`'s per-task table (OfflineRL-Kit's, MOPO's for its family)
/// has no row for `preset`; none where it has one or the method reads no table.
fn missing_table_row(method: Method, preset: &str) -> Option<crate::agent::AgentError> {
    match method {
        Method::Mopo | Method::TatuMopo | Method::Morel => crate::agent::mopo_preset(preset).err(),
        Method::Combo => crate::agent::combo_preset(preset).err(),
        Method::Mobile => crate::agent::mobile_preset(preset).err(),
        Method::Rambo => crate::agent::rambo_preset(preset).err(),
        Method::Edac => crate::agent::edac_preset(preset).err(),
        _ => None,
    }
}

/// MOPO's rollout length h and penalty λ, given in a grid row.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MopoRow {
    pub horizon: usize,
    pub penalty: f64,
}

/// A rollout length h and a method's weight (RAMBO's w_adv, COMBO's β), given
/// in a grid row.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HorizonWeight {
    pub horizon: usize,
    pub weight: f64,
}

/// EDAC's critics N and diversity weight η, given in a grid row.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EdacRow {
    pub critics: usize,
    pub eta: f64,
}

/// fit-policy's `--horizon`, `--cvar-alpha` and `--penalty`: h, α and λ_pen
/// (for MOPO's methods, MOPO's h and λ; α is TATU's CVaR level).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PolicySettings {
    pub horizon: usize,
    pub cvar_alpha: f64,
    pub penalty: f64,
}

/// What a dataset row's data is of, and where the policy step's h, α and
/// λ_pen come from.
enum RowSystem {
    /// A built-in task's data, with a Table 3 preset or with explicit settings
    /// (the tasks Table 3 has no row for).
    Task {
        task: TaskName,
        preset: Option<String>,
        layout: ObservationLayout,
        policy: Option<PolicySettings>,
    },
    File {
        file: PathBuf,
        policy: PolicySettings,
    },
}

/// A dataset row, checked: what its data is of and the methods it names.
struct CheckedRow {
    file: PathBuf,
    system: RowSystem,
    methods: Vec<Method>,
}

impl CheckedRow {
    /// Whether the row's observations hold root x (a built-in task in NeoRL's layout).
    fn observes_root_x(&self) -> bool {
        match &self.system {
            RowSystem::Task { task, layout, .. } => TaskConfig {
                layout: *layout,
                ..TaskConfig::d4rl(*task)
            }
            .observes_root_x(),
            RowSystem::File { .. } => false,
        }
    }
}

impl GridDataset {
    /// The row with its names checked and paths resolved against `base`.
    fn checked(&self, base: &Path) -> Result<CheckedRow, String> {
        let name = &self.name;
        if name.is_empty() || name.contains(['/', '\\']) || name.starts_with('.') {
            return Err(format!("dataset name `{name}` cannot name a folder"));
        }
        // Whether the file exists is the runner's check, on the cells it
        // runs: a report or status needs only the cells' folders.
        let file = base.join(&self.file);
        let system = self.row_system(base)?;
        if self.methods.is_empty() || self.seeds.is_empty() {
            return Err(format!(
                "dataset `{name}` needs at least one method and one seed"
            ));
        }
        let methods = (self.methods.iter())
            .map(|m| {
                m.parse::<Method>()
                    .map_err(|e| format!("dataset `{name}`: {e}"))
            })
            .collect::<Result<Vec<_>, _>>()?;
        if let RowSystem::Task {
            preset: Some(preset),
            ..
        } = &system
        {
            // The baselines' per-dataset tables, checked before anything runs.
            for &m in &methods {
                let given = match m {
                    Method::Mopo | Method::TatuMopo | Method::Morel => self.mopo.is_some(),
                    Method::Rambo => self.rambo.is_some(),
                    Method::Combo => self.combo.is_some(),
                    Method::Edac => self.edac.is_some(),
                    _ => false,
                };
                if let Some(e) = missing_table_row(m, preset).filter(|_| !given) {
                    return Err(format!("dataset `{name}`: {m} needs its own row: {e}"));
                }
            }
        }
        self.check_mopo_row(&methods)?;
        self.check_baseline_rows(&methods)?;
        if self.model_drift_inputs.is_some() && !methods.iter().any(|m| m.uses_sde()) {
            return Err(format!(
                "dataset `{name}`: `model_drift_inputs` sets the SDE's drift, but the row runs no nuno, nuno-r or nuno-al"
            ));
        }
        Ok(CheckedRow {
            file,
            system,
            methods,
        })
    }

    /// A row's `mopo` pair: only where MOPO's table has no row for its preset,
    /// and only with a method that reads it.
    fn check_mopo_row(&self, methods: &[Method]) -> Result<(), String> {
        let (name, Some(row)) = (&self.name, self.mopo) else {
            return Ok(());
        };
        if let Some(preset) = &self.preset
            && missing_table_row(Method::Mopo, preset).is_none()
        {
            return Err(format!(
                "dataset `{name}`: `mopo` is for datasets MOPO's table lacks; `{preset}` has its own row"
            ));
        }
        if !methods.iter().any(|m| m.is_mopo() || *m == Method::Morel) {
            return Err(format!(
                "dataset `{name}`: `mopo` sets MOPO's h and λ, but the row runs no mopo, tatu-mopo or morel"
            ));
        }
        if row.horizon == 0 || !(row.penalty.is_finite() && row.penalty >= 0.0) {
            return Err(format!(
                "dataset `{name}`: `mopo` needs horizon ≥ 1 and a finite penalty ≥ 0"
            ));
        }
        Ok(())
    }

    /// A row's `rambo`, `combo` and `edac` settings: each only where its
    /// method's table has no row for the preset, with that method in the row,
    /// and in range.
    fn check_baseline_rows(&self, methods: &[Method]) -> Result<(), String> {
        let name = &self.name;
        let given = [
            (
                self.rambo.map(|r| (r.horizon, r.weight)),
                Method::Rambo,
                "rambo",
            ),
            (
                self.combo.map(|r| (r.horizon, r.weight)),
                Method::Combo,
                "combo",
            ),
            (self.edac.map(|r| (r.critics, r.eta)), Method::Edac, "edac"),
        ];
        for (row, method, key) in given {
            let Some((count, weight)) = row else { continue };
            if let Some(preset) = &self.preset
                && missing_table_row(method, preset).is_none()
            {
                return Err(format!(
                    "dataset `{name}`: `{key}` is for datasets {method}'s table lacks; `{preset}` has its own row"
                ));
            }
            if !methods.contains(&method) {
                return Err(format!(
                    "dataset `{name}`: `{key}` sets {method}'s settings, but the row runs no {method}"
                ));
            }
            // EDAC's diversity term compares critics pairwise: two at least.
            let fewest = if method == Method::Edac { 2 } else { 1 };
            if count < fewest || !(weight.is_finite() && weight >= 0.0) {
                let (count_key, weight_key) = match method {
                    Method::Edac => ("critics", "eta"),
                    _ => ("horizon", "weight"),
                };
                return Err(format!(
                    "dataset `{name}`: `{key}` needs {count_key} ≥ {fewest} and a finite {weight_key} ≥ 0"
                ));
            }
        }
        Ok(())
    }

    /// A task with its preset or its policy settings, or a system file
    /// (resolved against `base`) with its policy settings: one of the three, checked.
    fn row_system(&self, base: &Path) -> Result<RowSystem, String> {
        let name = &self.name;
        match (self.task, &self.system, &self.preset, &self.policy) {
            (Some(task), None, Some(preset_name), None) => {
                let row = preset(preset_name).map_err(|e| format!("dataset `{name}`: {e}"))?;
                if row.task != task {
                    return Err(format!(
                        "dataset `{name}` is {task} data, its preset `{preset_name}` is for {}",
                        row.task
                    ));
                }
                Ok(RowSystem::Task {
                    task,
                    preset: Some(preset_name.clone()),
                    layout: row.layout,
                    policy: None,
                })
            }
            (Some(task), None, None, Some(policy)) => Ok(RowSystem::Task {
                task,
                preset: None,
                layout: ObservationLayout::D4rl,
                policy: Some(self.checked_policy(policy)?),
            }),
            (None, Some(file), None, Some(policy)) => Ok(RowSystem::File {
                file: base.join(file),
                policy: self.checked_policy(policy)?,
            }),
            _ => Err(format!(
                "dataset `{name}` needs task and preset (a Table 3 dataset), task and policy (a built-in task's other data), or system and policy (a system file)"
            )),
        }
    }

    fn checked_policy(&self, policy: &PolicySettings) -> Result<PolicySettings, String> {
        let PolicySettings {
            horizon,
            cvar_alpha,
            penalty,
        } = *policy;
        if horizon == 0
            || !(cvar_alpha > 0.0 && cvar_alpha <= 1.0)
            || !(penalty.is_finite() && penalty >= 0.0)
        {
            return Err(format!(
                "dataset `{}`: policy needs horizon ≥ 1, cvar_alpha in (0, 1] and penalty ≥ 0",
                self.name
            ));
        }
        Ok(*policy)
    }

    /// The row's cell for `method` and `seed`, `index`-th in the grid.
    fn cell(&self, index: usize, row: &CheckedRow, method: Method, seed: u64) -> Cell {
        let mut cell = Cell {
            index,
            dataset: self.name.clone(),
            file_in_grid: self.file.clone(),
            file: row.file.clone(),
            task: None,
            layout: ObservationLayout::default(),
            preset: None,
            system_in_grid: None,
            system: None,
            policy: None,
            mopo: self
                .mopo
                .filter(|_| method.is_mopo() || method == Method::Morel),
            rambo: self.rambo.filter(|_| method == Method::Rambo),
            combo: self.combo.filter(|_| method == Method::Combo),
            edac: self.edac.filter(|_| method == Method::Edac),
            method,
            seed,
        };
        match &row.system {
            RowSystem::Task {
                task,
                preset,
                layout,
                policy,
            } => {
                (cell.task, cell.layout) = (Some(*task), *layout);
                (cell.preset, cell.policy) = (preset.clone(), *policy);
            }
            RowSystem::File { file, policy } => {
                cell.system_in_grid = self.system.clone();
                (cell.system, cell.policy) = (Some(file.clone()), Some(*policy));
            }
        }
        cell
    }
}

/// The grid file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Grid {
    pub budget: Budget,
    pub datasets: Vec<GridDataset>,
}

/// One run of the grid: a dataset, a method, a seed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Cell {
    /// Position in the grid's order (the Slurm array index).
    pub index: usize,
    pub dataset: String,
    /// The dataset file as the grid names it, relative to the grid file's
    /// folder, so a kept result names no one machine's paths (results written
    /// before it record the path they ran from).
    #[serde(rename = "file")]
    pub file_in_grid: PathBuf,
    /// The same file resolved against the grid's folder, what the cell reads.
    #[serde(skip)]
    pub file: PathBuf,
    /// The built-in task, or none for a system file's data.
    pub task: Option<TaskName>,
    pub layout: ObservationLayout,
    /// The Table 3 row of a built-in task's data.
    pub preset: Option<String>,
    /// The system file as the grid names it (relative to the grid file's folder).
    #[serde(default, skip_serializing_if = "Option::is_none", rename = "system")]
    pub system_in_grid: Option<PathBuf>,
    /// The same file resolved against the grid's folder, what the cell reads.
    #[serde(skip)]
    pub system: Option<PathBuf>,
    /// h, α and λ_pen where there is no preset.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub policy: Option<PolicySettings>,
    /// MOPO's h and λ the row gives (its methods' cells only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mopo: Option<MopoRow>,
    /// RAMBO's h and w_adv the row gives (RAMBO's cells only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rambo: Option<HorizonWeight>,
    /// COMBO's h and β the row gives (COMBO's cells only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub combo: Option<HorizonWeight>,
    /// EDAC's N and η the row gives (EDAC's cells only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edac: Option<EdacRow>,
    pub method: Method,
    pub seed: u64,
}

impl Cell {
    /// `dataset/method/seed-N`: the cell's folder under the experiment.
    pub fn id(&self) -> String {
        format!("{}/{}/seed-{}", self.dataset, self.method, self.seed)
    }

    /// Whether a result written for `other` is this cell's: the same dataset
    /// (name and file name), task, layout, preset, method and seed. The cell's
    /// place in the grid and the folder the grid was named from are not what
    /// it computed, so a grid that gains a method, or is named by another path
    /// (a cluster's login and compute nodes), keeps its finished cells.
    pub fn is_same_cell_as(&self, other: &Cell) -> bool {
        self.dataset == other.dataset
            && self.file_in_grid.file_name() == other.file_in_grid.file_name()
            && self.task == other.task
            && self.layout == other.layout
            && self.preset == other.preset
            && self.system_in_grid.as_ref().map(|f| f.file_name())
                == other.system_in_grid.as_ref().map(|f| f.file_name())
            && self.policy == other.policy
            && self.mopo == other.mopo
            && self.rambo == other.rambo
            && self.combo == other.combo
            && self.edac == other.edac
            && self.method == other.method
            && self.seed == other.seed
    }

    /// `models/dataset/kind/seed-N`: the model's folder under the experiment,
    /// shared by the cells whose methods train in the same kind of model
    /// (`None` for a model-free method's cell).
    pub fn model_id(&self) -> Option<String> {
        let kind = self.method.model_kind()?;
        Some(format!("models/{}/{kind}/seed-{}", self.dataset, self.seed))
    }
}

/// Which of a grid's cells to run: those matching every dimension named (any
/// of its values); a dimension left empty matches every cell.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CellSelection {
    pub datasets: Vec<String>,
    pub methods: Vec<Method>,
    pub seeds: Vec<u64>,
}

impl CellSelection {
    /// The selected cells in grid order. A value no cell of the grid has, or a
    /// combination that leaves no cell, is an error naming it.
    pub fn select(&self, cells: &[Cell]) -> Result<Vec<Cell>, ExperimentError> {
        check_known("dataset", &self.datasets, cells, |c| c.dataset.clone())?;
        check_known("method", &self.methods, cells, |c| c.method)?;
        check_known("seed", &self.seeds, cells, |c| c.seed)?;
        let selected: Vec<Cell> = cells
            .iter()
            .filter(|c| {
                (self.datasets.is_empty() || self.datasets.contains(&c.dataset))
                    && (self.methods.is_empty() || self.methods.contains(&c.method))
                    && (self.seeds.is_empty() || self.seeds.contains(&c.seed))
            })
            .cloned()
            .collect();
        if selected.is_empty() {
            return Err(ExperimentError::Invalid(
                "no cell of the grid matches every --dataset, --method and --seed given".into(),
            ));
        }
        Ok(selected)
    }
}

/// Each of `wanted` must be some cell's `key`.
fn check_known<T: PartialEq + fmt::Display + Ord>(
    flag: &str,
    wanted: &[T],
    cells: &[Cell],
    key: impl Fn(&Cell) -> T,
) -> Result<(), ExperimentError> {
    let have: std::collections::BTreeSet<T> = cells.iter().map(key).collect();
    match wanted.iter().find(|w| !have.contains(w)) {
        Some(missing) => {
            let have: Vec<String> = have.iter().map(ToString::to_string).collect();
            Err(ExperimentError::Invalid(format!(
                "--{flag} {missing}: no cell of the grid has it (the grid's: {})",
                have.join(", ")
            )))
        }
        None => Ok(()),
    }
}

impl Grid {
    /// The budget `cell` runs under: the grid's, with its row's own drift inputs.
    pub fn budget_for(&self, cell: &Cell) -> Budget {
        let mut budget = self.budget.clone();
        let row = self.datasets.iter().find(|d| d.name == cell.dataset);
        if let Some(inputs) = row.and_then(|d| d.model_drift_inputs) {
            budget.model_drift_inputs = Some(inputs);
        }
        budget
    }

    /// Reads and checks `path`; dataset files are resolved against its folder.
    pub fn read(path: &Path) -> Result<(Grid, Vec<Cell>), ExperimentError> {
        let text = std::fs::read_to_string(path).map_err(|e| ExperimentError::Grid {
            file: path.to_path_buf(),
            message: e.to_string(),
        })?;
        let grid: Grid = toml::from_str(&text).map_err(|e| ExperimentError::Grid {
            file: path.to_path_buf(),
            message: e.to_string(),
        })?;
        // Absolute, so a cell is the same whichever folder the grid was named from.
        let parent = path.parent().filter(|p| !p.as_os_str().is_empty());
        let base = std::path::absolute(parent.unwrap_or(Path::new("."))).map_err(|e| {
            ExperimentError::Grid {
                file: path.to_path_buf(),
                message: e.to_string(),
            }
        })?;
        let cells = grid.cells(&base).map_err(|message| ExperimentError::Grid {
            file: path.to_path_buf(),
            message,
        })?;
        Ok((grid, cells))
    }

    /// The cells, every name checked, in the order below (seeds outermost).
    pub fn cells(&self, base: &Path) -> Result<Vec<Cell>, String> {
        self.budget.validate()?;
        if self.datasets.is_empty() {
            return Err("the grid names no dataset".into());
        }
        let mut names = std::collections::BTreeSet::new();
        let mut checked = Vec::new();
        for d in &self.datasets {
            if !names.insert(d.name.as_str()) {
                return Err(format!("dataset `{}` is named twice", d.name));
            }
            let row = d.checked(base)?;
            if self.budget.root_x_reward == Some(RootXReward::Velocity)
                && row.methods.iter().any(|m| m.uses_sde())
                && !row.observes_root_x()
            {
                return Err(format!(
                    "dataset `{}`: budget root_x_reward = \"velocity\" changes the reward on observations that hold root x (NeoRL's layout); this row's do not",
                    d.name
                ));
            }
            checked.push((d, row));
        }
        // Seeds outermost (each dataset's first seed, then each one's second,
        // ...), then datasets in file order, then methods: a sweep cut short
        // has every dataset × method at its first seeds.
        let rounds = self.datasets.iter().map(|d| d.seeds.len()).max();
        let mut cells = Vec::new();
        for round in 0..rounds.unwrap_or(0) {
            for (d, row) in &checked {
                let Some(&seed) = d.seeds.get(round) else {
                    continue;
                };
                for &method in &row.methods {
                    cells.push(d.cell(cells.len(), row, method, seed));
                }
            }
        }
        let mut ids = std::collections::BTreeSet::new();
        if let Some(twice) = cells.iter().find(|c| !ids.insert(c.id())) {
            return Err(format!(
                "cell {} appears twice (a repeated method or seed)",
                twice.id()
            ));
        }
        Ok(cells)
    }
}
