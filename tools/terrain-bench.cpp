// terrain-bench: run time against error for this project's whole pyramid and for the peer codecs.
//
// For every DEM: (1) the project end to end: build_pyramid_file (the library form of pyramid-build)
// at a sweep of rms / max-error targets and lossless, then the region decoder reconstructs the
// finest level; bits/sample = whole pyramid file bytes / finest samples, errors against the input in
// metres, build / full-decode / cold-region-decode speeds. (2) Every peer codec (and libcodec alone
// as one level) on the same grid converted to int16 sample units (the file's own integers for SRTM;
// the native quantum minus a mid-range offset for 16-bit data such as Puget Sound's 0.1 m units),
// one thread, codec time only. Writes a CSV and, with --markdown, the generated BENCHMARKS.md.
#include <build/pyramid_build.h>
#include <cli.h>
#include <container/pyramid_file.h>
#include <peers.h>
#include <readers/heightmap.h>
#include <runtime/region_decoder.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "cli.h"

namespace {

constexpr int kExitNotFound = 2, kExitWriteFailed = 9;

struct Options {
  std::string csv_path, markdown_path, command, provenance, work_dir, plot_dir = ".", region_speed;
  cli::CommonFlags common;
  bool quick = false;
  bool list = false;
  bool self_test = false;
  bool pyramid = true;
  int threads = 0;
  double min_time = 0.2;
  std::optional<double> vertical_scale;
  std::vector<std::string> peer_names;
  std::vector<std::string> files;
};

std::vector<std::string> split_commas(const std::string& text) {
  std::vector<std::string> parts;
  std::stringstream ss(text);
  std::string part;
  while (std::getline(ss, part, ','))
    if (!part.empty()) parts.push_back(part);
  return parts;
}

// Fills o; returns the status to exit with now (after --help, or a usage error it has reported).
std::optional<int> parse_args(int argc, char** argv, Options& o) {
  cli::ArgParser p(
      "terrain-bench", "[options] [FILE...]",
      "Run time against error. For each height grid: this project's whole pyramid (build_pyramid_file,\n"
      "then the region decoder) at a sweep of rms and max-error targets and lossless; and the peer\n"
      "codecs (OpenJPEG JPEG 2000, OpenJPH HTJ2K, libjxl JPEG XL lossless, jxrlib JPEG XR, CharLS\n"
      "JPEG-LS, LERC, ZFP, zstd, and libcodec alone as one level) over each codec's parameter sweep,\n"
      "one thread, codec time only.\n"
      "Writes a markdown summary to stdout (or BENCHMARKS.md with --markdown).");
  p.rest("FILE",
         "height grids; default: every .hgt and .png in the shared data directory ($TERRAIN_DATA_DIR,\n"
         "../shared/data or /work/shared/data)",
         &o.files);
  p.option("--csv", "PATH", "also write one CSV row per (file, codec, setting)", &o.csv_path);
  p.option("--markdown", "PATH", "write the generated benchmark report (BENCHMARKS.md) to PATH",
           &o.markdown_path);
  p.option("--command", "TEXT", "the command line quoted in the report as the way to reproduce it",
           &o.command);
  p.option("--provenance", "TEXT", "a line for the report: commit, machine, date", &o.provenance);
  p.option("--plot-dir", "DIR", "where the report's plots (rms.png, max.png, speed.png) are, relative to it",
           &o.plot_dir);
  p.option("--peers", "a,b,...", "only these peer codecs (see --list); 'none' for the pyramid only",
           [&](const std::string& v) { o.peer_names = split_commas(v); });
  bool no_pyramid = false;
  p.flag("--no-pyramid", "peers only (the former codec-bench)", &no_pyramid);
  p.option("--threads", "N",
           "pyramid build threads (default: the cores it may run on); decoding is single-threaded",
           [&](const std::string& v) { o.threads = int(cli::parse_int("--threads", v, 1, 256)); });
  p.option("--work-dir", "DIR", "where the pyramid files are built (default $TMPDIR or /tmp); removed after",
           &o.work_dir);
  p.flag("--quick", "short sweeps and one repetition (smoke runs)", &o.quick);
  p.option("--vertical-scale", "S",
           "metres per stored unit for every FILE (default: the file's own; the shared Puget Sound PNG is\n"
           "known to be 0.1)",
           [&](const std::string& v) {
             o.vertical_scale = cli::parse_double("--vertical-scale", v, 1e-12, 1e12);
           });
  p.option("--min-time", "S",
           "repeat encode and decode until each totals S seconds, keep the best (default 0.2)",
           [&](const std::string& v) { o.min_time = cli::parse_double("--min-time", v, 0, 60); });
  p.option("--region-speed", "PYR",
           "only time cold 256x256 region decodes of an existing pyramid file's finest level (scale runs):\n"
           "64 windows, one thread, prints Msamples/s",
           &o.region_speed);
  p.flag("--list", "print each codec's exact configuration and exit", &o.list);
  p.flag("--self-test",
         "round-trip a synthetic 97x61 int16 grid through every setting of every codec, checking the size\n"
         "and each declared error bound; exit 0 if all pass",
         &o.self_test);
  p.flag("--json", "print the rows as a JSON array on stdout instead of the markdown summary",
         &o.common.json);
  p.add_common(o.common, false);
  p.epilog(
      "Exit status 70 also reports a codec failure, an exceeded error bound or a failed self-test check.");
  if (auto status = p.parse(argc, argv)) return status;
  o.pyramid = !no_pyramid;
  if (o.quick) o.min_time = 0;
  if (o.work_dir.empty()) {
    const char* tmp = std::getenv("TMPDIR");
    o.work_dir = tmp && *tmp ? tmp : "/tmp";
  }
  return std::nullopt;
}

std::vector<std::string> default_files() {
  std::vector<std::string> dirs;
  if (const char* env = std::getenv("TERRAIN_DATA_DIR")) dirs.push_back(env);
  dirs.push_back("../shared/data");
  dirs.push_back("/work/shared/data");
  for (const std::string& dir : dirs) {
    std::error_code ec;
    if (!std::filesystem::is_directory(dir, ec)) continue;
    std::vector<std::string> files;
    for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
      const std::string ext = entry.path().extension().string();
      if (ext == ".hgt" || ext == ".png") files.push_back(entry.path().string());
    }
    std::sort(files.begin(), files.end());
    if (!files.empty()) return files;
  }
  return {};
}

// The grid in int16 units: round(metres / unit) - offset. unit is the native quantum (x 2^k only if
// the range exceeds 65535 quanta); offset is 0 when the values fit int16 as they are (SRTM: the file's
// own integers), else the mid-range, so 16-bit data such as Puget Sound keeps its 0.1 m quantum.
peers::Image16 to_image16(const terrain::Heightmap& map, std::string* note) {
  peers::Image16 img;
  img.width = map.width();
  img.height = map.height();
  img.valid = map.valid;
  const double quantum = map.info.integer_valued() ? map.info.vertical_scale : 0.1;
  double lo = 0, hi = 0;
  bool first = true;
  for (size_t i = 0; i < map.values.size(); ++i) {
    if (!map.valid.empty() && !map.valid[i]) continue;
    const double m = map.values[i] * map.info.vertical_scale + map.info.vertical_offset;
    lo = first ? m : std::min(lo, m);
    hi = first ? m : std::max(hi, m);
    first = false;
  }
  int k = 0;
  while (std::round(hi / (quantum * std::ldexp(1.0, k))) - std::round(lo / (quantum * std::ldexp(1.0, k))) >
         65535)
    ++k;
  img.unit_m = quantum * std::ldexp(1.0, k);
  const double lo_u = std::round(lo / img.unit_m), hi_u = std::round(hi / img.unit_m);
  const double offset = (lo_u >= -32768 && hi_u <= 32767) ? 0.0 : std::floor((lo_u + hi_u) / 2);
  img.samples.resize(map.values.size());
  for (size_t i = 0; i < map.values.size(); ++i) {
    const bool valid = map.valid.empty() || map.valid[i];
    const double m = valid ? map.values[i] * map.info.vertical_scale + map.info.vertical_offset : 0.0;
    img.samples[i] = int16_t(std::clamp(std::round(m / img.unit_m) - offset, -32768.0, 32767.0));
  }
  std::ostringstream os;
  os << "unit " << img.unit_m << " m";
  if (k > 0) os << " (native " << quantum << " m quantum x" << (1 << k) << " to fit 16 bits)";
  if (offset != 0) os << ", offset " << offset << " units to fit int16";
  if (!map.valid.empty()) {
    const auto voids = std::count(map.valid.begin(), map.valid.end(), uint8_t(0));
    if (voids > 0) os << ", " << voids << " voids coded as 0 m and excluded from the errors";
  }
  *note = os.str();
  return img;
}

// Vertical scales the shared data's MANIFEST.md states but the files do not carry.
std::optional<double> known_vertical_scale(const std::string& path) {
  const std::string name = std::filesystem::path(path).filename().string();
  if (name == "pugetsound_ps_height_1k.png") return 0.1;
  return std::nullopt;
}

struct Row {
  std::string file, codec, setting;
  std::string target_kind;  // pyramid rows: "lossless", "rms", "max"; peers: ""
  double target_m = 0;
  double unit_m = 1;
  int64_t width = 0, height = 0;
  peers::Result result;
  double bound = -1;  // declared max error in sample units (peers) or metres / unit_m (pyramid)
  // Pyramid rows only: cold region decodes (fresh cache per window) and the build's thread count.
  double region_seconds = 0, region_cpu_seconds = 0;
  int64_t region_samples = 0;
  int threads = 1;
  std::string error;  // non-empty when the codec failed or broke its bound
};

constexpr const char* kPyramid = "pyramid";

std::string short_name(const std::string& path) { return std::filesystem::path(path).stem().string(); }

double msps(double samples, double seconds) { return seconds > 0 ? samples / seconds / 1e6 : 0.0; }

void write_csv_header(std::ostream& os) {
  os << "file,codec,setting,target_kind,target_m,unit_m,width,height,bytes,bits_per_sample,rms_m,max_abs_m,"
        "p999_abs_m,psnr_db,encode_s,decode_s,encode_cpu_s,decode_cpu_s,encode_msamples_s,decode_msamples_s,"
        "encode_cpu_msamples_s,decode_cpu_msamples_s,region_msamples_s,region_cpu_msamples_s,encode_reps,"
        "decode_reps,threads,declared_bound_m,error\n";
}

void write_csv_row(std::ostream& os, const Row& r) {
  const double n = double(r.width * r.height);
  const peers::Result& x = r.result;
  char buf[800];
  std::snprintf(
      buf, sizeof buf,
      "%zu,%.5f,%.5f,%.4f,%.4f,%.3f,%.6f,%.6f,%.6f,%.6f,%.2f,%.2f,%.2f,%.2f,%.2f,%.2f,%d,%d,%d,%.4g", x.bytes,
      x.bits_per_sample, x.error.rms * r.unit_m, x.error.max_abs * r.unit_m, x.error.p999_abs * r.unit_m,
      x.error.psnr_db, x.encode_seconds, x.decode_seconds, x.encode_cpu_seconds, x.decode_cpu_seconds,
      msps(n, x.encode_seconds), msps(n, x.decode_seconds), msps(n, x.encode_cpu_seconds),
      msps(n, x.decode_cpu_seconds), msps(double(r.region_samples), r.region_seconds),
      msps(double(r.region_samples), r.region_cpu_seconds), x.encode_reps, x.decode_reps, r.threads,
      r.bound < 0 ? -1.0 : r.bound * r.unit_m);
  os << r.file << ',' << r.codec << ",\"" << r.setting << "\"," << r.target_kind << ',' << r.target_m << ','
     << r.unit_m << ',' << r.width << ',' << r.height << ',' << buf << ",\"" << r.error << "\"\n";
}

void write_json(std::ostream& os, const std::vector<Row>& rows) {
  os << "[\n";
  for (size_t i = 0; i < rows.size(); ++i) {
    const Row& r = rows[i];
    const peers::Result& x = r.result;
    const double psnr = std::isfinite(x.error.psnr_db) ? x.error.psnr_db : -1;
    const double n = double(r.width * r.height);
    os << "  {\"file\": " << terrain::json_quote(r.file) << ", \"codec\": " << terrain::json_quote(r.codec)
       << ", \"setting\": " << terrain::json_quote(r.setting) << ", \"unit_m\": " << r.unit_m
       << ", \"width\": " << r.width << ", \"height\": " << r.height << ", \"bytes\": " << x.bytes
       << ", \"bits_per_sample\": " << x.bits_per_sample << ", \"rms_m\": " << x.error.rms * r.unit_m
       << ", \"max_abs_m\": " << x.error.max_abs * r.unit_m
       << ", \"p999_abs_m\": " << x.error.p999_abs * r.unit_m << ", \"psnr_db\": " << psnr
       << ", \"encode_s\": " << x.encode_seconds << ", \"decode_s\": " << x.decode_seconds
       << ", \"encode_cpu_s\": " << x.encode_cpu_seconds << ", \"decode_cpu_s\": " << x.decode_cpu_seconds
       << ", \"region_cpu_msamples_s\": " << msps(double(r.region_samples), r.region_cpu_seconds)
       << ", \"encode_cpu_msamples_s\": " << msps(n, x.encode_cpu_seconds)
       << ", \"error\": " << terrain::json_quote(r.error) << "}" << (i + 1 < rows.size() ? ",\n" : "\n");
  }
  os << "]\n";
}

std::string fmt(const char* format, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}
std::string cell(double bits) { return bits < 0 ? "—" : fmt("%.2f", bits); }

double median(std::vector<double> v) {
  if (v.empty()) return -1;
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

double geomean(const std::vector<double>& v) {
  double s = 0;
  int n = 0;
  for (double x : v)
    if (x > 0) s += std::log(x), ++n;
  return n ? std::exp(s / n) : -1;
}

// The rate/speed figures of one (file, codec) over its sweep.
struct Curve {
  std::vector<peers::RatePoint> by_rms, by_max;
  double lossless = -1;
  std::vector<double> encode_msps, decode_msps, region_msps;  // CPU-time based, one figure per sweep point
  std::vector<double> build_msps, build_cpu_msps;             // pyramid: wall clock / CPU time, end to end
  bool any = false;
};

Curve curve_of(const std::vector<Row>& rows, const std::string& file, const std::string& codec) {
  Curve c;
  // One family per sweep: the pyramid's target kind, or a peer setting label's parameter name
  // ("step=3" and "maxerr=2" of libcodec are two sweeps; "9/7 1.50bps" is openjpeg's 9/7 sweep).
  std::vector<std::string> family_names;
  const auto family_of = [&](const Row& r) {
    const std::string key =
        !r.target_kind.empty() ? r.target_kind : r.setting.substr(0, r.setting.find_first_of("= "));
    auto it = std::find(family_names.begin(), family_names.end(), key);
    if (it == family_names.end()) it = family_names.insert(family_names.end(), key);
    return int(it - family_names.begin());
  };
  for (const Row& r : rows) {
    if (r.file != file || r.codec != codec || !r.error.empty()) continue;
    c.any = true;
    const peers::Result& x = r.result;
    const int family = family_of(r);
    c.by_rms.push_back({x.error.rms * r.unit_m, x.bits_per_sample, family});
    c.by_max.push_back({x.error.max_abs * r.unit_m, x.bits_per_sample, family});
    const double n = double(r.width * r.height);
    if (x.error.max_abs == 0) {
      if (c.lossless < 0 || x.bits_per_sample < c.lossless) c.lossless = x.bits_per_sample;
    }
    if (x.encode_cpu_seconds > 0) c.encode_msps.push_back(msps(n, x.encode_cpu_seconds));
    if (x.decode_cpu_seconds > 0) c.decode_msps.push_back(msps(n, x.decode_cpu_seconds));
    if (r.region_cpu_seconds > 0)
      c.region_msps.push_back(msps(double(r.region_samples), r.region_cpu_seconds));
    if (codec == kPyramid && x.encode_seconds > 0) c.build_msps.push_back(msps(n, x.encode_seconds));
    if (codec == kPyramid && x.encode_cpu_seconds > 0)
      c.build_cpu_msps.push_back(msps(n, x.encode_cpu_seconds));
  }
  return c;
}

std::string speed_range(const std::vector<double>& v) {
  if (v.empty()) return "—";
  const auto [lo, hi] = std::minmax_element(v.begin(), v.end());
  if (*hi < 1.05 * *lo) return fmt("%.3g", *lo);
  return fmt("%.3g", *lo) + "–" + fmt("%.3g", *hi);
}

const double kRmsTargets[] = {0.5, 1, 2, 4};
const double kMaxTargets[] = {1, 2, 5};

// Markdown summary: one row per (file, codec) with interpolated rates and the speed range.
void write_summary(std::ostream& os, const std::vector<Row>& rows, const std::vector<std::string>& file_order,
                   const std::vector<std::string>& codec_order) {
  os << "| DEM | codec | lossless | @rms 0.5 m | @rms 1 m | @rms 2 m | @rms 4 m | @max 1 m | @max 2 m | @max "
        "5 m "
        "| encode Ms/s (CPU) | decode Ms/s (CPU) |\n";
  os << "|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const std::string& file : file_order) {
    for (const std::string& codec : codec_order) {
      const Curve c = curve_of(rows, file, codec);
      if (!c.any) continue;
      os << "| " << file << " | " << codec << " | " << cell(c.lossless);
      for (double t : kRmsTargets) os << " | " << cell(peers::bits_at_error(c.by_rms, t));
      for (double t : kMaxTargets) os << " | " << cell(peers::bits_at_error(c.by_max, t));
      os << " | " << speed_range(c.encode_msps) << " | " << speed_range(c.decode_msps) << " |\n";
    }
  }
  os << "\nBits/sample; '—' = the sweep does not reach that error. Ms/s = million samples per second of "
        "process CPU time, one thread, best of N repetitions, range over the sweep (wall-clock figures: "
        "CSV). The pyramid row's encode figure is the whole build (CPU time of all build threads).\n";
}

bool is_ours(const std::string& codec) { return codec.rfind("libcodec", 0) == 0; }  // libcodec, libcodec-t256
bool is_external_peer(const std::string& codec) { return codec != kPyramid && !is_ours(codec); }

// Issue 4's goals for libcodec alone: bits against JPEG XR at equal rms, for each tile size run, and
// encode/decode speed at the step-sweep point nearest 2 bits/sample.
void write_codec_goals(std::ostream& os, const std::vector<Row>& rows,
                       const std::vector<std::string>& file_order,
                       const std::vector<std::string>& codec_order) {
  std::vector<std::string> ours;
  for (const std::string& c : codec_order)
    if (is_ours(c)) ours.push_back(c);
  if (ours.empty() || std::find(codec_order.begin(), codec_order.end(), "jpegxr") == codec_order.end())
    return;
  os << "## libcodec against JPEG XR (issue 4)\n\n"
     << "Goals: at equal rms, fewer bits than JPEG XR (jxrlib) on every tile; decode ≥ 300 and encode ≥ 60 "
        "Msamples/s per core at about 2 bits/sample. Cell: libcodec bits/sample ÷ JPEG XR bits/sample at "
        "that rms (✓ when < 1), one per tile size run (";
  for (size_t i = 0; i < ours.size(); ++i) os << (i ? " / " : "") << "`" << ours[i] << "`";
  os << "). Speed: each run's step-sweep point nearest 2 bits/sample, CPU time, one thread; JPEG XR's "
        "decode speed is the median over its sweep.\n\n"
     << "| DEM | rms 0.5 m | rms 1 m | rms 2 m | rms 4 m | bits/sample (step) | encode Ms/s | decode Ms/s | "
        "JPEG XR decode Ms/s |\n|---|---|---|---|---|---|---|---|---|\n";
  std::map<std::string, int> wins, cells;
  for (const std::string& file : file_order) {
    const Curve jxr = curve_of(rows, file, "jpegxr");
    if (!jxr.any) continue;
    std::vector<Curve> mine_curves;
    for (const std::string& c : ours) mine_curves.push_back(curve_of(rows, file, c));
    os << "| " << file;
    for (double t : kRmsTargets) {
      const double theirs = peers::bits_at_error(jxr.by_rms, t);
      os << " |";
      for (size_t i = 0; i < ours.size(); ++i) {
        const double mine = peers::bits_at_error(mine_curves[i].by_rms, t);
        os << (i ? " /" : "") << " ";
        if (mine < 0 || theirs <= 0) {
          os << "—";
          continue;
        }
        const double r = mine / theirs;
        ++cells[ours[i]];
        if (r < 1) ++wins[ours[i]];
        os << fmt("%.3f", r) << (r < 1 ? " ✓" : " ✗");
      }
    }
    std::string near_bits, near_encode, near_decode;
    for (size_t i = 0; i < ours.size(); ++i) {
      const Row* near = nullptr;
      for (const Row& r : rows)
        if (r.file == file && r.codec == ours[i] && r.error.empty() && r.setting.rfind("step=", 0) == 0 &&
            r.result.error.max_abs > 0 &&
            (!near || std::abs(r.result.bits_per_sample - 2) < std::abs(near->result.bits_per_sample - 2)))
          near = &r;
      const std::string sep = i ? " / " : "";
      if (!near) {
        near_bits += sep + "—", near_encode += sep + "—", near_decode += sep + "—";
        continue;
      }
      const double n = double(near->width * near->height);
      near_bits += sep + fmt("%.2f", near->result.bits_per_sample) + " (" + near->setting + ")";
      near_encode += sep + fmt("%.1f", msps(n, near->result.encode_cpu_seconds));
      near_decode += sep + fmt("%.1f", msps(n, near->result.decode_cpu_seconds));
    }
    os << " | " << near_bits << " | " << near_encode << " | " << near_decode;
    os << " | " << fmt("%.1f", median(jxr.decode_msps)) << " |\n";
  }
  os << "\nCells below 1 (fewer bits than JPEG XR):";
  for (const std::string& c : ours) os << " `" << c << "` " << wins[c] << " of " << cells[c] << ";";
  os << "\n\n";
}

// An error target of the report's columns.
struct Target {
  enum Kind { Lossless, Rms, Max } kind;
  double metres;
  std::string heading() const {
    return kind == Lossless ? "lossless" : (kind == Rms ? "rms " : "max ") + fmt("%g", metres) + " m";
  }
};

// Lossless, then the summary's rms and max-error targets.
std::vector<Target> summary_targets() {
  std::vector<Target> t{{Target::Lossless, 0}};
  for (double m : kRmsTargets) t.push_back({Target::Rms, m});
  for (double m : kMaxTargets) t.push_back({Target::Max, m});
  return t;
}

// Bits/sample of a codec at target t (-1 when its sweeps do not reach it).
double bits_at(const Curve& c, const Target& t) {
  if (t.kind == Target::Lossless) return c.lossless;
  return peers::bits_at_error(t.kind == Target::Rms ? c.by_rms : c.by_max, t.metres);
}

// The external peers' curves on one DEM.
struct PeerField {
  std::vector<Curve> curves;
  std::vector<std::string> names;
  // The cheapest peer at t: its bits/sample (-1 when no peer reaches t) and its name.
  std::pair<double, std::string> best(const Target& t) const {
    std::pair<double, std::string> out{-1.0, ""};
    for (size_t i = 0; i < curves.size(); ++i) {
      const double b = bits_at(curves[i], t);
      if (b > 0 && (out.first < 0 || b < out.first)) out = {b, names[i]};
    }
    return out;
  }
};

PeerField external_peers(const std::vector<Row>& rows, const std::string& file,
                         const std::vector<std::string>& codec_order) {
  PeerField field;
  for (const std::string& codec : codec_order)
    if (is_external_peer(codec)) {
      Curve c = curve_of(rows, file, codec);
      if (c.any) field.curves.push_back(std::move(c)), field.names.push_back(codec);
    }
  return field;
}

// Median full-decode speed (Ms per CPU-second) of a codec's settings that declare losslessness
// (bound 0), or of its other settings; -1 when there are none.
double median_decode_msps(const std::vector<Row>& rows, const std::string& file, const std::string& codec,
                          bool lossless) {
  std::vector<double> v;
  for (const Row& r : rows)
    if (r.file == file && r.codec == codec && r.error.empty() && (r.bound == 0) == lossless &&
        r.result.decode_cpu_seconds > 0)
      v.push_back(msps(double(r.width * r.height), r.result.decode_cpu_seconds));
  return median(v);
}

constexpr const char* kHtj2k = "htj2k";
constexpr const char* kJpegXl = "jpegxl";

// Pyramid coding v3: the whole pyramid against HTJ2K (the fast transform anchor) and against the
// best peer at the targets, with the decode speeds side by side.
void write_htj2k_comparison(std::ostream& os, const std::vector<Row>& rows,
                            const std::vector<std::string>& file_order,
                            const std::vector<std::string>& codec_order) {
  if (std::find(codec_order.begin(), codec_order.end(), kHtj2k) == codec_order.end() ||
      std::find(codec_order.begin(), codec_order.end(), kPyramid) == codec_order.end())
    return;
  const std::vector<Target> targets{
      {Target::Lossless, 0}, {Target::Rms, 1}, {Target::Rms, 2}, {Target::Max, 2}, {Target::Max, 5}};
  os << "## Pyramid against HTJ2K and the best peer (pyramid coding v3)\n\n"
     << "Cell: whole pyramid bits/sample ÷ HTJ2K (OpenJPH) bits/sample at that error / ÷ the best peer's "
        "(which peer); below 1 the pyramid is smaller. HTJ2K's lossless is its 5/3 reversible mode, its "
        "lossy points the 9/7 quantisation-step sweep, judged by measured rms and max |error|. Decode: "
        "million finest samples per CPU-second, one thread, median over the lossy settings / the lossless "
        "one (pyramid: the region decoder reconstructing the finest level whole).\n\n"
     << "| DEM";
  for (const Target& t : targets) os << " | " << t.heading();
  os << " | pyramid decode Ms/s | HTJ2K decode Ms/s (9/7 / 5/3) | JPEG XL decode Ms/s |\n|---";
  for (size_t i = 0; i < targets.size() + 3; ++i) os << "|---";
  os << "|\n";
  const auto ratio_cell = [](double r) { return r < 0 ? std::string("—") : fmt("%.2f", r); };
  const auto speed_cell = [](double v) { return v < 0 ? std::string("—") : fmt("%.1f", v); };
  std::vector<std::vector<double>> by_htj2k(targets.size()), by_best(targets.size());
  for (const std::string& file : file_order) {
    const Curve ours = curve_of(rows, file, kPyramid), htj2k = curve_of(rows, file, kHtj2k);
    if (!ours.any) continue;
    const PeerField field = external_peers(rows, file, codec_order);
    os << "| " << file;
    for (size_t i = 0; i < targets.size(); ++i) {
      const double mine = bits_at(ours, targets[i]), theirs = bits_at(htj2k, targets[i]);
      const auto [best, best_name] = field.best(targets[i]);
      const double r_htj2k = mine > 0 && theirs > 0 ? mine / theirs : -1;
      const double r_best = mine > 0 && best > 0 ? mine / best : -1;
      by_htj2k[i].push_back(r_htj2k);
      by_best[i].push_back(r_best);
      os << " | " << ratio_cell(r_htj2k) << " / " << ratio_cell(r_best)
         << (r_best < 0 ? "" : " " + best_name);
    }
    os << " | " << speed_cell(median_decode_msps(rows, file, kPyramid, false)) << " / "
       << speed_cell(median_decode_msps(rows, file, kPyramid, true)) << " | "
       << speed_cell(median_decode_msps(rows, file, kHtj2k, false)) << " / "
       << speed_cell(median_decode_msps(rows, file, kHtj2k, true)) << " | "
       << speed_cell(median_decode_msps(rows, file, kJpegXl, true)) << " |\n";
  }
  os << "| **geometric mean**";
  for (size_t i = 0; i < targets.size(); ++i)
    os << " | " << cell(geomean(by_htj2k[i])) << " / " << cell(geomean(by_best[i]));
  os << " | | | |\n\n";
}

// The generated BENCHMARKS.md: the pyramid against the best peer at each error point, the issue's
// goals, lossless rates and speeds. Everything comes from `rows`; nothing is typed in by hand.
void write_report(std::ostream& os, const std::vector<Row>& rows, const std::vector<std::string>& file_order,
                  const std::vector<std::string>& codec_order, const Options& opt,
                  const std::vector<std::string>& peer_configs) {
  os << "# Benchmarks: run time against error\n\n"
     << "This file is generated by `scripts/bench` (program `tools/terrain-bench.cpp`); do not edit it by "
        "hand.\n\n";
  if (!opt.provenance.empty()) os << opt.provenance << "\n\n";
  os << "Reproduce:\n\n```\n" << (opt.command.empty() ? "scripts/bench" : opt.command) << "\n```\n\n";
  os << "## Method\n\n"
     << "* **pyramid** = this project end to end: `build_pyramid_file` (what `pyramid-build` runs: streamed "
        "read, wavelet D filter (the default), closed-loop residuals, libcodec, container) at each `--rms` / "
        "`--max-error` "
        "target and `--lossless`, "
     << (opt.threads ? std::to_string(opt.threads) + " build thread(s)"
                     : std::string("all cores for the build"))
     << "; then `RegionDecoder` reconstructs the finest level (one thread). "
        "**bits/sample = whole pyramid file bytes × 8 / finest-level samples** (all levels, container, "
        "band tables, mask and metadata included). Errors are measured on the finest level against the "
        "input in metres, over valid samples.\n"
     << "* **Peers**: each codec on the same grid in int16 sample units, one thread, codec time only (no "
        "file I/O), best of N repetitions. `libcodec` is our residual coder alone on the single finest "
        "level (no pyramid); it is not counted as a peer.\n"
     << "* Bits/sample at a target error is interpolated on the lower envelope of (error, bits/sample) "
        "points of each of a codec's sweeps (one per mode: libcodec's step and max-error sweeps, the "
        "pyramid's "
        "rms and max-error targets), linear in log(bits) against log(error), and the cheapest sweep counts; "
        "a target below a sweep's smallest non-zero error takes the codec's lossless rate when it has one "
        "(lossless meets every target); '—' = no sweep reaches that error. The rms columns use the measured "
        "rms of every sweep, the max-error columns the measured max |error|.\n"
     << "* Speeds are million finest samples per second of process CPU time (the machine is shared); "
        "build speed is the whole `build_pyramid_file` call, file read to file renamed (rms targets include "
        "the step calibration), as wall clock and per CPU-second of all build threads. Region decode = "
        "256×256 windows of the "
        "finest level at scattered positions, each with an empty cache (cold).\n\n";

  // Table 1: pyramid vs best peer.
  os << "## Bits/sample of the pyramid and ratio to the best peer\n\n"
     << "Cell: pyramid bits/sample (ratio to the best peer at that error, and which peer). Ratio < 1 means "
        "the pyramid is smaller.\n\n";
  os << "| DEM | lossless | rms 0.5 m | rms 1 m | rms 2 m | rms 4 m | max 1 m | max 2 m | max 5 m |\n"
     << "|---|---|---|---|---|---|---|---|---|\n";
  const std::vector<Target> targets = summary_targets();
  std::vector<std::vector<double>> ratios(targets.size());  // per column, one ratio per DEM
  for (const std::string& file : file_order) {
    const Curve ours = curve_of(rows, file, kPyramid);
    if (!ours.any) continue;
    const PeerField field = external_peers(rows, file, codec_order);
    os << "| " << file;
    for (size_t i = 0; i < targets.size(); ++i) {
      const double mine = bits_at(ours, targets[i]);
      const auto [best, best_name] = field.best(targets[i]);
      os << " | ";
      if (mine < 0) {
        os << "—";
      } else if (best < 0) {
        os << cell(mine);
      } else {
        ratios[i].push_back(mine / best);
        os << cell(mine) << " (" << fmt("%.2f", mine / best) << " " << best_name << ")";
      }
    }
    os << " |\n";
  }
  os << "| **geometric mean of the ratios**";
  for (const std::vector<double>& r : ratios) os << " | " << cell(geomean(r));
  os << " |\n\n";

  // Table 2: the goals.
  os << "## Goals (issue 7)\n\n"
     << "Goals: bits/sample ≤ 0.9 × JPEG 2000 (openjpeg) at rms 1 and 2 m; ≤ 0.9 × JPEG-LS (charls) at max "
        "error 2 and 5 m; full decode ≥ 2 × OpenJPEG's Ms/s; build ≥ 30 Ms/s (scale run, reported "
        "separately). Decode speeds: median over the lossy sweep points.\n\n"
     << "| DEM | ÷J2K @rms 1 | ÷J2K @rms 2 | ÷JPEG-LS @max 2 | ÷JPEG-LS @max 5 | pyramid full decode Ms/s "
        "| region decode Ms/s | OpenJPEG decode Ms/s | decode ratio | build Ms/s (wall) | build Ms/CPU-s |\n"
     << "|---|---|---|---|---|---|---|---|---|---|---|\n";
  std::vector<double> g[5];
  for (const std::string& file : file_order) {
    const Curve ours = curve_of(rows, file, kPyramid);
    if (!ours.any) continue;
    const Curve j2k = curve_of(rows, file, "openjpeg"), jls = curve_of(rows, file, "charls");
    auto ratio = [](double a, double b) { return a > 0 && b > 0 ? a / b : -1.0; };
    const double r[4] = {ratio(peers::bits_at_error(ours.by_rms, 1), peers::bits_at_error(j2k.by_rms, 1)),
                         ratio(peers::bits_at_error(ours.by_rms, 2), peers::bits_at_error(j2k.by_rms, 2)),
                         ratio(peers::bits_at_error(ours.by_max, 2), peers::bits_at_error(jls.by_max, 2)),
                         ratio(peers::bits_at_error(ours.by_max, 5), peers::bits_at_error(jls.by_max, 5))};
    os << "| " << file;
    for (int i = 0; i < 4; ++i) {
      os << " | " << (r[i] < 0 ? "—" : fmt("%.2f", r[i]) + (r[i] <= 0.9 ? " ✓" : " ✗"));
      g[i].push_back(r[i]);
    }
    const double dec = median(ours.decode_msps), reg = median(ours.region_msps), oj = median(j2k.decode_msps);
    const double dr = ratio(dec, oj);
    g[4].push_back(dr);
    os << " | " << (dec < 0 ? "—" : fmt("%.1f", dec)) << " | " << (reg < 0 ? "—" : fmt("%.1f", reg)) << " | "
       << (oj < 0 ? "—" : fmt("%.1f", oj)) << " | "
       << (dr < 0 ? "—" : fmt("%.2f", dr) + (dr >= 2 ? " ✓" : " ✗")) << " | " << speed_range(ours.build_msps)
       << " | " << speed_range(ours.build_cpu_msps) << " |\n";
  }
  os << "| **geometric mean** | " << cell(geomean(g[0])) << " | " << cell(geomean(g[1])) << " | "
     << cell(geomean(g[2])) << " | " << cell(geomean(g[3])) << " | | | | " << cell(geomean(g[4]))
     << " | | |\n\n";

  write_htj2k_comparison(os, rows, file_order, codec_order);
  write_codec_goals(os, rows, file_order, codec_order);

  // Table 3: every codec, every point.
  os << "## All codecs\n\n";
  write_summary(os, rows, file_order, codec_order);
  os << "\n## Plots\n\n"
     << "![bits/sample against rms](" << opt.plot_dir << "/rms.png)\n\n![bits/sample against max error]("
     << opt.plot_dir << "/max.png)\n\n![decode speed against bits/sample](" << opt.plot_dir
     << "/speed.png)\n\n"
     << "Data: [" << opt.plot_dir << "/bench.csv](" << opt.plot_dir << "/bench.csv).\n\n";
  os << "## Codec configurations\n\n";
  for (const std::string& c : peer_configs) os << "* " << c << "\n";
  os << "* pyramid: `build_pyramid_file` defaults (automatic levels, default tile size), targets as in "
        "the CSV's `setting` column.\n";
}

std::vector<std::unique_ptr<peers::Peer>> select_peers(const std::vector<std::string>& names) {
  auto all = peers::all_peers();
  if (names.empty()) return all;
  std::vector<std::unique_ptr<peers::Peer>> chosen;
  for (const std::string& name : names) {
    if (name == "none") continue;
    auto it = std::find_if(all.begin(), all.end(), [&](const auto& p) { return p && p->name() == name; });
    if (it == all.end()) throw cli::UsageError("unknown codec '" + name + "' (see --list)");
    chosen.push_back(std::move(*it));
  }
  return chosen;
}

// Smooth relief, a negative basin and deterministic noise, so transforms, predictors and signed
// handling are all exercised.
peers::Image16 synthetic_image() {
  peers::Image16 img;
  img.width = 97;
  img.height = 61;
  img.samples.resize(size_t(img.width * img.height));
  uint32_t state = 12345;
  for (int64_t y = 0; y < img.height; ++y)
    for (int64_t x = 0; x < img.width; ++x) {
      state = state * 1664525u + 1013904223u;
      const double noise = double(state >> 24) / 255.0 * 40.0 - 20.0;
      double h = 1200 + 800 * std::sin(double(x) / 9.0) * std::cos(double(y) / 7.0) + 6.0 * double(x) + noise;
      if ((x - 20) * (x - 20) + (y - 40) * (y - 40) < 100) h = -300 + noise;
      img.samples[size_t(y * img.width + x)] = int16_t(std::lround(h));
    }
  return img;
}

int run_self_test(std::vector<std::unique_ptr<peers::Peer>>& peer_list) {
  const peers::Image16 img = synthetic_image();
  const auto [lo, hi] = std::minmax_element(img.samples.begin(), img.samples.end());
  const double range = double(*hi) - double(*lo);
  int failures = 0;
  for (auto& peer : peer_list) {
    bool has_lossless = false;
    for (const peers::Setting& s : peer->sweep(false, 1.0)) {
      std::string verdict = "ok";
      try {
        const peers::Result r = peers::measure(*peer, img, s, 0, 1);
        if (r.bytes == 0)
          verdict = "FAIL: empty stream";
        else if (s.max_error_bound >= 0 && r.error.max_abs > s.max_error_bound)
          verdict = "FAIL: max error above bound";
        else if (s.max_error_bound < 0 && !(r.error.rms <= 0.25 * range))
          verdict = "FAIL: rms above a quarter of the range";
        if (s.max_error_bound == 0 && r.error.max_abs == 0) has_lossless = true;
        std::printf("%-9s %-20s bytes %6zu  max|err| %7.1f  rms %7.2f  bound %5s  %s\n", peer->name().c_str(),
                    s.label.c_str(), r.bytes, r.error.max_abs, r.error.rms,
                    s.max_error_bound < 0 ? "none" : std::to_string(int(s.max_error_bound)).c_str(),
                    verdict.c_str());
      } catch (const std::exception& e) {
        verdict = std::string("FAIL: ") + e.what();
        std::printf("%-9s %-20s %s\n", peer->name().c_str(), s.label.c_str(), verdict.c_str());
      }
      if (verdict != "ok") ++failures;
    }
    if (peer->lossless_capable() && !has_lossless) {
      std::printf("%-9s FAIL: claims lossless capability but no setting round-tripped exactly\n",
                  peer->name().c_str());
      ++failures;
    }
  }
  std::printf("self-test: %s (%d failure%s)\n", failures ? "FAILED" : "passed", failures,
              failures == 1 ? "" : "s");
  return failures ? cli::kExitInternal : cli::kExitOk;
}

// ---------------------------------------------------------------------------------------------
// The pyramid end to end.

struct PyramidTarget {
  terrain::container::ErrorMode target;
  double metres;
};

std::vector<PyramidTarget> pyramid_sweep(bool quick) {
  using terrain::container::ErrorMode;
  std::vector<PyramidTarget> t{{ErrorMode::Lossless, 0}};
  const std::vector<double> rms =
      quick ? std::vector<double>{0.5, 1, 2, 4} : std::vector<double>{0.25, 0.5, 1, 1.4, 2, 2.8, 4, 8};
  const std::vector<double> max =
      quick ? std::vector<double>{1, 2, 5} : std::vector<double>{0.5, 1, 2, 3, 5, 8, 16};
  for (double m : rms) t.push_back({ErrorMode::Rms, m});
  for (double m : max) t.push_back({ErrorMode::MaxError, m});
  return t;
}

struct RegionTiming {
  double seconds = 0, cpu_seconds = 0;
  int64_t samples = 0;
  bool mismatch = false;
};

// Cold region decodes: `windows` 256x256 windows (clipped to the level) at scattered, deterministic
// positions, each decoded with an empty cache. When `whole` (the level decoded whole) is given, each
// window must equal the same samples of it.
RegionTiming time_cold_windows(terrain::runtime::RegionDecoder& decoder, int level, terrain::GridSize size,
                               int windows, const int32_t* whole) {
  RegionTiming t;
  const int64_t side_x = std::min<int64_t>(256, size.width), side_y = std::min<int64_t>(256, size.height);
  std::vector<int32_t> window(size_t(side_x * side_y));
  uint64_t state = 0x9E3779B97F4A7C15ull;
  for (int i = 0; i < windows; ++i) {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    const int64_t x0 = int64_t((state >> 33) % uint64_t(size.width - side_x + 1));
    const int64_t y0 = int64_t((state >> 13) % uint64_t(size.height - side_y + 1));
    decoder.clear_cache();
    const double c0 = peers::process_cpu_seconds();
    const auto t0 = std::chrono::steady_clock::now();
    decoder.decode_units(level, {x0, y0, side_x, side_y}, window.data(), side_x);
    t.seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    t.cpu_seconds += peers::process_cpu_seconds() - c0;
    t.samples += side_x * side_y;
    for (int64_t y = 0; whole && y < side_y; ++y)
      if (std::memcmp(&window[size_t(y * side_x)], &whole[size_t((y0 + y) * size.width + x0)],
                      size_t(side_x) * 4) != 0)
        t.mismatch = true;
  }
  return t;
}

// Builds one pyramid file at `target`, decodes its finest level whole (timed, best of N, cold cache
// each time) and in cold 256x256 windows, and measures the error against `reference` (metres).
Row measure_pyramid(const std::string& path, const terrain::ReadOptions& read_options,
                    const std::string& file, const terrain::Heightmap& map,
                    const std::vector<double>& reference, const PyramidTarget& target, const Options& opt) {
  using namespace terrain::runtime;
  using namespace terrain::container;
  using namespace terrain::build;
  Row row;
  row.file = file;
  row.codec = kPyramid;
  row.width = map.width();
  row.height = map.height();
  row.unit_m = 1;  // pyramid rows are measured in metres directly
  row.target_m = target.metres;
  row.target_kind = target.target == ErrorMode::Lossless ? "lossless"
                    : target.target == ErrorMode::Rms    ? "rms"
                                                         : "max";
  row.setting = target.target == ErrorMode::Lossless
                    ? "lossless"
                    : row.target_kind + "=" + fmt("%g", target.metres) + " m";
  row.bound = target.target == ErrorMode::Lossless   ? 0
              : target.target == ErrorMode::MaxError ? target.metres
                                                     : -1;
  row.threads = opt.threads ? opt.threads : int(std::max(1L, sysconf(_SC_NPROCESSORS_ONLN)));
  const std::string output =
      opt.work_dir + "/terrain-bench-" + std::to_string(getpid()) + "-" + file + ".pyr";
  struct Remove {
    std::string p;
    ~Remove() {
      std::error_code ec;
      std::filesystem::remove(p, ec);
    }
  } remove_output{output};

  BuildFileOptions bo;
  bo.mode = target.target;
  bo.target_metres = target.metres;
  bo.threads = opt.threads;
  peers::Result& x = row.result;
  BuildFileResult built;
  try {
    const double c0 = peers::process_cpu_seconds();
    const auto t0 = std::chrono::steady_clock::now();
    built = build_pyramid_file(path, read_options, output, bo);
    x.encode_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    x.encode_cpu_seconds = peers::process_cpu_seconds() - c0;
    x.encode_reps = 1;
  } catch (const std::invalid_argument& e) {
    row.error = std::string("n/a: ") + e.what();  // a target the input cannot honour (e.g. below its quantum)
    return row;
  }
  row.setting += " (step " + fmt("%g", built.step_units) + " u, " +
                 std::to_string(built.build.levels.size()) + " levels)";
  x.bytes = size_t(std::filesystem::file_size(output));
  const double n = double(map.width() * map.height());
  x.bits_per_sample = 8.0 * double(x.bytes) / n;

  auto pyramid = PyramidFile::open(output);
  RegionDecoder decoder(pyramid);
  const int finest = pyramid->level_count() - 1;
  const terrain::Rect whole{0, 0, map.width(), map.height()};
  std::vector<int32_t> units(size_t(map.width() * map.height()));
  x.decode_seconds = peers::best_time(
      [&] {
        decoder.clear_cache();
        decoder.decode_units(finest, whole, units.data(), map.width());
      },
      opt.min_time, 5, &x.decode_reps, &x.decode_cpu_seconds);
  std::vector<double> decoded(units.size());
  const double scale = decoder.metres_per_unit(), offset = decoder.metres_offset();
  for (size_t i = 0; i < units.size(); ++i) decoded[i] = double(units[i]) * scale + offset;
  x.error = terrain::error_stats(reference.data(), decoded.data(),
                                 map.valid.empty() ? nullptr : map.valid.data(), units.size());
  if (row.bound >= 0 && x.error.max_abs > row.bound * (1 + 1e-9))
    row.error = "max error " + fmt("%g", x.error.max_abs) + " m exceeds the requested bound " +
                fmt("%g", row.bound) + " m";

  const RegionTiming t =
      time_cold_windows(decoder, finest, {map.width(), map.height()}, opt.quick ? 8 : 16, units.data());
  row.region_seconds = t.seconds;
  row.region_cpu_seconds = t.cpu_seconds;
  row.region_samples = t.samples;
  if (t.mismatch) row.error = "region decode differs from the whole-level decode";
  return row;
}

// Writes `text` to path through a temporary name.
bool write_file_atomically(const std::string& path, const std::string& text) {
  const std::string tmp = path + ".tmp." + std::to_string(getpid());
  {
    std::ofstream f(tmp);
    f << text;
    f.close();
    if (!f) return false;
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  return !ec;
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  std::vector<std::unique_ptr<peers::Peer>> peer_list;
  try {
    if (auto status = parse_args(argc, argv, opt)) return *status;
    peer_list = select_peers(opt.peer_names);
  } catch (const cli::UsageError& e) {
    std::fprintf(stderr, "terrain-bench: %s\nTry 'terrain-bench --help'.\n", e.what());
    return cli::kExitUsage;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "terrain-bench: %s\n", e.what());
    return cli::kExitInternal;
  }

  if (opt.list) {
    for (const auto& p : peer_list) std::printf("%s: %s\n", p->name().c_str(), p->configuration().c_str());
    return cli::kExitOk;
  }
  if (opt.self_test) return run_self_test(peer_list);
  if (!opt.region_speed.empty()) {
    try {
      auto file = terrain::container::PyramidFile::open(opt.region_speed);
      terrain::runtime::RegionDecoder decoder(file);
      const int finest = file->level_count() - 1;
      const RegionTiming t = time_cold_windows(decoder, finest, file->level_size(finest), 64, nullptr);
      std::printf(
          "%s: %d levels, finest %lldx%lld; 64 cold 256x256 windows: %.1f Msamples/s wall, %.1f Msamples/s "
          "CPU\n",
          opt.region_speed.c_str(), file->level_count(), (long long)file->level_size(finest).width,
          (long long)file->level_size(finest).height, msps(double(t.samples), t.seconds),
          msps(double(t.samples), t.cpu_seconds));
      return cli::kExitOk;
    } catch (const terrain::Error& e) {
      std::fprintf(stderr, "terrain-bench: %s\n", e.what());
      return cli::exit_status(e.code());
    }
  }

  if (opt.files.empty()) opt.files = default_files();
  if (opt.files.empty()) {
    std::fprintf(stderr, "terrain-bench: no input files given and no shared data directory found\n");
    return kExitNotFound;
  }

  std::ofstream csv;
  const std::string csv_tmp = opt.csv_path + ".tmp." + std::to_string(getpid());
  if (!opt.csv_path.empty()) {
    csv.open(csv_tmp);
    if (!csv) {
      std::fprintf(stderr, "terrain-bench: cannot write %s\n", csv_tmp.c_str());
      return kExitWriteFailed;
    }
    write_csv_header(csv);
  }

  std::vector<Row> rows;
  std::vector<std::string> file_order, codec_order, peer_configs;
  if (opt.pyramid) codec_order.push_back(kPyramid);
  for (const auto& p : peer_list) {
    codec_order.push_back(p->name());
    peer_configs.push_back(p->name() + ": " + p->configuration());
  }
  bool codec_failed = false;
  auto add_row = [&](Row&& row) {
    if (!row.error.empty() && row.error.rfind("n/a:", 0) != 0) {
      codec_failed = true;
      std::fprintf(stderr, "terrain-bench: %s %s %s: %s\n", row.file.c_str(), row.codec.c_str(),
                   row.setting.c_str(), row.error.c_str());
    }
    if (csv.is_open()) {
      write_csv_row(csv, row);
      csv.flush();
    }
    rows.push_back(std::move(row));
  };
  // One line per measured setting on stderr: the pyramid's always (they are slow), the peers' with -v.
  // Peer rows are in sample units, pyramid rows in metres (unit_m 1).
  auto print_progress = [](const Row& row) {
    std::fprintf(stderr, "  %s %-40s %s\n", row.codec.c_str(), row.setting.c_str(),
                 row.error.empty() ? (fmt("%.3f bits/sample", row.result.bits_per_sample) +
                                      fmt(", rms %.3f m", row.result.error.rms * row.unit_m) +
                                      fmt(", max %.3f m", row.result.error.max_abs * row.unit_m))
                                         .c_str()
                                   : row.error.c_str());
  };
  for (const std::string& path : opt.files) {
    terrain::Heightmap map;
    terrain::ReadOptions read_options;
    try {
      read_options.vertical_scale = opt.vertical_scale ? opt.vertical_scale : known_vertical_scale(path);
      map = terrain::read_heightmap(path, read_options);
    } catch (const terrain::Error& e) {
      std::fprintf(stderr, "terrain-bench: %s\n", e.what());
      return cli::exit_status(e.code());
    } catch (const std::exception& e) {
      std::fprintf(stderr, "terrain-bench: %s: %s\n", path.c_str(), e.what());
      return kExitNotFound;
    }
    std::string note;
    const peers::Image16 img = to_image16(map, &note);
    const std::string file = short_name(path);
    file_order.push_back(file);
    if (!opt.common.quiet)
      std::fprintf(stderr, "%s: %lldx%lld, %s\n", file.c_str(), (long long)img.width, (long long)img.height,
                   note.c_str());
    if (opt.pyramid) {
      std::vector<double> reference(map.values.size());
      for (int64_t y = 0; y < map.height(); ++y)
        for (int64_t x = 0; x < map.width(); ++x) reference[size_t(y * map.width() + x)] = map.metres(x, y);
      for (const PyramidTarget& t : pyramid_sweep(opt.quick)) {
        try {
          add_row(measure_pyramid(path, read_options, file, map, reference, t, opt));
        } catch (const std::exception& e) {
          Row row{file,
                  kPyramid,
                  "target " + fmt("%g", t.metres),
                  "",
                  t.metres,
                  1,
                  map.width(),
                  map.height(),
                  {},
                  -1,
                  0,
                  0,
                  0,
                  1,
                  e.what()};
          add_row(std::move(row));
        }
        if (!opt.common.quiet) print_progress(rows.back());
      }
    }
    for (auto& peer : peer_list) {
      for (const peers::Setting& s : peer->sweep(opt.quick, img.unit_m)) {
        Row row{file, peer->name(),      s.label, "", 0, img.unit_m, img.width, img.height,
                {},   s.max_error_bound, 0,       0,  0, 1,          {}};
        try {
          row.result = peers::measure(*peer, img, s, opt.min_time, 50);
          row.result.decoded.clear();
          row.result.decoded.shrink_to_fit();
          if (s.max_error_bound >= 0 && row.result.error.max_abs > s.max_error_bound)
            row.error = "max error exceeds the declared bound";
        } catch (const std::exception& e) {
          row.error = e.what();
        }
        add_row(std::move(row));
        if (opt.common.verbose) print_progress(rows.back());
      }
    }
  }
  if (csv.is_open()) {
    csv.close();
    std::error_code ec;
    if (!csv || (std::filesystem::rename(csv_tmp, opt.csv_path, ec), ec)) {
      std::fprintf(stderr, "terrain-bench: cannot write %s\n", opt.csv_path.c_str());
      return kExitWriteFailed;
    }
  }
  if (!opt.markdown_path.empty()) {
    std::ostringstream md;
    write_report(md, rows, file_order, codec_order, opt, peer_configs);
    if (!write_file_atomically(opt.markdown_path, md.str())) {
      std::fprintf(stderr, "terrain-bench: cannot write %s\n", opt.markdown_path.c_str());
      return kExitWriteFailed;
    }
  }
  if (opt.common.json)
    write_json(std::cout, rows);
  else
    write_summary(std::cout, rows, file_order, codec_order);
  std::cout.flush();
  return codec_failed ? cli::kExitInternal : cli::kExitOk;
}
