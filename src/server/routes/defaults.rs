//! Defaults of optional request fields (serde's `default = "..."` needs functions).

pub(super) fn one() -> usize {
    1
}

pub(super) fn ten() -> usize {
    10
}

pub(super) fn unit() -> f64 {
    1.0
}

pub(super) fn unit_f32() -> f32 {
    1.0
}
