// CRC-32C: published check value, hardware/portable agreement, and chunked continuation.
#include <catch2/catch.hpp>
#include <cstring>
#include <random>
#include <vector>

#include "container/container.h"

using terrain::container::crc32c;
using terrain::container::crc32c_portable;

TEST_CASE("crc32c matches the published CRC-32C check value", "[runtime][container][crc]") {
  const char* check = "123456789";
  // 0xE3069283 is the catalogued check value of CRC-32/ISCSI (Castagnoli).
  CHECK(crc32c(check, 9) == 0xE3069283u);
  CHECK(crc32c_portable(check, 9) == 0xE3069283u);
  CHECK(crc32c(nullptr, 0) == 0u);
  // 32 zero bytes: the iSCSI specification's (RFC 3720 B.4) first example.
  const std::vector<uint8_t> zeros(32, 0);
  CHECK(crc32c(zeros.data(), zeros.size()) == 0x8A9136AAu);
  const std::vector<uint8_t> ones(32, 0xFF);
  CHECK(crc32c(ones.data(), ones.size()) == 0x62A8AB43u);
}

TEST_CASE("crc32c hardware and portable paths agree at every length and alignment",
          "[runtime][container][crc]") {
  std::mt19937_64 rng(12345);
  std::vector<uint8_t> buffer(4096 + 16);
  for (auto& b : buffer) b = uint8_t(rng());
  for (size_t offset = 0; offset < 8; ++offset) {
    for (size_t length : {size_t(0), size_t(1), size_t(7), size_t(8), size_t(9), size_t(63), size_t(64),
                          size_t(65), size_t(1000), size_t(4096)}) {
      INFO("offset " << offset << " length " << length);
      CHECK(crc32c(buffer.data() + offset, length) == crc32c_portable(buffer.data() + offset, length));
    }
  }
}

TEST_CASE("crc32c continues across chunks", "[runtime][container][crc]") {
  std::mt19937_64 rng(777);
  std::vector<uint8_t> data(3000);
  for (auto& b : data) b = uint8_t(rng());
  const uint32_t whole = crc32c(data.data(), data.size());
  for (int trial = 0; trial < 50; ++trial) {
    size_t pos = 0;
    uint32_t crc = 0, portable = 0;
    while (pos < data.size()) {
      const size_t n = std::min<size_t>(data.size() - pos, rng() % 200);
      crc = crc32c(data.data() + pos, n, crc);
      portable = crc32c_portable(data.data() + pos, n, portable);
      pos += n;
    }
    CHECK(crc == whole);
    CHECK(portable == whole);
  }
  // A single flipped bit changes the checksum.
  data[1234] ^= 0x10;
  CHECK(crc32c(data.data(), data.size()) != whole);
}

TEST_CASE("crc32c_combine gives the CRC of the concatenation", "[runtime][container][crc]") {
  std::mt19937_64 rng(4242);
  std::vector<uint8_t> data(5000);
  for (auto& b : data) b = uint8_t(rng());
  const uint32_t whole = crc32c(data.data(), data.size());
  for (size_t cut :
       {size_t(0), size_t(1), size_t(7), size_t(8), size_t(255), size_t(4096), size_t(4999), size_t(5000)}) {
    INFO("cut " << cut);
    const uint32_t a = crc32c(data.data(), cut), b = crc32c(data.data() + cut, data.size() - cut);
    CHECK(codec::crc32c_combine(a, b, data.size() - cut) == whole);
  }
  // Pieces of random sizes folded left to right, as the striped assembly combines a level's bands.
  for (int trial = 0; trial < 20; ++trial) {
    uint32_t crc = 0;
    for (size_t pos = 0; pos < data.size();) {
      const size_t n = std::min<size_t>(data.size() - pos, rng() % 700);
      crc = codec::crc32c_combine(crc, crc32c(data.data() + pos, n), n);
      pos += n;
    }
    CHECK(crc == whole);
  }
  // A piece of 1 MiB (zeros, chained 16 times): combining equals continuing the CRC over it.
  const std::vector<uint8_t> zeros(1 << 16, 0);
  uint32_t piece = 0, continued = 0x12345678u;
  for (int i = 0; i < 16; ++i) {
    piece = crc32c(zeros.data(), zeros.size(), piece);
    continued = crc32c(zeros.data(), zeros.size(), continued);
  }
  CHECK(codec::crc32c_combine(0x12345678u, piece, uint64_t(16) << 16) == continued);
}
