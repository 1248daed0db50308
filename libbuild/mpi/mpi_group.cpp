// ProcessGroup over MPI_COMM_WORLD. Only collectives the stripe build needs: all_true, and all_gather
// for the shared coarse levels' rows (each process writes its parts, rank 0 reads them).
#include "build/mpi_group.h"

// The C API only: Open MPI's deprecated C++ bindings would need libmpi_cxx.
#define OMPI_SKIP_MPICXX 1
#define MPICH_SKIP_MPICXX 1
#include <mpi.h>

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <stdexcept>
#include <vector>

namespace terrain::build {
namespace {

class MpiWorld final : public ProcessGroup {
 public:
  MpiWorld(int* argc, char*** argv) {
    int started = 0;
    MPI_Initialized(&started);
    if (!started) MPI_Init(argc, argv);
    MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
    MPI_Comm_size(MPI_COMM_WORLD, &size_);
  }
  ~MpiWorld() override {
    int finalized = 0;
    MPI_Finalized(&finalized);
    if (!finalized) MPI_Finalize();
  }
  int rank() const override { return rank_; }
  int size() const override { return size_; }
  bool all_true(bool value) override {
    int in = value ? 1 : 0, out = 0;
    MPI_Allreduce(&in, &out, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
    return out != 0;
  }
  std::vector<std::vector<uint8_t>> all_gather(std::vector<uint8_t> mine) override {
    std::vector<long long> sizes(size_t(size_), 0);
    long long n = (long long)mine.size();
    MPI_Allgather(&n, 1, MPI_LONG_LONG, sizes.data(), 1, MPI_LONG_LONG, MPI_COMM_WORLD);
    std::vector<std::vector<uint8_t>> all(static_cast<size_t>(size_));
    // One broadcast per rank, in pieces of at most 1 GiB (MPI's counts are int).
    constexpr long long kPiece = 1LL << 30;
    for (int r = 0; r < size_; ++r) {
      std::vector<uint8_t>& v = all[size_t(r)];
      if (r == rank_)
        v = std::move(mine);
      else
        v.resize(size_t(sizes[size_t(r)]));
      for (long long at = 0; at < sizes[size_t(r)]; at += kPiece) {
        const int count = int(std::min(kPiece, sizes[size_t(r)] - at));
        if (MPI_Bcast(v.data() + at, count, MPI_BYTE, r, MPI_COMM_WORLD) != MPI_SUCCESS)
          throw std::runtime_error("MPI_Bcast failed");
      }
    }
    return all;
  }

 private:
  int rank_ = 0, size_ = 1;
};

}  // namespace

bool launched_by_mpi() {
  for (const char* v : {"OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_SIZE"})
    if (std::getenv(v)) return true;
  return false;
}

int local_process_count() {
  const char* v = std::getenv("OMPI_COMM_WORLD_LOCAL_SIZE");
  const int n = v ? std::atoi(v) : 1;
  return n > 0 ? n : 1;
}

std::unique_ptr<ProcessGroup> mpi_world(int* argc, char*** argv) {
  return std::make_unique<MpiWorld>(argc, argv);
}

}  // namespace terrain::build
