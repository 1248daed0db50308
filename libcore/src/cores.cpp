#include "core/cores.h"

#include <sched.h>

#include <algorithm>
#include <cerrno>
#include <thread>
#include <vector>

namespace terrain {

int usable_cores() {
  const int all = int(std::max(1u, std::thread::hardware_concurrency()));
  // A mask sized for the machine's CPUs (the fixed cpu_set_t holds 1024; larger hosts exist).
  for (size_t cpus = std::max<size_t>(1024, size_t(all)); cpus <= (size_t(1) << 20); cpus *= 2) {
    std::vector<cpu_set_t> set(CPU_ALLOC_SIZE(cpus) / sizeof(cpu_set_t) + 1);
    const size_t bytes = CPU_ALLOC_SIZE(cpus);
    if (sched_getaffinity(0, bytes, set.data()) == 0) return std::max(1, CPU_COUNT_S(bytes, set.data()));
    if (errno != EINVAL) break;  // EINVAL: the kernel's mask is larger than ours
  }
  return all;
}

}  // namespace terrain
