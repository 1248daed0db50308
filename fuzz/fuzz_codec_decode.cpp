// libFuzzer target for the libcodec decoder.
//
// Each input is decoded twice: as given (exercises header/index validation and the checksums), and
// with every checksum recomputed (so mutations reach the RLGR and transform decoders, which a CRC
// would otherwise shield). Any status is fine; crashes, sanitizer reports and leaks are not. When the
// re-checksummed stream decodes, region decodes must agree with the full decode. Inputs of the form
// 'E' + bytes are encoded as a tiny image (lapped or residual transform, lossless, lossy or
// max-error, phase tiles) and must decode to the encoder's reconstruction; 'M' + bytes mutate such a stream.
//   Run: fuzz_codec_decode -max_len=4096 -max_total_time=60 [corpus_dir]
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <utility>
#include <vector>

#include "codec/codec.h"
#include "codec/crc32c.h"
#include "codec/internal/phase_coder.h"

namespace {

void put_u32(uint8_t* p, uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = uint8_t(v >> (8 * i));
}

bool get_varint(const std::vector<uint8_t>& s, size_t& p, uint64_t* v) {
  *v = 0;
  for (int shift = 0;; shift += 7) {
    if (p >= s.size() || shift > 63) return false;
    const uint8_t byte = s[p++];
    *v |= uint64_t(byte & 0x7F) << shift;
    if (!(byte & 0x80)) return true;
  }
}

// Rewrites the row and stream CRCs in place (stream layout of format 4, docs/codec.md: varint header,
// payloads back to back, index records, one CRC per tile row with payload, then the CRC of header and
// index (and the payloads, when there is one tile row) as the last 4 bytes).
void fix_checksums(std::vector<uint8_t>& s) {
  size_t p = 6;
  uint64_t w = 0, h = 0, tile16 = 0, flags = 0, step = 0, e = 0, payload = 0;
  for (uint64_t* field : {&w, &h, &tile16, &flags, &step})
    if (!get_varint(s, p, field)) return;
  if ((flags & 1) && !get_varint(s, p, &e)) return;
  if ((flags & 8) && s.size() >= 8 &&
      (s[4] == 7 || s[4] == 8)) {  // phase formats: the model, as the codec parses it
    const uint8_t* at = s.data() + p;
    codec::detail::PhaseModel model;
    if (!codec::detail::read_phase_model(at, s.data() + s.size(), &model)) return;
    p = size_t(at - s.data());
  }
  if (!get_varint(s, p, &payload)) return;
  const size_t data_offset = p;
  if (payload > s.size() || s.size() - payload < data_offset + 5 || tile16 == 0 || tile16 > (1u << 20) ||
      w == 0 || h == 0 || w > (uint64_t(1) << 40) || h > (uint64_t(1) << 40))
    return;
  const size_t index_offset = data_offset + size_t(payload), end = s.size() - 4;
  const uint64_t t = tile16 * 16, tiles_x = (w + t - 1) / t, tiles = tiles_x * ((h + t - 1) / t);
  const bool single_row = h <= t;  // no row CRC: the stream CRC covers the payloads
  p = index_offset;
  uint64_t offset = data_offset, row = UINT64_MAX;
  std::vector<std::pair<uint64_t, uint64_t>> rows;  // payload offset, size
  for (uint64_t n = 0; n < tiles;) {
    uint64_t record = 0;
    if (!get_varint(s, p, &record) || p > end) return;
    if (record & 1) {
      n += (record >> 1) + 1;
      continue;
    }
    if (n / tiles_x != row) rows.push_back({offset, 0});
    row = n / tiles_x;
    rows.back().second += record >> 1;
    offset += record >> 1;
    ++n;
  }
  for (const auto& [at, size] : rows) {
    if (single_row) break;
    if (end - p < 4) return;
    if (at <= index_offset && size <= index_offset - at)
      put_u32(s.data() + p, codec::crc32c(s.data() + at, size_t(size)));
    p += 4;
  }
  const size_t covered = single_row ? data_offset : index_offset;
  put_u32(s.data() + end,
          codec::crc32c(s.data() + covered, end - covered, codec::crc32c(s.data(), data_offset)));
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

// A small image from the input bytes, encoded with options the bytes choose: data[1], data[2] the
// size, data[3] bits 0-1 the tile size, bit 2 the residual transform (format 5), bits 3-5 a lossy
// step (0: lossless), bit 6 max-error mode, bit 7 phase tiles (format 8: with bit 6 or when lossless,
// max-error mode with E = the lossy setting; else bins of the step). The decoder must reproduce the encoder's
// reconstruction exactly (the input itself when lossless). Returns the stream.
std::vector<uint8_t> encode_checked(const uint8_t* data, size_t size, codec::Scratch& scratch) {
  const int64_t w = 1 + data[1] % 40, h = 1 + data[2] % 40;
  codec::EncodeOptions o;
  o.tile_size = 16u * (1 + data[3] % 3);
  o.transform = data[3] & 4 ? codec::Transform::Residual : codec::Transform::Lapped;
  const int lossy = (data[3] >> 3) & 7;
  o.step = lossy ? 1.5 * lossy : 1.0;
  o.bound_max_error = lossy && (data[3] & 64);
  o.max_error = o.bound_max_error ? uint32_t(lossy) : 0;
  if (data[3] & 128) {     // phase tiles: max-error (E = the lossy setting) or, with bit 6 clear and a
    o.phase_tiles = true;  // lossy setting, an rms stream whose bins are the (real-valued) step
    if (!lossy || (data[3] & 64)) {
      o.bound_max_error = true;
      o.max_error = uint32_t(lossy);
    }
  }
  std::vector<int32_t> img(size_t(w * h)), recon(img.size());
  for (size_t i = 0; i < img.size(); ++i) {
    const uint8_t b = size > 4 ? data[4 + i % (size - 4)] : data[i % size];
    img[i] = (int32_t(b) - 128) * (b & 1 ? 8191 : 1);
  }
  std::vector<uint8_t> stream(codec::encode_bound(w, h, o));
  size_t written = 0;
  if (codec::encode(img.data(), w, w, h, o, stream.data(), stream.size(), &written, scratch, recon.data(),
                    w) != codec::Status::Ok)
    std::abort();
  stream.resize(written);
  std::vector<int32_t> out(img.size());
  if (codec::decode(stream.data(), written, out.data(), w, scratch) != codec::Status::Ok) std::abort();
  if (out != recon || (!lossy && out != img)) std::abort();
  return stream;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static codec::Scratch scratch;
  if (size >= 4 && data[0] == 'E') {
    encode_checked(data, size, scratch);
    return 0;
  }
  // 'M' + 3 option bytes + 8 mutation bytes + image bytes: a valid stream of those options with
  // four bytes past its header xor-ed (offset, value pairs), re-checksummed, so that mutations reach
  // every tile decoder (the residual transform's included) however rarely random bytes form a stream.
  if (size >= 12 && data[0] == 'M') {
    std::vector<uint8_t> image(data, data + 4);
    image.insert(image.end(), data + 12, data + size);
    std::vector<uint8_t> stream = encode_checked(image.data(), image.size(), scratch);
    for (int k = 0; k < 4 && stream.size() > 8; ++k) {
      const size_t at = 6 + size_t(data[4 + 2 * k] * 131 + k * 17) % (stream.size() - 10);
      stream[at] ^= data[5 + 2 * k];
    }
    fix_checksums(stream);
    decode_checked(stream.data(), stream.size(), scratch);
    return 0;
  }
  decode_checked(data, size, scratch);
  std::vector<uint8_t> copy(data, data + size);
  fix_checksums(copy);
  decode_checked(copy.data(), copy.size(), scratch);
  return 0;
}
