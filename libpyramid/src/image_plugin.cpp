// Finds and loads the image plugin (image_plugin.h) the first time an image is read or written.
#include "image_plugin.h"

#include <dlfcn.h>

#include <cstdlib>
#include <mutex>
#include <string>
#include <type_traits>

#include "io_internal.h"

#ifndef TERRAIN_IMAGE_PLUGIN_PATH
#define TERRAIN_IMAGE_PLUGIN_PATH "libterrain_image_oiio.so"
#endif

namespace terrain::io {
namespace {

struct LoadedPlugin {
  ImagePlugin functions;
  std::string error;  // why it could not be loaded; empty once loaded
};

LoadedPlugin load_plugin() {
  LoadedPlugin loaded;
  const char* env = std::getenv("TERRAIN_IMAGE_PLUGIN");
  const bool from_env = env && *env;
  const std::string path = from_env ? env : TERRAIN_IMAGE_PLUGIN_PATH;
  const std::string where = "cannot load the image plugin " + path +
                            (from_env ? " (from $TERRAIN_IMAGE_PLUGIN)" : " (set $TERRAIN_IMAGE_PLUGIN to use another)");
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
    loaded.error = where + ": it has interface version " + std::to_string(abi_version()) + ", this program needs " +
                   std::to_string(TERRAIN_IMAGE_PLUGIN_ABI_VERSION);
  ImagePlugin& f = loaded.functions;
  find("terrain_image_open", f.open);
  find("terrain_image_read_rows", f.read_rows);
  find("terrain_image_close", f.close);
  find("terrain_image_create", f.create);
  find("terrain_image_write_rows", f.write_rows);
  find("terrain_image_finish", f.finish);
  find("terrain_image_destroy", f.destroy);
  if (!loaded.error.empty()) dlclose(handle);
  return loaded;
}

}  // namespace

const ImagePlugin& image_plugin(IoErrorCode code, const std::string& image_path) {
  static std::once_flag once;
  static LoadedPlugin loaded;
  std::call_once(once, [] { loaded = load_plugin(); });
  if (!loaded.error.empty()) fail(code, image_path, loaded.error);
  return loaded.functions;
}

}  // namespace terrain::io
