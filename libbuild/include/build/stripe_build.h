// The build cut into stripes of finest rows, each coded into a part file of its own, so that the
// stripes can be shared out among processes (MPI ranks: build/mpi_group.h) and a killed build can
// resume from the stripes it completed. Rank 0 then lays the .pyr out from the parts' record
// indexes, level by level, through the same PyramidFileWriter as the one-process build (the bytes
// are the same: docs/scale.md says why), and every process copies its own parts' band streams into
// their places in it (so the processes must share the output's filesystem, as they share the parts').
//
// Layout beside the output OUT: OUT.build/journal (the fingerprint of input and options; a journal
// that does not match makes the directory start over) and OUT.build/stripe-K-k.part, one per
// completed stripe (written to a temporary name, renamed when complete: a part that exists is
// complete). OUT itself appears only at the final rename; OUT.build is removed after it.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "container/pyramid_file.h"
#include "pyramid/pyramid.h"
#include "readers/heightmap.h"

namespace terrain::build {

// The processes that share one build (MPI ranks, or this process alone).
class ProcessGroup {
 public:
  virtual ~ProcessGroup() = default;
  virtual int rank() const = 0;  // 0 .. size() - 1; rank 0 writes the output
  virtual int size() const = 0;
  // Collective (every process calls it, a barrier): true when every process passed true.
  virtual bool all_true(bool value) = 0;
  // Collective: every process's `mine`, in rank order (this process's own included, moved: the
  // level rows it carries are tens of MiB, and one process alone would otherwise copy them).
  virtual std::vector<std::vector<uint8_t>> all_gather(std::vector<uint8_t> mine) = 0;
};

// This process alone.
class SingleProcess final : public ProcessGroup {
 public:
  int rank() const override { return 0; }
  int size() const override { return 1; }
  bool all_true(bool value) override { return value; }
  std::vector<std::vector<uint8_t>> all_gather(std::vector<uint8_t> mine) override {
    std::vector<std::vector<uint8_t>> all(1);
    all[0] = std::move(mine);
    return all;
  }
};

struct StripeBuildOptions {
  std::string directory;    // OUT.build
  std::string fingerprint;  // input and options: parts of another build are never reused
  int stripes = 1;          // stripes of whole finest bands (fewer when the input has fewer bands)
  bool resume = true;       // false: complete parts of a matching journal are coded again
  // With two or more stripes: levels 0..k are coded once, from the stripes' rows of T_k put together
  // (exchanged with ProcessGroup::all_gather), and each stripe codes levels k+1..m only (docs/scale.md
  // "Cost of the decomposition"); the bytes are the same either way. false: every stripe codes all.
  bool share_coarse_levels = true;
  ProcessGroup* group = nullptr;         // null: this process alone
  std::function<void(double)> progress;  // fraction of this process's stripes done
};

// The directory beside `output` that holds the journal and the parts.
std::string stripe_directory(const std::string& output);

// Codes this process's stripes (stripe k goes to rank k % size) into parts, skipping those a
// matching journal already has complete; then, when every process succeeded, rank 0 lays out the
// writer `open_output` creates (only then: a killed build leaves no temporary output) and every
// process writes its parts' streams into it (on `options.threads` threads), rank 0 combining their
// CRCs into the level CRCs; the caller's finish() on rank 0 completes the file. Returns, on rank 0, the whole
// build's result as build_pyramid gives it (figures added in band order); elsewhere the result of this
// process's first stripe. `open_input` opens the input again at row 0 (each stripe reads from the top).
// `stripes_resumed` (if not null) receives the number of parts reused. Throws as build_pyramid;
// Error(WriteFailed) for a part that cannot be written, Error(CorruptData/ChecksumMismatch) for a
// part damaged between the check and the assembly (a damaged part found at the start is coded
// again), Error(WriteFailed, "another process failed") on the processes that did not fail
// themselves. Collective: every process of the group calls it, from one thread (the builder uses
// options.threads workers inside). The parts are trusted as files this build wrote: their records
// are bounds- and CRC-checked, not defended against a forger.
BuildResult build_stripes(const std::function<std::unique_ptr<BandReader>()>& open_input,
                          const BuildOptions& options, ResidualCoder& coder,
                          const StripeBuildOptions& stripes,
                          const std::function<container::PyramidFileWriter&()>& open_output,
                          int* stripes_resumed = nullptr);

// The stripe count of the journal in `directory` when its fingerprint starts with `base` (the input
// and options without the stripe count), else 0: a resumed build keeps the stripes of the killed one
// whatever its process count.
int read_journal_stripes(const std::string& directory, const std::string& base);

// Removes the directory of the parts after the output is complete (missing: nothing to do).
void remove_stripe_directory(const std::string& directory);

}  // namespace terrain::build
