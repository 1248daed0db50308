// level_units: the integer level unit of an input (pyramid/level_units.h).
#include "pyramid/level_units.h"

#include <cmath>

namespace terrain {

LevelUnits level_units(const GridInfo& info, double quantum_metres) {
  LevelUnits u;
  u.offset_metres = info.vertical_offset;
  if (info.integer_valued() && quantum_metres <= 0) {
    u.metres_per_unit = std::abs(info.vertical_scale);
    u.value_scale = info.vertical_scale < 0 ? -1 : 1;
  } else {
    const double q = quantum_metres > 0 ? quantum_metres : 0.01;
    u.metres_per_unit = q;
    u.value_scale = info.vertical_scale / q;
  }
  return u;
}

}  // namespace terrain
