// Headless rendering of the clipmap (Mesa llvmpipe without a GPU): watertight rings, culling that
// never removes visible terrain, and transitions that remove popping.
#include <catch2/catch.hpp>

#include <cmath>
#include <memory>

#include "runtime/clipmap.h"
#include "runtime/renderer.h"

#if defined(__SANITIZE_ADDRESS__)
#include <sanitizer/lsan_interface.h>
#endif

using namespace terrain;
using namespace terrain::runtime;

namespace {

constexpr int kLevels = 6;
constexpr double kSpacing = 10.0;
constexpr int kW = 160, kH = 120;

// Smooth analytic terrain (metres) sampled at each level's points, defined everywhere.
double terrain_m(double x, double y) {
  return 60.0 * std::sin(x * 0.0021) * std::cos(y * 0.0017) + 25.0 * std::sin(x * 0.011 + y * 0.007) +
         8.0 * std::sin(x * 0.043) * std::sin(y * 0.051) + 3.0 * std::cos(x * 0.13 + y * 0.09);
}

FunctionHeightSource smooth_source() {
  return FunctionHeightSource(
      kLevels, GridSize{1 << 14, 1 << 14}, kSpacing,
      [](int level, int64_t x, int64_t y) {
        const double s = std::ldexp(kSpacing, kLevels - 1 - level);
        return float(terrain_m(double(x) * s, double(y) * s));
      },
      true);
}

HeadlessGL& gl() {
  static HeadlessGL context;  // one context for the whole test program
  return context;
}

// LeakSanitizer is paused inside the rendering tests: Mesa (libgio at driver load, llvmpipe's JIT
// on first draws) keeps a few allocations for the life of the process, which would fail the ASan
// run at exit. The clipmap code they exercise is leak-checked by the [clipmap] tests.
struct LeakCheckPause {
  LeakCheckPause() {
#if defined(__SANITIZE_ADDRESS__)
    __lsan_disable();
#endif
  }
  ~LeakCheckPause() {
#if defined(__SANITIZE_ADDRESS__)
    __lsan_enable();
#endif
  }
  LeakCheckPause(const LeakCheckPause&) = delete;
  LeakCheckPause& operator=(const LeakCheckPause&) = delete;
};

struct Scene {
  FunctionHeightSource source = smooth_source();
  Clipmap clipmap;
  ClipmapRenderer renderer;
  std::vector<uint8_t> pixels;
  explicit Scene(int n) : clipmap(source, options(n)), renderer((gl(), n), kLevels, kW, kH) {}
  static ClipmapOptions options(int n) {
    ClipmapOptions o;
    o.n = n;
    o.budget = 1 << 30;
    return o;
  }
  void move(const Camera& cam) {
    clipmap.update(cam.position[0], cam.position[1], cam.position[2]);
    renderer.upload(clipmap);
  }
  RenderStats draw(const Camera& cam, const RenderOptions& opt) {
    RenderStats s = renderer.render(clipmap, cam, opt);
    renderer.read_rgba(pixels);
    return s;
  }
};

Camera camera_at(double x, double y, double above, double yaw, double pitch) {
  Camera c;
  c.position[0] = x;
  c.position[1] = y;
  c.position[2] = terrain_m(x, y) + above;
  c.yaw = yaw;
  c.pitch = pitch;
  c.fov_y_deg = 60;
  return c;
}

double mean_abs_diff(const std::vector<uint8_t>& a, const std::vector<uint8_t>& b) {
  double s = 0;
  for (size_t i = 0; i < a.size(); ++i) s += std::abs(int(a[i]) - int(b[i]));
  return s / double(a.size());
}

}  // namespace

TEST_CASE("render: a headless OpenGL 4.5 core context comes up", "[render]") {
  LeakCheckPause pause;
  INFO("EGL platform " << gl().platform());
  CHECK(!gl().renderer_name().empty());
  WARN("OpenGL renderer: " << gl().renderer_name() << " (EGL " << gl().platform() << ")");
}

TEST_CASE("render: rings are watertight from many viewpoints", "[render]") {
  LeakCheckPause pause;
  Scene scene(31);
  RenderOptions opt;
  opt.flat_colour = true;
  opt.background_rgb[0] = opt.background_rgb[1] = opt.background_rgb[2] = 0.0f;
  // Negative control: no morph, no perimeter snap, no stitching leaves real cracks at the ring
  // boundaries; the same views must then show background pixels, or the test could not see cracks.
  RenderOptions broken = opt;
  broken.transitions = false;
  broken.snap_perimeter = false;
  broken.stitch = false;
  int levels_seen = 0;
  int64_t broken_background = 0;
  for (int i = 0; i < 24; ++i) {
    // Steep views whose whole frame lies on the terrain (the coarsest level reaches past the frame):
    // any background pixel is a crack.
    const double x = 1234.5 + 97.3 * i, y = -777.25 + 61.7 * i * (i % 3 - 1);
    const double above = 15.0 + 23.0 * (i % 7), yaw = 0.41 * i, pitch = -0.85 - 0.07 * (i % 8);
    const Camera cam = camera_at(x, y, above, yaw, pitch);
    scene.move(cam);
    scene.move(cam);
    auto background = [&] {
      int64_t count = 0;
      for (size_t p = 0; p < scene.pixels.size(); p += 4)
        if (scene.pixels[p] < 128) ++count;
      return count;
    };
    const RenderStats s = scene.draw(cam, opt);
    levels_seen = std::max(levels_seen, s.levels_drawn);
    INFO("view " << i << " at (" << x << ", " << y << ") " << above << " m above, yaw " << yaw << " pitch " << pitch);
    CHECK(background() == 0);
    scene.draw(cam, broken);
    broken_background += background();
  }
  CHECK(levels_seen >= 3);  // several rings (and so several level boundaries) were in view
  CHECK(broken_background > 0);
}

TEST_CASE("render: frustum culling never removes a visible block", "[render]") {
  LeakCheckPause pause;
  Scene scene(31);
  RenderOptions on, off;
  off.culling = false;
  int culled = 0;
  for (int i = 0; i < 12; ++i) {
    const Camera cam = camera_at(300.0 + 151.0 * i, 90.0 * i, 20.0 + 40.0 * (i % 4), 0.53 * i, -0.1 - 0.12 * (i % 5));
    scene.move(cam);
    const RenderStats a = scene.draw(cam, on);
    const std::vector<uint8_t> culled_image = scene.pixels;
    const RenderStats b = scene.draw(cam, off);
    culled += a.blocks_culled;
    CHECK(b.blocks_culled == 0);
    INFO("view " << i);
    CHECK(culled_image == scene.pixels);  // identical images: only invisible blocks were skipped
  }
  CHECK(culled > 0);  // and culling did skip some
}

TEST_CASE("render: transitions keep a slow flight free of popping", "[render]") {
  LeakCheckPause pause;
  // A slow flight: the clipmap follows the viewer, while the image is taken from a camera that
  // stays put, so that every change between consecutive frames comes from the level of detail
  // alone (moving the camera would change every pixel anyway). Without transitions a level shift
  // of 2 grid units changes a whole band of the image at once (a pop); with them the same change is
  // spread over many frames.
  double worst[2] = {0, 0}, total[2] = {0, 0};
  for (int transitions = 0; transitions < 2; ++transitions) {
    Scene scene(31);
    RenderOptions opt;
    opt.transitions = transitions == 1;
    opt.z_lo = -100;
    opt.z_hi = 100;
    const Camera cam = camera_at(2000.0, 1000.0, 60.0, 0.4, -0.45);
    std::vector<uint8_t> previous;
    for (int f = 0; f < 100; ++f) {
      const double t = 1.7 * f;  // metres along the flight
      scene.clipmap.update(cam.position[0] + t * 0.92, cam.position[1] + t * 0.39, cam.position[2]);
      scene.renderer.upload(scene.clipmap);
      scene.draw(cam, opt);
      if (!previous.empty()) {
        const double d = mean_abs_diff(previous, scene.pixels);
        worst[transitions] = std::max(worst[transitions], d);
        total[transitions] += d;
      }
      previous = scene.pixels;
    }
  }
  INFO("consecutive-frame mean |difference|, worst / total: without transitions " << worst[0] << " / " << total[0]
                                                                                 << ", with " << worst[1] << " / "
                                                                                 << total[1]);
  CHECK(worst[1] < 0.5 * worst[0]);
  CHECK(worst[1] < 0.5);
}
