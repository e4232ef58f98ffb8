//! Lanes of f32 for testing several boxes or triangles at once: one trait, implemented by plain
//! arrays (any target; the compiler may vectorise them) and, on x86_64, by SSE and AVX registers.
//!
//! Every operation is the single IEEE one (no fused multiply-add, no approximate reciprocal), and
//! `min`/`max`/comparisons treat NaN the way the scalar code's `if a < b { a } else { b }` does, so
//! all implementations compute bit for bit what the scalar triangle test computes. That is what
//! keeps hits identical to the brute-force oracle and the result independent of the CPU.

pub(super) trait Lanes: Copy {
    const N: usize;
    /// Loads `Self::N` floats from `p`.
    ///
    /// # Safety
    /// `p` must be valid for reading that many floats.
    unsafe fn load(p: *const f32) -> Self;
    fn splat(x: f32) -> Self;
    fn add(self, o: Self) -> Self;
    fn sub(self, o: Self) -> Self;
    fn mul(self, o: Self) -> Self;
    fn div(self, o: Self) -> Self;
    /// `if self > o { self } else { o }` per lane (a NaN in either gives `o`).
    fn max(self, o: Self) -> Self;
    /// `if self < o { self } else { o }` per lane (a NaN in either gives `o`).
    fn min(self, o: Self) -> Self;
    /// Comparisons give masks: every bit set where the comparison holds (never on NaN).
    fn lt(self, o: Self) -> Self;
    fn le(self, o: Self) -> Self;
    fn gt(self, o: Self) -> Self;
    fn eq(self, o: Self) -> Self;
    fn and(self, o: Self) -> Self;
    fn or(self, o: Self) -> Self;
    /// `self & !o`.
    fn and_not(self, o: Self) -> Self;
    fn xor(self, o: Self) -> Self;
    /// The sign bit of each lane, lane i at bit i (a mask's set lanes).
    fn bits(self) -> u32;
    /// Stores the lanes to `out[..N]`.
    fn store(self, out: &mut [f32; 8]);
}

/// N lanes as a plain array: the portable implementation.
#[derive(Clone, Copy)]
pub(super) struct Scalar<const N: usize>([f32; N]);

impl<const N: usize> Scalar<N> {
    #[inline(always)]
    fn map2(self, o: Self, f: impl Fn(f32, f32) -> f32) -> Self {
        Scalar(std::array::from_fn(|i| f(self.0[i], o.0[i])))
    }
    #[inline(always)]
    fn bitwise(self, o: Self, f: impl Fn(u32, u32) -> u32) -> Self {
        self.map2(o, |a, b| f32::from_bits(f(a.to_bits(), b.to_bits())))
    }
    #[inline(always)]
    fn cmp(self, o: Self, f: impl Fn(f32, f32) -> bool) -> Self {
        self.map2(o, |a, b| f32::from_bits(if f(a, b) { u32::MAX } else { 0 }))
    }
}

impl<const N: usize> Lanes for Scalar<N> {
    const N: usize = N;
    #[inline(always)]
    unsafe fn load(p: *const f32) -> Self {
        // SAFETY: the caller guarantees N readable floats at p.
        Scalar(unsafe { p.cast::<[f32; N]>().read_unaligned() })
    }
    #[inline(always)]
    fn splat(x: f32) -> Self {
        Scalar([x; N])
    }
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        self.map2(o, |a, b| a + b)
    }
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        self.map2(o, |a, b| a - b)
    }
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        self.map2(o, |a, b| a * b)
    }
    #[inline(always)]
    fn div(self, o: Self) -> Self {
        self.map2(o, |a, b| a / b)
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        self.map2(o, |a, b| if a > b { a } else { b })
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        self.map2(o, |a, b| if a < b { a } else { b })
    }
    #[inline(always)]
    fn lt(self, o: Self) -> Self {
        self.cmp(o, |a, b| a < b)
    }
    #[inline(always)]
    fn le(self, o: Self) -> Self {
        self.cmp(o, |a, b| a <= b)
    }
    #[inline(always)]
    fn gt(self, o: Self) -> Self {
        self.cmp(o, |a, b| a > b)
    }
    #[inline(always)]
    fn eq(self, o: Self) -> Self {
        self.cmp(o, |a, b| a == b)
    }
    #[inline(always)]
    fn and(self, o: Self) -> Self {
        self.bitwise(o, |a, b| a & b)
    }
    #[inline(always)]
    fn or(self, o: Self) -> Self {
        self.bitwise(o, |a, b| a | b)
    }
    #[inline(always)]
    fn and_not(self, o: Self) -> Self {
        self.bitwise(o, |a, b| a & !b)
    }
    #[inline(always)]
    fn xor(self, o: Self) -> Self {
        self.bitwise(o, |a, b| a ^ b)
    }
    #[inline(always)]
    fn bits(self) -> u32 {
        (0..N).fold(0, |m, i| m | (self.0[i].to_bits() >> 31) << i)
    }
    #[inline(always)]
    fn store(self, out: &mut [f32; 8]) {
        out[..N].copy_from_slice(&self.0);
    }
}

#[cfg(target_arch = "x86_64")]
pub(super) use x86::Avx;

#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::Lanes;
    use std::arch::x86_64::*;

    /// 8 lanes in an AVX register. Only used inside functions compiled with the `avx` target
    /// feature, which are only called once `is_x86_feature_detected!("avx")` said yes (see
    /// `Kernel`); these `#[inline(always)]` methods are inlined there.
    #[derive(Clone, Copy)]
    pub(in super::super) struct Avx(__m256);

    // SAFETY (every intrinsic here): see the type's doc: the CPU has AVX.
    impl Lanes for Avx {
        const N: usize = 8;
        #[inline(always)]
        unsafe fn load(p: *const f32) -> Self {
            Avx(unsafe { _mm256_loadu_ps(p) })
        }
        #[inline(always)]
        fn splat(x: f32) -> Self {
            Avx(unsafe { _mm256_set1_ps(x) })
        }
        #[inline(always)]
        fn add(self, o: Self) -> Self {
            Avx(unsafe { _mm256_add_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn sub(self, o: Self) -> Self {
            Avx(unsafe { _mm256_sub_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn mul(self, o: Self) -> Self {
            Avx(unsafe { _mm256_mul_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn div(self, o: Self) -> Self {
            Avx(unsafe { _mm256_div_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn max(self, o: Self) -> Self {
            Avx(unsafe { _mm256_max_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn min(self, o: Self) -> Self {
            Avx(unsafe { _mm256_min_ps(self.0, o.0) })
        }
        // Ordered, quiet predicates: false on NaN, like the scalar operators.
        #[inline(always)]
        fn lt(self, o: Self) -> Self {
            Avx(unsafe { _mm256_cmp_ps::<_CMP_LT_OQ>(self.0, o.0) })
        }
        #[inline(always)]
        fn le(self, o: Self) -> Self {
            Avx(unsafe { _mm256_cmp_ps::<_CMP_LE_OQ>(self.0, o.0) })
        }
        #[inline(always)]
        fn gt(self, o: Self) -> Self {
            Avx(unsafe { _mm256_cmp_ps::<_CMP_GT_OQ>(self.0, o.0) })
        }
        #[inline(always)]
        fn eq(self, o: Self) -> Self {
            Avx(unsafe { _mm256_cmp_ps::<_CMP_EQ_OQ>(self.0, o.0) })
        }
        #[inline(always)]
        fn and(self, o: Self) -> Self {
            Avx(unsafe { _mm256_and_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn or(self, o: Self) -> Self {
            Avx(unsafe { _mm256_or_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn and_not(self, o: Self) -> Self {
            Avx(unsafe { _mm256_andnot_ps(o.0, self.0) })
        }
        #[inline(always)]
        fn xor(self, o: Self) -> Self {
            Avx(unsafe { _mm256_xor_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn bits(self) -> u32 {
            unsafe { _mm256_movemask_ps(self.0) as u32 }
        }
        #[inline(always)]
        fn store(self, out: &mut [f32; 8]) {
            unsafe { _mm256_storeu_ps(out.as_mut_ptr(), self.0) }
        }
    }
}
