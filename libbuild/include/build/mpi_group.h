// The MPI world as a ProcessGroup, for pyramid-build under mpirun (docs/scale.md). Only in builds
// with TERRAIN_MPI (target build_mpi, Open MPI from Debian's libopenmpi-dev); the plain build
// needs no MPI.
#pragma once

#include <memory>

#include "build/stripe_build.h"

namespace terrain::build {

// True when this process was started by mpirun/mpiexec (Open MPI's or a PMI launcher's
// environment); needs no MPI library. Thread-safe.
bool launched_by_mpi();
// Processes of this job on this host (OMPI_COMM_WORLD_LOCAL_SIZE), 1 when unknown: a rank's share
// of the host's cores.
int local_process_count();

// MPI_Init (once per process), MPI_COMM_WORLD's rank and size; MPI_Finalize when destroyed.
// all_true is an MPI_Allreduce (a barrier). Call from the main thread only.
std::unique_ptr<ProcessGroup> mpi_world(int* argc, char*** argv);

}  // namespace terrain::build
