// Shared command-line plumbing for every tool: a tiny argument parser (with -q/-v/--json/--help),
// the heightmap read-option flags, and the mapping from errors to the documented exit statuses.
#pragma once

#include <cstdint>
#include <functional>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/text.h"
#include "readers/heightmap.h"

namespace cli {

// Exit statuses shared by all tools: exit_status() is the one mapping from the libraries' error codes
// (core/error.h) to the statuses exit_codes_help() documents.
constexpr int kExitOk = 0;
constexpr int kExitUsage = 1;
// A viewer (clipmap-view) that met damaged tiles, showed their regions from coarser levels and
// finished: "finished with damaged tiles".
constexpr int kExitDamaged = 11;
// A feature this build or this machine does not offer: clipmap-view --window built without GLFW, or
// no display to open a window on.
constexpr int kExitUnavailable = 12;
constexpr int kExitInternal = 70;
int exit_status(terrain::ErrorCode code);
// The exit-status table, for the end of every tool's --help.
const std::string& exit_codes_help();

// Bad command line: reported as "<tool>: <message>" plus a hint to --help, exit status 1.
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct CommonFlags {
  bool quiet = false;    // -q: no progress, no informational messages
  bool verbose = false;  // -v: extra detail on stderr
  bool json = false;     // --json: machine-readable result on stdout
};

class ArgParser {
 public:
  ArgParser(std::string program, std::string synopsis, std::string description);

  // names: comma-separated spellings, e.g. "-o,--output". Setters run during parse() and may throw
  // UsageError.
  void flag(const std::string& names, const std::string& help, bool* target);
  void option(const std::string& names, const std::string& metavar, const std::string& help,
              std::function<void(const std::string&)> set);
  // An option whose value is kept as given.
  void option(const std::string& names, const std::string& metavar, const std::string& help,
              std::string* target);
  void positional(const std::string& name, const std::string& help, std::string* target,
                  bool required = true);
  // Every argument after the positionals (e.g. FILE...), in order; fewer than `min` is a usage error.
  void rest(const std::string& name, const std::string& help, std::vector<std::string>* target,
            size_t min = 0);
  // Adds -q/--quiet, -v/--verbose and (if with_json) --json.
  void add_common(CommonFlags& flags, bool with_json = true);
  // Text printed after the option list in --help (the exit-code table is always appended).
  void epilog(std::string text) { epilog_ = std::move(text); }

  // Returns nullopt when the tool should go on, or the status to exit with now:
  // 0 after printing --help to stdout, 1 after printing a usage error to stderr.
  std::optional<int> parse(int argc, char** argv);
  std::string help() const;

 private:
  struct Option {
    std::vector<std::string> names;
    std::string metavar, help;
    std::function<void(const std::string&)> set;  // flags ignore the argument
    bool takes_value = false;
  };
  struct Positional {
    std::string name, help;
    std::string* target;
    bool required;
  };
  std::string program_, synopsis_, description_, epilog_;
  std::vector<Option> options_;
  std::vector<Positional> positionals_;
  struct Rest {
    std::string name, help;
    std::vector<std::string>* target;
    size_t min;
  };
  std::optional<Rest> rest_;
  const Option* find(const std::string& name) const;
};

// Value parsers for option setters; they throw UsageError naming the option.
int64_t parse_int(const std::string& option, const std::string& text, int64_t min, int64_t max);
// parse_double with a bound (min or max finite) also rejects NaN and values outside [min, max].
double parse_double(const std::string& option, const std::string& text,
                    double min = -std::numeric_limits<double>::infinity(),
                    double max = std::numeric_limits<double>::infinity());

// Adds --vscale --voffset --spacing --width --height --type --endian --nodata --terrain-rgb.
void add_read_options(ArgParser& parser, terrain::ReadOptions& options);

// Shortest decimal text that reads back as exactly `v` (core/text.h).
using terrain::shortest;

// Runs a tool body, turning exceptions into "<program>: error: <message>" on stderr and the documented
// exit status (terrain::Error -> exit_status(code), UsageError -> 1, anything else -> 70).
int run_tool(const std::string& program, const std::function<int()>& body);

}  // namespace cli
