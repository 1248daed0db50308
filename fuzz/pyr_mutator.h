// A structure-aware mutator for .pyr 2.0 files (LLVMFuzzerCustomMutator of fuzz_pyramid_open):
// it locates every section of the container (superblock, info block, level records, filter, mask,
// metadata, each level's band table and footer, each band stream's header, tile index and tile
// payloads; tests/runtime/pyr_test_util.h), mutates one field or a few payload bytes in place,
// and recomputes every checksum (band streams, band tables, blobs, mask, metadata, index,
// superblock), so that mutations get past the CRCs and reach the validation and the decoder behind
// them. One mutation in 16 keeps its damaged checksums (the CRC paths and DamagePolicy::Degrade).
// Sizes never change except through libFuzzer's own generic mutation (one in 8), after which the
// checksums are recomputed as far as the structure can still be located.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "runtime/pyr_test_util.h"

extern "C" size_t LLVMFuzzerMutate(uint8_t* data, size_t size, size_t max_size);

namespace pyr_mutator {

struct Field {
  size_t at;  // offset in its section
  int bytes;  // 2, 4 or 8
  bool f64;   // an IEEE double
};

// docs/format.md: superblock, info block and level record fields (the CRCs are recomputed anyway).
inline constexpr Field kSuperblock[] = {{8, 2, false},  {10, 2, false}, {12, 4, false}, {16, 8, false},
                                        {24, 8, false}, {32, 8, false}, {44, 4, false}, {48, 8, false}};
inline constexpr Field kInfo[] = {
    {0, 4, false},   {4, 4, false},   {8, 4, false},   {12, 4, false}, {16, 8, false},  {24, 8, false},
    {32, 8, true},   {40, 8, true},   {48, 8, false},  {80, 8, false}, {112, 8, true},  {120, 8, true},
    {128, 4, false}, {132, 4, false}, {136, 8, true},  {144, 8, true}, {152, 8, false}, {184, 8, true},
    {192, 8, true},  {200, 4, false}, {204, 4, false}, {208, 8, true}, {216, 8, false}, {224, 8, false},
    {232, 8, false}, {248, 8, false}, {256, 8, false}};
inline constexpr Field kRecord[] = {{0, 8, false},  {8, 8, false}, {16, 8, false}, {24, 8, false},
                                    {36, 4, false}, {40, 8, true}, {48, 8, true},  {56, 8, true},
                                    {64, 8, true},  {72, 8, true}, {80, 8, true},  {88, 8, true}};

using Rng = std::minstd_rand;

inline uint64_t pick(Rng& rng, uint64_t n) { return n ? uint64_t(rng()) % n : 0; }

// An interesting value for an integer field holding `old`.
inline uint64_t integer_value(Rng& rng, uint64_t old, int bytes) {
  const uint64_t max = bytes == 8 ? ~uint64_t(0) : (uint64_t(1) << (8 * bytes)) - 1;
  switch (pick(rng, 9)) {
    case 0:
      return 0;
    case 1:
      return 1;
    case 2:
      return max;
    case 3:
      return max >> 1;
    case 4:
      return old + 1;
    case 5:
      return old - 1;
    case 6:
      return old + 1 + pick(rng, 64);
    case 7:
      return old ^ (uint64_t(1) << pick(rng, uint64_t(8 * bytes)));
    default:
      return old * 2;
  }
}

inline double double_value(Rng& rng, double old) {
  switch (pick(rng, 10)) {
    case 0:
      return 0.0;
    case 1:
      return -old;
    case 2:
      return std::numeric_limits<double>::quiet_NaN();
    case 3:
      return std::numeric_limits<double>::infinity();
    case 4:
      return -1.0;
    case 5:
      return 1e300;
    case 6:
      return 5e-324;
    case 7:
      return old * 2;
    case 8:
      return old / 3;
    default:
      return std::nextafter(old, 0.0);
  }
}

inline void mutate_field(std::vector<uint8_t>& b, size_t base, const Field& f, Rng& rng) {
  if (base + f.at + size_t(f.bytes) > b.size()) return;
  const uint64_t old = pyrtest::get_le(b, base + f.at, f.bytes);
  if (f.f64) {
    double d;
    std::memcpy(&d, &old, 8);
    pyrtest::put_f64(b, base + f.at, double_value(rng, d));
  } else {
    pyrtest::put_le(b, base + f.at, integer_value(rng, old, f.bytes), f.bytes);
  }
}

// Replaces one of the varints in [begin, end) by another value of the same encoded length (LEB128
// padded with continuation bytes where the value is shorter; high bits dropped where longer).
inline void mutate_varint(std::vector<uint8_t>& b, size_t begin, size_t end, Rng& rng) {
  std::vector<std::pair<size_t, size_t>> found;  // (offset, length)
  const uint8_t* p = b.data() + begin;
  const uint8_t* const e = b.data() + end;
  while (p < e && found.size() < 4096) {
    const uint8_t* start = p;
    uint64_t v;
    if (!pyrtest::read_varint(p, e, &v)) break;
    found.push_back({size_t(start - b.data()), size_t(p - start)});
  }
  if (found.empty()) return;
  const auto [at, len] = found[pick(rng, found.size())];
  const uint8_t* q = b.data() + at;
  uint64_t old;
  pyrtest::read_varint(q, b.data() + at + len, &old);
  uint64_t v = integer_value(rng, old, 8);
  if (pick(rng, 2)) v = old ^ 1;  // a size's parity is the band/tile kind: flip it often
  for (size_t i = 0; i < len; ++i) {
    b[at + i] = uint8_t((v & 0x7f) | (i + 1 < len ? 0x80 : 0));
    v >>= 7;
  }
}

inline void mutate_bytes(std::vector<uint8_t>& b, size_t begin, size_t end, Rng& rng) {
  if (begin >= end || end > b.size()) return;
  const uint64_t n = 1 + pick(rng, 4);
  for (uint64_t i = 0; i < n; ++i) {
    const size_t at = begin + size_t(pick(rng, end - begin));
    if (pick(rng, 2))
      b[at] ^= uint8_t(1u << pick(rng, 8));
    else
      b[at] = uint8_t(rng());
  }
}

// One structured mutation of `b` in place (no size change).
inline void mutate_structure(std::vector<uint8_t>& b, Rng& rng) {
  if (b.size() < 64) return;
  const uint64_t index = pyrtest::get_le(b, pyrtest::kSbIndexOffset, 8);
  const uint64_t index_size = pyrtest::get_le(b, pyrtest::kSbIndexSize, 8);
  const bool has_index = pyrtest::inside(index, index_size, b.size()) && index_size >= pyrtest::kInfoBlock;
  const std::vector<pyrtest::LevelAt> levels = pyrtest::locate_levels(b);
  const pyrtest::LevelAt* lv = levels.empty() ? nullptr : &levels[pick(rng, levels.size())];
  const pyrtest::StreamAt* s =
      lv && !lv->streams.empty() ? &lv->streams[pick(rng, lv->streams.size())] : nullptr;
  switch (pick(rng, 12)) {
    case 0:
      mutate_field(b, 0, kSuperblock[pick(rng, std::size(kSuperblock))], rng);
      return;
    case 1:
      if (has_index) return mutate_field(b, size_t(index), kInfo[pick(rng, std::size(kInfo))], rng);
      break;
    case 2:
      if (lv) return mutate_field(b, lv->record, kRecord[pick(rng, std::size(kRecord))], rng);
      break;
    case 3:  // the filter coefficients and anything after the level records
      if (has_index && lv) {
        const size_t after = levels.back().record + 96;
        if (after + 8 <= size_t(index + index_size)) {
          const size_t k = size_t(pick(rng, (size_t(index + index_size) - after) / 8));
          return mutate_field(b, after + 8 * k, Field{0, 8, pick(rng, 4) != 0}, rng);
        }
      }
      break;
    case 4:  // mask runs
      if (has_index) {
        const uint64_t m = pyrtest::get_le(b, size_t(index) + pyrtest::kInfoMaskOffset, 8);
        const uint64_t ms = pyrtest::get_le(b, size_t(index) + pyrtest::kInfoMaskSize, 8);
        if (ms && pyrtest::inside(m, ms, b.size())) {
          if (pick(rng, 2)) return mutate_varint(b, size_t(m), size_t(m + ms), rng);
          return mutate_bytes(b, size_t(m), size_t(m + ms), rng);
        }
      }
      break;
    case 5:  // metadata JSON
      if (has_index) {
        const uint64_t m = pyrtest::get_le(b, size_t(index) + pyrtest::kInfoMetadataOffset, 8);
        const uint64_t ms = pyrtest::get_le(b, size_t(index) + pyrtest::kInfoMetadataSize, 8);
        if (ms && pyrtest::inside(m, ms, b.size())) return mutate_bytes(b, size_t(m), size_t(m + ms), rng);
      }
      break;
    case 6:  // band table records
      if (lv && lv->has_table) return mutate_varint(b, lv->table, lv->table + lv->table_size, rng);
      break;
    case 7:  // band table footer
      if (lv && lv->has_table) {
        const size_t footer = lv->blob + lv->blob_size - pyrtest::kBandFooter;
        if (pick(rng, 2)) return mutate_field(b, footer, Field{0, 4, false}, rng);
        return mutate_bytes(b, footer + 4, footer + 8, rng);
      }
      break;
    case 8:  // stream header: magic, version, varints
      if (s && s->parsed) {
        if (pick(rng, 4) == 0) return mutate_bytes(b, s->offset, s->offset + 6, rng);
        return mutate_varint(b, s->offset + 6, s->header_end, rng);
      }
      break;
    case 9:  // tile index records
      if (s && s->parsed && s->index_begin + 4 < s->offset + s->size)
        return mutate_varint(b, s->index_begin, s->offset + s->size - 4, rng);
      break;
    case 10:
    case 11:  // tile payloads
      if (s && s->parsed && s->header_end < s->index_begin)
        return mutate_bytes(b, s->header_end, s->index_begin, rng);
      break;
  }
  mutate_bytes(b, 0, b.size(), rng);  // the section was not there: anywhere
}

inline size_t mutate(uint8_t* data, size_t size, size_t max_size, unsigned seed) {
  Rng rng(seed);
  if (size < 64 || pick(rng, 8) == 0) {
    size = LLVMFuzzerMutate(data, size, max_size);
    std::vector<uint8_t> b(data, data + size);
    pyrtest::reseal_all(b);
    std::memcpy(data, b.data(), size);
    return size;
  }
  std::vector<uint8_t> b(data, data + size);
  const uint64_t n = 1 + pick(rng, 2);
  for (uint64_t i = 0; i < n; ++i) mutate_structure(b, rng);
  if (pick(rng, 16) != 0) pyrtest::reseal_all(b);
  std::memcpy(data, b.data(), size);
  return size;
}

}  // namespace pyr_mutator
