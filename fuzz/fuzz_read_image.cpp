// libFuzzer target for the image readers (PNG, TIFF, EXR through the OpenImageIO plugin, and
// Terrain-RGB decoding). Input: byte 0 selects the file name's extension (bits 0-1: .png, .tif,
// .exr, .tiff) and bit 2 asks for Terrain-RGB decoding; the rest is the file. Any terrain::Error is
// fine; a crash, a sanitizer report, an abort inside OpenImageIO or another exception type is not.
//   Run: fuzz_read_image -max_len=65536 -rss_limit_mb=2048 -max_total_time=600 [corpus_dir]
#include "fuzz_io_common.h"

// OpenImageIO keeps the text of each reader's last error in storage it never frees (seen through
// ImageInput::geterror): not ours to fix, so the leak checker ignores allocations made inside it.
extern "C" const char* __lsan_default_suppressions() { return "leak:libOpenImageIO\n"; }

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  static const char* const kNames[] = {"grid.png", "grid.tif", "grid.exr", "grid.tiff"};
  const std::string name = kNames[data[0] & 3];
  terrain::ReadOptions o;
  o.terrain_rgb = (data[0] & 4) != 0;
  const std::string path = fuzz_io::write_file(name, data + 1, size - 1);
  fuzz_io::read_both_ways(path, o);
  fuzz_io::remove_file(name);
  return 0;
}
