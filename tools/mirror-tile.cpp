// mirror-tile: makes a large seamless int16 raw grid (+ .json sidecar) by mirror-tiling a real tile,
// for out-of-core benchmarks. The output is written row by row: only the tile is held in memory.
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <limits>
#include <vector>

#include "cli.h"
#include "core/file.h"
#include "core/text.h"
#include "readers/heightmap.h"

namespace {

// Mirror reflection without repeating the edge sample, so tile copies join without a seam.
int64_t reflect(int64_t i, int64_t n) {
  if (n == 1) return 0;
  const int64_t period = 2 * (n - 1);
  i %= period;
  return i < n ? i : period - i;
}

void write_all(std::FILE* f, const void* data, size_t bytes, const std::string& path) {
  if (std::fwrite(data, 1, bytes, f) != bytes)
    throw terrain::Error(terrain::ErrorCode::WriteFailed, path + ": cannot write (disk full?)");
}

int run(int argc, char** argv) {
  std::string input, output;
  int64_t width = 0, height = 0;
  cli::CommonFlags common;
  terrain::ReadOptions read_options;
  cli::ArgParser parser(
      "mirror-tile", "TILE -o OUT.raw --out-width W --out-height H [options]",
      "Mirror-tiles TILE (reflected at every tile edge, so the result is seamless) into a\n"
      "W x H little-endian int16 raw grid OUT.raw with an OUT.raw.json sidecar. Rows are\n"
      "streamed to disk; memory is the tile plus one output row. Voids stay voids (-32768).");
  parser.positional("TILE", "heightmap tile to repeat (any format terrain-info reads)", &input);
  parser.option("-o,--output", "OUT", "raw grid to write (required)", &output);
  // 2^20: the widest row the readers take (docs/io.md, "Limits"); a wider grid could not be read back.
  parser.option("--out-width", "W", "output width in samples (at most 2^20)",
                [&](const std::string& v) { width = cli::parse_int("--out-width", v, 1, int64_t(1) << 20); });
  parser.option("--out-height", "H", "output height in samples", [&](const std::string& v) {
    height = cli::parse_int("--out-height", v, 1, int64_t(1) << 31);
  });
  cli::add_read_options(parser, read_options);
  parser.add_common(common, false);
  if (auto status = parser.parse(argc, argv)) return *status;
  if (output.empty()) throw cli::UsageError("missing -o OUT.raw");
  if (width <= 0 || height <= 0) throw cli::UsageError("--out-width and --out-height are required");

  const terrain::Heightmap tile = terrain::read_heightmap(input, read_options);
  const int64_t tw = tile.width(), th = tile.height();
  std::vector<int16_t> samples(size_t(tw * th));
  bool has_voids = false;
  for (int64_t k = 0; k < tw * th; ++k) {
    if (!tile.is_valid(k % tw, k / tw)) {
      samples[size_t(k)] = std::numeric_limits<int16_t>::min();
      has_voids = true;
      continue;
    }
    const double v = tile.values[size_t(k)];
    if (v != std::round(v) || v <= -32768.0 || v > 32767.0)
      throw terrain::Error(terrain::ErrorCode::UnknownType,
                           input + ": sample " + std::to_string(v) + " does not fit int16 (-32767..32767)");
    samples[size_t(k)] = int16_t(v);
  }

  terrain::check_output_path(output, {input});
  terrain::check_output_path(output + ".json", {input});
  // The grid is written out in full: refuse at once when it cannot fit (a 2^31 x 2^31 request wrote
  // 24 GiB before the disk filled).
  const std::filesystem::path dir = std::filesystem::absolute(output).parent_path();
  const unsigned __int128 need = (unsigned __int128)width * (unsigned __int128)height * 2;
  std::error_code ec;
  const std::filesystem::space_info space = std::filesystem::space(dir, ec);
  if (!ec && need > space.available)
    throw terrain::Error(terrain::ErrorCode::WriteFailed,
                         output + ": needs " + std::to_string(double(need) / (1 << 30)) +
                             " GiB, the file system has " +
                             std::to_string(double(space.available) / (1 << 30)) + " GiB free");
  std::string temp;
  const int fd = terrain::create_temp_beside(output, "", &temp);
  std::FILE* f = ::fdopen(fd, "wb");
  if (!f) {
    ::close(fd);
    std::remove(temp.c_str());
    throw terrain::Error(terrain::ErrorCode::WriteFailed, output + ": cannot create");
  }
  std::setvbuf(f, nullptr, _IOFBF, size_t(1) << 20);
  std::vector<int16_t> row(static_cast<size_t>(width));
  try {
    for (int64_t y = 0; y < height; ++y) {
      const int16_t* src = samples.data() + reflect(y, th) * tw;
      for (int64_t x = 0; x < width; ++x) row[size_t(x)] = src[reflect(x, tw)];  // little-endian host
      write_all(f, row.data(), row.size() * sizeof(int16_t), output);
    }
    if (std::fclose(f) != 0) throw terrain::Error(terrain::ErrorCode::WriteFailed, output + ": cannot close");
  } catch (...) {
    std::remove(temp.c_str());
    throw;
  }
  std::FILE* js = std::fopen((output + ".json").c_str(), "wb");
  if (!js) throw terrain::Error(terrain::ErrorCode::WriteFailed, output + ".json: cannot create");
  std::fprintf(
      js,
      "{\n  \"width\": %lld,\n  \"height\": %lld,\n  \"type\": \"int16\",\n  \"byte_order\": \"little\",\n"
      "  \"spacing_x\": %.17g,\n  \"spacing_y\": %.17g,\n  \"horizontal_units\": \"%s\",\n"
      "  \"vertical_scale\": %.17g,\n  \"vertical_offset\": %.17g,\n  \"nodata\": %s\n}\n",
      (long long)width, (long long)height, tile.info.spacing_x, tile.info.spacing_y,
      tile.info.horizontal_units.c_str(), tile.info.vertical_scale, tile.info.vertical_offset,
      has_voids ? "-32768" : "null");
  if (std::fclose(js) != 0)
    throw terrain::Error(terrain::ErrorCode::WriteFailed, output + ".json: cannot write");
  std::filesystem::rename(temp, output);
  if (!common.quiet)
    std::cerr << "mirror-tile: wrote " << output << " (" << width << "x" << height << " int16, "
              << double(width) * double(height) * 2 / (1 << 20) << " MiB) from " << tw << "x" << th
              << " tile\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return cli::run_tool("mirror-tile", [&] { return run(argc, argv); });
}
