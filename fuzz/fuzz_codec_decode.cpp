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
#include "codec/crc32c.h"

namespace {

void put_u32(uint8_t* p, uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = uint8_t(v >> (8 * i));
}

// Rewrites header, tile and index CRCs in place (stream layout of formats 2 and 3, docs/codec.md: 56-byte
// header with its CRC at 52, payloads back to back, then per tile a varint size and a CRC, then the index
// CRC).
void fix_checksums(std::vector<uint8_t>& s) {
  constexpr size_t kHeaderCrcAt = 52;
  if (s.size() < kHeaderCrcAt + 4) return;
  put_u32(s.data() + kHeaderCrcAt, codec::crc32c(s.data(), kHeaderCrcAt));
  codec::HeaderInfo h;
  if (codec::read_header(s.data(), s.size(), &h) != codec::Status::Ok) return;
  if (h.index_offset > s.size()) return;
  size_t p = h.index_offset;
  uint64_t offset = h.data_offset;
  for (int64_t i = 0; i < h.tile_count(); ++i) {
    uint64_t size = 0;
    for (int shift = 0;; shift += 7) {
      if (p >= s.size() || shift > 28) return;
      const uint8_t byte = s[p++];
      size |= uint64_t(byte & 0x7F) << shift;
      if (!(byte & 0x80)) break;
    }
    if (s.size() - p < 4) return;
    if (offset <= h.index_offset && size <= h.index_offset - offset)
      put_u32(s.data() + p, codec::crc32c(s.data() + offset, size_t(size)));
    p += 4;
    offset += size;
  }
  if (s.size() - p < 4) return;
  put_u32(s.data() + p, codec::crc32c(s.data() + h.index_offset, p - h.index_offset));
}

void decode_checked(const uint8_t* data, size_t size, codec::Scratch& scratch) {
  codec::Decoder decoder;
  if (decoder.open(data, size) != codec::Status::Ok) return;
  const auto& h = decoder.header();
  if (h.width * h.height > (int64_t(1) << 20)) return;  // keep memory per input small
  std::vector<int32_t> full(size_t(h.width * h.height));
  if (decoder.decode_region({0, 0, h.width, h.height}, full.data(), h.width, scratch) != codec::Status::Ok)
    return;
  const codec::Rect r{h.width / 3, h.height / 2, h.width - h.width / 3, h.height - h.height / 2};
  std::vector<int32_t> part(size_t(r.width * r.height));
  if (decoder.decode_region(r, part.data(), r.width, scratch) != codec::Status::Ok) std::abort();
  for (int64_t y = 0; y < r.height; ++y)
    for (int64_t x = 0; x < r.width; ++x)
      if (part[size_t(y * r.width + x)] != full[size_t((r.y0 + y) * h.width + r.x0 + x)]) std::abort();
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
  if (codec::encode(img.data(), w, w, h, o, stream.data(), stream.size(), &written, scratch) !=
      codec::Status::Ok)
    std::abort();
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
