// Progress reporting on stderr: a redrawn bar when stderr is a terminal, otherwise plain lines at
// 10 % steps (so logs stay readable). Disabled entirely with -q.
#pragma once

#include <cstdint>
#include <string>

namespace cli {

class Progress {
 public:
  // total: units of work (e.g. rows); enabled = !quiet.
  Progress(std::string label, int64_t total, bool enabled);
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  // Reports that `done` of `total` units are complete; cheap to call often (redraws are throttled).
  void update(int64_t done);
  // Marks completion (draws 100 % and ends the bar line). Called by the destructor if not before.
  void finish();

 private:
  std::string label_;
  int64_t total_;
  bool enabled_, tty_, finished_ = false;
  int last_shown_ = -1;  // last percent (tty) or decile (plain) shown
};

}  // namespace cli
