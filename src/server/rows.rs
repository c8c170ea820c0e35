//! `[[f32]]` request fields (`states`, `actions`) read straight into one
//! row-major buffer: no vector per row, 4 bytes a number while the body is
//! parsed. Widths are checked against the model afterwards, with the same
//! messages as any other width error.

use std::fmt;

use serde::de::{DeserializeSeed, SeqAccess, Visitor};
use serde::ser::SerializeSeq;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::ApiError;
use super::validate::flat;

/// Rows of numbers as read, flattened; what a ragged array looked like is
/// kept for its error message.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Rows {
    values: Vec<f32>,
    count: usize,
    /// Entries of row 0.
    first_width: usize,
    /// The first row whose length differs from row 0's: (index, length).
    ragged: Option<(usize, usize)>,
}

impl Rows {
    /// `values` as rows of `width` (a client's request; a last partial row is
    /// kept as the ragged row it is, for the server to name).
    pub fn new(values: Vec<f32>, width: usize) -> Self {
        let width = width.max(1);
        let count = values.len().div_ceil(width);
        let last = values.len() - (count.saturating_sub(1)) * width;
        Self {
            count,
            first_width: if count == 1 { last } else { width },
            ragged: (count > 1 && last != width).then_some((count - 1, last)),
            values,
        }
    }

    /// The values, row-major.
    pub fn values(&self) -> &[f32] {
        &self.values
    }

    /// Entries of the first row.
    pub fn width(&self) -> usize {
        self.first_width
    }

    /// Rows read.
    pub fn len(&self) -> usize {
        self.count
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// The row-major buffer, after checking there is a row, every row has
    /// `width` entries and every entry is finite.
    pub fn into_matrix(self, field: &str, width: usize) -> Result<Vec<f32>, ApiError> {
        if self.count == 0 {
            return Err(ApiError::Invalid(format!(
                "`{field}` is empty: send at least one row"
            )));
        }
        let wrong = match self.ragged {
            _ if self.first_width != width => Some((0, self.first_width)),
            Some(row) => Some(row),
            None => None,
        };
        if let Some((i, entries)) = wrong {
            return Err(ApiError::Invalid(format!(
                "`{field}[{i}]` has {entries} entries, this model expects {width}"
            )));
        }
        flat(field, &self.values, width)?;
        Ok(self.values)
    }
}

/// A row-major buffer as the `[[f32]]` rows JSON answers carry.
pub fn split_rows(values: &[f32], width: usize) -> Vec<Vec<f32>> {
    values.chunks(width.max(1)).map(<[f32]>::to_vec).collect()
}

/// As JSON rows: the rows of [`Rows::new`] (and of a request read, when it
/// was rectangular or ragged in one row).
impl Serialize for Rows {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut seq = serializer.serialize_seq(Some(self.count))?;
        let mut start = 0;
        for i in 0..self.count {
            let width = match self.ragged {
                Some((at, entries)) if at == i => entries,
                _ => self.first_width,
            };
            let end = (start + width).min(self.values.len());
            seq.serialize_element(&self.values[start..end])?;
            start = end;
        }
        seq.end()
    }
}

impl<'de> Deserialize<'de> for Rows {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        deserializer.deserialize_seq(RowsVisitor)
    }
}

struct RowsVisitor;

impl<'de> Visitor<'de> for RowsVisitor {
    type Value = Rows;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("an array of rows of numbers")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Rows, A::Error> {
        let mut rows = Rows::default();
        while let Some(entries) = seq.next_element_seed(AppendRow(&mut rows.values))? {
            if rows.count == 0 {
                rows.first_width = entries;
            } else if entries != rows.first_width && rows.ragged.is_none() {
                rows.ragged = Some((rows.count, entries));
            }
            rows.count += 1;
        }
        Ok(rows)
    }
}

/// Appends one row's numbers to the buffer; yields how many there were.
struct AppendRow<'a>(&'a mut Vec<f32>);

impl<'de> DeserializeSeed<'de> for AppendRow<'_> {
    type Value = usize;

    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<usize, D::Error> {
        deserializer.deserialize_seq(self)
    }
}

impl<'de> Visitor<'de> for AppendRow<'_> {
    type Value = usize;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a row: an array of numbers")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<usize, A::Error> {
        let mut entries = 0;
        while let Some(value) = seq.next_element::<f32>()? {
            self.0.push(value);
            entries += 1;
        }
        Ok(entries)
    }
}

#[cfg(test)]
mod tests {
    use super::Rows;

    fn rows(text: &str) -> Rows {
        serde_json::from_str(text).unwrap()
    }

    fn message(result: Result<Vec<f32>, crate::server::ApiError>) -> String {
        result.unwrap_err().to_string()
    }

    #[test]
    fn rows_read_into_one_row_major_buffer() {
        let r = rows("[[1, 2.5, -3], [4, 5, 6e-3]]");
        assert_eq!(r.len(), 2);
        assert_eq!(
            r.into_matrix("states", 3).unwrap(),
            [1.0, 2.5, -3.0, 4.0, 5.0, 6e-3]
        );
    }

    #[test]
    fn widths_emptiness_and_non_numbers_are_named() {
        assert_eq!(
            message(rows("[[1, 2], [3, 4]]").into_matrix("states", 3)),
            "`states[0]` has 2 entries, this model expects 3"
        );
        assert_eq!(
            message(rows("[[1, 2, 3], [3, 4, 5], [1]]").into_matrix("actions", 3)),
            "`actions[2]` has 1 entries, this model expects 3"
        );
        assert_eq!(
            message(rows("[]").into_matrix("states", 3)),
            "`states` is empty: send at least one row"
        );
        for bad in ["[1, 2]", "[[\"a\"]]", "{}", "[[1e39]]"] {
            assert!(serde_json::from_str::<Rows>(bad).is_err(), "{bad}");
        }
    }
}
