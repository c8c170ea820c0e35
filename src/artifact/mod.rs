//! Files nuno writes: every artifact and dataset is written atomically, so a
//! reader never sees a half-written file.

mod atomic;

pub use atomic::write_atomically;
