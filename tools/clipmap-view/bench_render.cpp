// clipmap-view --bench-render: the same flight drawn with both meshes (footprints, tessellation) in
// one run, at 640 x 480 and 1280 x 720. Every frame updates the clipmap once, uploads once, then
// renders both meshes (alternating which goes first) into one renderer, so both meet the same
// heights and the same machine load; the frames of the two meshes are compared by image PSNR.
#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>
#include <iostream>

#include "clipmap_view.h"

namespace clipmap_view {

using namespace terrain;
using namespace terrain::runtime;
using namespace terrain::render;

namespace {

struct MeshLog {
  std::vector<double> submit_ms, render_ms, gpu_ms, triangles, draw_calls, patches;
};

}  // namespace

int run_bench_render(const Flight& flight, int frames) {
  const ViewOptions& o = flight.options;
  const std::vector<Key> keys =
      o.path_file.empty() ? default_path(flight.source, flight.spacing, frames) : read_path(o.path_file);
  std::error_code ec;
  std::filesystem::create_directories(o.out_dir, ec);
  std::optional<GlLeakCheckPause> gl_setup_pause(std::in_place);
  HeadlessGL gl;
  gl_setup_pause.reset();
  RenderOptions ropt = render_options(o);
  constexpr int kWarmup = 2;  // frames left out of the timings: first uploads, shader compiles
  const std::array<std::pair<int, int>, 2> sizes = {{{640, 480}, {1280, 720}}};
  std::printf("renderer: %s (EGL %s); n = %d, %d frames (first %d untimed), median per frame\n",
              gl.renderer_name().c_str(), gl.platform().c_str(), flight.clipmap.n, frames, kWarmup);
  std::printf("%10s %13s %10s %10s %9s %8s %11s %7s %8s\n", "size", "mesh", "cpu_ms", "render_ms", "gpu_ms",
              "fps", "triangles", "draws", "patches");
  for (const auto& [width, height] : sizes) {
    Clipmap clipmap(flight.heights, flight.clipmap);
    std::optional<ClipmapRenderer> renderer;
    {
      const GlLeakCheckPause pause;
      renderer.emplace(flight.clipmap.n, clipmap.level_count(), width, height);
    }
    apply_drape(*renderer, flight);
    std::array<MeshLog, 2> logs;
    std::vector<double> psnr;
    std::array<std::vector<uint8_t>, 2> pixels;
    for (int f = 0; f < frames; ++f) {
      const Camera cam = camera_at(flight.source, interpolate(keys, double(f)), o.fov);
      clipmap.update(cam.position[0], cam.position[1], cam.position[2]);
      const GlLeakCheckPause pause;
      renderer->upload(clipmap);
      for (int k = 0; k < 2; ++k) {
        const int m = (f + k) % 2;  // 0: footprints, 1: tessellation; the first alternates
        ropt.mesh = m == 0 ? Mesh::Footprints : Mesh::Tessellation;
        const RenderStats rs = renderer->render(clipmap, cam, ropt);
        renderer->read_rgba(pixels[size_t(m)]);
        if (f < kWarmup) continue;
        MeshLog& lg = logs[size_t(m)];
        lg.submit_ms.push_back(rs.seconds_submit * 1e3);
        lg.render_ms.push_back(rs.seconds_render * 1e3);
        lg.gpu_ms.push_back(rs.seconds_gpu * 1e3);
        lg.triangles.push_back(double(rs.triangles));
        lg.draw_calls.push_back(rs.draw_calls);
        lg.patches.push_back(rs.patches);
      }
      psnr.push_back(image_psnr(pixels[1], pixels[0]));
      if (f == frames / 2 && o.png_every > 0) {  // --png-every 0: no PNG (no image plugin needed)
        for (int m = 0; m < 2; ++m) {
          char name[96];
          std::snprintf(name, sizeof name, "/mesh_%s_%dx%d.png", m == 0 ? "footprints" : "tessellation",
                        width, height);
          write_png_rgba(o.out_dir + name, width, height, pixels[size_t(m)]);
        }
      }
    }
    for (int m = 0; m < 2; ++m) {
      const MeshLog& lg = logs[size_t(m)];
      const double render = percentile(lg.render_ms, 0.5);
      char size[32];
      std::snprintf(size, sizeof size, "%dx%d", width, height);
      std::printf("%10s %13s %10.3f %10.2f %9.2f %8.1f %11.0f %7.0f %8.0f\n", size,
                  m == 0 ? "footprints" : "tessellation", percentile(lg.submit_ms, 0.5), render,
                  percentile(lg.gpu_ms, 0.5), render > 0 ? 1e3 / render : 0.0, percentile(lg.triangles, 0.5),
                  percentile(lg.draw_calls, 0.5), percentile(lg.patches, 0.5));
    }
    std::printf("%10s image PSNR tessellation vs footprints, all %d frames: median %.2f dB, min %.2f dB\n",
                "", frames, percentile(psnr, 0.5), percentile(psnr, 0.0));
    std::fflush(stdout);
  }
  if (!o.quiet && o.png_every > 0)
    std::fprintf(stderr, "clipmap-view: frames of both meshes (frame %d) in %s/mesh_*.png\n", frames / 2,
                 o.out_dir.c_str());
  return 0;
}

}  // namespace clipmap_view
