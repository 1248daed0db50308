// inverse_lapped on 8 lanes (two 4x4 blocks per vector). Only this file is compiled for AVX2, and
// inverse_lapped calls it only where the CPU has AVX2. The standard headers come before the target
// switch, so that none of their inline functions is compiled for AVX2 here (the linker could keep
// such a copy for the whole program).
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <type_traits>

#include "lapped_transform.h"

#if defined(__x86_64__) && (defined(__clang__) || (defined(__GNUC__) && __GNUC__ >= 12))
#define CODEC_AVX2_TRANSFORM 1
#ifdef __clang__
#pragma clang attribute push(__attribute__((target("avx2"))), apply_to = function)
#else
#pragma GCC push_options
#pragma GCC target("avx2")
#endif
#include "lapped_kernels.h"
#endif

namespace codec::detail {

bool inverse_lapped_avx2(int32_t* tile, int width, int height, bool lossy) {
#ifdef CODEC_AVX2_TRANSFORM
  inverse_lanes<V8>(tile, width, height, lossy);
  return true;
#else
  (void)tile, (void)width, (void)height, (void)lossy;
  return false;
#endif
}

}  // namespace codec::detail

#ifdef CODEC_AVX2_TRANSFORM
#ifdef __clang__
#pragma clang attribute pop
#else
#pragma GCC pop_options
#endif
#endif
