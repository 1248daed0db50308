// Read-only memory mapping of a whole file (POSIX mmap), released on destruction.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace terrain::container {

class MappedFile {
 public:
  // Maps `path` read-only; throws Error(NotFound) naming the file if it cannot be opened,
  // is not a regular file, or cannot be mapped. An empty file maps to data() == nullptr, size() 0.
  explicit MappedFile(const std::string& path);
  ~MappedFile();
  MappedFile(const MappedFile&) = delete;
  MappedFile& operator=(const MappedFile&) = delete;

  const uint8_t* data() const { return data_; }
  uint64_t size() const { return size_; }

 private:
  const uint8_t* data_ = nullptr;
  uint64_t size_ = 0;
};

}  // namespace terrain::container
