#include "report_file.h"

#include <sys/stat.h>
#include <unistd.h>

#include <cstdio>
#include <iostream>

#include "core/error.h"
#include "core/file.h"

namespace cli {

ReportFile::ReportFile(std::string path) : path_(std::move(path)) {
  if (path_ == "-") return;
  struct stat st {};
  if (::stat(path_.c_str(), &st) == 0 && !S_ISREG(st.st_mode) && !S_ISDIR(st.st_mode)) {
    // A device or pipe (/dev/stdout, a FIFO a reader waits on) is written straight through: there is
    // nothing to rename over it, and replacing it by a file would be wrong.
    file_.open(path_, std::ios::binary);
    if (!file_) throw terrain::Error(terrain::ErrorCode::WriteFailed, path_ + ": cannot open for writing");
    return;
  }
  terrain::check_output_path(path_);
  ::close(terrain::create_temp_beside(path_, "", &temp_));  // exclusive: a planted link is not followed
  file_.open(temp_, std::ios::binary | std::ios::trunc);
  if (!file_) throw terrain::Error(terrain::ErrorCode::WriteFailed, path_ + ": cannot create the report");
}

ReportFile::~ReportFile() {
  if (!finished_ && !temp_.empty()) std::remove(temp_.c_str());
}

std::ostream& ReportFile::stream() { return path_ == "-" ? std::cout : file_; }

void ReportFile::finish() {
  if (path_ == "-") {
    std::cout.flush();
    if (!std::cout) throw terrain::Error(terrain::ErrorCode::WriteFailed, "standard output: write error");
    finished_ = true;
    return;
  }
  file_.flush();
  file_.close();
  if (!file_) throw terrain::Error(terrain::ErrorCode::WriteFailed, path_ + ": write error (disk full?)");
  finished_ = temp_.empty();
  if (finished_) return;  // written straight through
  terrain::check_output_path(path_);
  if (std::rename(temp_.c_str(), path_.c_str()) != 0)
    throw terrain::Error(terrain::ErrorCode::WriteFailed, path_ + ": cannot rename the report into place");
  finished_ = true;
}

}  // namespace cli
