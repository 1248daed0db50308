// Live terrain edits over any height source, in memory: brushes (a bump or a pit around a point) and
// channels (the same profile around a segment, a brush dragged along a path), added to the base's
// heights on every level. The stand-in for editing the pyramid file itself (libedit, issue 20): the
// clipmap sees a source whose heights change and refills what Clipmap::invalidate marks.
//
// Coarser levels: the edit's profile evaluated at each level's sample positions (sample (i, j) of a
// level k steps coarser sits on finest sample (2^k i, 2^k j)), not D of the finest level's change:
// for profiles wider than D's support the two differ little, and the clipmap needs only that every
// level changes inside what invalidate marks.
//
// Threads: not thread-safe (drives the base source); use one per thread.
#pragma once

#include <string>
#include <vector>

#include "runtime/height_source.h"

namespace terrain::runtime {

enum class EditShape { Cone, Smooth, Flat };
// The shape's profile at r = distance / radius, 0 <= r <= 1: cone 1 - r, smooth (1 - r^2)^2, flat 1.
// Callers decide whether r = 1 still counts (the overlay stops before it, libedit's brush includes it).
double edit_profile(EditShape shape, double r);
// "cone", "smooth", "flat"; false for any other name.
bool parse_edit_shape(const std::string& name, EditShape* out);

struct TerrainEdit {
  // The segment (x0, y0) - (x1, y1) in finest-level samples (a brush: both ends the same point);
  // samples within `radius` samples of it get height * profile(distance / radius) metres added.
  double x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  double radius = 1, height = 0;
  EditShape shape = EditShape::Smooth;
};

// The finest-level samples `edit` changes (a rectangle covering the segment grown by the radius).
Rect edit_bounds(const TerrainEdit& edit);
// Metres the edit adds at finest-level position (x, y) (0 beyond the radius).
double edit_delta(const TerrainEdit& edit, double x, double y);
// "cone", "smooth" or "flat".
const char* edit_shape_name(EditShape shape);

class EditOverlaySource final : public HeightSource {
 public:
  explicit EditOverlaySource(HeightSource& base) : base_(base) {}  // base must outlive this
  int level_count() const override { return base_.level_count(); }
  GridSize level_size(int level) const override { return base_.level_size(level); }
  double spacing_m() const override { return base_.spacing_m(); }
  void fill(int level, const Rect& rect, float* out, int64_t out_stride) override;
  // The base's integer units pass through unchanged (a finer level refines the coarser one's base
  // units, then gets its own edits added to the heights), so a compressed pyramid keeps its fast path.
  bool refines_units() const override { return base_.refines_units(); }
  void fill_units(int level, const Rect& rect, const HeldUnits* coarser, float* out, int32_t* units_out,
                  int64_t out_stride, FillSplit* split) override;
  // Adds an edit (applied after those before it); returns the finest-level samples it changes
  // (for Clipmap::invalidate). Throws std::invalid_argument for a non-finite field or radius <= 0.
  Rect add(const TerrainEdit& edit);
  size_t edit_count() const { return edits_.size(); }

 private:
  void add_edits(int level, const Rect& rect, float* out, int64_t out_stride) const;
  HeightSource& base_;
  std::vector<TerrainEdit> edits_;
};

}  // namespace terrain::runtime
