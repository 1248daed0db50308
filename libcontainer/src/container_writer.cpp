// Streaming container writer: blobs go to a temporary file in level order (a level that arrives
// early waits in a HeldBytes), the mask, metadata and index follow, and the superblock (reserved
// as zeros at the start) is written last, so an interrupted write never carries a valid magic +
// checksum. finish() renames onto the target.
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <stdexcept>

#include "container/container.h"
#include "container/internal/container_format.h"
#include "container/internal/container_mask.h"
#include "container/internal/held_bytes.h"
#include "core/file.h"

namespace terrain::container {

using namespace layout;

namespace {

std::string directory_of(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  if (slash == std::string::npos) return ".";
  if (slash == 0) return "/";
  return path.substr(0, slash);
}

}  // namespace

ContainerWriter::LevelRecord::LevelRecord() = default;
ContainerWriter::LevelRecord::~LevelRecord() = default;
ContainerWriter::LevelRecord::LevelRecord(LevelRecord&&) noexcept = default;
ContainerWriter::LevelRecord& ContainerWriter::LevelRecord::operator=(LevelRecord&&) noexcept = default;

ContainerWriter::ContainerWriter(std::string path) : path_(std::move(path)), directory_(directory_of(path_)) {
  check_output_path(path_);
  fd_ = create_temp_beside(path_, "", &temp_path_);  // exclusive, random name: no two writers share it
  const uint8_t zeros[sb::kSizeV1] = {};             // superblock placeholder, overwritten by finish()
  try {
    write_bytes(zeros, sizeof zeros);
  } catch (...) {
    ::close(fd_);  // a throwing constructor gets no destructor
    ::unlink(temp_path_.c_str());
    throw;
  }
}

ContainerWriter::~ContainerWriter() {
  if (fd_ >= 0) ::close(fd_);
  if (!finished_) ::unlink(temp_path_.c_str());
}

void ContainerWriter::fail(const std::string& what) {
  const int err = errno;  // before any allocation below can disturb it
  throw Error(ErrorCode::WriteFailed, temp_path_ + ": " + what + ": " + std::strerror(err));
}

void ContainerWriter::write_bytes(const void* data, size_t size) {
  if (fd_ < 0) throw std::logic_error("ContainerWriter used after finish()");
  const uint8_t* p = static_cast<const uint8_t*>(data);
  while (size > 0) {
    const ssize_t n = ::write(fd_, p, size);
    if (n < 0) {
      if (errno == EINTR) continue;
      fail("cannot write");
    }
    p += n;
    size -= size_t(n);
    position_ += uint64_t(n);
  }
}

void ContainerWriter::pad_to_alignment() {
  const uint8_t zeros[kAlignment] = {};
  write_bytes(zeros, size_t(align_up(position_) - position_));
}

void ContainerWriter::set_info(const ContainerInfo& info) {
  validate_info(info);
  info_ = info;
}

void ContainerWriter::add_level(uint32_t level, const uint8_t* data, size_t size) {
  append_level(level, data, size);
  end_level(level);
}

ContainerWriter::LevelRecord& ContainerWriter::start_level(uint32_t level) {
  if (level >= kMaxLevels) throw std::invalid_argument("level index " + std::to_string(level) + " too large");
  if (records_.size() <= level) records_.resize(level + 1);
  LevelRecord& r = records_[level];
  if (r.ended) throw std::invalid_argument("level " + std::to_string(level) + " written twice");
  if (!r.started) {
    r.started = true;
    r.has_crc = level_checksums_;
  }
  return r;
}

// Fixes the level's place at the end of the file so far and writes what it held.
void ContainerWriter::place_level(uint32_t level) {
  LevelRecord& r = records_[level];
  if (r.placed) return;
  pad_to_alignment();
  r.placed = true;
  r.offset = position_;
  if (r.held) {
    r.held->drain([this](const uint8_t* data, size_t size) { write_bytes(data, size); });
    r.held.reset();
  }
}

void ContainerWriter::append_level(uint32_t level, const uint8_t* data, size_t size) {
  LevelRecord& r = start_level(level);
  if (size == 0) return;
  if (r.has_crc) r.crc = crc32c(data, size, r.crc);
  r.size += size;
  if (level == next_level_) {
    place_level(level);
    write_bytes(data, size);
  } else {
    if (!r.held) r.held = std::make_unique<detail::HeldBytes>(directory_, level_memory_limit_);
    r.held->append(data, size);
  }
}

uint64_t ContainerWriter::reserve_level(uint32_t level, uint64_t size) {
  LevelRecord& r = start_level(level);
  if (level != next_level_ || r.size != 0 || r.held)
    throw std::logic_error("reserve_level: level " + std::to_string(level) +
                           " is not the next level, or already has bytes");
  place_level(level);
  const uint64_t offset = position_;
  // The hole: later writes go after it; the file's size covers it once anything follows.
  if (::lseek(fd_, off_t(offset + size), SEEK_SET) < 0) fail("cannot extend the file");
  position_ += size;
  r.size = size;
  r.reserved = size;
  return offset;
}

void ContainerWriter::set_reserved_crc(uint32_t level, uint32_t crc) {
  // A hole of no bytes has the CRC of nothing, 0.
  if (level >= records_.size() || (records_[level].reserved == 0 && crc != 0))
    throw std::logic_error("set_reserved_crc: level " + std::to_string(level) + " has no reserved bytes");
  records_[level].reserved_crc = crc;
  records_[level].reserved_crc_set = true;
}

void ContainerWriter::end_level(uint32_t level) {
  start_level(level).ended = true;
  // Every ended level from the first gap on goes into the file; the level at the gap, if begun,
  // now streams straight to the file.
  while (next_level_ < records_.size() && records_[next_level_].ended) place_level(next_level_++);
  if (next_level_ < records_.size() && records_[next_level_].started) place_level(next_level_);
}

void ContainerWriter::append_mask(const uint8_t* valid, size_t count) {
  // Scans whole runs at a time (memchr for the end of a data run, 8 bytes at a time through a
  // void run): masks of large grids are mostly long runs.
  size_t i = 0;
  while (i < count) {
    size_t stop;
    if (current_run_valid_) {
      const void* zero = std::memchr(valid + i, 0, count - i);
      stop = zero ? size_t(static_cast<const uint8_t*>(zero) - valid) : count;
    } else {
      stop = i;
      uint64_t word = 0;
      while (stop + 8 <= count && (std::memcpy(&word, valid + stop, 8), word == 0)) stop += 8;
      while (stop < count && valid[stop] == 0) ++stop;
      mask_voids_ += stop - i;
    }
    current_run_ += stop - i;
    i = stop;
    if (i < count) {  // the run ends inside this call: the next sample starts the other kind
      mask_runs::put_varint(mask_runs_, current_run_);
      current_run_valid_ = !current_run_valid_;
      current_run_ = 0;
    }
  }
  mask_samples_ += count;
}

void ContainerWriter::set_metadata_json(std::string json) { metadata_json_ = std::move(json); }

void ContainerWriter::finish() {
  if (finished_ || finish_started_)
    throw std::logic_error("finish() called again after it finished or failed");
  if (!info_) throw std::invalid_argument("finish: set_info() was never called");
  const ContainerInfo& info = *info_;
  const size_t level_count = info.levels.size();
  if (records_.size() > level_count) {
    throw std::invalid_argument("finish: level " + std::to_string(records_.size() - 1) +
                                " written but info has " + std::to_string(level_count) + " levels");
  }
  for (size_t l = 0; l < records_.size(); ++l)
    if (records_[l].started && !records_[l].ended)
      throw std::logic_error("finish: level " + std::to_string(l) + " is still open");
  for (size_t l = 0; l < level_count; ++l) {
    if (l >= records_.size() || !records_[l].ended) {
      throw std::invalid_argument("finish: level " + std::to_string(l) + " was never written");
    }
    if (records_[l].reserved != 0 && !records_[l].reserved_crc_set)
      throw std::logic_error("finish: level " + std::to_string(l) + "'s reserved bytes have no CRC");
  }
  const uint64_t samples = info.width * info.height;
  if (mask_samples_ != 0 && mask_samples_ != samples) {
    throw std::invalid_argument("finish: mask has " + std::to_string(mask_samples_) + " samples, grid has " +
                                std::to_string(samples));
  }

  // Mask region (only when there are voids), then metadata, then the index. From here on a
  // failure leaves the writer unusable: the destructor removes the temporary file.
  finish_started_ = true;
  const bool has_mask = mask_voids_ > 0;
  if (has_mask) mask_runs::put_varint(mask_runs_, current_run_);
  pad_to_alignment();
  const uint64_t mask_offset = position_;
  const uint64_t mask_size = has_mask ? mask_runs_.size() : 0;
  const uint32_t mask_crc = has_mask ? crc32c(mask_runs_.data(), mask_runs_.size()) : 0;
  if (has_mask) write_bytes(mask_runs_.data(), mask_runs_.size());
  pad_to_alignment();
  const uint64_t metadata_offset = position_;
  write_bytes(metadata_json_.data(), metadata_json_.size());
  pad_to_alignment();

  IndexPlacement placement;
  for (size_t l = 0; l < level_count; ++l) {
    const LevelRecord& r = records_[l];
    const uint32_t crc = r.reserved ? crc32c_combine(r.reserved_crc, r.crc, r.size - r.reserved) : r.crc;
    placement.levels.push_back({r.offset, r.size, crc, r.has_crc});
  }
  placement.has_mask = has_mask;
  placement.mask_offset = has_mask ? mask_offset : 0;
  placement.mask_size = mask_size;
  placement.mask_crc = mask_crc;
  placement.void_count = mask_voids_;
  placement.metadata_offset = metadata_offset;
  placement.metadata_size = metadata_json_.size();
  placement.metadata_crc = crc32c(metadata_json_.data(), metadata_json_.size());
  const std::vector<uint8_t> index = encode_index(info, placement);
  const uint64_t index_offset = position_;
  write_bytes(index.data(), index.size());

  SuperblockFields fields;
  fields.file_size = position_;
  fields.index_offset = index_offset;
  fields.index_size = index.size();
  fields.index_crc = crc32c(index.data(), index.size());
  const std::array<uint8_t, sb::kSizeV1> super_bytes = encode_superblock(fields);
  const uint8_t* super = super_bytes.data();
  for (size_t done = 0; done < sb::kSizeV1;) {
    const ssize_t n = ::pwrite(fd_, super + done, sb::kSizeV1 - done, off_t(done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) fail("cannot write superblock");
    done += size_t(n);
  }

  if (::fsync(fd_) != 0) fail("cannot sync");
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) fail("cannot close");
  check_output_path(path_);  // again: something may have been put there while we wrote
  if (::rename(temp_path_.c_str(), path_.c_str()) != 0) {
    throw Error(ErrorCode::WriteFailed,
                path_ + ": cannot rename " + temp_path_ + " onto it: " + std::strerror(errno));
  }
  finished_ = true;
  // The rename is durable only once the directory entry is synced; failure here loses nothing
  // written, so it is not an error (some filesystems refuse fsync on directories).
  const int dir = ::open(directory_.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dir >= 0) {
    ::fsync(dir);
    ::close(dir);
  }
}

}  // namespace terrain::container
