// Python bindings (pybind11 + NumPy): open a .pyr and read any level's window as metres, inspect its
// description, and build a pyramid from a NumPy array or a heightmap file. A thin layer over the
// libraries' public API: container (open, info), runtime (RegionDecoder), build (build_pyramid_file).
//
//   import terrain
//   p = terrain.open("x.pyr")
//   a = p.read(p.level_count - 1, x, y, w, h)   # float32 (h, w) array, metres, NaN for voids
//   terrain.build(array_or_path, "out.pyr", rms=1.0)
//
// Errors raise terrain.Error (a RuntimeError) whose `code` is the library's error code name
// ("not found", "truncated", "corrupt", ...); decoding and building release the GIL.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <random>
#include <string>

#include "build/pyramid_build.h"
#include "container/pyramid_file.h"
#include "core/error.h"
#include "readers/heightmap.h"
#include "runtime/region_decoder.h"

namespace py = pybind11;
using namespace terrain;

namespace {

// An open pyramid: the mapped file and a region decoder (with its tile cache) over it.
class Pyramid {
 public:
  explicit Pyramid(const std::string& path)
      : file_(container::PyramidFile::open(path)),
        decoder_(std::make_shared<runtime::RegionDecoder>(file_)) {}

  int level_count() const { return file_->level_count(); }
  std::vector<std::pair<int64_t, int64_t>> levels() const {
    std::vector<std::pair<int64_t, int64_t>> out;
    for (int l = 0; l < level_count(); ++l)
      out.emplace_back(file_->level_size(l).width, file_->level_size(l).height);
    return out;
  }

  py::array_t<float> read(int level, int64_t x, int64_t y, int64_t w, int64_t h) const {
    if (level < 0 || level >= level_count())
      throw Error(ErrorCode::InvalidOption, file_->path() + ": level " + std::to_string(level) +
                                                " outside 0.." + std::to_string(level_count() - 1));
    const GridSize s = file_->level_size(level);
    if (w < 1 || h < 1 || x < 0 || y < 0 || x > s.width - w || y > s.height - h)
      throw Error(ErrorCode::InvalidOption, file_->path() + ": window " + std::to_string(w) + "x" +
                                                std::to_string(h) + " at (" + std::to_string(x) + ", " +
                                                std::to_string(y) + ") is not inside level " +
                                                std::to_string(level) + " (" + std::to_string(s.width) + "x" +
                                                std::to_string(s.height) + ")");
    py::array_t<float> out({h, w});
    float* data = out.mutable_data();
    {
      py::gil_scoped_release unlocked;
      decoder_->decode_metres(level, Rect{x, y, w, h}, data, w);
    }
    return out;
  }

  // GDAL's affine geotransform (x0, dx, 0, y0, 0, -dy) of sample corners, or None without a
  // georeference: the file stores the north-west sample's centre, half a spacing inside the corner.
  py::object geotransform() const {
    const container::ContainerInfo& i = file_->info();
    if (!i.georeference) return py::none();
    const std::array<double, 6>& t = i.georeference->geotransform;  // the stored one (2.0: derived)
    return py::make_tuple(t[0], t[1], t[2], t[3], t[4], t[5]);
  }

  py::dict info() const {
    const container::ContainerInfo& i = file_->info();
    py::dict d;
    d["path"] = file_->path();
    d["width"] = i.width;
    d["height"] = i.height;
    d["spacing"] = py::make_tuple(i.spacing_x, i.spacing_y);
    d["horizontal_units"] = i.horizontal_units;
    d["vertical_units"] = i.vertical_units;
    d["vertical_scale"] = i.vertical_scale;
    d["vertical_offset"] = i.vertical_offset;
    d["void_count"] = i.void_count;
    d["error_mode"] = container::error_mode_name(i.quantisation.mode);
    d["target"] = i.quantisation.target;
    d["step_metres"] = i.quantisation.step_metres;
    if (i.georeference) {
      d["origin"] = py::make_tuple(i.georeference->origin_x(), i.georeference->origin_y());
      d["origin_units"] = i.georeference->units;
      d["crs_epsg"] = i.georeference->crs_epsg ? py::object(py::int_(i.georeference->crs_epsg)) : py::none();
      d["crs_text"] = i.georeference->crs_text;
    }
    py::list levels;
    for (size_t l = 0; l < i.levels.size(); ++l) {
      py::dict ld;
      ld["width"] = i.levels[l].width;
      ld["height"] = i.levels[l].height;
      ld["bytes"] = i.levels[l].blob_size;
      if (const auto e = container::level_error_metres(i, l)) {
        ld["rms_m"] = e->rms;
        ld["max_m"] = e->max_abs;
      }
      levels.append(ld);
    }
    d["levels"] = levels;
    d["metadata"] = std::string(file_->container().metadata_json());
    return d;
  }

  const std::string& path() const { return file_->path(); }

 private:
  std::shared_ptr<const container::PyramidFile> file_;
  std::shared_ptr<runtime::RegionDecoder> decoder_;
};

build::BuildFileOptions build_options(std::optional<double> rms, std::optional<double> max_error,
                                      std::optional<double> step, bool lossless, int tile, int threads) {
  const int given = int(rms.has_value()) + int(max_error.has_value()) + int(step.has_value()) + int(lossless);
  if (given > 1) throw Error(ErrorCode::InvalidOption, "build: give one of rms, max_error, step, lossless");
  build::BuildFileOptions o;
  o.tile_size = uint32_t(tile);
  o.threads = threads;
  if (rms) o.mode = container::ErrorMode::Rms, o.target_metres = *rms;
  if (max_error) o.mode = container::ErrorMode::MaxError, o.target_metres = *max_error;
  if (step) o.mode = container::ErrorMode::Step, o.target_metres = *step;
  return o;
}

// A NumPy grid as a heightmap: integer arrays keep their integers (so lossless builds are exact),
// floating arrays become float32 with NaN marking voids.
Heightmap heightmap_from_array(const py::array& array, double spacing) {
  if (array.ndim() != 2)
    throw Error(ErrorCode::DimensionMismatch, "build: the array must be 2-D (rows, columns)");
  Heightmap map;
  map.info.height = array.shape(0);
  map.info.width = array.shape(1);
  map.info.spacing_x = map.info.spacing_y = spacing;
  const size_t n = size_t(map.info.width * map.info.height);
  map.values.resize(n);
  const py::dtype dt = array.dtype();
  if (dt.kind() == 'i' || dt.kind() == 'u') {
    const auto a = py::array_t<int64_t, py::array::c_style | py::array::forcecast>::ensure(array);
    const int64_t* v = a.data();
    int64_t lo = 0, hi = 0;
    for (size_t i = 0; i < n; ++i) lo = std::min(lo, v[i]), hi = std::max(hi, v[i]);
    map.info.sample_type = lo >= INT16_MIN && hi <= INT16_MAX ? SampleType::Int16 : SampleType::Int32;
    if (lo < INT32_MIN || hi > INT32_MAX)
      throw Error(ErrorCode::InvalidOption, "build: integer heights beyond the int32 range");
    for (size_t i = 0; i < n; ++i) map.values[i] = double(v[i]);
  } else if (dt.kind() == 'f') {
    const auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(array);
    const double* v = a.data();
    map.info.sample_type = SampleType::Float32;
    for (size_t i = 0; i < n; ++i) {
      if (std::isnan(v[i])) {
        if (map.valid.empty()) map.valid.assign(n, 1);
        map.valid[i] = 0;
        map.values[i] = 0;
      } else {
        map.values[i] = double(float(v[i]));
      }
    }
    if (!map.valid.empty()) map.info.nodata = std::nan("");
  } else {
    throw Error(ErrorCode::UnknownType, "build: the array must hold integers or floats");
  }
  return map;
}

// Builds `output` from a heightmap file or a 2-D array; returns pyramid-build's figures as a dict.
py::dict build_file(const py::object& source, const std::string& output, std::optional<double> rms,
                    std::optional<double> max_error, std::optional<double> step, bool lossless,
                    double spacing, int tile, int threads, const std::string& downsample,
                    const std::string& level_error, std::optional<double> coarse_step_ratio) {
  build::BuildFileOptions o = build_options(rms, max_error, step, lossless, tile, threads);
  const auto choice = build::downsample_choice_from_name(downsample);
  if (!choice) throw py::value_error("downsample must be 'auto', 'wavelet', 'optimal' or 'point'");
  o.downsample = *choice;
  if (level_error != "absolute" && level_error != "screen")
    throw py::value_error("level_error must be 'absolute' or 'screen'");
  o.screen_level_error = level_error == "screen";
  // None: automatic (pyramid-build --coarse-step-ratio auto); a value outside (0, 1] is the library's
  // InvalidOption error, as on the command line.
  if (coarse_step_ratio) {
    if (!(*coarse_step_ratio > 0))
      throw Error(ErrorCode::InvalidOption, "build: coarse_step_ratio must be in (0, 1]");
    o.coarse_step_ratio = *coarse_step_ratio;
  }
  std::string input, temp_dir;
  if (py::isinstance<py::str>(source) || py::hasattr(source, "__fspath__")) {
    input = py::str(py::module_::import("os").attr("fspath")(source));
  } else {
    const Heightmap map = heightmap_from_array(py::array::ensure(source), spacing);
    // The build streams from a file (bounded memory for any size), so an array goes through a
    // private raw grid + sidecar that is removed afterwards.
    std::random_device rd;
    temp_dir = (std::filesystem::temp_directory_path() / ("terrain-py-" + std::to_string(rd()))).string();
    std::filesystem::create_directory(temp_dir);
    input = temp_dir + "/array.raw";
    write_raw(input, map);
  }
  build::BuildFileResult r;
  try {
    py::gil_scoped_release unlocked;
    r = build::build_pyramid_file(input, {}, output, o);
  } catch (...) {
    if (!temp_dir.empty()) std::filesystem::remove_all(temp_dir);
    throw;
  }
  if (!temp_dir.empty()) std::filesystem::remove_all(temp_dir);
  py::dict d;
  d["bytes"] = r.file_bytes;
  d["bits_per_sample"] = 8.0 * double(r.file_bytes) / double(r.finest_samples);
  d["step_metres"] = r.step_units * r.metres_per_unit;
  d["finest_rms_m"] = r.build.levels.back().error_rms * r.metres_per_unit;
  d["finest_max_m"] = double(r.build.levels.back().error_max_abs) * r.metres_per_unit;
  d["coarse_step_ratio"] = r.coarse_step_ratio;
  py::list steps;  // coarsest first, metres
  for (double s : r.level_step_units) steps.append(s * r.metres_per_unit);
  d["level_step_metres"] = steps;
  return d;
}

}  // namespace

PYBIND11_MODULE(terrain, m) {
  m.doc() =
      "Compressed terrain pyramids (.pyr): read windows of any level as metres, build from arrays or files.";
  static py::exception<Error> error(m, "Error", PyExc_RuntimeError);
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const Error& e) {
      // An instance carrying the code, so Python callers can tell "not found" from "corrupt".
      py::object value = py::reinterpret_steal<py::object>(PyObject_CallFunction(error.ptr(), "s", e.what()));
      value.attr("code") = error_code_name(e.code());
      PyErr_SetObject(error.ptr(), value.ptr());
    }
  });

  py::class_<Pyramid>(m, "Pyramid", "An open .pyr file (read-only, memory-mapped).")
      .def_property_readonly("path", &Pyramid::path)
      .def_property_readonly("level_count", &Pyramid::level_count)
      .def_property_readonly("levels", &Pyramid::levels, "(width, height) of each level, coarsest first")
      .def_property_readonly("info", &Pyramid::info, "the file's description as a dict")
      .def_property_readonly("geotransform", &Pyramid::geotransform,
                             "GDAL-style (x0, dx, 0, y0, 0, -dy) of sample corners, or None")
      .def("read", &Pyramid::read, py::arg("level"), py::arg("x"), py::arg("y"), py::arg("width"),
           py::arg("height"), "float32 array (height, width) of the level's heights in metres; NaN at voids");
  m.def(
      "open", [](const std::string& path) { return Pyramid(path); }, py::arg("path"),
      "Opens and validates a .pyr file.");
  m.def("build", &build_file, py::arg("source"), py::arg("output"), py::kw_only(),
        py::arg("rms") = py::none(), py::arg("max_error") = py::none(), py::arg("step") = py::none(),
        py::arg("lossless") = false, py::arg("spacing") = 1.0, py::arg("tile") = 32, py::arg("threads") = 0,
        py::arg("downsample") = "auto", py::arg("level_error") = "absolute",
        py::arg("coarse_step_ratio") = py::none(),
        "Builds a .pyr from a heightmap file or a 2-D array (integers: exact; floats: NaN = void). One of "
        "rms / max_error / step (metres) or lossless (the default). downsample: the coarse levels' filter, "
        "'auto' (the default, as pyramid-build: 'point' for max_error and lossless, 'wavelet' for step, the "
        "smaller of the two at an rms target), "
        "'wavelet', 'optimal' (the paper's fitted D) or 'point' (subsampling). level_error: 'absolute' (one "
        "step at every level, the default) or 'screen' (level l's step 2^(m-l) times the finest's). "
        "coarse_step_ratio: step and rms targets, the two levels above the finest get the finest step "
        "times R and R^2, R in (0, 1]; None (the default) is 1 for a step and calibrated for an rms "
        "target. The dict returned gives the ratio used and every level's step (coarsest first).");
}
