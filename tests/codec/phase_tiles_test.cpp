// libcodec format 7 (phase tiles of max-error streams, docs/codec.md "Phase tiles (format 7)"): the
// bound at every sample (lossless included), the encoder's reconstruction, region decoding, the
// version rules, the stream's token model (fitting, reuse for splicing, parsing), the static token
// tables and rANS, and damaged streams, on the residuals of a point-sampled pyramid.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <random>
#include <vector>

#include "codec/codec.h"
#include "codec/crc32c.h"
#include "codec/internal/phase_coder.h"
#include "codec/internal/rans.h"
#include "codec/internal/token_tables.h"
#include "stream_test_util.h"

namespace {

using codec_test::encode;
using codec_test::Image;

// What a point-sampled pyramid's residual looks like: even-even samples within +-e (the coarse
// level's error), the other phases Laplacian of scale b (the four-point interpolation's error).
Image point_residual(int64_t w, int64_t h, double b, int e, uint32_t seed) {
  std::mt19937 rng(seed);
  std::exponential_distribution<double> lap(1.0 / b);
  std::uniform_int_distribution<int> small(-e, e);
  Image img{w, h, std::vector<int32_t>(size_t(w * h))};
  for (int64_t y = 0; y < h; ++y)
    for (int64_t x = 0; x < w; ++x)
      img.samples[size_t(y * w + x)] =
          (x % 2 == 0 && y % 2 == 0) ? small(rng) : int32_t(std::lround((rng() & 1 ? 1 : -1) * lap(rng)));
  return img;
}

codec::EncodeOptions options(uint32_t e, bool phase, uint32_t tile = 32) {
  codec::EncodeOptions o;
  o.bound_max_error = true;
  o.max_error = e;
  o.tile_size = tile;
  o.transform = codec::Transform::Residual;
  o.phase_tiles = phase;
  return o;
}

codec::Status decode(const std::vector<uint8_t>& s, const Image& like, std::vector<int32_t>* out) {
  return codec_test::decode_into(s, like, out);
}

int64_t max_abs_error(const Image& img, const std::vector<int32_t>& out) {
  int64_t m = 0;
  for (size_t i = 0; i < out.size(); ++i)
    m = std::max<int64_t>(m, std::llabs(int64_t(out[i]) - img.samples[i]));
  return m;
}

}  // namespace

TEST_CASE("phase tiles: the bound holds at every sample, lossless is exact, decode == encoder", "[codec]") {
  for (uint32_t e : {0u, 1u, 2u, 5u})
    for (int64_t w : {1, 2, 17, 64, 101})
      for (int64_t h : {1, 3, 32, 75}) {
        const Image img = point_residual(w, h, 3.0 + 4.0 * e, int(e), uint32_t(w * 131 + h * 7 + e));
        std::vector<int32_t> recon, out;
        const auto s = encode(img, options(e, true, 16), &recon);
        REQUIRE(decode(s, img, &out) == codec::Status::Ok);
        CHECK(out == recon);
        CHECK(max_abs_error(img, out) <= int64_t(e));
      }
}

TEST_CASE("phase tiles: smaller than the other modes on a point-sampled residual, never larger", "[codec]") {
  for (uint32_t e : {0u, 2u, 5u}) {
    const Image img = point_residual(256, 192, 2.0 + 3.0 * e, int(e), 40 + e);
    std::vector<int32_t> recon;
    const auto with = encode(img, options(e, true), &recon);
    const auto without = encode(img, options(e, false), &recon);
    INFO("E " << e << ": " << with.size() << " bytes with phase tiles, " << without.size() << " without");
    CHECK(double(with.size()) < 0.9 * double(without.size()));
    // Each tile of the residual skips its even phase, so the encoder keeps it a phase tile without
    // trying the other modes (mode bytes 2..26: 2 + the two final states' byte counts k0 + 5 k1).
    codec::Decoder decoder;
    REQUIRE(decoder.open(with.data(), with.size()) == codec::Status::Ok);
    size_t phase_tiles = 0;
    for (const codec::TileEntry& t : decoder.index())
      if (t.size > 0) {
        const uint8_t mode = with[size_t(t.offset)];
        CHECK((mode >= 2 && mode <= 26));
        ++phase_tiles;
      }
    CHECK(phase_tiles == size_t((256 / 32) * (192 / 32)));
    // Data the phase mode does not suit (a smooth ramp, its even phase far outside the bound) keeps
    // the other modes: at most the stream's version costs nothing and every tile picks the smallest.
    Image ramp{256, 64, std::vector<int32_t>(256 * 64)};
    for (int64_t y = 0; y < 64; ++y)
      for (int64_t x = 0; x < 256; ++x) ramp.samples[size_t(y * 256 + x)] = int32_t(3 * x + 5 * y);
    const auto ramp_with = encode(ramp, options(e, true), &recon);
    const auto ramp_without = encode(ramp, options(e, false), &recon);
    CHECK(ramp_with.size() <= ramp_without.size());
  }
}

TEST_CASE("phase tiles in an rms stream: the step is a real-valued bin, every tile a phase tile", "[codec]") {
  for (double step : {1.0, 2.0, 3.3, 3.5, 6.75}) {
    const double half = step / 2;
    const Image img = point_residual(130, 96, 2.0 * step, int(half), uint32_t(step * 100));
    codec::EncodeOptions o;
    o.step = step;
    o.tile_size = 32;
    o.transform = codec::Transform::Residual;
    o.phase_tiles = true;
    std::vector<int32_t> recon, out;
    const auto s = encode(img, o, &recon);
    codec::HeaderInfo h;
    REQUIRE(codec::read_header(s.data(), s.size(), &h) == codec::Status::Ok);
    CHECK(h.version == 8);
    CHECK(h.phase_tiles);
    CHECK(!h.bound_max_error);
    REQUIRE(decode(s, img, &out) == codec::Status::Ok);
    CHECK(out == recon);
    // Every error within half a bin plus the output's rounding; the rms near a uniform quantiser's.
    double squares = 0;
    for (size_t i = 0; i < out.size(); ++i) {
      const double e = double(out[i]) - img.samples[i];
      REQUIRE(std::abs(e) <= std::floor(half + (step == std::floor(step) ? 0.0 : 0.5)));
      squares += e * e;
    }
    const double rms = std::sqrt(squares / double(out.size()));
    INFO("step " << step << ": rms " << rms);
    if (step == 1.0) CHECK(rms == 0.0);
    if (step >= 2.0) CHECK((rms > 0.2 * step && rms < 0.4 * step));
    codec_test::check_regions(s, img, recon);
  }
}

TEST_CASE("phase tiles: region decodes equal the full decode", "[codec]") {
  const Image img = point_residual(203, 157, 6.0, 2, 11);
  std::vector<int32_t> recon;
  const auto s = encode(img, options(2, true), &recon);
  codec_test::check_regions(s, img, recon);
}

TEST_CASE("format versions: 7 exactly with the phase flag, only in max-error streams, 6 unsupported",
          "[codec]") {
  // One tile row, so codec_test::reseal works. Header: magic, u16 version, varints width (64), height (16),
  // tile / 16 (2), flags.
  const Image img = point_residual(64, 16, 4.0, 1, 5);
  constexpr size_t kFlags = 9;
  std::vector<int32_t> recon;
  const auto phase = encode(img, options(1, true), &recon);
  const auto plain = encode(img, options(1, false), &recon);
  codec::HeaderInfo h;
  REQUIRE(codec::read_header(phase.data(), phase.size(), &h) == codec::Status::Ok);
  CHECK(h.version == 8);
  CHECK(h.phase_tiles);
  CHECK(!h.phase_model.empty());
  CHECK(h.phase_model.size() <= size_t(codec::detail::kPhaseModelBytes));
  // Format 6 (the first phase tiles, adaptive binary coding) is retired: named, not misread.
  std::vector<uint8_t> v6 = phase;
  v6[4] = 6;
  codec_test::reseal(v6);
  CHECK(codec::read_header(v6.data(), v6.size(), &h) == codec::Status::UnsupportedVersion);
  REQUIRE(codec::read_header(plain.data(), plain.size(), &h) == codec::Status::Ok);
  CHECK(h.version == 5);
  CHECK(!h.phase_tiles);
  REQUIRE(phase[kFlags] == (1 | 4 | 8));  // max error, residual transform, phase tiles

  std::vector<uint8_t> v7_without_flag = phase;
  v7_without_flag[kFlags] = 1 | 4;
  codec_test::reseal(v7_without_flag);
  CHECK(codec::read_header(v7_without_flag.data(), v7_without_flag.size(), &h) == codec::Status::Corrupt);
  std::vector<uint8_t> v5_with_flag = plain;
  v5_with_flag[kFlags] = 1 | 4 | 8;
  codec_test::reseal(v5_with_flag);
  CHECK(codec::read_header(v5_with_flag.data(), v5_with_flag.size(), &h) == codec::Status::Corrupt);
  // A phase tile in a stream that does not allow them (the flag cleared, version 5) is rejected.
  std::vector<uint8_t> downgraded = phase;
  downgraded[4] = 5;
  downgraded[kFlags] = 1 | 4;
  codec_test::reseal(downgraded);
  std::vector<int32_t> out;
  CHECK(decode(downgraded, img, &out) != codec::Status::Ok);
}

TEST_CASE("phase tiles: every damaged byte is rejected, never a crash", "[codec]") {
  const Image img = point_residual(70, 40, 6.0, 2, 9);
  std::vector<int32_t> recon, out;
  const auto s = encode(img, options(2, true, 16), &recon);
  for (size_t i = 0; i < s.size(); ++i)
    for (uint8_t flip : {uint8_t(1), uint8_t(0x80)}) {
      std::vector<uint8_t> bad = s;
      bad[i] ^= flip;
      CHECK(decode(bad, img, &out) != codec::Status::Ok);
    }
  for (size_t n = 1; n < s.size(); n += 3) {
    std::vector<uint8_t> cut(s.begin(), s.begin() + std::ptrdiff_t(n));
    CHECK(decode(cut, img, &out) != codec::Status::Ok);
  }
  // The phase decoder itself on random payloads and models (what a forged stream with resealed CRCs
  // reaches): it returns or rejects, stays in its buffers (ASan), and keeps accepted samples within
  // +-2^30. Most random payloads fail the final-state check (the state must return to 1 with every
  // word read); the stream's CRCs catch damage before a payload gets here.
  std::mt19937 rng(1);
  std::vector<int32_t> recon_out(32 * 32);
  codec::detail::PhaseWork work;
  int accepted = 0;
  for (int k = 0; k < 2000; ++k) {
    codec::detail::PhaseModel model;
    for (int c = 0; c < codec::detail::kPhaseContexts; ++c) {
      model.used[c] = rng() & 1;
      model.member[c] = uint16_t(rng() % codec::detail::kFamilySize);
    }
    const codec::detail::PhaseTables tables(model);
    std::vector<uint8_t> payload(size_t(1 + rng() % 64));
    for (uint8_t& b : payload) b = uint8_t(rng());
    payload[0] = uint8_t(2 + rng() % 5);
    if (codec::detail::decode_phase(payload.data(), payload.size(), 32, 32, rng() % 4, tables,
                                    recon_out.data(), work)) {
      ++accepted;
      for (int32_t v : recon_out) REQUIRE(std::abs(int64_t(v)) <= (int64_t(1) << 30));
    }
  }
  CHECK(accepted < 200);  // measured: 64 of 2000
}

TEST_CASE("phase tiles: token tables are complete distributions built by integer arithmetic", "[codec]") {
  using namespace codec::detail;
  for (int i = 0; i < kFamilySize; ++i) {
    const TokenTable& t = token_table(i);
    REQUIRE(t.cum[kSymbols] == 4096);
    REQUIRE(t.freq[kTokenEscape] >= 1);
    REQUIRE(t.freq[0] >= 1);
    for (int k = 0; k < kSymbols; ++k) REQUIRE(t.cum[k + 1] == t.cum[k] + t.freq[k]);
    for (uint32_t s = 0; s < 4096; s += 7) {
      const int k = t.slots[s];
      REQUIRE((t.cum[k] <= s && s < t.cum[k] + t.freq[k]));
      REQUIRE(t.freq_cum[k] == (t.freq[k] | uint32_t(t.cum[k]) << 16));
    }
  }
  // Spot values: a change here changes every phase stream's decoding (a new format version).
  CHECK(token_table(0).freq[0] == 21);
  CHECK(token_table(kFamilySize - 1).freq[0] == 4086);
  CHECK(token_table(7 * kMeanLevels + 10).freq[1] == 523);  // +1: half of its share, and the remainder
  CHECK(token_table(7 * kMeanLevels + 10).freq[2] == 511);  // -1: the other half
  // Every magnitude up to 2^31 - 1 has a token and raw bits that rebuild it.
  for (uint32_t m : {0u, 1u, 15u, 16u, 17u, 23u, 24u, 31u, 32u, 1000u, 65535u, (1u << 30) + 5, 0x7fffffffu}) {
    int raw = 0;
    const int t = token_of(m, &raw);
    REQUIRE(t < kTokens);
    if (t >= 16) {
      int raw2 = 0;
      const uint32_t base = token_base(t, &raw2);
      CHECK(raw2 == raw);
      CHECK((base | (m & ((1u << raw) - 1))) == m);
    } else {
      CHECK(uint32_t(t) == m);
    }
  }
}

TEST_CASE("phase tiles: rANS round trip with raw bits, from state 1, on one and two lanes", "[codec]") {
  using namespace codec::detail;
  std::mt19937 rng(3);
  const auto round_trip = [](int lanes, const RansEncoder& enc,
                             const std::vector<std::pair<int, uint32_t>>& sent, const TokenTable& t,
                             uint32_t* states) {
    std::vector<uint16_t> words;
    enc.finish(lanes, states, words);
    std::vector<uint8_t> bytes;
    for (uint16_t w : words) bytes.push_back(uint8_t(w)), bytes.push_back(uint8_t(w >> 8));
    const auto check = [&](auto dec) {
      for (const auto& [k, v] : sent) {
        if (k < 0) {
          REQUIRE(dec.raw(-k) == v);
        } else {
          const int got = t.slots[dec.slot()];
          REQUIRE(got == k);
          dec.advance(t.cum[got], t.freq[got]);
        }
      }
      CHECK(dec.finished());
    };
    if (lanes == 2)
      check(RansDecoder<2>(states, bytes.data(), words.size()));
    else
      check(RansDecoder<1>(states, bytes.data(), words.size()));
  };
  for (int lanes : {1, 2})
    for (int n : {0, 1, 2, 3, 10, 1000}) {
      const TokenTable& t = token_table(int(rng() % kFamilySize));
      RansEncoder enc;
      std::vector<std::pair<int, uint32_t>> sent;  // symbol (or -bits for raw), value
      for (int i = 0; i < n; ++i) {
        if (rng() % 3 == 0) {
          const int bits = int(1 + rng() % 31);
          const uint32_t v = rng() & ((1u << bits) - 1);
          enc.put_raw(v, bits);
          sent.push_back({-bits, v});
        } else {
          int k = int(rng() % kSymbols);
          while (t.freq[k] == 0) k = (k + 1) % kSymbols;
          enc.put(t.cum[k], t.freq[k]);
          sent.push_back({k, 0});
        }
      }
      uint32_t states[2] = {};
      round_trip(lanes, enc, sent, t, states);
    }
  // Lane 0 gets symbols that cost almost nothing, lane 1 twelve raw bits each: lane 1 emits words
  // while lane 0 is still growing from 1, so the encoder must start both lanes at 2^16 instead.
  const TokenTable& t = token_table(kFamilySize - 1);
  int likely = 0;
  for (int k = 0; k < kSymbols; ++k)
    if (t.freq[k] > t.freq[likely]) likely = k;
  RansEncoder enc;
  std::vector<std::pair<int, uint32_t>> sent;
  for (int i = 0; i < 40; ++i) {
    enc.put(t.cum[likely], t.freq[likely]);
    sent.push_back({likely, 0});
    enc.put_raw(uint32_t(i * 97 % 4096), kRansMaxRawBits);
    sent.push_back({-kRansMaxRawBits, uint32_t(i * 97 % 4096)});
  }
  uint32_t states[2] = {};
  round_trip(2, enc, sent, t, states);
  CHECK(states[0] >= kRansLow);  // the fallback
  round_trip(1, enc, sent, t, states);
}

TEST_CASE("phase tiles: the stream's model is fitted, reused on request, and parsed strictly", "[codec]") {
  const Image a = point_residual(128, 64, 3.0, 1, 21), b = point_residual(128, 64, 12.0, 1, 22);
  std::vector<int32_t> recon_a, recon, out;
  const auto sa = encode(a, options(1, true), &recon_a);
  const auto sb = encode(b, options(1, true), &recon);
  codec::HeaderInfo ha, hb;
  REQUIRE(codec::read_header(sa.data(), sa.size(), &ha) == codec::Status::Ok);
  REQUIRE(codec::read_header(sb.data(), sb.size(), &hb) == codec::Status::Ok);
  CHECK(ha.phase_model != hb.phase_model);  // different scales, different members
  // Different models cannot be spliced; b coded with a's model can, and decodes like its tiles.
  std::vector<uint8_t> spliced;
  const std::vector<uint8_t> half = {1, 0, 1, 0, 1, 0, 1, 0};  // 4 x 2 tiles of 32
  CHECK(codec::splice_tiles(sa.data(), sa.size(), sb.data(), sb.size(), half, &spliced) ==
        codec::Status::InvalidArgument);
  codec::EncodeOptions o = options(1, true);
  o.phase_model_stream = sa.data();
  o.phase_model_stream_size = sa.size();
  std::vector<int32_t> recon_b;
  const auto sb_with_a = encode(b, o, &recon_b);
  codec::HeaderInfo h;
  REQUIRE(codec::read_header(sb_with_a.data(), sb_with_a.size(), &h) == codec::Status::Ok);
  CHECK(h.phase_model == ha.phase_model);
  CHECK(sb_with_a.size() >= sb.size());  // the fitted model is the better one
  REQUIRE(codec::splice_tiles(sa.data(), sa.size(), sb_with_a.data(), sb_with_a.size(), half, &spliced) ==
          codec::Status::Ok);
  REQUIRE(decode(spliced, a, &out) == codec::Status::Ok);
  for (int64_t y = 0; y < 64; ++y)
    for (int64_t x = 0; x < 128; ++x) {
      const size_t i = size_t(y * 128 + x);
      const bool fresh = half[size_t((y / 32) * 4 + x / 32)] != 0;
      REQUIRE(out[i] == (fresh ? recon_b : recon_a)[i]);
      REQUIRE(std::llabs(int64_t(out[i]) - (fresh ? b : a).samples[i]) <= 1);
    }
  // A garbage model source is ignored (the model is fitted).
  const uint8_t junk[5] = {1, 2, 3, 4, 5};
  o.phase_model_stream = junk;
  o.phase_model_stream_size = sizeof(junk);
  CHECK(encode(b, o, &recon_b) == sb);

  // Parsing: a member beyond the family or non-zero padding is rejected.
  using namespace codec::detail;
  PhaseModel m;
  m.used[0] = true;
  m.member[0] = kFamilySize - 1;
  uint8_t bytes[kPhaseModelBytes];
  const size_t n = write_phase_model(m, bytes);
  CHECK(n == 8);  // 48 flag bits + 10 member bits, padded
  const uint8_t* p = bytes;
  PhaseModel back;
  REQUIRE(read_phase_model(p, bytes + n, &back));
  CHECK(back == m);
  CHECK(p == bytes + n);
  bytes[7] |= 1;  // padding
  p = bytes;
  CHECK(!read_phase_model(p, bytes + n, &back));
  m.member[0] = 1023;
  write_phase_model(m, bytes);
  p = bytes;
  CHECK(!read_phase_model(p, bytes + n, &back));
  p = bytes;
  CHECK(!read_phase_model(p, bytes + n - 1, &back));
}

TEST_CASE("encode threads: the same stream and reconstruction for any thread count", "[codec]") {
  // Phase tiles (max error, lossless, rms bins, with and without a recon to replay into), the
  // residual and lapped transforms, and a stream spliceable into another's model; images of 1, 3 and
  // 7 tile rows, so that some threads get no row and chunks are uneven.
  std::vector<codec::EncodeOptions> modes;
  for (uint32_t e : {0u, 2u}) modes.push_back(options(e, true, 16));
  codec::EncodeOptions rms = options(0, true, 16);
  rms.bound_max_error = false;
  rms.step = 3.4;
  modes.push_back(rms);
  codec::EncodeOptions residual = rms;
  residual.phase_tiles = false;
  modes.push_back(residual);
  codec::EncodeOptions lapped = residual;
  lapped.transform = codec::Transform::Lapped;
  modes.push_back(lapped);
  for (int64_t h : {16, 40, 112}) {
    const Image img = point_residual(77, h, 6.0, 2, uint32_t(h));
    for (size_t m = 0; m < modes.size(); ++m) {
      std::vector<int32_t> recon1;
      const auto one = encode(img, modes[m], &recon1);
      for (uint32_t threads : {2u, 3u, 7u, 64u}) {
        codec::EncodeOptions o = modes[m];
        o.threads = threads;
        std::vector<int32_t> recon;
        CHECK(encode(img, o, &recon) == one);
        CHECK(recon == recon1);
        // Without a reconstruction (no replay of the statistics pass) the stream is the same too.
        codec::Scratch scratch;
        std::vector<uint8_t> out(codec::encode_bound(img.width, img.height, o));
        size_t n = 0;
        REQUIRE(codec::encode(img.samples.data(), img.width, img.width, img.height, o, out.data(), out.size(),
                              &n, scratch) == codec::Status::Ok);
        out.resize(n);
        CHECK(out == one);
        // A model taken from a given stream (an editor's splice).
        if (modes[m].phase_tiles) {
          codec::EncodeOptions given = o;
          given.phase_model_stream = one.data();
          given.phase_model_stream_size = one.size();
          codec::EncodeOptions given1 = given;
          given1.threads = 1;
          std::vector<int32_t> r1, rn;
          CHECK(encode(img, given, &rn) == encode(img, given1, &r1));
          CHECK(rn == r1);
        }
      }
    }
  }
}
