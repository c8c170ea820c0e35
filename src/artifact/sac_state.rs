//! What every training checkpoint holds, whichever loop writes it: SAC's
//! networks and Adam state (moments by module path, so either SAC kernel
//! resumes either's run), the random generator's position, and the directory
//! written under a temporary name, fsynced, renamed and named by `LATEST`.

use std::collections::BTreeMap;
use std::fs::File;
use std::path::{Path, PathBuf};

use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::json_file::read_checked_weights;
use super::safetensors_file::safetensors_bytes;
use super::tensors::{NamedTensors, collect_tensors, load_tensors};
use super::{ArtifactError, sha256_hex};
use crate::agent::Sac;
use crate::nn::{AdamState, Moments};
use crate::shared::write_atomically;

const LATEST: &str = "LATEST";
const NETWORKS: &str = "networks.safetensors";
const ADAM: &str = "adam.safetensors";
const OPTIMIZERS: [&str; 3] = ["actor", "critic", "alpha"];

/// Where the generator stands: enough to continue its exact stream.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct RngState {
    seed: [u8; 32],
    stream: u64,
    word_pos: u128,
}

impl RngState {
    pub(crate) fn of(rng: &ChaCha8Rng) -> Self {
        Self {
            seed: rng.get_seed(),
            stream: rng.get_stream(),
            word_pos: rng.get_word_pos(),
        }
    }

    pub(crate) fn restore(&self) -> ChaCha8Rng {
        let mut rng = <ChaCha8Rng as rand::SeedableRng>::from_seed(self.seed);
        rng.set_stream(self.stream);
        rng.set_word_pos(self.word_pos);
        rng
    }
}

/// The SAC part of a checkpoint's `state.json`: the hashes of its two files
/// and Adam's step counts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct SacFiles {
    /// Adam steps taken, per optimiser.
    adam_time: BTreeMap<String, u64>,
    networks_sha256: String,
    adam_sha256: String,
}

/// The checkpoint directory `LATEST` names in `dir`, if any.
pub fn latest_checkpoint(dir: &Path) -> Result<Option<PathBuf>, ArtifactError> {
    let pointer = dir.join(LATEST);
    if !pointer.exists() {
        return Ok(None);
    }
    let name = std::fs::read_to_string(&pointer).map_err(|e| ArtifactError::io(&pointer, e))?;
    let name = name.trim();
    if name.is_empty() || name.contains('/') || name.contains("..") {
        return Err(ArtifactError::Invalid(format!(
            "{}: `{name}` is not a checkpoint name",
            pointer.display()
        )));
    }
    Ok(Some(dir.join(name)))
}

/// Writes checkpoint `name` in `dir` with `write` (into a temporary
/// directory, then renamed), points `LATEST` at it and removes the older
/// checkpoints, those whose names start like `name` up to its first `-`.
pub(crate) fn save_checkpoint_dir(
    dir: &Path,
    name: &str,
    write: impl FnOnce(&Path) -> Result<(), ArtifactError>,
) -> Result<PathBuf, ArtifactError> {
    std::fs::create_dir_all(dir).map_err(|e| ArtifactError::io(dir, e))?;
    let final_dir = dir.join(name);
    let tmp = dir.join(format!(".{name}.tmp-{}", std::process::id()));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(|e| ArtifactError::io(&tmp, e))?;
    }
    std::fs::create_dir_all(&tmp).map_err(|e| ArtifactError::io(&tmp, e))?;
    let written = write(&tmp).and_then(|()| {
        if final_dir.exists() {
            std::fs::remove_dir_all(&final_dir).map_err(|e| ArtifactError::io(&final_dir, e))?;
        }
        std::fs::rename(&tmp, &final_dir).map_err(|e| ArtifactError::io(&final_dir, e))?;
        File::open(dir)
            .and_then(|d| d.sync_all())
            .map_err(|e| ArtifactError::io(dir, e))
    });
    if let Err(e) = written {
        let _ = std::fs::remove_dir_all(&tmp);
        return Err(e);
    }
    let pointer = dir.join(LATEST);
    write_atomically(
        &pointer,
        |p| std::fs::write(p, name).map_err(|e| ArtifactError::io(p, e)),
        |e| ArtifactError::io(&pointer, e),
    )?;
    // Older checkpoints are no longer needed once LATEST names the new one.
    let prefix = name.split_inclusive('-').next().unwrap_or(name);
    for entry in std::fs::read_dir(dir).map_err(|e| ArtifactError::io(dir, e))? {
        let path = entry.map_err(|e| ArtifactError::io(dir, e))?.path();
        let file_name = path.file_name().map(|n| n.to_string_lossy().into_owned());
        if let Some(other) = file_name
            && other.starts_with(prefix)
            && other != name
        {
            std::fs::remove_dir_all(&path).map_err(|e| ArtifactError::io(&path, e))?;
        }
    }
    Ok(final_dir)
}

/// Writes and fsyncs a file inside a temporary checkpoint directory.
pub(crate) fn write_synced(path: &Path, bytes: &[u8]) -> Result<(), ArtifactError> {
    std::fs::write(path, bytes)
        .and_then(|()| File::open(path)?.sync_all())
        .map_err(|e| ArtifactError::io(path, e))
}

/// Writes `sac`'s networks and Adam state into checkpoint directory `dir`.
pub(crate) fn write_sac(dir: &Path, sac: &Sac) -> Result<SacFiles, ArtifactError> {
    let mut networks = NamedTensors::new();
    let mut add = |prefix: &str, tensors: NamedTensors| {
        for (k, v) in tensors {
            networks.insert(format!("{prefix}.{k}"), v);
        }
    };
    add("actor", collect_tensors(&sac.actor));
    add("critic", collect_tensors(&sac.critic));
    add("target_critic", collect_tensors(&sac.target_critic));
    add("temperature", collect_tensors(&sac.temperature));
    let networks = safetensors_bytes(&networks, None)?;
    write_synced(&dir.join(NETWORKS), &networks)?;

    let a = &sac.adam;
    let mut adam = NamedTensors::new();
    let mut adam_time = BTreeMap::new();
    for (name, state) in OPTIMIZERS.iter().zip([&a.actor, &a.critic, &a.alpha]) {
        adam_time.insert(name.to_string(), state.time);
        put_moments(&mut adam, &format!("{name}/"), state);
    }
    let adam = safetensors_bytes(&adam, None)?;
    write_synced(&dir.join(ADAM), &adam)?;
    Ok(SacFiles {
        adam_time,
        networks_sha256: sha256_hex(&networks),
        adam_sha256: sha256_hex(&adam),
    })
}

/// Restores `sac`'s networks and Adam state from checkpoint directory `dir`.
pub(crate) fn read_sac(dir: &Path, files: &SacFiles, sac: &mut Sac) -> Result<(), ArtifactError> {
    let networks = read_checked_weights(&dir.join(NETWORKS), &files.networks_sha256)?;
    let part = |prefix: &str| -> NamedTensors {
        let dotted = format!("{prefix}.");
        networks
            .iter()
            .filter_map(|(k, v)| {
                k.strip_prefix(&dotted)
                    .map(|rest| (rest.to_string(), v.clone()))
            })
            .collect()
    };
    let device = sac.device().clone();
    let plain = device.clone().inner();
    sac.actor = load_tensors(sac.actor.clone(), &part("actor"), &device)?;
    sac.critic = load_tensors(sac.critic.clone(), &part("critic"), &device)?;
    sac.target_critic = load_tensors(sac.target_critic.clone(), &part("target_critic"), &plain)?;
    sac.temperature = load_tensors(sac.temperature.clone(), &part("temperature"), &device)?;
    let mut adam = read_checked_weights(&dir.join(ADAM), &files.adam_sha256)?;
    let a = &mut sac.adam;
    for (name, optimizer) in OPTIMIZERS
        .iter()
        .zip([&mut a.actor, &mut a.critic, &mut a.alpha])
    {
        *optimizer = read_adam(name, &mut adam, files, &networks)?;
    }
    if let Some(extra) = adam.keys().next() {
        return Err(ArtifactError::UnexpectedTensor(format!("{ADAM}: {extra}")));
    }
    Ok(())
}

/// Optimiser `name`'s state, taking its moments out of `adam`: every moment
/// belongs to a saved parameter of the network `name` steps and has its size.
fn read_adam(
    name: &str,
    adam: &mut NamedTensors,
    files: &SacFiles,
    networks: &NamedTensors,
) -> Result<AdamState, ArtifactError> {
    let network = if name == "alpha" { "temperature" } else { name };
    let moments = take_moments(adam, &format!("{name}/"), |path| {
        networks
            .get(&format!("{network}.{path}"))
            .map(|(_, values)| values.len())
    })?;
    Ok(AdamState {
        time: files.adam_time.get(name).copied().unwrap_or(0),
        moments,
    })
}

/// Adds `state`'s moments to `adam` as `{prefix}{path}/first` and `/second`.
pub(crate) fn put_moments(adam: &mut NamedTensors, prefix: &str, state: &AdamState) {
    for (path, moments) in &state.moments {
        let n = moments.first.len();
        adam.insert(
            format!("{prefix}{path}/first"),
            (vec![n], moments.first.clone()),
        );
        adam.insert(
            format!("{prefix}{path}/second"),
            (vec![n], moments.second.clone()),
        );
    }
}

/// Takes the moments under `prefix` out of `adam`, by parameter path; each
/// must belong to a parameter `size` knows and have its size.
pub(crate) fn take_moments(
    adam: &mut NamedTensors,
    prefix: &str,
    size: impl Fn(&str) -> Option<usize>,
) -> Result<BTreeMap<String, Moments>, ArtifactError> {
    let paths: Vec<String> = adam
        .keys()
        .filter_map(|k| k.strip_prefix(prefix)?.strip_suffix("/first"))
        .map(str::to_string)
        .collect();
    let mut moments = BTreeMap::new();
    for path in paths {
        let first = adam.remove(&format!("{prefix}{path}/first"));
        let second = adam.remove(&format!("{prefix}{path}/second"));
        match (first, second, size(&path)) {
            (Some((_, first)), Some((_, second)), Some(n))
                if first.len() == n && second.len() == n =>
            {
                moments.insert(path, Moments { first, second });
            }
            _ => {
                return Err(ArtifactError::Invalid(format!(
                    "{ADAM}: the moments of `{prefix}{path}` do not match a saved parameter"
                )));
            }
        }
    }
    Ok(moments)
}
