// Functions compiled for several instruction-set levels, one picked at load time (GCC's and clang's
// target_clones, an ifunc). ThreadSanitizer cannot run ifunc resolvers (they run during relocation,
// before its runtime is up), so a TSan build (CMake TERRAIN_TSAN, which defines
// TERRAIN_NO_TARGET_CLONES) compiles each such function once, for the baseline.
#pragma once

#if defined(TERRAIN_NO_TARGET_CLONES)
#define TERRAIN_TARGET_CLONES(...)
#else
// Attribute list entry: __attribute__((TERRAIN_TARGET_CLONES("avx2", "default"), flatten)) is not
// possible with an empty expansion, so the macro is a whole attribute of its own.
#define TERRAIN_TARGET_CLONES(...) __attribute__((target_clones(__VA_ARGS__)))
#endif
