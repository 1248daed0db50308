// The integer unit in which the pyramid stores an input's heights (the level unit).
#pragma once

#include "readers/heightmap.h"

namespace terrain {

// The level unit of an input: metres per unit and the native->level value scale
// (level value = round(native * value_scale); metres = level value * metres_per_unit + offset_metres).
struct LevelUnits {
  double metres_per_unit = 1;
  double value_scale = 1;
  double offset_metres = 0;
};
// Integer input with quantum_metres <= 0 keeps its own unit (|vertical_scale| metres; a negative
// scale flips the sign); otherwise the unit is quantum_metres (0.01 m when <= 0). Pure; never throws.
LevelUnits level_units(const GridInfo& info, double quantum_metres);

}  // namespace terrain
