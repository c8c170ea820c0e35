//! The `[mujoco]` table: a MuJoCo model and the rules Gymnasium's `*-v4`
//! tasks step it by (frame skip, observation layout, reward terms, health,
//! reset noise, time limit, score references), read from TOML and checked
//! against the compiled model. The built-in tasks are such tables
//! (`src/envs/tasks/*.toml`), embedded at build time with their MJCF.
//!
//! ```toml
//! [mujoco]
//! model = "hopper.xml"
//! frame_skip = 4
//! observe_qpos_from = 1      # the observation is qpos[1..] ++ qvel
//! velocity_clip = 10.0       # optional: observed velocities clipped to ±10
//! forward_body = "torso"     # optional: the forward velocity is this body frame's x (else qpos[0])
//! max_episode_steps = 1000
//! reset_noise = { scale = 5e-3, velocity = "uniform" }   # or "normal"
//!
//! [mujoco.reward]            # (forward_weight · ẋ + healthy) − control_cost · ‖a‖²
//! forward_weight = 1.0
//! control_cost = 1e-3
//! healthy = 1.0
//!
//! [mujoco.health]            # optional: omitted, an episode never ends early
//! upright = { z = [0.7, inf], angle = [-0.2, 0.2], state = [-100.0, 100.0] }
//! # or: finite_within = { qpos = 2, range = [0.2, 1.0] }
//!
//! [mujoco.score]             # the normalised score's 0 and 100
//! random = -20.272305
//! expert = 3234.3
//! neorl = { random = 5.0, expert = 3294.0 }   # optional: for the layout observing all of qpos
//! ```

use std::sync::Arc;

use mujoco_rs::prelude::MjModel;
use mujoco_rs::wrappers::mj_model::MjtObjBase;
use serde::Deserialize;

use super::score::ScoreReference;
use super::task::{CompiledModel, HealthRule, ResetNoise, TaskSpec, install_mujoco_logging};

/// A system file's `[mujoco]` table as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct MujocoFile {
    mujoco: MujocoTable,
}

/// The table itself, as a system file holds it under `[mujoco]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct MujocoTable {
    /// The MJCF file: an embedded model's name in a built-in table, a path
    /// relative to the system file in a user's.
    model: Option<String>,
    /// The MJCF itself, in place of `model` (what an artifact records, so
    /// it needs no file to be read again).
    model_xml: Option<String>,
    frame_skip: usize,
    observe_qpos_from: usize,
    velocity_clip: Option<f64>,
    forward_body: Option<String>,
    max_episode_steps: usize,
    reset_noise: ResetNoiseTable,
    reward: RewardTable,
    health: Option<HealthTable>,
    score: ScoreTable,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ResetNoiseTable {
    scale: f64,
    velocity: VelocityNoise,
}

#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(rename_all = "snake_case")]
enum VelocityNoise {
    /// qvel gets `U(-scale, scale)`, as qpos does.
    Uniform,
    /// qvel gets `scale · N(0, 1)`.
    Normal,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RewardTable {
    forward_weight: f64,
    control_cost: f64,
    healthy: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, rename_all = "snake_case")]
enum HealthTable {
    Upright {
        z: [f64; 2],
        angle: [f64; 2],
        state: Option<[f64; 2]>,
    },
    FiniteWithin {
        qpos: usize,
        range: [f64; 2],
    },
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ScoreTable {
    random: f64,
    expert: f64,
    neorl: Option<ReferenceTable>,
}

#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
struct ReferenceTable {
    random: f64,
    expert: f64,
}

/// Where a table's MJCF is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum ModelSource<'a> {
    /// A file, by the name the table gives.
    File(&'a str),
    /// The MJCF's text.
    Inline(&'a str),
}

impl MujocoFile {
    /// Reads the table from `text`.
    pub(super) fn parse(text: &str) -> Result<Self, String> {
        toml::from_str(text).map_err(|e| e.to_string())
    }

    pub(super) fn table(self) -> MujocoTable {
        self.mujoco
    }
}

impl MujocoTable {
    /// Where the MJCF is: exactly one of `model` and `model_xml`.
    pub(super) fn model_source(&self) -> Result<ModelSource<'_>, String> {
        match (&self.model, &self.model_xml) {
            (Some(file), None) => Ok(ModelSource::File(file)),
            (None, Some(xml)) => Ok(ModelSource::Inline(xml)),
            _ => Err(
                "mujoco.model, mujoco.model_xml: give exactly one (the MJCF file, or its text)"
                    .into(),
            ),
        }
    }

    /// The task the table describes, on the model compiled from `xml`,
    /// checked against it; a bad value is named by its key.
    pub(super) fn check(self, xml: &str) -> Result<TaskSpec, String> {
        let what = match self.model_source()? {
            ModelSource::File(file) => format!("mujoco.model: `{file}`"),
            ModelSource::Inline(_) => "mujoco.model_xml".to_string(),
        };
        let t = self;
        install_mujoco_logging();
        let model =
            MjModel::from_xml_string(xml).map_err(|e| format!("{what} does not compile: {e}"))?;
        let (nq, nv) = (model.ffi().nq as usize, model.ffi().nv as usize);
        positive_count("mujoco.frame_skip", t.frame_skip)?;
        positive_count("mujoco.max_episode_steps", t.max_episode_steps)?;
        if t.observe_qpos_from > nq {
            return Err(format!(
                "mujoco.observe_qpos_from: {} is past the model's {nq} qpos entries",
                t.observe_qpos_from
            ));
        }
        if let Some(clip) = t.velocity_clip {
            positive("mujoco.velocity_clip", clip)?;
        }
        let forward_body = match &t.forward_body {
            Some(body) => Some(model.name_to_id(MjtObjBase::mjOBJ_BODY, body).ok_or_else(
                || format!("mujoco.forward_body: the model has no body named `{body}`"),
            )?),
            None => None,
        };
        let reward = &t.reward;
        finite("mujoco.reward.forward_weight", reward.forward_weight)?;
        finite("mujoco.reward.healthy", reward.healthy)?;
        non_negative("mujoco.reward.control_cost", reward.control_cost)?;
        non_negative("mujoco.reset_noise.scale", t.reset_noise.scale)?;
        let health = match t.health {
            None => HealthRule::AlwaysHealthy,
            Some(health) => health.check(nq, t.observe_qpos_from)?,
        };
        let (d4rl_score, neorl_score) = t.score.check()?;
        let scale = t.reset_noise.scale;
        Ok(TaskSpec {
            model: CompiledModel(Arc::new(model)),
            nq,
            nv,
            observed_qpos_from: t.observe_qpos_from,
            frame_skip: t.frame_skip,
            forward_body,
            forward_reward_weight: reward.forward_weight,
            ctrl_cost_weight: reward.control_cost,
            healthy_reward: reward.healthy,
            health,
            velocity_clip: t.velocity_clip,
            reset_noise: match t.reset_noise.velocity {
                VelocityNoise::Uniform => ResetNoise::Uniform { scale },
                VelocityNoise::Normal => ResetNoise::UniformPositionNormalVelocity { scale },
            },
            max_episode_steps: t.max_episode_steps,
            d4rl_score,
            neorl_score,
        })
    }
}

impl HealthTable {
    /// The rule, its qpos entries within the model and observed (the rules on
    /// observations read them there).
    fn check(self, nq: usize, observed_from: usize) -> Result<HealthRule, String> {
        match self {
            HealthTable::Upright { z, angle, state } => {
                if nq < 3 || observed_from > 1 {
                    return Err(
                        "mujoco.health.upright: needs qpos[1] (height) and qpos[2] (angle) observed"
                            .into(),
                    );
                }
                Ok(HealthRule::Upright {
                    z_range: interval("mujoco.health.upright.z", z)?,
                    angle_range: interval("mujoco.health.upright.angle", angle)?,
                    state_range: state
                        .map(|s| interval("mujoco.health.upright.state", s))
                        .transpose()?,
                })
            }
            HealthTable::FiniteWithin { qpos, range } => {
                if qpos >= nq || qpos < observed_from {
                    return Err(format!(
                        "mujoco.health.finite_within.qpos: {qpos} is not an observed qpos entry \
                         (qpos[{observed_from}..{nq}])"
                    ));
                }
                Ok(HealthRule::FiniteWithin {
                    qpos,
                    range: interval("mujoco.health.finite_within.range", range)?,
                })
            }
        }
    }
}

impl ScoreTable {
    /// The references of the default layout and of the one observing all of
    /// qpos (the default's, where the table gives none).
    fn check(self) -> Result<(ScoreReference, ScoreReference), String> {
        let reference = |key: &str, r: ReferenceTable| {
            finite(&format!("{key}.random"), r.random)?;
            finite(&format!("{key}.expert"), r.expert)?;
            if r.expert <= r.random {
                return Err(format!(
                    "{key}: expert ({}) must be above random ({})",
                    r.expert, r.random
                ));
            }
            Ok(ScoreReference {
                random: r.random,
                expert: r.expert,
            })
        };
        let own = ReferenceTable {
            random: self.random,
            expert: self.expert,
        };
        let d4rl = reference("mujoco.score", own)?;
        let neorl = reference("mujoco.score.neorl", self.neorl.unwrap_or(own))?;
        Ok((d4rl, neorl))
    }
}

fn interval(key: &str, [low, high]: [f64; 2]) -> Result<(f64, f64), String> {
    if low.is_nan() || high.is_nan() || low >= high {
        return Err(format!("{key}: [{low}, {high}] is not an interval"));
    }
    Ok((low, high))
}

fn positive_count(key: &str, value: usize) -> Result<(), String> {
    if value == 0 {
        return Err(format!("{key}: must be at least 1"));
    }
    Ok(())
}

fn positive(key: &str, value: f64) -> Result<(), String> {
    if !(value.is_finite() && value > 0.0) {
        return Err(format!("{key}: must be a positive number, got {value}"));
    }
    Ok(())
}

fn non_negative(key: &str, value: f64) -> Result<(), String> {
    if !(value.is_finite() && value >= 0.0) {
        return Err(format!("{key}: must be a number ≥ 0, got {value}"));
    }
    Ok(())
}

fn finite(key: &str, value: f64) -> Result<(), String> {
    if !value.is_finite() {
        return Err(format!("{key}: must be a finite number, got {value}"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cart on a slider with a hinged pole: qpos = [x, θ].
    const CART_POLE: &str = r#"<mujoco><worldbody><body name="cart">
        <joint name="x" type="slide" axis="1 0 0"/><geom type="box" size="0.1 0.1 0.1"/>
        <body name="pole"><joint name="theta" type="hinge" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 0 0 0.6" size="0.05"/></body></body></worldbody>
        <actuator><motor joint="x" ctrlrange="-3 3"/></actuator></mujoco>"#;

    const TABLE: &str = r#"
        [mujoco]
        model = "cart_pole.xml"
        frame_skip = 2
        observe_qpos_from = 0
        forward_body = "cart"
        max_episode_steps = 500
        reset_noise = { scale = 0.01, velocity = "normal" }
        [mujoco.reward]
        forward_weight = 0.0
        control_cost = 0.0
        healthy = 1.0
        [mujoco.health]
        finite_within = { qpos = 1, range = [-0.2, 0.2] }
        [mujoco.score]
        random = 5.0
        expert = 500.0
    "#;

    fn check(table: &str) -> Result<TaskSpec, String> {
        MujocoFile::parse(table)?.table().check(CART_POLE)
    }

    #[test]
    fn a_table_reads_into_the_task_it_describes() {
        let table = MujocoFile::parse(TABLE).unwrap().table();
        assert_eq!(table.model_source(), Ok(ModelSource::File("cart_pole.xml")));
        let spec = table.check(CART_POLE).unwrap();
        assert_eq!((spec.nq, spec.nv, spec.frame_skip), (2, 2, 2));
        assert_eq!(
            spec.forward_body,
            Some(1),
            "the cart is body 1 (0 is the world)"
        );
        assert_eq!(
            spec.health,
            HealthRule::FiniteWithin {
                qpos: 1,
                range: (-0.2, 0.2)
            }
        );
        assert_eq!(
            spec.reset_noise,
            ResetNoise::UniformPositionNormalVelocity { scale: 0.01 }
        );
        // Without its own NeoRL references, the full layout scores as the default.
        assert_eq!(spec.neorl_score, spec.d4rl_score);
        assert_eq!(
            (spec.d4rl_score.random, spec.d4rl_score.expert),
            (5.0, 500.0)
        );
    }

    #[test]
    fn bad_tables_are_refused_naming_the_key() {
        for (from, to, named) in [
            ("frame_skip = 2", "frame_skip = 0", "mujoco.frame_skip"),
            (
                "max_episode_steps = 500",
                "max_episode_steps = 0",
                "mujoco.max_episode_steps",
            ),
            (
                "observe_qpos_from = 0",
                "observe_qpos_from = 3",
                "mujoco.observe_qpos_from",
            ),
            ("\"cart\"", "\"wheel\"", "no body named `wheel`"),
            (
                "control_cost = 0.0",
                "control_cost = -1.0",
                "mujoco.reward.control_cost",
            ),
            ("healthy = 1.0", "healthy = nan", "mujoco.reward.healthy"),
            ("scale = 0.01", "scale = -0.01", "mujoco.reset_noise.scale"),
            ("\"normal\"", "\"gaussian\"", "unknown variant `gaussian`"),
            ("qpos = 1,", "qpos = 2,", "mujoco.health.finite_within.qpos"),
            (
                "[-0.2, 0.2]",
                "[0.2, -0.2]",
                "mujoco.health.finite_within.range",
            ),
            (
                "finite_within = { qpos = 1, range = [-0.2, 0.2] }",
                "upright = { z = [0.7, inf], angle = [-0.2, 0.2] }",
                "mujoco.health.upright",
            ),
            (
                "expert = 500.0",
                "expert = 5.0",
                "mujoco.score: expert (5) must be above",
            ),
            (
                "frame_skip = 2",
                "frame_skip = 2\nframes = 2",
                "unknown field `frames`",
            ),
        ] {
            assert!(TABLE.contains(from), "{from}");
            let error = check(&TABLE.replacen(from, to, 1)).unwrap_err();
            assert!(error.contains(named), "{to}: {error}");
        }
        let error = MujocoFile::parse(TABLE)
            .unwrap()
            .table()
            .check("<mujoco><bad")
            .unwrap_err();
        assert!(
            error.contains("`cart_pole.xml` does not compile"),
            "{error}"
        );
        let both = TABLE.replacen(
            "model = \"cart_pole.xml\"",
            "model = \"cart_pole.xml\"\nmodel_xml = \"<mujoco/>\"",
            1,
        );
        let error = check(&both).unwrap_err();
        assert!(error.contains("give exactly one"), "{error}");
    }
}
