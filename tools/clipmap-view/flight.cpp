// clipmap-view's camera flight: keyframes (a --path file or the built-in pass), the clipmap update
// and render of every frame (and of the reference flight beside it), PNG frames, stats.csv and
// stats.json.
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>

#include "cli.h"
#include "clipmap_view.h"
#include "codec/codec.h"
#include "core/file.h"
#include "edit/pyramid_edit.h"
#include "json_writer.h"
#include "plot.h"
#include "readers/heightmap.h"
#include "render/renderer.h"
#include "report_file.h"

namespace clipmap_view {

using namespace terrain;
using namespace terrain::runtime;
using namespace terrain::render;

void DamageLog::poll(const RegionDecoder& decoder) {
  size_t& seen = seen_[&decoder];
  for (DamagedTile& d : decoder.damaged_tiles(seen)) {
    ++seen;
    if (!keys_.emplace(d.level, d.band, d.tile_x, d.tile_y).second) continue;
    // Logged even with -q: the exit status alone does not say where the file is damaged.
    std::cerr << "clipmap-view: damaged: " << d.message << "; shown from a coarser level\n";
    parts_.push_back(std::move(d));
  }
}

RenderOptions render_options(const ViewOptions& o) {
  RenderOptions r;
  r.transitions = !o.no_transitions;
  r.culling = !o.no_culling;
  r.shading = o.shading;
  r.drape = !o.drape.empty();
  r.mesh = o.mesh;
  return r;
}

void apply_drape(ClipmapRenderer& renderer, const Flight& flight) {
  const ViewOptions& o = flight.options;
  if (o.drape.empty()) return;
  ReadOptions ro;
  ro.terrain_rgb = true;  // value = R * 65536 + G * 256 + B, exactly
  const Heightmap image = read_heightmap(o.drape, ro);
  if (image.info.sample_type != SampleType::TerrainRGB)
    throw Error(ErrorCode::UnknownType, o.drape + ": --drape needs an 8-bit RGB or RGBA image");
  if (image.width() > 16384 || image.height() > 16384)
    throw Error(ErrorCode::Oversized, o.drape + ": --drape image larger than 16384 pixels a side");
  std::vector<uint8_t> rgba(size_t(image.width()) * size_t(image.height()) * 4);
  for (size_t i = 0; i < image.values.size(); ++i) {
    const auto v = uint32_t(image.values[i]);
    rgba[4 * i] = uint8_t(v >> 16), rgba[4 * i + 1] = uint8_t(v >> 8), rgba[4 * i + 2] = uint8_t(v);
    rgba[4 * i + 3] = image.valid.empty() || image.valid[i] ? 255 : 0;
  }
  const GridSize fs = flight.source.level_size(flight.source.level_count() - 1);
  const double g = flight.spacing;
  const GlLeakCheckPause gl_pause;
  renderer.set_drape(rgba, int(image.width()), int(image.height()), -0.5 * g, -0.5 * g, double(fs.width) * g,
                     double(fs.height) * g);
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const double k = std::clamp(std::ceil(p * double(v.size())) - 1, 0.0, double(v.size() - 1));
  return v[size_t(k)];
}

std::vector<std::pair<int, std::string>> read_small_text(const std::string& path, const std::string& what) {
  // A small text file: anything else (a FIFO, /dev/zero) is refused before reading.
  constexpr uint64_t kMaxBytes = uint64_t(16) << 20;
  uint64_t bytes = 0;
  ::close(terrain::open_regular_file(path, &bytes));
  if (bytes > kMaxBytes) throw Error(ErrorCode::Oversized, path + ": " + what + " larger than 16 MiB");
  std::ifstream in(path);
  if (!in) throw Error(ErrorCode::NotFound, "cannot open " + what + " " + path);
  std::vector<std::pair<int, std::string>> lines;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    lines.emplace_back(number, line);
  }
  return lines;
}

std::vector<Key> read_path(const std::string& path) {
  std::vector<Key> keys;
  for (const auto& [number, line] : read_small_text(path, "camera path")) {
    std::istringstream s(line);
    Key k{};
    if (!(s >> k.frame)) continue;  // blank or comment line
    if (!(s >> k.x >> k.y >> k.above >> k.yaw_deg >> k.pitch_deg) ||
        !std::isfinite(k.x + k.y + k.above + k.yaw_deg + k.pitch_deg))
      throw Error(ErrorCode::MissingField, path + ":" + std::to_string(number) +
                                               ": expected 'frame x_m y_m above_m yaw_deg pitch_deg'");
    if (!keys.empty() && k.frame <= keys.back().frame)
      throw Error(ErrorCode::MissingField,
                  path + ":" + std::to_string(number) + ": frame numbers must increase");
    keys.push_back(k);
  }
  if (keys.empty()) throw Error(ErrorCode::MissingField, path + ": no keyframes");
  return keys;
}

// The built-in flight: towards the highest point of the coarsest level (so the default shows relief
// rather than sea), past it, then a climbing turn. Distances scale with the terrain's extent.
std::vector<Key> default_path(HeightSource& source, double spacing, int frames) {
  const GridSize c = source.level_size(0);
  std::vector<float> coarse(size_t(c.width * c.height));
  source.fill(0, Rect{0, 0, c.width, c.height}, coarse.data(), c.width);
  const size_t peak = size_t(std::max_element(coarse.begin(), coarse.end()) - coarse.begin());
  const double cs = std::ldexp(spacing, source.level_count() - 1);  // metres per coarsest sample
  // Kept in the middle of the terrain: beyond its edges the clipmap shows the repeated edge samples.
  const double wm = double(c.width) * cs, hm = double(c.height) * cs;
  const double px = std::clamp(double(int64_t(peak) % c.width) * cs, 0.45 * wm, 0.7 * wm);
  const double py = std::clamp(double(int64_t(peak) / c.width) * cs, 0.4 * hm, 0.55 * hm);
  const double ext = std::max(wm, hm), f = std::max(frames - 1, 1);
  return {{0, px - 0.25 * ext, py - 0.10 * ext, 0.008 * ext, 20, -14},
          {0.6 * f, px - 0.06 * ext, py - 0.03 * ext, 0.008 * ext, 25, -16},
          {0.8 * f, px + 0.01 * ext, py + 0.02 * ext, 0.015 * ext, 90, -22},
          {f, px, py + 0.08 * ext, 0.04 * ext, 180, -35}};
}

Key interpolate(const std::vector<Key>& keys, double frame) {
  if (frame <= keys.front().frame) return keys.front();
  if (frame >= keys.back().frame) return keys.back();
  size_t i = 1;
  while (keys[i].frame < frame) ++i;
  if (keys[i].frame == frame) return keys[i];  // exactly the keyframe (a recorded path replays exactly)
  const Key &a = keys[i - 1], &b = keys[i];
  const double t = (frame - a.frame) / (b.frame - a.frame);
  auto mix = [t](double u, double v) { return u + (v - u) * t; };
  return Key{frame,
             mix(a.x, b.x),
             mix(a.y, b.y),
             mix(a.above, b.above),
             mix(a.yaw_deg, b.yaw_deg),
             mix(a.pitch_deg, b.pitch_deg)};
}

float ground_height(HeightSource& source, double x, double y) {
  const int finest_level = source.level_count() - 1;
  const double spacing = source.spacing_m();
  const GridSize fs = source.level_size(finest_level);
  const int64_t gx = std::clamp<int64_t>(int64_t(std::llround(x / spacing)), 0, fs.width - 1);
  const int64_t gy = std::clamp<int64_t>(int64_t(std::llround(y / spacing)), 0, fs.height - 1);
  float ground = 0;
  source.fill(finest_level, Rect{gx, gy, 1, 1}, &ground, 1);
  return ground;
}

Camera camera_at(HeightSource& source, const Key& k, double fov_deg) {
  Camera cam;
  cam.position[0] = k.x;
  cam.position[1] = k.y;
  cam.position[2] = double(ground_height(source, k.x, k.y)) + k.above;
  cam.yaw = k.yaw_deg * M_PI / 180.0;
  cam.pitch = k.pitch_deg * M_PI / 180.0;
  cam.fov_y_deg = fov_deg;
  return cam;
}

std::vector<EditEvent> read_edit_script(const std::string& path) {
  std::vector<EditEvent> events;
  for (const auto& [number, line] : read_small_text(path, "edit script")) {
    std::istringstream s(line);
    double seconds = 0;
    std::string kind;
    if (!(s >> seconds)) continue;  // blank or comment line
    const std::string where = path + ":" + std::to_string(number) + ": ";
    EditEvent e;
    bool ok = bool(s >> kind);
    if (ok && kind == "brush") {
      ok = bool(s >> e.edit.x0 >> e.edit.y0 >> e.edit.radius >> e.edit.height);
      e.edit.x1 = e.edit.x0, e.edit.y1 = e.edit.y0;
      std::string shape;
      if (ok && s >> shape && !parse_edit_shape(shape, &e.edit.shape))
        throw Error(ErrorCode::MissingField,
                    where + "brush shape must be cone, smooth or flat, got " + shape);
    } else if (ok && kind == "channel") {
      double depth = 0;
      ok = bool(s >> e.edit.x0 >> e.edit.y0 >> e.edit.x1 >> e.edit.y1 >> e.edit.radius >> depth);
      e.edit.height = -depth;
    } else {
      throw Error(ErrorCode::MissingField, where +
                                               "expected 'SECONDS brush X Y RADIUS HEIGHT [SHAPE]' or "
                                               "'SECONDS channel X0 Y0 X1 Y1 RADIUS DEPTH'");
    }
    const TerrainEdit& t = e.edit;
    if (!ok || !std::isfinite(seconds + t.x0 + t.y0 + t.x1 + t.y1 + t.radius + t.height) || seconds < 0 ||
        seconds > 1e6 || !(t.radius > 0) || t.radius > 1e9)
      throw Error(ErrorCode::MissingField,
                  where + "bad " + kind + " (seconds 0..1e6, finite numbers, radius in (0, 1e9] samples)");
    e.frame = int(std::lround(seconds * 30));
    events.push_back(e);
  }
  std::stable_sort(events.begin(), events.end(),
                   [](const EditEvent& a, const EditEvent& b) { return a.frame < b.frame; });
  return events;
}

namespace {

// Resident memory now, MiB (/proc/self/statm), and the peak so far (getrusage).
double rss_mib() {
  std::ifstream statm("/proc/self/statm");
  long pages = 0, resident = 0;
  if (!(statm >> pages >> resident)) return 0;
  return double(resident) * double(sysconf(_SC_PAGESIZE)) / double(1 << 20);
}
double peak_rss_mib() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_maxrss) / 1024.0;
}

// CPU seconds of the calling thread: the update's own work, without the time a loaded machine
// does not run it (wall time includes that).
double thread_cpu_seconds() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
}

// CPU seconds of the whole process (all threads, llvmpipe's included): on a shared machine a steadier
// measure of the work per frame than wall time.
double cpu_seconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

// Per-frame times (ms) and counts of a flight, for the summaries.
struct FlightLog {
  std::vector<double> frame_ms, update_ms, update_cpu_ms, render_ms, upload_ms, psnr, rss_mib;
  double peak_rss_mib = 0;  // at the end of the flight (before the plot and the summary are written)
  // The update's parts per frame, ms: decode (all of the fill), U, residual, zc, normals, bounds.
  std::array<std::vector<double>, 6> part_ms;
  int64_t triangles_total = 0;
  double cpu_ms_per_frame = 0;
};
const char* const kPartNames[] = {"decode", "upsample", "residual", "zc", "normals", "bounds"};

void write_stats_json(const std::string& json_path, const Flight& flight, const Clipmap& clipmap,
                      const std::string& renderer_name, const FlightLog& log,
                      const std::vector<LevelScreenError>& sse, double s_px,
                      const std::vector<DamagedTile>& damaged) {
  const ViewOptions& o = flight.options;
  const double med = percentile(log.frame_ms, 0.5), p99 = percentile(log.frame_ms, 0.99);
  cli::ReportFile file(json_path);
  cli::JsonWriter j(file.stream());
  j.begin_object();
  j.field("pyramid", o.pyramid)
      .field("renderer", renderer_name)
      .field("n", flight.clipmap.n)
      .field("levels", clipmap.level_count())
      .field("mesh", o.mesh == Mesh::Tessellation ? "tessellation" : "footprints");
  if (o.max_screen_error) j.field("max_screen_error_px", *o.max_screen_error);
  j.field("width", o.width).field("height", o.height).field("fov_y_deg", o.fov).field("frames", o.frames);
  j.field("budget", clipmap.budget()).field("transitions", !o.no_transitions).field("culling", !o.no_culling);
  j.field("budget_ms", clipmap.budget_ms());
  if (o.mirror > 0) j.field("mirror", o.mirror);
  j.field("update_ms_p95", percentile(log.update_ms, 0.95))
      .field("update_ms_max", percentile(log.update_ms, 1.0))
      .field("update_cpu_ms_median", percentile(log.update_cpu_ms, 0.5))
      .field("update_cpu_ms_p95", percentile(log.update_cpu_ms, 0.95));
  // Memory: the peak, and the resident size a tenth into the flight and at its end (a flight whose
  // memory is bounded has the two about equal, however long it is).
  j.field("peak_rss_mib", log.peak_rss_mib)
      .field("rss_mib_at_10_percent", log.rss_mib.empty() ? 0.0 : log.rss_mib[log.rss_mib.size() / 10])
      .field("rss_mib_at_end", log.rss_mib.empty() ? 0.0 : log.rss_mib.back());
  j.field("frame_ms_median", med).field("frame_ms_p99", p99);
  j.field("fps_median", med > 0 ? 1e3 / med : 0.0).field("cpu_ms_per_frame", log.cpu_ms_per_frame);
  j.field("update_ms_median", percentile(log.update_ms, 0.5))
      .field("update_ms_p99", percentile(log.update_ms, 0.99));
  for (size_t k = 0; k < log.part_ms.size(); ++k) {
    j.field(std::string(kPartNames[k]) + "_ms_median", percentile(log.part_ms[k], 0.5));
    j.field(std::string(kPartNames[k]) + "_ms_p99", percentile(log.part_ms[k], 0.99));
  }
  j.field("upload_ms_median", percentile(log.upload_ms, 0.5))
      .field("upload_ms_p99", percentile(log.upload_ms, 0.99));
  j.field("render_ms_median", percentile(log.render_ms, 0.5))
      .field("render_ms_p99", percentile(log.render_ms, 0.99));
  j.field("triangles_mean", double(log.triangles_total) / o.frames);
  if (!log.psnr.empty()) {
    double sum = 0;
    for (double v : log.psnr) sum += v;
    j.field("reference", flight.ref_file ? o.reference : o.original)
        .field("psnr_db_mean", sum / double(log.psnr.size()));
    j.field("psnr_db_min", *std::min_element(log.psnr.begin(), log.psnr.end()));
    j.field("psnr_db_median", percentile(log.psnr, 0.5));
  }
  if (!sse.empty()) {
    j.field("triangle_size_px", s_px);
    j.key("screen_space_error").begin_array();
    for (const LevelScreenError& e : sse) {
      j.begin_object();
      j.field("level", e.level)
          .field("spacing_m", e.spacing_m)
          .field("rms_m", e.rms_m)
          .field("max_m", e.max_m);
      j.field("rms_px", e.rms_px).field("p999_px", e.p999_px).field("max_px", e.max_px);
      j.end_object();
    }
    j.end_array();
  }
  j.key("damaged_tiles").begin_array();
  for (const DamagedTile& d : damaged) {
    j.begin_object();
    j.field("level", d.level)
        .field("band", int64_t(d.band))
        .field("tile_x", d.tile_x)
        .field("tile_y", d.tile_y);
    j.field("x0", d.area.x0)
        .field("y0", d.area.y0)
        .field("width", d.area.width)
        .field("height", d.area.height);
    j.field("file_offset", int64_t(d.file_offset)).field("bytes", int64_t(d.bytes));
    j.field("message", d.message);
    j.end_object();
  }
  j.end_array();
  j.end_object();
  j.finish();
  file.finish();
}

void print_summary(const Flight& flight, const FlightLog& log) {
  const ViewOptions& o = flight.options;
  const double med = percentile(log.frame_ms, 0.5), p99 = percentile(log.frame_ms, 0.99);
  std::printf(
      "frames %d at %dx%d: frame time median %.2f ms (%.1f fps), p99 %.2f ms; update median %.3f ms, p99 "
      "%.3f ms; "
      "upload median %.3f ms; render median %.2f ms; %.0f triangles/frame; process CPU %.1f ms/frame; stats "
      "in %s\n",
      o.frames, o.width, o.height, med, med > 0 ? 1e3 / med : 0.0, p99, percentile(log.update_ms, 0.5),
      percentile(log.update_ms, 0.99), percentile(log.upload_ms, 0.5), percentile(log.render_ms, 0.5),
      double(log.triangles_total) / o.frames, log.cpu_ms_per_frame, o.out_dir.c_str());
  std::printf(
      "update parts, median ms: decode %.3f (U %.3f, residual %.3f), zc %.3f, normals %.3f, bounds %.3f\n",
      percentile(log.part_ms[0], 0.5), percentile(log.part_ms[1], 0.5), percentile(log.part_ms[2], 0.5),
      percentile(log.part_ms[3], 0.5), percentile(log.part_ms[4], 0.5), percentile(log.part_ms[5], 0.5));
  std::printf("update ms: median %.3f, p95 %.3f, max %.3f%s; peak RSS %.1f MiB\n",
              percentile(log.update_ms, 0.5), percentile(log.update_ms, 0.95), percentile(log.update_ms, 1.0),
              flight.clipmap.budget_ms > 0
                  ? (" (budget " + cli::tick_label(flight.clipmap.budget_ms) + " ms)").c_str()
                  : "",
              log.peak_rss_mib);
  if (!log.psnr.empty())
    std::printf("image PSNR against %s: median %.2f dB, min %.2f dB (99 = identical)\n",
                (flight.ref_file ? o.reference : o.original).c_str(), percentile(log.psnr, 0.5),
                *std::min_element(log.psnr.begin(), log.psnr.end()));
}

// --plot-times: update and render (upload + draw) time per frame, the time budget as a line.
void write_times_plot(const std::string& path, const FlightLog& log, double budget_ms,
                      const std::string& title) {
  cli::PlotSeries update{"update", {200, 40, 40, 255}, {}, {}, false, 1};
  cli::PlotSeries render{"render", {30, 80, 200, 255}, {}, {}, false, 1};
  for (size_t f = 0; f < log.update_ms.size(); ++f) {
    update.x.push_back(double(f)), update.y.push_back(log.update_ms[f]);
    render.x.push_back(double(f)), render.y.push_back(log.render_ms[f] + log.upload_ms[f]);
  }
  std::vector<cli::PlotSeries> series{update, render};
  if (budget_ms > 0 && !log.update_ms.empty())
    series.push_back(cli::PlotSeries{"budget",
                                     {20, 150, 60, 255},
                                     {0, double(log.update_ms.size() - 1)},
                                     {budget_ms, budget_ms},
                                     false,
                                     1});
  cli::PlotAxes axes;
  axes.title = title;
  axes.x_label = "frame";
  axes.y_label = "milliseconds";
  axes.log_y = true;  // update (sub-millisecond) and render (tens of ms on llvmpipe) on one plot
  try {
    cli::line_plot(series, axes).write_png(path);
  } catch (const Error& e) {
    throw Error(ErrorCode::WriteFailed, std::string("cannot write the times plot: ") + e.what());
  }
}

// --mirror without --path: a straight low flight from the middle of the virtual terrain, 4 finest
// samples a frame (fast for the finest level, which then refills every frame).
std::vector<Key> mirror_path(HeightSource& source, double spacing, int frames) {
  const GridSize fs = source.level_size(source.level_count() - 1);
  const double cx = 0.5 * double(fs.width) * spacing, cy = 0.5 * double(fs.height) * spacing;
  const double d = 4.0 * spacing * std::max(frames - 1, 1);
  return {{0, cx, cy, 300, 30, -12},
          {double(std::max(frames - 1, 1)), cx + d * 0.866, cy + d * 0.5, 300, 30, -12}};
}

// What the clipmap shows when --edit-pyramid rewrites the file: the source of the file's latest
// version, switched after each commit (the clipmap keeps its reference to this).
class SwitchableSource final : public HeightSource {
 public:
  explicit SwitchableSource(HeightSource& s) : s_(&s) {}
  void set(HeightSource& s) { s_ = &s; }
  int level_count() const override { return s_->level_count(); }
  GridSize level_size(int level) const override { return s_->level_size(level); }
  double spacing_m() const override { return s_->spacing_m(); }
  void fill(int level, const Rect& rect, float* out, int64_t out_stride) override {
    s_->fill(level, rect, out, out_stride);
  }
  bool refines_units() const override { return s_->refines_units(); }
  void fill_units(int level, const Rect& rect, const HeldUnits* coarser, float* out, int32_t* units_out,
                  int64_t out_stride, FillSplit* split) override {
    s_->fill_units(level, rect, coarser, out, units_out, out_stride, split);
  }

 private:
  HeightSource* s_;
};

// The codec tile side of a pyramid's levels (the largest any band's header gives): what an edit
// re-codes as a whole.
int64_t codec_tile_size(const container::PyramidFile& file) {
  int64_t t = 1;
  for (int l = 0; l < file.level_count(); ++l)
    for (const container::BandView& v : file.bands(l)) {
      codec::HeaderInfo h;
      if (!v.empty() && codec::read_header(v.data, v.size, &h) == codec::Status::Ok)
        t = std::max<int64_t>(t, int64_t(h.tile_size));
    }
  return t;
}

// One edit written into the file through libedit: a brush as it is, a channel as a patch of the
// current finest level plus the channel's profile (NaN where it adds nothing).
edit::EditStats commit_edit(edit::PyramidEditor& editor, const TerrainEdit& e, HeightSource& current) {
  if (e.x0 == e.x1 && e.y0 == e.y1) {
    const edit::Brush b{e.x0, e.y0, e.radius, e.height, e.shape};
    editor.apply(b);
  } else {
    const Rect r = edit_bounds(e);
    if (r.width * r.height > (int64_t(1) << 26))
      throw Error(ErrorCode::Oversized, "edit script: a channel over more than 2^26 samples");
    edit::Patch p;
    p.x = r.x0, p.y = r.y0, p.width = r.width, p.height = r.height;
    p.heights.resize(size_t(r.width * r.height));
    current.fill(current.level_count() - 1, r, p.heights.data(), r.width);
    for (int64_t y = 0; y < r.height; ++y)
      for (int64_t x = 0; x < r.width; ++x) {
        const double d = edit_delta(e, double(r.x0 + x), double(r.y0 + y));
        float& h = p.heights[size_t(y * r.width + x)];
        h = d != 0 ? float(h + d) : std::nanf("");
      }
    editor.apply(p);
  }
  return editor.commit();
}

}  // namespace

int run_flight(const Flight& flight) {
  const ViewOptions& o = flight.options;
  const ClipmapOptions& copt = flight.clipmap;
  const double spacing = flight.spacing;
  HeightSource* ground = flight.ground ? flight.ground : &flight.source;
  // --edit-script: the edits go into an overlay over what the clipmap shows (or, --edit-pyramid,
  // into the file, whose new version the clipmap then reads), and the clipmap refills the samples
  // each one reaches (Clipmap::invalidate) within its budget.
  const std::vector<EditEvent> edits =
      o.edit_script.empty() ? std::vector<EditEvent>{} : read_edit_script(o.edit_script);
  EditOverlaySource overlay(flight.heights);
  SwitchableSource live(flight.heights);
  std::unique_ptr<edit::PyramidEditor> editor;
  std::shared_ptr<const RegionDecoder> decoder = flight.decoder;
  std::unique_ptr<RegionDecoderSource> edited_source;
  int64_t tile_size = 1;
  if (o.edit_pyramid) {
    editor = edit::PyramidEditor::open(o.pyramid);
    if (!o.edit_source.empty()) editor->set_source(o.edit_source);
    tile_size = codec_tile_size(*flight.file);
  }
  HeightSource& shown = edits.empty() ? flight.heights : editor ? static_cast<HeightSource&>(live) : overlay;
  Clipmap clipmap(shown, copt);
  size_t next_edit = 0;
  DamageLog damage;

  // The reference flight: same clipmap options over another pyramid or the original input.
  Reference reference;
  if (auto status = open_reference(flight, reference)) return *status;
  std::unique_ptr<Clipmap> ref_clipmap;
  if (reference.source) ref_clipmap = std::make_unique<Clipmap>(*reference.source, copt);

  const std::vector<Key> keys = !o.path_file.empty() ? read_path(o.path_file)
                                : o.mirror > 0       ? mirror_path(*ground, spacing, o.frames)
                                                     : default_path(*ground, spacing, o.frames);

  std::error_code ec;
  std::filesystem::create_directories(o.out_dir, ec);
  const std::string csv_path = o.out_dir + "/stats.csv", json_path = o.out_dir + "/stats.json";
  // Through a temporary renamed when complete; a flight that fails leaves neither it nor stats.csv.
  cli::ReportFile csv_file(csv_path);
  std::ostream& csv = csv_file.stream();
  csv << "frame,x_m,y_m,z_m,update_ms,decode_ms,upsample_ms,residual_ms,zc_ms,normals_ms,bounds_ms,upload_ms,"
         "render_ms,frame_ms,"
         "triangles,blocks_drawn,blocks_culled,draw_calls,active_levels,levels_behind,samples_decoded,"
         "samples_reconstructed,residual_samples_decoded,samples_uploaded,psnr_db,pieces,out_of_time,edits,"
         "edit_ms,rss_mib,update_cpu_ms\n";

  // Screen-space geometric error of the levels this clipmap renders (L&H 2004 Table 2).
  const double s_px = triangle_size_px(o.width, o.height, o.fov, copt.n);
  std::vector<LevelScreenError> sse;
  if (reference.original)
    sse = report_screen_space_error(flight, *reference.original, clipmap.source_level(0), s_px, damage);

  // Every GL call runs under a GlLeakCheckPause: Mesa's process-lifetime allocations would otherwise
  // fail an ASan build at exit.
  std::optional<GlLeakCheckPause> gl_setup_pause(std::in_place);
  HeadlessGL gl;
  ClipmapRenderer renderer(copt.n, clipmap.level_count(), o.width, o.height);
  std::unique_ptr<ClipmapRenderer> ref_renderer;
  if (ref_clipmap)
    ref_renderer = std::make_unique<ClipmapRenderer>(copt.n, clipmap.level_count(), o.width, o.height);
  gl_setup_pause.reset();
  apply_drape(renderer, flight);
  if (ref_renderer) apply_drape(*ref_renderer, flight);
  std::vector<uint8_t> ref_pixels;
  if (!o.quiet)
    std::cerr << "clipmap-view: " << gl.renderer_name() << " (EGL " << gl.platform() << "), n=" << copt.n
              << ", " << clipmap.level_count() << " levels, " << o.width << "x" << o.height << ", spacing "
              << spacing << " m\n";
  const RenderOptions ropt = render_options(o);
  std::vector<uint8_t> pixels;
  FlightLog log;
  std::vector<std::string> written;
  const double cpu0 = cpu_seconds();
  for (int f = 0; f < o.frames; ++f) {
    const Key k = interpolate(keys, double(f));
    // Ground under the camera from the finest level (one sample, decoded through the tile cache).
    int edits_now = 0;
    double edit_ms = 0;
    for (; next_edit < edits.size() && edits[next_edit].frame <= f; ++next_edit, ++edits_now) {
      const TerrainEdit& e = edits[next_edit].edit;
      if (!editor) {
        clipmap.invalidate(overlay.add(e));
        continue;
      }
      // Write through: commit, reopen the file's new version, show it, refill what changed.
      const auto te = Clock::now();
      const edit::EditStats es = commit_edit(*editor, e, *ground);
      decoder = std::make_shared<const RegionDecoder>(container::PyramidFile::open(o.pyramid),
                                                      size_t(256) << 20, DamagePolicy::Degrade);
      edited_source = std::make_unique<RegionDecoderSource>(decoder, spacing);
      live.set(*edited_source);
      ground = edited_source.get();
      clipmap.invalidate(edit_bounds(e), tile_size);
      edit_ms += since(te) * 1e3;
      if (!o.quiet)
        std::cerr << "clipmap-view: frame " << f << ": edit committed (generation " << es.generation << ", "
                  << es.bytes_appended << " bytes appended, " << since(te) * 1e3 << " ms)\n";
    }
    const Camera cam = camera_at(*ground, k, o.fov);
    const RegionStats before = decoder->stats();
    const double cpu_before = thread_cpu_seconds();
    const auto t0 = Clock::now();
    const ClipmapUpdateStats us = clipmap.update(cam.position[0], cam.position[1], cam.position[2]);
    const double upd = since(t0);
    log.update_cpu_ms.push_back((thread_cpu_seconds() - cpu_before) * 1e3);
    RenderStats rs;
    {
      const GlLeakCheckPause gl_pause;
      renderer.upload(clipmap);
      rs = renderer.render(clipmap, cam, ropt);
    }
    const double total = since(t0);
    const RegionStats after = decoder->stats();
    damage.poll(*decoder);
    double frame_psnr = std::nan("");
    if (ref_clipmap) {
      ref_clipmap->update(cam.position[0], cam.position[1], cam.position[2]);
      {
        const GlLeakCheckPause gl_pause;
        ref_renderer->upload(*ref_clipmap);
        ref_renderer->render(*ref_clipmap, cam, ropt);
        ref_renderer->read_rgba(ref_pixels);
        renderer.read_rgba(pixels);
      }
      frame_psnr = image_psnr(pixels, ref_pixels);
      log.psnr.push_back(frame_psnr);
    }
    if (o.png_every > 0 && f % o.png_every == 0) {
      {
        const GlLeakCheckPause gl_pause;
        renderer.read_rgba(pixels);
      }
      char name[64];
      std::snprintf(name, sizeof name, "/frame_%05d.png", f);
      write_png_rgba(o.out_dir + name, o.width, o.height, pixels);
      written.push_back(o.out_dir + name);
      if (ref_renderer) {
        std::snprintf(name, sizeof name, "/reference_%05d.png", f);
        write_png_rgba(o.out_dir + name, o.width, o.height, ref_pixels);
      }
    }
    log.frame_ms.push_back(total * 1e3);
    log.update_ms.push_back(upd * 1e3);
    const double parts[6] = {us.seconds_fill,   us.seconds_upsample, us.seconds_residual,
                             us.seconds_coarse, us.seconds_normals,  us.seconds_bounds};
    for (size_t part = 0; part < log.part_ms.size(); ++part) log.part_ms[part].push_back(parts[part] * 1e3);
    log.render_ms.push_back(rs.seconds_render * 1e3);
    log.upload_ms.push_back(rs.seconds_upload * 1e3);
    log.triangles_total += rs.triangles;
    csv << f << ',' << cam.position[0] << ',' << cam.position[1] << ',' << cam.position[2] << ',' << upd * 1e3
        << ',' << us.seconds_fill * 1e3 << ',' << us.seconds_upsample * 1e3 << ','
        << us.seconds_residual * 1e3 << ',' << us.seconds_coarse * 1e3 << ',' << us.seconds_normals * 1e3
        << ',' << us.seconds_bounds * 1e3 << ',' << rs.seconds_upload * 1e3 << ',' << rs.seconds_render * 1e3
        << ',' << total * 1e3 << ',' << rs.triangles << ',' << rs.blocks_drawn << ',' << rs.blocks_culled
        << ',' << rs.draw_calls << ',' << us.active_levels << ',' << us.levels_behind << ','
        << us.samples_filled << ',' << after.samples_reconstructed - before.samples_reconstructed << ','
        << after.residual_samples_decoded - before.residual_samples_decoded << ',' << rs.samples_uploaded
        << ',';
    if (!std::isnan(frame_psnr)) csv << frame_psnr;
    log.rss_mib.push_back(rss_mib());
    csv << ',' << us.pieces << ',' << (us.out_of_time ? 1 : 0) << ',' << edits_now << ',' << edit_ms << ','
        << log.rss_mib.back() << ',' << log.update_cpu_ms.back() << '\n';
  }
  // CPU per frame covers everything in the loop (reference renders and PNG writing included).
  log.cpu_ms_per_frame = (cpu_seconds() - cpu0) * 1e3 / o.frames;
  log.peak_rss_mib = peak_rss_mib();
  csv_file.finish();

  damage.poll(*decoder);
  write_stats_json(json_path, flight, clipmap, gl.renderer_name(), log, sse, s_px, damage.parts());
  if (!o.plot_times.empty())
    write_times_plot(
        o.plot_times, log, clipmap.budget_ms(),
        std::filesystem::path(o.pyramid).filename().string() +
            (clipmap.budget_ms() > 0 ? ", --budget-ms " + cli::tick_label(clipmap.budget_ms()) : ""));
  print_summary(flight, log);
  if (!written.empty() && !o.quiet)
    std::cerr << "clipmap-view: " << written.size() << " PNG frames in " << o.out_dir << "\n";
  if (damage.parts().empty()) return cli::kExitOk;
  std::cerr << "clipmap-view: finished with " << damage.parts().size()
            << " damaged tile(s), shown from coarser levels (exit " << cli::kExitDamaged << ")\n";
  return cli::kExitDamaged;
}

}  // namespace clipmap_view
