// Zigzag mapping of the uniform quantiser's values (then LEB128 varints, core/bytes.h).
#pragma once

#include <cstddef>
#include <cstdint>

namespace terrain::detail {

inline uint32_t zigzag(int32_t v) { return (uint32_t(v) << 1) ^ uint32_t(v >> 31); }
inline int32_t unzigzag(uint32_t u) { return int32_t(u >> 1) ^ -int32_t(u & 1); }

}  // namespace terrain::detail
