//! The paper's Tables 1 (D4RL) and 2 (NeoRL): its published best scores per
//! dataset and method, and the table of nuno's own finished cells laid out as
//! those tables (dataset rows in the paper's order, method columns), the
//! paper's figure for the same cell beside each of nuno's.

use std::collections::BTreeMap;

use super::ExperimentError;
use super::results::CellResult;
use crate::agent::{Method, PRESETS};
use crate::shared::mean_std_sample;

/// A published score: the mean of the best normalised scores over the
/// paper's runs, and their std where the table gives one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaperScore {
    pub mean: f64,
    pub std: Option<f64>,
}

/// A dataset's row: the preset name, then (mean, std) per column.
type Row<const N: usize> = (&'static str, [(f64, Option<f64>); N]);

/// Table 1's columns, by nuno's method names (those nuno lacks as the paper spells them).
const TABLE_1_METHODS: [&str; 9] = [
    "nuno",
    "nuno-r",
    "mobile",
    "tatu-mopo",
    "mopo",
    "combo",
    "morel",
    "rambo",
    "edac",
];

/// Table 1, in its order (D4RL v2, five runs of 1M gradient steps for NUNO).
#[rustfmt::skip]
const TABLE_1: [Row<9>; 12] = [
    ("halfcheetah-random", [(52.7, Some(3.4)), (52.2, Some(0.5)), (39.3, Some(3.0)), (33.3, None), (35.9, None), (38.8, None), (38.9, None), (39.5, None), (28.4, None)]),
    ("hopper-random", [(73.2, Some(9.8)), (53.7, Some(13.9)), (31.9, Some(0.6)), (31.9, None), (16.7, None), (17.9, None), (38.1, None), (25.4, None), (25.3, None)]),
    ("walker2d-random", [(27.7, Some(0.9)), (28.1, Some(1.2)), (17.9, Some(6.6)), (10.4, None), (4.2, None), (7.0, None), (16.0, None), (0.0, None), (16.6, None)]),
    ("halfcheetah-medium", [(68.8, Some(0.4)), (64.7, Some(0.5)), (74.6, Some(1.2)), (61.9, None), (73.1, None), (54.2, None), (60.7, None), (77.9, None), (65.9, None)]),
    ("hopper-medium", [(104.6, Some(0.2)), (104.4, Some(0.3)), (106.6, Some(0.6)), (104.3, None), (38.3, None), (97.2, None), (84.0, None), (87.0, None), (101.6, None)]),
    ("walker2d-medium", [(85.4, Some(0.9)), (92.6, Some(1.3)), (87.7, Some(1.1)), (77.9, None), (41.2, None), (81.9, None), (72.8, None), (84.9, None), (92.5, None)]),
    ("halfcheetah-medium-replay", [(66.5, Some(0.2)), (64.6, Some(0.3)), (71.7, Some(1.2)), (67.2, None), (69.2, None), (55.1, None), (44.5, None), (68.7, None), (61.3, None)]),
    ("hopper-medium-replay", [(107.8, Some(1.2)), (106.6, Some(1.9)), (103.9, Some(1.0)), (104.4, None), (32.7, None), (89.5, None), (81.8, None), (99.5, None), (101.0, None)]),
    ("walker2d-medium-replay", [(97.0, Some(1.4)), (101.1, Some(3.9)), (89.9, Some(1.5)), (75.3, None), (73.7, None), (56.0, None), (40.8, None), (89.2, None), (87.1, None)]),
    ("halfcheetah-medium-expert", [(97.0, Some(0.5)), (95.8, Some(1.2)), (108.2, Some(2.5)), (74.1, None), (70.3, None), (90.0, None), (80.4, None), (95.4, None), (106.3, None)]),
    ("hopper-medium-expert", [(112.2, Some(0.3)), (111.9, Some(0.5)), (112.6, Some(0.2)), (107.0, None), (60.6, None), (111.1, None), (105.6, None), (88.2, None), (110.7, None)]),
    ("walker2d-medium-expert", [(113.2, Some(0.5)), (112.6, Some(0.6)), (115.2, Some(0.7)), (107.9, None), (77.4, None), (103.3, None), (107.5, None), (56.7, None), (114.7, None)]),
];

/// Table 2's columns.
const TABLE_2_METHODS: [&str; 8] = [
    "nuno", "nuno-r", "mobile", "mopo", "bc", "cql", "td3-bc", "edac",
];

/// Table 2, in its order (NeoRL, four runs of 1M gradient steps for NUNO).
#[rustfmt::skip]
const TABLE_2: [Row<8>; 9] = [
    ("neorl-halfcheetah-low", [(52.5, Some(0.6)), (58.4, Some(0.5)), (54.7, Some(3.0)), (40.1, None), (29.1, None), (38.2, None), (30.0, None), (31.3, None)]),
    ("neorl-hopper-low", [(26.9, Some(3.8)), (26.4, Some(6.8)), (17.4, Some(3.9)), (6.2, None), (15.1, None), (16.0, None), (15.8, None), (18.3, None)]),
    ("neorl-walker2d-low", [(52.5, Some(2.4)), (49.4, Some(1.9)), (37.6, Some(2.0)), (11.6, None), (28.5, None), (44.7, None), (43.0, None), (40.2, None)]),
    ("neorl-halfcheetah-medium", [(73.4, Some(0.6)), (78.8, Some(0.8)), (77.8, Some(1.4)), (62.3, None), (49.0, None), (54.6, None), (52.3, None), (54.9, None)]),
    ("neorl-hopper-medium", [(103.3, Some(2.2)), (92.3, Some(1.7)), (51.1, Some(13.3)), (1.0, None), (51.3, None), (64.5, None), (70.3, None), (44.9, None)]),
    ("neorl-walker2d-medium", [(65.8, Some(0.4)), (49.4, Some(16.9)), (62.2, Some(1.6)), (39.9, None), (48.7, None), (57.3, None), (58.5, None), (57.6, None)]),
    ("neorl-halfcheetah-high", [(85.2, Some(0.6)), (84.9, Some(0.4)), (83.0, Some(4.6)), (65.9, None), (71.3, None), (77.4, None), (75.3, None), (81.4, None)]),
    ("neorl-hopper-high", [(103.0, Some(3.1)), (97.9, Some(5.5)), (87.8, Some(26.0)), (11.5, None), (43.1, None), (76.6, None), (75.3, None), (52.5, None)]),
    ("neorl-walker2d-high", [(72.9, Some(1.6)), (74.5, Some(1.6)), (74.9, Some(3.4)), (18.0, None), (72.6, None), (75.3, None), (69.6, None), (75.5, None)]),
];

/// The paper's score for `method` on the dataset of Table 3's row `preset`,
/// where its tables report one.
pub fn paper_score(preset: &str, method: Method) -> Option<PaperScore> {
    let lookup = |methods: &[&str], scores: &[(f64, Option<f64>)]| {
        let column = methods.iter().position(|m| *m == method.as_str())?;
        let (mean, std) = scores[column];
        Some(PaperScore { mean, std })
    };
    if let Some((_, scores)) = TABLE_1.iter().find(|(name, _)| *name == preset) {
        return lookup(&TABLE_1_METHODS, scores);
    }
    let (_, scores) = TABLE_2.iter().find(|(name, _)| *name == preset)?;
    lookup(&TABLE_2_METHODS, scores)
}

/// The finished cells of any number of experiments as the paper's tables:
/// one row per dataset (Table 3's rows in the paper's order, then the
/// datasets without a preset by name), one column per method, each cell
/// nuno's mean ± std of best scores over seeds (runs) and the paper's figure
/// in brackets; the policy steps each row ran beside it. The same cell given
/// twice (a result copied into another experiment) counts once; two
/// different results for one dataset, method and seed, or one dataset ×
/// method finished under two budgets, are refused.
pub fn paper_layout_table(results: &[CellResult]) -> Result<String, ExperimentError> {
    let entries = grouped(results)?;
    let mut methods: Vec<Method> = entries.keys().map(|(_, m)| *m).collect();
    methods.sort();
    methods.dedup();
    let mut rows: Vec<String> = entries.keys().map(|(row, _)| row.clone()).collect();
    rows.dedup();
    rows.sort_by_key(|row| {
        let place = PRESETS.iter().position(|p| p.name == row);
        (place.unwrap_or(PRESETS.len()), row.clone())
    });
    let layout = (&entries, &methods[..], &rows[..]);
    Ok(format!(
        "Best normalised score, mean ± std over seeds (runs) [the paper's figure for the same \
         dataset and method: 1M gradient steps, 5 runs (Table 1) or 4 (Table 2)]\n\n{}\n\
         Final normalised score (the last evaluation), mean ± std over seeds (runs)\n\n{}",
        score_table(layout, |r| r.best_score, true),
        score_table(layout, |r| r.final_score, false),
    ))
}

/// The markdown table of `score` over `rows` × `methods`, with the paper's
/// figure beside each cell it has where `with_paper`.
fn score_table(
    (entries, methods, rows): (&Grouped, &[Method], &[String]),
    score: fn(&CellResult) -> f64,
    with_paper: bool,
) -> String {
    let mut out = String::from("| dataset | policy steps |");
    for m in methods {
        out.push_str(&format!(" {m} |"));
    }
    out.push_str("\n|---|---|");
    out.push_str(&"---|".repeat(methods.len()));
    out.push('\n');
    for row in rows {
        let steps = (entries.iter())
            .filter(|((r, _), _)| r == row)
            .map(|(_, runs)| runs[0].steps)
            .max()
            .unwrap_or(0);
        out.push_str(&format!("| {row} | {steps} |"));
        for m in methods {
            let text = match entries.get(&(row.clone(), *m)) {
                Some(runs) => {
                    let (mean, std) = mean_std_sample(runs.iter().map(|r| score(r)));
                    let ours = match runs.len() {
                        1 => format!("{mean:.1} (1)"),
                        n => format!("{mean:.1} ± {std:.1} ({n})"),
                    };
                    match paper_score(row, *m).filter(|_| with_paper) {
                        Some(p) => format!("{ours} [{}]", paper_text(p)),
                        None => ours,
                    }
                }
                None => "–".into(),
            };
            out.push_str(&format!(" {text} |"));
        }
        out.push('\n');
    }
    out
}

/// Finished runs by (row, method).
type Grouped<'a> = BTreeMap<(String, Method), Vec<&'a CellResult>>;

/// The results by row and method, each cell once; conflicting copies and
/// one row × method under two budgets refused.
fn grouped(results: &[CellResult]) -> Result<Grouped<'_>, ExperimentError> {
    let mut cells: BTreeMap<(String, Method, u64), &CellResult> = BTreeMap::new();
    for r in results {
        let key = (row_name(r), r.cell.method, r.cell.seed);
        match cells.get(&key) {
            Some(seen) if seen.best_score != r.best_score || seen.steps != r.steps => {
                return Err(ExperimentError::Invalid(format!(
                    "two different results for {} / {} / seed {} (best {:.1} at {} steps and {:.1} at {} steps): \
                     give the folders of one experiment per dataset",
                    key.0, key.1, key.2, seen.best_score, seen.steps, r.best_score, r.steps
                )));
            }
            _ => {
                cells.insert(key, r);
            }
        }
    }
    let mut entries = Grouped::new();
    for ((row, method, _), r) in cells {
        let runs = entries.entry((row.clone(), method)).or_default();
        if let Some(first) = runs.first() {
            let budget = |c: &CellResult| c.budget.as_ref().map(|b| b.for_method(method));
            let data = |c: &CellResult| c.dataset_sha256.clone();
            let same_data = data(first).is_none() || data(r).is_none() || data(first) == data(r);
            if first.steps != r.steps || budget(first) != budget(r) || !same_data {
                return Err(ExperimentError::Invalid(format!(
                    "{row} / {method}: seeds {} and {} ran under different budgets or on different \
                     dataset files ({} and {} policy steps); give the folders of one experiment per dataset",
                    first.cell.seed, r.cell.seed, first.steps, r.steps
                )));
            }
        }
        runs.push(r);
    }
    Ok(entries)
}

/// A cell's row: its Table 3 preset (the paper's dataset), else its grid name.
fn row_name(r: &CellResult) -> String {
    r.cell
        .preset
        .clone()
        .unwrap_or_else(|| r.cell.dataset.clone())
}

fn paper_text(p: PaperScore) -> String {
    match p.std {
        Some(std) => format!("{:.1} ± {std:.1}", p.mean),
        None => format!("{:.1}", p.mean),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::results::test_result;

    /// Rows in Table 3's order whatever the results' order; a copied cell
    /// counts once; the paper's figure only where its tables have the column;
    /// conflicting copies and mixed budgets refused.
    #[test]
    fn nuno_cells_are_laid_out_as_the_papers_tables() {
        let medium = test_result(0, "hm", "hopper-medium", Method::Nuno, 0, 80.0);
        let last = |mut r: CellResult, score: f64| {
            r.final_score = score;
            r
        };
        let results = vec![
            medium.clone(),
            last(
                test_result(1, "hr", "hopper-random", Method::Nuno, 0, 40.0),
                2.0,
            ),
            last(
                test_result(2, "hr", "hopper-random", Method::Nuno, 1, 60.0),
                4.0,
            ),
            test_result(3, "hr", "hopper-random", Method::Bc, 0, 5.0),
            medium.clone(),
        ];
        let table = paper_layout_table(&results).unwrap();
        let random =
            table.find("| hopper-random | 1000 | 50.0 ± 14.1 (2) [73.2 ± 9.8] | 5.0 (1) |");
        let medium_row = table.find("| hopper-medium | 1000 | 80.0 (1) [104.6 ± 0.2] | – |");
        assert!(random.is_some() && medium_row.is_some(), "{table}");
        assert!(random < medium_row, "{table}");
        // The final scores' table follows, without the paper's figures.
        let finals = table
            .find("Final normalised score")
            .expect("the final table");
        let final_random = table.find("| hopper-random | 1000 | 3.0 ± 1.4 (2) | 0.0 (1) |");
        assert!(final_random > Some(finals), "{table}");

        let mut conflicting = medium.clone();
        conflicting.best_score = 81.0;
        let err = paper_layout_table(&[medium.clone(), conflicting]).unwrap_err();
        assert!(err.to_string().contains("two different results"), "{err}");
        let mut longer = test_result(4, "hm", "hopper-medium", Method::Nuno, 1, 70.0);
        longer.steps = 2000;
        let err = paper_layout_table(&[medium, longer]).unwrap_err();
        assert!(err.to_string().contains("different budgets"), "{err}");
    }

    /// Spot checks against the paper's text (Tables 1 and 2, read by hand).
    #[test]
    fn the_paper_scores_are_the_tables() {
        let score = |preset, method| paper_score(preset, method).unwrap();
        assert_eq!(
            score("hopper-random", Method::Nuno),
            PaperScore {
                mean: 73.2,
                std: Some(9.8)
            }
        );
        assert_eq!(
            score("walker2d-medium-expert", Method::TatuMopo).mean,
            107.9
        );
        assert_eq!(score("halfcheetah-medium-replay", Method::Mopo).mean, 69.2);
        assert_eq!(score("neorl-hopper-medium", Method::Td3Bc).mean, 70.3);
        assert_eq!(score("neorl-walker2d-low", Method::Bc).mean, 28.5);
        assert_eq!(
            score("neorl-halfcheetah-high", Method::NunoR),
            PaperScore {
                mean: 84.9,
                std: Some(0.4)
            }
        );
        // Table 1 has no BC column, Table 2 no TATU+MOPO one.
        assert_eq!(paper_score("hopper-medium", Method::Bc), None);
        assert_eq!(paper_score("neorl-hopper-low", Method::TatuMopo), None);
        assert_eq!(paper_score("invertedpendulum-random", Method::Nuno), None);
        // Each table's average row, recomputed from its entries.
        let average = |rows: &[[(f64, Option<f64>); 9]], column: usize| {
            rows.iter().map(|r| r[column].0).sum::<f64>() / rows.len() as f64
        };
        let table_1: Vec<_> = TABLE_1.iter().map(|(_, r)| *r).collect();
        assert!((average(&table_1, 0) - 83.8).abs() < 0.05);
        assert!((average(&table_1, 4) - 49.4).abs() < 0.05);
        let neorl_nuno = TABLE_2.iter().map(|(_, r)| r[0].0).sum::<f64>() / 9.0;
        assert!((neorl_nuno - 70.6).abs() < 0.05);
    }
}
