// Finds and loads the image plugin (image_plugin.h) the first time an image is read or written.
#include "readers/internal/image_plugin.h"

#include <dlfcn.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <string>
#include <type_traits>
#include <vector>

#include "readers/internal/io_internal.h"

// Where to look, in order: beside the running program (bin/../lib/terrain/: an installed tree,
// wherever it was moved, uses its own plugin), this build tree's plugin (build trees and fresh
// clones need no setup), the configured install prefix (other programs that link libpyramid).
#ifndef TERRAIN_IMAGE_PLUGIN_PATH
#define TERRAIN_IMAGE_PLUGIN_PATH "libterrain_image_oiio.so"
#endif
#ifndef TERRAIN_IMAGE_PLUGIN_RELATIVE
#define TERRAIN_IMAGE_PLUGIN_RELATIVE "../lib/terrain/libterrain_image_oiio.so"
#endif
#ifndef TERRAIN_IMAGE_PLUGIN_INSTALLED
#define TERRAIN_IMAGE_PLUGIN_INSTALLED "/usr/local/lib/terrain/libterrain_image_oiio.so"
#endif

namespace terrain::io {
namespace {

struct LoadedPlugin {
  ImagePlugin functions;
  std::string error;  // why it could not be loaded; empty once loaded
};

// The plugin file to load: $TERRAIN_IMAGE_PLUGIN when set, else the first candidate that exists.
// Sets `tried` to the candidates looked at when none exists.
std::string plugin_path(bool& from_env, std::string& tried) {
  const char* env = std::getenv("TERRAIN_IMAGE_PLUGIN");
  from_env = env && *env;
  if (from_env) return env;
  std::vector<std::string> candidates;
  std::error_code ec;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (!ec)
    candidates.push_back((exe.parent_path() / TERRAIN_IMAGE_PLUGIN_RELATIVE).lexically_normal().string());
  candidates.push_back(TERRAIN_IMAGE_PLUGIN_PATH);
  candidates.push_back(TERRAIN_IMAGE_PLUGIN_INSTALLED);
  for (const std::string& c : candidates) {
    if (access(c.c_str(), F_OK) == 0) return c;
    tried += (tried.empty() ? "" : ", ") + c;
  }
  return candidates[candidates.size() - 2];  // the build tree's, named in the error
}

LoadedPlugin load_plugin() {
  LoadedPlugin loaded;
  bool from_env = false;
  std::string tried;
  const std::string path = plugin_path(from_env, tried);
  const std::string where = "cannot load the image plugin " + path +
                            (from_env ? " (from $TERRAIN_IMAGE_PLUGIN)"
                                      : (tried.empty() ? std::string() : " (none of " + tried + " exists)") +
                                            " (set $TERRAIN_IMAGE_PLUGIN to use another)");
  void* handle = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (!handle) {
    const char* why = dlerror();
    loaded.error = where + ": " + (why ? why : "dlopen failed");
    return loaded;
  }
  auto find = [&](const char* name, auto& function) {
    dlerror();
    void* symbol = dlsym(handle, name);
    if (!symbol && loaded.error.empty()) {
      const char* why = dlerror();
      loaded.error = where + ": " + (why ? why : std::string("no symbol ") + name);
    }
    function = reinterpret_cast<std::remove_reference_t<decltype(function)>>(symbol);
  };
  decltype(&terrain_image_abi_version) abi_version = nullptr;
  find("terrain_image_abi_version", abi_version);
  if (loaded.error.empty() && abi_version() != TERRAIN_IMAGE_PLUGIN_ABI_VERSION)
    loaded.error = where + ": it has interface version " + std::to_string(abi_version()) +
                   ", this program needs " + std::to_string(TERRAIN_IMAGE_PLUGIN_ABI_VERSION);
  ImagePlugin& f = loaded.functions;
  find("terrain_image_open", f.open);
  find("terrain_image_read_rows", f.read_rows);
  find("terrain_image_close", f.close);
  find("terrain_image_read_georef", f.read_georef);
  find("terrain_image_create", f.create);
  find("terrain_image_write_rows", f.write_rows);
  find("terrain_image_finish", f.finish);
  find("terrain_image_destroy", f.destroy);
  if (!loaded.error.empty()) dlclose(handle);
  return loaded;
}

}  // namespace

const ImagePlugin& image_plugin(ErrorCode code, const std::string& image_path) {
  static std::once_flag once;
  static LoadedPlugin loaded;
  std::call_once(once, [] { loaded = load_plugin(); });
  if (!loaded.error.empty()) fail(code, image_path, loaded.error);
  return loaded.functions;
}

}  // namespace terrain::io
