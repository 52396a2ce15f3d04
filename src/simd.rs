//! The one run-time choice of instruction set. Each hot pass over a chunk has a baseline body
//! and an AVX2 twin that does the same IEEE operations in the same order (so the same bits);
//! [`dispatch`] runs the twin when the CPU has AVX2 ([`crate::contact::lanes::wide`]).
//! A leaf below the engine and the samplers, which both dispatch their passes through it.

/// A pass over one chunk with a baseline body and an AVX2 twin.
pub(crate) trait Twin: Sized {
    type Out;
    /// The baseline body.
    fn base(self) -> Self::Out;
    /// The AVX2 twin; by default the baseline body, compiled for AVX2 where it is inlined
    /// (so `base` should be `#[inline(always)]`).
    ///
    /// # Safety
    /// Only on CPUs with AVX2.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn avx2(self) -> Self::Out {
        self.base()
    }
}

/// Run a pass with the instruction set chosen at run time.
pub(crate) fn dispatch<K: Twin>(k: K) -> K::Out {
    #[cfg(target_arch = "x86_64")]
    if crate::contact::lanes::wide() {
        // SAFETY: `wide` checked that the CPU has AVX2
        return unsafe { avx2(k) };
    }
    k.base()
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn avx2<K: Twin>(k: K) -> K::Out {
    // SAFETY: this function only runs on AVX2 CPUs (see `dispatch`)
    unsafe { k.avx2() }
}
