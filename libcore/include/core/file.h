// Opening input files without surprises: a FIFO, a device or a directory given as an input must be
// refused at once, not block the process (a FIFO's open() waits for a writer) or be read forever.
#pragma once

#include <cstdint>
#include <string>

namespace terrain {

// Opens `path` read-only (O_CLOEXEC; O_NONBLOCK while opening, so a FIFO cannot block) and returns
// the descriptor of a regular file, with its size in *size when size is not null. Throws
// Error(NotFound, "<path>: ...") when it is missing, unreadable or not a regular file. The caller
// closes the descriptor. Thread-safe.
int open_regular_file(const std::string& path, uint64_t* size = nullptr);

}  // namespace terrain
