// codec-bench: rate/error/speed comparison of our codec and the peer codecs on DEMs.
//
// Every input grid is converted to int16 sample units (the file's own integers for SRTM; the native
// quantum minus a mid-range offset for 16-bit data such as Puget Sound's 0.1 m units), coded by every
// setting of every peer, and judged against that int16 grid. Errors are reported in metres.
#include <peers.h>
#include <pyramid/heightmap.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

namespace {

constexpr int kExitOk = 0, kExitUsage = 1, kExitNotFound = 2, kExitWriteFailed = 9, kExitInternal = 70;

const char* const kUsage =
    "usage: codec-bench [options] [FILE...]\n"
    "Codes each height grid with our codec and the peer codecs (OpenJPEG JPEG 2000, jxrlib JPEG XR,\n"
    "CharLS JPEG-LS, LERC, ZFP, zstd) over each codec's parameter sweep, one thread, codec time only.\n"
    "Writes a markdown summary (bits/sample at rms 0.5/1/2/4 m and max error 1/2/5 m, log-log\n"
    "interpolated between sweep points) to stdout.\n"
    "FILE defaults to every .hgt and .png in the shared data directory ($TERRAIN_DATA_DIR,\n"
    "../shared/data or /work/shared/data).\n"
    "options:\n"
    "  --csv PATH        also write one CSV row per (file, codec, setting)\n"
    "  --json            print the rows as JSON to stdout instead of the markdown summary\n"
    "  --peers a,b,...   only these codecs (see --list)\n"
    "  --quick           short sweeps and one repetition (smoke runs)\n"
    "  --vertical-scale S metres per stored unit for every FILE (default: the file's own; the shared\n"
    "                    Puget Sound PNG is known to be 0.1)\n"
    "  --min-time S      repeat encode and decode until each totals S seconds, keep the best (default 0.2)\n"
    "  --list            print each codec's exact configuration and exit\n"
    "  --self-test       round-trip a synthetic 97x61 int16 grid through every setting of every codec,\n"
    "                    checking the size and each declared error bound; exit 0 if all pass\n"
    "  --help            this text\n"
    "exit status: 0 success; 1 usage error; 2 input not found or unreadable; 3 truncated input;\n"
    "  4 oversized input; 5 dimensions don't match; 6 unknown sample type or format; 7 NaN/Inf in input;\n"
    "  8 missing or malformed header/sidecar field; 9 cannot write output; 10 corrupted data;\n"
    "  70 internal error (a codec failed or a self-test check failed).\n";

struct Options {
  std::string csv_path;
  bool json = false;
  bool quick = false;
  bool list = false;
  bool self_test = false;
  double min_time = 0.2;
  std::optional<double> vertical_scale;
  std::vector<std::string> peer_names;
  std::vector<std::string> files;
};

struct UsageError {
  std::string message;
};

std::vector<std::string> split_commas(const std::string& text) {
  std::vector<std::string> parts;
  std::stringstream ss(text);
  std::string part;
  while (std::getline(ss, part, ','))
    if (!part.empty()) parts.push_back(part);
  return parts;
}

Options parse_args(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw UsageError{a + " needs a value"};
      return argv[++i];
    };
    if (a == "--help" || a == "-h") {
      std::fputs(kUsage, stdout);
      std::exit(kExitOk);
    } else if (a == "--csv") {
      o.csv_path = value();
    } else if (a == "--json") {
      o.json = true;
    } else if (a == "--quick") {
      o.quick = true;
    } else if (a == "--list") {
      o.list = true;
    } else if (a == "--self-test") {
      o.self_test = true;
    } else if (a == "--peers") {
      o.peer_names = split_commas(value());
    } else if (a == "--min-time") {
      const std::string v = value();
      char* end = nullptr;
      o.min_time = std::strtod(v.c_str(), &end);
      if (end == v.c_str() || *end || !(o.min_time >= 0 && o.min_time <= 60))
        throw UsageError{"--min-time must be a number of seconds in [0, 60], got '" + v + "'"};
    } else if (a == "--vertical-scale") {
      const std::string v = value();
      char* end = nullptr;
      const double scale = std::strtod(v.c_str(), &end);
      if (end == v.c_str() || *end || !(scale > 0 && std::isfinite(scale)))
        throw UsageError{"--vertical-scale must be a positive number, got '" + v + "'"};
      o.vertical_scale = scale;
    } else if (a.size() > 1 && a[0] == '-') {
      throw UsageError{"unknown option " + a};
    } else {
      o.files.push_back(a);
    }
  }
  if (o.quick) o.min_time = 0;
  return o;
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
  while (std::round(hi / (quantum * std::ldexp(1.0, k))) - std::round(lo / (quantum * std::ldexp(1.0, k))) > 65535) ++k;
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
  double unit_m = 1;
  int64_t width = 0, height = 0;
  peers::Result result;
  double bound = -1;
  std::string error;  // non-empty when the codec failed
};

std::string short_name(const std::string& path) { return std::filesystem::path(path).stem().string(); }

void write_csv_header(std::ostream& os) {
  os << "file,codec,setting,unit_m,width,height,bytes,bits_per_sample,rms_m,max_abs_m,p999_abs_m,psnr_db,"
        "encode_s,decode_s,encode_cpu_s,decode_cpu_s,encode_msamples_s,decode_msamples_s,encode_cpu_msamples_s,"
        "decode_cpu_msamples_s,encode_reps,decode_reps,declared_bound_m,"
        "error\n";
}

void write_csv_row(std::ostream& os, const Row& r) {
  const double n = double(r.width * r.height);
  const peers::Result& x = r.result;
  char buf[640];
  const auto msps = [n](double seconds) { return seconds > 0 ? n / seconds / 1e6 : 0.0; };
  std::snprintf(buf, sizeof buf, "%zu,%.5f,%.5f,%.4f,%.4f,%.3f,%.6f,%.6f,%.6f,%.6f,%.2f,%.2f,%.2f,%.2f,%d,%d,%.4g",
                x.bytes, x.bits_per_sample, x.error.rms * r.unit_m, x.error.max_abs * r.unit_m,
                x.error.p999_abs * r.unit_m, x.error.psnr_db, x.encode_seconds, x.decode_seconds,
                x.encode_cpu_seconds, x.decode_cpu_seconds, msps(x.encode_seconds), msps(x.decode_seconds),
                msps(x.encode_cpu_seconds), msps(x.decode_cpu_seconds), x.encode_reps, x.decode_reps,
                r.bound < 0 ? -1.0 : r.bound * r.unit_m);
  os << r.file << ',' << r.codec << ",\"" << r.setting << "\"," << r.unit_m << ',' << r.width << ','
     << r.height << ',' << buf << ",\"" << r.error << "\"\n";
}

std::string json_string(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    if (static_cast<unsigned char>(c) < 0x20) continue;
    out += c;
  }
  return out + "\"";
}

void write_json(std::ostream& os, const std::vector<Row>& rows) {
  os << "[\n";
  for (size_t i = 0; i < rows.size(); ++i) {
    const Row& r = rows[i];
    const peers::Result& x = r.result;
    const double psnr = std::isfinite(x.error.psnr_db) ? x.error.psnr_db : -1;
    os << "  {\"file\": " << json_string(r.file) << ", \"codec\": " << json_string(r.codec)
       << ", \"setting\": " << json_string(r.setting) << ", \"unit_m\": " << r.unit_m
       << ", \"width\": " << r.width << ", \"height\": " << r.height << ", \"bytes\": " << x.bytes
       << ", \"bits_per_sample\": " << x.bits_per_sample << ", \"rms_m\": " << x.error.rms * r.unit_m
       << ", \"max_abs_m\": " << x.error.max_abs * r.unit_m << ", \"p999_abs_m\": " << x.error.p999_abs * r.unit_m
       << ", \"psnr_db\": " << psnr << ", \"encode_s\": " << x.encode_seconds
       << ", \"decode_s\": " << x.decode_seconds << ", \"encode_cpu_s\": " << x.encode_cpu_seconds
       << ", \"decode_cpu_s\": " << x.decode_cpu_seconds << ", \"error\": " << json_string(r.error) << "}"
       << (i + 1 < rows.size() ? ",\n" : "\n");
  }
  os << "]\n";
}

std::string cell(double bits) {
  if (bits < 0) return "—";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f", bits);
  return buf;
}

std::string speed_range(const std::vector<double>& msps) {
  if (msps.empty()) return "—";
  const auto [lo, hi] = std::minmax_element(msps.begin(), msps.end());
  char buf[48];
  if (*hi < 1.05 * *lo) std::snprintf(buf, sizeof buf, "%.3g", *lo);
  else std::snprintf(buf, sizeof buf, "%.3g–%.3g", *lo, *hi);
  return buf;
}

// Markdown summary: one row per (file, codec) with interpolated rates and the speed range.
void write_summary(std::ostream& os, const std::vector<Row>& rows, const std::vector<std::string>& file_order,
                   const std::vector<std::string>& codec_order) {
  const double rms_targets[] = {0.5, 1, 2, 4};
  const double max_targets[] = {1, 2, 5};
  os << "| DEM | codec | lossless | @rms 0.5 m | @rms 1 m | @rms 2 m | @rms 4 m | @max 1 m | @max 2 m | @max 5 m "
        "| encode Ms/s (CPU) | decode Ms/s (CPU) |\n";
  os << "|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const std::string& file : file_order) {
    for (const std::string& codec : codec_order) {
      std::vector<peers::RatePoint> by_rms, by_max;
      std::vector<double> enc, dec;
      double lossless = -1;
      bool any = false;
      for (const Row& r : rows) {
        if (r.file != file || r.codec != codec || !r.error.empty()) continue;
        any = true;
        const peers::Result& x = r.result;
        by_rms.push_back({x.error.rms * r.unit_m, x.bits_per_sample});
        by_max.push_back({x.error.max_abs * r.unit_m, x.bits_per_sample});
        if (x.error.max_abs == 0 && (lossless < 0 || x.bits_per_sample < lossless)) lossless = x.bits_per_sample;
        const double n = double(r.width * r.height);
        if (x.encode_cpu_seconds > 0) enc.push_back(n / x.encode_cpu_seconds / 1e6);
        if (x.decode_cpu_seconds > 0) dec.push_back(n / x.decode_cpu_seconds / 1e6);
      }
      if (!any) continue;
      os << "| " << file << " | " << codec << " | " << cell(lossless);
      for (double t : rms_targets) os << " | " << cell(peers::bits_at_error(by_rms, t));
      for (double t : max_targets) os << " | " << cell(peers::bits_at_error(by_max, t));
      os << " | " << speed_range(enc) << " | " << speed_range(dec) << " |\n";
    }
  }
  os << "\nBits/sample; '—' = the sweep does not reach that error. Ms/s = million samples per second of "
        "process CPU time, one thread, best of N repetitions, range over the sweep (wall-clock figures: "
        "CSV).\n";
}

std::vector<std::unique_ptr<peers::Peer>> select_peers(const std::vector<std::string>& names) {
  auto all = peers::all_peers();
  if (names.empty()) return all;
  std::vector<std::unique_ptr<peers::Peer>> chosen;
  for (const std::string& name : names) {
    auto it = std::find_if(all.begin(), all.end(), [&](const auto& p) { return p && p->name() == name; });
    if (it == all.end()) throw UsageError{"unknown codec '" + name + "' (see --list)"};
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
        if (r.bytes == 0) verdict = "FAIL: empty stream";
        else if (s.max_error_bound >= 0 && r.error.max_abs > s.max_error_bound) verdict = "FAIL: max error above bound";
        else if (s.max_error_bound < 0 && !(r.error.rms <= 0.25 * range)) verdict = "FAIL: rms above a quarter of the range";
        if (s.max_error_bound == 0 && r.error.max_abs == 0) has_lossless = true;
        std::printf("%-9s %-20s bytes %6zu  max|err| %7.1f  rms %7.2f  bound %5s  %s\n", peer->name().c_str(),
                    s.label.c_str(), r.bytes, r.error.max_abs, r.error.rms,
                    s.max_error_bound < 0 ? "none" : std::to_string(int(s.max_error_bound)).c_str(), verdict.c_str());
      } catch (const std::exception& e) {
        verdict = std::string("FAIL: ") + e.what();
        std::printf("%-9s %-20s %s\n", peer->name().c_str(), s.label.c_str(), verdict.c_str());
      }
      if (verdict != "ok") ++failures;
    }
    if (peer->lossless_capable() && !has_lossless) {
      std::printf("%-9s FAIL: claims lossless capability but no setting round-tripped exactly\n", peer->name().c_str());
      ++failures;
    }
  }
  std::printf("self-test: %s (%d failure%s)\n", failures ? "FAILED" : "passed", failures, failures == 1 ? "" : "s");
  return failures ? kExitInternal : kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  std::vector<std::unique_ptr<peers::Peer>> peer_list;
  try {
    opt = parse_args(argc, argv);
    peer_list = select_peers(opt.peer_names);
  } catch (const UsageError& e) {
    std::fprintf(stderr, "codec-bench: %s\n%s", e.message.c_str(), kUsage);
    return kExitUsage;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "codec-bench: %s\n", e.what());
    return kExitInternal;
  }

  if (opt.list) {
    for (const auto& p : peer_list) std::printf("%s: %s\n", p->name().c_str(), p->configuration().c_str());
    return kExitOk;
  }
  if (opt.self_test) return run_self_test(peer_list);

  if (opt.files.empty()) opt.files = default_files();
  if (opt.files.empty()) {
    std::fprintf(stderr, "codec-bench: no input files given and no shared data directory found\n");
    return kExitNotFound;
  }

  std::ofstream csv;
  if (!opt.csv_path.empty()) {
    csv.open(opt.csv_path);
    if (!csv) {
      std::fprintf(stderr, "codec-bench: cannot write %s\n", opt.csv_path.c_str());
      return kExitWriteFailed;
    }
    write_csv_header(csv);
  }

  std::vector<Row> rows;
  std::vector<std::string> file_order, codec_order;
  for (const auto& p : peer_list) codec_order.push_back(p->name());
  bool codec_failed = false;
  for (const std::string& path : opt.files) {
    terrain::Heightmap map;
    try {
      terrain::ReadOptions read_options;
      read_options.vertical_scale = opt.vertical_scale ? opt.vertical_scale : known_vertical_scale(path);
      map = terrain::read_heightmap(path, read_options);
    } catch (const terrain::IoError& e) {
      std::fprintf(stderr, "codec-bench: %s\n", e.what());
      return int(e.code());
    } catch (const std::exception& e) {
      std::fprintf(stderr, "codec-bench: %s: %s\n", path.c_str(), e.what());
      return kExitNotFound;
    }
    std::string note;
    const peers::Image16 img = to_image16(map, &note);
    const std::string file = short_name(path);
    file_order.push_back(file);
    std::fprintf(stderr, "%s: %lldx%lld, %s\n", file.c_str(), (long long)img.width, (long long)img.height,
                 note.c_str());
    for (auto& peer : peer_list) {
      for (const peers::Setting& s : peer->sweep(opt.quick, img.unit_m)) {
        Row row{file, peer->name(), s.label, img.unit_m, img.width, img.height, {}, s.max_error_bound, {}};
        try {
          row.result = peers::measure(*peer, img, s, opt.min_time, 50);
          row.result.decoded.clear();
          row.result.decoded.shrink_to_fit();
          if (s.max_error_bound >= 0 && row.result.error.max_abs > s.max_error_bound)
            row.error = "max error exceeds the declared bound";
        } catch (const std::exception& e) {
          row.error = e.what();
        }
        if (!row.error.empty()) {
          codec_failed = true;
          std::fprintf(stderr, "codec-bench: %s %s %s: %s\n", file.c_str(), row.codec.c_str(), row.setting.c_str(),
                       row.error.c_str());
        }
        if (csv.is_open()) write_csv_row(csv, row);
        rows.push_back(std::move(row));
      }
    }
  }
  if (csv.is_open()) {
    csv.close();
    if (!csv) {
      std::fprintf(stderr, "codec-bench: cannot write %s\n", opt.csv_path.c_str());
      return kExitWriteFailed;
    }
  }
  if (opt.json) write_json(std::cout, rows);
  else write_summary(std::cout, rows, file_order, codec_order);
  std::cout.flush();
  return codec_failed ? kExitInternal : kExitOk;
}
