/* The AVX-512 instance of the vector right-hand side (8 carts per
 * instruction, mask registers for the contacts); chain_simd_kernel.h holds
 * the code, chain_simd.h the scheme. Runs only where cpuid says AVX-512 F,
 * DQ and VL and the OS saves their state. */
#include "chain_simd.h"

#if LSS_HAVE_SIMD
#pragma GCC push_options
#pragma GCC target("avx512f,avx512dq,avx512vl,avx2,fma")
#define VW 8
#define SIMD_ENTRY chain_rhs_avx512
#include "chain_simd_kernel.h"
#pragma GCC pop_options
#else
void chain_rhs_avx512(Chain *c, const double *y, double *dy) { (void)c; (void)y; (void)dy; }
#endif
