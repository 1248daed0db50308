// Temporary spill files of the out-of-core builder: written sequentially, then read back sequentially,
// removed on destruction.
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>

namespace terrain::detail {

class SpillFile {
 public:
  explicit SpillFile(std::string path);  // creates/truncates; Error(WriteFailed) naming the path
  ~SpillFile();
  SpillFile(const SpillFile&) = delete;
  SpillFile& operator=(const SpillFile&) = delete;

  void write(const void* data, size_t bytes);
  // Switches from writing to reading from the start.
  void rewind_for_reading();
  // Reads exactly `bytes`; Error(Truncated) when the file is shorter.
  void read(void* data, size_t bytes);
  bool read_byte(uint8_t* b);
  const std::string& path() const { return path_; }

 private:
  std::string path_;
  std::FILE* file_ = nullptr;
};

}  // namespace terrain::detail
