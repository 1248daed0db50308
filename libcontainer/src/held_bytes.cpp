// Level blobs held back until the levels before them are in the file (see held_bytes.h).
#include "container/internal/held_bytes.h"

#include <fcntl.h>
#include <stdlib.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include "container/container.h"

namespace terrain::container::detail {
namespace {

[[noreturn]] void spill_failure(const std::string& dir, const std::string& what, int err) {
  throw Error(ErrorCode::WriteFailed,
              dir + ": " + what + " spill file: " + (err ? std::strerror(err) : "short read"));
}

}  // namespace

int create_unnamed_file(const std::string& dir) {
  int fd = ::open(dir.c_str(), O_RDWR | O_TMPFILE | O_CLOEXEC, 0600);
  if (fd >= 0) return fd;
  // Filesystems without O_TMPFILE: mkostemp's random name, created O_EXCL, gone before first use.
  std::string name = dir + "/.pyr-spill-XXXXXX";
  fd = ::mkostemp(name.data(), O_CLOEXEC);
  if (fd < 0) spill_failure(dir, "cannot create", errno);
  ::unlink(name.c_str());
  return fd;
}

HeldBytes::HeldBytes(std::string dir, size_t memory_limit)
    : dir_(std::move(dir)), memory_limit_(memory_limit) {}

HeldBytes::~HeldBytes() {
  if (fd_ >= 0) ::close(fd_);
}

void HeldBytes::append(const uint8_t* data, size_t size) {
  const size_t in_memory =
      fd_ >= 0 ? 0 : std::min(size, memory_limit_ - std::min(memory_limit_, memory_.size()));
  memory_.insert(memory_.end(), data, data + in_memory);
  data += in_memory;
  size -= in_memory;
  if (size == 0) return;
  if (fd_ < 0) fd_ = create_unnamed_file(dir_);
  while (size > 0) {
    const ssize_t n = ::write(fd_, data, size);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) spill_failure(dir_, "cannot write", n < 0 ? errno : ENOSPC);
    data += n;
    size -= size_t(n);
    spilled_ += uint64_t(n);
  }
}

void HeldBytes::drain(const std::function<void(const uint8_t*, size_t)>& out) {
  if (!memory_.empty()) out(memory_.data(), memory_.size());
  std::vector<uint8_t>().swap(memory_);
  if (fd_ < 0) return;
  std::vector<uint8_t> chunk(size_t(1) << 20);
  for (uint64_t pos = 0; pos < spilled_;) {
    const size_t want = size_t(std::min<uint64_t>(chunk.size(), spilled_ - pos));
    const ssize_t n = ::pread(fd_, chunk.data(), want, off_t(pos));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) spill_failure(dir_, "cannot read back", n < 0 ? errno : 0);
    out(chunk.data(), size_t(n));
    pos += uint64_t(n);
  }
  ::close(fd_);
  fd_ = -1;
  spilled_ = 0;
}

}  // namespace terrain::container::detail
