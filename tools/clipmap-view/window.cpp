// clipmap-view --window: the viewer in a desktop window. What differs from the headless flight is
// only the context (GLFW's window instead of EGL's surfaceless one) and the event loop (keyboard,
// mouse or a --script of timed events move the camera); the clipmap, ClipmapRenderer, its shaders and
// RenderOptions are the flight's. The renderer draws into its framebuffer object as always, which is
// then blitted to the window and overlaid with a text panel (fps, levels, screen-space error), so the
// --screenshot (the framebuffer object) is exactly what the headless path renders for that camera.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <optional>
#include <sstream>

#include "cli.h"
#include "clipmap_view.h"
#include "raster.h"
#include "render/renderer.h"
#include "report_file.h"

#if defined(TERRAIN_HAVE_GLFW)
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>
#endif

namespace clipmap_view {

using namespace terrain;
using namespace terrain::runtime;
using namespace terrain::render;

#if !defined(TERRAIN_HAVE_GLFW)

int run_window(const Flight&) {
  std::cerr << "clipmap-view: --window: this build has no GLFW (install libglfw3-dev and rebuild); the "
               "headless flight works without it (exit "
            << cli::kExitUnavailable << ")\n";
  return cli::kExitUnavailable;
}

#else

namespace {

// One scripted event: at `time` seconds, a key goes down or up, the mouse moves, or the viewer quits.
struct ScriptEvent {
  double time = 0;
  enum Kind { Key, Mouse, Quit } kind = Key;
  int key = 0;
  bool down = false;
  double dx = 0, dy = 0;
};

int key_code(const std::string& name) {
  static const std::map<std::string, int> keys = {
      {"W", GLFW_KEY_W},           {"A", GLFW_KEY_A},         {"S", GLFW_KEY_S},
      {"D", GLFW_KEY_D},           {"Q", GLFW_KEY_Q},         {"E", GLFW_KEY_E},
      {"T", GLFW_KEY_T},           {"C", GLFW_KEY_C},         {"L", GLFW_KEY_L},
      {"F", GLFW_KEY_F},           {"PLUS", GLFW_KEY_EQUAL},  {"+", GLFW_KEY_EQUAL},
      {"MINUS", GLFW_KEY_MINUS},   {"-", GLFW_KEY_MINUS},     {"ESC", GLFW_KEY_ESCAPE},
      {"ESCAPE", GLFW_KEY_ESCAPE}, {"UP", GLFW_KEY_UP},       {"DOWN", GLFW_KEY_DOWN},
      {"LEFT", GLFW_KEY_LEFT},     {"RIGHT", GLFW_KEY_RIGHT},
  };
  std::string upper = name;
  for (char& c : upper) c = char(std::toupper(static_cast<unsigned char>(c)));
  const auto it = keys.find(upper);
  return it == keys.end() ? -1 : it->second;
}

std::vector<ScriptEvent> read_script(const std::string& path) {
  std::vector<ScriptEvent> events;
  for (const auto& [number, line] : read_small_text(path, "script")) {
    std::istringstream s(line);
    ScriptEvent e;
    std::string what;
    if (!(s >> e.time)) continue;  // blank or comment line
    const std::string where = path + ":" + std::to_string(number) + ": ";
    if (!std::isfinite(e.time) || e.time < 0 || !(s >> what))
      throw Error(ErrorCode::MissingField, where + "expected 'SECONDS key|mouse|quit ...'");
    if (!events.empty() && e.time < events.back().time)
      throw Error(ErrorCode::MissingField, where + "times must not decrease");
    if (what == "key") {
      std::string name, state;
      if (!(s >> name >> state) || (state != "down" && state != "up") || (e.key = key_code(name)) < 0)
        throw Error(ErrorCode::MissingField,
                    where + "expected 'SECONDS key NAME down|up' (NAME: W A S D Q E T C L F PLUS MINUS ESC)");
      e.down = state == "down";
    } else if (what == "mouse") {
      e.kind = ScriptEvent::Mouse;
      if (!(s >> e.dx >> e.dy) || !std::isfinite(e.dx + e.dy))
        throw Error(ErrorCode::MissingField, where + "expected 'SECONDS mouse DX DY' (pixels)");
    } else if (what == "quit") {
      e.kind = ScriptEvent::Quit;
    } else {
      throw Error(ErrorCode::MissingField, where + "unknown event '" + what + "' (key, mouse or quit)");
    }
    events.push_back(e);
  }
  return events;
}

// The viewer's state: camera, speed, toggles, held keys; changed by key and mouse events alike from
// GLFW's callbacks or the script.
struct Viewer {
  Camera camera;
  RenderOptions render;
  double speed = 100;  // metres per second
  bool quit = false;
  std::map<int, bool> held;
  bool dragging = false;
  double last_x = 0, last_y = 0;

  void key(int k, bool down) {
    held[k] = down;
    if (!down) return;
    // The toggles; Esc quits, +/- change the speed.
    const std::pair<int, bool*> toggles[] = {{GLFW_KEY_T, &render.transitions},
                                             {GLFW_KEY_C, &render.culling},
                                             {GLFW_KEY_L, &render.level_colours},
                                             {GLFW_KEY_F, &render.wireframe}};
    for (const auto& [code, flag] : toggles)
      if (k == code) *flag = !*flag;
    if (k == GLFW_KEY_ESCAPE) quit = true;
    if (k == GLFW_KEY_EQUAL || k == GLFW_KEY_KP_ADD) speed *= 2;
    if (k == GLFW_KEY_MINUS || k == GLFW_KEY_KP_SUBTRACT) speed = std::max(speed / 2, 0.01);
  }
  // Mouse look: right turns right, up looks up (0.003 radians per pixel).
  void mouse(double dx, double dy) {
    camera.yaw -= 0.003 * dx;
    camera.pitch = std::clamp(camera.pitch - 0.003 * dy, -1.55, 1.55);
  }
  bool is_held(int k) const {
    const auto it = held.find(k);
    return it != held.end() && it->second;
  }
  // WASD in the horizontal plane of the view, E/Q up and down; dt seconds.
  void move(double dt) {
    const double f[2] = {std::cos(camera.yaw), std::sin(camera.yaw)}, r[2] = {f[1], -f[0]};
    double ahead = 0, side = 0, up = 0;
    if (is_held(GLFW_KEY_W) || is_held(GLFW_KEY_UP)) ahead += 1;
    if (is_held(GLFW_KEY_S) || is_held(GLFW_KEY_DOWN)) ahead -= 1;
    if (is_held(GLFW_KEY_D) || is_held(GLFW_KEY_RIGHT)) side += 1;
    if (is_held(GLFW_KEY_A) || is_held(GLFW_KEY_LEFT)) side -= 1;
    if (is_held(GLFW_KEY_E)) up += 1;
    if (is_held(GLFW_KEY_Q)) up -= 1;
    const double d = speed * dt;
    camera.position[0] += d * (ahead * f[0] + side * r[0]);
    camera.position[1] += d * (ahead * f[1] + side * r[1]);
    camera.position[2] += d * up;
  }
};

// The overlay: text lines rasterised on the CPU (cli::Canvas, the 5 x 7 font) into a texture drawn
// with alpha blending over the top-left corner of the window.
class Overlay {
 public:
  Overlay() {
    const char* vs = R"(#version 450 core
uniform vec4 u_rect;  // x0 y0 x1 y1 in normalised device coordinates
out vec2 v_uv;
void main() {
  vec2 c = vec2(float(gl_VertexID & 1), float((gl_VertexID >> 1) & 1));
  v_uv = vec2(c.x, 1.0 - c.y);  // the canvas' row 0 is its top
  gl_Position = vec4(mix(u_rect.xy, u_rect.zw, c), 0.0, 1.0);
}
)";
    const char* fs = R"(#version 450 core
in vec2 v_uv;
uniform sampler2D u_text;
out vec4 o_colour;
void main() { o_colour = texture(u_text, v_uv); }
)";
    program_ = glCreateProgram();
    for (auto [kind, src] : {std::pair{GL_VERTEX_SHADER, vs}, std::pair{GL_FRAGMENT_SHADER, fs}}) {
      const GLuint s = glCreateShader(kind);
      glShaderSource(s, 1, &src, nullptr);
      glCompileShader(s);
      glAttachShader(program_, s);
      glDeleteShader(s);
    }
    glLinkProgram(program_);
    GLint ok = 0;
    glGetProgramiv(program_, GL_LINK_STATUS, &ok);
    if (!ok) throw std::runtime_error("clipmap-view: overlay shader failed to link");
    u_rect_ = glGetUniformLocation(program_, "u_rect");
    glCreateVertexArrays(1, &vao_);
    glCreateTextures(GL_TEXTURE_2D, 1, &texture_);
    glTextureParameteri(texture_, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTextureParameteri(texture_, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  }
  ~Overlay() {
    glDeleteTextures(1, &texture_);
    glDeleteVertexArrays(1, &vao_);
    glDeleteProgram(program_);
  }
  Overlay(const Overlay&) = delete;
  Overlay& operator=(const Overlay&) = delete;

  // Draws `lines` into the default framebuffer of fb_w x fb_h pixels.
  void draw(const std::vector<std::string>& lines, int fb_w, int fb_h) {
    const int scale = fb_w >= 1200 ? 2 : 1, pad = 4 * scale, step = 10 * scale;
    int w = 0;
    for (const std::string& l : lines) w = std::max(w, cli::Canvas::text_width(l, scale));
    cli::Canvas canvas(w + 2 * pad, int(lines.size()) * step + 2 * pad - 3 * scale, {0, 0, 0, 150});
    for (size_t i = 0; i < lines.size(); ++i)
      canvas.text(pad, pad + int(i) * step, lines[i], {255, 255, 255, 255}, scale);
    if (canvas.width() != tex_w_ || canvas.height() != tex_h_) {
      glDeleteTextures(1, &texture_);
      glCreateTextures(GL_TEXTURE_2D, 1, &texture_);
      glTextureParameteri(texture_, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
      glTextureParameteri(texture_, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
      glTextureStorage2D(texture_, 1, GL_RGBA8, canvas.width(), canvas.height());
      tex_w_ = canvas.width(), tex_h_ = canvas.height();
    }
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glTextureSubImage2D(texture_, 0, 0, 0, tex_w_, tex_h_, GL_RGBA, GL_UNSIGNED_BYTE, canvas.rgba().data());
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    glViewport(0, 0, fb_w, fb_h);
    glDisable(GL_DEPTH_TEST);
    glEnable(GL_BLEND);
    glBlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
    glUseProgram(program_);
    const float x0 = -1 + 2.0f * 8 / float(fb_w), y1 = 1 - 2.0f * 8 / float(fb_h);
    glUniform4f(u_rect_, x0, y1 - 2.0f * float(tex_h_) / float(fb_h), x0 + 2.0f * float(tex_w_) / float(fb_w),
                y1);
    glBindTextureUnit(0, texture_);
    glBindVertexArray(vao_);
    glDrawArrays(GL_TRIANGLE_STRIP, 0, 4);
    glDisable(GL_BLEND);
  }

 private:
  GLuint program_ = 0, vao_ = 0, texture_ = 0;
  GLint u_rect_ = -1;
  int tex_w_ = 0, tex_h_ = 0;
};

std::string glfw_error_text;
void on_glfw_error(int code, const char* text) {
  glfw_error_text = std::string(text ? text : "?") + " (GLFW error " + std::to_string(code) + ")";
}

struct GlfwSession {
  bool ok = false;
  GlfwSession() : ok(glfwInit() == GLFW_TRUE) {}
  ~GlfwSession() {
    if (ok) glfwTerminate();
  }
  GlfwSession(const GlfwSession&) = delete;
  GlfwSession& operator=(const GlfwSession&) = delete;
};

std::string on_off(bool b) { return b ? "on" : "off"; }

}  // namespace

int run_window(const Flight& flight) {
  const ViewOptions& o = flight.options;
  const ClipmapOptions& copt = flight.clipmap;
  RegionDecoderSource& source = flight.source;
  const std::vector<ScriptEvent> script =
      o.script.empty() ? std::vector<ScriptEvent>{} : read_script(o.script);
  const bool scripted = !o.script.empty();
  const std::vector<Key> keys = o.path_file.empty()
                                    ? default_path(source, flight.spacing, std::max(o.frames, 2))
                                    : read_path(o.path_file);
  Clipmap clipmap(flight.heights, copt);
  DamageLog damage;

  // Screen-space error per level (the estimate --max-screen-error uses, with the file's finest-level
  // error as a bound): the overlay shows the worst level being drawn.
  const int first_level = clipmap.source_level(0);
  const double s_px = triangle_size_px(o.width, o.height, o.fov, copt.n);
  std::vector<LevelScreenError> sse;
  std::optional<container::LevelError> finest_error;
  if (&flight.heights == &source)
    sse = screen_error_bound(o, flight.file->info(), source, first_level, s_px, finest_error);

  // Through a temporary renamed when complete (cli::ReportFile), like the flight's stats.
  std::optional<cli::ReportFile> record_file;
  std::ostream* record = nullptr;
  if (!o.record_path.empty()) {
    record = &record_file.emplace(o.record_path).stream();
    *record << "# clipmap-view --window camera: frame x_m y_m above_ground_m yaw_deg pitch_deg\n";
    record->precision(17);
  }

  // GLFW, X11 and the GL driver keep process-lifetime allocations: the whole GL session is paused.
  const GlLeakCheckPause gl_pause;
  glfwSetErrorCallback(on_glfw_error);
  GlfwSession glfw;
  if (!glfw.ok) {
    std::cerr << "clipmap-view: --window: cannot initialise GLFW: " << glfw_error_text
              << " (is DISPLAY set? try xvfb-run) (exit " << cli::kExitUnavailable << ")\n";
    return cli::kExitUnavailable;
  }
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 4);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 5);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
  const std::string title = "clipmap-view: " + o.pyramid;
  GLFWwindow* window = glfwCreateWindow(o.width, o.height, title.c_str(), nullptr, nullptr);
  if (!window) {
    std::cerr << "clipmap-view: --window: cannot open an OpenGL 4.5 core window: " << glfw_error_text
              << " (exit " << cli::kExitUnavailable << ")\n";
    return cli::kExitUnavailable;
  }
  glfwMakeContextCurrent(window);
  glfwSwapInterval(scripted ? 0 : 1);
  int status = cli::kExitOk;
  {
    ClipmapRenderer renderer(copt.n, clipmap.level_count(), o.width, o.height);
    apply_drape(renderer, flight);
    Overlay overlay;
    const auto* gl_name = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
    if (!o.quiet)
      std::cerr << "clipmap-view: window " << o.width << "x" << o.height << ", " << (gl_name ? gl_name : "?")
                << ", n=" << copt.n << ", " << clipmap.level_count() << " levels"
                << (scripted ? ", scripted" : "") << "\n";

    Viewer viewer;
    viewer.camera = camera_at(source, keys.front(), o.fov);
    viewer.render = render_options(o);
    const GridSize fs = source.level_size(source.level_count() - 1);
    viewer.speed = 0.02 * double(std::max(fs.width, fs.height)) * flight.spacing;  // 50 s across
    glfwSetWindowUserPointer(window, &viewer);
    if (!scripted) {
      glfwSetKeyCallback(window, [](GLFWwindow* w, int key, int, int action, int) {
        if (action != GLFW_REPEAT)
          static_cast<Viewer*>(glfwGetWindowUserPointer(w))->key(key, action == GLFW_PRESS);
      });
      glfwSetMouseButtonCallback(window, [](GLFWwindow* w, int button, int action, int) {
        auto* v = static_cast<Viewer*>(glfwGetWindowUserPointer(w));
        if (button != GLFW_MOUSE_BUTTON_LEFT) return;
        v->dragging = action == GLFW_PRESS;
        glfwGetCursorPos(w, &v->last_x, &v->last_y);
      });
      glfwSetCursorPosCallback(window, [](GLFWwindow* w, double x, double y) {
        auto* v = static_cast<Viewer*>(glfwGetWindowUserPointer(w));
        if (v->dragging) v->mouse(x - v->last_x, y - v->last_y);
        v->last_x = x, v->last_y = y;
      });
    }

    std::vector<uint8_t> window_pixels;
    int window_w = 0, window_h = 0;
    size_t next_event = 0;
    double fps = 0;
    auto last = Clock::now();
    for (int f = 0; !viewer.quit && !glfwWindowShouldClose(window); ++f) {
      if (o.frames_given && f >= o.frames) break;
      // Script time advances 1/30 s a frame whatever the machine's speed, so a script replays exactly.
      const double wall_dt = std::min(since(last), 0.25);
      last = Clock::now();
      const double dt = scripted ? 1.0 / 30 : wall_dt;
      if (f > 0) viewer.move(dt);
      const double t = scripted ? f / 30.0 : 0;
      for (; next_event < script.size() && script[next_event].time <= t + 1e-9; ++next_event) {
        const ScriptEvent& e = script[next_event];
        if (e.kind == ScriptEvent::Key) viewer.key(e.key, e.down);
        if (e.kind == ScriptEvent::Mouse) viewer.mouse(e.dx, e.dy);
        if (e.kind == ScriptEvent::Quit) viewer.quit = true;
      }
      // A script without a quit event ends after its last event.
      if (scripted && (script.empty() || t > script.back().time + 1e-9)) viewer.quit = true;
      if (viewer.quit && f > 0) break;
      glfwPollEvents();
      // Stay above the ground (the finest level's sample under the camera, as the flight measures it).
      const double ground = ground_height(source, viewer.camera.position[0], viewer.camera.position[1]);
      viewer.camera.position[2] = std::max(viewer.camera.position[2], ground + 2.0);
      Camera& cam = viewer.camera;
      const ClipmapUpdateStats us = clipmap.update(cam.position[0], cam.position[1], cam.position[2]);
      renderer.upload(clipmap);
      const RenderStats rs = renderer.render(clipmap, cam, viewer.render);
      damage.poll(*flight.decoder);
      if (record)
        *record << f << ' ' << cam.position[0] << ' ' << cam.position[1] << ' ' << cam.position[2] - ground
                << ' ' << cam.yaw * 180 / M_PI << ' ' << cam.pitch * 180 / M_PI << '\n';
      int fb_w = 0, fb_h = 0;
      glfwGetFramebufferSize(window, &fb_w, &fb_h);
      if (fb_w > 0 && fb_h > 0) {
        renderer.blit_to_default_framebuffer(fb_w, fb_h);
        if (f > 0 && wall_dt > 0) fps = fps == 0 ? 1 / wall_dt : 0.9 * fps + 0.1 / wall_dt;  // wall clock
        double worst = -1;
        for (const LevelScreenError& e : sse)
          if (e.level >= first_level && e.level < first_level + us.active_levels)
            worst = std::max(worst, e.p999_px);
        char line[4][160];
        std::snprintf(line[0], sizeof line[0], "%.1f fps  %.2f M triangles  %d draw calls", fps,
                      double(rs.triangles) / 1e6, rs.draw_calls);
        std::snprintf(line[1], sizeof line[1], "levels %d active of %d, %d behind, n = %d", us.active_levels,
                      clipmap.level_count(), us.levels_behind, copt.n);
        if (worst >= 0)
          std::snprintf(line[2], sizeof line[2], "screen-space error p99.9 %s %.2f px (worst level drawn)",
                        finest_error ? "<=" : "~", worst);
        else
          std::snprintf(line[2], sizeof line[2], "screen-space error: not estimated (synthesised levels)");
        std::snprintf(line[3], sizeof line[3], "height %.0f m above ground, speed %.0f m/s (+/-)",
                      cam.position[2] - ground, viewer.speed);
        overlay.draw(
            {line[0], line[1], line[2], line[3],
             "T transitions " + on_off(viewer.render.transitions) + "  C culling " +
                 on_off(viewer.render.culling) + "  L levels " + on_off(viewer.render.level_colours) +
                 "  F wireframe " + on_off(viewer.render.wireframe)},
            fb_w, fb_h);
        if (!o.screenshot_window.empty()) {  // the window as shown, overlay included (bottom row first)
          window_pixels.resize(size_t(fb_w) * size_t(fb_h) * 4);
          glPixelStorei(GL_PACK_ALIGNMENT, 1);
          glReadBuffer(GL_BACK);
          glReadPixels(0, 0, fb_w, fb_h, GL_RGBA, GL_UNSIGNED_BYTE, window_pixels.data());
          window_w = fb_w, window_h = fb_h;
        }
        glfwSwapBuffers(window);
      }
    }
    if (!o.screenshot.empty()) {
      std::vector<uint8_t> pixels;
      renderer.read_rgba(pixels);
      write_png_rgba(o.screenshot, o.width, o.height, pixels);
      if (!o.quiet) std::cerr << "clipmap-view: screenshot " << o.screenshot << "\n";
    }
    if (!o.screenshot_window.empty() && !window_pixels.empty()) {
      const size_t row = size_t(window_w) * 4;
      for (int y = 0; y < window_h / 2; ++y)
        std::swap_ranges(window_pixels.begin() + ptrdiff_t(size_t(y) * row),
                         window_pixels.begin() + ptrdiff_t(size_t(y + 1) * row),
                         window_pixels.begin() + ptrdiff_t(size_t(window_h - 1 - y) * row));
      for (size_t i = 3; i < window_pixels.size(); i += 4) window_pixels[i] = 255;
      write_png_rgba(o.screenshot_window, window_w, window_h, window_pixels);
    }
  }
  glfwDestroyWindow(window);
  if (record_file) record_file->finish();
  damage.poll(*flight.decoder);
  if (!damage.parts().empty()) status = cli::kExitDamaged;
  return status;
}

#endif

}  // namespace clipmap_view
