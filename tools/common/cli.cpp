// Argument parsing and exit-status mapping shared by the tools.
#include "cli.h"

#include <cctype>
#include <charconv>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <iostream>
#include <new>
#include <sstream>

namespace cli {

namespace {
// The documented exit statuses: each library error code maps to one (exit_status), and --help prints
// this table (exit_codes_help), so the two cannot disagree.
struct ExitStatus {
  int status;
  const char* meaning;
  std::vector<terrain::ErrorCode> codes;
};
const std::vector<ExitStatus>& exit_table() {
  using C = terrain::ErrorCode;
  static const std::vector<ExitStatus> table = {
      {kExitOk, "success", {}},
      {kExitUsage, "usage error (unknown, missing or out-of-range option)", {C::InvalidOption}},
      {2, "input not found or unreadable", {C::NotFound}},
      {3, "truncated input", {C::Truncated}},
      {4, "oversized input (more bytes than the dimensions need)", {C::Oversized}},
      {5, "dimensions don't match the file size / cannot be derived", {C::DimensionMismatch}},
      {6, "unknown sample type or format", {C::UnknownType}},
      {7, "NaN/Inf in float input", {C::NonFinite}},
      {8, "missing or malformed header/sidecar field", {C::MissingField}},
      {9, "cannot write output", {C::WriteFailed}},
      {10,
       "corrupted compressed data (bad checksum, bad bitstream, unknown version)",
       {C::CorruptData, C::ChecksumMismatch, C::UnsupportedVersion}},
      {kExitDamaged,
       "finished with damaged tiles (clipmap-view: each logged once, its region shown from a coarser level)",
       {}},
      {kExitUnavailable,
       "not available here (clipmap-view --window: built without GLFW, or no display to open a window on)",
       {}},
      {kExitInternal, "internal error", {}},
  };
  return table;
}
}  // namespace

int exit_status(terrain::ErrorCode code) {
  for (const ExitStatus& e : exit_table())
    for (const terrain::ErrorCode c : e.codes)
      if (c == code) return e.status;
  return kExitInternal;
}

const std::string& exit_codes_help() {
  static const std::string text = [] {
    std::string t = "Exit status:\n";
    for (const ExitStatus& e : exit_table()) {
      const std::string n = std::to_string(e.status);
      t += std::string(n.size() < 2 ? "  " : " ") + n + "  " + e.meaning + "\n";
    }
    return t;
  }();
  return text;
}

ArgParser::ArgParser(std::string program, std::string synopsis, std::string description)
    : program_(std::move(program)), synopsis_(std::move(synopsis)), description_(std::move(description)) {}

namespace {
std::vector<std::string> split_names(const std::string& names) {
  std::vector<std::string> out;
  std::stringstream ss(names);
  std::string n;
  while (std::getline(ss, n, ',')) out.push_back(n);
  return out;
}
}  // namespace

void ArgParser::flag(const std::string& names, const std::string& help, bool* target) {
  options_.push_back({split_names(names), "", help, [target](const std::string&) { *target = true; }, false});
}

void ArgParser::option(const std::string& names, const std::string& metavar, const std::string& help,
                       std::function<void(const std::string&)> set) {
  options_.push_back({split_names(names), metavar, help, std::move(set), true});
}

void ArgParser::option(const std::string& names, const std::string& metavar, const std::string& help,
                       std::string* target) {
  option(names, metavar, help, [target](const std::string& v) { *target = v; });
}

void ArgParser::rest(const std::string& name, const std::string& help, std::vector<std::string>* target,
                     size_t min) {
  rest_ = Rest{name, help, target, min};
}

void ArgParser::positional(const std::string& name, const std::string& help, std::string* target,
                           bool required) {
  positionals_.push_back({name, help, target, required});
}

void ArgParser::add_common(CommonFlags& flags, bool with_json) {
  flag("-q,--quiet", "no progress or informational messages", &flags.quiet);
  flag("-v,--verbose", "more detail on stderr", &flags.verbose);
  if (with_json) flag("--json", "print the result as one JSON object on stdout", &flags.json);
}

const ArgParser::Option* ArgParser::find(const std::string& name) const {
  for (const auto& o : options_)
    for (const auto& n : o.names)
      if (n == name) return &o;
  return nullptr;
}

std::string ArgParser::help() const {
  std::ostringstream out;
  out << "Usage: " << program_ << " " << synopsis_ << "\n\n" << description_ << "\n\n";
  if (!positionals_.empty() || rest_) {
    out << "Arguments:\n";
    for (const auto& p : positionals_) out << "  " << p.name << "\n      " << p.help << "\n";
    if (rest_) out << "  " << rest_->name << "...\n      " << rest_->help << "\n";
    out << "\n";
  }
  out << "Options:\n";
  for (const auto& o : options_) {
    std::string spelled;
    for (const auto& n : o.names) spelled += (spelled.empty() ? "" : ", ") + n;
    if (o.takes_value) spelled += " " + o.metavar;
    out << "  " << spelled << "\n      " << o.help << "\n";
  }
  out << "  -h, --help\n      show this help and exit\n\n";
  if (!epilog_.empty()) out << epilog_ << "\n\n";
  out << exit_codes_help();
  return out.str();
}

std::optional<int> ArgParser::parse(int argc, char** argv) {
  try {
    size_t next_positional = 0;
    bool only_positionals = false;
    for (int i = 1; i < argc; ++i) {
      std::string arg = argv[i];
      if (!only_positionals && (arg == "-h" || arg == "--help")) {
        std::cout << help();
        return kExitOk;
      }
      if (!only_positionals && arg == "--") {
        only_positionals = true;
        continue;
      }
      if (!only_positionals && arg.size() > 1 && arg[0] == '-' &&
          !(std::isdigit(static_cast<unsigned char>(arg[1])))) {
        std::string name = arg, inline_value;
        bool has_inline = false;
        if (auto eq = arg.find('='); arg.rfind("--", 0) == 0 && eq != std::string::npos) {
          name = arg.substr(0, eq);
          inline_value = arg.substr(eq + 1);
          has_inline = true;
        }
        const Option* o = find(name);
        if (!o) throw UsageError("unknown option " + name);
        if (!o->takes_value) {
          if (has_inline) throw UsageError("option " + name + " takes no value");
          o->set("");
          continue;
        }
        if (!has_inline) {
          if (i + 1 >= argc) throw UsageError("option " + name + " needs a value (" + o->metavar + ")");
          inline_value = argv[++i];
        }
        o->set(inline_value);
        continue;
      }
      if (next_positional < positionals_.size())
        *positionals_[next_positional++].target = arg;
      else if (rest_)
        rest_->target->push_back(arg);
      else
        throw UsageError("unexpected argument " + arg);
    }
    for (size_t p = next_positional; p < positionals_.size(); ++p)
      if (positionals_[p].required) throw UsageError("missing argument " + positionals_[p].name);
    if (rest_ && rest_->target->size() < rest_->min) throw UsageError("missing argument " + rest_->name);
  } catch (const UsageError& e) {
    std::cerr << program_ << ": " << e.what() << "\n"
              << "Try '" << program_ << " --help'.\n";
    return kExitUsage;
  }
  return std::nullopt;
}

int64_t parse_int(const std::string& option, const std::string& text, int64_t min, int64_t max) {
  int64_t v = 0;
  auto res = std::from_chars(text.data(), text.data() + text.size(), v);
  if (res.ec != std::errc() || res.ptr != text.data() + text.size())
    throw UsageError("option " + option + ": \"" + text + "\" is not an integer");
  if (v < min || v > max)
    throw UsageError("option " + option + ": " + text + " is out of range [" + std::to_string(min) + ", " +
                     std::to_string(max) + "]");
  return v;
}

double parse_double(const std::string& option, const std::string& text, double min, double max) {
  double v = 0;
  const char* begin = text.data();
  if (!text.empty() && text[0] == '+') ++begin;
  auto res = std::from_chars(begin, text.data() + text.size(), v);
  if (res.ec != std::errc() || res.ptr != text.data() + text.size() || text.empty())
    throw UsageError("option " + option + ": \"" + text + "\" is not a number");
  const bool bounded = std::isfinite(min) || std::isfinite(max);  // unbounded callers check NaN themselves
  if (bounded && !(v >= min && v <= max))
    throw UsageError("option " + option + ": " + text + " is out of range [" + shortest(min) + ", " +
                     shortest(max) + "]");
  return v;
}

void add_read_options(ArgParser& p, terrain::ReadOptions& o) {
  p.option("--vscale", "S", "metres per stored unit (e.g. 0.1 for the Puget Sound PNG); overrides the file",
           [&o](const std::string& v) {
             o.vertical_scale = parse_double("--vscale", v);
             if (!std::isfinite(*o.vertical_scale) || *o.vertical_scale == 0)
               throw UsageError("--vscale must be finite and non-zero");
           });
  p.option("--voffset", "M", "metres added after scaling", [&o](const std::string& v) {
    o.vertical_offset = parse_double("--voffset", v);
    if (!std::isfinite(*o.vertical_offset)) throw UsageError("--voffset must be finite");
  });
  p.option("--spacing", "D[,DY]", "horizontal sample spacing (x, optionally y)", [&o](const std::string& v) {
    auto comma = v.find(',');
    o.spacing_x = parse_double("--spacing", v.substr(0, comma));
    o.spacing_y = comma == std::string::npos ? *o.spacing_x : parse_double("--spacing", v.substr(comma + 1));
    if (!(*o.spacing_x > 0) || !(*o.spacing_y > 0) || !std::isfinite(*o.spacing_x) ||
        !std::isfinite(*o.spacing_y))
      throw UsageError("--spacing must be positive");
  });
  p.option("--width", "N", "samples per row (raw grids)",
           [&o](const std::string& v) { o.width = parse_int("--width", v, 1, int64_t(1) << 31); });
  p.option("--height", "N", "rows (raw grids)",
           [&o](const std::string& v) { o.height = parse_int("--height", v, 1, int64_t(1) << 31); });
  p.option("--type", "T", "sample type of raw grids: int16, uint16, int32, float32",
           [&o](const std::string& v) {
             o.sample_type = terrain::sample_type_from_name(v);
             if (!o.sample_type)
               throw UsageError("--type: unknown sample type \"" + v + "\" (int16, uint16, int32, float32)");
           });
  p.option("--endian", "E", "byte order of raw grids: little or big", [&o](const std::string& v) {
    if (v == "little" || v == "le")
      o.big_endian = false;
    else if (v == "big" || v == "be")
      o.big_endian = true;
    else
      throw UsageError("--endian must be little or big");
  });
  p.option("--nodata", "V", "stored value that marks a void (\"nan\" for a NaN)", [&o](const std::string& v) {
    o.nodata = (v == "nan" || v == "NaN") ? std::nan("") : parse_double("--nodata", v);
  });
  p.flag("--terrain-rgb", "decode an 8-bit RGB(A) image as Mapbox Terrain-RGB (automatic for RGB PNGs)",
         &o.terrain_rgb);
}

int run_tool(const std::string& program, const std::function<int()>& body) {
  // Past a file-size limit (ulimit -f) a write fails with EFBIG, reported as "cannot write" (exit 9),
  // instead of the default SIGXFSZ killing the process with its temporary file left behind.
  std::signal(SIGXFSZ, SIG_IGN);
  try {
    const int status = body();
    // Data on stdout that never arrived (a full disk, /dev/full, a closed pipe) is a failed run.
    std::cout.flush();
    if (!std::cout || std::fflush(stdout) != 0 || std::ferror(stdout))
      throw terrain::Error(terrain::ErrorCode::WriteFailed, "standard output: write error");
    return status;
  } catch (const terrain::Error& e) {
    std::cerr << program << ": error: " << e.what() << "\n";
    return exit_status(e.code());
  } catch (const UsageError& e) {
    std::cerr << program << ": " << e.what() << "\nTry '" << program << " --help'.\n";
    return kExitUsage;
  } catch (const std::bad_alloc&) {
    std::cerr << program << ": error: out of memory\n";
    return kExitInternal;
  } catch (const std::exception& e) {
    std::cerr << program << ": internal error: " << e.what() << "\n";
    return kExitInternal;
  }
}

}  // namespace cli
