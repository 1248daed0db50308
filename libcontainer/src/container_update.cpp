// Copy-on-write commits of an edited container (docs/format.md "Editing (2.2)"): new bytes after the
// committed end, then the index and a tail copy of the superblock, fsync, then the superblock at
// offset 0, fsync. The superblock write is the commit point; the tail copy makes a torn one
// recoverable (the reader falls back to it), and until it happens the old index stays reachable.
#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>

#include "container/container.h"
#include "container/internal/container_format.h"

namespace terrain::container {

using namespace layout;

ContainerUpdater::ContainerUpdater(const Container& current)
    : path_(current.path()), info_(current.info()), generation_(current.generation()) {
  fd_ = ::open(path_.c_str(), O_RDWR | O_CLOEXEC | O_NOFOLLOW);
  if (fd_ < 0)
    throw Error(ErrorCode::WriteFailed, path_ + ": cannot open for editing: " + std::strerror(errno));
  const size_t n = info_.levels.size();
  for (size_t l = 0; l < n; ++l) {
    const LevelInfo& li = info_.levels[l];
    offsets_.push_back(li.blob_offset);
    sizes_.push_back(li.blob_size);
    crcs_.push_back(li.blob_crc);
    has_crc_.push_back(li.has_blob_crc);
  }
  metadata_offset_ = current.metadata_offset();
  metadata_size_ = current.metadata_json().size();
  metadata_crc_ = current.metadata_crc();
  mask_offset_ = current.mask_offset();
  mask_size_ = current.mask_bytes();
  mask_crc_ = current.mask_crc();
  start_ = end_ = current.committed_size();
  try {
    // An interrupted edit's tail is no part of any version: drop it so the new bytes follow the end.
    if (current.uncommitted_bytes() > 0 && ::ftruncate(fd_, off_t(start_)) != 0)
      throw Error(ErrorCode::WriteFailed,
                  path_ + ": cannot cut the uncommitted tail: " + std::strerror(errno));
    // Before anything else past the end: the pending record (synced), which tells readers that
    // the bytes after the committed end are an edit in progress, not damage.
    const std::array<uint8_t, sb::kSizeV1> pending = encode_pending(start_, generation_ + 1);
    append(pending.data(), pending.size());
    sync();
  } catch (...) {
    ::close(fd_);
    throw;
  }
}

ContainerUpdater::~ContainerUpdater() {
  if (fd_ >= 0) ::close(fd_);
}

void ContainerUpdater::write_at(uint64_t offset, const uint8_t* data, size_t size) {
  for (size_t done = 0; done < size;) {
    const ssize_t n = ::pwrite(fd_, data + done, size - done, off_t(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw Error(ErrorCode::WriteFailed, path_ + ": cannot write: " + std::strerror(errno));
    done += size_t(n);
  }
}

void ContainerUpdater::sync() {
  if (::fsync(fd_) != 0)
    throw Error(ErrorCode::WriteFailed, path_ + ": cannot sync: " + std::strerror(errno));
}

uint64_t ContainerUpdater::append(const uint8_t* data, size_t size) {
  if (committed_) throw std::logic_error("ContainerUpdater used after commit()");
  const uint64_t at = align_up(end_);
  static const uint8_t zeros[kAlignment] = {};
  if (at > end_) write_at(end_, zeros, size_t(at - end_));
  write_at(at, data, size);
  end_ = at + size;
  return at;
}

void ContainerUpdater::set_level(uint32_t level, uint64_t offset, uint64_t size, uint32_t crc) {
  offsets_.at(level) = offset;
  sizes_.at(level) = size;
  crcs_.at(level) = crc;
  has_crc_.at(level) = true;
}

uint64_t ContainerUpdater::commit(CommitStop stop) {
  if (committed_) throw std::logic_error("ContainerUpdater::commit() called twice");
  if (stop == CommitStop::AfterBlobs) {
    committed_ = true;
    return end_;
  }
  IndexPlacement placement;
  for (size_t l = 0; l < offsets_.size(); ++l)
    placement.levels.push_back({offsets_[l], sizes_[l], crcs_[l], bool(has_crc_[l])});
  placement.has_mask = mask_size_ > 0;
  placement.mask_offset = mask_offset_;
  placement.mask_size = mask_size_;
  placement.mask_crc = mask_crc_;
  placement.void_count = info_.void_count;
  placement.metadata_offset = metadata_offset_;
  placement.metadata_size = metadata_size_;
  placement.metadata_crc = metadata_crc_;
  const std::vector<uint8_t> index = encode_index(info_, placement);
  const uint64_t index_offset = append(index.data(), index.size());
  if (stop == CommitStop::AfterIndex) {
    committed_ = true;
    return end_;
  }
  SuperblockFields fields;
  fields.index_offset = index_offset;
  fields.index_size = index.size();
  fields.index_crc = crc32c(index.data(), index.size());
  fields.flags = sb::kFlagEdited;
  fields.generation = generation_ + 1;
  fields.file_size = align_up(end_) + sb::kSizeV1;
  const std::array<uint8_t, sb::kSizeV1> super = encode_superblock(fields);
  append(super.data(), super.size());  // the tail copy: what a torn superblock falls back to
  committed_ = true;
  sync();
  // The commit point. A torn write here leaves a superblock failing its CRC: readers take the tail.
  write_at(0, super.data(), stop == CommitStop::TornSuperblock ? 20 : super.size());
  if (stop == CommitStop::TornSuperblock) return fields.file_size;
  sync();
  return fields.file_size;
}

}  // namespace terrain::container
