// Spill files of the out-of-core builder.
#include "pyramid/internal/pyramid_spill.h"

#include <cerrno>
#include <cstring>

#include "readers/heightmap.h"

namespace terrain::detail {

SpillFile::SpillFile(std::string path) : path_(std::move(path)) {
  file_ = std::fopen(path_.c_str(), "w+b");
  if (!file_)
    throw Error(ErrorCode::WriteFailed, path_ + ": cannot create spill file: " + std::strerror(errno));
  std::setvbuf(file_, nullptr, _IOFBF, size_t(1) << 20);
}

SpillFile::~SpillFile() {
  if (file_) std::fclose(file_);
  std::remove(path_.c_str());
}

void SpillFile::write(const void* data, size_t bytes) {
  if (bytes && std::fwrite(data, 1, bytes, file_) != bytes)
    throw Error(ErrorCode::WriteFailed, path_ + ": cannot write spill file (disk full?)");
}

void SpillFile::rewind_for_reading() {
  if (std::fflush(file_) != 0) throw Error(ErrorCode::WriteFailed, path_ + ": cannot flush spill file");
  std::rewind(file_);
}

void SpillFile::read(void* data, size_t bytes) {
  if (bytes && std::fread(data, 1, bytes, file_) != bytes)
    throw Error(ErrorCode::Truncated, path_ + ": spill file shorter than expected");
}

bool SpillFile::read_byte(uint8_t* b) {
  const int c = std::fgetc(file_);
  if (c == EOF) return false;
  *b = uint8_t(c);
  return true;
}

}  // namespace terrain::detail
