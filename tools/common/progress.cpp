// Progress bar / plain progress lines on stderr.
#include "progress.h"

#include <unistd.h>

#include <algorithm>
#include <cstdio>

namespace cli {

Progress::Progress(std::string label, int64_t total, bool enabled)
    : label_(std::move(label)),
      total_(std::max<int64_t>(total, 1)),
      enabled_(enabled),
      tty_(isatty(STDERR_FILENO) != 0) {}

Progress::~Progress() {
  if (!finished_) finish();
}

void Progress::update(int64_t done) {
  if (!enabled_ || finished_) return;
  int percent = int(std::clamp<int64_t>(done * 100 / total_, 0, 100));
  if (tty_) {
    if (percent == last_shown_) return;
    last_shown_ = percent;
    constexpr int kWidth = 30;
    int filled = percent * kWidth / 100;
    std::fprintf(stderr, "\r%s [%.*s%*s] %3d%%", label_.c_str(), filled, "##############################",
                 kWidth - filled, "", percent);
    std::fflush(stderr);
  } else {
    int decile = percent / 10;
    if (decile <= last_shown_ || decile == 10) return;  // 100 % is printed by finish()
    last_shown_ = decile;
    if (decile > 0) std::fprintf(stderr, "%s: %d%%\n", label_.c_str(), decile * 10);
  }
}

void Progress::finish() {
  if (finished_) return;
  finished_ = true;
  if (!enabled_) return;
  if (tty_) {
    last_shown_ = -1;
    std::fprintf(stderr, "\r%s [%s] 100%%\n", label_.c_str(), "##############################");
  } else {
    std::fprintf(stderr, "%s: done\n", label_.c_str());
  }
  std::fflush(stderr);
}

}  // namespace cli
