//! What a cell leaves behind and what a report makes of it: `result.json` in
//! the cell's folder once it has finished (its best and final D4RL-normalised
//! scores and its learning curve, from fit-policy's `metrics.jsonl`), the
//! status of unfinished cells, and the Table 1/2-style aggregate (mean ± std
//! over seeds per dataset × method).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::ExperimentError;
use super::grid::{Budget, Cell};
use crate::agent::EpochRecord;
use crate::agent::Method;
use crate::agent::MopoSettings;
use crate::artifact::{
    latest_checkpoint, read_dynamics_metadata, read_versioned_json_filled, sha256_file, write_json,
};
use crate::sde::FitConfig;
use crate::shared::{Metric, MetricsTable, mean_std_sample};

pub const RESULT_SCHEMA_VERSION: u32 = 1;
const RESULT: &str = "result.json";

/// A finished cell.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CellResult {
    pub schema_version: u32,
    pub cell: Cell,
    /// The best evaluation's normalised score (the paper's "best score"; for a system file's
    /// data, the return in the model) and its step.
    pub best_score: f64,
    pub best_step: usize,
    /// The last evaluation's normalised score.
    pub final_score: f64,
    pub steps: usize,
    /// (gradient step, normalised score) after every epoch.
    pub curve: Vec<(usize, f64)>,
    /// Wall-clock seconds of the policy's epochs (updates, rollouts,
    /// evaluation, η probe; the model fit not included). Absent from results
    /// written before it was recorded.
    #[serde(default)]
    pub policy_seconds: Option<f64>,
    /// The grid's budget the cell ran under. Absent from results written
    /// before it was recorded.
    #[serde(default)]
    pub budget: Option<Budget>,
    /// SHA-256 of the dataset file when the cell was summarised. Absent from
    /// results written before it was recorded.
    #[serde(default)]
    pub dataset_sha256: Option<String>,
}

/// Where a cell stands.
#[derive(Debug, Clone, PartialEq)]
pub enum CellStatus {
    Done(Box<CellResult>),
    /// Policy training has checkpointed this many epochs.
    Partial {
        epochs: usize,
    },
    /// Nothing yet, or only the model.
    Pending,
}

/// The cell's folder under the experiment's output folder.
pub fn cell_dir(root: &Path, cell: &Cell) -> PathBuf {
    root.join(cell.id())
}

/// Reads fit-policy's `metrics.jsonl` into a result for `cell`, run under `budget`.
pub fn summarize_run(
    cell: &Cell,
    budget: &Budget,
    metrics: &Path,
) -> Result<CellResult, ExperimentError> {
    let text = std::fs::read_to_string(metrics).map_err(|e| ExperimentError::Io {
        file: metrics.to_path_buf(),
        source: e,
    })?;
    let records = text
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(serde_json::from_str::<EpochRecord>)
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| ExperimentError::Invalid(format!("{}: {e}", metrics.display())))?;
    let last = records.last().ok_or_else(|| {
        ExperimentError::Invalid(format!("{}: no finished epoch", metrics.display()))
    })?;
    // A system file's cells score the return in the model (it has no simulator).
    let best = records
        .iter()
        .max_by(|a, b| a.eval.score().total_cmp(&b.eval.score()))
        .unwrap_or(last);
    Ok(CellResult {
        schema_version: RESULT_SCHEMA_VERSION,
        cell: cell.clone(),
        best_score: best.eval.score(),
        best_step: best.step,
        final_score: last.eval.score(),
        steps: last.step,
        curve: records.iter().map(|r| (r.step, r.eval.score())).collect(),
        policy_seconds: Some(records.iter().map(|r| r.seconds.total()).sum()),
        budget: Some(budget.clone()),
        dataset_sha256: Some(sha256_file(&cell.file)?),
    })
}

/// Marks `cell` finished with `result` (atomically: a cell is done or not).
pub fn write_result(root: &Path, result: &CellResult) -> Result<(), ExperimentError> {
    Ok(write_json(
        &cell_dir(root, &result.cell).join(RESULT),
        result,
    )?)
}

/// A cell's `result.json`.
pub fn read_result(path: &Path) -> Result<CellResult, ExperimentError> {
    Ok(read_versioned_json_filled(
        path,
        RESULT_SCHEMA_VERSION,
        fill_older_budget,
    )?)
}

/// Every `result.json` under each of `dirs` (at any depth), in path order:
/// finished cells of any number of experiments, kept or running.
pub fn collect_results(dirs: &[PathBuf]) -> Result<Vec<CellResult>, ExperimentError> {
    let mut files = Vec::new();
    let mut pending: Vec<PathBuf> = dirs.to_vec();
    while let Some(dir) = pending.pop() {
        let io = |e| ExperimentError::Io {
            file: dir.clone(),
            source: e,
        };
        for entry in std::fs::read_dir(&dir).map_err(io)? {
            let path = entry.map_err(io)?.path();
            if path.is_dir() {
                pending.push(path);
            } else if path.file_name().is_some_and(|n| n == RESULT) {
                files.push(path);
            }
        }
    }
    files.sort();
    files.iter().map(|f| read_result(f)).collect()
}

/// A budget recorded before `mopo_settings` existed ran MOPO on NUNO's SAC settings.
fn fill_older_budget(value: &mut serde_json::Value) {
    if let Some(budget) = value.get_mut("budget").and_then(|b| b.as_object_mut()) {
        budget
            .entry("mopo_settings")
            .or_insert(serde_json::json!(MopoSettings::Nuno));
    }
}

/// Where `cell` stands under `root` with the grid's `budget`. A cell finished
/// at fewer policy steps (the budget has since grown) is partial, to be
/// continued from its last checkpoint; one finished under any other budget
/// is an error, so a table never mixes budgets.
pub fn cell_status(
    root: &Path,
    cell: &Cell,
    budget: &Budget,
) -> Result<CellStatus, ExperimentError> {
    let dir = cell_dir(root, cell);
    let result = dir.join(RESULT);
    if result.is_file() {
        let mut result = read_result(&result)?;
        if !result.cell.is_same_cell_as(cell) {
            let old = &result.cell;
            return Err(ExperimentError::Invalid(format!(
                "{}: written for another cell (preset {}, dataset file {}); move the old experiment away",
                dir.display(),
                old.preset.as_deref().unwrap_or("none: a system file's"),
                old.file_in_grid.display()
            )));
        }
        if let Some(then) = &result.budget {
            let method = cell.method;
            let changed = budget_changes(&then.for_method(method), &budget.for_method(method));
            if !changed.is_empty() {
                return Err(ExperimentError::Invalid(format!(
                    "{}: finished under another budget ({}); give the grid another --out, or move this folder away",
                    dir.display(),
                    changed.join("; ")
                )));
            }
        }
        if result.steps < budget.policy_steps {
            return Ok(CellStatus::Partial {
                epochs: result.curve.len(),
            });
        }
        // Where the cell sits in this grid, and its file as this grid names it.
        result.cell = cell.clone();
        return Ok(CellStatus::Done(Box::new(result)));
    }
    match latest_checkpoint(&dir.join("policy/checkpoints"))? {
        Some(checkpoint) => {
            let epochs = checkpoint
                .file_name()
                .and_then(|n| n.to_str()?.strip_prefix("epoch-")?.parse().ok())
                .unwrap_or(0);
            Ok(CellStatus::Partial { epochs })
        }
        None => Ok(CellStatus::Pending),
    }
}

/// The budget's entries that differ between `then` and `now`, as "name: then
/// then, now now"; more policy steps now is not a change (the cell continues).
fn budget_changes(then: &Budget, now: &Budget) -> Vec<String> {
    let as_map = |b: &Budget| match serde_json::to_value(b) {
        Ok(serde_json::Value::Object(map)) => map,
        _ => serde_json::Map::new(),
    };
    let (then_map, now_map) = (as_map(then), as_map(now));
    then_map
        .iter()
        .filter(|(key, value)| now_map.get(*key) != Some(*value))
        .filter(|(key, _)| {
            !(key.as_str() == "policy_steps" && now.policy_steps > then.policy_steps)
        })
        .map(|(key, value)| {
            let now = now_map.get(key).map_or("none".into(), ToString::to_string);
            format!("{key}: {value} then, {now} now")
        })
        .collect()
}

/// The settings of an SDE fit that a grid's budget gives, by name.
fn budget_fit_settings(fit: &FitConfig) -> [(&'static str, serde_json::Value); 7] {
    use serde_json::json;
    [
        ("max_steps", json!(fit.max_steps)),
        ("likelihood", json!(fit.loss.likelihood)),
        ("step_discount", json!(fit.loss.step_discount)),
        ("eta_losses", json!(fit.loss.eta_losses)),
        ("sample_noise_scale", json!(fit.model.sample_noise_scale)),
        ("drift_inputs", json!(fit.model.drift_inputs)),
        ("reward_model", json!(fit.model.reward_model)),
    ]
}

/// Refuses the SDE in `dir` where it was fitted under other budget settings
/// than `wanted` and ε's `wanted_margin` (a grid edited after its models were
/// fitted), naming each: a cell would otherwise train its policy in a model
/// its budget does not describe. What a model did not record is taken as it is.
pub fn check_fitted_sde(
    dir: &Path,
    wanted: &FitConfig,
    wanted_margin: f32,
) -> Result<(), ExperimentError> {
    let provenance = read_dynamics_metadata(dir)?.provenance;
    let Some(fitted) = provenance.fit else {
        return Ok(());
    };
    let margin = provenance.thresholds.and_then(|t| t.max_margin);
    let changed = fit_changes((&fitted, margin), (wanted, wanted_margin));
    if changed.is_empty() {
        return Ok(());
    }
    Err(ExperimentError::Invalid(format!(
        "{}: fitted under another budget ({}); give the grid another --out, or move this folder away",
        dir.display(),
        changed.join("; ")
    )))
}

/// The budget's fit settings that differ between a fit `then` (its ε margin,
/// if recorded) and the one wanted `now`, as "name: then then, now now".
pub fn fit_changes(then: (&FitConfig, Option<f32>), now: (&FitConfig, f32)) -> Vec<String> {
    let mut changed: Vec<String> = (budget_fit_settings(then.0).into_iter())
        .zip(budget_fit_settings(now.0))
        .filter(|(a, b)| a.1 != b.1)
        .map(|((name, a), (_, b))| format!("{name}: {a} then, {b} now"))
        .collect();
    if let Some(margin) = then.1.filter(|&m| m != now.1) {
        changed.push(format!(
            "threshold_max_margin: {margin} then, {} now",
            now.1
        ));
    }
    changed
}

/// Policy training left in a grid, each method at its own pace.
#[derive(Debug, Clone, PartialEq)]
pub struct TimeLeft {
    /// The paced methods' cells: seconds per epoch over the method's finished
    /// cells times the epochs its cells have not yet run.
    pub seconds: f64,
    /// Methods with cells to run and no finished, timed cell to pace them by.
    pub unpaced: Vec<Method>,
}

/// Policy training left in a grid whose cells each run `epochs_per_cell`.
/// Paced per method, not across them: one method's update can cost 65 times
/// another's (EDAC's 50 critics against SAC's two, BENCHMARKS.md), so the
/// cheap methods' finished cells would understate an expensive one's.
pub fn policy_time_left(cells: &[(Method, &CellStatus)], epochs_per_cell: usize) -> TimeLeft {
    // Per method: recorded seconds, the epochs they timed, epochs left.
    let mut paces: BTreeMap<Method, (f64, usize, usize)> = BTreeMap::new();
    for (method, status) in cells {
        let pace = paces.entry(*method).or_default();
        match status {
            CellStatus::Done(r) => {
                if let Some(s) = r.policy_seconds {
                    pace.0 += s;
                    pace.1 += r.curve.len();
                }
            }
            CellStatus::Partial { epochs } => pace.2 += epochs_per_cell.saturating_sub(*epochs),
            CellStatus::Pending => pace.2 += epochs_per_cell,
        }
    }
    let mut left = TimeLeft {
        seconds: 0.0,
        unpaced: Vec::new(),
    };
    for (method, (seconds, timed, epochs)) in paces.into_iter().filter(|p| p.1.2 > 0) {
        match timed {
            0 => left.unpaced.push(method),
            _ => left.seconds += seconds / timed as f64 * epochs as f64,
        }
    }
    left
}

/// Mean ± std over the seeds of one dataset × method.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    pub dataset: String,
    pub method: Method,
    pub runs: usize,
    pub best_mean: f64,
    pub best_std: f64,
    pub final_mean: f64,
    pub final_std: f64,
}

/// Aggregates finished cells per dataset × method, datasets in `dataset_order`
/// (the grid file's order, whichever of their cells have finished; a dataset
/// not named there comes last).
pub fn summarize(results: &[CellResult], dataset_order: &[&str]) -> Vec<Summary> {
    let mut groups: BTreeMap<(usize, &str, Method), Vec<&CellResult>> = BTreeMap::new();
    for r in results {
        let place = dataset_order
            .iter()
            .position(|d| *d == r.cell.dataset)
            .unwrap_or(dataset_order.len());
        groups
            .entry((place, &r.cell.dataset, r.cell.method))
            .or_default()
            .push(r);
    }
    groups
        .into_values()
        .map(|runs| {
            let (best_mean, best_std) = mean_std_sample(runs.iter().map(|r| r.best_score));
            let (final_mean, final_std) = mean_std_sample(runs.iter().map(|r| r.final_score));
            Summary {
                dataset: runs[0].cell.dataset.clone(),
                method: runs[0].cell.method,
                runs: runs.len(),
                best_mean,
                best_std,
                final_mean,
                final_std,
            }
        })
        .collect()
}

/// One dataset × method's learning curve: the normalised score at each
/// evaluated step, the mean over the seeds that reached it.
#[derive(Debug, Clone, PartialEq)]
pub struct MeanCurve {
    pub dataset: String,
    pub method: Method,
    pub seeds: usize,
    /// (step, mean score), by step.
    pub points: Vec<(usize, f64)>,
}

/// Each dataset × method's mean learning curve over its seeds, by dataset
/// then method.
pub fn mean_curves(results: &[CellResult]) -> Vec<MeanCurve> {
    let mut groups: BTreeMap<(&str, Method), Vec<&CellResult>> = BTreeMap::new();
    for r in results {
        groups
            .entry((&r.cell.dataset, r.cell.method))
            .or_default()
            .push(r);
    }
    groups
        .into_iter()
        .map(|((dataset, method), runs)| {
            let mut steps: BTreeMap<usize, Vec<f64>> = BTreeMap::new();
            for &(step, score) in runs.iter().flat_map(|run| &run.curve) {
                steps.entry(step).or_default().push(score);
            }
            MeanCurve {
                dataset: dataset.to_string(),
                method,
                seeds: runs.len(),
                points: steps
                    .into_iter()
                    .map(|(step, scores)| (step, scores.iter().sum::<f64>() / scores.len() as f64))
                    .collect(),
            }
        })
        .collect()
}

/// Mean and sample standard deviation (0 for one run).
/// One line per finished cell.
pub fn results_csv(results: &[CellResult]) -> String {
    MetricsTable::new()
        .column("dataset", |r: &CellResult| r.cell.dataset.as_str().into())
        .column("method", |r: &CellResult| r.cell.method.to_string().into())
        .column("seed", |r: &CellResult| r.cell.seed.into())
        .column("best_score", |r: &CellResult| r.best_score.into())
        .column("best_step", |r: &CellResult| r.best_step.into())
        .column("final_score", |r: &CellResult| r.final_score.into())
        .column("steps", |r: &CellResult| r.steps.into())
        .column("policy_seconds", |r: &CellResult| {
            r.policy_seconds
                .map_or_else(Metric::none, |s| Metric::fixed(s, 1))
        })
        .csv(results)
}

/// A Table 1/2-style markdown table: datasets as rows, methods as columns,
/// best score mean ± std (runs; a single run's score alone), then the same
/// for the final score.
pub fn markdown_table(summaries: &[Summary]) -> String {
    let mut methods: Vec<Method> = summaries.iter().map(|s| s.method).collect();
    methods.sort();
    methods.dedup();
    let mut datasets: Vec<&str> = Vec::new();
    for s in summaries {
        if !datasets.contains(&s.dataset.as_str()) {
            datasets.push(&s.dataset);
        }
    }
    let mut out = String::new();
    for (title, pick) in [
        (
            "Best normalised score",
            (|s: &Summary| (s.best_mean, s.best_std)) as fn(&Summary) -> (f64, f64),
        ),
        ("Final normalised score", |s: &Summary| {
            (s.final_mean, s.final_std)
        }),
    ] {
        out.push_str(&format!(
            "### {title} (mean ± std over seeds)\n\n| dataset |"
        ));
        for m in &methods {
            out.push_str(&format!(" {m} |"));
        }
        out.push_str("\n|---|");
        out.push_str(&"---|".repeat(methods.len()));
        out.push('\n');
        for d in &datasets {
            out.push_str(&format!("| {d} |"));
            for m in &methods {
                match summaries.iter().find(|s| s.dataset == *d && s.method == *m) {
                    // One run has no spread to state.
                    Some(s) if s.runs == 1 => out.push_str(&format!(" {:.1} (1) |", pick(s).0)),
                    Some(s) => {
                        let (mean, std) = pick(s);
                        out.push_str(&format!(" {mean:.1} ± {std:.1} ({}) |", s.runs));
                    }
                    None => out.push_str(" – |"),
                }
            }
            out.push('\n');
        }
        out.push('\n');
    }
    out
}

/// A finished hopper cell of 1000 steps for tests: `dataset` under Table 3's row `preset`.
#[cfg(test)]
pub(super) fn test_result(
    index: usize,
    dataset: &str,
    preset: &str,
    method: Method,
    seed: u64,
    best: f64,
) -> CellResult {
    use crate::envs::{ObservationLayout, TaskName};
    CellResult {
        schema_version: RESULT_SCHEMA_VERSION,
        cell: Cell {
            index,
            dataset: dataset.into(),
            file_in_grid: PathBuf::from(format!("{dataset}.hdf5")),
            file: PathBuf::from(format!("{dataset}.hdf5")),
            task: Some(TaskName::Hopper),
            layout: ObservationLayout::D4rl,
            preset: Some(preset.into()),
            system_in_grid: None,
            system: None,
            policy: None,
            mopo: None,
            rambo: None,
            combo: None,
            edac: None,
            method,
            seed,
        },
        best_score: best,
        best_step: 0,
        final_score: 0.0,
        steps: 1000,
        curve: vec![(1000, 0.0)],
        policy_seconds: None,
        budget: None,
        dataset_sha256: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn result(index: usize, dataset: &str, method: Method, seed: u64, best: f64) -> CellResult {
        test_result(index, dataset, "hopper-random", method, seed, best)
    }

    fn done(epochs: usize, policy_seconds: Option<f64>) -> CellStatus {
        CellStatus::Done(Box::new(CellResult {
            steps: epochs * 1000,
            curve: (1..=epochs).map(|e| (e * 1000, 0.0)).collect(),
            policy_seconds,
            ..result(0, "d", Method::Nuno, 0, 0.0)
        }))
    }

    #[test]
    fn the_report_lists_datasets_in_the_grid_order_whichever_cells_finished() {
        // Seeds outermost: dataset a's seed-0 cells are missing, so b's
        // finished cells come first by index, yet the grid lists a first.
        let results = [
            result(5, "b", Method::Mopo, 0, 10.0),
            result(4, "b", Method::Nuno, 0, 30.0),
            result(6, "a", Method::Nuno, 1, 70.0),
            result(10, "b", Method::Nuno, 1, 50.0),
            result(8, "a", Method::Nuno, 2, 80.0),
        ];
        let summaries = summarize(&results, &["a", "b"]);
        let rows: Vec<(&str, Method, usize, f64)> = summaries
            .iter()
            .map(|s| (s.dataset.as_str(), s.method, s.runs, s.best_mean))
            .collect();
        assert_eq!(
            rows,
            [
                ("a", Method::Nuno, 2, 75.0),
                ("b", Method::Nuno, 2, 40.0),
                ("b", Method::Mopo, 1, 10.0),
            ]
        );
        let table = markdown_table(&summaries);
        let a = table.find("| a |").unwrap();
        let b = table.find("| b |").unwrap();
        assert!(a < b, "{table}");
    }

    #[test]
    fn a_grown_policy_budget_is_no_change_but_anything_else_is() {
        let then: Budget = toml::from_str("model_steps = 20\npolicy_steps = 100").unwrap();
        let with = |text: &str| -> Budget { toml::from_str(text).unwrap() };
        assert!(budget_changes(&then, &then).is_empty());
        assert!(budget_changes(&then, &with("model_steps = 20\npolicy_steps = 300")).is_empty());
        assert_eq!(
            budget_changes(&then, &with("model_steps = 20\npolicy_steps = 50")),
            ["policy_steps: 100 then, 50 now"]
        );
        // As the runner compares them: resolved for the method (the hidden
        // sizes left out are the method's own).
        let now = with("model_steps = 30\npolicy_steps = 100\nhidden = [8]");
        assert_eq!(
            budget_changes(
                &then.for_method(Method::Nuno),
                &now.for_method(Method::Nuno)
            ),
            [
                "hidden: [256,256] then, [8] now",
                "model_steps: 20 then, 30 now"
            ]
        );
    }

    /// A setting only the other kind of method reads changes nothing for a
    /// cell, nor does naming a method's own default; an older result's MOPO
    /// ran on NUNO's settings.
    #[test]
    fn only_the_methods_own_settings_count_as_a_budget_change() {
        let with = |text: &str| -> Budget { toml::from_str(text).unwrap() };
        let plain = with("model_steps = 20\npolicy_steps = 100");
        let kit = with("model_steps = 20\npolicy_steps = 100\nmopo_settings = \"offlinerl-kit\"");
        let code = with("model_steps = 20\npolicy_steps = 100\nrecipe = \"code\"");
        let changes = |then: &Budget, now: &Budget, method| {
            budget_changes(&then.for_method(method), &now.for_method(method))
        };
        assert!(changes(&plain, &code, Method::Mopo).is_empty());
        assert!(changes(&plain, &kit, Method::Combo).is_empty());
        // Naming the default is no change; NUNO's settings are, with their rollout batch.
        assert!(changes(&plain, &kit, Method::Mopo).is_empty());
        let nuno_sac = with("model_steps = 20\npolicy_steps = 100\nmopo_settings = \"nuno\"");
        assert!(changes(&plain, &nuno_sac, Method::Nuno).is_empty());
        // And the other way round for NUNO: MOPO's settings are a change.
        assert_eq!(
            changes(&plain, &kit, Method::Nuno),
            [
                "mopo_settings: null then, \"offlinerl-kit\" now",
                "rollout_batch: 5000 then, 50000 now"
            ]
        );
        assert_eq!(
            changes(&plain, &nuno_sac, Method::Mopo),
            [
                "mopo_settings: \"offlinerl-kit\" then, \"nuno\" now",
                "rollout_batch: 50000 then, 5000 now"
            ]
        );
        assert_eq!(
            changes(&plain, &code, Method::NunoAl),
            ["recipe: \"paper\" then, \"code\" now"]
        );
        let mut old = serde_json::json!({"budget": {"model_steps": 20, "policy_steps": 100}});
        fill_older_budget(&mut old);
        let old: Budget = serde_json::from_value(old["budget"].clone()).unwrap();
        let nuno = with("model_steps = 20\npolicy_steps = 100\nmopo_settings = \"nuno\"");
        assert!(changes(&old, &nuno, Method::Mopo).is_empty());
        assert!(!changes(&old, &kit, Method::TatuMopo).is_empty());
    }

    #[test]
    fn time_left_paces_each_method_by_its_own_finished_cells() {
        // NUNO: 10 + 10 epochs in 30 s + 50 s, 4 s an epoch, an untimed result
        // adding nothing; left 10 − 4 of a partial cell and 10 of a pending one.
        // MOPO: 10 epochs in 200 s, 20 s an epoch, one pending cell. EDAC has
        // finished nothing; MOReL has nothing left.
        let (nuno, mopo) = (
            [done(10, Some(30.0)), done(10, Some(50.0)), done(10, None)],
            done(10, Some(200.0)),
        );
        let (partial, pending) = (CellStatus::Partial { epochs: 4 }, CellStatus::Pending);
        let cells = [
            (Method::Nuno, &nuno[0]),
            (Method::Nuno, &nuno[1]),
            (Method::Nuno, &nuno[2]),
            (Method::Nuno, &partial),
            (Method::Nuno, &pending),
            (Method::Mopo, &mopo),
            (Method::Mopo, &pending),
            (Method::Edac, &pending),
            (Method::Morel, &mopo),
        ];
        let left = policy_time_left(&cells, 10);
        assert_eq!(left.seconds, 4.0 * 16.0 + 20.0 * 10.0);
        assert_eq!(left.unpaced, [Method::Edac]);
        let untimed = policy_time_left(&cells[2..5], 10);
        assert_eq!(
            (untimed.seconds, untimed.unpaced),
            (0.0, vec![Method::Nuno])
        );
    }
}
