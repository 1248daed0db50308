// Helpers shared by the rendering tests of the runtime test program: the one headless GL context
// of the whole program and the crack check of the watertight
// tests (flat terrain colour on a black background: any background pixel in a frame that lies
// wholly on the terrain is a crack).
#pragma once

#include <cmath>
#include <cstdint>
#include <vector>

#include "render/leak_check.h"
#include "render/renderer.h"

namespace rendertest {

// One context for the whole test program (inline: every test file shares it, so renderers created
// by different files never meet a context that is not current).
inline terrain::render::HeadlessGL& gl() {
  static terrain::render::HeadlessGL context;
  return context;
}

// Render options of the crack check: every terrain pixel white, the background black.
inline terrain::render::RenderOptions crack_check_options() {
  terrain::render::RenderOptions opt;
  opt.flat_colour = true;
  opt.background_rgb[0] = opt.background_rgb[1] = opt.background_rgb[2] = 0.0f;
  return opt;
}

// The same with transitions, perimeter snap and stitching off: real cracks at the ring boundaries
// (the negative control: the crack check must see them).
inline terrain::render::RenderOptions cracked_options() {
  terrain::render::RenderOptions opt = crack_check_options();
  opt.transitions = false;
  opt.snap_perimeter = false;
  opt.stitch = false;
  return opt;
}

// View i of the low grazing flights: the camera 32-48 m above the source's finest sample under
// (x, y) metres, yaw 0.41 i, the top of the frame 0.15 rad below the horizon (the frame reaches from
// below the camera to where the rays meet the ground, hundreds of metres ahead or more). The height
// above that sample goes to *above_m when given.
inline terrain::render::Camera low_grazing_view(terrain::runtime::HeightSource& source, int i, double x,
                                                double y, double* above_m = nullptr) {
  float ground = 0;
  const double g = source.spacing_m();
  source.fill(source.level_count() - 1, terrain::Rect{int64_t(x / g), int64_t(y / g), 1, 1}, &ground, 1);
  terrain::render::Camera cam;
  cam.position[0] = x;
  cam.position[1] = y;
  const double above = 32.0 + 4.0 * (i % 5);
  if (above_m) *above_m = above;
  cam.position[2] = double(ground) + above;
  cam.yaw = 0.41 * i;
  cam.pitch = -0.15 - 0.5 * cam.fov_y_deg * M_PI / 180.0;
  return cam;
}

// Background pixels of an RGBA frame rendered with crack_check_options().
inline int64_t background_pixels(const std::vector<uint8_t>& rgba) {
  int64_t count = 0;
  for (size_t p = 0; p < rgba.size(); p += 4)
    if (rgba[p] < 128) ++count;
  return count;
}

}  // namespace rendertest
