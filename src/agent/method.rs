//! The offline methods nuno trains a policy with, one list for every caller
//! (`fit-policy --algo`, grid files, the experiment runner): the model kind
//! each trains in (none for the model-free ones) and where its rollouts truncate.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// The offline method: which model kind, penalty and truncation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// NUNO: the neural SDE with the task's reward, η-penalised rollouts
    /// truncated at ε(h, α) from the model's table.
    Nuno,
    /// NUNO^R: NUNO on a neural SDE that learned the reward (fit-model --reward-model).
    NunoR,
    /// NUNO^al (Appendix D): NUNO with the aleatoric ‖σ‖ in place of η, ε(h, α)
    /// computed on it.
    NunoAl,
    /// MOPO: the Gaussian ensemble (fit-ensemble), max-‖σᵢ‖ penalty, no truncation.
    Mopo,
    /// TATU+MOPO: MOPO, truncated once the accumulated ensemble disagreement
    /// passes its largest value on the dataset divided by the pessimism coefficient.
    TatuMopo,
    /// Behaviour cloning (OfflineRL-Kit's `run_bc.py`): no model.
    Bc,
    /// TD3+BC (Fujimoto & Gu, 2021, the authors' code): no model.
    #[serde(rename = "td3-bc")]
    Td3Bc,
    /// CQL (Kumar et al., 2020, OfflineRL-Kit's `run_cql.py`): no model.
    Cql,
    /// EDAC (An et al., 2021, OfflineRL-Kit's `run_edac.py`): no model.
    Edac,
    /// COMBO (Yu et al., 2021, OfflineRL-Kit's `run_combo.py`): MOPO's Gaussian
    /// ensemble, no reward penalty, CQL's conservative term on the mixed batch.
    Combo,
    /// MOReL (Kidambi et al., 2020, the authors' mjrl code): MOPO's Gaussian
    /// ensemble as a pessimistic MDP that halts where the members disagree,
    /// trained by MOPO's SAC loop in place of MOReL's NPG.
    Morel,
    /// MOBILE (Sun et al., 2023, OfflineRL-Kit's `run_mobile.py`): MOPO's
    /// Gaussian ensemble, the reward penalised at each update by the Bellman
    /// inconsistency over its elites.
    Mobile,
    /// RAMBO (Rigter et al., 2022, OfflineRL-Kit's `run_rambo.py`): MOPO's
    /// Gaussian ensemble trained adversarially against the policy, no penalty.
    Rambo,
}

impl Method {
    pub const ALL: [Method; 13] = [
        Method::Nuno,
        Method::NunoR,
        Method::NunoAl,
        Method::Mopo,
        Method::TatuMopo,
        Method::Bc,
        Method::Td3Bc,
        Method::Cql,
        Method::Edac,
        Method::Combo,
        Method::Morel,
        Method::Mobile,
        Method::Rambo,
    ];

    /// The name in grid files, and `fit-policy --algo`'s.
    pub fn as_str(self) -> &'static str {
        match self {
            Method::Nuno => "nuno",
            Method::NunoR => "nuno-r",
            Method::NunoAl => "nuno-al",
            Method::Mopo => "mopo",
            Method::TatuMopo => "tatu-mopo",
            Method::Bc => "bc",
            Method::Td3Bc => "td3-bc",
            Method::Cql => "cql",
            Method::Edac => "edac",
            Method::Combo => "combo",
            Method::Morel => "morel",
            Method::Mobile => "mobile",
            Method::Rambo => "rambo",
        }
    }

    /// Whether the method trains in the Gaussian ensemble (else the neural SDE, or none).
    pub fn uses_ensemble(self) -> bool {
        matches!(
            self,
            Method::Mopo
                | Method::TatuMopo
                | Method::Combo
                | Method::Morel
                | Method::Mobile
                | Method::Rambo
        )
    }

    /// Whether the method trains in the neural SDE (NUNO, NUNO^R, NUNO^al).
    pub fn uses_sde(self) -> bool {
        !self.is_model_free() && !self.uses_ensemble()
    }

    /// Whether the method is MOPO's policy step (MOPO, TATU+MOPO): its (h, λ)
    /// table and `--mopo-settings`.
    pub fn is_mopo(self) -> bool {
        matches!(self, Method::Mopo | Method::TatuMopo)
    }

    /// Whether `--mopo-settings` chooses the method's SAC settings: MOPO's
    /// policy step, and NUNO's loop (whose own are `MopoSettings::Nuno`).
    pub fn takes_mopo_settings(self) -> bool {
        self.is_mopo() || self.uses_sde()
    }

    /// The model the method trains in (`None`: it learns from the dataset
    /// alone); methods naming the same one share its fit per dataset and seed
    /// (NUNO and NUNO^al one SDE, MOPO and TATU+MOPO one ensemble), so their
    /// comparison is of the policy step alone.
    pub fn model_kind(self) -> Option<&'static str> {
        match self {
            Method::Nuno | Method::NunoAl => Some("sde"),
            Method::NunoR => Some("sde-reward"),
            Method::Mopo
            | Method::TatuMopo
            | Method::Combo
            | Method::Morel
            | Method::Mobile
            | Method::Rambo => Some("ensemble"),
            Method::Bc | Method::Td3Bc | Method::Cql | Method::Edac => None,
        }
    }

    /// The hidden sizes of the method's networks in its reference
    /// implementation: SAC's 2×256 for the model-based methods (NUNO's code,
    /// OfflineRL-Kit's MOPO), the model-free ones' own (CQL's 3×256).
    pub fn default_hidden(self) -> Vec<usize> {
        match super::LearnerConfig::for_method(self) {
            Ok(learner) => learner.hidden(),
            Err(_) if self == Method::Combo => super::CqlConfig::kit_sac().actor_hidden,
            Err(_) => super::SacConfig::new().actor_hidden,
        }
    }

    /// Whether the method learns from the dataset alone, with no model.
    pub fn is_model_free(self) -> bool {
        self.model_kind().is_none()
    }
}

/// Where a method's rollouts truncate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Truncation {
    /// At ε(h, α) from the model's own threshold table (NUNO, NUNO^R).
    ModelTable,
    /// At ε(h, α) computed on the aleatoric ‖σ‖ the same way (NUNO^al, Appendix D).
    AleatoricCvar,
    /// At the ensemble's largest disagreement over the dataset over the
    /// pessimism coefficient (TATU's `compute_max_disc`).
    DatasetDisagreement,
    /// Never (MOPO; the model-free methods, which roll nothing out).
    Never,
    /// MOReL's HALT: a step whose pairwise ensemble disagreement passes the
    /// pessimism coefficient × its largest value over the dataset ends the
    /// rollout as a terminal transition.
    Halt,
}

impl Truncation {
    /// Whether rollouts end once an accumulated signal passes a threshold
    /// (NUNO's, NUNO^al's and TATU's truncation; not MOReL's per-step HALT).
    pub fn accumulates(self) -> bool {
        matches!(
            self,
            Truncation::ModelTable | Truncation::AleatoricCvar | Truncation::DatasetDisagreement
        )
    }
}

impl Method {
    /// Where this method's rollouts truncate.
    pub fn truncation(self) -> Truncation {
        match self {
            Method::Nuno | Method::NunoR => Truncation::ModelTable,
            Method::NunoAl => Truncation::AleatoricCvar,
            Method::TatuMopo => Truncation::DatasetDisagreement,
            Method::Morel => Truncation::Halt,
            Method::Mopo
            | Method::Combo
            | Method::Mobile
            | Method::Rambo
            | Method::Bc
            | Method::Td3Bc
            | Method::Cql
            | Method::Edac => Truncation::Never,
        }
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for Method {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        Method::ALL
            .into_iter()
            .find(|m| m.as_str() == s)
            .ok_or_else(|| {
                let known: Vec<&str> = Method::ALL.iter().map(|m| m.as_str()).collect();
                format!("unknown method `{s}` (known: {})", known.join(", "))
            })
    }
}
