//! Request fields: the defaults of optional ones (serde's `default = "..."`
//! needs functions) and integers read the way JSON Schema counts them.

use serde::{Deserialize, Deserializer};

pub(super) fn one() -> usize {
    1
}

/// Episodes of an evaluation request that names none (fewer when the server's limit is lower).
pub(super) const DEFAULT_EPISODES: usize = 10;

pub(super) fn unit() -> f64 {
    1.0
}

pub(super) fn yes() -> bool {
    true
}

/// A non-negative integer field. JSON Schema, and so the spec, counts `9.0` as
/// the integer 9, and clients that hold numbers as floats (numpy, JavaScript)
/// send it that way: integral floats are taken, fractions and negatives are not.
pub(super) fn integer<'de, D, T>(deserializer: D) -> Result<T, D::Error>
where
    D: Deserializer<'de>,
    T: TryFrom<u64>,
{
    use serde::de::Error;
    let value = match serde_json::Number::deserialize(deserializer)? {
        n if n.as_u64().is_some() => n.as_u64(),
        n => n
            .as_f64()
            // 2^64 as f64 is the first float past u64::MAX.
            .filter(|f| f.fract() == 0.0 && *f >= 0.0 && *f < 18_446_744_073_709_551_616.0)
            .map(|f| f as u64),
    };
    value
        .and_then(|v| T::try_from(v).ok())
        .ok_or_else(|| D::Error::custom("expected a non-negative integer"))
}

/// One [`integer`], where serde needs a type (in an `Option`, a `Vec`).
#[derive(Deserialize)]
#[serde(bound = "T: TryFrom<u64>")]
struct Integer<T>(#[serde(deserialize_with = "integer")] T);

/// [`integer`] for a field that may be absent or null.
pub(super) fn optional_integer<'de, D, T>(deserializer: D) -> Result<Option<T>, D::Error>
where
    D: Deserializer<'de>,
    T: TryFrom<u64>,
{
    Ok(Option::<Integer<T>>::deserialize(deserializer)?.map(|Integer(v)| v))
}

/// [`integer`] for every element of a list.
pub(super) fn integers<'de, D, T>(deserializer: D) -> Result<Vec<T>, D::Error>
where
    D: Deserializer<'de>,
    T: TryFrom<u64>,
{
    let values = Vec::<Integer<T>>::deserialize(deserializer)?;
    Ok(values.into_iter().map(|Integer(v)| v).collect())
}

#[cfg(test)]
mod tests {
    use serde::Deserialize;

    #[derive(Debug, Deserialize)]
    struct Fields {
        #[serde(deserialize_with = "super::integer")]
        count: usize,
        #[serde(deserialize_with = "super::integers")]
        shape: Vec<u64>,
    }

    fn parse(text: &str) -> Result<Fields, String> {
        serde_json::from_str(text).map_err(|e| e.to_string())
    }

    #[test]
    fn integral_floats_are_integers_and_fractions_are_not() {
        let f = parse(r#"{"count": 9.0, "shape": [3, 4.0, 18446744073709551615]}"#).unwrap();
        assert_eq!((f.count, f.shape), (9, vec![3, 4, u64::MAX]));
        for bad in ["9.5", "-1", "-1.0", "1e20", "\"9\""] {
            let error = parse(&format!(r#"{{"count": {bad}, "shape": []}}"#)).unwrap_err();
            assert!(
                error.contains("non-negative integer") || error.contains("invalid type"),
                "{bad}: {error}"
            );
        }
    }
}
