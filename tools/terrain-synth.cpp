// terrain-synth: write a deterministic synthetic terrain (pyramid/synth.h) in the format the
// output's extension names.
#include <algorithm>
#include <cmath>
#include <iostream>

#include "cli.h"
#include "readers/heightmap.h"
#include "readers/terrain_generator.h"
#include "runtime/synthesis.h"

namespace {

// The terrain at 2^-K of the size (coarse_extent K times, spacing 2^K times), amplified by K
// synthesised levels of Gaussian detail (runtime/synthesis.h, docs/synthesis.md) and cropped to
// the requested size. Whole metres, sea (<= 0) kept flat, unless float output keeps the fractions.
terrain::Heightmap amplified_terrain(const terrain::SynthOptions& synth, int levels, double std0_m,
                                     double hurst, bool whole_metres) {
  terrain::SynthOptions base_options = synth;
  for (int k = 0; k < levels; ++k)
    base_options.width = terrain::coarse_extent(base_options.width),
    base_options.height = terrain::coarse_extent(base_options.height);
  base_options.spacing_m = std::ldexp(synth.spacing_m, levels);
  const terrain::Heightmap base = terrain::synthesize_terrain(base_options);
  terrain::runtime::FunctionHeightSource coarse(
      1, terrain::GridSize{base.width(), base.height()}, base_options.spacing_m,
      [&](int, int64_t x, int64_t y) { return float(base.metres(x, y)); }, false);
  terrain::runtime::SynthesisOptions o;
  o.levels = levels;
  o.std_m = terrain::runtime::fractal_std(std0_m, hurst, levels);
  o.seed = synth.seed;
  terrain::runtime::SynthesisSource source(coarse, o);
  std::vector<float> z(size_t(synth.width * synth.height));
  source.fill(levels, terrain::Rect{0, 0, synth.width, synth.height}, z.data(), synth.width);
  terrain::Heightmap map;
  map.info = base.info;
  map.info.width = synth.width;
  map.info.height = synth.height;
  map.info.spacing_x = map.info.spacing_y = synth.spacing_m;
  if (!whole_metres) map.info.sample_type = terrain::SampleType::Float32;
  map.values.resize(z.size());
  for (size_t i = 0; i < z.size(); ++i) {
    const double v = std::max(0.0, double(z[i]));
    map.values[i] = whole_metres ? std::min(32767.0, std::round(v)) : v;
  }
  return map;
}

int run(int argc, char** argv) {
  std::string out;
  bool big_endian = false;
  cli::CommonFlags common;
  terrain::SynthOptions synth;
  cli::ArgParser parser(
      "terrain-synth", "-o OUT --width W --height H [--seed S]",
      "Generates deterministic fractal terrain (integer metres, 0 = sea, up to ~3000 m; the same\n"
      "seed and size give the same bytes on every machine) and writes it by OUT's extension:\n"
      ".raw (+ OUT.json sidecar, int16), .png (16-bit grey), .tif/.tiff (16-bit), .exr (float32).");
  bool have_width = false, have_height = false;
  parser.option("-o,--output", "OUT", "output file", &out);
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
  int detail_levels = 0;
  double detail_std = -1, hurst = 0.8;
  parser.option(
      "--detail-levels", "K",
      "generate at 2^-K of the size and add K levels of synthesised fractal detail (U + Gaussian\n"
      "noise, the clipmap's synthesis; docs/synthesis.md)",
      [&](const std::string& v) { detail_levels = int(cli::parse_int("--detail-levels", v, 1, 8)); });
  parser.option("--detail-std", "M",
                "noise std of the first added level, metres (default 0.02 x its spacing)",
                [&](const std::string& v) {
                  detail_std = cli::parse_double("--detail-std", v);
                  if (!(detail_std >= 0 && detail_std < 1e4))
                    throw cli::UsageError("--detail-std must be in [0, 10000)");
                });
  parser.option("--hurst", "H", "std falls by 2^-H per finer level (default 0.8)", [&](const std::string& v) {
    hurst = cli::parse_double("--hurst", v);
    if (!(hurst >= 0 && hurst <= 2)) throw cli::UsageError("--hurst must be in [0, 2]");
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
  if (ends(".raw"))
    kind = Kind::Raw;
  else if (ends(".png") || ends(".tif") || ends(".tiff"))
    kind = Kind::Image16;
  else if (ends(".exr"))
    kind = Kind::Exr;
  else
    throw cli::UsageError("unknown output extension in " + out + " (use .raw, .png, .tif, .tiff or .exr)");

  if (detail_std < 0) detail_std = 0.02 * std::ldexp(synth.spacing_m, detail_levels - 1);
  terrain::Heightmap map = detail_levels > 0
                               ? amplified_terrain(synth, detail_levels, detail_std, hurst, kind != Kind::Exr)
                               : terrain::synthesize_terrain(synth);
  switch (kind) {
    case Kind::Raw:
      terrain::write_raw(out, map, big_endian);
      break;
    case Kind::Image16:
      terrain::write_image16(out, map);
      break;
    case Kind::Exr:
      terrain::write_exr(out, map);
      break;
  }
  if (common.verbose)
    std::cerr << "terrain-synth: wrote " << out << " (" << synth.width << "x" << synth.height << ")\n";
  return cli::kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  return cli::run_tool("terrain-synth", [&] { return run(argc, argv); });
}
