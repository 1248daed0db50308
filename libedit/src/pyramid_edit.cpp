// PyramidEditor: an edit of the finest level carried through the pyramid and written copy-on-write.
//
// Per commit: the queued brushes and patches become Delta, an integer change of the finest level in
// level units on a window; Delta_l = round(D(Delta_{l+1})) on a window padded by D's radius (plus one
// for the even alignment), the level's own mirror rule applying where the window meets its edge.
// Then from the coarsest level up, band by band over the rows the change can reach: the target
// T_l = T^_l + Delta_l, U of the already re-coded coarser level, the residual T_l - U; a tile is
// dirty when its Delta_l or its U differs anywhere (compared exactly, so the reach rectangles only
// bound the work and never decide what is re-coded). A band with dirty tiles is coded again with
// the band stream's own step / max error and its clean tiles' payloads are spliced back in verbatim
// (codec::splice_tiles), so their reconstruction, and everything that depends on it, is unchanged.
#include "edit/pyramid_edit.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <optional>
#include <stdexcept>
#include <string>
#include <variant>

#include "build/ptc_coder.h"
#include "codec/codec.h"
#include "container/container.h"
#include "container/pyramid_file.h"
#include "core/error.h"
#include "pyramid/builder.h"
#include "pyramid/downsample.h"
#include "pyramid/level_units.h"
#include "pyramid/reference.h"
#include "pyramid/upsample.h"
#include "runtime/region_decoder.h"

namespace terrain::edit {
namespace {

using container::BandView;
using container::PyramidFile;

// Half-open box of samples.
struct Box {
  int64_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  bool empty() const { return x1 <= x0 || y1 <= y0; }
  int64_t width() const { return x1 - x0; }
  int64_t height() const { return y1 - y0; }
  Rect rect() const { return Rect{x0, y0, x1 - x0, y1 - y0}; }
};
Box unite(const Box& a, const Box& b) {
  if (a.empty()) return b;
  if (b.empty()) return a;
  return {std::min(a.x0, b.x0), std::min(a.y0, b.y0), std::max(a.x1, b.x1), std::max(a.y1, b.y1)};
}
Box intersect(const Box& a, const Box& b) {
  return {std::max(a.x0, b.x0), std::max(a.y0, b.y0), std::min(a.x1, b.x1), std::min(a.y1, b.y1)};
}
Box level_box(GridSize s) { return {0, 0, s.width, s.height}; }
Box grow(const Box& b, int64_t m) { return {b.x0 - m, b.y0 - m, b.x1 + m, b.y1 + m}; }

// An int32 image of part of a level.
struct Window {
  Box box;
  std::vector<int32_t> v;
  int32_t& at(int64_t x, int64_t y) { return v[size_t((y - box.y0) * box.width() + (x - box.x0))]; }
  int32_t get(int64_t x, int64_t y) const {
    if (x < box.x0 || x >= box.x1 || y < box.y0 || y >= box.y1) return 0;
    return v[size_t((y - box.y0) * box.width() + (x - box.x0))];
  }
};

// Bounding box of the non-zero samples.
Box nonzero_box(const Window& w) {
  Box b{w.box.x1, w.box.y1, w.box.x0, w.box.y0};
  for (int64_t y = w.box.y0; y < w.box.y1; ++y)
    for (int64_t x = w.box.x0; x < w.box.x1; ++x)
      if (w.get(x, y) != 0)
        b = {std::min(b.x0, x), std::min(b.y0, y), std::max(b.x1, x + 1), std::max(b.y1, y + 1)};
  return b.empty() ? Box{} : b;
}

// w cut down to its non-zero samples (empty when all are zero).
Window crop_nonzero(const Window& w) {
  const Box nz = nonzero_box(w);
  if (nz.empty()) return {};
  Window out{nz, std::vector<int32_t>(size_t(nz.width() * nz.height()))};
  for (int64_t y = nz.y0; y < nz.y1; ++y)
    for (int64_t x = nz.x0; x < nz.x1; ++x) out.at(x, y) = w.get(x, y);
  return out;
}

// Delta_l = round(D(Delta_{l+1})) where Delta_{l+1} is zero outside fine.box. The fine window is padded
// by D's radius + 1 (zeros), aligned to even samples and clipped to the level, so D sees exactly the
// samples it sees in the whole level (zeros beyond the non-zero box, the level's mirror at its edges).
Window downsample_delta(const DownsampleFilter& d, const Window& fine, GridSize fine_level) {
  Box p = intersect(grow(fine.box, DownsampleFilter::kRadius + 1), level_box(fine_level));
  p.x0 -= p.x0 % 2;
  p.y0 -= p.y0 % 2;
  Window padded{p, std::vector<int32_t>(size_t(p.width() * p.height()), 0)};
  for (int64_t y = fine.box.y0; y < fine.box.y1; ++y)
    for (int64_t x = fine.box.x0; x < fine.box.x1; ++x) padded.at(x, y) = fine.get(x, y);
  Window coarse;
  coarse.box = {p.x0 / 2, p.y0 / 2, p.x0 / 2 + coarse_extent(p.width()),
                p.y0 / 2 + coarse_extent(p.height())};
  coarse.v.assign(size_t(coarse.box.width() * coarse.box.height()), 0);
  downsample(d, padded.v.data(), GridSize{p.width(), p.height()}, coarse.v.data());
  // A padded side that stops inside the level mirrors zeros: its coarse samples there are those of
  // the whole level only where D's support stays inside the window, which the padding guarantees for
  // every coarse sample whose support reaches the non-zero box.
  return crop_nonzero(coarse);
}

using Edit = std::variant<Brush, Patch>;

Box edit_box(const Edit& e, GridSize finest) {
  Box b;
  if (const Brush* br = std::get_if<Brush>(&e))
    b = {int64_t(std::floor(br->x - br->radius)), int64_t(std::floor(br->y - br->radius)),
         int64_t(std::floor(br->x + br->radius)) + 1, int64_t(std::floor(br->y + br->radius)) + 1};
  else {
    const Patch& p = std::get<Patch>(e);
    b = {p.x, p.y, p.x + p.width, p.y + p.height};
  }
  return intersect(b, level_box(finest));
}

// The bands of a level as the editor treats them: the file's bands, with runs of all-zero bands cut
// into pieces of the level's band height (any split is valid: readers take heights from the table).
struct EditBand {
  int64_t y0 = 0, rows = 0;
  const uint8_t* data = nullptr;
  size_t size = 0;
};

std::vector<EditBand> edit_bands(const PyramidFile& f, int level) {
  const auto& views = f.bands(level);
  const GridSize s = f.level_size(level);
  int64_t band_rows = 0;
  for (const BandView& v : views)
    if (!v.empty()) {
      band_rows = v.rows;
      break;
    }
  if (band_rows == 0) band_rows = std::min<int64_t>(s.height, 128);
  std::vector<EditBand> out;
  for (const BandView& v : views) {
    if (!v.empty()) {
      out.push_back({v.y0, v.rows, v.data, v.size});
      continue;
    }
    for (int64_t y = v.y0; y < v.y0 + v.rows; y += band_rows)
      out.push_back({y, std::min(band_rows, v.y0 + v.rows - y), nullptr, 0});
  }
  return out;
}

// The coding options of a level's streams, from the first stream found at that level (else at any
// level, with the file's tile size and quantisation: a level of all-zero bands).
PtcCoderOptions level_coder_options(const PyramidFile& f, int level) {
  const auto from_header = [](const codec::HeaderInfo& h) {
    PtcCoderOptions o;
    o.step = h.step;
    o.bound_max_error = h.bound_max_error;
    o.max_error = h.max_error;
    o.tile_size = h.tile_size;
    o.residual_transform = h.transform;
    o.phase_tiles = h.phase_tiles;
    return o;
  };
  for (const BandView& v : f.bands(level)) {
    codec::HeaderInfo h;
    if (!v.empty() && codec::read_header(v.data, v.size, &h) == codec::Status::Ok) return from_header(h);
  }
  PtcCoderOptions o;
  for (int l = f.level_count() - 1; l >= 0; --l)
    for (const BandView& v : f.bands(l)) {
      codec::HeaderInfo h;
      if (!v.empty() && codec::read_header(v.data, v.size, &h) == codec::Status::Ok) {
        o = from_header(h);
        l = -1;
        break;
      }
    }
  const container::Quantisation& q = f.info().quantisation;
  // A point-sampled pyramid codes its bounded levels (lossless: E = 0) with phase tiles (pyramid_build.cpp).
  const bool point = f.info().filter_provenance == container::FilterProvenance::Point;
  o.phase_tiles =
      point && (q.mode == container::ErrorMode::MaxError || q.mode == container::ErrorMode::Lossless);
  if (point && q.mode == container::ErrorMode::Lossless) {
    o.bound_max_error = true;
    o.max_error = 0;
    o.step = 0;
  } else if (q.mode == container::ErrorMode::MaxError) {
    o.bound_max_error = true;
    o.max_error = uint32_t(std::max(0.0, std::floor(q.target / std::abs(f.info().vertical_scale))));
    o.step = 0;
  } else {
    o.bound_max_error = false;
    o.step = std::max(1.0, q.step_units);
  }
  return o;
}

// Applies the edits in order to `cur` (metres of the samples of `box`, row-major).
void apply_edits(const std::vector<Edit>& edits, GridSize finest, const Box& box, std::vector<double>& cur) {
  for (const Edit& e : edits) {
    const Box b = edit_box(e, finest);
    for (int64_t y = b.y0; y < b.y1; ++y)
      for (int64_t x = b.x0; x < b.x1; ++x) {
        double& c = cur[size_t((y - box.y0) * box.width() + (x - box.x0))];
        if (const Brush* br = std::get_if<Brush>(&e)) {
          const double r = std::hypot(double(x) - br->x, double(y) - br->y) / br->radius;
          if (r <= 1) c += br->height * runtime::edit_profile(br->shape, r);
        } else {
          const Patch& p = std::get<Patch>(e);
          const float h = p.heights[size_t((y - p.y) * p.width + (x - p.x))];
          if (!std::isnan(h)) c = (1 - p.blend) * c + p.blend * double(h);
        }
      }
  }
}

// The window of a whole-level difference b - a where it is non-zero.
Window difference(const std::vector<int32_t>& a, const std::vector<int32_t>& b, GridSize s) {
  Window all{level_box(s), std::vector<int32_t>(a.size())};
  for (size_t i = 0; i < a.size(); ++i) all.v[i] = b[i] - a[i];
  return crop_nonzero(all);
}

}  // namespace

struct PyramidEditor::Impl {
  std::string path;
  std::shared_ptr<const PyramidFile> file;
  std::vector<Edit> edits;
  std::optional<Heightmap> source;
  BuildOptions source_options;  // how the builder turned it into level units
};

void PyramidEditor::set_source(const std::string& heightmap_path, const ReadOptions& read_options) {
  Heightmap map = read_heightmap(heightmap_path, read_options);
  const PyramidFile& f = *impl_->file;
  const GridSize fs = f.level_size(f.level_count() - 1);
  if (map.width() != fs.width || map.height() != fs.height)
    throw std::invalid_argument(heightmap_path + ": " + std::to_string(map.width()) + "x" +
                                std::to_string(map.height()) + " samples, but " + impl_->path +
                                "'s finest level is " + std::to_string(fs.width) + "x" +
                                std::to_string(fs.height));
  const double scale = f.info().vertical_scale;
  LevelUnits units = level_units(map.info, 0);
  if (units.metres_per_unit != scale) units = level_units(map.info, scale);
  if (units.metres_per_unit != scale)
    throw std::invalid_argument(heightmap_path + ": its level unit (" +
                                std::to_string(units.metres_per_unit) + " m) is not " + impl_->path + "'s (" +
                                std::to_string(scale) + " m)");
  BuildOptions bo;
  bo.level_count = f.level_count();
  bo.value_scale = units.value_scale;
  bo.value_offset = std::nearbyint((f.info().vertical_offset - units.offset_metres) / scale);
  bo.use_fixed_filter = true;
  bo.fixed_filter = f.downsample_filter();
  bo.threads = 1;
  impl_->source = std::move(map);
  impl_->source_options = bo;
}

PyramidEditor::PyramidEditor(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
PyramidEditor::~PyramidEditor() = default;
const std::string& PyramidEditor::path() const { return impl_->path; }
const Heightmap* PyramidEditor::source() const { return impl_->source ? &*impl_->source : nullptr; }

std::unique_ptr<PyramidEditor> PyramidEditor::open(const std::string& path) {
  auto impl = std::make_unique<Impl>();
  impl->path = path;
  impl->file = PyramidFile::open(path);
  return std::unique_ptr<PyramidEditor>(new PyramidEditor(std::move(impl)));
}

void PyramidEditor::apply(const Brush& b) {
  if (!std::isfinite(b.x) || !std::isfinite(b.y) || !std::isfinite(b.radius) || !std::isfinite(b.height))
    throw std::invalid_argument("brush: x, y, radius and height must be finite numbers");
  if (!(b.radius > 0)) throw std::invalid_argument("brush: radius must be > 0");
  const GridSize s = impl_->file->level_size(impl_->file->level_count() - 1);
  if (edit_box(b, s).empty())
    throw std::invalid_argument("brush at (" + std::to_string(b.x) + ", " + std::to_string(b.y) +
                                ") radius " + std::to_string(b.radius) + " lies outside the " +
                                std::to_string(s.width) + "x" + std::to_string(s.height) + " grid");
  impl_->edits.push_back(b);
}

void PyramidEditor::apply(const Patch& p) {
  if (p.width < 1 || p.height < 1 || p.heights.size() != size_t(p.width) * size_t(p.height))
    throw std::invalid_argument("patch: " + std::to_string(p.heights.size()) + " heights for a " +
                                std::to_string(p.width) + "x" + std::to_string(p.height) + " patch");
  if (!(p.blend >= 0 && p.blend <= 1)) throw std::invalid_argument("patch: blend must lie in [0, 1]");
  for (float h : p.heights)
    if (std::isinf(h)) throw std::invalid_argument("patch: infinite height");
  const GridSize s = impl_->file->level_size(impl_->file->level_count() - 1);
  if (edit_box(p, s).empty())
    throw std::invalid_argument("patch at (" + std::to_string(p.x) + ", " + std::to_string(p.y) +
                                ") does not overlap the " + std::to_string(s.width) + "x" +
                                std::to_string(s.height) + " grid");
  impl_->edits.push_back(p);
}

EditStats PyramidEditor::commit(CrashPoint crash) {
  const auto t0 = std::chrono::steady_clock::now();
  const PyramidFile& f = *impl_->file;
  const int n = f.level_count();
  const int finest = n - 1;
  const GridSize fs = f.level_size(finest);
  const container::ContainerInfo& info = f.info();
  const double scale = info.vertical_scale, offset = info.vertical_offset;
  runtime::RegionDecoder decoder(impl_->file, size_t(64) << 20);
  EditStats stats;
  stats.levels.resize(size_t(n));

  // --- Delta at the finest level: the edits applied in order to T^ (metres), on their union's box.
  // With a source, Delta of every level is the difference of the builder's T_l after and before.
  Box ebox;
  for (const Edit& e : impl_->edits) ebox = unite(ebox, edit_box(e, fs));
  std::vector<Window> delta(static_cast<size_t>(n));
  std::vector<std::vector<int32_t>> reference;  // source: T_l before the edit, every level
  std::optional<Heightmap> edited_source;
  if (impl_->source && !ebox.empty()) {
    Heightmap& edited = edited_source.emplace(*impl_->source);
    std::vector<double> cur(size_t(ebox.width() * ebox.height()));
    for (int64_t y = ebox.y0; y < ebox.y1; ++y)
      for (int64_t x = ebox.x0; x < ebox.x1; ++x)
        cur[size_t((y - ebox.y0) * ebox.width() + (x - ebox.x0))] = edited.metres(x, y);
    apply_edits(impl_->edits, fs, ebox, cur);
    for (int64_t y = ebox.y0; y < ebox.y1; ++y)
      for (int64_t x = ebox.x0; x < ebox.x1; ++x)
        if (edited.is_valid(x, y)) {  // voids stay voids: the mask is not edited
          const double native =
              (cur[size_t((y - ebox.y0) * ebox.width() + (x - ebox.x0))] - edited.info.vertical_offset) /
              edited.info.vertical_scale;
          // An integer grid stays one: the edited input is rounded to its own unit.
          edited.values[size_t(y * fs.width + x)] =
              edited.info.integer_valued() ? std::round(native) : native;
        }
    reference = reference_levels(*impl_->source, impl_->source_options).levels;
    const std::vector<std::vector<int32_t>> after = reference_levels(edited, impl_->source_options).levels;
    for (int l = 0; l < n; ++l)
      delta[size_t(l)] = difference(reference[size_t(l)], after[size_t(l)], f.level_size(l));
  } else if (!ebox.empty()) {
    Window base{ebox, std::vector<int32_t>(size_t(ebox.width() * ebox.height()))};
    decoder.decode_units(finest, ebox.rect(), base.v.data(), ebox.width());
    std::vector<double> cur(base.v.size());
    for (size_t i = 0; i < cur.size(); ++i) cur[i] = base.v[i] * scale + offset;
    std::vector<uint8_t> valid(size_t(ebox.height() * fs.width));
    f.container().mask_rows(uint64_t(ebox.y0), uint64_t(ebox.height()), valid.data());
    apply_edits(impl_->edits, fs, ebox, cur);
    Window d{ebox, std::vector<int32_t>(base.v.size())};
    for (int64_t y = ebox.y0; y < ebox.y1; ++y)
      for (int64_t x = ebox.x0; x < ebox.x1; ++x) {
        const size_t i = size_t((y - ebox.y0) * ebox.width() + (x - ebox.x0));
        const double units = std::nearbyint((cur[i] - offset) / scale) - double(base.v[i]);
        if (!(std::abs(units) <= double(codec::kMaxAbsSample)))
          throw Error(ErrorCode::InvalidOption, impl_->path + ": the edit changes sample (" +
                                                    std::to_string(x) + ", " + std::to_string(y) +
                                                    ") by more than the coder's range");
        // Voids stay voids: the mask is not edited.
        d.v[i] = valid[size_t((y - ebox.y0) * fs.width + x)] ? int32_t(units) : 0;
      }
    delta[size_t(finest)] = crop_nonzero(d);
  }
  impl_->edits.clear();
  const DownsampleFilter filter = f.downsample_filter();
  for (int l = finest; l > 0 && reference.empty() && !delta[size_t(l)].box.empty(); --l)
    delta[size_t(l - 1)] = downsample_delta(filter, delta[size_t(l)], f.level_size(l));
  for (int l = 0; l < n; ++l)
    for (int32_t v : delta[size_t(l)].v)
      stats.levels[size_t(l)].max_abs_delta_units =
          std::max(stats.levels[size_t(l)].max_abs_delta_units, std::abs(double(v)));

  // --- Re-code, coarsest first. changed[l]: T^_l after the edit on the rows it re-coded (full width),
  // changed_box[l]: where it differs from before.
  std::vector<Window> changed(static_cast<size_t>(n));
  std::vector<Box> changed_box(static_cast<size_t>(n));
  struct NewLevel {
    std::vector<container::BandMapRecord> records;  // offset 0 + size: a new stream, index into streams
    std::vector<std::vector<uint8_t>> streams;
    std::vector<int> stream_of;  // per record: index into streams, or -1 (old stream / zero run)
    bool any = false;
    double recoded_error_max = 0;  // largest |T^ - target| over the re-coded tiles, level units
  };
  std::vector<NewLevel> levels(static_cast<size_t>(n));
  UpsampleScratch up_scratch;
  for (int l = 0; l < n; ++l) {
    const GridSize s = f.level_size(l);
    Box reach = delta[size_t(l)].box;
    if (l > 0 && !changed_box[size_t(l - 1)].empty()) {
      const Box& a = changed_box[size_t(l - 1)];
      // U's four-point support (and the edge reflection's) reaches at most 4 fine samples beyond
      // twice the coarse box; 8 is a safe bound, the exact comparison below decides.
      reach =
          unite(reach, intersect(Box{2 * a.x0 - 8, 2 * a.y0 - 8, 2 * a.x1 + 8, 2 * a.y1 + 8}, level_box(s)));
    }
    if (reach.empty()) continue;
    const std::vector<EditBand> bands = edit_bands(f, l);
    const PtcCoderOptions opts = level_coder_options(f, l);
    PtcResidualCoder coder(opts);
    const int64_t t = opts.tile_size;
    int64_t first = -1, last = -1;
    for (size_t b = 0; b < bands.size(); ++b)
      if (bands[b].y0 < reach.y1 && bands[b].y0 + bands[b].rows > reach.y0) {
        if (first < 0) first = int64_t(b);
        last = int64_t(b);
      }
    Window& now = changed[size_t(l)];
    now.box = {0, bands[size_t(first)].y0, s.width, bands[size_t(last)].y0 + bands[size_t(last)].rows};
    now.v.assign(size_t(now.box.width() * now.box.height()), 0);
    Box diff{};
    NewLevel& nl = levels[size_t(l)];
    LevelEditStats& ls = stats.levels[size_t(l)];
    for (size_t b = 0; b < bands.size(); ++b) {
      const EditBand& band = bands[b];
      const bool in_reach = int64_t(b) >= first && int64_t(b) <= last;
      container::BandMapRecord rec{uint64_t(band.rows), 1, band.data ? f.container().offset_of(band.data) : 0,
                                   band.size};
      int stream = -1;
      if (in_reach) {
        const Rect br{0, band.y0, s.width, band.rows};
        const size_t area = size_t(s.width * band.rows);
        std::vector<int32_t> old_t(area), u_old(area, 0), u_new(area, 0), target(area);
        decoder.decode_units(l, br, old_t.data(), s.width);
        if (l > 0) {
          const GridSize cs = f.level_size(l - 1);
          const Rect cw = upsample_required_window(br, s);
          std::vector<int32_t> coarse(size_t(cw.width * cw.height));
          decoder.decode_units(l - 1, cw, coarse.data(), cw.width);
          upsample_region(CoarseWindow{coarse.data(), cw.width, cw, cs}, s, br, u_old.data(), s.width,
                          up_scratch);
          const Window& cc = changed[size_t(l - 1)];
          const Box hit =
              intersect(changed_box[size_t(l - 1)], Box{cw.x0, cw.y0, cw.x0 + cw.width, cw.y0 + cw.height});
          if (!hit.empty()) {
            for (int64_t y = hit.y0; y < hit.y1; ++y)
              for (int64_t x = hit.x0; x < hit.x1; ++x)
                coarse[size_t((y - cw.y0) * cw.width + (x - cw.x0))] = cc.get(x, y);
            upsample_region(CoarseWindow{coarse.data(), cw.width, cw, cs}, s, br, u_new.data(), s.width,
                            up_scratch);
          } else {
            u_new = u_old;
          }
        }
        const Window& d = delta[size_t(l)];
        std::vector<int32_t> residual(area);
        for (int64_t y = 0; y < band.rows; ++y)
          for (int64_t x = 0; x < s.width; ++x) {
            const size_t i = size_t(y * s.width + x);
            // The target: the builder's T_l of the edited source, or T^_l + Delta_l.
            const int32_t base =
                reference.empty() ? old_t[i] : reference[size_t(l)][size_t((band.y0 + y) * s.width + x)];
            target[i] = base + d.get(x, band.y0 + y);
            residual[i] = target[i] - u_new[i];
          }
        const int64_t tiles_x = (s.width + t - 1) / t, tiles_y = (band.rows + t - 1) / t;
        std::vector<uint8_t> dirty(size_t(tiles_x * tiles_y), 0);
        bool any_dirty = false;
        for (int64_t y = 0; y < band.rows; ++y)
          for (int64_t x = 0; x < s.width; ++x) {
            const size_t i = size_t(y * s.width + x);
            if (d.get(x, band.y0 + y) != 0 || u_new[i] != u_old[i]) {
              dirty[size_t((y / t) * tiles_x + x / t)] = 1;
              any_dirty = true;
            }
          }
        std::vector<int32_t> recon(area, 0);
        if (any_dirty) {
          std::vector<uint8_t> fresh;
          try {
            fresh = coder.encode_spliceable(residual.data(), s.width, band.rows, recon.data(), finest - l,
                                            l == 0, band.data, band.size);
          } catch (const std::runtime_error& e) {  // a residual beyond libcodec's range
            throw Error(ErrorCode::InvalidOption, impl_->path + ": level " + std::to_string(l) +
                                                      ": the edit is too large to code: " + e.what());
          }
          std::vector<uint8_t> spliced;
          const codec::Status st =
              band.size == 0 && fresh.empty()
                  ? codec::Status::Ok  // all empty before and after: still no stream
                  : codec::splice_tiles(band.data, band.size, fresh.data(), fresh.size(), dirty, &spliced);
          if (st != codec::Status::Ok)
            throw std::runtime_error(impl_->path + ": level " + std::to_string(l) + " rows " +
                                     std::to_string(band.y0) +
                                     "..: cannot splice the re-coded tiles into the band's stream (" +
                                     codec::status_name(st) + ")");
          const int64_t recoded = std::count(dirty.begin(), dirty.end(), uint8_t(1));
          ls.tiles_recoded += recoded;
          ls.tiles_kept += int64_t(dirty.size()) - recoded;
          const bool same = spliced.size() == band.size &&
                            (band.size == 0 || std::memcmp(spliced.data(), band.data, band.size) == 0);
          if (!same) {
            ++ls.bands_recoded;
            nl.any = true;
            rec.size = spliced.size();
            rec.offset = 0;
            if (!spliced.empty()) {
              stream = int(nl.streams.size());
              nl.streams.push_back(std::move(spliced));
            }
          }
        }
        // T^ after the edit: dirty tiles take U_new + the new reconstruction, clean ones keep T^.
        for (int64_t y = 0; y < band.rows; ++y)
          for (int64_t x = 0; x < s.width; ++x) {
            const size_t i = size_t(y * s.width + x);
            const bool dt = dirty[size_t((y / t) * tiles_x + x / t)] != 0;
            const int32_t v = dt ? u_new[i] + recon[i] : old_t[i];
            if (dt)
              nl.recoded_error_max = std::max(nl.recoded_error_max, std::abs(double(v) - double(target[i])));
            now.at(x, band.y0 + y) = v;
            if (v != old_t[i]) diff = unite(diff, Box{x, band.y0 + y, x + 1, band.y0 + y + 1});
          }
      }
      // Records: consecutive all-zero bands of equal height fold into one run.
      if (rec.size == 0 && !nl.records.empty() && nl.records.back().size == 0 &&
          nl.records.back().rows == rec.rows)
        ++nl.records.back().run;
      else {
        nl.records.push_back(rec);
        nl.stream_of.push_back(stream);
      }
    }
    changed_box[size_t(l)] = diff;
    if (!diff.empty()) ls.changed = diff.rect();
  }

  // --- Write: one band-map blob per changed level (its new streams first, then the map), then commit.
  bool any = false;
  for (const NewLevel& nl : levels) any = any || nl.any;
  if (!any) {
    stats.file_bytes = f.container().committed_size();
    stats.dead_bytes = f.dead_bytes();
    stats.generation = f.container().generation();
    stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return stats;
  }
  container::ContainerUpdater up(f.container());
  for (int l = 0; l < n; ++l) {
    NewLevel& nl = levels[size_t(l)];
    if (!nl.any) continue;
    const uint64_t at = up.next_offset();
    std::vector<uint8_t> blob;
    for (size_t r = 0; r < nl.records.size(); ++r)
      if (nl.stream_of[r] >= 0) {
        const std::vector<uint8_t>& st = nl.streams[size_t(nl.stream_of[r])];
        nl.records[r].offset = at + blob.size();
        blob.insert(blob.end(), st.begin(), st.end());
      }
    const std::vector<uint8_t> map = container::encode_band_map(nl.records);
    blob.insert(blob.end(), map.begin(), map.end());
    const uint64_t placed = up.append(blob.data(), blob.size());
    if (placed != at) throw std::logic_error("edit: band map placed at an unexpected offset");
    up.set_level(uint32_t(l), placed, blob.size(), container::crc32c(blob.data(), blob.size()));
    // The recorded max error must still bound the level (a viewer bounds its screen error with it);
    // the rms stays the build's (the edit touches a small part of the level).
    if (const auto& e = info.levels[size_t(l)].error)
      up.set_level_error(uint32_t(l),
                         container::LevelError{e->rms, std::max(e->max_abs, nl.recoded_error_max)});
  }
  const container::CommitStop stop = crash == CrashPoint::AfterBlobs   ? container::CommitStop::AfterBlobs
                                     : crash == CrashPoint::AfterIndex ? container::CommitStop::AfterIndex
                                     : crash == CrashPoint::TornSuperblock
                                         ? container::CommitStop::TornSuperblock
                                         : container::CommitStop::None;
  up.commit(stop);
  if (edited_source) impl_->source = std::move(*edited_source);  // later commits edit the edited input
  stats.bytes_appended = up.bytes_appended();
  stats.changed = true;
  impl_->file = PyramidFile::open(impl_->path);
  stats.file_bytes = impl_->file->container().committed_size();
  stats.dead_bytes = impl_->file->dead_bytes();
  stats.generation = impl_->file->container().generation();
  stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return stats;
}

}  // namespace terrain::edit
