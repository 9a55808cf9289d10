/* The AVX2 + FMA instance of the vector right-hand side (4 carts per
 * instruction); chain_simd_kernel.h holds the code, chain_simd.h the scheme.
 * Compiled with the target pragma so that the rest of the core stays
 * baseline x86-64: this code runs only where cpuid says AVX2 and FMA. */
#include "chain_simd.h"

#if LSS_HAVE_SIMD
#pragma GCC push_options
#pragma GCC target("avx2,fma")
#define VW 4
#define SIMD_ENTRY chain_rhs_avx2
#include "chain_simd_kernel.h"
#pragma GCC pop_options
#else
void chain_rhs_avx2(Chain *c, const double *y, double *dy) { (void)c; (void)y; (void)dy; }
#endif
