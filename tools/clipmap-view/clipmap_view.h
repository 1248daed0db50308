// clipmap-view's parts: main.cpp (options, dispatch), flight.cpp (the camera flight, its frames and
// statistics), verify.cpp (the reference flight and the screen-space error against the original),
// bench.cpp (--bench: refill and region-decode timing), bench_render.cpp (--bench-render: both meshes).
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include "container/container.h"
#include "render/leak_check.h"
#include "render/renderer.h"
#include "runtime/clipmap.h"
#include "runtime/edit_overlay.h"
#include "runtime/region_decoder.h"
#include "runtime/screen_error.h"

namespace clipmap_view {

using Clock = std::chrono::steady_clock;
inline double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// p-quantile of v by nearest rank (0 for an empty v); p = 0.5 is the median, 0 the minimum.
double percentile(std::vector<double> v, double p);

// The damaged parts of the pyramid the flight's decoders met (DamagePolicy::Degrade), each logged
// once on stderr ("clipmap-view: damaged: ..."), whichever decoder met it first.
class DamageLog {
 public:
  // Logs what `decoder` met since the last poll of it and no decoder reported before.
  void poll(const terrain::runtime::RegionDecoder& decoder);
  const std::vector<terrain::runtime::DamagedTile>& parts() const { return parts_; }

 private:
  std::map<const terrain::runtime::RegionDecoder*, size_t> seen_;  // damaged_count() at the last poll
  std::set<std::tuple<int, size_t, int64_t, int64_t>> keys_;       // level, band, tile_x, tile_y
  std::vector<terrain::runtime::DamagedTile> parts_;
};

// The command line, as far as the flight needs it (clipmap options go in ClipmapOptions).
struct ViewOptions {
  std::string pyramid, out_dir = "clipmap-frames", path_file, reference, original;
  std::optional<double> original_vscale;
  int width = 640, height = 480, frames = 300, png_every = 1;
  double fov = 60;
  std::optional<double> max_screen_error;
  bool no_transitions = false, no_culling = false;
  bool quiet = false;
  terrain::render::Shading shading = terrain::render::Shading::Hypsometric;
  bool frames_given = false;
  // --window: a desktop window (GLFW) instead of the headless flight; --script drives it with timed
  // events, --screenshot writes its last frame, --record-path its camera per frame as keyframes.
  bool window = false;
  std::string script, screenshot, screenshot_window, record_path;
  std::string drape;  // --drape: an 8-bit RGB(A) image over the terrain's extent
  terrain::render::Mesh mesh = terrain::render::Mesh::Footprints;  // --mesh
  // --plot-times: a PNG of update and render time per frame; --edit-script: timed terrain edits;
  // --mirror: the virtual mirrored terrain's side (0: none).
  std::string plot_times, edit_script;
  int64_t mirror = 0;
  // --edit-pyramid: write the edits into the pyramid file (libedit) instead of an overlay in memory;
  // --edit-source: the heightmap it was built from (the editor then re-codes against its rebuild).
  bool edit_pyramid = false;
  std::string edit_source;
};

// The renderer's options from the command line.
terrain::render::RenderOptions render_options(const ViewOptions& o);

// One keyframe: position in metres (x east along columns, y along rows), height above the ground,
// heading and pitch in degrees.
struct Key {
  double frame, x, y, above, yaw_deg, pitch_deg;
};
// The lines of a small text file (at most 16 MiB, a regular file) with their 1-based numbers, '#'
// comments cut off; `what` names it in errors. Throws Error.
std::vector<std::pair<int, std::string>> read_small_text(const std::string& path, const std::string& what);
// A --path file's keyframes (frame numbers increasing); throws Error.
std::vector<Key> read_path(const std::string& path);
// The built-in flight over `source`'s terrain for `frames` frames.
std::vector<Key> default_path(terrain::runtime::HeightSource& source, double spacing, int frames);
// The keyframes interpolated linearly at `frame` (clamped to the first and last).
Key interpolate(const std::vector<Key>& keys, double frame);
// The finest level's height (metres) at the sample nearest (x, y), clamped into the terrain.
float ground_height(terrain::runtime::HeightSource& source, double x, double y);
// The flight's camera at a keyframe: `above` metres over ground_height.
terrain::render::Camera camera_at(terrain::runtime::HeightSource& source, const Key& k, double fov_deg);

// --edit-script: lines 'SECONDS brush X Y RADIUS HEIGHT [cone|smooth|flat]' and 'SECONDS channel X0
// Y0 X1 Y1 RADIUS DEPTH' (finest-level samples, metres; # comments), at frame round(30 SECONDS).
struct EditEvent {
  int frame = 0;
  terrain::runtime::TerrainEdit edit;
};
std::vector<EditEvent> read_edit_script(const std::string& path);

// What a flight flies over.
struct Flight {
  const ViewOptions& options;
  std::shared_ptr<const terrain::container::PyramidFile> file, ref_file;  // ref_file: --reference, or null
  std::shared_ptr<const terrain::runtime::RegionDecoder> decoder;         // source's (per-frame counts)
  terrain::runtime::RegionDecoderSource& source;  // the pyramid's levels (ground height, default path)
  terrain::runtime::HeightSource& heights;        // what the clipmap shows: source or its synthesis
  terrain::runtime::ClipmapOptions clipmap;
  double spacing;  // metres between finest samples
  // Under the camera (ground height, the default path): `source`, or --mirror's virtual terrain.
  terrain::runtime::HeightSource* ground = nullptr;
};

// The screen-space error of levels first_level.. for triangles of s_px pixels, estimated from the
// pyramid's own finest level, plus that level's recorded compression error (finest_error, when the
// file has it) as a bound; warns on stderr when it has not.
std::vector<terrain::runtime::LevelScreenError> screen_error_bound(
    const ViewOptions& o, const terrain::container::ContainerInfo& info,
    terrain::runtime::RegionDecoderSource& source, int first_level, double s_px,
    std::optional<terrain::container::LevelError>& finest_error);

// --drape: reads the image (any 8-bit RGB or RGBA file the readers take, through their Terrain-RGB
// path, which keeps R, G, B exactly) and hands it to the renderer over the finest level's area
// (samples -0.5 .. size - 0.5, pixel-is-area). Nothing without --drape. Throws Error (UnknownType for
// an image that is not 8-bit RGB).
void apply_drape(terrain::render::ClipmapRenderer& renderer, const Flight& flight);

// --window: the interactive (or --script driven) viewer; the same clipmap, renderer and shaders as
// run_flight, in a GLFW window. Returns the exit status; cli::kExitUnavailable when this build has no
// GLFW or no window can be opened.
int run_window(const Flight& flight);

// Plays the flight: PNG frames, stats.csv and stats.json in options.out_dir, a summary on stdout.
// Returns the exit status (cli::kExitDamaged when the pyramid's decoder met damaged tiles, which are
// logged once each); throws Error when an output cannot be written.
int run_flight(const Flight& flight);

// The reference flight's height source: --reference's pyramid or --original's levels (then also
// `original`, for the screen-space error); source stays null without either.
struct Reference {
  std::unique_ptr<terrain::runtime::HeightSource> source;
  const terrain::runtime::GridHeightSource* original = nullptr;
};
// Fills `out`; when the reference does not match the pyramid, prints why and returns the exit status.
std::optional<int> open_reference(const Flight& flight, Reference& out);
// Screen-space geometric error (L&H 2004 Table 2) of the pyramid's levels from first_level on against
// the original, for triangles of s_px pixels; printed as a table on stdout and returned. Damaged tiles
// are shown from coarser levels (and go to `damage`), as in the flight.
std::vector<terrain::runtime::LevelScreenError> report_screen_space_error(
    const Flight& flight, const terrain::runtime::GridHeightSource& original, int first_level, double s_px,
    DamageLog& damage);
// Image PSNR of two RGBA frames of equal size over the colour channels; 99 dB when identical.
double image_psnr(const std::vector<uint8_t>& pixels, const std::vector<uint8_t>& reference);

// --bench: `reps` full refills of every clipmap level, then one n x n window of the finest level
// split into U and residual. Prints the tables on stdout; returns the exit status.
int run_bench(const std::shared_ptr<const terrain::container::PyramidFile>& file, double spacing,
              terrain::runtime::ClipmapOptions options, int reps, bool quiet);

// --bench-render: the flight's first `frames` frames drawn with both meshes at 640 x 480 and
// 1280 x 720: a table of CPU (submission), render and GPU milliseconds, fps and triangles per mesh
// and the image PSNR between them on stdout, the middle frame of each mesh as PNG in options.out_dir.
// Returns the exit status; throws Error when a frame cannot be written.
int run_bench_render(const Flight& flight, int frames);

}  // namespace clipmap_view
