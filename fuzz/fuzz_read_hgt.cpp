// libFuzzer target for the SRTM .hgt reader (plain and gzipped).
// Input: byte 0 selects the variant (bit 0: name ends in .hgt.gz; bit 1: explicit --width from byte
// 1, so small non-standard tiles reach the sample decoder; bit 2: little endian), the rest is the
// file. Standard tiles are 2.9 MB, so without bit 1 mostly the size checks and gzip paths run.
//   Run: fuzz_read_hgt -max_len=65536 -max_total_time=600 [corpus_dir]
#include "fuzz_io_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 2) return 0;
  const uint8_t mode = data[0];
  terrain::ReadOptions o;
  if (mode & 2) o.width = 1 + data[1] % 128;
  if (mode & 4) o.big_endian = false;
  const std::string name = (mode & 1) ? "S33W071.hgt.gz" : "N27E086.hgt";
  const std::string path = fuzz_io::write_file(name, data + 2, size - 2);
  fuzz_io::read_both_ways(path, o);
  fuzz_io::remove_file(name);
  return 0;
}
