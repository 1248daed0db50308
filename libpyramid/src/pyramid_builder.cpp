// The closed-loop residual pyramid, built streamed out of core in one pass over the input.
//
// Pass A (the only pass over the input): rows -> int32 -> push-pull void fill per band -> finest level
//   T_m and its validity mask spilled to temp files; the filter-fit windows are copied on the way.
// Fit D on those windows (the same windows whatever the input's band sizes, so memory and streamed
//   builds agree).
// Pass B: T_m streamed back through a cascade of D row engines; level l's rows feed level l-1 as soon
//   as it has enough of them; every level is spilled.
// Pass C (closed loop, coarse to fine): level l is cut into coder bands; each band is predicted by U
//   from the decoded coarser level T^_{l-1} (a sliding window of its rows), R = T - U(T^), coded, and
//   T^_l = U(T^) + R^ is spilled for the next level. Only the coarser level's decoded rows are needed,
//   so bands are independent and run in parallel.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <sstream>
#include <stdexcept>

#include "filter_downsample.h"
#include "pyramid/pyramid.h"
#include "pyramid_fill.h"
#include "pyramid_parallel.h"
#include "pyramid_spill.h"
#include "pyramid_varint.h"

namespace terrain {
namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

inline int32_t saturate(int64_t v) {
  return int32_t(std::clamp<int64_t>(v, std::numeric_limits<int32_t>::min(), std::numeric_limits<int32_t>::max()));
}

void validate(const BuildOptions& o, const GridInfo& info) {
  if (info.width <= 0 || info.height <= 0)
    throw std::invalid_argument("pyramid: input has no samples (" + std::to_string(info.width) + "x" +
                                std::to_string(info.height) + ")");
  if (o.threads < 1 || o.threads > 256) throw std::invalid_argument("pyramid: threads must be 1..256");
  if (!(o.value_scale > 0) || !std::isfinite(o.value_scale))
    throw std::invalid_argument("pyramid: value_scale must be finite and > 0");
  if (o.fill_band_rows < 1) throw std::invalid_argument("pyramid: fill_band_rows must be >= 1");
  if (o.level_count < 0) throw std::invalid_argument("pyramid: level_count must be >= 0");
  if (o.use_fixed_filter && !(std::abs(o.fixed_filter.sum() - 1.0) < 1e-9))
    throw std::invalid_argument("pyramid: the fixed filter must sum to 1");
}

// Input samples -> level integers (value * scale, rounded; integer grids must stay integers) with the
// voids filled by push-pull. Bands must come in order and be opt.fill_band_rows tall (the last one
// shorter), so the fill - and everything after it - never depends on how the input was chunked.
class InputConverter {
 public:
  InputConverter(const BuildOptions& opt, const GridInfo& info)
      : scale_(opt.value_scale), exact_(info.integer_valued() && opt.value_scale == 1.0), width_(info.width) {}

  // Returns the number of voids in the band.
  int64_t convert(const double* values, const uint8_t* valid, int64_t y, int64_t rows, int32_t* ints) {
    const int64_t W = width_;
    int64_t voids = 0;
    for (int64_t k = 0; k < rows * W; ++k) {
      if (!valid[k]) {
        ++voids;
        ints[k] = 0;
        continue;
      }
      const double v = values[k] * scale_;
      const double r = std::nearbyint(v);
      if (!(std::abs(r) <= double(std::numeric_limits<int32_t>::max())))
        throw std::invalid_argument("pyramid input: sample at row " + std::to_string(y + k / W) + ", column " +
                                    std::to_string(k % W) + " does not fit int32 after scaling");
      if (exact_ && r != v)
        throw std::invalid_argument("pyramid input: non-integer sample in an integer grid at row " +
                                    std::to_string(y + k / W) + ", column " + std::to_string(k % W));
      ints[k] = int32_t(r);
    }
    if (voids) detail::fill_voids(ints, valid, W, rows, kFillTile, &carry_, scratch_);
    return voids;
  }

 private:
  static constexpr int64_t kFillTile = 256;
  double scale_;
  bool exact_;
  int64_t width_;
  int32_t carry_ = 0;
  detail::PushPullScratch scratch_;
};

// Per-band state of pass C, reused across band groups.
struct BandWork {
  int64_t y0 = 0, rows = 0;
  std::vector<int32_t> t, pred, res, rhat;
  std::vector<uint8_t> valid, bytes;
  UpsampleScratch scratch;
  double res_sq = 0, err_sq = 0;
  int64_t res_max = 0, err_max = 0, counted = 0;
};

}  // namespace

BuildResult build_pyramid(BandReader& input, const BuildOptions& opt, ResidualCoder& coder, PyramidSink& sink) {
  const GridInfo info = input.info();
  validate(opt, info);
  const GridSize finest{info.width, info.height};
  const std::vector<GridSize> sizes = pyramid_level_sizes(finest, opt.level_count, opt.min_coarsest_side);
  const int L = int(sizes.size()), m = L - 1;
  const int64_t W = finest.width, H = finest.height;
  const std::string base = opt.temp_dir + "/" + opt.temp_name + ".pyr.tmp.";

  BuildResult result;
  {
    std::ostringstream s;
    s << "levels " << L << ":";
    for (auto& g : sizes) s << " " << g.width << "x" << g.height;
    result.log.push_back(s.str());
  }

  std::vector<std::unique_ptr<detail::SpillFile>> level_spill(static_cast<size_t>(L));
  level_spill[size_t(m)] = std::make_unique<detail::SpillFile>(base + "level" + std::to_string(m));
  detail::SpillFile mask_spill(base + "mask");

  // ---- Pass A: the input, once.
  auto t0 = Clock::now();
  const std::vector<Rect> windows =
      opt.use_fixed_filter ? std::vector<Rect>{} : filter_fit_windows(finest, opt.fit);
  std::vector<std::vector<int32_t>> window_data(windows.size());
  for (size_t k = 0; k < windows.size(); ++k) window_data[k].resize(size_t(windows[k].width * windows[k].height));

  const int64_t B = std::min(opt.fill_band_rows, H);
  std::vector<double> values(size_t(B * W));
  std::vector<uint8_t> valid(size_t(B * W));
  std::vector<int32_t> ints(size_t(B * W));
  std::vector<uint8_t> mask_bytes;
  InputConverter converter(opt, info);
  for (int64_t y = 0; y < H; y += B) {
    const int64_t rows = std::min(B, H - y);
    for (int64_t got = 0; got < rows;) {
      const int64_t n = input.read_rows(rows - got, values.data() + got * W, valid.data() + got * W);
      if (n <= 0 || n > rows - got)
        throw IoError(IoErrorCode::Truncated, "pyramid input: ended after " + std::to_string(y + got) + " of " +
                                                  std::to_string(H) + " rows");
      got += n;
    }
    result.void_count += converter.convert(values.data(), valid.data(), y, rows, ints.data());
    level_spill[size_t(m)]->write(ints.data(), size_t(rows * W) * sizeof(int32_t));
    for (int64_t r = 0; r < rows; ++r) {
      mask_bytes = encode_mask_rows(valid.data() + r * W, W, 1);
      uint8_t len[10];
      mask_spill.write(len, size_t(detail::put_varint(len, mask_bytes.size()) - len));
      mask_spill.write(mask_bytes.data(), mask_bytes.size());
    }
    for (size_t k = 0; k < windows.size(); ++k) {
      const Rect& wr = windows[k];
      for (int64_t yy = std::max(y, wr.y0); yy < std::min(y + rows, wr.y0 + wr.height); ++yy)
        std::copy(ints.begin() + (yy - y) * W + wr.x0, ints.begin() + (yy - y) * W + wr.x0 + wr.width,
                  window_data[k].begin() + (yy - wr.y0) * wr.width);
    }
  }
  result.seconds_pass_input = seconds_since(t0);

  DownsampleFilter filter = opt.fixed_filter;
  if (opt.use_fixed_filter) {
    result.filter_report.reason = "fixed filter given by the caller";
    result.log.push_back("D: fixed filter given by the caller");
  } else {
    filter = fit_optimal_filter(windows, window_data, opt.fit, &result.filter_report);
    result.log.push_back(result.filter_report.summary());
  }
  window_data.clear();
  if (result.void_count)
    result.log.push_back("nodata: " + std::to_string(result.void_count) + " void samples filled by push-pull");

  // ---- Pass B: Gaussian levels through a cascade of D engines.
  t0 = Clock::now();
  if (m > 0) {
    std::vector<std::unique_ptr<detail::DownsampleEngine>> engines(static_cast<size_t>(L));
    std::vector<std::vector<int32_t>> emitted(static_cast<size_t>(L));
    std::vector<detail::DownsampleEngine::Emit> emit(static_cast<size_t>(L));
    for (int l = m; l >= 1; --l) {
      engines[size_t(l)] = std::make_unique<detail::DownsampleEngine>(filter, sizes[size_t(l)], opt.threads);
      level_spill[size_t(l - 1)] = std::make_unique<detail::SpillFile>(base + "level" + std::to_string(l - 1));
    }
    for (int l = m; l >= 1; --l) {
      emit[size_t(l)] = [&, l](int64_t, int64_t n, const double* rows) {
        const int64_t cw = sizes[size_t(l - 1)].width;
        std::vector<int32_t>& out = emitted[size_t(l - 1)];
        out.resize(size_t(n * cw));
        for (int64_t k = 0; k < n * cw; ++k) out[size_t(k)] = detail::round_to_int32(rows[k]);
        level_spill[size_t(l - 1)]->write(out.data(), out.size() * sizeof(int32_t));
        if (l - 1 >= 1) engines[size_t(l - 1)]->push_rows(out.data(), n, emit[size_t(l - 1)]);
      };
    }
    level_spill[size_t(m)]->rewind_for_reading();
    const int64_t chunk = 64;
    std::vector<int32_t> rows_in(size_t(chunk * W));
    for (int64_t y = 0; y < H; y += chunk) {
      const int64_t n = std::min(chunk, H - y);
      level_spill[size_t(m)]->read(rows_in.data(), size_t(n * W) * sizeof(int32_t));
      engines[size_t(m)]->push_rows(rows_in.data(), n, emit[size_t(m)]);
    }
    for (int l = m; l >= 1; --l) engines[size_t(l)]->finish(emit[size_t(l)]);
  }
  result.seconds_pass_filter = seconds_since(t0);

  // ---- Pass C: closed-loop residuals, coarse to fine.
  t0 = Clock::now();
  PyramidHeader& hdr = result.header;
  hdr.levels = sizes;
  hdr.filter = filter;
  hdr.band_rows = coder.band_rows();
  hdr.has_voids = result.void_count > 0;
  hdr.value_scale = opt.value_scale;
  hdr.input = info;
  sink.begin(hdr);
  const int64_t S = hdr.band_rows;
  if (S < 1) throw std::invalid_argument("pyramid: coder band_rows must be >= 1");
  mask_spill.rewind_for_reading();

  std::vector<BandWork> work(static_cast<size_t>(opt.threads));
  std::unique_ptr<detail::SpillFile> prev_rec;
  std::vector<int32_t> cbuf;
  result.levels.resize(size_t(L));
  for (int l = 0; l <= m; ++l) {
    const GridSize fs = sizes[size_t(l)];
    const int64_t fw = fs.width, fh = fs.height;
    const bool finest_level = l == m;
    const bool with_mask = finest_level && hdr.has_voids;
    detail::SpillFile& tin = *level_spill[size_t(l)];
    tin.rewind_for_reading();
    std::unique_ptr<detail::SpillFile> rec_out;
    if (!finest_level) rec_out = std::make_unique<detail::SpillFile>(base + "decoded" + std::to_string(l));
    GridSize cs{0, 0};
    int64_t cbase = 0, ccount = 0, cread = 0;
    if (l > 0) {
      cs = sizes[size_t(l - 1)];
      prev_rec->rewind_for_reading();
    }
    LevelStats& st = result.levels[size_t(l)];
    st.size = fs;
    double res_sq = 0, err_sq = 0;
    int64_t counted = 0;
    const int64_t group_rows = S * opt.threads;
    for (int64_t gy0 = 0; gy0 < fh; gy0 += group_rows) {
      const int64_t gy1 = std::min(fh, gy0 + group_rows);
      const int64_t nb = (gy1 - gy0 + S - 1) / S;
      if (int64_t(work.size()) < nb) work.resize(size_t(nb));
      for (int64_t b = 0; b < nb; ++b) {
        BandWork& bw = work[size_t(b)];
        bw.y0 = gy0 + b * S;
        bw.rows = std::min(S, gy1 - bw.y0);
        const size_t n = size_t(bw.rows * fw);
        bw.t.resize(n), bw.pred.resize(n), bw.res.resize(n), bw.rhat.resize(n);
        tin.read(bw.t.data(), n * sizeof(int32_t));
        bw.valid.assign(with_mask ? n : 0, 1);
        if (with_mask) {
          for (int64_t r = 0; r < bw.rows; ++r) {
            uint64_t len = 0;
            uint8_t byte;
            for (int shift = 0;; shift += 7) {
              if (shift > 63 || !mask_spill.read_byte(&byte))
                throw IoError(IoErrorCode::Truncated, mask_spill.path() + ": mask spill truncated");
              len |= uint64_t(byte & 0x7f) << shift;
              if (!(byte & 0x80)) break;
            }
            mask_bytes.resize(size_t(len));
            mask_spill.read(mask_bytes.data(), mask_bytes.size());
            if (!decode_mask_rows(mask_bytes.data(), mask_bytes.size(), fw, 1, bw.valid.data() + r * fw))
              throw std::logic_error("pyramid: mask spill corrupt");
          }
        }
      }
      if (l > 0) {
        const Rect need = upsample_required_window(Rect{0, gy0, fw, gy1 - gy0}, fs);
        const int64_t drop = std::clamp<int64_t>(need.y0 - cbase, 0, ccount);
        if (drop > 0) {
          std::memmove(cbuf.data(), cbuf.data() + drop * cs.width, size_t((ccount - drop) * cs.width) * sizeof(int32_t));
          cbase += drop, ccount -= drop;
        }
        const int64_t want_end = need.y0 + need.height;
        if (cbase + ccount < want_end) {
          const int64_t more = want_end - (cbase + ccount);
          cbuf.resize(size_t((ccount + more) * cs.width));
          prev_rec->read(cbuf.data() + ccount * cs.width, size_t(more * cs.width) * sizeof(int32_t));
          ccount += more;
          cread += more;
        }
      }
      const CoarseWindow cwin{cbuf.data(), cs.width, Rect{0, cbase, cs.width, ccount}, cs};
      detail::parallel_chunks(opt.threads, nb, [&](int, int64_t b0, int64_t b1) {
        for (int64_t b = b0; b < b1; ++b) {
          BandWork& bw = work[size_t(b)];
          const int64_t n = bw.rows * fw;
          if (l > 0)
            upsample_region(cwin, fs, Rect{0, bw.y0, fw, bw.rows}, bw.pred.data(), fw, bw.scratch);
          else
            std::fill(bw.pred.begin(), bw.pred.end(), 0);
          for (int64_t k = 0; k < n; ++k) bw.res[size_t(k)] = saturate(int64_t(bw.t[size_t(k)]) - bw.pred[size_t(k)]);
          // Voids are restored from the mask, so their residual carries no information.
          if (with_mask)
            for (int64_t k = 0; k < n; ++k)
              if (!bw.valid[size_t(k)]) bw.res[size_t(k)] = 0;
          bw.bytes = coder.encode(bw.res.data(), fw, bw.rows, bw.rhat.data());
          bw.res_sq = bw.err_sq = 0;
          bw.res_max = bw.err_max = bw.counted = 0;
          for (int64_t k = 0; k < n; ++k) {
            const int32_t rec = saturate(int64_t(bw.pred[size_t(k)]) + bw.rhat[size_t(k)]);
            if (!with_mask || bw.valid[size_t(k)]) {
              const int64_t r = bw.res[size_t(k)], e = int64_t(bw.t[size_t(k)]) - rec;
              bw.res_sq += double(r) * double(r);
              bw.err_sq += double(e) * double(e);
              bw.res_max = std::max(bw.res_max, r < 0 ? -r : r);
              bw.err_max = std::max(bw.err_max, e < 0 ? -e : e);
              ++bw.counted;
            }
            bw.rhat[size_t(k)] = rec;  // now T^ for this band
          }
        }
      });
      for (int64_t b = 0; b < nb; ++b) {
        BandWork& bw = work[size_t(b)];
        const size_t n = size_t(bw.rows * fw);
        if (with_mask) {
          std::vector<uint8_t> mb = encode_mask_rows(bw.valid.data(), fw, bw.rows);
          result.mask_bytes += mb.size();
          sink.mask_band(bw.y0, bw.rows, std::move(mb));
        }
        st.bytes += bw.bytes.size();
        sink.band(l, bw.y0, bw.rows, std::move(bw.bytes));
        bw.bytes = {};
        if (sink.wants_reconstruction(l)) sink.reconstructed_rows(l, bw.y0, bw.rows, bw.rhat.data());
        if (rec_out) rec_out->write(bw.rhat.data(), n * sizeof(int32_t));
        res_sq += bw.res_sq, err_sq += bw.err_sq, counted += bw.counted;
        st.residual_max_abs = std::max(st.residual_max_abs, bw.res_max);
        st.error_max_abs = std::max(st.error_max_abs, bw.err_max);
      }
    }
    (void)cread;
    st.residual_rms = counted ? std::sqrt(res_sq / double(counted)) : 0.0;
    st.error_rms = counted ? std::sqrt(err_sq / double(counted)) : 0.0;
    prev_rec = std::move(rec_out);
    // Level l's Gaussian samples are no longer needed.
    if (!finest_level) level_spill[size_t(l)].reset();
  }
  result.seconds_pass_residual = seconds_since(t0);
  return result;
}

namespace {

class MemoryBandReader final : public BandReader {
 public:
  MemoryBandReader(const Heightmap& map, int64_t max_rows) : map_(map), max_rows_(std::max<int64_t>(1, max_rows)) {
    const int64_t n = map.width() * map.height();
    if (map.width() < 0 || map.height() < 0 || int64_t(map.values.size()) != n ||
        (!map.valid.empty() && int64_t(map.valid.size()) != n))
      throw std::invalid_argument("pyramid: heightmap arrays do not match its dimensions");
  }
  const GridInfo& info() const override { return map_.info; }
  int64_t read_rows(int64_t rows, double* values, uint8_t* valid) override {
    const int64_t w = map_.width();
    const int64_t n = std::min({rows, max_rows_, map_.height() - rows_read_});
    if (n <= 0) return 0;
    const size_t off = size_t(rows_read_ * w), cnt = size_t(n * w);
    std::copy(map_.values.begin() + off, map_.values.begin() + off + cnt, values);
    if (map_.valid.empty())
      std::fill(valid, valid + cnt, uint8_t(1));
    else
      std::copy(map_.valid.begin() + off, map_.valid.begin() + off + cnt, valid);
    rows_read_ += n;
    return n;
  }

 private:
  const Heightmap& map_;
  int64_t max_rows_;
};

}  // namespace

std::unique_ptr<BandReader> make_memory_band_reader(const Heightmap& map, int64_t max_rows_per_call) {
  return std::make_unique<MemoryBandReader>(map, max_rows_per_call);
}

std::vector<int32_t> to_level_grid(const Heightmap& map, const BuildOptions& options, std::vector<uint8_t>* valid) {
  validate(options, map.info);
  MemoryBandReader reader(map, int64_t(1) << 40);
  const int64_t W = map.width(), H = map.height();
  std::vector<int32_t> out(size_t(W * H));
  std::vector<double> values(size_t(W * H));
  std::vector<uint8_t> mask(size_t(W * H));
  reader.read_rows(H, values.data(), mask.data());
  InputConverter converter(options, map.info);
  const int64_t B = options.fill_band_rows;
  for (int64_t y = 0; y < H; y += B)
    converter.convert(values.data() + y * W, mask.data() + y * W, y, std::min(B, H - y), out.data() + y * W);
  if (valid) *valid = std::move(mask);
  return out;
}

BuildResult build_pyramid(const Heightmap& map, const BuildOptions& options, ResidualCoder& coder,
                          PyramidSink& sink) {
  MemoryBandReader reader(map, int64_t(1) << 40);
  return build_pyramid(reader, options, coder, sink);
}

}  // namespace terrain
