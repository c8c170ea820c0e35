//! NUNO's per-task hyperparameters, Table 3 of the paper: rollout length h,
//! CVaR level α of the truncation threshold, and penalty weight λ_pen (the
//! real-data ratio β = 0.05 is shared, Appendix C.3).

use serde::Serialize;

use super::AgentError;
use crate::envs::{ObservationLayout, TaskName};

/// One row of Table 3.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Preset {
    /// `hopper-random` for D4RL, `neorl-hopper-low` for NeoRL.
    pub name: &'static str,
    pub task: TaskName,
    pub layout: ObservationLayout,
    /// h
    pub horizon: usize,
    /// α of ε(h, α)
    pub cvar_alpha: f64,
    /// λ_pen
    pub penalty: f64,
}

const fn row(
    name: &'static str,
    task: TaskName,
    layout: ObservationLayout,
    horizon: usize,
    cvar_alpha: f64,
    penalty: f64,
) -> Preset {
    Preset {
        name,
        task,
        layout,
        horizon,
        cvar_alpha,
        penalty,
    }
}

use ObservationLayout::{D4rl, Neorl};
use TaskName::{HalfCheetah, Hopper, Walker2d};

/// Table 3, in the paper's order: 12 D4RL rows, then 9 NeoRL rows.
pub const PRESETS: [Preset; 21] = [
    row("halfcheetah-random", HalfCheetah, D4rl, 20, 1.0, 0.001),
    row("hopper-random", Hopper, D4rl, 10, 1.0, 0.001),
    row("walker2d-random", Walker2d, D4rl, 10, 0.99, 0.001),
    row("halfcheetah-medium", HalfCheetah, D4rl, 5, 0.99, 1.0),
    row("hopper-medium", Hopper, D4rl, 10, 0.99, 1.0),
    row("walker2d-medium", Walker2d, D4rl, 10, 0.98, 1.0),
    row("halfcheetah-medium-replay", HalfCheetah, D4rl, 5, 0.9, 1.0),
    row("hopper-medium-replay", Hopper, D4rl, 10, 0.99, 1.0),
    row("walker2d-medium-replay", Walker2d, D4rl, 10, 0.95, 1.0),
    row(
        "halfcheetah-medium-expert",
        HalfCheetah,
        D4rl,
        10,
        0.95,
        1.0,
    ),
    row("hopper-medium-expert", Hopper, D4rl, 10, 0.99, 1.0),
    row("walker2d-medium-expert", Walker2d, D4rl, 10, 0.98, 1.0),
    row("neorl-halfcheetah-low", HalfCheetah, Neorl, 10, 1.0, 1.0),
    row("neorl-hopper-low", Hopper, Neorl, 10, 0.99, 0.001),
    row("neorl-walker2d-low", Walker2d, Neorl, 5, 0.99, 0.001),
    row(
        "neorl-halfcheetah-medium",
        HalfCheetah,
        Neorl,
        10,
        0.99,
        1.0,
    ),
    row("neorl-hopper-medium", Hopper, Neorl, 5, 0.9, 0.1),
    row("neorl-walker2d-medium", Walker2d, Neorl, 5, 0.99, 0.001),
    row("neorl-halfcheetah-high", HalfCheetah, Neorl, 5, 0.99, 1.0),
    row("neorl-hopper-high", Hopper, Neorl, 5, 0.9, 0.1),
    row("neorl-walker2d-high", Walker2d, Neorl, 5, 0.99, 1.0),
];

/// The preset called `name`.
pub fn preset(name: &str) -> Result<&'static Preset, AgentError> {
    PRESETS
        .iter()
        .find(|p| p.name == name)
        .ok_or_else(|| AgentError::UnknownPreset {
            name: name.to_string(),
            known: PRESETS
                .iter()
                .map(|p| p.name)
                .collect::<Vec<_>>()
                .join(", "),
        })
}

/// MOPO's rollout length h and penalty coefficient λ for a D4RL dataset (the
/// MOPO paper's hyperparameter table, Yu et al. 2020, Appendix), by the same
/// names as Table 3's rows. MOPO gives none for NeoRL.
pub const MOPO_PRESETS: [(&str, usize, f64); 12] = [
    ("halfcheetah-random", 5, 0.5),
    ("hopper-random", 5, 1.0),
    ("walker2d-random", 1, 1.0),
    ("halfcheetah-medium", 1, 1.0),
    ("hopper-medium", 5, 5.0),
    ("walker2d-medium", 5, 5.0),
    ("halfcheetah-medium-replay", 5, 1.0),
    ("hopper-medium-replay", 5, 1.0),
    ("walker2d-medium-replay", 1, 1.0),
    ("halfcheetah-medium-expert", 5, 1.0),
    ("hopper-medium-expert", 5, 1.0),
    ("walker2d-medium-expert", 1, 2.0),
];

/// MOPO's (h, λ) for the dataset `name` names.
pub fn mopo_preset(name: &str) -> Result<(usize, f64), AgentError> {
    table_row(&MOPO_PRESETS, name, "for MOPO").map(|&(_, h, penalty)| (h, penalty))
}

/// TATU's pessimism coefficient where TATU's own scripts give one for a
/// dataset (TATU+MOPO: `run_tatu_modelbased.sh`); TATU+MOPO's h and λ are
/// MOPO's for the same dataset ([`MOPO_PRESETS`]).
pub const TATU_PESSIMISM: [(&str, f64); 2] =
    [("hopper-medium-replay", 2.0), ("hopper-medium-expert", 3.5)];

/// The pessimism coefficient for a dataset TATU's scripts do not name: the
/// medium-replay script's 2 (the TATU paper's table is not in our references).
pub const TATU_DEFAULT_PESSIMISM: f64 = 2.0;

/// MOReL's pessimism coefficient: its D4RL configuration's (`d4rl_hopper_medium.txt`,
/// the one D4RL dataset the authors' code configures; 0.5 for their own Hopper-v3 data).
pub const MOREL_PESSIMISM: f64 = 3.0;

/// TATU's pessimism coefficient for the dataset `name` names.
pub fn tatu_pessimism(name: &str) -> f64 {
    TATU_PESSIMISM
        .iter()
        .find(|(n, _)| *n == name)
        .map_or(TATU_DEFAULT_PESSIMISM, |&(_, p)| p)
}

/// EDAC's critics N and diversity weight η for a D4RL dataset (OfflineRL-Kit's
/// `run_edac.py` "suggested hypers"), by Table 3's names; none for the random
/// datasets or NeoRL.
pub const EDAC_PRESETS: [(&str, usize, f64); 9] = [
    ("halfcheetah-medium", 10, 1.0),
    ("hopper-medium", 50, 1.0),
    ("walker2d-medium", 10, 1.0),
    ("halfcheetah-medium-replay", 10, 1.0),
    ("hopper-medium-replay", 50, 1.0),
    ("walker2d-medium-replay", 10, 1.0),
    ("halfcheetah-medium-expert", 10, 5.0),
    ("hopper-medium-expert", 50, 1.0),
    ("walker2d-medium-expert", 10, 5.0),
];

/// EDAC's (N, η) for the dataset `name` names.
pub fn edac_preset(name: &str) -> Result<(usize, f64), AgentError> {
    table_row(&EDAC_PRESETS, name, "for EDAC's critics and η").map(|&(_, n, eta)| (n, eta))
}

/// COMBO's rollout length h and conservative weight β for a D4RL dataset
/// (OfflineRL-Kit's `run_combo.py` "suggested hypers"), by Table 3's names;
/// none for the random datasets or NeoRL.
pub const COMBO_PRESETS: [(&str, usize, f64); 9] = [
    ("halfcheetah-medium", 5, 0.5),
    ("hopper-medium", 5, 5.0),
    ("walker2d-medium", 1, 5.0),
    ("halfcheetah-medium-replay", 5, 0.5),
    ("hopper-medium-replay", 5, 0.5),
    ("walker2d-medium-replay", 1, 0.5),
    ("halfcheetah-medium-expert", 5, 5.0),
    ("hopper-medium-expert", 5, 5.0),
    ("walker2d-medium-expert", 1, 5.0),
];

/// COMBO's (h, β) for the dataset `name` names.
pub fn combo_preset(name: &str) -> Result<(usize, f64), AgentError> {
    table_row(&COMBO_PRESETS, name, "for COMBO's h and β").map(|&(_, h, beta)| (h, beta))
}

/// MOBILE's rollout length h, penalty weight β and, where its script turns
/// the temperature's tuning off, the fixed α, for a D4RL dataset
/// (OfflineRL-Kit's `run_mobile.py` "suggested hypers", the only per-task
/// table with the random datasets), by Table 3's names; none for NeoRL.
pub const MOBILE_PRESETS: [(&str, usize, f64, Option<f64>); 12] = [
    ("halfcheetah-random", 5, 0.5, None),
    ("hopper-random", 5, 5.0, None),
    ("walker2d-random", 5, 2.0, None),
    ("halfcheetah-medium", 5, 0.5, None),
    ("hopper-medium", 5, 1.5, Some(0.2)),
    ("walker2d-medium", 5, 0.5, None),
    ("halfcheetah-medium-replay", 5, 0.1, None),
    ("hopper-medium-replay", 5, 0.1, None),
    ("walker2d-medium-replay", 1, 0.5, None),
    ("halfcheetah-medium-expert", 5, 2.0, None),
    ("hopper-medium-expert", 5, 1.5, None),
    ("walker2d-medium-expert", 1, 1.5, None),
];

/// MOBILE's (h, β, fixed α) for the dataset `name` names.
pub fn mobile_preset(name: &str) -> Result<(usize, f64, Option<f64>), AgentError> {
    table_row(&MOBILE_PRESETS, name, "for MOBILE's h and β")
        .map(|&(_, h, beta, alpha)| (h, beta, alpha))
}

/// RAMBO's rollout length h and adversarial weight w_adv for a D4RL dataset
/// (OfflineRL-Kit's `run_rambo.py` "suggested hypers"), by Table 3's names;
/// none for the random datasets or NeoRL.
pub const RAMBO_PRESETS: [(&str, usize, f64); 9] = [
    ("halfcheetah-medium", 5, 3e-4),
    ("hopper-medium", 5, 3e-4),
    ("walker2d-medium", 5, 0.0),
    ("halfcheetah-medium-replay", 5, 3e-4),
    ("hopper-medium-replay", 5, 3e-4),
    ("walker2d-medium-replay", 5, 0.0),
    ("halfcheetah-medium-expert", 5, 0.0),
    ("hopper-medium-expert", 5, 0.0),
    ("walker2d-medium-expert", 2, 3e-4),
];

/// RAMBO's (h, w_adv) for the dataset `name` names.
pub fn rambo_preset(name: &str) -> Result<(usize, f64), AgentError> {
    table_row(&RAMBO_PRESETS, name, "for RAMBO's h and w_adv").map(|&(_, h, w)| (h, w))
}

/// A dataset's row of a per-task table whose rows start with its name;
/// unknown names are refused with the table's names (`what`: whose table).
fn table_row<'t, T: DatasetRow>(
    table: &'t [T],
    name: &str,
    what: &str,
) -> Result<&'t T, AgentError> {
    table
        .iter()
        .find(|row| row.dataset() == name)
        .ok_or_else(|| AgentError::UnknownPreset {
            name: format!("{name} ({what})"),
            known: table
                .iter()
                .map(DatasetRow::dataset)
                .collect::<Vec<_>>()
                .join(", "),
        })
}

/// A per-task table's row, named by its dataset.
trait DatasetRow {
    fn dataset(&self) -> &str;
}

impl<A, B> DatasetRow for (&str, A, B) {
    fn dataset(&self) -> &str {
        self.0
    }
}

impl<A, B, C> DatasetRow for (&str, A, B, C) {
    fn dataset(&self) -> &str {
        self.0
    }
}
