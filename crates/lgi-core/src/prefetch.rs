//! Software prefetch: the per-bundle indices are far larger than the caches and their tets are
//! visited in scattered order, so the solve asks for the lines it will read before it needs them.

/// Hints the cache to load `x` (its first 128 bytes) ahead of use; no-op off x86_64.
#[inline(always)]
#[allow(unsafe_code)]
pub(crate) fn prefetch<T>(x: &T) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        let ptr = (x as *const T).cast::<i8>();
        // SAFETY: a prefetch is only a hint: it never faults, whatever the address, and SSE
        // is part of every x86_64 target.
        unsafe {
            _mm_prefetch::<_MM_HINT_T0>(ptr);
            if std::mem::size_of::<T>() > 64 {
                _mm_prefetch::<_MM_HINT_T0>(ptr.wrapping_add(64));
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = x;
}
