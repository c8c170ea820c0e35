//! How well a fitted η_ϕ separates the data from what is not data: the check
//! behind Figure 3 (η of dataset vs other actions) and Section 4.1's "distance
//! aware" claim, on any dataset, so a user can see whether η will steer the
//! policy before training one (docs/paper-map.md, known gaps).

use burn::tensor::{Device, Tensor, TensorData};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::{NeuralSde, SdeError};
use crate::data::Dataset;
use crate::nn::{standard_normal, to_f32_vec};

/// What [`eta_report`] samples.
#[derive(burn::config::Config, Debug, PartialEq)]
pub struct EtaReportConfig {
    /// Dataset transitions the report draws (uniformly, with replacement).
    #[config(default = 1000)]
    pub rows: usize,
    /// Perturbation scales, in multiples of the radius r of L_sc.
    #[config(default = "vec![1.0, 3.0]")]
    pub radii: Vec<f32>,
    #[config(default = 0)]
    pub seed: u64,
}

/// η on a set of points, against η on the data.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EtaComparison {
    pub mean_eta: f32,
    /// P(η here > η at a datum), ties counting half: 0.5 = no separation, 1 = perfect.
    pub auroc_vs_data: f64,
}

/// The report: η at the data, at the same states with uniform random actions,
/// and at the data moved by N(0, (k·r)²) in normalised (s, a).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EtaReport {
    pub rows: usize,
    /// r of L_sc, normalised units (from the model's fit, else the default).
    pub radius: f32,
    pub eta_max: f32,
    pub data_mean_eta: f32,
    /// Actions uniform over the dataset's per-dimension action range.
    pub random_actions: EtaComparison,
    /// `(k, η at data + N(0, (k·r)²))` for each k of the config.
    pub perturbed: Vec<(f32, EtaComparison)>,
}

/// η_ϕ of `model` on `config.rows` transitions of `dataset` and on the points
/// [`EtaReport`] describes. `radius` is r of L_sc.
pub fn eta_report(
    model: &NeuralSde,
    dataset: &Dataset,
    radius: f32,
    config: &EtaReportConfig,
    device: &Device,
) -> Result<EtaReport, SdeError> {
    let spec = &model.constants.spec;
    check_dims(model, dataset)?;
    if config.rows == 0 || dataset.is_empty() {
        return Err(SdeError::Config(format!(
            "eta report: {} rows from a dataset of {} transitions",
            config.rows,
            dataset.len()
        )));
    }
    if let Some(k) = config.radii.iter().find(|k| !(k.is_finite() && **k > 0.0)) {
        return Err(SdeError::Config(format!(
            "eta report: perturbation scale {k} must be > 0"
        )));
    }
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let rows: Vec<usize> = (0..config.rows)
        .map(|_| rng.random_range(0..dataset.len()))
        .collect();
    let gather = |values: &ndarray::Array2<f32>| -> Vec<f32> {
        rows.iter().flat_map(|&i| values.row(i).to_vec()).collect()
    };
    let (n, act_dim) = (rows.len(), spec.act_dim);
    let observations = gather(&dataset.observations);
    let actions = gather(&dataset.actions);
    let random_actions = uniform_actions(&dataset.action_bounds(), n, &mut rng);

    let matrix = |values: Vec<f32>, width: usize| {
        Tensor::<2>::from_data(TensorData::new(values, [n, width]), device)
    };
    let input = |actions: Vec<f32>| {
        model.normalized_input(
            matrix(observations.clone(), spec.obs_dim),
            matrix(actions, act_dim),
        )
    };
    let eta = |x: Tensor<2>| to_f32_vec(model.distance.eta(x));
    let data_input = input(actions);
    let on_data = eta(data_input.clone());
    let compare = |values: Vec<f32>| EtaComparison {
        mean_eta: mean(&values),
        auroc_vs_data: auroc(&values, &on_data),
    };
    let random_actions = compare(eta(input(random_actions)));
    let width = spec.obs_dim + act_dim;
    let perturbed = config
        .radii
        .iter()
        .map(|&k| {
            let noise = standard_normal(n * width, &mut rng);
            let shift = matrix(noise, width) * (k * radius);
            (k, compare(eta(data_input.clone() + shift)))
        })
        .collect();
    Ok(EtaReport {
        rows: n,
        radius,
        eta_max: model.distance.eta_max,
        data_mean_eta: mean(&on_data),
        random_actions,
        perturbed,
    })
}

/// Refuses a dataset whose widths are not the model's.
pub(crate) fn check_dims(model: &NeuralSde, dataset: &Dataset) -> Result<(), SdeError> {
    let spec = &model.constants.spec;
    if dataset.obs_dim() != spec.obs_dim || dataset.act_dim() != spec.act_dim {
        return Err(SdeError::Spec(format!(
            "the dataset has {}-D observations and {}-D actions, the model {} and {}",
            dataset.obs_dim(),
            dataset.act_dim(),
            spec.obs_dim,
            spec.act_dim
        )));
    }
    Ok(())
}

/// `rows` actions, each dimension uniform over its `(low, high)`.
pub(crate) fn uniform_actions(bounds: &[(f32, f32)], rows: usize, rng: &mut impl Rng) -> Vec<f32> {
    let mut actions = Vec::with_capacity(rows * bounds.len());
    for _ in 0..rows {
        actions.extend(
            bounds
                .iter()
                .map(|(low, high)| low + (high - low) * rng.random::<f32>()),
        );
    }
    actions
}

pub(crate) fn mean(values: &[f32]) -> f32 {
    values.iter().sum::<f32>() / values.len().max(1) as f32
}

/// Area under the ROC curve of a score that should rank `positives` above
/// `negatives`: P(p > n) + P(p = n)/2, by ranks (O((P + N) log(P + N))).
pub fn auroc(positives: &[f32], negatives: &[f32]) -> f64 {
    if positives.is_empty() || negatives.is_empty() {
        return 0.5;
    }
    // (score, is positive), sorted; tied scores share their mean rank.
    let mut scored: Vec<(f32, bool)> = positives
        .iter()
        .map(|&s| (s, true))
        .chain(negatives.iter().map(|&s| (s, false)))
        .collect();
    scored.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut positive_rank_sum = 0.0;
    let mut start = 0;
    while start < scored.len() {
        let end = start
            + scored[start..]
                .iter()
                .take_while(|s| s.0 == scored[start].0)
                .count();
        // Ranks start..end (0-based) share the mean rank, 1-based.
        let rank = (start + end + 1) as f64 / 2.0;
        let tied_positives = scored[start..end].iter().filter(|s| s.1).count();
        positive_rank_sum += rank * tied_positives as f64;
        start = end;
    }
    let (p, q) = (positives.len() as f64, negatives.len() as f64);
    (positive_rank_sum - p * (p + 1.0) / 2.0) / (p * q)
}

#[cfg(test)]
mod tests {
    use super::auroc;

    #[test]
    fn auroc_counts_wins_and_half_ties() {
        assert_eq!(auroc(&[2.0, 3.0], &[0.0, 1.0]), 1.0);
        assert_eq!(auroc(&[0.0, 1.0], &[2.0, 3.0]), 0.0);
        assert_eq!(auroc(&[1.0, 1.0], &[1.0]), 0.5);
        // wins: 2>1, 2>0, 3>1, 3>0, 1=1 (half), 1>0 → 5.5 of 6
        assert_eq!(auroc(&[1.0, 2.0, 3.0], &[1.0, 0.0]), 5.5 / 6.0);
    }
}
