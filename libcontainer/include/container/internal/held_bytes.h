// Bytes that must wait before they can go to their place in the output: a level blob that arrives
// while the levels before it are still being written. Kept in memory up to a bound, the rest in a
// spill file that has no name (nothing is left behind, even if the process dies).
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace terrain::container::detail {

class HeldBytes {
 public:
  // The first memory_limit bytes stay in memory; the rest go to a spill file created in `dir` on
  // the first byte beyond the limit (the output's directory: the spilled bytes end up in the output
  // there anyway). Not thread-safe.
  HeldBytes(std::string dir, size_t memory_limit);
  ~HeldBytes();  // closes the spill file, which frees its blocks
  HeldBytes(const HeldBytes&) = delete;
  HeldBytes& operator=(const HeldBytes&) = delete;

  // Throws Error(WriteFailed) naming the directory when the spill file cannot be created or
  // written.
  void append(const uint8_t* data, size_t size);
  // Hands every held byte to `out`, in order and in pieces, then holds nothing. Throws
  // Error(WriteFailed) when the spill file cannot be read back in full.
  void drain(const std::function<void(const uint8_t*, size_t)>& out);
  uint64_t size() const { return memory_.size() + spilled_; }
  bool spilled() const { return fd_ >= 0; }

 private:
  std::string dir_;
  size_t memory_limit_;
  std::vector<uint8_t> memory_;
  int fd_ = -1;
  uint64_t spilled_ = 0;
};

// An unnamed read-write file in `dir`: O_TMPFILE where the filesystem has it, else an exclusively
// created random name that is unlinked at once. Returns the descriptor; throws
// Error(WriteFailed) naming `dir`.
int create_unnamed_file(const std::string& dir);

}  // namespace terrain::container::detail
