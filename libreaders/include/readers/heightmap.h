// Heightmap grids and GDAL-free readers/writers: the "reader" stage of the data flow.
//
// Samples are held as double in the file's native units (an int16 .hgt sample is held exactly as
// that integer, a float32 sample exactly as that float); metres = value * vertical_scale +
// vertical_offset. Doubles hold every supported sample type exactly, so integer inputs can be
// coded losslessly downstream.
//
// Errors: every reader/writer throws terrain::Error (core/error.h) whose message names the file and
// the problem, and whose code() classifies it; beyond that only std::bad_alloc.
// Threads: every function may be called from any thread at once (the image plugin is loaded once,
// under std::call_once); a BandReader is used by one thread at a time.
// Untrusted input: the readers are meant for files from anywhere. .hgt, raw and ESRI grids must
// have exactly the bytes their dimensions need (else Truncated/Oversized) and are fuzzed
// (fuzz/fuzz_read_*.cpp); images are decoded by OpenImageIO through the plugin, so an image
// header claiming a huge size can make read_heightmap allocate up to its 2^34-sample limit.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/error.h"

namespace terrain {

enum class SampleType { Int16, UInt16, Int32, Float32, TerrainRGB };
// "int16", "uint16", "int32", "float32", "terrain-rgb"; static storage.
const char* sample_type_name(SampleType t);
// Parses "int16", "uint16", "int32", "float32" (also "i16", "u16", "i32", "f32", "short", "float"; any
// case); nullopt if unknown.
std::optional<SampleType> sample_type_from_name(const std::string& name);

enum class FileFormat { Hgt, Raw, EsriBil, EsriFlt, Image, TerrainRgbImage, EsriAscii };
const char* file_format_name(FileFormat f);  // e.g. "srtm-hgt", "raw"; static storage

// Everything known about a grid except its samples.
struct GridInfo {
  int64_t width = 0;
  int64_t height = 0;
  SampleType sample_type = SampleType::Int16;
  FileFormat format = FileFormat::Raw;
  double spacing_x = 1.0;  // horizontal sample spacing, in horizontal_units
  double spacing_y = 1.0;
  std::string horizontal_units = "m";  // "m" or "arc-second"
  double vertical_scale = 1.0;         // metres = value * vertical_scale + vertical_offset
  double vertical_offset = 0.0;
  std::optional<double> nodata;  // native value marking a void, if any
  // Georeference of the north-west sample centre, when the input has one (.hgt file name, ESRI
  // header, GeoTIFF tags), in the CRS's units (degrees when horizontal_units is "arc-second"). Grids
  // are north-up: columns run east by spacing_x, rows south by spacing_y; readers refuse rotated or
  // flipped georeferences. geotransform() below gives the full affine form.
  std::optional<double> origin_x;  // longitude or easting of column 0
  std::optional<double> origin_y;  // latitude or northing of row 0
  // The coordinate reference system, when known: its EPSG code (4326 for SRTM names, a GeoTIFF's
  // GeographicType/ProjectedCSType key, a .prj's AUTHORITY) and/or the CRS text the input carries
  // (a .prj's WKT, a GeoTIFF's "ESRI PE String" citation), kept as is (is_crs_text, core/text.h).
  std::optional<int> crs_epsg;
  std::string crs_text;
  bool integer_valued() const { return sample_type != SampleType::Float32; }
};

// GDAL's affine geotransform of pixel corners: x = gt[0] + col * gt[1] + row * gt[2], y = gt[3] +
// col * gt[4] + row * gt[5], in the CRS's units (spacing in arc-seconds becomes degrees); gt[2] and
// gt[4] are 0 and gt[5] = -spacing (north-up). nullopt without an origin.
std::optional<std::array<double, 6>> geotransform(const GridInfo& info);

// A whole grid in memory. Row-major, row 0 is the northern edge. at/is_valid/metres do not check
// their coordinates (0 <= x < width, 0 <= y < height).
struct Heightmap {
  GridInfo info;
  std::vector<double> values;  // width*height native values (voids hold 0)
  std::vector<uint8_t> valid;  // width*height, 1 = data, 0 = void; empty means all valid

  int64_t width() const { return info.width; }
  int64_t height() const { return info.height; }
  double at(int64_t x, int64_t y) const { return values[size_t(y * info.width + x)]; }
  bool is_valid(int64_t x, int64_t y) const { return valid.empty() || valid[size_t(y * info.width + x)]; }
  double metres(int64_t x, int64_t y) const { return at(x, y) * info.vertical_scale + info.vertical_offset; }
};

// How to interpret a file whose layout is not self-describing (raw grids), and overrides.
// Fields left unset come from the file, its header or its JSON sidecar (<file>.json).
struct ReadOptions {
  std::optional<int64_t> width, height;                   // samples (raw grids)
  std::optional<SampleType> sample_type;                  // raw grids
  std::optional<bool> big_endian;                         // raw grids; default little endian
  std::optional<double> spacing_x, spacing_y;             // override, in the file's horizontal units
  std::optional<double> vertical_scale, vertical_offset;  // override: metres = value * scale + offset
  std::optional<double> nodata;                           // override: native value marking a void
  bool terrain_rgb = false;  // decode an RGB(A) 8-bit image as Mapbox Terrain-RGB
};

// Streams a grid in bands of rows; memory is O(width * rows requested). Opened through open_band_reader.
class BandReader {
 public:
  virtual ~BandReader() = default;
  virtual const GridInfo& info() const = 0;  // known once opened, before any row is read
  // Reads up to `rows` further rows into values (rows*width) and valid (rows*width, 1 = data).
  // Returns the number of rows read: 0 at the end. Throws Error on bad data (e.g. NaN, truncation).
  virtual int64_t read_rows(int64_t rows, double* values, uint8_t* valid) = 0;
  // Moves past up to `rows` further rows without returning them (they count as read). Returns the
  // number of rows skipped: fewer only at the end. Uncompressed fixed-layout files (raw, .hgt, .bil,
  // .flt) seek; other formats read and discard. The skipped rows are not checked (a later pass that
  // reads them reports their errors), except that a file too short to hold them is Truncated.
  virtual int64_t skip_rows(int64_t rows);
  // Whether read_rows_int32 decodes the stored integers directly (raw, .hgt and .bil grids of an
  // integer type): the same rows as read_rows, as int32 without the detour through doubles (the
  // pyramid builder's input thread reads that way; at 16 threads it was on the build's critical path).
  virtual bool reads_int32() const { return false; }
  // Where reads_int32(): reads up to `rows` further rows into values (the samples, 0 where void) and
  // valid, exactly as read_rows would; returns the rows read, 0 at the end; throws Error as read_rows
  // does. Elsewhere it throws std::logic_error.
  virtual int64_t read_rows_int32(int64_t rows, int32_t* values, uint8_t* valid);
  int64_t rows_read() const { return rows_read_; }  // rows returned so far

 protected:
  int64_t rows_read_ = 0;
};

// Detects the format from the name and contents: .hgt/.hgt.gz, .bil/.flt (+ .hdr), .raw/.bin/.r16/.r32
// (+ .json sidecar or options), .png/.tif/.tiff/.exr via OpenImageIO. An 8-bit RGB(A) image is decoded
// as Mapbox Terrain-RGB when options.terrain_rgb is set or when it is a PNG (auto-detected); an 8-bit
// RGB TIFF without the option is an UnknownType error. See docs/io.md for the sidecar schema.
// probe: the grid's description without its samples (reads headers and sidecars only). Throws
// Error: NotFound, UnknownType (no format recognised), DimensionMismatch, MissingField, ...
GridInfo probe(const std::string& path, const ReadOptions& options = {});
// A reader positioned before row 0, never null; throws Error as probe does.
std::unique_ptr<BandReader> open_band_reader(const std::string& path, const ReadOptions& options = {});
// Reads the whole grid (through the band reader); valid comes back empty when there is no void.
// Throws Error as open_band_reader and read_rows do, and DimensionMismatch beyond 2^34 samples.
Heightmap read_heightmap(const std::string& path, const ReadOptions& options = {});

// Writers. Each writes to a temporary name beside the target and renames it when complete, so the
// target is either the old file or the whole new one; on failure the temporary is removed. They throw
// Error(WriteFailed, ...) when the samples do not fit the format (a void without a nodata value,
// a value the sample type cannot hold) or the file cannot be written.
// Raw: samples in info.sample_type (little endian unless big_endian), plus <path>.json sidecar.
void write_raw(const std::string& path, const Heightmap& map, bool big_endian = false);
// 16-bit grey PNG or TIFF (by extension): values must be integers within uint16 (or int16 for TIFF).
void write_image16(const std::string& path, const Heightmap& map);
// float32 EXR of the native values.
void write_exr(const std::string& path, const Heightmap& map);

// Statistics over valid samples, in metres.
struct GridStats {
  double min_m = 0, max_m = 0, mean_m = 0;    // metres; all 0 when no sample is valid
  int64_t valid_count = 0, nodata_count = 0;  // samples
};
GridStats compute_stats(const Heightmap& map);  // no throw
// Same statistics, streamed from a freshly opened band reader in bands of band_rows rows
// (memory O(width * band_rows)). Throws Error like read_rows.
GridStats stream_stats(BandReader& reader, int64_t band_rows = 256);

}  // namespace terrain
