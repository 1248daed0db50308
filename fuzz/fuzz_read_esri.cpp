// libFuzzer target for the ESRI .bil / .flt readers and their .hdr header parser.
// Input: byte 0 bit 0 = write the grid as grid.flt (else grid.bil), byte 1 = length L of the header
// text, bytes 2..L+1 = grid.hdr, the rest = the grid samples.
//   Run: fuzz_read_esri -max_len=8192 -max_total_time=600 [corpus_dir]
#include "fuzz_io_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 2) return 0;
  const bool flt = data[0] & 1;
  const size_t hdr_len = data[1];
  if (2 + hdr_len > size) return 0;
  const std::string name = flt ? "grid.flt" : "grid.bil";
  fuzz_io::write_file("grid.hdr", data + 2, hdr_len);
  const std::string path = fuzz_io::write_file(name, data + 2 + hdr_len, size - 2 - hdr_len);
  fuzz_io::read_both_ways(path, {});
  fuzz_io::remove_file(name);
  fuzz_io::remove_file("grid.hdr");
  return 0;
}
