#include "container/internal/mmap_file.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <limits>

#include "container/container.h"

namespace terrain::container {

MappedFile::MappedFile(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    throw Error(ErrorCode::NotFound, path + ": cannot open: " + std::strerror(errno));
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    const int err = errno;
    ::close(fd);
    throw Error(ErrorCode::NotFound,
                path + ": " + (S_ISREG(st.st_mode) ? std::strerror(err) : "not a regular file"));
  }
  const uint64_t size = uint64_t(st.st_size);
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
