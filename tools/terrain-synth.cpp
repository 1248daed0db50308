// terrain-synth: write a deterministic synthetic terrain (pyramid/synth.h) in the format the
// output's extension names.
#include <iostream>

#include "cli.h"
#include "pyramid/heightmap.h"
#include "pyramid/synth.h"

namespace {

int run(int argc, char** argv) {
  std::string out;
  bool big_endian = false;
  cli::CommonFlags common;
  terrain::SynthOptions synth;
  cli::ArgParser parser("terrain-synth", "-o OUT --width W --height H [--seed S]",
                        "Generates deterministic fractal terrain (integer metres, 0 = sea, up to ~3000 m; the same\n"
                        "seed and size give the same bytes on every machine) and writes it by OUT's extension:\n"
                        ".raw (+ OUT.json sidecar, int16), .png (16-bit grey), .tif/.tiff (16-bit), .exr (float32).");
  bool have_width = false, have_height = false;
  parser.option("-o,--output", "OUT", "output file", [&](const std::string& v) { out = v; });
  parser.option("--width", "W", "samples per row (1..65536)", [&](const std::string& v) {
    synth.width = cli::parse_int("--width", v, 1, 65536);
    have_width = true;
  });
  parser.option("--height", "H", "rows (1..65536)", [&](const std::string& v) {
    synth.height = cli::parse_int("--height", v, 1, 65536);
    have_height = true;
  });
  parser.option("--seed", "S", "random seed (default 1)", [&](const std::string& v) {
    synth.seed = uint64_t(cli::parse_int("--seed", v, 0, INT64_MAX));
  });
  parser.option("--spacing", "M", "horizontal spacing recorded in the metadata, metres (default 30)",
                [&](const std::string& v) {
                  synth.spacing_m = cli::parse_double("--spacing", v);
                  if (!(synth.spacing_m > 0)) throw cli::UsageError("--spacing must be positive");
                });
  parser.flag("--big-endian", "write .raw samples big-endian", &big_endian);
  parser.add_common(common, false);
  if (auto status = parser.parse(argc, argv)) return *status;
  if (out.empty()) throw cli::UsageError("missing -o OUT");
  if (!have_width || !have_height) throw cli::UsageError("missing --width or --height");

  const std::string lower = [&] {
    std::string s = out;
    for (auto& c : s) c = char(c >= 'A' && c <= 'Z' ? c + 32 : c);
    return s;
  }();
  auto ends = [&](const char* ext) {
    std::string e = ext;
    return lower.size() >= e.size() && lower.compare(lower.size() - e.size(), e.size(), e) == 0;
  };
  enum class Kind { Raw, Image16, Exr } kind;
  if (ends(".raw")) kind = Kind::Raw;
  else if (ends(".png") || ends(".tif") || ends(".tiff")) kind = Kind::Image16;
  else if (ends(".exr")) kind = Kind::Exr;
  else throw cli::UsageError("unknown output extension in " + out + " (use .raw, .png, .tif, .tiff or .exr)");

  terrain::Heightmap map = terrain::synthesize_terrain(synth);
  switch (kind) {
    case Kind::Raw: terrain::write_raw(out, map, big_endian); break;
    case Kind::Image16: terrain::write_image16(out, map); break;
    case Kind::Exr: terrain::write_exr(out, map); break;
  }
  if (common.verbose) std::cerr << "terrain-synth: wrote " << out << " (" << synth.width << "x" << synth.height << ")\n";
  return cli::kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  return cli::run_tool("terrain-synth", [&] { return run(argc, argv); });
}
