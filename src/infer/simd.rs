//! Which vector instructions the fused kernels use: the widest this CPU has
//! (AVX-512, AVX2 + FMA, or the portable baseline), capped by `NUNO_SIMD`
//! (`portable`, `avx2`, `avx512`) or by [`set_simd_cap`], so every variant can
//! be run and tested on a machine that has a wider one. gemm's products pick
//! their own instructions and are not capped.

use std::sync::atomic::{AtomicU8, Ordering};

/// A level of vector instructions, ordered from narrowest to widest.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum SimdLevel {
    Portable = 0,
    Avx2 = 1,
    Avx512 = 2,
}

impl SimdLevel {
    pub const ALL: [SimdLevel; 3] = [SimdLevel::Portable, SimdLevel::Avx2, SimdLevel::Avx512];

    fn from_u8(value: u8) -> Self {
        match value {
            0 => SimdLevel::Portable,
            1 => SimdLevel::Avx2,
            _ => SimdLevel::Avx512,
        }
    }

    /// The `NUNO_SIMD` spelling.
    pub fn parse(text: &str) -> Option<Self> {
        match text.trim().to_ascii_lowercase().as_str() {
            "portable" => Some(SimdLevel::Portable),
            "avx2" => Some(SimdLevel::Avx2),
            "avx512" => Some(SimdLevel::Avx512),
            _ => None,
        }
    }
}

/// The widest level this CPU supports.
pub fn detected_simd_level() -> SimdLevel {
    #[cfg(target_arch = "x86_64")]
    {
        let fma = std::arch::is_x86_feature_detected!("fma");
        if fma && std::arch::is_x86_feature_detected!("avx512f") {
            return SimdLevel::Avx512;
        }
        if fma && std::arch::is_x86_feature_detected!("avx2") {
            return SimdLevel::Avx2;
        }
    }
    SimdLevel::Portable
}

const UNSET: u8 = u8::MAX;
static CAP: AtomicU8 = AtomicU8::new(UNSET);

/// The cap: `NUNO_SIMD` when first asked (none, or an unknown value, caps
/// nothing), then whatever [`set_simd_cap`] set.
fn cap() -> SimdLevel {
    match CAP.load(Ordering::Relaxed) {
        UNSET => {
            let from_env = std::env::var("NUNO_SIMD")
                .ok()
                .and_then(|v| SimdLevel::parse(&v))
                .unwrap_or(SimdLevel::Avx512);
            // Another thread may have set a cap meanwhile: theirs stands.
            let _ =
                CAP.compare_exchange(UNSET, from_env as u8, Ordering::Relaxed, Ordering::Relaxed);
            SimdLevel::from_u8(CAP.load(Ordering::Relaxed))
        }
        value => SimdLevel::from_u8(value),
    }
}

/// Caps the level for the whole process (tests run every variant this way).
pub fn set_simd_cap(level: SimdLevel) {
    CAP.store(level as u8, Ordering::Relaxed);
}

/// The level the fused kernels use now: the CPU's, capped.
pub fn simd_level() -> SimdLevel {
    detected_simd_level().min(cap())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_parse_order_and_never_exceed_the_cpu() {
        assert_eq!(SimdLevel::parse(" AVX2 "), Some(SimdLevel::Avx2));
        assert_eq!(SimdLevel::parse("portable"), Some(SimdLevel::Portable));
        assert_eq!(SimdLevel::parse("sse"), None);
        assert!(SimdLevel::Portable < SimdLevel::Avx2 && SimdLevel::Avx2 < SimdLevel::Avx512);
        assert!(simd_level() <= detected_simd_level());
    }
}
