// Brush shapes: names and the radial profile an edit adds.
#include <string>

#include "edit/pyramid_edit.h"

namespace terrain::edit {

const char* brush_shape_name(BrushShape shape) {
  switch (shape) {
    case BrushShape::Cone:
      return "cone";
    case BrushShape::Smooth:
      return "smooth";
    case BrushShape::Flat:
      return "flat";
  }
  return "unknown";
}

bool parse_brush_shape(const std::string& name, BrushShape* out) {
  for (BrushShape s : {BrushShape::Cone, BrushShape::Smooth, BrushShape::Flat})
    if (name == brush_shape_name(s)) {
      *out = s;
      return true;
    }
  return false;
}

}  // namespace terrain::edit
