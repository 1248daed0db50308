// libFuzzer target for the ESRI ASCII grid reader (.asc) and the .prj beside it.
// Input: byte 0 = length L of the .prj text (0: none), bytes 1..L = grid.prj, the rest = grid.asc.
//   Run: fuzz_read_ascii -max_len=8192 -max_total_time=600 [corpus_dir]
#include "fuzz_io_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const size_t prj_len = data[0];
  if (1 + prj_len > size) return 0;
  if (prj_len) fuzz_io::write_file("grid.prj", data + 1, prj_len);
  const std::string path = fuzz_io::write_file("grid.asc", data + 1 + prj_len, size - 1 - prj_len);
  fuzz_io::read_both_ways(path, {});
  fuzz_io::remove_file("grid.asc");
  fuzz_io::remove_file("grid.prj");
  return 0;
}
