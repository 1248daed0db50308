// libFuzzer target for the libcodec decoder.
//
// Each input is decoded twice: as given (exercises header/index validation and the checksums), and
// with every checksum recomputed (so mutations reach the RLGR and transform decoders, which a CRC
// would otherwise shield). Any status is fine; crashes, sanitizer reports and leaks are not. When the
// re-checksummed stream decodes, region decodes must agree with the full decode. Inputs of the form
// 'E' + bytes are also encoded as a tiny image and must round-trip losslessly.
//   Run: fuzz_codec_decode -max_len=4096 -max_total_time=60 [corpus_dir]
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "codec/codec.h"
#include "crc32c.h"

namespace {

uint32_t get_u32(const uint8_t* p) { return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24; }
uint64_t get_u64(const uint8_t* p) { return uint64_t(get_u32(p)) | uint64_t(get_u32(p + 4)) << 32; }
void put_u32(uint8_t* p, uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = uint8_t(v >> (8 * i));
}

// Rewrites header, index and tile CRCs in place (layout from docs/codec.md).
void fix_checksums(std::vector<uint8_t>& s) {
  if (s.size() < 172) return;
  put_u32(s.data() + 168, codec::detail::crc32c(s.data(), 168));
  codec::HeaderInfo h;
  if (codec::read_header(s.data(), s.size(), &h) != codec::Status::Ok) return;
  if (s.size() < h.data_offset) return;
  const size_t tiles = size_t(h.tile_count());
  for (size_t i = 0; i < tiles; ++i) {
    uint8_t* e = s.data() + h.index_offset + 16 * i;
    const uint64_t offset = get_u64(e), size = get_u32(e + 8);
    if (offset <= s.size() && size <= s.size() - offset) put_u32(e + 12, codec::detail::crc32c(s.data() + offset, size_t(size)));
  }
  put_u32(s.data() + h.data_offset - 4, codec::detail::crc32c(s.data() + h.index_offset, h.data_offset - 4 - h.index_offset));
}

void decode_checked(const uint8_t* data, size_t size, codec::Scratch& scratch) {
  codec::Decoder decoder;
  if (decoder.open(data, size) != codec::Status::Ok) return;
  const auto& h = decoder.header();
  if (h.width * h.height > (int64_t(1) << 20)) return;  // keep memory per input small
  std::vector<int32_t> full(size_t(h.width * h.height));
  if (decoder.decode_region({0, 0, h.width, h.height}, full.data(), h.width, scratch) != codec::Status::Ok) return;
  const codec::Rect r{h.width / 3, h.height / 2, h.width - h.width / 3, h.height - h.height / 2};
  std::vector<int32_t> part(size_t(r.width * r.height));
  if (decoder.decode_region(r, part.data(), r.width, scratch) != codec::Status::Ok) std::abort();
  for (int64_t y = 0; y < r.height; ++y)
    for (int64_t x = 0; x < r.width; ++x)
      if (part[size_t(y * r.width + x)] != full[size_t((r.y + y) * h.width + r.x + x)]) std::abort();
}

void round_trip(const uint8_t* data, size_t size, codec::Scratch& scratch) {
  if (size < 4) return;
  const int64_t w = 1 + data[1] % 40, h = 1 + data[2] % 40;
  codec::EncodeOptions o;
  o.tile_size = 16u * (1 + data[3] % 3);
  std::vector<int32_t> img(size_t(w * h));
  for (size_t i = 0; i < img.size(); ++i) {
    const uint8_t b = size > 4 ? data[4 + i % (size - 4)] : data[i % size];
    img[i] = (int32_t(b) - 128) * (b & 1 ? 8191 : 1);
  }
  std::vector<uint8_t> stream(codec::encode_bound(w, h, o));
  size_t written = 0;
  if (codec::encode(img.data(), w, w, h, o, stream.data(), stream.size(), &written, scratch) != codec::Status::Ok) std::abort();
  std::vector<int32_t> out(img.size());
  if (codec::decode(stream.data(), written, out.data(), w, scratch) != codec::Status::Ok) std::abort();
  if (out != img) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static codec::Scratch scratch;
  if (size > 0 && data[0] == 'E') {
    round_trip(data, size, scratch);
    return 0;
  }
  decode_checked(data, size, scratch);
  std::vector<uint8_t> copy(data, data + size);
  fix_checksums(copy);
  decode_checked(copy.data(), copy.size(), scratch);
  return 0;
}
