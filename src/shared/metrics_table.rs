//! The one way nuno writes metrics tables: each column named once, beside
//! the value a row gives it, then written as CSV (a header, then a line per
//! row) and, where a command keeps them, as JSON Lines of the same rows.
//!
//! ```
//! use nuno::shared::{Metric, MetricsTable};
//! struct Epoch { step: usize, loss: f32, seconds: f64 }
//! let table = MetricsTable::new()
//!     .column("step", |e: &Epoch| e.step.into())
//!     .column("loss", |e: &Epoch| e.loss.into())
//!     .column("time/total", |e: &Epoch| Metric::fixed(e.seconds, 3));
//! let rows = [Epoch { step: 10, loss: 0.5, seconds: 1.23456 }];
//! assert_eq!(table.csv(&rows), "step,loss,time/total\n10,0.5,1.235\n");
//! assert_eq!(table.jsonl(&rows), "{\"step\":10,\"loss\":0.5,\"time/total\":1.23456}\n");
//! ```

use serde_json::Value;

/// One value of a row: its CSV text and its JSON value.
#[derive(Debug, Clone, PartialEq)]
pub struct Metric {
    text: String,
    json: Value,
}

impl Metric {
    /// `value` printed with `decimals` decimals in CSV (JSON keeps it whole).
    pub fn fixed(value: f64, decimals: usize) -> Self {
        Self {
            text: format!("{value:.decimals$}"),
            json: Value::from(value),
        }
    }

    /// No value: an empty CSV field, JSON null.
    pub fn none() -> Self {
        Self {
            text: String::new(),
            json: Value::Null,
        }
    }

    /// The CSV field, quoted when it holds a comma, a quote or a line break (RFC 4180).
    fn csv_field(&self) -> String {
        if self.text.contains([',', '"', '\n', '\r']) {
            format!("\"{}\"", self.text.replace('"', "\"\""))
        } else {
            self.text.clone()
        }
    }
}

macro_rules! metric_from_display {
    ($($ty:ty),+) => {$(
        impl From<$ty> for Metric {
            fn from(value: $ty) -> Self {
                Self { text: value.to_string(), json: Value::from(value) }
            }
        }
    )+};
}

metric_from_display!(f32, f64, usize, u64, i64, bool, &str, String);

/// The value each column takes from a row of type `R`.
type ColumnValue<'a, R> = Box<dyn Fn(&R) -> Metric + 'a>;

/// Columns of a metrics table over rows of type `R`.
pub struct MetricsTable<'a, R> {
    columns: Vec<(String, ColumnValue<'a, R>)>,
}

impl<R> Default for MetricsTable<'_, R> {
    fn default() -> Self {
        Self {
            columns: Vec::new(),
        }
    }
}

impl<'a, R> MetricsTable<'a, R> {
    pub fn new() -> Self {
        Self::default()
    }

    /// The table with one more column, `name`, whose value in a row is `value(row)`.
    pub fn column(mut self, name: impl Into<String>, value: impl Fn(&R) -> Metric + 'a) -> Self {
        self.columns.push((name.into(), Box::new(value)));
        self
    }

    /// The header, then one line per row.
    pub fn csv<'r>(&self, rows: impl IntoIterator<Item = &'r R>) -> String
    where
        R: 'r,
    {
        rows.into_iter()
            .fold(self.header(), |out, row| out + &self.line(row))
    }

    /// The CSV header line (for a file written as rows arrive).
    pub fn header(&self) -> String {
        let names: Vec<&str> = self.columns.iter().map(|(name, _)| name.as_str()).collect();
        names.join(",") + "\n"
    }

    /// One row's CSV line.
    pub fn line(&self, row: &R) -> String {
        let fields: Vec<String> = self
            .columns
            .iter()
            .map(|(_, v)| v(row).csv_field())
            .collect();
        fields.join(",") + "\n"
    }

    /// One JSON object per row, keyed by the column names, in column order.
    pub fn jsonl<'r>(&self, rows: impl IntoIterator<Item = &'r R>) -> String
    where
        R: 'r,
    {
        // By hand: serde_json's maps sort their keys.
        let mut out = String::new();
        for row in rows {
            let fields: Vec<String> = self
                .columns
                .iter()
                .map(|(name, value)| format!("{}:{}", Value::from(name.as_str()), value(row).json))
                .collect();
            out.push_str(&format!("{{{}}}\n", fields.join(",")));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_that_need_it_are_quoted_and_missing_values_are_empty() {
        let table = MetricsTable::new()
            .column("model", |r: &(&str, Option<f64>)| r.0.into())
            .column("score", |r: &(&str, Option<f64>)| {
                r.1.map_or_else(Metric::none, Metric::from)
            });
        let rows = [("a,\"b\"", None), ("c", Some(2.5))];
        assert_eq!(table.csv(&rows), "model,score\n\"a,\"\"b\"\"\",\nc,2.5\n");
        assert_eq!(
            table.jsonl(&rows),
            "{\"model\":\"a,\\\"b\\\"\",\"score\":null}\n{\"model\":\"c\",\"score\":2.5}\n"
        );
    }

    #[test]
    fn f32_values_print_as_f32_not_as_their_f64_widening() {
        assert_eq!(Metric::from(0.1f32).text, "0.1");
        assert_eq!(Metric::fixed(2.0, 1).text, "2.0");
    }
}
