//! Text files the subcommands write beside their artifacts (metrics, reports,
//! job scripts), each atomically.

use std::path::Path;

use anyhow::Context;
use nuno::agent::SacLosses;
use nuno::shared::{Metric, MetricsTable, write_atomically};

/// Writes `text` to `path` atomically (temporary file, fsync, rename).
pub fn write_text(path: &Path, text: &str) -> anyhow::Result<()> {
    write_atomically(path, |tmp| std::fs::write(tmp, text), |e| e)
        .with_context(|| format!("writing {}", path.display()))
}

/// `table` with SAC's losses under CleanRL's `losses/*` names, read from each
/// row by `losses` (fit-policy's and online SAC's metrics share them).
pub fn with_sac_losses<'a, R: 'a>(
    table: MetricsTable<'a, R>,
    losses: fn(&R) -> &SacLosses,
) -> MetricsTable<'a, R> {
    let column = move |f: fn(&SacLosses) -> f32| move |r: &R| Metric::from(f(losses(r)));
    table
        .column("losses/qf1_values", column(|l| l.qf1_values))
        .column("losses/qf1_loss", column(|l| l.qf1_loss))
        .column("losses/qf2_loss", column(|l| l.qf2_loss))
        .column("losses/actor_loss", column(|l| l.actor_loss))
        .column("losses/alpha", column(|l| l.alpha))
        .column("losses/alpha_loss", column(|l| l.alpha_loss))
        .column("losses/entropy", column(|l| l.entropy))
}
