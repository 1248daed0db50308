#include "core/file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <mutex>

#include "core/error.h"

namespace terrain {

int open_regular_file(const std::string& path, uint64_t* size) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) throw Error(ErrorCode::NotFound, path + ": cannot open: " + std::strerror(errno));
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    const int err = errno;
    const bool regular = S_ISREG(st.st_mode);
    ::close(fd);
    throw Error(ErrorCode::NotFound, path + ": " + (regular ? std::strerror(err) : "not a regular file"));
  }
  // Regular files ignore O_NONBLOCK; clear it anyway so the descriptor behaves as a plain one.
  const int flags = ::fcntl(fd, F_GETFL);
  if (flags >= 0) ::fcntl(fd, F_SETFL, flags & ~O_NONBLOCK);
  if (size) *size = uint64_t(st.st_size);
  return fd;
}

void check_output_path(const std::string& path, const std::vector<std::string>& inputs) {
  struct stat out {};
  if (::stat(path.c_str(), &out) != 0) return;  // absent (or unreachable: creating it will say so)
  if (!S_ISREG(out.st_mode))
    throw Error(ErrorCode::WriteFailed, path +
                                            ": not a regular file (a device, FIFO or directory); refusing to "
                                            "replace it");
  for (const std::string& in : inputs) {
    struct stat st {};
    if (::stat(in.c_str(), &st) == 0 && st.st_dev == out.st_dev && st.st_ino == out.st_ino)
      throw Error(ErrorCode::WriteFailed, path + ": is the input " + in + "; refusing to overwrite it");
  }
}

int create_temp_beside(const std::string& path, const std::string& suffix, std::string* temp) {
  std::string name = path + ".tmp.XXXXXX" + suffix;
  const int fd = ::mkostemps(name.data(), int(suffix.size()), O_CLOEXEC);
  if (fd < 0)
    throw Error(ErrorCode::WriteFailed,
                path + ": cannot create a temporary file beside it: " + std::strerror(errno));
  // mkostemps creates 0600; an output gets what open(O_CREAT, 0666) would have given it. The umask
  // can only be read by setting it, so it is read once.
  static std::once_flag once;
  static mode_t mask = 022;
  std::call_once(once, [] {
    mask = ::umask(022);
    ::umask(mask);
  });
  ::fchmod(fd, 0666 & ~mask);
  *temp = std::move(name);
  return fd;
}

}  // namespace terrain
