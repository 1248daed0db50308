// Fixed-layout sample streams (raw grids, and the .hgt / .bil / .flt payloads), the raw JSON sidecar,
// and the raw writer.
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <bit>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <memory>
#include <sstream>
#include <vector>

#include "core/file.h"
#include "readers/internal/io_internal.h"
#include "readers/internal/io_json.h"

namespace terrain::io {
namespace {

std::string row_col(int64_t row, int64_t col) {
  return "row " + std::to_string(row) + ", column " + std::to_string(col);
}

// Streams rows of a fixed-layout file with fread (or zlib's inflate), keeping one band of bytes.
class RawStreamReader final : public BandReader {
 public:
  RawStreamReader(std::string path, const RawLayout& layout) : path_(std::move(path)), layout_(layout) {
    row_bytes_ = uint64_t(layout_.info.width) * uint64_t(stored_bytes(layout_.stored));
    if (layout_.info.nodata) {
      nodata_as_float_ = float(*layout_.info.nodata);
      std::memcpy(&nodata_float_bits_, &nodata_as_float_, sizeof nodata_float_bits_);
    }
    // A regular file only (core/file.h): a FIFO swapped in after the probe must not block the read.
    fd_.fd = open_regular_file(path_);
    if (layout_.gzip) {
      // 16 + MAX_WBITS: one gzip member (header, deflate data, CRC-32 and length trailer).
      if (inflateInit2(&gz_.z, 16 + MAX_WBITS) != Z_OK)
        fail(ErrorCode::CorruptData, path_, "cannot start zlib");
      gz_.started = true;
      gz_in_.resize(size_t(1) << 17);
      std::vector<uint8_t> skip(size_t(std::min<uint64_t>(layout_.data_offset, uint64_t(1) << 20)));
      for (uint64_t left = layout_.data_offset; left > 0;) {
        const size_t n = size_t(std::min<uint64_t>(left, skip.size()));
        if (inflate_into(skip.data(), n) != n)
          fail(ErrorCode::Truncated, path_, "gzip stream ends before the data offset");
        left -= n;
      }
    } else {
      file_.reset(::fdopen(fd_.fd, "rb"));
      if (!file_) fail(ErrorCode::NotFound, path_, std::string("cannot open: ") + std::strerror(errno));
      fd_.fd = -1;  // file_ owns it now
      if (layout_.data_offset > 0 && fseeko(file_.get(), off_t(layout_.data_offset), SEEK_SET) != 0)
        fail(ErrorCode::Truncated, path_, "cannot seek to the data offset");
    }
  }
  RawStreamReader(const RawStreamReader&) = delete;
  RawStreamReader& operator=(const RawStreamReader&) = delete;

  const GridInfo& info() const override { return layout_.info; }

  int64_t read_rows(int64_t rows, double* values, uint8_t* valid) override {
    return read_and_decode(rows, [&](const uint8_t* src, int64_t row, int64_t r) {
      const int64_t w = layout_.info.width;
      decode_row(src, row, values + r * w, valid + r * w);
    });
  }

  bool reads_int32() const override { return layout_.stored != StoredType::Float32; }
  int64_t read_rows_int32(int64_t rows, int32_t* values, uint8_t* valid) override {
    if (!reads_int32()) return BandReader::read_rows_int32(rows, values, valid);
    return read_and_decode(rows, [&](const uint8_t* src, int64_t, int64_t r) {
      const int64_t w = layout_.info.width;
      decode_int_row(src, values + r * w, valid + r * w);
    });
  }

  // A gzip stream has no random access: inflate and discard (BandReader's). Else seek, once the file
  // is known to hold the rows (a shorter one fails as a read of them would).
  int64_t skip_rows(int64_t rows) override {
    if (layout_.gzip) return BandReader::skip_rows(rows);
    const int64_t n = std::min(rows, layout_.info.height - rows_read_);
    if (n <= 0) return 0;
    const uint64_t end = layout_.data_offset + uint64_t(rows_read_ + n) * row_bytes_;
    struct stat st {};
    if (::fstat(::fileno(file_.get()), &st) != 0) fail(ErrorCode::NotFound, path_, "cannot stat");
    if (uint64_t(st.st_size) < end)
      fail_data_ends(uint64_t(st.st_size) > layout_.data_offset
                         ? int64_t((uint64_t(st.st_size) - layout_.data_offset) / row_bytes_)
                         : 0);
    if (fseeko(file_.get(), off_t(uint64_t(n) * row_bytes_), SEEK_CUR) != 0)
      fail(ErrorCode::NotFound, path_, std::string("cannot seek: ") + std::strerror(errno));
    rows_read_ += n;
    return n;
  }

 private:
  std::string path_;
  RawLayout layout_;
  // Owners (so that a constructor that throws releases what it took): the descriptor until stdio
  // owns it, the stdio stream, zlib's state.
  struct Descriptor {
    int fd = -1;
    ~Descriptor() {
      if (fd >= 0) ::close(fd);
    }
  } fd_;
  struct FileCloser {
    void operator()(FILE* f) const { std::fclose(f); }
  };
  std::unique_ptr<FILE, FileCloser> file_;
  struct Inflater {
    z_stream z{};
    bool started = false;
    ~Inflater() {
      if (started) inflateEnd(&z);
    }
  } gz_;
  bool gz_ended_ = false;
  std::vector<uint8_t> gz_in_;  // compressed bytes read from fd_ and not yet inflated
  uint64_t row_bytes_ = 0;
  std::vector<uint8_t> buffer_;
  float nodata_as_float_ = 0;
  uint32_t nodata_float_bits_ = 0;

  size_t read_gz(size_t want) { return inflate_into(buffer_.data(), want); }

  // Reads up to `rows` rows as bytes and hands each to decode(bytes, grid row, row in the call).
  template <typename Decode> int64_t read_and_decode(int64_t rows, Decode decode) {
    const int64_t n = std::min(rows, layout_.info.height - rows_read_);
    if (n <= 0) return 0;
    const size_t want = size_t(uint64_t(n) * row_bytes_);
    if (buffer_.size() < want) buffer_.resize(want);
    const size_t got = layout_.gzip ? read_gz(want) : std::fread(buffer_.data(), 1, want, file_.get());
    if (got < want) {
      if (file_ && std::ferror(file_.get())) fail(ErrorCode::NotFound, path_, "read error");
      fail_data_ends(rows_read_ + int64_t(got / row_bytes_));
    }
    for (int64_t r = 0; r < n; ++r) decode(buffer_.data() + size_t(r) * row_bytes_, rows_read_ + r, r);
    rows_read_ += n;
    if (layout_.gzip && rows_read_ == layout_.info.height) check_gz_end();
    return n;
  }

  // The file holds only `rows` whole rows of the grid (read_rows and skip_rows).
  [[noreturn]] void fail_data_ends(int64_t rows) const {
    fail(ErrorCode::Truncated, path_,
         "data ends in row " + std::to_string(rows) + " of " + std::to_string(layout_.info.height) + " (" +
             std::to_string(layout_.info.width) + "x" + std::to_string(layout_.info.height) + " " +
             sample_type_name(layout_.info.sample_type) + ")");
  }

  // Inflates up to `size` bytes into `out`; fewer only where the member (or the file) ends. The end
  // of the member must be the end of the file: anything after it (garbage, or a second member,
  // which gzread would have read on or skipped in silence) is refused, so the grid is never a part
  // of what the file holds (docs/io.md, "Limits").
  size_t inflate_into(uint8_t* out, size_t size) {
    size_t done = 0;
    while (done < size && !gz_ended_) {
      if (gz_.z.avail_in == 0) {
        const ssize_t n = ::read(fd_.fd, gz_in_.data(), gz_in_.size());
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) fail(ErrorCode::NotFound, path_, std::string("read error: ") + std::strerror(errno));
        if (n == 0) break;  // the compressed data ends early: the caller reports what is missing
        gz_.z.next_in = gz_in_.data();
        gz_.z.avail_in = uInt(n);
      }
      const size_t chunk = std::min<size_t>(size - done, size_t(1) << 30);
      gz_.z.next_out = out + done;
      gz_.z.avail_out = uInt(chunk);
      const int r = inflate(&gz_.z, Z_NO_FLUSH);
      done += chunk - gz_.z.avail_out;
      if (r == Z_STREAM_END) {
        gz_ended_ = true;
        uint8_t extra = 0;
        ssize_t more;
        while ((more = ::read(fd_.fd, &extra, 1)) < 0 && errno == EINTR) {
        }
        if (gz_.z.avail_in > 0 || more > 0)
          fail(ErrorCode::CorruptData, path_,
               "data after the end of the gzip stream (only one member is read; docs/io.md)");
      } else if (r != Z_OK && r != Z_BUF_ERROR) {
        fail(ErrorCode::CorruptData, path_,
             std::string("corrupt gzip stream: ") + (gz_.z.msg ? gz_.z.msg : "unknown error"));
      }
    }
    return done;
  }

  // Inflating one byte past the samples verifies the trailer CRC and finds extra data.
  void check_gz_end() {
    uint8_t extra = 0;
    if (inflate_into(&extra, 1) > 0)
      fail(ErrorCode::Oversized, path_, "gzip stream holds more bytes than the dimensions need");
    if (!gz_ended_) fail(ErrorCode::Truncated, path_, "gzip stream ends before its trailer");
  }

  // One row of integer samples (stored as T, in either byte order) to doubles and validity. The byte
  // order and the nodata test are decided once per row and the loop writes through restrict pointers
  // (valid's bytes could otherwise alias the layout), so that it vectorises: per sample it was a
  // fifth of a 16-thread build's input thread.
  template <typename T, bool kBigEndian, bool kNodata, typename Out>
  static void decode_ints(const uint8_t* __restrict src, int64_t w, T nodata, Out* __restrict values,
                          uint8_t* __restrict valid) {
    for (int64_t x = 0; x < w; ++x) {
      T v;
      std::memcpy(&v, src + x * int64_t(sizeof(T)), sizeof(T));
      if constexpr (kBigEndian && sizeof(T) == 2) v = T(__builtin_bswap16(uint16_t(v)));
      if constexpr (kBigEndian && sizeof(T) == 4) v = T(__builtin_bswap32(uint32_t(v)));
      const bool is_void = kNodata && v == nodata;
      values[x] = is_void ? Out(0) : Out(v);
      valid[x] = is_void ? 0 : 1;
    }
  }
  // Out: double (read_rows) or int32_t (read_rows_int32, integer storage only: every T fits).
  template <typename T, typename Out>
  void decode_ints_row(const uint8_t* src, Out* values, uint8_t* valid) const {
    static_assert(std::endian::native == std::endian::little);
    const int64_t w = layout_.info.width;
    // Compared as T (a sample equals the nodata value exactly when the value is a whole number in
    // T's range, and then as T), not each sample converted to double: 4x the work at SSE2.
    const double nodata = layout_.info.nodata.value_or(0.0);
    const bool big = layout_.big_endian && sizeof(T) > 1,
               has = layout_.info.nodata.has_value() && nodata == std::floor(nodata) &&
                     nodata >= double(std::numeric_limits<T>::min()) &&
                     nodata <= double(std::numeric_limits<T>::max());
    const T nodata_t = has ? T(nodata) : T(0);
    if (big)
      has ? decode_ints<T, true, true, Out>(src, w, nodata_t, values, valid)
          : decode_ints<T, true, false, Out>(src, w, nodata_t, values, valid);
    else
      has ? decode_ints<T, false, true, Out>(src, w, nodata_t, values, valid)
          : decode_ints<T, false, false, Out>(src, w, nodata_t, values, valid);
  }

  uint32_t load_u32(const uint8_t* p) const {
    return layout_.big_endian ? (uint32_t(p[0]) << 24 | uint32_t(p[1]) << 16 | uint32_t(p[2]) << 8 | p[3])
                              : (uint32_t(p[3]) << 24 | uint32_t(p[2]) << 16 | uint32_t(p[1]) << 8 | p[0]);
  }

  // A row of an integer stored type (not Float32) to Out.
  template <typename Out> void decode_int_row(const uint8_t* src, Out* values, uint8_t* valid) const {
    switch (layout_.stored) {
      case StoredType::UInt8:
        decode_ints_row<uint8_t>(src, values, valid);
        break;
      case StoredType::Int16:
        decode_ints_row<int16_t>(src, values, valid);
        break;
      case StoredType::UInt16:
        decode_ints_row<uint16_t>(src, values, valid);
        break;
      case StoredType::Int32:
      case StoredType::Float32:  // never here: callers take it apart
        decode_ints_row<int32_t>(src, values, valid);
        break;
    }
  }

  void decode_row(const uint8_t* src, int64_t row, double* values, uint8_t* valid) {
    if (layout_.stored == StoredType::Float32)
      decode_float_row(src, row, values, valid);
    else
      decode_int_row(src, values, valid);
  }

  void decode_float_row(const uint8_t* src, int64_t row, double* values, uint8_t* valid) {
    const int64_t w = layout_.info.width;
    const bool has_nodata = layout_.info.nodata.has_value();
    for (int64_t x = 0; x < w; ++x) {
      uint32_t bits = load_u32(src + x * 4);
      float f;
      std::memcpy(&f, &bits, sizeof f);
      // A NaN nodata value is matched by bit pattern, since NaN never compares equal.
      bool is_void = has_nodata && (bits == nodata_float_bits_ || f == nodata_as_float_);
      if (!is_void && !std::isfinite(f))
        fail(ErrorCode::NonFinite, path_,
             std::string(std::isnan(f) ? "NaN" : "Inf") + " at " + row_col(row, x));
      values[x] = is_void ? 0.0 : double(f);
      valid[x] = is_void ? 0 : 1;
    }
  }
};

std::optional<std::string> find_sidecar(const std::string& path) {
  if (file_exists(path + ".json")) return path + ".json";
  auto dot = path.find_last_of('.');
  auto slash = path.find_last_of('/');
  if (dot != std::string::npos && (slash == std::string::npos || dot > slash)) {
    std::string alt = path.substr(0, dot) + ".json";
    if (alt != path && file_exists(alt)) return alt;
  }
  return std::nullopt;
}

// Reads a numeric member; MissingField if it is present but not a number.
std::optional<double> number_member(const JsonObject& obj, const std::string& key,
                                    const std::string& sidecar) {
  auto it = obj.find(key);
  if (it == obj.end() || it->second.kind == JsonScalar::Kind::Null) return std::nullopt;
  const JsonScalar& v = it->second;
  if (v.kind == JsonScalar::Kind::Number) return v.number;
  if (v.kind == JsonScalar::Kind::String) {
    std::string s = to_lower(v.text);
    if (s == "nan") return std::nan("");  // JSON has no NaN literal; float nodata may be NaN
  }
  fail(ErrorCode::MissingField, sidecar, "field \"" + key + "\" must be a number");
}

int64_t dimension_member(const JsonObject& obj, const std::string& key, const std::string& sidecar) {
  auto v = number_member(obj, key, sidecar);
  if (!v) fail(ErrorCode::MissingField, sidecar, "missing required field \"" + key + "\"");
  if (!(*v >= 1 && *v <= 2147483648.0) || *v != std::floor(*v))
    fail(ErrorCode::MissingField, sidecar,
         "field \"" + key + "\" must be a positive integer, got " + format_double(*v));
  return int64_t(*v);
}

}  // namespace

std::unique_ptr<BandReader> open_raw_stream(const std::string& path, const RawLayout& layout) {
  return std::make_unique<RawStreamReader>(path, layout);
}

RawLayout probe_raw_layout(const std::string& path, const ReadOptions& options) {
  uint64_t size = existing_file_size(path);
  RawLayout layout;
  layout.info.format = FileFormat::Raw;
  std::optional<int64_t> width = options.width, height = options.height;
  std::optional<SampleType> type = options.sample_type;
  std::optional<bool> big_endian = options.big_endian;

  auto sidecar = find_sidecar(path);
  if (sidecar) {
    std::string error;
    auto obj = parse_json_object(read_small_text_file(*sidecar, kSideFileLimit), error);
    if (!obj) fail(ErrorCode::MissingField, *sidecar, "malformed JSON sidecar: " + error);
    // The sidecar must describe the grid fully; command-line options may still override it.
    int64_t w = dimension_member(*obj, "width", *sidecar);
    int64_t h = dimension_member(*obj, "height", *sidecar);
    if (!width) width = w;
    if (!height) height = h;
    auto t = obj->find("type");
    if (t == obj->end()) fail(ErrorCode::MissingField, *sidecar, "missing required field \"type\"");
    if (t->second.kind != JsonScalar::Kind::String)
      fail(ErrorCode::MissingField, *sidecar, "field \"type\" must be a string");
    auto parsed = sample_type_from_name(t->second.text);
    if (!parsed)
      fail(ErrorCode::UnknownType, *sidecar,
           "unknown sample type \"" + t->second.text + "\" (expected int16, uint16, int32 or float32)");
    if (!type) type = parsed;
    auto bo = obj->find("byte_order");
    if (bo != obj->end() && bo->second.kind != JsonScalar::Kind::Null) {
      std::string order = bo->second.kind == JsonScalar::Kind::String ? to_lower(bo->second.text) : "";
      bool big;
      if (order == "little" || order == "little_endian" || order == "le")
        big = false;
      else if (order == "big" || order == "big_endian" || order == "be")
        big = true;
      else
        fail(ErrorCode::UnknownType, *sidecar, "unknown byte_order (expected \"little\" or \"big\")");
      if (!big_endian) big_endian = big;
    }
    GridInfo& g = layout.info;
    if (auto v = number_member(*obj, "spacing_x", *sidecar)) g.spacing_x = *v;
    if (auto v = number_member(*obj, "spacing_y", *sidecar)) g.spacing_y = *v;
    if (auto v = number_member(*obj, "vertical_scale", *sidecar)) g.vertical_scale = *v;
    if (auto v = number_member(*obj, "vertical_offset", *sidecar)) g.vertical_offset = *v;
    if (auto v = number_member(*obj, "nodata", *sidecar)) g.nodata = *v;
    if (auto v = number_member(*obj, "origin_x", *sidecar)) g.origin_x = *v;
    if (auto v = number_member(*obj, "origin_y", *sidecar)) g.origin_y = *v;
    auto units = obj->find("horizontal_units");
    if (units != obj->end() && units->second.kind == JsonScalar::Kind::String)
      g.horizontal_units = units->second.text;
    if (auto v = number_member(*obj, "crs_epsg", *sidecar)) {
      if (!(*v >= 1 && *v <= 999999) || *v != std::floor(*v))
        fail(ErrorCode::MissingField, *sidecar, "field \"crs_epsg\" must be an integer 1..999999");
      g.crs_epsg = int(*v);
    }
    auto crs = obj->find("crs_text");
    if (crs != obj->end() && crs->second.kind == JsonScalar::Kind::String) g.crs_text = crs->second.text;
  }
  if (!type) {
    if (ends_with_ci(path, ".r16"))
      type = SampleType::UInt16;
    else if (ends_with_ci(path, ".r32"))
      type = SampleType::Float32;
    else
      fail(ErrorCode::DimensionMismatch, path,
           "raw grid without a sidecar (" + path + ".json): give --type and --width/--height");
  }
  layout.info.sample_type = *type;
  layout.stored = stored_type_for(*type);
  layout.big_endian = big_endian.value_or(false);
  const uint64_t bytes = uint64_t(stored_bytes(layout.stored));
  // Without a sidecar the missing dimension can be derived from the file size (square if both miss).
  if (!width && !height) {
    uint64_t samples = size / bytes;
    auto side = int64_t(std::llround(std::sqrt(double(samples))));
    if (size % bytes != 0 || side <= 0 || uint64_t(side) * uint64_t(side) != samples)
      fail(ErrorCode::DimensionMismatch, path,
           std::to_string(size) + " bytes is not a square " + sample_type_name(*type) +
               " grid: give --width/--height");
    width = height = side;
  } else if (!height || !width) {
    int64_t known = width ? *width : *height;
    if (known <= 0 || size % (uint64_t(known) * bytes) != 0)
      fail(ErrorCode::DimensionMismatch, path,
           std::to_string(size) + " bytes is not a whole number of " + std::to_string(known) +
               "-sample lines");
    int64_t other = int64_t(size / (uint64_t(known) * bytes));
    if (!width)
      width = other;
    else
      height = other;
  }
  layout.info.width = *width;
  layout.info.height = *height;
  apply_common_overrides(layout.info, options);
  uint64_t need = layout_bytes(path, layout);
  if (need != size)
    fail(ErrorCode::DimensionMismatch, path,
         std::to_string(layout.info.width) + "x" + std::to_string(layout.info.height) + " " +
             sample_type_name(*type) + " needs " + std::to_string(need) + " bytes but the file has " +
             std::to_string(size) + " (" + (size < need ? "too short" : "too long") + ")");
  return layout;
}

void write_raw_with_sidecar(const std::string& path, const Heightmap& map, bool big_endian) {
  const GridInfo& g = map.info;
  if (g.width <= 0 || g.height <= 0 || map.values.size() != size_t(g.width * g.height))
    fail(ErrorCode::WriteFailed, path, "heightmap dimensions do not match its sample count");
  const StoredType stored = stored_type_for(g.sample_type);
  const SampleType written_type = g.sample_type == SampleType::TerrainRGB ? SampleType::Int32 : g.sample_type;
  AtomicOutput out(path);
  {
    FILE* f = std::fopen(out.temp_path().c_str(), "wb");
    if (!f) fail(ErrorCode::WriteFailed, path, std::string("cannot create: ") + std::strerror(errno));
    std::unique_ptr<FILE, int (*)(FILE*)> guard(f, std::fclose);
    const int bytes = stored_bytes(stored);
    std::vector<uint8_t> row(size_t(g.width) * size_t(bytes));
    auto put = [&](uint8_t* p, uint32_t u, int n) {
      for (int i = 0; i < n; ++i) {
        int shift = big_endian ? 8 * (n - 1 - i) : 8 * i;
        p[i] = uint8_t(u >> shift);
      }
    };
    for (int64_t y = 0; y < g.height; ++y) {
      for (int64_t x = 0; x < g.width; ++x) {
        double v = value_for_writing(map, x, y, path);
        uint8_t* p = row.data() + x * bytes;
        bool fits = true;
        switch (stored) {
          case StoredType::UInt8:
          case StoredType::Int16:
            fits = v == std::floor(v) && v >= -32768 && v <= 32767;
            put(p, uint32_t(uint16_t(int16_t(fits ? v : 0))), 2);
            break;
          case StoredType::UInt16:
            fits = v == std::floor(v) && v >= 0 && v <= 65535;
            put(p, uint32_t(fits ? v : 0), 2);
            break;
          case StoredType::Int32:
            fits = v == std::floor(v) && v >= -2147483648.0 && v <= 2147483647.0;
            put(p, uint32_t(int32_t(fits ? v : 0)), 4);
            break;
          case StoredType::Float32: {
            float fv = float(v);
            uint32_t bits;
            std::memcpy(&bits, &fv, sizeof bits);
            put(p, bits, 4);
            break;
          }
        }
        if (!fits)
          fail(ErrorCode::WriteFailed, path,
               "value " + format_double(v) + " at " + row_col(y, x) + " does not fit " +
                   sample_type_name(written_type));
      }
      if (std::fwrite(row.data(), 1, row.size(), f) != row.size())
        fail(ErrorCode::WriteFailed, path, std::string("write error: ") + std::strerror(errno));
    }
    if (std::fclose(guard.release()) != 0) fail(ErrorCode::WriteFailed, path, "write error on close");
  }

  std::ostringstream js;
  js << "{\n  \"width\": " << g.width << ",\n  \"height\": " << g.height << ",\n  \"type\": \""
     << sample_type_name(written_type) << "\",\n  \"byte_order\": \"" << (big_endian ? "big" : "little")
     << "\",\n  \"spacing_x\": " << format_double(g.spacing_x)
     << ",\n  \"spacing_y\": " << format_double(g.spacing_y)
     << ",\n  \"horizontal_units\": " << json_quote(g.horizontal_units)
     << ",\n  \"vertical_scale\": " << format_double(g.vertical_scale)
     << ",\n  \"vertical_offset\": " << format_double(g.vertical_offset) << ",\n  \"nodata\": ";
  if (!g.nodata)
    js << "null";
  else if (std::isnan(*g.nodata))
    js << "\"NaN\"";
  else
    js << format_double(*g.nodata);
  if (g.origin_x) js << ",\n  \"origin_x\": " << format_double(*g.origin_x);
  if (g.origin_y) js << ",\n  \"origin_y\": " << format_double(*g.origin_y);
  if (g.crs_epsg) js << ",\n  \"crs_epsg\": " << *g.crs_epsg;
  if (!g.crs_text.empty()) js << ",\n  \"crs_text\": " << json_quote(g.crs_text);
  js << "\n}\n";
  std::string text = js.str();
  AtomicOutput side(path + ".json");
  {
    FILE* f = std::fopen(side.temp_path().c_str(), "wb");
    if (!f)
      fail(ErrorCode::WriteFailed, path + ".json", std::string("cannot create: ") + std::strerror(errno));
    bool ok = std::fwrite(text.data(), 1, text.size(), f) == text.size();
    ok = (std::fclose(f) == 0) && ok;
    if (!ok) fail(ErrorCode::WriteFailed, path + ".json", "write error");
  }
  // The sidecar goes in first, so a reader never sees new samples described by an old sidecar.
  side.commit();
  out.commit();
}

}  // namespace terrain::io

namespace terrain {
void write_raw(const std::string& path, const Heightmap& map, bool big_endian) {
  io::write_raw_with_sidecar(path, map, big_endian);
}
}  // namespace terrain
