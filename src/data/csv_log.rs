//! A system's log as CSV: one row per time step, a header naming the
//! columns. Columns: `episode` (rows of one episode are consecutive), the
//! system's observation and action names, and optionally `reward` (on a row:
//! the reward of the transition that starts there), `terminal` and `timeout`
//! (1 on an episode's last row when it ended in a terminal state or at a time
//! limit) and `t` (time, increasing within an episode). Consecutive rows of
//! an episode are transitions; the last row's action and reward are unused.
//! Other columns are ignored. Without a `reward` column the system's reward
//! expression gives the rewards; a learned reward needs the column.
//!
//! Every error names the file, the line (the header is line 1) and the column.

use std::collections::BTreeSet;
use std::path::Path;

use ndarray::{Array1, Array2};

use super::{DataError, Dataset, DatasetMetadata, DatasetParts};
use crate::envs::{SystemReward, SystemSpec};

/// Where each needed column sits in the header.
struct Columns {
    episode: usize,
    observations: Vec<usize>,
    actions: Vec<usize>,
    reward: Option<usize>,
    terminal: Option<usize>,
    timeout: Option<usize>,
    t: Option<usize>,
}

/// One parsed row, with the line it came from.
struct Row {
    line: usize,
    episode: String,
    observation: Vec<f32>,
    action: Vec<f32>,
    reward: Option<f32>,
    terminal: bool,
    timeout: bool,
    t: Option<f64>,
}

/// Reads `path`, a CSV log of `system`.
pub fn read_csv_log(path: &Path, system: &SystemSpec) -> Result<Dataset, DataError> {
    let invalid = |message: String| DataError::Invalid {
        file: path.to_path_buf(),
        message,
    };
    let file = std::fs::File::open(path).map_err(|source| DataError::Io {
        file: path.to_path_buf(),
        source,
    })?;
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_reader(file);
    let header = reader
        .headers()
        .map_err(|e| invalid(format!("line 1: {e}")))?
        .clone();
    let columns = Columns::find(&header, system).map_err(&invalid)?;
    if columns.reward.is_none() && matches!(system.reward, SystemReward::Learned) {
        return Err(invalid(format!(
            "no `reward` column, and {}'s reward is learned from the data",
            system.name
        )));
    }
    let mut rows = Vec::new();
    for (i, record) in reader.records().enumerate() {
        let line = i + 2;
        let record = record.map_err(|e| invalid(format!("line {line}: {e}")))?;
        rows.push(columns.row(&record, &header, line).map_err(&invalid)?);
    }
    let parts = transitions(&rows, system).map_err(&invalid)?;
    Dataset::from_parts(parts, path)
}

impl Columns {
    fn find(header: &csv::StringRecord, system: &SystemSpec) -> Result<Self, String> {
        let mut seen = BTreeSet::new();
        for name in header {
            if !seen.insert(name) {
                return Err(format!("line 1: column `{name}` appears twice"));
            }
        }
        let at = |name: &str| header.iter().position(|h| h == name);
        let needed = |name: &str| {
            at(name).ok_or_else(|| format!("line 1: no column `{name}` (the system names it)"))
        };
        Ok(Self {
            episode: at("episode").ok_or("line 1: no column `episode`")?,
            observations: system
                .observations
                .iter()
                .map(|n| needed(n))
                .collect::<Result<_, _>>()?,
            actions: system
                .actions
                .iter()
                .map(|n| needed(n))
                .collect::<Result<_, _>>()?,
            reward: at("reward"),
            terminal: at("terminal"),
            timeout: at("timeout"),
            t: at("t"),
        })
    }

    fn row(
        &self,
        record: &csv::StringRecord,
        header: &csv::StringRecord,
        line: usize,
    ) -> Result<Row, String> {
        if record.len() != header.len() {
            return Err(format!(
                "line {line}: {} fields, the header has {}",
                record.len(),
                header.len()
            ));
        }
        let number = |c: usize| -> Result<f64, String> {
            let text = &record[c];
            let value: f64 = text.parse().map_err(|_| {
                format!(
                    "line {line}, column `{}`: `{text}` is not a number",
                    &header[c]
                )
            })?;
            if value.is_finite() {
                Ok(value)
            } else {
                Err(format!(
                    "line {line}, column `{}`: {text} is not finite",
                    &header[c]
                ))
            }
        };
        let flag = |c: Option<usize>| -> Result<bool, String> {
            let Some(c) = c else { return Ok(false) };
            match &record[c] {
                "0" | "" => Ok(false),
                "1" => Ok(true),
                other => Err(format!(
                    "line {line}, column `{}`: `{other}` is not 0 or 1",
                    &header[c]
                )),
            }
        };
        let values = |cs: &[usize]| {
            cs.iter()
                .map(|&c| number(c).map(|v| v as f32))
                .collect::<Result<Vec<_>, _>>()
        };
        Ok(Row {
            line,
            episode: record[self.episode].to_string(),
            observation: values(&self.observations)?,
            action: values(&self.actions)?,
            reward: self
                .reward
                .map(|c| number(c).map(|v| v as f32))
                .transpose()?,
            terminal: flag(self.terminal)?,
            timeout: flag(self.timeout)?,
            t: self.t.map(number).transpose()?,
        })
    }
}

/// The transitions of `rows`, episode by episode, with their rewards (the
/// column's, or the system's expression's).
fn transitions(rows: &[Row], system: &SystemSpec) -> Result<DatasetParts, String> {
    let (obs_dim, act_dim) = (system.obs_dim(), system.act_dim());
    let mut parts = Transitions::default();
    let mut ended = BTreeSet::new();
    let mut start = 0;
    while start < rows.len() {
        let episode = &rows[start].episode;
        if !ended.insert(episode.as_str()) {
            return Err(format!(
                "line {}: episode `{episode}` continues after another episode (an episode's rows must be consecutive)",
                rows[start].line
            ));
        }
        let end = start
            + rows[start..]
                .iter()
                .take_while(|r| &r.episode == episode)
                .count();
        parts.episode(&rows[start..end])?;
        start = end;
    }
    let n = parts.rewards.len();
    let observations =
        Array2::from_shape_vec((n, obs_dim), parts.observations).expect("rows of obs_dim");
    let actions = Array2::from_shape_vec((n, act_dim), parts.actions).expect("rows of act_dim");
    let next_observations =
        Array2::from_shape_vec((n, obs_dim), parts.next_observations).expect("rows of obs_dim");
    let rewards = match (&system.reward, parts.rewards.iter().all(Option::is_some)) {
        (_, true) => parts.rewards.into_iter().flatten().collect(),
        (SystemReward::Expression(expression), false) => expression.rewards(
            (
                observations.as_slice().expect("standard layout"),
                actions.as_slice().expect("standard layout"),
                next_observations.as_slice().expect("standard layout"),
            ),
            (obs_dim, act_dim),
        ),
        (SystemReward::Learned, false) => unreachable!("checked against the header"),
    };
    Ok(DatasetParts {
        observations,
        actions,
        rewards: Array1::from(rewards),
        next_observations,
        terminals: parts.terminals,
        timeouts: parts.timeouts,
        qpos: None,
        qvel: None,
        action_log_probs: None,
        metadata: DatasetMetadata::from([
            ("system".into(), system.name.clone()),
            ("source".into(), "csv log".into()),
        ]),
    })
}

/// The transitions gathered so far, column by column.
#[derive(Default)]
struct Transitions {
    observations: Vec<f32>,
    actions: Vec<f32>,
    next_observations: Vec<f32>,
    rewards: Vec<Option<f32>>,
    terminals: Vec<bool>,
    timeouts: Vec<bool>,
}

impl Transitions {
    /// One episode's rows: a transition from each row to the next; the last
    /// ends terminal or cut, as its row's flags say.
    fn episode(&mut self, rows: &[Row]) -> Result<(), String> {
        for pair in rows.windows(2) {
            let (row, next) = (&pair[0], &pair[1]);
            if let (Some(t), Some(t_next)) = (row.t, next.t)
                && t_next <= t
            {
                return Err(format!(
                    "line {}, column `t`: {t_next} does not increase on line {}'s {t}",
                    next.line, row.line
                ));
            }
            for early in [row.terminal, row.timeout] {
                if early {
                    return Err(format!(
                        "line {}: a terminal or timeout flag before the episode's last row",
                        row.line
                    ));
                }
            }
            self.observations.extend(&row.observation);
            self.actions.extend(&row.action);
            self.next_observations.extend(&next.observation);
            self.rewards.push(row.reward);
            let last = std::ptr::eq(next, rows.last().expect("two rows"));
            self.terminals.push(last && next.terminal);
            self.timeouts.push(last && !next.terminal);
        }
        Ok(())
    }
}
