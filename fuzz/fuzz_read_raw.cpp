// libFuzzer target for the raw grid reader and its JSON sidecar parser.
// Input: byte 0 = length L of the sidecar text that follows (0: no sidecar, the reader must then
// use options or a square size), bytes 1..L = grid.raw.json, the rest = grid.raw (or grid.r16 /
// grid.r32 when L is 254 / 255 with no sidecar, which exercises their default types).
//   Run: fuzz_read_raw -max_len=8192 -max_total_time=600 [corpus_dir]
#include "fuzz_io_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  size_t json_len = data[0];
  std::string name = "grid.raw";
  if (json_len == 254 || json_len == 255) {
    name = json_len == 254 ? "grid.r16" : "grid.r32";
    json_len = 0;
  }
  if (1 + json_len > size) return 0;
  if (json_len) fuzz_io::write_file(name + ".json", data + 1, json_len);
  const std::string path = fuzz_io::write_file(name, data + 1 + json_len, size - 1 - json_len);
  fuzz_io::read_both_ways(path, {});
  fuzz_io::remove_file(name);
  fuzz_io::remove_file(name + ".json");
  return 0;
}
