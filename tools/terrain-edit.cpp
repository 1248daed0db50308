// terrain-edit: changes a compressed pyramid in place (libedit): brushes and patches on the finest
// level, carried to every level, re-coded tile by tile and committed copy-on-write; or compaction.
#include <cstdio>
#include <iostream>
#include <limits>
#include <string>
#include <vector>

#include "cli.h"
#include "container/container.h"
#include "edit/pyramid_edit.h"
#include "json_writer.h"
#include "readers/heightmap.h"

namespace {

using terrain::edit::Brush;
using terrain::edit::BrushShape;

// "x,y,radius,height[,shape]"
Brush parse_brush(const std::string& text) {
  std::vector<std::string> parts;
  size_t start = 0;
  for (size_t comma; (comma = text.find(',', start)) != std::string::npos; start = comma + 1)
    parts.push_back(text.substr(start, comma - start));
  parts.push_back(text.substr(start));
  if (parts.size() < 4 || parts.size() > 5)
    throw cli::UsageError("--brush: expected x,y,radius,height[,shape], got '" + text + "'");
  Brush b;
  b.x = cli::parse_double("--brush x", parts[0]);
  b.y = cli::parse_double("--brush y", parts[1]);
  b.radius = cli::parse_double("--brush radius", parts[2], 1e-9);
  b.height = cli::parse_double("--brush height", parts[3], -1e7, 1e7);
  if (parts.size() == 5 && !terrain::runtime::parse_edit_shape(parts[4], &b.shape))
    throw cli::UsageError("--brush: unknown shape '" + parts[4] + "' (cone, smooth or flat)");
  return b;
}

void parse_at(const std::string& text, int64_t* x, int64_t* y) {
  const size_t comma = text.find(',');
  if (comma == std::string::npos) throw cli::UsageError("--at: expected x,y, got '" + text + "'");
  *x = cli::parse_int("--at x", text.substr(0, comma), -(int64_t(1) << 40), int64_t(1) << 40);
  *y = cli::parse_int("--at y", text.substr(comma + 1), -(int64_t(1) << 40), int64_t(1) << 40);
}

int run(int argc, char** argv) {
  std::string path, patch_path, at_text, source_path, source_out;
  std::vector<Brush> brushes;
  double blend = 1;
  bool compact = false;
  cli::CommonFlags common;
  terrain::ReadOptions read_options;
  cli::ArgParser parser(
      "terrain-edit",
      "PYR (--brush x,y,radius,height[,shape] ... | --patch FILE --at x,y [--blend F]) | PYR --compact",
      "Edits a pyramid file in place. The finest level changes in the edited region; every coarser level\n"
      "follows through the file's D filter; exactly the libcodec tiles the change reaches (U's support\n"
      "included) are re-coded with the file's own step / max error, untouched tiles keep their bytes.\n"
      "New bytes are appended and committed atomically (a crash leaves the previous version readable);\n"
      "--compact rewrites the file without the dead bytes edits leave. Coordinates are finest-level\n"
      "columns and rows, heights metres. docs/format.md, \"Editing (2.2)\".");
  parser.positional("PYR", "the pyramid file to edit", &path);
  parser.option("--brush", "x,y,radius,height[,shape]",
                "add height metres at (x, y) within radius samples, shaped cone, smooth (default) or flat; "
                "repeatable, applied in order",
                [&](const std::string& v) { brushes.push_back(parse_brush(v)); });
  parser.option("--patch", "FILE",
                "a heightmap to blend in (any format terrain-info reads; voids leave samples alone)",
                &patch_path);
  parser.option("--at", "x,y", "--patch: finest-level position of the patch's first sample", &at_text);
  parser.option("--blend", "F", "--patch: new = (1 - F) old + F patch, F in [0, 1] (default 1)",
                [&](const std::string& v) { blend = cli::parse_double("--blend", v, 0.0, 1.0); });
  parser.option("--source", "FILE",
                "the heightmap the file was built from: edits apply to it, and the re-coded tiles get a "
                "rebuild's residuals (the file's error bound then holds against the edited input)",
                &source_path);
  parser.option(
      "--source-out", "FILE.raw",
      "with --source: also write the edited source heightmap (raw grid with its .json sidecar), the "
      "input a rebuild or terrain-report compares with",
      &source_out);
  parser.flag("--compact", "rewrite the file without dead bytes (through a temporary file, renamed over it)",
              &compact);
  cli::add_read_options(parser, read_options);
  parser.add_common(common);
  parser.epilog(
      "--json prints per level the bands and tiles re-coded and kept, then bytes appended, dead bytes,\n"
      "file bytes, the edit generation and seconds. Read options apply to --patch and --source.\n");
  if (auto status = parser.parse(argc, argv)) return *status;
  const bool editing = !brushes.empty() || !patch_path.empty();
  if (compact && editing) throw cli::UsageError("--compact runs alone: edit first, then compact");
  if (!compact && !editing) throw cli::UsageError("nothing to do: give --brush, --patch or --compact");
  if (!patch_path.empty() && at_text.empty()) throw cli::UsageError("--patch needs --at x,y");
  if (patch_path.empty() && !at_text.empty()) throw cli::UsageError("--at applies to --patch only");
  if (compact && !source_path.empty()) throw cli::UsageError("--source applies to edits only");
  if (!source_out.empty() && source_path.empty()) throw cli::UsageError("--source-out needs --source");
  if (!terrain::container::is_container_file(path))
    throw terrain::Error(terrain::ErrorCode::UnknownType, path + ": not a pyramid file (.pyr)");

  if (compact) {
    const terrain::edit::CompactStats s = terrain::edit::compact(path);
    if (common.json) {
      cli::JsonWriter j(std::cout);
      j.begin_object();
      j.field("file", path)
          .field("bytes_before", int64_t(s.bytes_before))
          .field("bytes_after", int64_t(s.bytes_after));
      j.end_object();
      j.finish();
    } else if (!common.quiet) {
      std::fprintf(stderr, "terrain-edit: %s compacted, %llu -> %llu bytes\n", path.c_str(),
                   static_cast<unsigned long long>(s.bytes_before),
                   static_cast<unsigned long long>(s.bytes_after));
    }
    return cli::kExitOk;
  }

  auto editor = terrain::edit::PyramidEditor::open(path);
  try {
    if (!source_path.empty()) editor->set_source(source_path, read_options);
    for (const Brush& b : brushes) editor->apply(b);
    if (!patch_path.empty()) {
      const terrain::Heightmap map = terrain::read_heightmap(patch_path, read_options);
      terrain::edit::Patch p;
      parse_at(at_text, &p.x, &p.y);
      p.width = map.width();
      p.height = map.height();
      p.blend = blend;
      p.heights.resize(size_t(p.width * p.height));
      for (int64_t y = 0; y < p.height; ++y)
        for (int64_t x = 0; x < p.width; ++x)
          p.heights[size_t(y * p.width + x)] =
              map.is_valid(x, y) ? float(map.metres(x, y)) : std::numeric_limits<float>::quiet_NaN();
      editor->apply(p);
    }
  } catch (const std::invalid_argument& e) {
    throw cli::UsageError(e.what());
  }
  const terrain::edit::EditStats s = editor->commit();
  if (!source_out.empty()) terrain::write_raw(source_out, *editor->source());
  if (common.json) {
    cli::JsonWriter j(std::cout);
    j.begin_object();
    j.field("file", path).field("changed", s.changed);
    j.key("levels").begin_array();
    for (size_t l = 0; l < s.levels.size(); ++l) {
      const auto& ls = s.levels[l];
      j.begin_object();
      j.field("level", int64_t(l)).field("bands_recoded", ls.bands_recoded);
      j.field("tiles_recoded", ls.tiles_recoded).field("tiles_kept", ls.tiles_kept);
      j.field("max_abs_delta_units", ls.max_abs_delta_units);
      j.key("changed").begin_array();  // x0, y0, width, height of where the level changed
      for (int64_t v : {ls.changed.x0, ls.changed.y0, ls.changed.width, ls.changed.height}) j.value(v);
      j.end_array();
      j.end_object();
    }
    j.end_array();
    j.field("bytes_appended", int64_t(s.bytes_appended)).field("dead_bytes", int64_t(s.dead_bytes));
    j.field("file_bytes", int64_t(s.file_bytes)).field("generation", int64_t(s.generation));
    j.field("seconds", s.seconds);
    j.end_object();
    j.finish();
  } else if (!common.quiet) {
    if (!s.changed) {
      std::fprintf(stderr, "terrain-edit: %s: the edit rounds to no change, file untouched\n", path.c_str());
    } else {
      int64_t tiles = 0, bands = 0;
      for (const auto& ls : s.levels) {
        tiles += ls.tiles_recoded;
        bands += ls.bands_recoded;
      }
      std::fprintf(
          stderr,
          "terrain-edit: %s generation %llu: %lld tiles in %lld bands re-coded, %llu bytes appended, "
          "%llu dead bytes (%.3f s)\n",
          path.c_str(), static_cast<unsigned long long>(s.generation), static_cast<long long>(tiles),
          static_cast<long long>(bands), static_cast<unsigned long long>(s.bytes_appended),
          static_cast<unsigned long long>(s.dead_bytes), s.seconds);
      if (common.verbose)
        for (size_t l = 0; l < s.levels.size(); ++l)
          std::fprintf(stderr,
                       "  level %zu: %lld bands, %lld tiles re-coded, %lld kept, max |delta| %.0f units\n", l,
                       static_cast<long long>(s.levels[l].bands_recoded),
                       static_cast<long long>(s.levels[l].tiles_recoded),
                       static_cast<long long>(s.levels[l].tiles_kept), s.levels[l].max_abs_delta_units);
    }
  }
  return cli::kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  return cli::run_tool("terrain-edit", [&] { return run(argc, argv); });
}
