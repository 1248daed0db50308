// Opening input files without surprises: a FIFO, a device or a directory given as an input must be
// refused at once, not block the process (a FIFO's open() waits for a writer) or be read forever.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace terrain {

// Opens `path` read-only (O_CLOEXEC; O_NONBLOCK while opening, so a FIFO cannot block) and returns
// the descriptor of a regular file, with its size in *size when size is not null. Throws
// Error(NotFound, "<path>: ...") when it is missing, unreadable or not a regular file. The caller
// closes the descriptor. Thread-safe.
int open_regular_file(const std::string& path, uint64_t* size = nullptr);

// Outputs are written to a temporary file and renamed over the target, which would replace a device
// node or FIFO by a regular file (as root, `-o /dev/null` did). Throws Error(WriteFailed, "<path>:
// ...") when `path` exists and is not a regular file (symbolic links are followed), or when it is
// the same file as one of `inputs` (device and inode compared; inputs that do not exist are ignored).
void check_output_path(const std::string& path, const std::vector<std::string>& inputs = {});

// Creates the temporary file an output `path` is written to before it is renamed over `path`:
// `<path>.tmp.XXXXXX<suffix>` in the same directory, the X a random part, created O_CREAT|O_EXCL
// (mkostemps), so that a link planted at a predictable name is never followed and two writers of
// one target (threads or processes) never share a temporary. Mode 0666 less the umask, as a file
// created by open(). `suffix` keeps an extension last where the writer chooses a format by it
// (".png"). Returns the descriptor (O_CLOEXEC, read-write); the name goes to *temp. Throws
// Error(WriteFailed, "<path>: ...") when it cannot be created.
int create_temp_beside(const std::string& path, const std::string& suffix, std::string* temp);

}  // namespace terrain
