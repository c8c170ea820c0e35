//! A system described as data: a TOML file naming its observations and
//! actions, the time between observations, the action box, the kinematic
//! pairs of eq. 8's prior (d position/dt = velocity), the angles a
//! pose-aware drift sees through cos and sin, its reward (learned from the
//! dataset, NUNO^R, or an expression over the names) and when an episode
//! ends. Everything is checked when the file is read; a bad file is refused
//! naming the key and the reason.
//!
//! ```toml
//! name = "my-arm"
//! dt = 0.04
//! observations = ["x", "theta", "x_dot", "theta_dot"]
//! actions = ["force"]
//! action_low = [-3.0]
//! action_high = [3.0]
//!
//! [physics]                  # optional: without it the drift is learned alone
//! pairs = [["x", "x_dot"], ["theta", "theta_dot"]]
//! angles = ["theta"]         # optional
//!
//! [reward]                   # exactly one of the two
//! expression = "1.0 - 0.001 * force^2"   # or: learned = true
//!
//! [termination]              # optional: omitted, an episode never ends
//! bounds = { theta = [-0.2, 0.2] }
//! ```
//!
//! A system that MuJoCo can simulate adds a `[mujoco]` table (its MJCF
//! file, relative to the system file, and the rules it is stepped by: see
//! [`super::mujoco_table`]); then `dt`, the action box and `[physics]` may be
//! left out, taken from the model (its timestep × frame skip, its actuators'
//! control ranges, its joints), and what is given is checked against it, as
//! are the widths. Such a system is evaluated, generated from and trained
//! on in the simulator as the built-in tasks are.
//!
//! Observations may come in any order: the state split is built from the
//! names. A position without a velocity, or a velocity without a position,
//! is left to the learned drift. Reward expressions read each observation by
//! its name, the next state's as `next_<name>`, and each action by its name;
//! they are parsed once (the `exmex` crate: `+ - * / ^`, parentheses, `sin`,
//! `cos`, `exp`, `abs`, `sqrt`, …, every number a float) and evaluated row by
//! row over a batch.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::sync::Arc;

use exmex::prelude::*;
use serde::Deserialize;

use super::EnvError;
use super::mujoco_table::{ModelSource, MujocoTable};
use super::mujoco_task::TaskConfig;
use super::task::{FileTask, StateSplit, TaskSpec};

/// The file as written; checked into a [`SystemSpec`].
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SystemFile {
    name: String,
    dt: Option<f64>,
    observations: Vec<String>,
    actions: Vec<String>,
    action_low: Option<Vec<f64>>,
    action_high: Option<Vec<f64>>,
    physics: Option<PhysicsFile>,
    reward: RewardFile,
    termination: Option<TerminationFile>,
    mujoco: Option<MujocoTable>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PhysicsFile {
    #[serde(default)]
    pairs: Vec<[String; 2]>,
    #[serde(default)]
    angles: Vec<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RewardFile {
    learned: Option<bool>,
    expression: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TerminationFile {
    #[serde(default)]
    bounds: BTreeMap<String, [f64; 2]>,
}

/// A checked system description.
#[derive(Debug, Clone)]
pub struct SystemSpec {
    /// The file as written, kept so an artifact can carry the system it
    /// models and be re-checked when it is loaded.
    pub source: String,
    pub name: String,
    /// Seconds between consecutive observations.
    pub dt: f64,
    pub observations: Vec<String>,
    pub actions: Vec<String>,
    pub action_low: Vec<f64>,
    pub action_high: Vec<f64>,
    /// Positions (the pairs' first names) with their velocities; every other
    /// observation is a velocity of the learned drift; the angles by index.
    pub split: StateSplit,
    pub reward: SystemReward,
    /// An episode ends when one of these observations leaves its interval.
    pub bounds: Vec<ObservationBound>,
    /// The MuJoCo task that simulates the system, where the file has a `[mujoco]` table.
    pub simulation: Option<TaskConfig>,
}

/// Where a system's reward comes from.
#[derive(Debug, Clone)]
pub enum SystemReward {
    /// NUNO^R: the model learns the dataset's rewards.
    Learned,
    /// Known: an expression over the observation, next-observation and action names.
    Expression(Box<RewardExpression>),
}

/// `low ≤ observation[index] ≤ high` while an episode lasts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObservationBound {
    pub index: usize,
    pub low: f64,
    pub high: f64,
}

/// Where an expression's variable is read from, per row.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Input {
    Observation(usize),
    NextObservation(usize),
    Action(usize),
}

/// A reward expression, parsed once, with its variables resolved to columns.
#[derive(Debug, Clone)]
pub struct RewardExpression {
    text: String,
    expression: FlatEx<f64>,
    /// In the order of `expression.var_names()` (alphabetical).
    inputs: Vec<Input>,
}

impl RewardExpression {
    /// The expression as written.
    pub fn text(&self) -> &str {
        &self.text
    }

    /// The reward of each transition: `observations`, `actions` and
    /// `next_observations` are `[rows, width]`, row-major.
    ///
    /// # Panics
    /// When the three do not hold the same number of rows of the system's
    /// widths (the caller's shape check comes first).
    pub fn rewards(
        &self,
        (observations, actions, next_observations): (&[f32], &[f32], &[f32]),
        (obs_dim, act_dim): (usize, usize),
    ) -> Vec<f32> {
        let rows = observations.len() / obs_dim;
        assert_eq!(observations.len(), rows * obs_dim, "observation rows");
        assert_eq!(actions.len(), rows * act_dim, "action rows");
        assert_eq!(
            next_observations.len(),
            rows * obs_dim,
            "next observation rows"
        );
        let mut values = vec![0.0; self.inputs.len()];
        (0..rows)
            .map(|r| {
                self.reward_into(
                    &mut values,
                    &observations[r * obs_dim..(r + 1) * obs_dim],
                    &actions[r * act_dim..(r + 1) * act_dim],
                    &next_observations[r * obs_dim..(r + 1) * obs_dim],
                )
            })
            .collect()
    }

    /// The reward of one transition (`observation`, `action`, `next`: one row each).
    pub fn reward(&self, observation: &[f32], action: &[f32], next: &[f32]) -> f32 {
        // Rewards read a handful of names: no allocation per row for those.
        const ON_STACK: usize = 16;
        let n = self.inputs.len();
        if n <= ON_STACK {
            self.reward_into(&mut [0.0; ON_STACK][..n], observation, action, next)
        } else {
            self.reward_into(&mut vec![0.0; n], observation, action, next)
        }
    }

    /// The reward of one transition, with `values` (one per input) as scratch.
    fn reward_into(
        &self,
        values: &mut [f64],
        observation: &[f32],
        action: &[f32],
        next: &[f32],
    ) -> f32 {
        for (value, input) in values.iter_mut().zip(&self.inputs) {
            *value = f64::from(match *input {
                Input::Observation(i) => observation[i],
                Input::NextObservation(i) => next[i],
                Input::Action(i) => action[i],
            });
        }
        // Every variable was resolved when the expression was read, so
        // evaluation cannot miss one; a NaN stays a NaN.
        self.expression.eval(values).unwrap_or(f64::NAN) as f32
    }
}

impl SystemSpec {
    /// Reads and checks the system file at `path`.
    pub fn read(path: &Path) -> Result<Self, EnvError> {
        let text = std::fs::read_to_string(path).map_err(|e| EnvError::System {
            file: path.to_path_buf(),
            message: format!("cannot read it: {e}"),
        })?;
        Self::parse(&text, path)
    }

    /// Checks the system file `text` (read from `file`, for messages).
    pub fn parse(text: &str, file: &Path) -> Result<Self, EnvError> {
        let error = |message: String| EnvError::System {
            file: file.to_path_buf(),
            message,
        };
        let mut raw: SystemFile = toml::from_str(text).map_err(|e| error(e.to_string()))?;
        let model = match raw.mujoco.as_ref() {
            Some(table) => Some(read_model(table, file).map_err(error)?),
            None => None,
        };
        let inlined = model
            .as_ref()
            .and_then(|(xml, from_file)| from_file.then_some(xml));
        let source = match inlined {
            Some(xml) => inline_model(text, xml).map_err(error)?,
            None => text.to_string(),
        };
        let task = match (raw.mujoco.take(), model) {
            (Some(table), Some((xml, _))) => Some(table.check(&xml).map_err(error)?),
            _ => None,
        };
        let mut spec = raw.check(task).map_err(error)?;
        spec.source = source;
        Ok(spec)
    }

    pub fn obs_dim(&self) -> usize {
        self.observations.len()
    }

    pub fn act_dim(&self) -> usize {
        self.actions.len()
    }

    /// Whether an episode ends at `observation` (one row). The bounds are
    /// compared in f32, the observations' precision, so a bound written as
    /// 0.2 holds an observation of 0.2.
    pub fn terminated(&self, observation: &[f32]) -> bool {
        self.bounds.iter().any(|b| {
            let x = observation[b.index];
            !(b.low as f32..=b.high as f32).contains(&x)
        })
    }
}

/// The MJCF a `[mujoco]` table names, read relative to the system file
/// `file`, or given inline; and whether it came from a file.
fn read_model(table: &MujocoTable, file: &Path) -> Result<(String, bool), String> {
    match table.model_source()? {
        ModelSource::Inline(xml) => Ok((xml.to_string(), false)),
        ModelSource::File(name) => {
            let path = file.parent().unwrap_or(Path::new("")).join(name);
            let xml = std::fs::read_to_string(&path)
                .map_err(|e| format!("mujoco.model: cannot read `{}`: {e}", path.display()))?;
            Ok((xml, true))
        }
    }
}

/// `text` with its `[mujoco]` table's `model` file replaced by the file's
/// contents (`model_xml`): what an artifact records, so the system reads
/// again where the MJCF file is not. The rest stays as written.
fn inline_model(text: &str, xml: &str) -> Result<String, String> {
    let mut document: toml_edit::DocumentMut = text.parse().map_err(|e| format!("{e}"))?;
    let table = document
        .get_mut("mujoco")
        .and_then(|item| item.as_table_like_mut())
        .ok_or("mujoco: must be a table")?;
    table.remove("model");
    table.insert("model_xml", toml_edit::value(xml));
    Ok(document.to_string())
}

impl SystemFile {
    /// The checked system, simulated by `task` where the file has a `[mujoco]` table.
    fn check(self, task: Option<TaskSpec>) -> Result<SystemSpec, String> {
        if self.name.trim().is_empty() {
            return Err("name: must not be empty".into());
        }
        let names = Names::new(&self.observations, &self.actions)?;
        let model = task
            .as_ref()
            .map(|spec| ModelFacts::of(spec, &names))
            .transpose()?;
        let dt = match (self.dt, &model) {
            (Some(dt), model) => check_dt(dt, model.as_ref())?,
            (None, Some(model)) => model.dt,
            (None, None) => return Err("dt: required (or a [mujoco] table to take it from)".into()),
        };
        let (action_low, action_high) = match (self.action_low, self.action_high, &model) {
            (Some(low), Some(high), model) => {
                check_action_box(&low, &high, self.actions.len())?;
                if let Some(model) = model {
                    model.check_action_box(&low, &high)?;
                }
                (low, high)
            }
            (None, None, Some(model)) => model.action_box()?,
            _ => {
                return Err(
                    "action_low, action_high: give both (or neither, with a [mujoco] table)".into(),
                );
            }
        };
        let split = match (&self.physics, &model) {
            (Some(physics), _) => physics.split(&names)?,
            (None, Some(model)) => model.split.clone(),
            (None, None) => StateSplit {
                positions: Vec::new(),
                velocities: (0..self.observations.len()).collect(),
                position_velocity: Vec::new(),
                angles: Vec::new(),
            },
        };
        let reward = self.reward.check(&names)?;
        let bounds = match &self.termination {
            Some(termination) => termination.bounds(&names)?,
            None => Vec::new(),
        };
        let simulation = task.map(|spec| {
            TaskConfig::of_file(Arc::new(FileTask {
                name: self.name.clone(),
                spec,
            }))
        });
        Ok(SystemSpec {
            source: String::new(),
            name: self.name,
            dt,
            observations: self.observations,
            actions: self.actions,
            action_low,
            action_high,
            split,
            reward,
            bounds,
            simulation,
        })
    }
}

fn check_dt(dt: f64, model: Option<&ModelFacts>) -> Result<f64, String> {
    if !(dt.is_finite() && dt > 0.0) {
        return Err(format!(
            "dt: must be a positive number of seconds, got {dt}"
        ));
    }
    match model {
        // Written in decimal, a dt need not be the model's product to the last bit.
        Some(model) if (dt - model.dt).abs() > 1e-9 * model.dt => Err(format!(
            "dt: {dt} s, but the [mujoco] model's observations are {} s apart (timestep × frame_skip)",
            model.dt
        )),
        Some(model) => Ok(model.dt),
        None => Ok(dt),
    }
}

/// What a `[mujoco]` table's model says about the system, checked against its names.
struct ModelFacts {
    dt: f64,
    split: StateSplit,
    /// Each actuator's control range (`None`: not limited).
    controls: Vec<Option<(f64, f64)>>,
}

impl ModelFacts {
    fn of(spec: &TaskSpec, names: &Names) -> Result<Self, String> {
        let from = spec.observed_qpos_from;
        let observed = spec.nq - from + spec.nv;
        if names.observations.len() != observed {
            return Err(format!(
                "observations: {} names, but the [mujoco] model observes {observed} values (qpos[{from}..{}] and qvel[0..{}])",
                names.observations.len(),
                spec.nq,
                spec.nv
            ));
        }
        let controls = spec.control_ranges();
        if names.actions.len() != controls.len() {
            return Err(format!(
                "actions: {} names, but the [mujoco] model has {} actuators",
                names.actions.len(),
                controls.len()
            ));
        }
        Ok(Self {
            dt: spec.dt(),
            split: spec.state_split(from),
            controls,
        })
    }

    /// The actuators' control ranges, all of which must be limited.
    fn action_box(&self) -> Result<(Vec<f64>, Vec<f64>), String> {
        self.controls
            .iter()
            .enumerate()
            .map(|(i, range)| {
                range.ok_or_else(|| {
                    format!("action_low, action_high: actuator {i} of the [mujoco] model has no ctrlrange; give the box here")
                })
            })
            .collect::<Result<Vec<_>, _>>()
            .map(|ranges| ranges.into_iter().unzip())
    }

    /// A box given beside the model must be its control ranges where it has them
    /// (MuJoCo clips controls to those).
    fn check_action_box(&self, low: &[f64], high: &[f64]) -> Result<(), String> {
        for (i, range) in self.controls.iter().enumerate() {
            if let Some((l, h)) = *range
                && (l, h) != (low[i], high[i])
            {
                return Err(format!(
                    "action_low, action_high: action {i} has [{}, {}], but the [mujoco] model's control range is [{l}, {h}]",
                    low[i], high[i]
                ));
            }
        }
        Ok(())
    }
}

/// The system's names, checked unique, by kind.
struct Names<'a> {
    observations: &'a [String],
    actions: &'a [String],
}

impl<'a> Names<'a> {
    fn new(observations: &'a [String], actions: &'a [String]) -> Result<Self, String> {
        if observations.is_empty() {
            return Err("observations: name at least one".into());
        }
        if actions.is_empty() {
            return Err("actions: name at least one".into());
        }
        let mut seen = BTreeSet::new();
        for (key, name) in observations
            .iter()
            .map(|n| ("observations", n))
            .chain(actions.iter().map(|n| ("actions", n)))
        {
            if !is_identifier(name) {
                return Err(format!(
                    "{key}: `{name}` is not a name (letters, digits and _, not starting with a digit)"
                ));
            }
            if name.starts_with("next_") {
                return Err(format!(
                    "{key}: `{name}`: names may not start with next_ (it names the next state's values in expressions)"
                ));
            }
            if !seen.insert(name.as_str()) {
                return Err(format!(
                    "{key}: `{name}` is named twice (names are unique across observations and actions)"
                ));
            }
        }
        Ok(Self {
            observations,
            actions,
        })
    }

    /// The observation called `name`, for `key`'s message.
    fn observation(&self, key: &str, name: &str) -> Result<usize, String> {
        self.observations
            .iter()
            .position(|n| n == name)
            .ok_or_else(|| {
                format!(
                    "{key}: `{name}` is not an observation ({})",
                    self.observations.join(", ")
                )
            })
    }

    fn action(&self, name: &str) -> Option<usize> {
        self.actions.iter().position(|n| n == name)
    }
}

fn is_identifier(name: &str) -> bool {
    let mut chars = name.chars();
    chars
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

fn check_action_box(low: &[f64], high: &[f64], width: usize) -> Result<(), String> {
    for (key, values) in [("action_low", low), ("action_high", high)] {
        if values.len() != width {
            return Err(format!(
                "{key}: {} values for {width} actions",
                values.len()
            ));
        }
    }
    for (i, (l, h)) in low.iter().zip(high).enumerate() {
        if !(l.is_finite() && h.is_finite() && l < h) {
            return Err(format!(
                "action_low, action_high: action {i} has the interval [{l}, {h}]; each needs finite low < high"
            ));
        }
    }
    Ok(())
}

impl PhysicsFile {
    /// Positions in the pairs' order, each with its velocity; the other
    /// observations are velocities; the angles among the positions.
    fn split(&self, names: &Names) -> Result<StateSplit, String> {
        let mut positions = Vec::new();
        let mut position_velocity = Vec::new();
        let mut paired = BTreeSet::new();
        for [position, velocity] in &self.pairs {
            let (p, v) = (
                names.observation("physics.pairs", position)?,
                names.observation("physics.pairs", velocity)?,
            );
            if p == v || !paired.insert(p) || !paired.insert(v) {
                return Err(format!(
                    "physics.pairs: [`{position}`, `{velocity}`]: each observation may be in one pair, once"
                ));
            }
            positions.push(p);
            position_velocity.push(v);
        }
        let velocities = (0..names.observations.len())
            .filter(|i| !positions.contains(i))
            .collect();
        let mut angles = Vec::new();
        for angle in &self.angles {
            let a = names.observation("physics.angles", angle)?;
            if !positions.contains(&a) {
                return Err(format!(
                    "physics.angles: `{angle}` is not the position of a pair (an angle's drift is its velocity)"
                ));
            }
            if angles.contains(&a) {
                return Err(format!("physics.angles: `{angle}` is named twice"));
            }
            angles.push(a);
        }
        Ok(StateSplit {
            positions,
            velocities,
            position_velocity,
            angles,
        })
    }
}

impl RewardFile {
    fn check(self, names: &Names) -> Result<SystemReward, String> {
        match (self.learned, self.expression) {
            (Some(true), None) => Ok(SystemReward::Learned),
            (Some(true), Some(_)) => {
                Err("reward: give learned = true or an expression, not both".into())
            }
            (_, Some(text)) => Ok(SystemReward::Expression(Box::new(RewardExpression::parse(
                text, names,
            )?))),
            _ => Err("reward: give learned = true or an expression".into()),
        }
    }
}

impl RewardExpression {
    fn parse(text: String, names: &Names) -> Result<Self, String> {
        let expression = FlatEx::<f64>::parse(&text).map_err(|e| {
            format!(
                "reward.expression: `{text}` does not parse: {}",
                short(&e.to_string())
            )
        })?;
        let inputs = expression
            .var_names()
            .iter()
            .map(|name| {
                let observation = |n: &str| names.observations.iter().position(|o| o == n);
                if let Some(i) = observation(name) {
                    Ok(Input::Observation(i))
                } else if let Some(i) = name.strip_prefix("next_").and_then(observation) {
                    Ok(Input::NextObservation(i))
                } else if let Some(i) = names.action(name) {
                    Ok(Input::Action(i))
                } else {
                    Err(format!(
                        "reward.expression: `{name}` is not an observation, next_<observation> or action name"
                    ))
                }
            })
            .collect::<Result<_, _>>()?;
        Ok(Self {
            text,
            expression,
            inputs,
        })
    }
}

/// exmex's parse errors print its operator tables: the sentence before them.
fn short(message: &str) -> &str {
    message.split(", Operator").next().unwrap_or(message)
}

impl TerminationFile {
    fn bounds(&self, names: &Names) -> Result<Vec<ObservationBound>, String> {
        self.bounds
            .iter()
            .map(|(name, &[low, high])| {
                let index = names.observation("termination.bounds", name)?;
                if !(low.is_finite() && high.is_finite() && low < high) {
                    return Err(format!(
                        "termination.bounds: `{name}` has [{low}, {high}]; it needs finite low < high"
                    ));
                }
                Ok(ObservationBound { index, low, high })
            })
            .collect()
    }
}
