// Headless EGL context for the renderer: Mesa's surfaceless platform first (no window system, no
// GPU needed: llvmpipe), then the default display (GPU drivers), OpenGL 4.5 core, no surface.
#include <EGL/egl.h>
#include <EGL/eglext.h>
#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>

#include <cstring>
#include <stdexcept>
#include <string>

#include "render/renderer.h"

namespace terrain::render {

using namespace terrain::runtime;  // the stage below

namespace {

[[noreturn]] void egl_fail(const char* step) {
  char code[32];
  std::snprintf(code, sizeof code, "0x%04X", unsigned(eglGetError()));
  throw std::runtime_error(std::string("headless OpenGL: ") + step + " failed (EGL error " + code +
                           "); is Mesa's EGL (libegl-mesa0, libgl1-mesa-dri) installed?");
}

bool has_extension(const char* list, const char* name) {
  if (!list) return false;
  const size_t n = std::strlen(name);
  for (const char* p = list; (p = std::strstr(p, name)) != nullptr; p += n)
    if ((p == list || p[-1] == ' ') && (p[n] == ' ' || p[n] == '\0')) return true;
  return false;
}

}  // namespace

HeadlessGL::HeadlessGL() {
  EGLDisplay dpy = EGL_NO_DISPLAY;
  const char* client_ext = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
  if (has_extension(client_ext, "EGL_MESA_platform_surfaceless")) {
    auto get_platform_display =
        reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(eglGetProcAddress("eglGetPlatformDisplayEXT"));
    if (get_platform_display) {
      dpy = get_platform_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
      EGLint major = 0, minor = 0;
      if (dpy != EGL_NO_DISPLAY && eglInitialize(dpy, &major, &minor))
        platform_ = "surfaceless";
      else
        dpy = EGL_NO_DISPLAY;
    }
  }
  if (dpy == EGL_NO_DISPLAY) {
    dpy = eglGetDisplay(EGL_DEFAULT_DISPLAY);
    EGLint major = 0, minor = 0;
    if (dpy == EGL_NO_DISPLAY || !eglInitialize(dpy, &major, &minor)) egl_fail("eglInitialize");
    platform_ = "default";
  }
  display_ = dpy;
  if (!eglBindAPI(EGL_OPENGL_API)) egl_fail("eglBindAPI(OpenGL)");
  // The default EGL_SURFACE_TYPE (window) matches nothing on the surfaceless platform: ask for
  // pbuffer-capable configs, which every headless driver offers, although no surface is made.
  const EGLint config_attribs[] = {EGL_SURFACE_TYPE, EGL_PBUFFER_BIT, EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT,
                                   EGL_NONE};
  EGLConfig config = nullptr;
  EGLint count = 0;
  if (!eglChooseConfig(dpy, config_attribs, &config, 1, &count) || count < 1)
    egl_fail("eglChooseConfig (pbuffer, OpenGL)");
  const EGLint context_attribs[] = {EGL_CONTEXT_MAJOR_VERSION,
                                    4,
                                    EGL_CONTEXT_MINOR_VERSION,
                                    5,
                                    EGL_CONTEXT_OPENGL_PROFILE_MASK,
                                    EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT,
                                    EGL_NONE};
  EGLContext ctx = eglCreateContext(dpy, config, EGL_NO_CONTEXT, context_attribs);
  if (ctx == EGL_NO_CONTEXT) egl_fail("eglCreateContext(OpenGL 4.5 core)");
  context_ = ctx;
  // Drawing goes to an FBO: no surface (EGL_KHR_surfaceless_context).
  if (!eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, ctx)) egl_fail("eglMakeCurrent(no surface)");
}

HeadlessGL::~HeadlessGL() {
  auto dpy = static_cast<EGLDisplay>(display_);
  eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
  if (context_) eglDestroyContext(dpy, static_cast<EGLContext>(context_));
  eglTerminate(dpy);
}

std::string HeadlessGL::renderer_name() const {
  const auto* s = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
  return s ? s : "?";
}

}  // namespace terrain::render
