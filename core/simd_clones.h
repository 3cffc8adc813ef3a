// Runtime dispatch of the hot loops: LPM_SIMD_CLONES before a function compiles it for
// AVX-512, AVX2+FMA and SSE2, the best chosen at load time (GCC target_clones, an ifunc).
// The x86-64 levels, not "avx2" alone: that target has no FMA. Off under the sanitizers
// (LPM_NO_CLONES: ifunc resolvers run before their runtime is initialised).
#pragma once

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && !defined(LPM_NO_CLONES)
#define LPM_SIMD_CLONES __attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#else
#define LPM_SIMD_CLONES
#endif
