// How many cores a process may use, for the default thread count of the tools and libraries.
#pragma once

namespace terrain {

// The cores this process may run on: the size of its CPU affinity mask, which is what `taskset`, a
// cgroup cpuset or an MPI launcher's binding (`mpirun --bind-to core`, Open MPI's default at -np 2
// and below) leaves it; std::thread::hardware_concurrency() where the mask cannot be read. At least
// 1. Thread-safe; reads the mask at every call (a process may be re-bound).
int usable_cores();

}  // namespace terrain
