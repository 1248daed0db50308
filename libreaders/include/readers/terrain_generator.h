// Deterministic synthetic terrain for tests and benchmarks: hash-based value-noise continents with
// ridged-multifractal mountains, computed in fixed-point integers only, so the output is bit-identical
// on every machine, compiler and optimisation level.
#pragma once

#include <cstdint>

#include "readers/heightmap.h"

namespace terrain {

struct SynthOptions {
  uint64_t seed = 1;        // every seed gives another terrain
  int64_t width = 513;      // samples, 1..65536
  int64_t height = 513;     // samples, 1..65536
  double spacing_m = 30.0;  // horizontal spacing recorded in the GridInfo (does not change the samples)
};

// Generates a width x height int16 grid of whole metres in [0, 3100] (the lowest quarter of the area is a
// flat sea at 0; the highest sample is 3100 m), no voids.
// Feature sizes scale with the larger side, so small and large outputs both show several ranges.
// Throws Error(DimensionMismatch) for non-positive or absurd (> 65536) sizes. A pure function of
// `options` (any thread).
Heightmap synthesize_terrain(const SynthOptions& options);

}  // namespace terrain
