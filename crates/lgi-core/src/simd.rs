//! Kernels compiled twice, for the baseline x86-64 (SSE2: two doubles per instruction) and with
//! AVX2 (four), the AVX2 build chosen at run time where the processor has it
//! ([`with_avx2`]). Rust never fuses a multiply and an add into one rounding unless asked
//! (`mul_add`), so a loop vectorised four entries wide does each entry's operations in the
//! same order as two wide: the same bits on every processor.

/// Defines a function whose body is compiled for the baseline target and, on x86-64, once
/// more with AVX2 enabled; a call takes the AVX2 build when the processor reports AVX2
/// (detected once, then a cached flag). For loops over contiguous slices that vectorise.
macro_rules! with_avx2 {
    (
        $(#[$meta:meta])*
        $vis:vis fn $name:ident($($arg:ident: $ty:ty),* $(,)?) $(-> $ret:ty)? $body:block
    ) => {
        $(#[$meta])*
        // The one unsafe call: the AVX2 build, where the processor has AVX2.
        #[allow(unsafe_code)]
        $vis fn $name($($arg: $ty),*) $(-> $ret)? {
            #[inline(always)]
            fn body($($arg: $ty),*) $(-> $ret)? $body
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx2")]
                fn avx2($($arg: $ty),*) $(-> $ret)? {
                    body($($arg),*)
                }
                if std::arch::is_x86_feature_detected!("avx2") && !$crate::simd::baseline_only() {
                    // SAFETY: the processor has AVX2, checked just above.
                    return unsafe { avx2($($arg),*) };
                }
            }
            body($($arg),*)
        }
    };
}

pub(crate) use with_avx2;

/// Tests set this to take the baseline builds on any processor (and compare the bits).
#[cfg(test)]
pub(crate) static BASELINE_ONLY: std::sync::atomic::AtomicBool =
    std::sync::atomic::AtomicBool::new(false);

/// Whether the baseline builds are asked for: never outside tests.
#[inline(always)]
pub(crate) fn baseline_only() -> bool {
    #[cfg(test)]
    return BASELINE_ONLY.load(std::sync::atomic::Ordering::Relaxed);
    #[cfg(not(test))]
    false
}

/// `f` run with the AVX2 builds (where the processor has them) and with the baseline builds.
#[cfg(test)]
pub(crate) fn both_builds<T>(mut f: impl FnMut() -> T) -> (T, T) {
    use std::sync::atomic::Ordering;
    BASELINE_ONLY.store(false, Ordering::Relaxed);
    let fast = f();
    BASELINE_ONLY.store(true, Ordering::Relaxed);
    let baseline = f();
    BASELINE_ONLY.store(false, Ordering::Relaxed);
    (fast, baseline)
}
