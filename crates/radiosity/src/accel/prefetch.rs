//! A software prefetch: asks for the cache line holding a value before a loop reaches it.
//! Gathers through random indices (a hierarchical link reading its source node) wait on
//! one cache miss per element otherwise.
#![allow(unsafe_code)]

/// Starts loading the cache line that holds `x` (no effect where the target has no
/// prefetch instruction). Never faults, whatever the address.
#[inline(always)]
pub(crate) fn prefetch<T>(x: &T) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        // SAFETY: a prefetch is a hint; it reads nothing and never faults (SSE, which
        // every x86_64 target has).
        unsafe { _mm_prefetch::<_MM_HINT_T0>(x as *const T as *const i8) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = x;
}
