#include "container/internal/mmap_file.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <limits>

#include "container/container.h"
#include "core/file.h"

namespace terrain::container {

MappedFile::MappedFile(const std::string& path) {
  uint64_t size = 0;
  const int fd = open_regular_file(path, &size);
  if (size > std::numeric_limits<size_t>::max()) {
    ::close(fd);
    throw Error(ErrorCode::NotFound, path + ": too large to map in this address space");
  }
  if (size > 0) {
    void* p = ::mmap(nullptr, size_t(size), PROT_READ, MAP_PRIVATE, fd, 0);
    if (p == MAP_FAILED) {
      const int err = errno;
      ::close(fd);
      throw Error(ErrorCode::NotFound, path + ": cannot map: " + std::strerror(err));
    }
    data_ = static_cast<const uint8_t*>(p);
  }
  size_ = size;
  ::close(fd);  // the mapping keeps the file contents reachable
}

MappedFile::~MappedFile() {
  if (data_) ::munmap(const_cast<uint8_t*>(data_), size_t(size_));
}

}  // namespace terrain::container
