// Where a tool's --json (or other) report goes: a regular file, written under a temporary name and
// renamed when complete; a device or pipe (/dev/stdout), written straight through; or standard
// output for "-". Every write is checked: a full disk or /dev/full gives
// Error(WriteFailed) naming the file instead of a truncated report and exit 0.
#pragma once

#include <fstream>
#include <ostream>
#include <string>

namespace cli {

class ReportFile {
 public:
  // Throws terrain::Error(WriteFailed) when the file cannot be created (or the path is a directory).
  explicit ReportFile(std::string path);
  ~ReportFile();  // an unfinished file's temporary is removed
  ReportFile(const ReportFile&) = delete;
  ReportFile& operator=(const ReportFile&) = delete;
  std::ostream& stream();
  // Flushes and checks the stream, then closes the file and renames it into place; throws
  // terrain::Error(WriteFailed) on any failure.
  void finish();

 private:
  std::string path_, temp_;
  std::ofstream file_;
  bool finished_ = false;
};

}  // namespace cli
